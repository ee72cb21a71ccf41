//! The uniffi bindings generator, built from the same uniffi version as `monotrack-ffi`.
//! Usage: `cargo run -p monotrack-uniffi-bindgen -- generate --library <lib> --language kotlin --out-dir <dir>`.

fn main() {
    uniffi::uniffi_bindgen_main()
}
