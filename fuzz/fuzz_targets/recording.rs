//! The `recording` target: its body is `monotrack_fuzz_entry::recording` (fuzz/entry), which the
//! stable test `fuzz/entry/tests/corpora.rs` also runs on the committed corpus.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| monotrack_fuzz_entry::recording::run(data));
