//! Helpers shared by the cross-crate tests: locating `../shared/data` (a user's fresh clone has
//! no `../shared`: the tests that need it are then ignored, with the reason, by the `shared_data`
//! cfg that build.rs sets).

use std::path::PathBuf;

/// Where the shared data folder is looked for: `$MONOTRACK_SHARED_DATA`, else
/// `<workspace>/../shared/data` (build.rs reads the same place).
pub fn shared_data_path() -> PathBuf {
    std::env::var_os("MONOTRACK_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"))
}

/// The shared data folder, if present (for tools that work with or without it).
pub fn shared_data_if_present() -> Option<PathBuf> {
    let p = shared_data_path();
    p.is_dir().then_some(p)
}

/// The shared data folder, for a test marked
/// `#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]`: build.rs sets `shared_data`
/// when the folder is present, so the test runs only then, and a folder gone since the build is a
/// failure with this message, never a silent pass.
pub fn shared_data() -> PathBuf {
    let p = shared_data_path();
    assert!(
        p.is_dir(),
        "{} is not a folder (it was at build time: rebuild, or set MONOTRACK_SHARED_DATA)",
        p.display()
    );
    p
}

pub mod poseeval;
pub mod qualityeval;
pub mod synth;
pub mod trackeval;
