//! Tells the tests what they can run here, as cfgs that the test attributes read, so that a test
//! that cannot run is reported by the runner as ignored with its reason rather than passing empty:
//! - `shared_data`: `../shared/data` (or `$MONOTRACK_SHARED_DATA`) is present. Where
//!   `MONOTRACK_REQUIRE_SHARED_DATA` is set (CI), its absence fails the build instead.
//! - `emulated`: the tests are built to run under qemu (`MONOTRACK_EMULATED`, tests/aarch64.sh),
//!   which runs the networks about a thousand times slower than a phone.
use std::path::PathBuf;

fn main() {
    println!("cargo::rustc-check-cfg=cfg(shared_data)");
    println!("cargo::rustc-check-cfg=cfg(emulated)");
    println!("cargo::rerun-if-changed=build.rs");
    for var in [
        "MONOTRACK_SHARED_DATA",
        "MONOTRACK_REQUIRE_SHARED_DATA",
        "MONOTRACK_EMULATED",
    ] {
        println!("cargo::rerun-if-env-changed={var}");
    }
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let data = std::env::var_os("MONOTRACK_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("../../shared/data"));
    if data.is_dir() {
        println!("cargo::rustc-cfg=shared_data");
        // A folder is scanned whole: the tests rebuild when the data changes or goes away.
        println!("cargo::rerun-if-changed={}", data.display());
    } else if std::env::var_os("MONOTRACK_REQUIRE_SHARED_DATA").is_some() {
        panic!(
            "MONOTRACK_REQUIRE_SHARED_DATA is set but {} is not a folder: the tests that need it \
             would be ignored",
            data.display()
        );
    }
    if std::env::var_os("MONOTRACK_EMULATED").is_some() {
        println!("cargo::rustc-cfg=emulated");
    }
}
