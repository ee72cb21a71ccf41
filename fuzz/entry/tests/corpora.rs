//! Every committed fuzz input (`fuzz/corpus/<target>/`) and every seed through the same entry
//! point the fuzzer runs, on stable and in every test run: a fixed crash stays fixed, and a change
//! that breaks the contract on an input the fuzzer once found fails here without nightly.

use monotrack_fuzz_entry::{TARGETS, seeds};
use std::path::Path;

fn replay(target: &str) -> usize {
    let run = TARGETS.iter().find(|(n, _)| *n == target).unwrap().1;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../corpus")
        .join(target);
    let mut inputs: Vec<(String, Vec<u8>)> = match std::fs::read_dir(&dir) {
        Ok(entries) => entries
            .map(|e| {
                let p = e.unwrap().path();
                (p.display().to_string(), std::fs::read(&p).unwrap())
            })
            .collect(),
        Err(_) => Vec::new(),
    };
    inputs.sort();
    inputs.extend(seeds(target));
    for (name, bytes) in &inputs {
        let r = std::panic::catch_unwind(|| run(bytes));
        assert!(r.is_ok(), "{target}: the input {name} breaks the contract");
    }
    println!("{target}: {} inputs", inputs.len());
    inputs.len()
}

#[test]
fn frames_corpus() {
    assert!(
        replay("frames") > 100,
        "the committed frames corpus is missing"
    );
}

#[test]
fn fit_inputs_corpus() {
    assert!(
        replay("fit_inputs") > 100,
        "the committed fit_inputs corpus is missing"
    );
}

#[test]
fn json_inputs_seeds() {
    assert_eq!(replay("json_inputs"), 5);
}

#[test]
fn model_bundle_seeds() {
    assert!(replay("model_bundle") >= 5);
}

#[test]
fn recording_corpus() {
    assert!(
        replay("recording") >= 10,
        "the committed recording corpus is missing"
    );
    // The corpus was written from FORMAT.md alone (fuzz/make_recording_corpus.py): its valid
    // files read, its invalid ones are refused, so the document and the reader agree.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../corpus/recording");
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let parsed = std::fs::read(&path).map(|b| {
            monotrack_core::record::Recording::parse(&b)
                .map(|r| r.frames())
                .map_err(|e| e.to_string())
        });
        match parsed.unwrap() {
            Ok(frames) => assert!(name.starts_with("valid-"), "{name} reads ({frames} frames)"),
            Err(e) => assert!(name.starts_with("invalid-"), "{name}: {e}"),
        }
    }
    let every = std::fs::read(dir.join("valid-every-kind")).unwrap();
    let rec = monotrack_core::record::Recording::parse(&every).unwrap();
    assert_eq!(
        (rec.frames(), rec.checked_frames(), rec.dropped_frames()),
        (3, 2, 3)
    );
}
