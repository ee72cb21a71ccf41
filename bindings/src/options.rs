//! The tracker's options (`bindings/API.md`, "Options"): MediaPipe Face Landmarker's names with
//! MediaPipe's meanings, every field with a default, and the knobs MediaPipe has no word for
//! grouped apart in `TrackerTuning`. Converted to the core's `TrackerConfig` here only.

use crate::MonotrackError;
use crate::bundle::ModelBundle;
use crate::types::CameraIntrinsics;
use monotrack_core::camera::Intrinsics;
use monotrack_core::detect::DetectorConfig;
use monotrack_core::fit::MsbpConfig;
use monotrack_core::gaze::{GazeConfig, GazeFilter};
use monotrack_core::track::quality::QualityConfig;
use monotrack_core::track::{self as core_track, Tracker};
use std::sync::Arc;

/// How frames reach the tracker (MediaPipe's `RunningMode`); each mode has its call.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum RunningMode {
    /// Independent stills: `FaceTracker::detect`, every call detects afresh.
    Image,
    /// Frames of one stream, handled on the caller's thread: `FaceTracker::detect_for_video`
    /// tracks between them; timestamps must increase.
    Video,
    /// A camera stream handled on the tracker's own worker thread: `FaceTracker::detect_async`
    /// returns at once and the results reach the `LiveStreamListener` given to the constructor;
    /// timestamps must increase.
    LiveStream,
}

/// Settings beyond MediaPipe's options (every field has a default: `TrackerTuning()` in Kotlin
/// and Swift).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct TrackerTuning {
    /// Smallest face the detector looks for, pixels of the upright image (16..=4096). 16 with
    /// `min_face_detection_confidence` 0.25 is the small-faces operating point (faces down to
    /// about 17 px, more false positives and a longer detection; `core/models/MODEL_CARD.md`,
    /// "Face detector").
    #[uniffi(default = 24)]
    pub min_face_size_px: u32,
    /// The fast tracker's template match must score at least this (normalised cross-correlation,
    /// -1..=1); below it the face is re-detected.
    #[uniffi(default = 0.5)]
    pub min_match_score: f32,
    /// How far the fast tracker searches around the last face, as a fraction of the face's larger
    /// side in each direction (0 < margin ≤ 4).
    #[uniffi(default = 0.5)]
    pub search_margin: f32,
    /// The optical-flow landmark filter (steadier points between frames).
    #[uniffi(default = true)]
    pub flow_filter: bool,
    /// Temporal smoothing of the gaze direction that leaves saccades sharp.
    #[uniffi(default = false)]
    pub gaze_filter: bool,
    /// Frames over which a new track's shape units are estimated before being held (1..=1000).
    #[uniffi(default = 10)]
    pub shape_frames: u32,
    /// Landmarks in M3's mirror-average mode: more accurate, slower (five nets also run on their
    /// mirrored input; `core/models/MODEL_CARD.md`). `None`: on in the image running mode, off
    /// where it would run on every frame of a stream.
    #[uniffi(default = None)]
    pub mirror_average: Option<bool>,
    /// The ultra-light mode: the learning-free gradient landmark detector (no landmark network
    /// loaded; 27 of the 68 landmarks measured, `Face.landmark_confidence` says which) and the
    /// weak-perspective FFBP fit; no gestures, gaze or action units. Far less accurate than M3
    /// (`core/models/gradient_metrics.json`); its face check is weak: start from
    /// `ultra_light_face_tracker_options()`.
    #[uniffi(default = false)]
    pub ultra_light: bool,
    /// The thresholds of the quality reasons (`Face.quality`, `TrackingResult.reasons`).
    #[uniffi(default)]
    pub quality: QualityThresholds,
}

/// Where each quality reason starts (`QualityReason`; every field has a default,
/// `monotrack_core::track::quality` documents each measurement). A face's factor for a
/// measurement is 0.5 at its threshold; the reason is listed below 0.5.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct QualityThresholds {
    /// `Dark` below this mean luma of the face (or the frame), 0..=255.
    #[uniffi(default = 40.0)]
    pub dark_luma: f32,
    /// `Overexposed` above this fraction of saturated samples, 0..=1.
    #[uniffi(default = 0.25)]
    pub overexposed_fraction: f32,
    /// `Blurred` below this sharpness, whatever the face's recent frames.
    #[uniffi(default = 0.08)]
    pub min_sharpness: f32,
    /// `Blurred` below this fraction of the face's (or the stream's) recent sharpness, 0..=1.
    #[uniffi(default = 0.6)]
    pub blur_drop: f32,
    /// `Small` below this larger side of the landmarks' box, pixels.
    #[uniffi(default = 64.0)]
    pub min_face_px: f32,
    /// `PartlyOutside` above this fraction of the face's box outside the frame, 0..=1.
    #[uniffi(default = 0.1)]
    pub max_outside_fraction: f32,
    /// `Turned` past this yaw either way, degrees.
    #[uniffi(default = 45.0)]
    pub max_yaw_deg: f32,
    /// `Turned` past this pitch either way, degrees.
    #[uniffi(default = 30.0)]
    pub max_pitch_deg: f32,
    /// `Occluded` below this face probability of the landmark network, 0..=1.
    #[uniffi(default = 0.7)]
    pub min_face_probability: f32,
    /// `Occluded` above this fit residual (RMS pixels over the outer-eye distance).
    #[uniffi(default = 0.06)]
    pub max_fit_residual: f32,
}

impl Default for QualityThresholds {
    fn default() -> Self {
        QualityConfig::default().into()
    }
}

impl From<QualityConfig> for QualityThresholds {
    fn from(c: QualityConfig) -> Self {
        Self {
            dark_luma: c.dark_luma,
            overexposed_fraction: c.overexposed_fraction,
            min_sharpness: c.min_sharpness,
            blur_drop: c.blur_drop,
            min_face_px: c.min_face_px,
            max_outside_fraction: c.max_outside_fraction,
            max_yaw_deg: c.max_yaw_deg,
            max_pitch_deg: c.max_pitch_deg,
            min_face_probability: c.min_face_probability,
            max_fit_residual: c.max_fit_residual,
        }
    }
}

impl From<QualityThresholds> for QualityConfig {
    fn from(q: QualityThresholds) -> Self {
        Self {
            dark_luma: q.dark_luma,
            overexposed_fraction: q.overexposed_fraction,
            min_sharpness: q.min_sharpness,
            blur_drop: q.blur_drop,
            min_face_px: q.min_face_px,
            max_outside_fraction: q.max_outside_fraction,
            max_yaw_deg: q.max_yaw_deg,
            max_pitch_deg: q.max_pitch_deg,
            min_face_probability: q.min_face_probability,
            max_fit_residual: q.max_fit_residual,
        }
    }
}

/// The tracker's options. The names and meanings are MediaPipe Face Landmarker's where it has the
/// setting (`bindings/API.md` has the migration table); every field has a default, so Kotlin's
/// `FaceTrackerOptions()` and Swift's `FaceTrackerOptions()` are a working tracker.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct FaceTrackerOptions {
    /// `None`: `RunningMode::Image`, MediaPipe's default.
    #[uniffi(default = None)]
    pub running_mode: Option<RunningMode>,
    /// Most faces tracked at once (1..=16).
    #[uniffi(default = 1)]
    pub num_faces: u32,
    /// The face detector's score (0..=1) a candidate needs to be checked as a face.
    #[uniffi(default = 0.4)]
    pub min_face_detection_confidence: f32,
    /// Face presence (0..=1): a detection becomes a face when the landmark network's face
    /// confidence on its box is at least this. This network's confidences sit higher than
    /// MediaPipe's: its decision point is the default, and MediaPipe's 0.5 admits more false
    /// faces (`core/models/MODEL_CARD.md`, "Face check"). In a stream, a detection where a face
    /// was lost in the last 30 frames, and of its size, needs 0.8 / 0.95 of this.
    #[uniffi(default = 0.95)]
    pub min_face_presence_confidence: f32,
    /// Tracking (0..=1): a tracked face is kept while the landmark network's face confidence in
    /// its window is at least this; below it the face is detected again.
    #[uniffi(default = 0.5)]
    pub min_tracking_confidence: f32,
    /// Each face's `action_units` (MediaPipe's blendshapes' counterpart: the 3D face model's six
    /// animation units). Off, the fit skips their solves and the field is `None`.
    #[uniffi(default = true)]
    pub output_action_units: bool,
    /// Each face's `transform`: the 4×4 head-to-camera matrix.
    #[uniffi(default = true)]
    pub output_facial_transformation_matrixes: bool,
    /// Each face's `gestures` (off, `None`; the gesture heads share the networks that place the
    /// landmarks, so this saves only their decoding).
    #[uniffi(default = true)]
    pub output_gestures: bool,
    /// Each face's `gaze` and `point_of_gaze` (off, both `None`, the point-of-gaze stage is
    /// skipped and taps are refused).
    #[uniffi(default = true)]
    pub output_gaze: bool,
    /// The camera's intrinsics for the frames as passed in (the sensor's, before rotation and
    /// mirroring: `CameraIntrinsics`); `None`: `default_camera` of the upright image.
    #[uniffi(default = None)]
    pub camera: Option<CameraIntrinsics>,
    /// The networks to run (MediaPipe's `base_options` model asset): `None`, the ones built into
    /// the library; a `ModelBundle` a product trained itself (`core/models/train`).
    #[uniffi(default = None)]
    pub models: Option<Arc<ModelBundle>>,
    /// Settings MediaPipe has no word for.
    #[uniffi(default)]
    pub tuning: TrackerTuning,
}

impl Default for TrackerTuning {
    fn default() -> Self {
        let c = core_track::TrackerConfig::default();
        Self {
            min_face_size_px: DetectorConfig::default().min_face_px.round() as u32,
            min_match_score: c.min_ncc_score,
            search_margin: c.search_margin,
            flow_filter: c.flow_filter,
            gaze_filter: false,
            shape_frames: c.shape_frames as u32,
            mirror_average: None,
            ultra_light: false,
            quality: QualityThresholds::default(),
        }
    }
}

impl Default for FaceTrackerOptions {
    fn default() -> Self {
        let c = core_track::TrackerConfig::default();
        Self {
            running_mode: None,
            num_faces: c.max_faces as u32,
            min_face_detection_confidence: c.min_detection_score,
            min_face_presence_confidence: c.min_detection_confidence,
            min_tracking_confidence: c.min_face_confidence,
            output_action_units: true,
            output_facial_transformation_matrixes: true,
            output_gestures: true,
            output_gaze: true,
            camera: None,
            models: None,
            tuning: TrackerTuning::default(),
        }
    }
}

impl FaceTrackerOptions {
    /// The running mode, `None` read as MediaPipe's default.
    pub(crate) fn mode(&self) -> RunningMode {
        self.running_mode.unwrap_or(RunningMode::Image)
    }
}

/// The options' defaults, as the core defines them (equal to `FaceTrackerOptions()` in Kotlin and
/// Swift, whose literals the bindings' tests hold to this).
#[uniffi::export]
pub fn default_face_tracker_options() -> FaceTrackerOptions {
    FaceTrackerOptions::default()
}

/// The ultra-light mode's options for `running_mode`: `TrackerTuning.ultra_light` on, detections
/// accepted on the detector's score (presence 0), tracked windows kept while the gradient points'
/// mean confidence is at least 0.3; the rest as the defaults.
#[uniffi::export]
pub fn ultra_light_face_tracker_options(running_mode: RunningMode) -> FaceTrackerOptions {
    let c = core_track::TrackerConfig::ultra_light();
    FaceTrackerOptions {
        running_mode: Some(running_mode),
        min_face_presence_confidence: c.min_detection_confidence,
        min_tracking_confidence: c.min_face_confidence,
        tuning: TrackerTuning {
            ultra_light: true,
            ..TrackerTuning::default()
        },
        ..FaceTrackerOptions::default()
    }
}

/// Which optional outputs a tracker's faces carry (the options' toggles; the ultra-light mode has
/// no gestures, gaze or action units).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Outputs {
    pub(crate) gestures: bool,
    pub(crate) gaze: bool,
    pub(crate) action_units: bool,
    pub(crate) transform: bool,
}

impl From<&FaceTrackerOptions> for Outputs {
    fn from(o: &FaceTrackerOptions) -> Self {
        let m3 = !o.tuning.ultra_light;
        Self {
            gestures: o.output_gestures && m3,
            gaze: o.output_gaze && m3,
            action_units: o.output_action_units && m3,
            transform: o.output_facial_transformation_matrixes,
        }
    }
}

/// The embedded models' tracker for `options` (video tracking for both stream modes).
pub(crate) fn build_tracker(options: &FaceTrackerOptions) -> Result<Tracker, MonotrackError> {
    let (core, det) = to_core(options)?;
    let mut t = match &options.models {
        Some(bundle) => Tracker::with_bundle(core, det, &bundle.inner)?,
        None => Tracker::with_detector_config(core, det)?,
    };
    // The core's choice by mode unless the caller made one.
    if let Some(on) = options.tuning.mirror_average {
        t.estimator_mut().set_mirror_average(on);
    }
    t.set_gaze_config(GazeConfig {
        filter: options.tuning.gaze_filter.then(GazeFilter::default),
        ..GazeConfig::default()
    });
    Ok(t)
}

pub(crate) fn to_core(
    o: &FaceTrackerOptions,
) -> Result<(core_track::TrackerConfig, DetectorConfig), MonotrackError> {
    let t = &o.tuning;
    if !(16..=4096).contains(&t.min_face_size_px) {
        return Err(MonotrackError::InvalidConfig {
            msg: format!(
                "tuning.min_face_size_px must be 16..=4096, got {}",
                t.min_face_size_px
            ),
        });
    }
    let base = if t.ultra_light {
        core_track::TrackerConfig::ultra_light()
    } else {
        core_track::TrackerConfig::default()
    };
    let out = Outputs::from(o);
    let core = core_track::TrackerConfig {
        mode: match o.mode() {
            RunningMode::Image => core_track::Mode::Image,
            RunningMode::Video | RunningMode::LiveStream => core_track::Mode::Video,
        },
        max_faces: o.num_faces as usize,
        camera: o.camera.map(Intrinsics::from),
        flow_filter: t.flow_filter,
        shape_frames: t.shape_frames as usize,
        min_detection_score: o.min_face_detection_confidence,
        min_detection_confidence: o.min_face_presence_confidence,
        min_redetection_confidence: o.min_face_presence_confidence
            * (core_track::DEFAULT_MIN_REDETECTION_CONFIDENCE
                / core_track::DEFAULT_MIN_DETECTION_CONFIDENCE),
        min_face_confidence: o.min_tracking_confidence,
        min_ncc_score: t.min_match_score,
        search_margin: t.search_margin,
        gaze: out.gaze,
        quality: t.quality.into(),
        msbp: MsbpConfig {
            animation_units: out.action_units,
            ..MsbpConfig::default()
        },
        ..base
    };
    core.validate()?;
    let det = core_track::detector_config_for(
        &core,
        DetectorConfig {
            min_face_px: t.min_face_size_px as f32,
            ..DetectorConfig::default()
        },
    );
    Ok((core, det))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The uniffi literals (what Kotlin's and Swift's `FaceTrackerOptions()` hold) are the core's
    /// defaults: a core default that moves fails here until the literal follows.
    #[test]
    fn the_literal_defaults_are_the_cores() {
        let c = core_track::TrackerConfig::default();
        let o = FaceTrackerOptions::default();
        assert_eq!(o.num_faces, 1);
        assert_eq!(o.min_face_detection_confidence, 0.4);
        assert_eq!(o.min_face_presence_confidence, 0.95);
        assert_eq!(o.min_tracking_confidence, 0.5);
        assert_eq!(o.mode(), RunningMode::Image);
        assert_eq!(
            (c.min_detection_score, c.min_detection_confidence),
            (0.4, 0.95)
        );
        let t = o.tuning;
        assert_eq!(
            (t.min_face_size_px, t.min_match_score, t.search_margin),
            (24, 0.5, 0.5)
        );
        assert_eq!(t.shape_frames, 10);
        assert!(t.flow_filter && !t.gaze_filter && !t.ultra_light);
        let q = t.quality;
        assert_eq!(
            (
                q.dark_luma,
                q.overexposed_fraction,
                q.min_sharpness,
                q.blur_drop
            ),
            (40.0, 0.25, 0.08, 0.6)
        );
        assert_eq!(
            (
                q.min_face_px,
                q.max_outside_fraction,
                q.max_yaw_deg,
                q.max_pitch_deg
            ),
            (64.0, 0.1, 45.0, 30.0)
        );
        assert_eq!((q.min_face_probability, q.max_fit_residual), (0.7, 0.06));
        assert_eq!(QualityConfig::from(q), c.quality);
    }

    /// The stream bar follows the presence bar; the ultra-light options take the core's
    /// ultra-light thresholds and checks.
    #[test]
    fn the_redetection_bar_follows_the_presence_bar() {
        let (core, _) = to_core(&FaceTrackerOptions::default()).unwrap();
        assert_eq!(
            core.min_redetection_confidence,
            core_track::DEFAULT_MIN_REDETECTION_CONFIDENCE
        );
        let strict = FaceTrackerOptions {
            min_face_presence_confidence: 0.99,
            ..FaceTrackerOptions::default()
        };
        let (core, _) = to_core(&strict).unwrap();
        assert!(core.min_redetection_confidence > 0.8 && core.min_redetection_confidence < 0.99);
        let (core, _) = to_core(&ultra_light_face_tracker_options(RunningMode::Video)).unwrap();
        let want = core_track::TrackerConfig::ultra_light();
        assert_eq!(core.min_redetection_confidence, 0.0);
        assert_eq!(core.verify_interval, want.verify_interval);
        assert_eq!(core.landmarks, want.landmarks);
    }

    #[test]
    fn out_of_range_options_are_refused() {
        for bad in [
            FaceTrackerOptions {
                num_faces: 0,
                ..FaceTrackerOptions::default()
            },
            FaceTrackerOptions {
                min_tracking_confidence: f32::NAN,
                ..FaceTrackerOptions::default()
            },
            FaceTrackerOptions {
                tuning: TrackerTuning {
                    min_face_size_px: 8,
                    ..TrackerTuning::default()
                },
                ..FaceTrackerOptions::default()
            },
        ] {
            assert!(matches!(
                to_core(&bad),
                Err(MonotrackError::InvalidConfig { .. })
            ));
        }
    }
}
