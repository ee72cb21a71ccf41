//! The face-tracking pipeline (thesis 4.3.2–4.3.3, Algorithms 8 and 9): [`FaceTracker`].
//!
//! Per frame, for each tracked face (at most [`TrackerConfig::max_faces`]):
//! 1. **Region.** On the first frame, after a loss, or in [`Mode::Image`], the whole-frame
//!    [`RegionDetector`] runs. Otherwise the fitted model of the previous frame was projected to a
//!    face region and cut from the previous frame as a template; [`ncc::NccMatcher`] finds it in a
//!    search window around the old place at a reduced scale, and the found window is validated by
//!    [`LandmarkEstimator::face_confidence`] (M3 level 1's face classifier). A failed match or
//!    validation ends the track; the detector then runs on the *next* frame as in the thesis, or on
//!    the same frame with [`TrackerConfig::redetect_immediately`].
//! 2. **Landmarks** by the [`LandmarkEstimator`] (M3) on the region.
//! 3. **Optical-flow filter** ([`flow::FlowFilter`], Alg. 8) on the 68 points when tracking.
//! 4. **3D fit** by MSBP, from the previous frame's fit when tracking. The shape units are fitted
//!    freely over the first [`TrackerConfig::shape_frames`] frames of a track, then held at their
//!    per-unit median ([`ShapeAccumulator`]); a new track re-estimates them.
//!
//! The region handed to the landmark estimator keeps the detector's box convention: when a track
//! starts, the offset and scale between the detector's box and the bounding box of the projected
//! model are recorded, and every tracked region (a projected-model box moved by NCC) is mapped back
//! through them. Whatever convention M3 was trained on, tracking feeds it the same kind of box.
//!
//! Everything per frame lives in buffers held by the tracker; after the first frames nothing is
//! allocated (the result's face list keeps its capacity).

pub mod flow;
pub mod live;
pub mod models;
pub mod ncc;
pub mod quality;

pub use models::{GradientLandmarks, Landmarker, ModelDetector, Tracker, detector_config_for};

use crate::camera::Intrinsics;
use crate::error::{Error, Result};
use crate::fit::{FaceFit, Ffbp, FfbpConfig, Msbp, MsbpConfig, ShapeAccumulator};
use crate::gaze::{
    GazeCalibration, GazeConfig, GazeRay, PointOfGaze, Target, eye_openness,
    point_of_gaze_from_rays, raw_eye_rays,
};
use crate::image::{Frame, FrameDesc, GrayImage, Rect};
use crate::landmarks::warp::{Affine, sample};
use crate::landmarks::{FaceLandmarks, N_POINTS};
use crate::math::Libm;
use crate::model::{FaceModel, N_LANDMARKS};
use flow::{FlowFilter, LkConfig, Pyramid};
use nalgebra::Vector3;
use ncc::NccMatcher;
use quality::{
    FaceEvidence, FaceQuality, QualityConfig, QualityReasons, SharpnessHistory, face_quality,
    frame_reasons,
};
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Most faces a tracker may be configured for (each face costs landmarks + fit per frame).
pub const MAX_FACES_LIMIT: usize = 16;

/// Default [`TrackerConfig::min_detection_score`]: detector candidates down to this go to M3's
/// face check ([`check_detections`]). With [`DEFAULT_MIN_DETECTION_CONFIDENCE`] and the detector's
/// default min face it is the operating point with the fewest false positives; a lower score finds
/// hardly more faces for more false positives and face checks
/// (`models/train/detector/eval_peers.py`; figures: `models/MODEL_CARD.md`, "Face detector"; how
/// the point was chosen: `models/train/RESEARCH_LOG.md`, "Face detector").
pub const DEFAULT_MIN_DETECTION_SCORE: f32 = 0.4;

/// The small-faces operating point: detector min face (pixels) at which the SDK's detection
/// ([`check_detections`] with [`SMALL_FACES_MIN_DETECTION_SCORE`] and
/// [`DEFAULT_MIN_DETECTION_CONFIDENCE`]) also finds the 17–23 px faces of group photos, which the
/// default min face skips, at more false positives per image (`models/MODEL_CARD.md`, "Face
/// detector"; `models/train/RESEARCH_LOG.md`, "Face detector"). A 640×480 frame runs at 400×300,
/// and more candidates get face checks, so the whole detection takes longer (BENCHMARKS.md, "Face
/// detector"). The defaults keep the point with fewer false positives and less clutter;
/// `monotrack landmarks --small-faces` detects at this one. Apps choose it through
/// `DetectorConfig::min_face_px` and [`TrackerConfig::min_detection_score`].
pub const SMALL_FACES_MIN_FACE_PX: f32 = 16.0;

/// The detector score of the small-faces operating point (see [`SMALL_FACES_MIN_FACE_PX`]).
pub const SMALL_FACES_MIN_DETECTION_SCORE: f32 = 0.25;

/// Default [`TrackerConfig::min_detection_confidence`] (see [`DEFAULT_MIN_DETECTION_SCORE`]).
pub const DEFAULT_MIN_DETECTION_CONFIDENCE: f32 = 0.95;

/// Default [`TrackerConfig::min_redetection_confidence`]: a lost face's place and size are
/// evidence for a detection that matches them, so it needs less of the classifier than a guess
/// anywhere in the frame. On `track_eval --roll 35 --scale 0.35 --brightness 0.3 --blur
/// --translation 100 --period 20 --segments 30` a small, heavily blurred face whose detections
/// scored below a new face's bar went unfound for frames at that bar and is found at once at this
/// one (`models/train/RESEARCH_LOG.md`, "Tracking"); tracked windows keep 0.5.
pub const DEFAULT_MIN_REDETECTION_CONFIDENCE: f32 = 0.8;

/// Face width (pixels) at which the flow threshold applies unscaled: the thesis' 5 px were set on
/// 640×480 video of a user at arm's length, where the 68-point box spans about 200 px. The
/// threshold scales with the face's box size relative to this.
pub const FLOW_REFERENCE_FACE_PX: f32 = 200.0;

/// Default [`TrackerConfig::flow_pull`]. On `track_eval`'s clips with the light swinging ±30 %
/// (a phone's exposure) the thesis' filter (0) made landmarks less accurate than no filter at all:
/// a point kept on its flow keeps any error it once had. With 0.25 the filter is as accurate as
/// no filter there and steadier, and keeps most of the thesis' jitter cut on steadily lit still
/// faces (BENCHMARKS.md, "Tracking").
pub const DEFAULT_FLOW_PULL: f32 = 0.25;

/// Whole-frame face detection (`core::detect`'s detector implements it).
pub trait RegionDetector {
    /// Appends the faces found in `image` to `out` (cleared first by the callee) as (box, score in
    /// 0..1), any order. Boxes follow the detector's own convention; the tracker preserves it.
    ///
    /// # Errors
    /// Whatever the detector reports (model failures); "no face" is an empty `out`, not an error.
    fn detect(&mut self, image: &GrayImage, out: &mut Vec<(Rect, f32)>) -> Result<()>;
}

/// Landmarks and face validation on one face region (`core::landmarks`' M3 implements it).
pub trait LandmarkEstimator {
    /// Fills `out` with the 68 landmarks (image pixels), yaw, face probability, gestures and gaze
    /// of the face in `face`.
    ///
    /// # Errors
    /// Whatever the estimator reports (model failures, a box it cannot use).
    fn estimate(&mut self, image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()>;

    /// Probability (0..1) that `face` holds a face — the cheap check the tracker runs on the window
    /// NCC found and on each detection (M3 level 1's face confidence). Whatever the check computes
    /// on the way (M3: the level-1 points and yaw) may be left in `out` for [`Self::complete`].
    ///
    /// # Errors
    /// Whatever the estimator reports.
    fn face_confidence(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        out: &mut FaceLandmarks,
    ) -> Result<f32>;

    /// [`Self::face_confidence`] for a face expected turned in roll by `roll` (radians, image y
    /// down: the eye line's angle), as a tracked face is. The default ignores `roll`.
    ///
    /// # Errors
    /// Whatever the estimator reports.
    fn face_confidence_turned(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        roll: f32,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        let _ = roll;
        self.face_confidence(image, face, out)
    }

    /// Finishes `out` for the same `image` and `face` that [`Self::face_confidence`] just filled
    /// it for, reusing that work (M3: level 2 only). The default runs [`Self::estimate`].
    ///
    /// # Errors
    /// Whatever the estimator reports.
    fn complete(&mut self, image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        self.estimate(image, face, out)
    }

    /// The face's box in the detector's convention, estimated from what
    /// [`Self::face_confidence`] just left in `out` (M3: [`crate::landmarks::M3::level1_box`]).
    /// The detection cascade ([`check_detections`]) checks a detection again on it. The default,
    /// `None`, keeps the detector's box.
    fn face_box(&self, out: &FaceLandmarks) -> Option<Rect> {
        let _ = out;
        None
    }
}

/// A detection whose face check on the detector's box is below this is rejected without the
/// second check on [`LandmarkEstimator::face_box`]: on the faces68 validation split the cascade
/// finds the same faces with or without this gate, while many of the candidates score below it
/// and skip their second run (`models/train/RESEARCH_LOG.md`, "Face detector").
pub const MIN_CONFIDENCE_TO_REFINE: f32 = 0.2;

/// Two accepted detections overlapping by more than this are one face (the better-ranked one
/// stays): re-boxed on the face, two candidates of one face can land on nearly the same box. The
/// detector's own NMS default.
pub const CASCADE_NMS_IOU: f32 = 0.4;

/// The SDK's detection cascade: every candidate in `candidates` (box, detector score) gets
/// `estimator`'s face check ([`LandmarkEstimator::face_confidence`]). Where the estimator gives a
/// box of its own for the face ([`LandmarkEstimator::face_box`]) and the first check reaches
/// [`MIN_CONFIDENCE_TO_REFINE`], the face is checked again on that box, which becomes the
/// detection's box: the compact detector's boxes of small faces are too small and off-centre, which
/// costs both the face check and the box's overlap with the face (on the faces68 validation split,
/// `models/train/RESEARCH_LOG.md`, "Face detector"). Detections whose (last) check reaches
/// `min_confidence` go to `out` as
/// (box, detector score, face confidence, what the check left for
/// [`LandmarkEstimator::complete`]), ranked by detector score × confidence (the compact detector
/// scores some face-like clutter and oversized boxes above the real face, and the confidence alone
/// saturates near 1 on small clutter, so neither ranks well alone), with those overlapping a
/// better-ranked one by more than [`CASCADE_NMS_IOU`] dropped. `candidates` is sorted by score
/// (best first) on the way, so equal products keep the detector's order; `scratch` is working
/// space. Allocates only when `out` must grow.
///
/// # Errors
/// Whatever the estimator reports.
pub fn check_detections<L: LandmarkEstimator>(
    estimator: &mut L,
    image: &GrayImage,
    candidates: &mut [(Rect, f32)],
    min_confidence: f32,
    scratch: &mut FaceLandmarks,
    out: &mut Vec<(Rect, f32, f32, FaceLandmarks)>,
) -> Result<()> {
    check_detections_by(
        estimator,
        image,
        candidates,
        |_, conf| conf >= min_confidence,
        scratch,
        out,
    )
}

/// [`check_detections`] with the acceptance decided by `accept(box, confidence)` (the box the
/// last check ran on), before the overlaps are merged.
fn check_detections_by<L: LandmarkEstimator>(
    estimator: &mut L,
    image: &GrayImage,
    candidates: &mut [(Rect, f32)],
    accept: impl Fn(&Rect, f32) -> bool,
    scratch: &mut FaceLandmarks,
    out: &mut Vec<(Rect, f32, f32, FaceLandmarks)>,
) -> Result<()> {
    out.clear();
    candidates.sort_by(|a, b| b.1.total_cmp(&a.1));
    for &(rect, score) in candidates.iter() {
        let mut rect = rect;
        let mut conf = estimator.face_confidence(image, &rect, scratch)?;
        if conf >= MIN_CONFIDENCE_TO_REFINE
            && let Some(better) = estimator.face_box(scratch)
        {
            rect = better;
            conf = estimator.face_confidence(image, &rect, scratch)?;
        }
        if accept(&rect, conf) {
            out.push((rect, score, conf, *scratch));
        }
    }
    out.sort_by(|a, b| (b.1 * b.2).total_cmp(&(a.1 * a.2)));
    let mut k = 0;
    while k < out.len() {
        let rect = out[k].0;
        let mut j = k + 1;
        while j < out.len() {
            if out[j].0.iou(&rect) > CASCADE_NMS_IOU {
                out.remove(j);
            } else {
                j += 1;
            }
        }
        k += 1;
    }
    Ok(())
}

/// Processing mode (MediaPipe-like).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Mode {
    /// Independent images: detect on every call, no temporal state but stable ids by overlap.
    Image,
    /// A video stream: detect once, then track; timestamps must strictly increase.
    #[default]
    Video,
}

/// Which landmark estimator and fit the shipped tracker runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum LandmarkMode {
    /// M3's networks and the MSBP fit.
    #[default]
    M3,
    /// The ultra-light mode: the learning-free gradient detector (32 points, no landmark network
    /// loaded) and the weak-perspective FFBP fit weighted by the points' confidences. No gestures
    /// or gaze, and no face classifier (`models::GradientLandmarks`).
    Gradient,
}

/// Tracker settings. Every field has a default (`#[serde(default)]`), so a JSON object with only
/// the fields to change is a valid config.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrackerConfig {
    /// Image or video mode.
    pub mode: Mode,
    /// Most faces tracked at once (1..=[`MAX_FACES_LIMIT`]). When a detector run finds more
    /// accepted faces than free slots, those with the highest detector score × face confidence
    /// take them.
    pub max_faces: usize,
    /// Camera intrinsics, pixels, of the frames as they are passed in: for
    /// [`FaceTracker::process_frame`], the sensor's, for the buffer as delivered (what Camera2's
    /// `LENS_INTRINSIC_CALIBRATION` and `AVCameraCalibrationData` give, scaled to the buffer): the
    /// tracker turns and mirrors them with the frame ([`Intrinsics::for_upright`]); for
    /// [`FaceTracker::process`], the upright image's. `None` = the CONTRACT default for the upright
    /// image's size (a field of view, so no turn is needed).
    pub camera: Option<Intrinsics>,
    /// Detections scoring below this are ignored. The detector proposes, M3's face check decides
    /// ([`Self::min_detection_confidence`]), so this sits below the detector's standalone operating
    /// point to keep small faces: with [`Self::min_detection_confidence`] it is the cascade's
    /// operating point chosen on the faces68 validation split (`models/train/RESEARCH_LOG.md`,
    /// "Face detector"; figures: `models/MODEL_CARD.md`, "Face detector").
    /// [`crate::track::Tracker::with_default_models`] runs the detector at this threshold.
    pub min_detection_score: f32,
    /// A new detection is accepted when M3's face confidence on its box is at least this. Stricter
    /// than [`Self::min_face_confidence`]: a detection is a guess anywhere in the frame, a tracked
    /// window is where the face just was. Nearly all jittered validation faces reach the default
    /// while few of the detector's false positives do (`models/train/eval_face_check.py`;
    /// `models/MODEL_CARD.md`, "Face check").
    pub min_detection_confidence: f32,
    /// In video mode, for the frames a lost face is searched for ([`FaceTracker`]'s lost-face
    /// search), a detection near its last place and of about its size is accepted at this face
    /// confidence instead of [`Self::min_detection_confidence`]. Default
    /// [`DEFAULT_MIN_REDETECTION_CONFIDENCE`]; set it to `min_detection_confidence` for one bar.
    pub min_redetection_confidence: f32,
    /// A tracked window whose face confidence is below this is a loss. 0.5: the classifier's
    /// decision point (M3 level 1 is trained with a balanced face / non-face loss).
    pub min_face_confidence: f32,
    /// An NCC peak below this is a loss without asking the classifier. Consecutive frames of a
    /// tracked face score far above it in our synthetic sequences; 0.5 only rejects clearly wrong
    /// matches.
    pub min_ncc_score: f32,
    /// Search window margin around the previous region, as a fraction of the region's larger side,
    /// each direction. 0.5 follows a face moving half its width per frame.
    pub search_margin: f32,
    /// Larger side (pixels) of the NCC template after decimation: the reduced scale. 32 keeps the
    /// search cheap whatever the face size (BENCHMARKS.md, "The tracker's own checks and
    /// kernels").
    pub ncc_template_px: usize,
    /// Optical-flow filter on or off.
    pub flow_filter: bool,
    /// The filter's threshold for a face of [`FLOW_REFERENCE_FACE_PX`] (thesis: 5 px); scaled by
    /// face size.
    pub flow_threshold_px: f32,
    /// Least fraction by which a point the filter takes from the flow moves towards this frame's
    /// landmark (more when the two are farther apart: (distance / threshold)²); 0 is the thesis'
    /// filter, which keeps the flow whole ([`FlowFilter::apply`]). Default [`DEFAULT_FLOW_PULL`].
    pub flow_pull: f32,
    /// Lucas–Kanade settings of the filter.
    pub lk: LkConfig,
    /// Frames at the start of a track over which shape units are estimated before being held.
    pub shape_frames: usize,
    /// MSBP rounds on a tracking frame (from the previous fit; 1 is enough, `benches/fit.rs`).
    pub tracking_fit_rounds: u32,
    /// MSBP settings for a face's first frame (and every face in image mode).
    pub msbp: MsbpConfig,
    /// Intersection over union above which a detection is the same face as a track.
    pub match_iou: f32,
    /// In video mode with fewer faces than `max_faces`, run the detector every this many frames to
    /// pick up new faces (0 = only when no face is tracked).
    pub new_face_interval: u32,
    /// In video mode, run the detector every this many frames while faces are tracked and hand
    /// each track the box of the detection on it, ending a track no detection overlaps when the
    /// detector found a face elsewhere (0 = never). For face checks too weak to end a track that
    /// has drifted off its face, and templates that keep their size: the ultra-light mode's
    /// ([`TrackerConfig::ultra_light`]).
    pub verify_interval: u32,
    /// Re-detect in the same frame when tracking fails (`false`: in the next frame, as the thesis
    /// does because its detector was too slow to run again in the frame that lost the face).
    /// Default `true`: our detector is cheap enough for that (BENCHMARKS.md, "Face detector"), and
    /// re-detecting at once keeps the frame where a face reappears elsewhere (more correct frames
    /// on the synthetic sequences of `track_eval`).
    pub redetect_immediately: bool,
    /// The landmark estimator and fit of [`crate::track::Tracker`] (and the fit of any
    /// [`FaceTracker`]): M3 with MSBP, or the ultra-light gradient detector with FFBP.
    pub landmarks: LandmarkMode,
    /// Whether the point-of-gaze stage runs (default on): each face's gaze ray from between its
    /// eyes, the tap calibration's correction and the targets it lands on. Off,
    /// [`TrackedFace::gaze`] is `None` and taps are refused. M3's per-eye directions
    /// ([`FaceLandmarks`]) come from the eye networks, which the eye landmarks need anyway.
    pub gaze: bool,
    /// The thresholds of the quality reasons ([`TrackedFace::quality`],
    /// [`TrackingResult::reasons`]).
    pub quality: QualityConfig,
}

impl TrackerConfig {
    /// The face confidence a detection where a face was just lost needs: the re-detection bar,
    /// never stricter than a new face's.
    fn redetection_bar(&self) -> f32 {
        self.min_detection_confidence
            .min(self.min_redetection_confidence)
    }

    /// The ultra-light mode's settings: [`LandmarkMode::Gradient`], a detection accepted on the
    /// detector's score alone (the gradient points' mean confidence is no face classifier), and a
    /// tracked window kept while that confidence is at least 0.3 (most faces68 validation faces on
    /// their boxes pass it, fewer windows away from them; `models/train/RESEARCH_LOG.md`,
    /// "Gradient landmark detector").
    pub fn ultra_light() -> Self {
        Self {
            landmarks: LandmarkMode::Gradient,
            min_detection_confidence: 0.0,
            min_redetection_confidence: 0.0,
            min_face_confidence: 0.3,
            verify_interval: ULTRA_LIGHT_VERIFY_INTERVAL,
            ..Self::default()
        }
    }
}

/// The intrinsics of `frame`'s upright image that the tracker works with: `camera` (the
/// sensor's, for the buffer as delivered) turned and mirrored with the frame, or
/// [`Intrinsics::default_for`] the upright size when none are given. What an overlay projects
/// the pose and vertices with.
///
/// # Errors
/// [`Error::InvalidCamera`] for a zero-size frame.
pub fn upright_intrinsics(camera: Option<Intrinsics>, frame: &FrameDesc) -> Result<Intrinsics> {
    match camera {
        Some(k) => Ok(k.for_upright(frame.width, frame.height, frame.rotation, frame.mirrored)),
        None => {
            let (w, h) = frame.upright_size();
            Intrinsics::default_for(w as u32, h as u32)
        }
    }
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            mode: Mode::Video,
            max_faces: 1,
            camera: None,
            min_detection_score: DEFAULT_MIN_DETECTION_SCORE,
            min_detection_confidence: DEFAULT_MIN_DETECTION_CONFIDENCE,
            min_redetection_confidence: DEFAULT_MIN_REDETECTION_CONFIDENCE,
            min_face_confidence: 0.5,
            min_ncc_score: 0.5,
            search_margin: 0.5,
            ncc_template_px: 32,
            flow_filter: true,
            flow_threshold_px: 5.0,
            flow_pull: DEFAULT_FLOW_PULL,
            lk: LkConfig::default(),
            shape_frames: 10,
            tracking_fit_rounds: 1,
            msbp: MsbpConfig::default(),
            match_iou: 0.3,
            new_face_interval: 15,
            verify_interval: 0,
            redetect_immediately: true,
            landmarks: LandmarkMode::M3,
            gaze: true,
            quality: QualityConfig::default(),
        }
    }
}

fn unit_interval(name: &str, v: f32) -> Result<()> {
    if v.is_finite() && (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(Error::InvalidConfig(format!(
            "{name} must be in 0..=1, got {v}"
        )))
    }
}

impl TrackerConfig {
    /// Checks every field's range.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] naming the first bad field (or [`Error::InvalidCamera`] for bad
    /// intrinsics).
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_FACES_LIMIT).contains(&self.max_faces) {
            return Err(Error::InvalidConfig(format!(
                "max_faces must be 1..={MAX_FACES_LIMIT}, got {}",
                self.max_faces
            )));
        }
        if let Some(c) = &self.camera {
            c.validate()?;
        }
        unit_interval("min_detection_score", self.min_detection_score)?;
        unit_interval("min_detection_confidence", self.min_detection_confidence)?;
        unit_interval(
            "min_redetection_confidence",
            self.min_redetection_confidence,
        )?;
        unit_interval("min_face_confidence", self.min_face_confidence)?;
        unit_interval("match_iou", self.match_iou)?;
        if !(self.min_ncc_score.is_finite() && (-1.0..=1.0).contains(&self.min_ncc_score)) {
            return Err(Error::InvalidConfig(format!(
                "min_ncc_score must be in -1..=1, got {}",
                self.min_ncc_score
            )));
        }
        if !(self.search_margin.is_finite()
            && self.search_margin > 0.0
            && self.search_margin <= 4.0)
        {
            return Err(Error::InvalidConfig(format!(
                "search_margin must be in (0, 4], got {}",
                self.search_margin
            )));
        }
        if !(8..=256).contains(&self.ncc_template_px) {
            return Err(Error::InvalidConfig(format!(
                "ncc_template_px must be 8..=256, got {}",
                self.ncc_template_px
            )));
        }
        if !(self.flow_threshold_px.is_finite() && self.flow_threshold_px >= 0.0) {
            return Err(Error::InvalidConfig(format!(
                "flow_threshold_px must be finite and >= 0, got {}",
                self.flow_threshold_px
            )));
        }
        if !(0.0..=1.0).contains(&self.flow_pull) {
            return Err(Error::InvalidConfig(format!(
                "flow_pull must be in 0..=1, got {}",
                self.flow_pull
            )));
        }
        self.lk.validate()?;
        self.quality.validate()?;
        if !(1..=1000).contains(&self.shape_frames) {
            return Err(Error::InvalidConfig(format!(
                "shape_frames must be 1..=1000, got {}",
                self.shape_frames
            )));
        }
        if !(1..=10).contains(&self.tracking_fit_rounds) {
            return Err(Error::InvalidConfig(format!(
                "tracking_fit_rounds must be 1..=10, got {}",
                self.tracking_fit_rounds
            )));
        }
        let m = &self.msbp;
        if !(m.z_near_mm.is_finite()
            && m.z_far_mm.is_finite()
            && m.z_near_mm > 0.0
            && m.z_far_mm > m.z_near_mm
            && m.xy_range_mm.is_finite()
            && m.xy_range_mm > 0.0
            && m.outer_iterations >= 1
            && m.shape_prior.is_finite()
            && m.shape_prior >= 0.0
            && m.animation_prior.is_finite()
            && m.animation_prior >= 0.0
            && m.yaw_seeds_deg.iter().all(|v| v.is_finite()))
        {
            return Err(Error::InvalidConfig(format!(
                "msbp settings out of range: {m:?}"
            )));
        }
        Ok(())
    }
}

/// How a face's region was found this frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FaceState {
    /// By the whole-frame detector.
    Detected,
    /// By the NCC tracker from the previous frame.
    Tracked,
}

/// What a frame's faces were, as a whole (CONTRACT's `state`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FrameState {
    /// At least one face came from the detector this frame.
    Detected,
    /// Every face was tracked.
    Tracked,
    /// No face.
    Lost,
}

/// Per-stage wall time of one frame, microseconds (all faces together).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct StageTimings {
    /// Frame → upright luma (only for [`FaceTracker::process_frame`]).
    pub image_us: u64,
    /// Region: detector, or NCC search + face validation.
    pub region_us: u64,
    /// Of `region_us`, the detector's share (0 on pure tracking frames).
    pub detect_us: u64,
    /// Landmark estimation.
    pub landmarks_us: u64,
    /// Pyramid + Lucas–Kanade + filter.
    pub flow_us: u64,
    /// MSBP (+ projecting the model for the next region).
    pub fit_us: u64,
    /// Point of gaze (eye rays, calibration, targets).
    pub gaze_us: u64,
    /// The whole call.
    pub total_us: u64,
}

/// One face of a [`TrackingResult`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackedFace {
    /// Stable id: the same while a track lasts, new for every new track.
    pub id: u64,
    /// The region the landmarks were estimated on (detector box convention), pixels.
    pub rect: Rect,
    /// Detector score on a detection frame, face confidence of the window on a tracked frame.
    pub score: f32,
    /// How the region was found.
    pub state: FaceState,
    /// Landmarks (68 points after the flow filter), yaw, face probability, gestures, gaze.
    pub landmarks: FaceLandmarks,
    /// The 3D fit: pose (R, t in mm; Euler via [`crate::fit::Pose::euler_deg`]), shape units,
    /// animation units and the fit report (RMS reprojection error).
    pub fit: FaceFit,
    /// Whether the shape units are held (estimated over the track's first frames).
    pub shape_held: bool,
    /// Landmarks that came from the optical flow rather than the detection this frame.
    pub flow_points: u32,
    /// Where the face looks: the gaze ray from between its eyes (corrected by the tap
    /// calibration), its source and confidence, and the target it lands on when targets are set
    /// ([`FaceTracker::set_gaze_targets`]). `None` when [`TrackerConfig::gaze`] is off.
    pub gaze: Option<PointOfGaze>,
    /// How far to trust this face, and why not more ([`quality`]).
    pub quality: FaceQuality,
}

/// The result of one [`FaceTracker::process`] call; owned by the tracker and refilled each call.
#[derive(Debug, Clone, Default)]
pub struct TrackingResult {
    /// The caller's timestamp, nanoseconds.
    pub timestamp_ns: i64,
    /// 0-based count of processed frames.
    pub frame_index: u64,
    /// The faces, in slot order (stable while tracks last).
    pub faces: Vec<TrackedFace>,
    /// Whether the whole-frame detector ran on this frame.
    pub detector_ran: bool,
    /// The frame's own quality reasons: its light and sharpness, no face, a face lost
    /// ([`quality::frame_reasons`]).
    pub reasons: QualityReasons,
    /// Per-stage timings.
    pub timings: StageTimings,
}

impl TrackingResult {
    /// Detected / tracked / lost, as CONTRACT's `state`.
    pub fn state(&self) -> FrameState {
        if self.faces.is_empty() {
            FrameState::Lost
        } else if self.faces.iter().any(|f| f.state == FaceState::Detected) {
            FrameState::Detected
        } else {
            FrameState::Tracked
        }
    }
}

/// The detector box relative to the projected-model box at the start of a track: centre offset in
/// units of the model box's size, and size ratios.
#[derive(Debug, Clone, Copy, PartialEq)]
struct BoxCalib {
    dx: f32,
    dy: f32,
    sx: f32,
    sy: f32,
}

impl BoxCalib {
    const IDENTITY: Self = Self {
        dx: 0.0,
        dy: 0.0,
        sx: 1.0,
        sy: 1.0,
    };

    fn between(model_box: &Rect, det_box: &Rect) -> Self {
        if !(model_box.is_valid() && det_box.is_valid()) {
            return Self::IDENTITY;
        }
        let (mc, dc) = (model_box.center(), det_box.center());
        Self {
            dx: (dc[0] - mc[0]) / model_box.w,
            dy: (dc[1] - mc[1]) / model_box.h,
            sx: det_box.w / model_box.w,
            sy: det_box.h / model_box.h,
        }
    }

    fn apply(&self, model_box: &Rect) -> Rect {
        let c = model_box.center();
        let (w, h) = (model_box.w * self.sx, model_box.h * self.sy);
        let (cx, cy) = (c[0] + self.dx * model_box.w, c[1] + self.dy * model_box.h);
        Rect::new(cx - 0.5 * w, cy - 0.5 * h, w, h)
    }
}

/// One face's track state and buffers.
#[derive(Debug, Clone)]
struct Slot {
    active: bool,
    /// Seen in this frame (image mode: matched by a detection).
    seen: bool,
    id: u64,
    state: FaceState,
    score: f32,
    /// Region for the landmark estimator this frame.
    rect: Rect,
    /// Bounding box of the projected fitted model, previous frame (the NCC template's region).
    model_box: Rect,
    calib: BoxCalib,
    /// Whether the calibration is still to be taken from this frame's fit.
    calib_pending: bool,
    landmarks: FaceLandmarks,
    /// `landmarks` holds the face check's output for `rect` on this frame.
    level1_ready: bool,
    fit: Option<FaceFit>,
    ncc: NccMatcher,
    filter: FlowFilter,
    flow_points: u32,
    shape_acc: ShapeAccumulator,
    msbp_init: Msbp,
    msbp_track: Msbp,
    ffbp: Ffbp,
    /// The last frame's gaze direction, for the optional gaze filter.
    gaze_dir: Option<Vector3<f64>>,
    /// This frame's quality, and the track's recent sharpness it is judged against.
    quality: FaceQuality,
    sharpness: SharpnessHistory,
}

impl Slot {
    fn new(cfg: &TrackerConfig) -> Result<Self> {
        Ok(Self {
            active: false,
            seen: false,
            id: 0,
            state: FaceState::Detected,
            score: 0.0,
            rect: Rect::default(),
            model_box: Rect::default(),
            calib: BoxCalib::IDENTITY,
            calib_pending: true,
            landmarks: FaceLandmarks::default(),
            level1_ready: false,
            fit: None,
            ncc: NccMatcher::new(cfg.ncc_template_px),
            filter: FlowFilter::new(cfg.lk)?,
            flow_points: 0,
            shape_acc: ShapeAccumulator::new(cfg.shape_frames),
            msbp_init: Msbp::new(cfg.msbp),
            msbp_track: Msbp::new(MsbpConfig {
                outer_iterations: cfg.tracking_fit_rounds,
                ..cfg.msbp
            }),
            ffbp: Ffbp::new(FfbpConfig::default()),
            gaze_dir: None,
            quality: FaceQuality::default(),
            sharpness: SharpnessHistory::default(),
        })
    }

    /// Starts a new track on a detection.
    fn start(&mut self, id: u64, rect: Rect, score: f32) {
        self.active = true;
        self.level1_ready = false;
        self.seen = true;
        self.id = id;
        self.state = FaceState::Detected;
        self.score = score;
        self.rect = rect;
        self.calib = BoxCalib::IDENTITY;
        self.calib_pending = true;
        self.fit = None;
        self.ncc.clear();
        self.filter.reset();
        self.shape_acc.clear();
        self.msbp_init.set_fixed_shape(None);
        self.msbp_track.set_fixed_shape(None);
        self.sharpness.reset();
    }

    fn end(&mut self) {
        self.active = false;
        self.level1_ready = false;
        self.seen = false;
        self.fit = None;
        self.ncc.clear();
        self.filter.reset();
        self.gaze_dir = None;
    }
}

/// [`TrackerConfig::verify_interval`] in the ultra-light mode. Its tracked windows are checked by
/// the gradient points' mean confidence, which passes windows off the face, and its template
/// keeps its size. On `track_eval --ultra-light --segments 30` (three scale amplitudes) every
/// tenth frame matched re-detecting every frame at the smaller amplitudes, and stayed a little
/// behind it at the largest, at a fraction of its time; checking more often was no better for
/// more time, less often lost correct frames at the largest amplitude (BENCHMARKS.md and
/// `models/train/RESEARCH_LOG.md`, "Ultra-light mode on the same clips").
pub const ULTRA_LIGHT_VERIFY_INTERVAL: u32 = 10;

/// A face whose track ended on a loss, kept for [`LOST_FRAMES`] frames: the upright detector
/// misses faces turned in roll beyond about 25°, which a fast head often is when its track
/// breaks. While it finds nothing, a window around the face's last place, turned by its last
/// roll and by ±30° from it (one turn per frame), is searched too; after
/// [`LOST_WINDOW_ONLY_FRAMES`], every other frame searches the whole frame turned instead.
#[derive(Debug, Clone, Copy)]
struct LostFace {
    /// Centre of the last region, pixels.
    centre: [f32; 2],
    /// Larger side of the last region, pixels.
    size: f32,
    /// The face's roll then (eye line, radians, image y down).
    roll: f32,
    /// Frames since the loss.
    frames: u32,
}

impl LostFace {
    /// Whether `r` could be this face now: its centre within [`LOST_NEAR_FACES`] face sizes of the
    /// last place, plus [`LOST_DRIFT_FACES`] for each frame since, and its size within a factor
    /// of 2 of the last.
    fn near(&self, r: &Rect) -> bool {
        let [cx, cy] = r.center();
        let reach = (LOST_NEAR_FACES + LOST_DRIFT_FACES * self.frames as f32) * self.size;
        let ratio = r.w.max(r.h) / self.size;
        (cx - self.centre[0]).mhypot(cy - self.centre[1]) <= reach && (0.5..=2.0).contains(&ratio)
    }
}

/// Frames a lost face is looked for turned.
const LOST_FRAMES: u32 = 30;

/// Reach of [`LostFace::near`] at the loss, face sizes: half the turned window's side.
const LOST_NEAR_FACES: f32 = 0.5 * TURNED_WINDOW_FACES;

/// Growth of that reach per frame since the loss, face sizes: a face moving a quarter of its size
/// a frame (fast: 25 px a frame for a 100 px face).
const LOST_DRIFT_FACES: f32 = 0.25;

/// Frames after a loss that search only the window around the face's last place (one round of
/// its three turns): a face lost to fast motion is still near it. Past them the face may be
/// anywhere (it left and came back, or the scene cut), so every other frame searches the whole
/// frame turned ([`WHOLE_FRAME_TURNS_DEG`]) as when nothing is tracked. With the window alone a
/// head held at 40–55° that appeared elsewhere went unfound until the loss expired
/// (`track_eval --roll-offset 40 --roll 5`); with more window-only frames fewer of those faces
/// were found, and with none more faces lost to fast motion went unfound on the blur-and-light
/// clip (`models/train/RESEARCH_LOG.md`, "Tracking"). A frame costs at most what a frame with
/// nothing tracked costs (the upright pass plus the whole-frame turn).
const LOST_WINDOW_ONLY_FRAMES: u32 = 3;

/// Side of the turned window in face sizes (the face may have moved about a face size).
const TURNED_WINDOW_FACES: f32 = 3.0;

/// Pixels a face spans in the turned window: enough for the face check, a quarter of a VGA
/// frame's detector work for the window.
const TURNED_FACE_PX: f32 = 96.0;

/// A tracked face turned in roll by at least this (its last frame's eye line) is checked, and its
/// level-1 points read, on a crop turned by that roll ([`LandmarkEstimator::face_confidence_turned`]):
/// level 1 reads faces within about ±25° of upright, and its face check fails first on fast, blurred
/// frames of tilted heads, which ends their tracks. Below it the crop stays upright, as a
/// detection's is.
const TURNED_CHECK_FROM: f32 = 15.0 * std::f32::consts::PI / 180.0;

/// Past this the last roll is taken for a misread (a face read upside down, whose turned crop
/// would read it upside down again frame after frame) and the check stays upright: on the
/// portable path a track started on such a reading held it, far off the face, for many frames of
/// the 40° clip (`models/train/RESEARCH_LOG.md`, "Tracking").
const TURNED_CHECK_TO: f32 = 75.0 * std::f32::consts::PI / 180.0;

/// Turns within this of upright are left to the upright detector, which covers them.
const UPRIGHT_COVERS: f32 = 15.0 * std::f32::consts::PI / 180.0;

/// Turns of the whole frame searched while no face is tracked or lost (app start, a face gone
/// for good), one per frame: the upright detector finds faces to about 25° of roll, and each turn
/// covers about as much either side of it, so with these a head held at up to about 85° either way
/// is found within four frames, at the cost of one turned pass per frame. With ±30° alone a head
/// held at 60° (`track_eval --roll-offset 60 --roll 5`) was read correctly on far fewer frames
/// (`models/train/RESEARCH_LOG.md`, "Tracking"); at 30° and 40° both give the same frames.
const WHOLE_FRAME_TURNS_DEG: [f32; 4] = [30.0, -30.0, 60.0, -60.0];

/// Side of the square window the whole frame is turned into, pixels: the frame's longer side
/// shrinks to it, so the search costs about half an upright detector pass over a VGA frame, and
/// faces under 1.7 × the detector's minimum size (at VGA) are left out of it.
const WHOLE_FRAME_WINDOW: usize = 384;

/// The roll of `l`'s eye line (outer corners 36 and 45), radians.
fn eye_roll(l: &FaceLandmarks) -> f32 {
    let (r, e) = (l.points[36], l.points[45]);
    (e[1] - r[1]).matan2(e[0] - r[0])
}

/// The face tracker: detector + landmark estimator + NCC tracking + flow filter + MSBP, generic
/// over the detector and the landmark estimator.
#[derive(Debug)]
pub struct FaceTracker<D: RegionDetector, L: LandmarkEstimator> {
    detector: D,
    estimator: L,
    config: TrackerConfig,
    slots: Vec<Slot>,
    next_id: u64,
    last_timestamp: Option<i64>,
    frame_index: u64,
    frames_since_detect: u32,
    redetect_next: bool,
    detections: Vec<(Rect, f32)>,
    /// Detections that passed M3's face check: (box, detector score, face confidence, what the
    /// check left for [`LandmarkEstimator::complete`]).
    ranked: Vec<(Rect, f32, f32, FaceLandmarks)>,
    /// Scratch output of the detections' face checks.
    checked: FaceLandmarks,
    /// The face whose track was lost last, while the tracker looks for it turned (see
    /// [`LostFace`]).
    lost: Option<LostFace>,
    /// Frames the whole frame was searched turned (it picks the turn, [`WHOLE_FRAME_TURNS_DEG`]).
    whole_frame_turns: u32,
    /// The turned window searched for a lost face or over the whole frame, and its detections.
    turned: GrayImage,
    turned_buf: Vec<u8>,
    turned_detections: Vec<(Rect, f32)>,
    pyr_prev: Pyramid,
    pyr_cur: Pyramid,
    luma: GrayImage,
    points: [[f32; 2]; N_POINTS],
    points64: [[f64; 2]; N_LANDMARKS],
    /// The landmarks' weights in the fit (the estimator's per-point confidences).
    weights64: [f64; N_LANDMARKS],
    projected: [[f64; 2]; N_LANDMARKS],
    result: TrackingResult,
    frame_size: (usize, usize),
    gaze: GazeState,
    /// The stream's recent whole-frame sharpness (the frame's blur reason).
    frame_sharpness: SharpnessHistory,
    /// The ids of the faces the previous frame reported (the frame's lost reason).
    last_ids: [u64; MAX_FACES_LIMIT],
    last_faces: usize,
}

/// Frames of eye rays kept for taps ([`FaceTracker::add_calibration_point`]): a tap is matched
/// with the frame nearest its time, and reaches the app a few frames after the look.
const GAZE_HISTORY: usize = 32;

/// A tap's time may be this far from the nearest recorded frame, nanoseconds.
const TAP_MATCH_NS: u64 = 250_000_000;

/// One frame's uncorrected eye rays per face.
#[derive(Debug, Clone, Copy)]
struct GazeFrame {
    timestamp_ns: i64,
    faces: usize,
    rays: [[GazeRay; 2]; MAX_FACES_LIMIT],
}

/// Targets, settings, the user's calibration and recent eye rays.
#[derive(Debug, Clone)]
struct GazeState {
    targets: Vec<Target>,
    config: GazeConfig,
    calibration: GazeCalibration,
    history: Vec<GazeFrame>,
    next: usize,
}

impl GazeState {
    fn new() -> Self {
        Self {
            targets: Vec::new(),
            config: GazeConfig::default(),
            calibration: GazeCalibration::default(),
            history: Vec::with_capacity(GAZE_HISTORY),
            next: 0,
        }
    }

    fn record(&mut self, frame: GazeFrame) {
        if self.history.len() < GAZE_HISTORY {
            self.history.push(frame);
        } else {
            self.history[self.next] = frame;
        }
        self.next = (self.next + 1) % GAZE_HISTORY;
    }
}

fn us(t: Instant) -> u64 {
    t.elapsed().as_micros() as u64
}

impl<D: RegionDetector, L: LandmarkEstimator> FaceTracker<D, L> {
    /// A tracker over `detector` and `estimator`.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] / [`Error::InvalidCamera`] when `config` fails
    /// [`TrackerConfig::validate`].
    pub fn new(detector: D, estimator: L, config: TrackerConfig) -> Result<Self> {
        config.validate()?;
        let slots = (0..config.max_faces)
            .map(|_| Slot::new(&config))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            detector,
            estimator,
            config,
            slots,
            next_id: 1,
            last_timestamp: None,
            frame_index: 0,
            frames_since_detect: 0,
            redetect_next: true,
            detections: Vec::with_capacity(64),
            ranked: Vec::with_capacity(64),
            checked: FaceLandmarks::default(),
            lost: None,
            whole_frame_turns: 0,
            turned: GrayImage::default(),
            turned_buf: Vec::new(),
            turned_detections: Vec::with_capacity(64),
            pyr_prev: Pyramid::new(),
            pyr_cur: Pyramid::new(),
            luma: GrayImage::default(),
            points: [[0.0; 2]; N_POINTS],
            points64: [[0.0; 2]; N_LANDMARKS],
            weights64: [1.0; N_LANDMARKS],
            projected: [[0.0; 2]; N_LANDMARKS],
            result: TrackingResult {
                faces: Vec::with_capacity(config.max_faces),
                ..Default::default()
            },
            frame_size: (0, 0),
            gaze: GazeState::new(),
            frame_sharpness: SharpnessHistory::default(),
            last_ids: [0; MAX_FACES_LIMIT],
            last_faces: 0,
        })
    }

    /// Sets the targets the point of gaze is located among (screens, mirrors, zones; camera
    /// frame), replacing any before; an empty list turns location off. The tap calibration stays.
    pub fn set_gaze_targets(&mut self, targets: Vec<Target>) {
        self.gaze.targets = targets;
    }

    /// The targets set.
    pub fn gaze_targets(&self) -> &[Target] {
        &self.gaze.targets
    }

    /// Point-of-gaze settings (eye confidence, head fallback, temporal filter).
    pub fn set_gaze_config(&mut self, config: GazeConfig) {
        self.gaze.config = config;
    }

    /// Tells the tracker the user looked at `point_mm` (u, v) on target `target` (an index into
    /// the targets set) at `timestamp_ns` — a tap, a button press. The face whose uncorrected gaze
    /// at the frame nearest that time points closest to the point teaches the per-user
    /// correction, applied from the next frame. Returns the taps recorded so far.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for an unknown target, a non-finite point, or no frame with a face
    /// within 250 ms of `timestamp_ns`; [`Error::InvalidConfig`] when the gaze stage is off
    /// ([`TrackerConfig::gaze`]).
    pub fn add_calibration_point(
        &mut self,
        target: usize,
        point_mm: [f64; 2],
        timestamp_ns: i64,
    ) -> Result<usize> {
        if !self.config.gaze {
            return Err(Error::InvalidConfig(
                "the gaze stage is off (TrackerConfig::gaze): taps cannot calibrate it".into(),
            ));
        }
        let t = self.gaze.targets.get(target).ok_or_else(|| {
            Error::InvalidInput(format!(
                "no gaze target {target} ({} set)",
                self.gaze.targets.len()
            ))
        })?;
        if !point_mm.iter().all(|v| v.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "calibration point {point_mm:?} is not finite"
            )));
        }
        let p = t.point_at(point_mm);
        let frame = self
            .gaze
            .history
            .iter()
            .filter(|f| f.faces > 0)
            .min_by_key(|f| f.timestamp_ns.abs_diff(timestamp_ns))
            .filter(|f| f.timestamp_ns.abs_diff(timestamp_ns) <= TAP_MATCH_NS)
            .copied()
            .ok_or_else(|| {
                Error::InvalidInput(format!(
                    "no frame with a face within 250 ms of the tap at {timestamp_ns} ns"
                ))
            })?;
        let miss = |rays: &[GazeRay; 2]| {
            let o = (rays[0].origin + rays[1].origin) / 2.0;
            crate::math::angle(&(rays[0].direction + rays[1].direction), &(p - o))
        };
        let rays = frame.rays[..frame.faces]
            .iter()
            .min_by(|a, b| miss(a).total_cmp(&miss(b)))
            .copied()
            .ok_or_else(|| Error::Internal("empty gaze frame".into()))?;
        self.gaze.calibration.add_tap(&rays, &p)?;
        Ok(self.gaze.calibration.taps())
    }

    /// The tap calibration learnt so far.
    pub fn gaze_calibration(&self) -> &GazeCalibration {
        &self.gaze.calibration
    }

    /// Forgets the tap calibration (a new user).
    pub fn reset_gaze_calibration(&mut self) {
        self.gaze.calibration.reset();
    }

    /// Settings.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// The detector (e.g. to read its statistics).
    pub fn detector(&self) -> &D {
        &self.detector
    }

    /// The detector, mutable.
    pub fn detector_mut(&mut self) -> &mut D {
        &mut self.detector
    }

    /// The landmark estimator.
    pub fn estimator(&self) -> &L {
        &self.estimator
    }

    /// The landmark estimator, mutable.
    pub fn estimator_mut(&mut self) -> &mut L {
        &mut self.estimator
    }

    /// The last result.
    pub fn result(&self) -> &TrackingResult {
        &self.result
    }

    /// Ends every track and forgets the timestamp history (a new stream).
    pub fn reset(&mut self) {
        for s in &mut self.slots {
            s.end();
        }
        self.last_timestamp = None;
        self.redetect_next = true;
        self.frames_since_detect = 0;
        self.lost = None;
        self.pyr_prev = Pyramid::new();
        self.frame_size = (0, 0);
        self.frame_sharpness.reset();
        self.last_faces = 0;
    }

    /// Converts `frame` to upright luma (in a buffer the tracker keeps) and processes it.
    ///
    /// # Errors
    /// As [`FaceTracker::process`].
    pub fn process_frame(
        &mut self,
        frame: &Frame<'_>,
        timestamp_ns: i64,
    ) -> Result<&TrackingResult> {
        let t0 = Instant::now();
        let mut luma = std::mem::take(&mut self.luma);
        frame.to_luma(&mut luma);
        let image_us = us(t0);
        let d = frame.desc();
        let camera = self
            .config
            .camera
            .map(|k| k.for_upright(d.width, d.height, d.rotation, d.mirrored));
        let r = self.process_inner(&luma, timestamp_ns, t0, camera);
        self.luma = luma;
        r?;
        self.result.timings.image_us = image_us;
        Ok(&self.result)
    }

    /// Processes one upright luma image taken at `timestamp_ns`.
    ///
    /// # Errors
    /// [`Error::InvalidFrame`] for an empty image; [`Error::InvalidInput`] in video mode when
    /// `timestamp_ns` is not greater than the previous call's; errors of the detector, the landmark
    /// estimator or the fit (non-finite landmarks) pass through. After an error the tracker's
    /// tracks are unchanged where the error came before any update, and may have ended otherwise.
    pub fn process(&mut self, image: &GrayImage, timestamp_ns: i64) -> Result<&TrackingResult> {
        let camera = self.config.camera;
        self.process_inner(image, timestamp_ns, Instant::now(), camera)?;
        Ok(&self.result)
    }

    /// Looks for a face turned in roll, with the detector and the face check, where the upright
    /// detector found none: the lost face ([`LostFace`]) in a window around its last place,
    /// turned by this frame's turn; or, where no face is tracked (`nothing_tracked`) and none
    /// lost, or a lost one's window-only frames are over and this frame is not the window's
    /// ([`LOST_WINDOW_ONLY_FRAMES`]), the whole frame turned by one of [`WHOLE_FRAME_TURNS_DEG`].
    /// What passes goes to `ranked` in image coordinates, its box from its landmarks mapped back
    /// ([`LandmarkEstimator::face_box`]).
    fn detect_turned(&mut self, image: &GrayImage, nothing_tracked: bool) -> Result<()> {
        let window = self.lost.filter(|l| {
            !nothing_tracked || l.frames < LOST_WINDOW_ONLY_FRAMES || l.frames % 2 == 0
        });
        let (turn, centre, k, side) = if let Some(lost) = window {
            let step = 30f32.to_radians();
            let mut turns = [lost.roll, lost.roll + step, lost.roll - step];
            let n = turns.iter().filter(|t| t.abs() >= UPRIGHT_COVERS).count();
            turns.sort_by_key(|t| t.abs() < UPRIGHT_COVERS);
            if n == 0 {
                return Ok(());
            }
            // Past the window-only frames the window has every other frame.
            let round = if lost.frames < LOST_WINDOW_ONLY_FRAMES {
                lost.frames
            } else {
                lost.frames / 2
            };
            let side = (TURNED_WINDOW_FACES * TURNED_FACE_PX).round() as usize;
            (
                turns[round as usize % n],
                lost.centre,
                lost.size / TURNED_FACE_PX,
                side,
            )
        } else if nothing_tracked {
            let turns = WHOLE_FRAME_TURNS_DEG;
            let turn = turns[self.whole_frame_turns as usize % turns.len()].to_radians();
            self.whole_frame_turns = self.whole_frame_turns.wrapping_add(1);
            let (w, h) = (image.width() as f32, image.height() as f32);
            let side = WHOLE_FRAME_WINDOW;
            (turn, [0.5 * w, 0.5 * h], w.max(h) / side as f32, side)
        } else {
            return Ok(());
        };
        let k = f64::from(k);
        let (c, s) = (f64::from(turn.mcos()), f64::from(turn.msin()));
        let half = side as f64 / 2.0;
        let [cx, cy] = centre.map(f64::from);
        // Window pixel → image pixel: scaled by k, turned by the roll, centred on the face.
        let map = Affine {
            m: [
                k * c,
                -k * s,
                cx - k * (c - s) * half,
                k * s,
                k * c,
                cy - k * (s + c) * half,
            ],
        };
        sample(image, &map, side, side, &mut self.turned_buf)?;
        self.turned.resize(side, side);
        self.turned.data_mut().copy_from_slice(&self.turned_buf);
        self.detector
            .detect(&self.turned, &mut self.turned_detections)?;
        self.turned_detections.retain(|(r, s)| {
            r.is_valid() && s.is_finite() && *s >= self.config.min_detection_score
        });
        // The lost face's window is its place and size: the re-detection bar applies there.
        let min_confidence = if window.is_some() {
            self.config.redetection_bar()
        } else {
            self.config.min_detection_confidence
        };
        check_detections(
            &mut self.estimator,
            &self.turned,
            &mut self.turned_detections,
            min_confidence,
            &mut self.checked,
            &mut self.ranked,
        )?;
        for (rect, _, _, landmarks) in &mut self.ranked {
            for p in &mut landmarks.points {
                let q = map.apply([f64::from(p[0]), f64::from(p[1])]);
                *p = [q[0] as f32, q[1] as f32];
            }
            *rect = match self.estimator.face_box(landmarks) {
                Some(b) => b,
                None => Rect::bounding(&landmarks.points),
            };
        }
        self.ranked.retain(|(r, ..)| r.is_valid());
        Ok(())
    }

    /// One frame through the pipeline's stages, in order: region (the tracks' template match and
    /// face check, then the detector where due and its detections checked and assigned to
    /// tracks), landmarks, flow filter and fit for each face, then the result with gaze.
    /// `camera`: the upright image's intrinsics, `None` for the default.
    fn process_inner(
        &mut self,
        image: &GrayImage,
        timestamp_ns: i64,
        t0: Instant,
        camera: Option<Intrinsics>,
    ) -> Result<()> {
        let camera = self.begin_frame(image, timestamp_ns, camera)?;
        let video = self.config.mode == Mode::Video;
        let mut timings = StageTimings::default();

        // 1. Region: the tracks' template match, then the detector where due.
        let t = Instant::now();
        let lost_now = self.track_regions(image)?;
        let n_active = self.slots.iter().filter(|s| s.active).count();
        let (run_detector, verify) = self.detection_due(n_active, lost_now);
        // A loss this frame (not re-detected at once) triggers the detector on the next frame.
        self.redetect_next = lost_now && !self.config.redetect_immediately;
        if run_detector {
            timings.detect_us = self.detect_and_check(image, verify, n_active)?;
            self.assign_detections(verify);
        } else {
            self.frames_since_detect = self.frames_since_detect.saturating_add(1);
        }
        self.end_unseen_faces();
        timings.region_us = us(t);

        // 2–4. Landmarks, flow filter, fit; then the next frame's region and template.
        let use_flow = video && self.config.flow_filter;
        if use_flow {
            let t = Instant::now();
            self.build_flow_pyramid(image);
            timings.flow_us += us(t);
        }
        for i in 0..self.slots.len() {
            if !self.slots[i].active {
                continue;
            }
            let t = Instant::now();
            self.landmarks(i, image)?;
            timings.landmarks_us += us(t);
            let t = Instant::now();
            self.filter(i, use_flow)?;
            timings.flow_us += us(t);
            let t = Instant::now();
            self.fit(i, image, &camera)?;
            timings.fit_us += us(t);
            self.judge_quality(i, image);
        }

        // 5. Result, with each face's point of gaze.
        let t = Instant::now();
        self.report(timestamp_ns);
        timings.gaze_us = us(t);
        self.judge_frame(image);
        self.end_frame(use_flow);
        self.result.timestamp_ns = timestamp_ns;
        self.result.frame_index = self.frame_index;
        self.result.detector_ran = run_detector;
        timings.total_us = us(t0);
        self.result.timings = timings;
        self.frame_index += 1;
        Ok(())
    }

    /// Checks the frame and its timestamp, forgets the tracks on a new frame size, and gives the
    /// camera this frame is fitted with.
    fn begin_frame(
        &mut self,
        image: &GrayImage,
        timestamp_ns: i64,
        camera: Option<Intrinsics>,
    ) -> Result<Intrinsics> {
        let (w, h) = (image.width(), image.height());
        if w == 0 || h == 0 || image.data().len() != w * h {
            return Err(Error::InvalidFrame(format!(
                "empty or inconsistent {w}x{h} image"
            )));
        }
        if self.config.mode == Mode::Video {
            if let Some(last) = self.last_timestamp
                && timestamp_ns <= last
            {
                return Err(Error::InvalidTimestamp(format!(
                    "video mode needs strictly increasing timestamps: got {timestamp_ns} ns after {last} ns"
                )));
            }
            self.last_timestamp = Some(timestamp_ns);
            if self.frame_size != (w, h) {
                // A new frame size: old regions and pyramids mean nothing here.
                for s in &mut self.slots {
                    s.end();
                }
                self.pyr_prev = Pyramid::new();
                self.redetect_next = true;
            }
        }
        self.frame_size = (w, h);
        match camera {
            Some(c) => Ok(c),
            None => Intrinsics::default_for(w as u32, h as u32),
        }
    }

    /// Video mode: each active track's template matched in this frame and its region checked by
    /// M3's face confidence; a track that fails ends, leaving its face as the lost one. Returns
    /// whether a track was lost. Image mode: marks every face unseen.
    fn track_regions(&mut self, image: &GrayImage) -> Result<bool> {
        let mut lost_now = false;
        if self.config.mode != Mode::Video {
            for s in &mut self.slots {
                s.seen = false;
            }
            return Ok(lost_now);
        }
        for s in self.slots.iter_mut().filter(|s| s.active) {
            s.seen = false;
            let lost = LostFace {
                centre: s.rect.center(),
                size: s.rect.w.max(s.rect.h),
                roll: eye_roll(&s.landmarks),
                frames: 0,
            };
            let Some(hit) = s.ncc.search(image, self.config.search_margin) else {
                s.end();
                lost_now = true;
                self.lost = Some(lost);
                continue;
            };
            if hit.score < self.config.min_ncc_score {
                s.end();
                lost_now = true;
                self.lost = Some(lost);
                continue;
            }
            let region = s.calib.apply(&hit.rect);
            // The gradient detector keeps its own roll from frame to frame.
            let m3 = self.config.landmarks != LandmarkMode::Gradient;
            let turned = m3 && (TURNED_CHECK_FROM..=TURNED_CHECK_TO).contains(&lost.roll.abs());
            let mut conf = if turned {
                self.estimator.face_confidence_turned(
                    image,
                    &region,
                    lost.roll,
                    &mut s.landmarks,
                )?
            } else {
                self.estimator
                    .face_confidence(image, &region, &mut s.landmarks)?
            };
            if conf < self.config.min_face_confidence && turned {
                // The last roll may be off (a wrong last frame): upright, as below it, and
                // the better of the two.
                let turned_out = s.landmarks;
                let upright = self
                    .estimator
                    .face_confidence(image, &region, &mut s.landmarks)?;
                if upright >= conf {
                    conf = upright;
                } else {
                    s.landmarks = turned_out;
                }
            }
            if conf < self.config.min_face_confidence {
                s.end();
                lost_now = true;
                self.lost = Some(lost);
                continue;
            }
            s.seen = true;
            s.rect = region;
            s.score = conf;
            s.state = FaceState::Tracked;
            s.level1_ready = true;
        }
        Ok(lost_now)
    }

    /// Whether the detector runs on this frame, and whether as the periodic check of the tracks.
    fn detection_due(&self, n_active: usize, lost_now: bool) -> (bool, bool) {
        // Detect: always in image mode; in video mode when nothing is tracked (first frame, or no
        // face yet) unless the loss happened just now and re-detection waits for the next frame,
        // when a loss asked for it, or periodically while some faces are tracked and there is room
        // for more.
        let video = self.config.mode == Mode::Video;
        let verify = video
            && n_active > 0
            && self.config.verify_interval > 0
            && self.frames_since_detect + 1 >= self.config.verify_interval;
        let run_detector = !video
            || verify
            || (n_active == 0 && !lost_now)
            || (lost_now && self.config.redetect_immediately)
            || self.redetect_next
            || (n_active > 0
                && n_active < self.config.max_faces
                && self.config.new_face_interval > 0
                && self.frames_since_detect + 1 >= self.config.new_face_interval);
        (run_detector, verify)
    }

    /// The detector on the whole frame, its detections face-checked and ranked into
    /// `self.ranked` (turned where none is upright), and, on a periodic check, the tracks that
    /// drifted off their faces ended. Returns the detector's microseconds.
    fn detect_and_check(
        &mut self,
        image: &GrayImage,
        verify: bool,
        n_active: usize,
    ) -> Result<u64> {
        let video = self.config.mode == Mode::Video;
        let td = Instant::now();
        self.detector.detect(image, &mut self.detections)?;
        let detect_us = us(td);
        self.frames_since_detect = 0;
        self.redetect_next = false;
        self.detections.retain(|(r, s)| {
            r.is_valid() && s.is_finite() && *s >= self.config.min_detection_score
        });
        if verify {
            // A check that finds its tracks needs only the detections on them, whose face
            // check is one search from the track's roll; the others, each checked from
            // several starting rolls, would cost most of the frame. Where none is on a
            // track, all are checked: the track has drifted and a new one starts.
            let on_track = |r: &Rect, slots: &[Slot]| {
                slots
                    .iter()
                    .any(|s| s.active && s.rect.iou(r) > self.config.match_iou)
            };
            if self
                .detections
                .iter()
                .any(|(r, _)| on_track(r, &self.slots))
            {
                let slots = &self.slots;
                self.detections.retain(|(r, _)| on_track(r, slots));
            }
        }
        // Every detection must pass the classifier tracked windows are checked with (M3's
        // face confidence), on the face's own box; ranked by detector score × confidence
        // (small subtitle characters pass near certainty while the real face may score lower,
        // so the confidence alone ranks badly).
        let (min_new, min_again) = (
            self.config.min_detection_confidence,
            self.config.redetection_bar(),
        );
        let lost = self.lost.filter(|_| video);
        check_detections_by(
            &mut self.estimator,
            image,
            &mut self.detections,
            |r, conf| conf >= min_new || (conf >= min_again && lost.is_some_and(|l| l.near(r))),
            &mut self.checked,
            &mut self.ranked,
        )?;
        if video && self.ranked.is_empty() {
            // A face found turned starts its track as any other: its level-1 points, found
            // upright in the turned window and mapped back, place level 2's zones.
            self.detect_turned(image, n_active == 0)?;
        }
        if verify && !self.ranked.is_empty() {
            // A track no detection overlaps, while the detector found a face, has drifted
            // off its face (its check was too weak to end it): it ends, and the face found
            // starts a new one below. Where the detector finds nothing the tracks stay, since
            // it misses faces the template still follows.
            for s in &mut self.slots {
                let overlapped = self
                    .ranked
                    .iter()
                    .any(|(r, ..)| s.rect.iou(r) > self.config.match_iou);
                if s.active && !overlapped {
                    s.end();
                }
            }
        }
        Ok(detect_us)
    }

    /// Each ranked detection to the track it overlaps most (re-anchoring it on a periodic check;
    /// in image mode the same face as last call keeps its id), or to a free slot as a new face.
    fn assign_detections(&mut self, verify: bool) {
        let video = self.config.mode == Mode::Video;
        for k in 0..self.ranked.len() {
            let (rect, score, _, checked) = self.ranked[k];
            // The track this detection belongs to, by overlap with its region this frame
            // (video: the tracked window; image: last call's box).
            let mut best: Option<(usize, f32)> = None;
            for (i, s) in self.slots.iter().enumerate() {
                if !s.active {
                    continue;
                }
                let iou = s.rect.iou(&rect);
                if iou > self.config.match_iou && best.is_none_or(|(_, b)| iou > b) {
                    best = Some((i, iou));
                }
            }
            match best {
                Some((i, _)) if video && verify => {
                    // The detector's box re-anchors the track's place and size, with the
                    // check's landmarks on it; the template is taken from it at the end of
                    // this frame.
                    let s = &mut self.slots[i];
                    s.rect = rect;
                    s.landmarks = checked;
                    s.level1_ready = true;
                }
                Some((i, _)) => {
                    let s = &mut self.slots[i];
                    if !video && !s.seen {
                        // Image mode: the same face as last call keeps its id.
                        s.seen = true;
                        s.rect = rect;
                        s.score = score;
                        s.state = FaceState::Detected;
                        s.fit = None;
                        s.landmarks = checked;
                        s.level1_ready = true;
                    }
                }
                None => {
                    // A free slot; in image mode also one whose face was not seen this call.
                    if let Some(s) = self
                        .slots
                        .iter_mut()
                        .find(|s| !s.active || (!video && !s.seen))
                    {
                        s.start(self.next_id, rect, score);
                        s.landmarks = checked;
                        s.level1_ready = true;
                        self.next_id += 1;
                        self.lost = None;
                    }
                }
            }
        }
    }

    /// Ages the lost face (forgotten after [`LOST_FRAMES`], and at once in image mode), and in
    /// image mode ends the faces this call did not find.
    fn end_unseen_faces(&mut self) {
        let video = self.config.mode == Mode::Video;
        if let Some(l) = self.lost.as_mut() {
            l.frames += 1;
            if l.frames > LOST_FRAMES || !video {
                self.lost = None;
            }
        }
        if !video {
            for s in self.slots.iter_mut().filter(|s| s.active && !s.seen) {
                s.end();
            }
        }
    }

    /// This frame's flow pyramid (kept as the next frame's previous), only around the faces: the
    /// flow reads windows near their landmarks, in this frame (as the next image) and in the next
    /// (as the previous one). Without faces nothing is built: a new track resets its filter, so
    /// no flow reads this frame's pyramid.
    fn build_flow_pyramid(&mut self, image: &GrayImage) {
        if let Some(region) = flow_region(&self.slots, &self.config.lk) {
            self.pyr_cur
                .build_region(image, self.config.lk.levels, &region);
        }
    }

    /// Slot `i`'s 68 landmarks on its region.
    fn landmarks(&mut self, i: usize, image: &GrayImage) -> Result<()> {
        let s = &mut self.slots[i];
        if s.level1_ready {
            // The face check on this region already ran M3's level 1.
            self.estimator.complete(image, &s.rect, &mut s.landmarks)?;
        } else {
            self.estimator.estimate(image, &s.rect, &mut s.landmarks)?;
        }
        s.level1_ready = false;
        Ok(())
    }

    /// Slot `i`'s landmarks through the optical-flow filter (video mode with the filter on).
    fn filter(&mut self, i: usize, use_flow: bool) -> Result<()> {
        let s = &mut self.slots[i];
        s.flow_points = 0;
        if use_flow {
            if s.state == FaceState::Detected || self.pyr_prev.size() != self.pyr_cur.size() {
                s.filter.reset();
            }
            let ref_scale = self.config.flow_threshold_px / FLOW_REFERENCE_FACE_PX;
            self.points = s.landmarks.points;
            let size = face_size(&self.points);
            let used = s.filter.apply(
                &self.pyr_prev,
                &self.pyr_cur,
                &mut self.points,
                ref_scale * size,
                self.config.flow_pull,
            )?;
            s.landmarks.points = self.points;
            s.flow_points = used as u32;
        }
        Ok(())
    }

    /// Slot `i`'s 3D fit (MSBP, or FFBP in the ultra-light mode), its shape held once enough
    /// frames agree, and in video mode the next frame's template from the fitted model's box.
    fn fit(&mut self, i: usize, image: &GrayImage, camera: &Intrinsics) -> Result<()> {
        let video = self.config.mode == Mode::Video;
        let s = &mut self.slots[i];
        for (o, p) in self.points64.iter_mut().zip(&s.landmarks.points) {
            *o = [f64::from(p[0]), f64::from(p[1])];
        }
        for (w, c) in self.weights64.iter_mut().zip(&s.landmarks.weights) {
            *w = f64::from(*c);
        }
        let tracking = video && s.state == FaceState::Tracked && s.fit.is_some();
        let ultra_light = self.config.landmarks == LandmarkMode::Gradient;
        let fit = if ultra_light {
            s.ffbp.fit(&self.points64, Some(&self.weights64), camera)?
        } else if tracking {
            s.msbp_track.fit(
                &self.points64,
                Some(&self.weights64),
                camera,
                s.fit.as_ref(),
            )?
        } else {
            s.msbp_init
                .fit(&self.points64, Some(&self.weights64), camera, None)?
        };
        if video && !ultra_light && s.msbp_init.fixed_shape().is_none() {
            s.shape_acc.push(&fit.shape);
            if s.shape_acc.is_complete() {
                let shape = s.shape_acc.median();
                s.msbp_init.set_fixed_shape(shape);
                s.msbp_track.set_fixed_shape(shape);
            }
        }
        s.fit = Some(fit);
        if video {
            FaceModel::builtin().project_into(
                &fit.shape,
                &fit.animation,
                &fit.pose.rotation,
                &fit.pose.translation,
                camera,
                &mut self.projected,
            );
            s.model_box = bbox64(&self.projected);
            if ultra_light {
                // The gradient points are too coarse to place the next template (a biased
                // chin or brow grows the box frame by frame): the region the detector and
                // the template match found is the template.
                s.model_box = s.rect;
                s.calib = BoxCalib::IDENTITY;
                s.calib_pending = false;
            }
            if s.calib_pending {
                s.calib = BoxCalib::between(&s.model_box, &s.rect);
                s.calib_pending = false;
            }
            // On failure (face off-frame or flat) the track ends after this frame's report.
            s.ncc.set_template(image, &s.model_box);
        }
        Ok(())
    }

    /// Slot `i`'s quality on this frame, from its landmarks and fit.
    fn judge_quality(&mut self, i: usize, image: &GrayImage) {
        let m3 = self.config.landmarks == LandmarkMode::M3;
        let s = &mut self.slots[i];
        let Some(fit) = s.fit else {
            return;
        };
        if self.config.mode != Mode::Video {
            // Independent images have no recent frames to compare sharpness with.
            s.sharpness.reset();
        }
        let evidence = FaceEvidence::of(&s.landmarks, &fit, m3);
        s.quality = face_quality(image, &evidence, &self.config.quality, &mut s.sharpness);
    }

    /// The frame's own reasons, once its faces are reported; remembers their ids for the next
    /// frame's lost reason.
    fn judge_frame(&mut self, image: &GrayImage) {
        if self.config.mode != Mode::Video {
            self.frame_sharpness.reset();
        }
        let faces = &self.result.faces;
        let lost = self.last_ids[..self.last_faces]
            .iter()
            .any(|id| !faces.iter().any(|f| f.id == *id));
        self.result.reasons = frame_reasons(
            image,
            &self.config.quality,
            &mut self.frame_sharpness,
            faces.len(),
            lost,
        );
        self.last_faces = faces.len().min(MAX_FACES_LIMIT);
        for (o, f) in self.last_ids.iter_mut().zip(faces) {
            *o = f.id;
        }
    }

    /// The frame's result: each fitted face, with its point of gaze where gaze is on; the eye
    /// rays are recorded for taps.
    fn report(&mut self, timestamp_ns: i64) {
        self.result.faces.clear();
        let still = GazeRay {
            origin: Vector3::zeros(),
            direction: Vector3::zeros(),
        };
        let mut frame = GazeFrame {
            timestamp_ns,
            faces: 0,
            rays: [[still; 2]; MAX_FACES_LIMIT],
        };
        let gaze_on = self.config.gaze;
        for s in self.slots.iter_mut().filter(|s| s.active) {
            if let Some(fit) = s.fit {
                let g = &self.gaze;
                let gaze = gaze_on.then(|| {
                    let raw = g
                        .config
                        .head_correction
                        .apply(&raw_eye_rays(&s.landmarks, &fit), &fit);
                    if frame.faces < MAX_FACES_LIMIT {
                        frame.rays[frame.faces] = raw;
                        frame.faces += 1;
                    }
                    point_of_gaze_from_rays(
                        &raw,
                        eye_openness(&s.landmarks.points),
                        &fit,
                        &g.calibration,
                        &g.config,
                        s.gaze_dir.as_ref(),
                        &g.targets,
                    )
                });
                s.gaze_dir = gaze.as_ref().map(|g| g.ray.direction);
                self.result.faces.push(TrackedFace {
                    id: s.id,
                    rect: s.rect,
                    score: s.score,
                    state: s.state,
                    landmarks: s.landmarks,
                    fit,
                    shape_held: s.msbp_track.fixed_shape().is_some(),
                    flow_points: s.flow_points,
                    gaze,
                    quality: s.quality,
                });
            }
        }
        self.gaze.record(frame);
    }

    /// Video mode: ends the tracks left without a template (after reporting them), and keeps
    /// this frame's pyramid as the next frame's previous.
    fn end_frame(&mut self, use_flow: bool) {
        if self.config.mode != Mode::Video {
            return;
        }
        // Tracks without a template cannot be followed: end them after reporting this frame.
        for s in self
            .slots
            .iter_mut()
            .filter(|s| s.active && !s.ncc.has_template())
        {
            s.end();
            self.redetect_next = true;
        }
        if use_flow {
            std::mem::swap(&mut self.pyr_prev, &mut self.pyr_cur);
        }
    }
}

/// The part of the frame the flow filter reads for the active faces: the union of their regions,
/// each widened by a quarter of its larger side (landmarks outside the box, motion to the next
/// frame) plus the LK window at the coarsest level. `None` without an active face.
fn flow_region(slots: &[Slot], lk: &LkConfig) -> Option<Rect> {
    let window = ((lk.half_window + 2) << lk.levels.saturating_sub(1)) as f32;
    let mut out: Option<[f32; 4]> = None;
    for s in slots.iter().filter(|s| s.active) {
        let r = s.rect;
        let m = 0.25 * r.w.max(r.h) + window;
        let b = [r.x - m, r.y - m, r.x + r.w + m, r.y + r.h + m];
        out = Some(match out {
            None => b,
            Some(o) => [
                o[0].min(b[0]),
                o[1].min(b[1]),
                o[2].max(b[2]),
                o[3].max(b[3]),
            ],
        });
    }
    out.map(|[x0, y0, x1, y1]| Rect::new(x0, y0, x1 - x0, y1 - y0))
}

/// Larger side of the points' bounding box.
fn face_size(points: &[[f32; 2]]) -> f32 {
    let b = Rect::bounding(points);
    b.w.max(b.h).max(0.0)
}

/// Bounding box of projected points.
fn bbox64(points: &[[f64; 2]]) -> Rect {
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for p in points {
        x0 = x0.min(p[0]);
        y0 = y0.min(p[1]);
        x1 = x1.max(p[0]);
        y1 = y1.max(p[1]);
    }
    Rect::new(x0 as f32, y0 as f32, (x1 - x0) as f32, (y1 - y0) as f32)
}

#[cfg(test)]
mod tests {
    use super::ncc::tests::shifted;
    use super::*;
    use crate::fit::Pose;
    use crate::model::{N_ANIM, N_SHAPE};
    use nalgebra::Vector3;

    /// Truth faces of a synthetic frame: 68 points each.
    #[derive(Default)]
    struct Truth {
        faces: Vec<([[f32; 2]; N_POINTS], f32)>,
        /// Face check confidence per face (0.99 for faces beyond the list).
        confidence: Vec<f32>,
    }

    struct Det<'a> {
        truth: &'a std::cell::RefCell<Truth>,
        calls: usize,
    }

    impl RegionDetector for Det<'_> {
        fn detect(&mut self, _: &GrayImage, out: &mut Vec<(Rect, f32)>) -> Result<()> {
            self.calls += 1;
            out.clear();
            for (p, score) in &self.truth.borrow().faces {
                // A detector box 10 % larger than the points and a little low, like a real one.
                let b = Rect::bounding(p);
                out.push((
                    Rect::new(b.x - 0.05 * b.w, b.y, 1.1 * b.w, 1.1 * b.h),
                    *score,
                ));
            }
            Ok(())
        }
    }

    struct Est<'a> {
        truth: &'a std::cell::RefCell<Truth>,
    }

    impl Est<'_> {
        fn find_index(&self, face: &Rect) -> Option<usize> {
            self.truth
                .borrow()
                .faces
                .iter()
                .position(|(p, _)| Rect::bounding(p).iou(face) > 0.4)
        }

        fn find(&self, face: &Rect) -> Option<[[f32; 2]; N_POINTS]> {
            self.find_index(face)
                .map(|i| self.truth.borrow().faces[i].0)
        }
    }

    impl LandmarkEstimator for Est<'_> {
        fn estimate(&mut self, _: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
            let p = self
                .find(face)
                .ok_or_else(|| Error::Internal(format!("no face at {face:?}")))?;
            out.points = p;
            out.face_prob = 1.0;
            Ok(())
        }

        fn face_confidence(
            &mut self,
            _: &GrayImage,
            face: &Rect,
            _: &mut FaceLandmarks,
        ) -> Result<f32> {
            // By default a face the classifier is sure of: above both the tracked-window and
            // the new-detection levels.
            Ok(match self.find_index(face) {
                Some(i) => self
                    .truth
                    .borrow()
                    .confidence
                    .get(i)
                    .copied()
                    .unwrap_or(0.99),
                None => 0.1,
            })
        }
    }

    /// A tracker on the mock detector and estimator over `truth`.
    fn mock_tracker<'a>(
        truth: &'a std::cell::RefCell<Truth>,
        config: TrackerConfig,
    ) -> Result<FaceTracker<Det<'a>, Est<'a>>> {
        FaceTracker::new(Det { truth, calls: 0 }, Est { truth }, config)
    }

    fn image_mode() -> TrackerConfig {
        TrackerConfig {
            mode: Mode::Image,
            ..Default::default()
        }
    }

    /// Two faces side by side at arm's length, turned a little.
    fn two_poses() -> [Pose; 2] {
        [
            Pose::from_euler_deg(10.0, 0.0, 0.0, Vector3::new(-120.0, -20.0, 700.0)),
            Pose::from_euler_deg(-15.0, 5.0, 0.0, Vector3::new(110.0, 30.0, 650.0)),
        ]
    }

    /// The model's landmarks at `pose`, moved by `shift` pixels.
    fn face_points(pose: &Pose, cam: &Intrinsics, shift: [f32; 2]) -> [[f32; 2]; N_POINTS] {
        let mut p = [[0.0; 2]; N_LANDMARKS];
        FaceModel::builtin().project_into(
            &[0.0; N_SHAPE],
            &[0.0; N_ANIM],
            &pose.rotation,
            &pose.translation,
            cam,
            &mut p,
        );
        std::array::from_fn(|i| [p[i][0] as f32 + shift[0], p[i][1] as f32 + shift[1]])
    }

    #[test]
    fn a_lost_face_is_near_where_it_was_and_of_its_size() {
        let lost = LostFace {
            centre: [300.0, 200.0],
            size: 100.0,
            roll: 0.0,
            frames: 0,
        };
        let at = |cx: f32, side: f32| Rect::new(cx - side / 2.0, 200.0 - side / 2.0, side, side);
        assert!(lost.near(&at(300.0, 100.0)));
        assert!(lost.near(&at(440.0, 60.0)));
        // Beyond the reach, or half / twice the size.
        assert!(!lost.near(&at(460.0, 100.0)));
        assert!(!lost.near(&at(300.0, 45.0)));
        assert!(!lost.near(&at(300.0, 210.0)));
        // The reach grows with the frames since the loss (a quarter of a face size each).
        let later = LostFace { frames: 4, ..lost };
        assert!(later.near(&at(540.0, 100.0)));
        assert!(!later.near(&at(560.0, 100.0)));
    }

    #[test]
    fn bad_configs_are_typed_errors() {
        assert!(TrackerConfig::default().validate().is_ok());
        let bad = [
            TrackerConfig {
                max_faces: 0,
                ..Default::default()
            },
            TrackerConfig {
                max_faces: MAX_FACES_LIMIT + 1,
                ..Default::default()
            },
            TrackerConfig {
                min_face_confidence: f32::NAN,
                ..Default::default()
            },
            TrackerConfig {
                min_detection_score: 1.5,
                ..Default::default()
            },
            TrackerConfig {
                min_detection_confidence: -0.1,
                ..Default::default()
            },
            TrackerConfig {
                min_redetection_confidence: f32::NAN,
                ..Default::default()
            },
            TrackerConfig {
                search_margin: 0.0,
                ..Default::default()
            },
            TrackerConfig {
                ncc_template_px: 2,
                ..Default::default()
            },
            TrackerConfig {
                flow_threshold_px: -1.0,
                ..Default::default()
            },
            TrackerConfig {
                flow_pull: f32::NAN,
                ..Default::default()
            },
            TrackerConfig {
                flow_pull: 1.5,
                ..Default::default()
            },
            TrackerConfig {
                shape_frames: 0,
                ..Default::default()
            },
            TrackerConfig {
                lk: LkConfig {
                    half_window: 0,
                    ..Default::default()
                },
                ..Default::default()
            },
            TrackerConfig {
                msbp: MsbpConfig {
                    z_far_mm: 10.0,
                    ..Default::default()
                },
                ..Default::default()
            },
        ];
        for c in bad {
            assert!(
                matches!(c.validate(), Err(Error::InvalidConfig(_))),
                "{c:?}"
            );
        }
        let cam = TrackerConfig {
            camera: Some(Intrinsics {
                fx: -1.0,
                fy: 1.0,
                cx: 0.0,
                cy: 0.0,
            }),
            ..Default::default()
        };
        assert!(matches!(cam.validate(), Err(Error::InvalidCamera(_))));
        // Partial JSON configs take the defaults for the rest.
        let c: TrackerConfig =
            serde_json::from_str(r#"{"max_faces": 3, "flow_filter": false, "mode": "Image"}"#)
                .unwrap();
        assert_eq!(c.max_faces, 3);
        assert_eq!(c.mode, Mode::Image);
        assert_eq!(c.search_margin, TrackerConfig::default().search_margin);
        let truth = std::cell::RefCell::new(Truth::default());
        let made = mock_tracker(
            &truth,
            TrackerConfig {
                max_faces: 0,
                ..Default::default()
            },
        );
        assert!(matches!(made, Err(Error::InvalidConfig(_))));
    }

    #[test]
    fn video_timestamps_must_increase() {
        let truth = std::cell::RefCell::new(Truth::default());
        let img = GrayImage::new(64, 48);
        let mut t = mock_tracker(&truth, TrackerConfig::default()).unwrap();
        let r = t.process(&img, 1_000).unwrap();
        assert_eq!(r.state(), FrameState::Lost);
        assert!(r.detector_ran);
        for bad in [1_000, 999, -5] {
            assert!(matches!(
                t.process(&img, bad),
                Err(Error::InvalidTimestamp(_))
            ));
        }
        assert!(t.process(&img, 1_001).is_ok());
        assert!(matches!(
            t.process(&GrayImage::new(0, 0), 2_000),
            Err(Error::InvalidFrame(_))
        ));
        t.reset();
        assert!(t.process(&img, 0).is_ok());
        // Image mode accepts any order.
        let mut t = mock_tracker(&truth, image_mode()).unwrap();
        assert!(t.process(&img, 5).is_ok());
        assert!(t.process(&img, 5).is_ok());
        assert!(t.process(&img, 1).is_ok());
    }

    #[test]
    fn two_faces_keep_their_ids_while_tracked() {
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let poses = two_poses();
        let truth = std::cell::RefCell::new(Truth::default());
        let set_truth = |shift: [f32; 2]| {
            truth.borrow_mut().faces = vec![
                (face_points(&poses[0], &cam, shift), 0.8),
                (face_points(&poses[1], &cam, shift), 0.9),
            ];
        };
        for max_faces in [2usize, 1] {
            let mut t = mock_tracker(
                &truth,
                TrackerConfig {
                    max_faces,
                    new_face_interval: 0,
                    ..Default::default()
                },
            )
            .unwrap();
            let mut ids: Vec<u64> = Vec::new();
            for f in 0..6 {
                let shift = [3.0 * f as f32, -2.0 * f as f32];
                set_truth(shift);
                let img = shifted(shift);
                let r = t.process(&img, f as i64 * 33_000_000).unwrap();
                assert_eq!(r.faces.len(), max_faces, "frame {f}");
                let now: Vec<u64> = r.faces.iter().map(|x| x.id).collect();
                if f == 0 {
                    assert_eq!(r.state(), FrameState::Detected);
                    ids = now;
                    if max_faces == 1 {
                        // The higher-scoring face wins the only slot.
                        let b = Rect::bounding(&truth.borrow().faces[1].0);
                        assert!(r.faces[0].rect.iou(&b) > 0.5);
                    }
                } else {
                    assert_eq!(r.state(), FrameState::Tracked, "frame {f}");
                    assert_eq!(now, ids, "frame {f}");
                    for face in &r.faces {
                        assert!(face.fit.report.rms_px < 1.0, "{:?}", face.fit.report);
                    }
                }
                assert!(r.timings.total_us >= r.timings.fit_us);
            }
            assert_eq!(t.detector().calls, 1);
        }
    }

    #[test]
    fn detections_rank_by_detector_score_times_confidence() {
        // The video case: small clutter (subtitle characters) that the detector scores low
        // but the face check passes at 1.0, against the face at 0.95 / 0.99. Either order of
        // the two in the detector's output, the face takes the only slot.
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let poses = two_poses();
        for (scores, confidence, want) in
            [([0.5, 0.95], [1.0, 0.99], 1), ([0.95, 0.5], [0.99, 1.0], 0)]
        {
            let truth = std::cell::RefCell::new(Truth {
                faces: (0..2)
                    .map(|i| (face_points(&poses[i], &cam, [0.0; 2]), scores[i]))
                    .collect(),
                confidence: confidence.to_vec(),
            });
            let mut t = mock_tracker(&truth, image_mode()).unwrap();
            let r = t.process(&shifted([0.0; 2]), 0).unwrap();
            assert_eq!(r.faces.len(), 1);
            let b = Rect::bounding(&truth.borrow().faces[want].0);
            assert!(r.faces[0].rect.iou(&b) > 0.5, "{scores:?} {confidence:?}");
        }
    }

    /// An estimator that knows one face box: its check gives 0.99 on boxes overlapping the face
    /// by IoU ≥ 0.7, 0.5 on IoU ≥ 0.3 (a detector box of a small face: off), 0.05 elsewhere, and
    /// (with `reboxes`) its face box is the true one whenever the last check overlapped it.
    struct BoxEst {
        face: Rect,
        reboxes: bool,
        last_iou: f32,
        checks: usize,
    }

    impl LandmarkEstimator for BoxEst {
        fn estimate(&mut self, _: &GrayImage, _: &Rect, _: &mut FaceLandmarks) -> Result<()> {
            Ok(())
        }

        fn face_confidence(
            &mut self,
            _: &GrayImage,
            face: &Rect,
            out: &mut FaceLandmarks,
        ) -> Result<f32> {
            self.checks += 1;
            self.last_iou = face.iou(&self.face);
            out.points[0] = [face.x, face.y];
            Ok(match self.last_iou {
                v if v >= 0.7 => 0.99,
                v if v >= 0.3 => 0.5,
                _ => 0.05,
            })
        }

        fn face_box(&self, _: &FaceLandmarks) -> Option<Rect> {
            (self.reboxes && self.last_iou >= 0.3).then_some(self.face)
        }
    }

    #[test]
    fn the_cascade_reboxes_detections_on_the_face_and_merges_them() {
        let face = Rect::new(100.0, 100.0, 20.0, 20.0);
        let img = GrayImage::new(8, 8);
        // Two off boxes of the one face (IoU 0.51 and 0.64: checked at 0.5, re-boxed), clutter.
        let candidates = [
            (Rect::new(104.0, 106.0, 15.0, 15.0), 0.3),
            (Rect::new(102.0, 104.0, 16.0, 16.0), 0.45),
            (Rect::new(300.0, 40.0, 20.0, 20.0), 0.9),
        ];
        for (reboxes, want) in [(true, 1), (false, 0)] {
            let mut est = BoxEst {
                face,
                reboxes,
                last_iou: 0.0,
                checks: 0,
            };
            let mut cands = candidates.to_vec();
            let (mut scratch, mut out) = (FaceLandmarks::default(), Vec::new());
            check_detections(&mut est, &img, &mut cands, 0.95, &mut scratch, &mut out).unwrap();
            assert_eq!(out.len(), want, "reboxes {reboxes}");
            if reboxes {
                let (rect, score, conf, checked) = out[0];
                assert_eq!((rect, score, conf), (face, 0.45, 0.99));
                // What the check on the new box left, for `complete`.
                assert_eq!(checked.points[0], [face.x, face.y]);
                // Clutter (0.05 < MIN_CONFIDENCE_TO_REFINE) is checked once, each face box twice.
                assert_eq!(est.checks, 5);
            }
            // Best detector score first.
            assert_eq!(cands[0].1, 0.9);
        }
    }

    #[test]
    fn box_calibration_round_trips() {
        let model = Rect::new(100.0, 80.0, 120.0, 140.0);
        let det = Rect::new(90.0, 85.0, 140.0, 150.0);
        let c = BoxCalib::between(&model, &det);
        let back = c.apply(&model);
        assert!((back.x - det.x).abs() < 1e-3 && (back.w - det.w).abs() < 1e-3);
        assert!((back.y - det.y).abs() < 1e-3 && (back.h - det.h).abs() < 1e-3);
        // Moved model box → moved detector-convention box.
        let moved = c.apply(&Rect::new(110.0, 70.0, 120.0, 140.0));
        assert!((moved.x - 100.0).abs() < 1e-3 && (moved.y - 75.0).abs() < 1e-3);
    }
}
