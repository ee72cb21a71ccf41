//! Model bundles as an app passes them (`ModelBundle::from_bytes`, then a tracker built on it):
//! the input as it is (magic, version, checksum, entry table), and the input with its checksum
//! made right, so that mutated entries reach the loaders of every network and the face model
//! (seeded with the built-in bundle and damaged copies of it, `crate::seeds`).
use crate::bytes::typed;
use monotrack_ffi::{FaceTracker, FaceTrackerOptions, ModelBundle, RunningMode};

/// `bytes` with its last four bytes replaced by the CRC-32 of the rest, as a bundle file ends.
pub fn sealed(bytes: &[u8]) -> Vec<u8> {
    let n = bytes.len().saturating_sub(4);
    let mut out = bytes[..n].to_vec();
    out.extend_from_slice(&crc32fast::hash(&out).to_le_bytes());
    out
}

/// One input of the `model_bundle` target.
pub fn run(data: &[u8]) {
    typed(
        "ModelBundle::from_bytes",
        ModelBundle::from_bytes(data.to_vec()),
    );
    if let Ok(bundle) = ModelBundle::from_bytes(sealed(data)) {
        let options = FaceTrackerOptions {
            running_mode: Some(RunningMode::Image),
            models: Some(bundle),
            ..FaceTrackerOptions::default()
        };
        typed("FaceTracker::new", FaceTracker::new(options, None));
    }
}
