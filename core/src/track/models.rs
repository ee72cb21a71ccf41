//! The tracker over the SDK's own models: [`crate::detect::FaceDetector`] finds faces,
//! [`crate::landmarks::M3`] gives landmarks and validates tracked windows. [`Tracker`] is the
//! pipeline apps use (the FFI's `FaceTracker` and the CLI's `track` wrap it).

use super::{FaceTracker, LandmarkEstimator, LandmarkMode, Mode, RegionDetector, TrackerConfig};
use crate::detect::{Detection, DetectorConfig, FaceDetector};
use crate::error::{Error, Result};
use crate::gaze::{GazeCalibration, GazeConfig};
use crate::image::{GrayImage, Rect};
use crate::landmarks::{FaceLandmarks, GradientDetector, GradientPoints, M3};
use crate::model::bundle::ModelBundle;
use crate::model::{BUILTIN_JSON, FaceModel};

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

    fn face_confidence_turned(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        roll: f32,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        M3::level1_turned(self, image, face, roll, out)
    }

    fn complete(&mut self, image: &GrayImage, _face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        M3::refine(self, image, out)
    }

    fn face_box(&self, out: &FaceLandmarks) -> Option<Rect> {
        M3::level1_box(self, out)
    }
}

/// The learning-free gradient detector as a [`LandmarkEstimator`] (the ultra-light mode): its 32
/// points as 68-point landmarks with per-point weights ([`GradientPoints::to_landmarks`]), each
/// search started from the roll it found last.
///
/// It has no face classifier: its face confidence is the mean confidence of its points with a
/// 68-point counterpart ([`GradientPoints::mean_confidence`]), a weak one (on faces68 validation
/// images it scores windows away from the faces not far below the faces themselves;
/// [`TrackerConfig::ultra_light`] sets the thresholds for it).
#[derive(Debug, Clone, Default)]
pub struct GradientLandmarks {
    detector: GradientDetector,
    points: GradientPoints,
    /// The last face's region: the last roll starts the search only on the same face.
    last: Rect,
}

impl GradientLandmarks {
    /// The last face's 32 points, confidences and roll.
    pub fn points(&self) -> &GradientPoints {
        &self.points
    }
}

impl LandmarkEstimator for GradientLandmarks {
    fn estimate(&mut self, image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        if face.iou(&self.last) > 0.3 {
            let roll = self.points.roll_deg;
            self.detector
                .detect_tracked(image, face, roll, &mut self.points)?;
        } else {
            self.detector.detect(image, face, 0.0, &mut self.points)?;
        }
        self.last = *face;
        *out = FaceLandmarks::default();
        self.points.to_landmarks(out);
        Ok(())
    }

    fn face_confidence(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        self.estimate(image, face, out)?;
        Ok(self.points.mean_confidence())
    }

    /// [`Self::face_confidence`] left the whole result in `out`.
    fn complete(&mut self, _: &GrayImage, _: &Rect, _: &mut FaceLandmarks) -> Result<()> {
        Ok(())
    }
}

/// The landmark estimator of the shipped tracker: M3, or the gradient detector in the
/// ultra-light mode ([`crate::track::LandmarkMode`]).
#[derive(Debug)]
pub enum Landmarker {
    /// The M3 networks.
    M3(Box<M3>),
    /// The learning-free gradient detector.
    Gradient(Box<GradientLandmarks>),
}

impl Landmarker {
    /// M3's mirror-average mode ([`M3::set_mirror_average`]); nothing for the gradient detector.
    pub fn set_mirror_average(&mut self, on: bool) {
        if let Self::M3(m3) = self {
            m3.set_mirror_average(on);
        }
    }

    /// M3, when that is the estimator.
    pub fn m3(&self) -> Option<&M3> {
        match self {
            Self::M3(m3) => Some(m3),
            Self::Gradient(_) => None,
        }
    }
}

impl LandmarkEstimator for Landmarker {
    fn estimate(&mut self, image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        match self {
            Self::M3(m) => LandmarkEstimator::estimate(m.as_mut(), image, face, out),
            Self::Gradient(g) => g.estimate(image, face, out),
        }
    }

    fn face_confidence(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        match self {
            Self::M3(m) => LandmarkEstimator::face_confidence(m.as_mut(), image, face, out),
            Self::Gradient(g) => g.face_confidence(image, face, out),
        }
    }

    fn face_confidence_turned(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        roll: f32,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        match self {
            Self::M3(m) => {
                LandmarkEstimator::face_confidence_turned(m.as_mut(), image, face, roll, out)
            }
            Self::Gradient(g) => g.face_confidence_turned(image, face, roll, out),
        }
    }

    fn complete(&mut self, image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        match self {
            Self::M3(m) => LandmarkEstimator::complete(m.as_mut(), image, face, out),
            Self::Gradient(g) => g.complete(image, face, out),
        }
    }

    fn face_box(&self, out: &FaceLandmarks) -> Option<Rect> {
        match self {
            Self::M3(m) => LandmarkEstimator::face_box(m.as_ref(), out),
            Self::Gradient(_) => None,
        }
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
        Self::from_detector(FaceDetector::with_config(config)?)
    }

    fn from_detector(detector: FaceDetector) -> Result<Self> {
        Ok(Self {
            detector,
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
pub type Tracker = FaceTracker<ModelDetector, Landmarker>;

impl FaceTracker<ModelDetector, Landmarker> {
    /// A tracker over the embedded detector (default settings, score threshold
    /// [`TrackerConfig::min_detection_score`]: M3's face check decides) and M3 — in [`Mode::Image`]
    /// in its mirror-average mode ([`M3::set_mirror_average`]; `estimator_mut` changes it).
    ///
    /// Why by mode: on still images the mode's second runs are more accurate (BENCHMARKS.md, "M3
    /// landmarks: accuracy"); in a video track they would run on every frame, so video mode stays
    /// single-pass and leaves the choice to the caller (the mode in the tracker, accuracy and time
    /// per frame: BENCHMARKS.md, "Tracking").
    ///
    /// # Errors
    /// As [`FaceTracker::new`], plus [`crate::Error::ModelLoad`] if an embedded model cannot be
    /// loaded.
    pub fn with_default_models(config: TrackerConfig) -> Result<Self> {
        // The tracker's own errors first (a NaN score would otherwise surface as the detector's).
        config.validate()?;
        Self::with_detector_config(
            config,
            detector_config_for(&config, DetectorConfig::default()),
        )
    }

    /// A tracker over the embedded models with detector settings of the caller's choosing. The
    /// detector's own `score_threshold` applies before [`TrackerConfig::min_detection_score`];
    /// [`detector_config_for`] aligns the two.
    ///
    /// # Errors
    /// As [`FaceTracker::with_default_models`].
    pub fn with_detector_config(config: TrackerConfig, detector: DetectorConfig) -> Result<Self> {
        let landmarker = match config.landmarks {
            LandmarkMode::M3 => {
                let mut m3 = M3::new()?;
                m3.set_mirror_average(config.mode == Mode::Image);
                Landmarker::M3(Box::new(m3))
            }
            LandmarkMode::Gradient => Landmarker::Gradient(Box::default()),
        };
        FaceTracker::new(ModelDetector::new(detector)?, landmarker, config)
    }
}

impl Tracker {
    /// A tracker over a model bundle's networks ([`ModelBundle`]), with detector settings as
    /// [`Tracker::with_detector_config`]. The bundle's face model must be the built-in one: the
    /// fit, vertices and projections run on it.
    ///
    /// # Errors
    /// As [`Tracker::with_detector_config`]; [`crate::Error::ModelLoad`] when a network in the
    /// bundle does not load or does not fit its contract, or the face model differs.
    pub fn with_bundle(
        config: TrackerConfig,
        detector: DetectorConfig,
        bundle: &ModelBundle,
    ) -> Result<Self> {
        config.validate()?;
        let face_model = bundle.required("face_model.json")?;
        if face_model != BUILTIN_JSON {
            FaceModel::from_json(face_model)?;
            return Err(Error::ModelLoad(
                "the bundle's face model is not the built-in one: this version fits the built-in \
                 face model only"
                    .into(),
            ));
        }
        let landmarker = match config.landmarks {
            LandmarkMode::M3 => {
                let files: Vec<(&str, &[u8])> = bundle.files().collect();
                let mut m3 = M3::from_bytes(bundle.required("m3.json")?, &files)?;
                m3.set_mirror_average(config.mode == Mode::Image);
                Landmarker::M3(Box::new(m3))
            }
            LandmarkMode::Gradient => Landmarker::Gradient(Box::default()),
        };
        let net = FaceDetector::from_bytes(
            detector,
            bundle.required("detector.json")?,
            bundle.required("detector.onnx")?,
        )?;
        FaceTracker::new(ModelDetector::from_detector(net)?, landmarker, config)
    }
}

/// `detector` with its score threshold at the tracker's `min_detection_score`, so every candidate
/// the tracker would consider reaches M3's face check (kept inside the detector's valid range).
pub fn detector_config_for(config: &TrackerConfig, detector: DetectorConfig) -> DetectorConfig {
    DetectorConfig {
        score_threshold: config.min_detection_score.clamp(0.01, 0.99),
        ..detector
    }
}

impl<D: RegionDetector, L: LandmarkEstimator> FaceTracker<D, L> {
    /// The point-of-gaze settings ([`FaceTracker::set_gaze_config`]).
    pub fn gaze_config(&self) -> &GazeConfig {
        &self.gaze.config
    }
}

/// Where a recorded stream starts ([`crate::record`]): what a tracker keeps across
/// [`FaceTracker::reset`] and a freshly built one lacks. A recording starts by ending every track
/// ([`Tracker::begin_recorded_stream`]), so that a replay built from the recorded settings and
/// this ([`Tracker::resume_recorded_stream`]) is in the same state before the first frame.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamStart {
    /// The id the next new face gets (ids go on counting across resets).
    pub next_face_id: u64,
    /// [`crate::track::TrackingResult::frame_index`] of the next frame.
    pub frame_index: u64,
    /// Frames the whole frame was searched turned so far (it picks the next turn).
    pub whole_frame_turns: u32,
    /// The user's tap calibration.
    pub calibration: GazeCalibration,
}

impl Tracker {
    /// Ends every track, as [`FaceTracker::reset`] does, forgets the eye rays kept for taps and
    /// the gradient detector's last roll, and returns what a replay needs to start from the same
    /// state ([`Self::resume_recorded_stream`]).
    pub fn begin_recorded_stream(&mut self) -> StreamStart {
        self.restart_stream();
        StreamStart {
            next_face_id: self.next_id,
            frame_index: self.frame_index,
            whole_frame_turns: self.whole_frame_turns,
            calibration: self.gaze.calibration.clone(),
        }
    }

    /// Puts this tracker where [`Self::begin_recorded_stream`] left the recorded one.
    pub fn resume_recorded_stream(&mut self, start: &StreamStart) {
        self.restart_stream();
        self.next_id = start.next_face_id;
        self.frame_index = start.frame_index;
        self.whole_frame_turns = start.whole_frame_turns;
        self.gaze.calibration = start.calibration.clone();
    }

    fn restart_stream(&mut self) {
        self.reset();
        self.gaze.history.clear();
        self.gaze.next = 0;
        if let Landmarker::Gradient(g) = &mut self.estimator {
            g.points = GradientPoints::default();
            g.last = Rect::default();
        }
    }
}
