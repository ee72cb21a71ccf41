//! Model bundles through the FFI (`bindings/API.md`, "Own weights"): the networks and face model a
//! product trained itself, loaded from bytes or a file and handed to `FaceTrackerOptions.models`
//! (`monotrack_core::model::bundle`).

use crate::MonotrackError;
use crate::error::guard;
use monotrack_core::model::bundle::ModelBundle as CoreBundle;
use std::sync::Arc;

/// A checked model bundle (format, version, checksum, the required files); whether its networks
/// load is told when a tracker is built with it.
#[derive(Debug, PartialEq, Eq, uniffi::Object)]
pub struct ModelBundle {
    pub(crate) inner: CoreBundle,
}

#[uniffi::export]
impl ModelBundle {
    /// Reads a bundle file's bytes (`core/models/train/make_bundle.py` writes them).
    ///
    /// # Errors
    /// `BundleVersion` for another format version, `BundleChecksum` for damaged bytes,
    /// `ModelLoad` for bytes that are no bundle or lack a required file.
    #[uniffi::constructor]
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Arc<Self>, MonotrackError> {
        guard(|| {
            Ok(Arc::new(Self {
                inner: CoreBundle::from_bytes(&bytes)?,
            }))
        })
    }

    /// Reads a bundle file at `path` (an app's asset copied to storage, a downloaded file).
    ///
    /// # Errors
    /// As `from_bytes`; `ModelLoad` when the file cannot be read.
    #[uniffi::constructor]
    pub fn from_path(path: String) -> Result<Arc<Self>, MonotrackError> {
        guard(|| {
            let bytes = std::fs::read(&path).map_err(|e| MonotrackError::ModelLoad {
                msg: format!("cannot read the model bundle {path:?}: {e}"),
            })?;
            Ok(Arc::new(Self {
                inner: CoreBundle::from_bytes(&bytes)?,
            }))
        })
    }

    /// The models built into the library, as a bundle (what a tracker without `models` runs).
    #[uniffi::constructor]
    pub fn builtin() -> Arc<Self> {
        Arc::new(Self {
            inner: CoreBundle::builtin(),
        })
    }

    /// The bundle format version this library reads and writes.
    pub fn format_version(&self) -> u32 {
        CoreBundle::FORMAT_VERSION
    }

    /// The files in the bundle, by name.
    pub fn file_names(&self) -> Vec<String> {
        self.inner.files().map(|(n, _)| n.to_string()).collect()
    }

    /// The bundle as a file (`from_bytes` reads it back).
    pub fn to_bytes(&self) -> Vec<u8> {
        self.inner.to_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::options::{FaceTrackerOptions, RunningMode};
    use crate::tracker::FaceTracker;
    use crate::tracker::tests::{gray_desc, upright_face};

    fn options(models: Option<Arc<ModelBundle>>) -> FaceTrackerOptions {
        FaceTrackerOptions {
            running_mode: Some(RunningMode::Video),
            models,
            ..FaceTrackerOptions::default()
        }
    }

    /// The built-in models written as a bundle file and read back track exactly as the built-in
    /// ones do.
    #[test]
    fn a_bundle_round_trip_tracks_as_the_builtin_models() {
        let (upright, w, h) = upright_face();
        let desc = gray_desc(w, h, 0, false);
        let dir = std::env::temp_dir().join(format!("monotrack-bundle-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("models.mtb");
        std::fs::write(&path, ModelBundle::builtin().to_bytes()).unwrap();
        let bundle = ModelBundle::from_path(path.display().to_string()).unwrap();
        assert_eq!(bundle.format_version(), 1);
        assert!(bundle.file_names().iter().any(|n| n == "face_model.json"));
        let own = FaceTracker::new(options(Some(bundle)), None).unwrap();
        let builtin = FaceTracker::new(options(None), None).unwrap();
        for ts in 1..=3 {
            let a = own.detect_for_video(&upright, desc, ts).unwrap();
            let b = builtin.detect_for_video(&upright, desc, ts).unwrap();
            assert_eq!(a.faces, b.faces, "frame {ts}");
        }
        assert!(matches!(
            ModelBundle::from_path(dir.join("missing.mtb").display().to_string()),
            Err(MonotrackError::ModelLoad { .. })
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A wrong version, a damaged file and a corrupt network are each their own error.
    #[test]
    fn bundle_errors_are_typed() {
        let bytes = ModelBundle::builtin().to_bytes();
        let mut newer = bytes.clone();
        newer[8] = 9;
        assert!(matches!(
            ModelBundle::from_bytes(newer),
            Err(MonotrackError::BundleVersion { .. })
        ));
        let mut damaged = bytes.clone();
        let mid = damaged.len() / 2;
        damaged[mid] ^= 1;
        assert!(matches!(
            ModelBundle::from_bytes(damaged),
            Err(MonotrackError::BundleChecksum { .. })
        ));
        assert!(matches!(
            ModelBundle::from_bytes(b"not a bundle".to_vec()),
            Err(MonotrackError::ModelLoad { .. })
        ));
        for broken in ["detector.onnx", "level1.onnx"] {
            let files = CoreBundle::builtin()
                .files()
                .map(|(n, b)| {
                    let b = if n == broken {
                        vec![7u8; 100]
                    } else {
                        b.to_vec()
                    };
                    (n.to_string(), b)
                })
                .collect();
            // A well-formed bundle (version, checksum) around a network that is no network.
            let bytes = CoreBundle::from_files(files).unwrap().to_bytes();
            let bundle = ModelBundle::from_bytes(bytes).unwrap();
            assert!(
                matches!(
                    FaceTracker::new(options(Some(bundle)), None),
                    Err(MonotrackError::ModelLoad { .. })
                ),
                "{broken}"
            );
        }
    }
}
