//! The tracker over the SDK's own models: [`crate::detect::FaceDetector`] finds faces,
//! [`crate::landmarks::M3`] gives landmarks and validates tracked windows. [`Tracker`] is the
//! pipeline apps use (the FFI's `FaceTracker` and the CLI's `track` wrap it).

use super::{FaceTracker, LandmarkEstimator, RegionDetector, TrackerConfig};
use crate::detect::{Detection, DetectorConfig, FaceDetector};
use crate::error::Result;
use crate::image::{GrayImage, Rect};
use crate::landmarks::{FaceLandmarks, M3};

impl LandmarkEstimator for M3 {
    fn estimate(&mut self, image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        M3::estimate(self, image, face, out)
    }

    fn face_confidence(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        M3::level1(self, image, face, out)
    }

    fn complete(&mut self, image: &GrayImage, _face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        M3::refine(self, image, out)
    }
}

/// [`FaceDetector`] as the tracker's [`RegionDetector`], with its detections buffer kept between
/// frames (no allocation per frame).
#[derive(Debug)]
pub struct ModelDetector {
    detector: FaceDetector,
    found: Vec<Detection>,
}

impl ModelDetector {
    /// The embedded detector with `config`.
    ///
    /// # Errors
    /// [`crate::Error::InvalidConfig`] for a bad config, [`crate::Error::ModelLoad`] if the embedded
    /// model cannot be loaded.
    pub fn new(config: DetectorConfig) -> Result<Self> {
        Ok(Self {
            detector: FaceDetector::with_config(config)?,
            found: Vec::with_capacity(64),
        })
    }

    /// The wrapped detector.
    pub fn detector(&self) -> &FaceDetector {
        &self.detector
    }
}

impl RegionDetector for ModelDetector {
    fn detect(&mut self, image: &GrayImage, out: &mut Vec<(Rect, f32)>) -> Result<()> {
        self.detector.detect(image, &mut self.found)?;
        out.clear();
        out.extend(self.found.iter().map(|d| (d.rect, d.score)));
        Ok(())
    }
}

/// The face tracker over the shipped models.
pub type Tracker = FaceTracker<ModelDetector, M3>;

impl FaceTracker<ModelDetector, M3> {
    /// A tracker over the embedded detector (default settings) and M3.
    ///
    /// # Errors
    /// As [`FaceTracker::new`], plus [`crate::Error::ModelLoad`] if an embedded model cannot be
    /// loaded.
    pub fn with_default_models(config: TrackerConfig) -> Result<Self> {
        Self::with_detector_config(config, DetectorConfig::default())
    }

    /// A tracker over the embedded models with detector settings of the caller's choosing.
    ///
    /// # Errors
    /// As [`FaceTracker::with_default_models`].
    pub fn with_detector_config(config: TrackerConfig, detector: DetectorConfig) -> Result<Self> {
        FaceTracker::new(ModelDetector::new(detector)?, M3::new()?, config)
    }
}
