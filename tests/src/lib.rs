//! Helpers shared by the cross-crate tests: locating `../shared/data` and skipping with a printed
//! reason when it is absent (a user's fresh clone has no `../shared`).

use std::path::PathBuf;

/// The shared data folder, if present: `$MONOTRACK_SHARED_DATA`, else `<workspace>/../shared/data`.
pub fn shared_data() -> Option<PathBuf> {
    let p = std::env::var_os("MONOTRACK_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"));
    p.is_dir().then_some(p)
}

/// Like [`shared_data`], but prints why a test is skipped when the data is absent.
pub fn shared_data_or_skip(test: &str) -> Option<PathBuf> {
    let d = shared_data();
    if d.is_none() {
        eprintln!("SKIPPED {test}: ../shared/data not found (set MONOTRACK_SHARED_DATA to run it)");
    }
    d
}

pub mod synth;
pub mod trackeval;
