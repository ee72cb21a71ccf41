//! The `FaceTracker` object (`bindings/API.md`): `monotrack_core::track::Tracker` behind a Mutex
//! (uniffi objects are shared across threads), its config and result records, and the shared
//! benchmark (`monotrack_core::bench`) for the device benchmark apps.

use crate::MonotrackError;
use crate::error::{guard, guard_infallible};
use crate::gaze::{GazeTarget, PlanePoint, PointOfGaze};
use crate::types::{ActionUnits, CameraIntrinsics, FrameDesc, HeadPose, Point2, ShapeUnits, Vec3};
use monotrack_core::camera::Intrinsics;
use monotrack_core::detect::DetectorConfig;
use monotrack_core::fit::MsbpConfig;
use monotrack_core::gaze::{GazeConfig, GazeFilter, Target};
use monotrack_core::image::{Frame, Rect as CoreRect};
use monotrack_core::model::FaceModel;
use monotrack_core::track::{self as core_track, TrackedFace, Tracker};
use std::sync::{Arc, Mutex, MutexGuard};

/// Image (detect every call) or video (track between calls; timestamps must increase).
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum RunningMode {
    /// Independent stills.
    Image,
    /// A camera stream.
    Video,
}

/// Tracker settings (the rest of the core's `TrackerConfig` keeps its defaults).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct TrackerConfig {
    /// Image or video mode.
    pub running_mode: RunningMode,
    /// Most faces tracked at once (1..=16).
    pub max_faces: u32,
    /// The camera's intrinsics for the frames as passed in (the sensor's, before rotation and
    /// mirroring: `CameraIntrinsics`); `None`: fx = fy = 0.9·max side of the upright image,
    /// centred.
    pub camera: Option<CameraIntrinsics>,
    /// Smallest face the detector looks for, pixels of the upright image (16..=4096). Default 24;
    /// 16 with `min_detection_score` 0.25 is the small-faces operating point (faces down to ~17 px,
    /// more false positives and a longer detection; `core/models/MODEL_CARD.md`, "Face detector";
    /// BENCHMARKS.md, "Face detector").
    pub min_face_size_px: u32,
    /// Detector candidates scoring below this (0..=1) are not checked as faces. Default 0.4;
    /// 0.25 at the small-faces operating point.
    pub min_detection_score: f32,
    /// Face presence: a detection becomes a face when M3's face confidence on its box is at least
    /// this (0..=1; default 0.95). Lower finds more faces and more false ones. In video mode a
    /// detection where a face was lost in the last 30 frames, and of its size, needs 0.8 / 0.95 of
    /// this (0.8 by default): where the face just was is evidence for it.
    pub min_detection_confidence: f32,
    /// Tracking confidence: a tracked face is kept while M3's face confidence in its window is at
    /// least this (0..=1; default 0.5, the classifier's decision point); below it the face is
    /// re-detected.
    pub min_tracking_confidence: f32,
    /// The fast tracker's template match must score at least this (normalised cross-correlation,
    /// -1..=1; default 0.5); below it the face is re-detected.
    pub min_match_score: f32,
    /// How far the fast tracker searches around the last face, as a fraction of the face's larger
    /// side in each direction (0 < margin ≤ 4; default 0.5: half a face width per frame).
    pub search_margin: f32,
    /// Optical-flow landmark filter on or off.
    pub flow_filter: bool,
    /// Temporal smoothing of the gaze direction that leaves saccades sharp (default off).
    pub gaze_filter: bool,
    /// Frames over which a new track's shape units are estimated before being held (1..=1000).
    pub shape_frames: u32,
    /// Landmarks in M3's mirror-average mode: more accurate on still images, slower (five nets —
    /// level 1 and the brows, mouth, face and nose zones — also run on their mirrored input;
    /// `core/models/MODEL_CARD.md`). `None` (the default): on for stills (`process_image`, image
    /// running mode), off in video mode, where it would run on every frame (the mode in the
    /// tracker: BENCHMARKS.md, "Tracking").
    pub mirror_average: Option<bool>,
    /// The ultra-light mode: the learning-free gradient landmark detector (no landmark network
    /// loaded; 32 points, 27 of them in `landmarks`, the others placed by the mean face with
    /// weight 0) and the weak-perspective FFBP fit; no gestures or gaze. Far less accurate than
    /// M3 (`core/models/gradient_metrics.json`). Its face check is weak: take the thresholds of
    /// `ultra_light_tracker_config()`. Default off.
    #[uniffi(default = false)]
    pub ultra_light: bool,
    /// Gesture probabilities in each `Face` (default on). Off, `Face.gestures` is `None`; the
    /// gesture heads share the zone networks that place the landmarks, so this saves only their
    /// decoding.
    #[uniffi(default = true)]
    pub gestures: bool,
    /// The gaze outputs (default on): M3's eye directions (`Face.gaze`) and the point-of-gaze
    /// stage (`Face.point_of_gaze`: the ray from between the eyes, the tap calibration, the
    /// targets), which is skipped when off; both are then `None` and taps are refused.
    #[uniffi(default = true)]
    pub gaze: bool,
    /// Expressions: the 3D fit's action units (default on). Off, the fit solves pose and shape
    /// only, skipping its six one-unit solves per round, and `Face.action_units` is `None`.
    #[uniffi(default = true)]
    pub expressions: bool,
}

/// Which optional outputs a tracker's faces carry (its config's toggles; the ultra-light mode has
/// no gestures, gaze or action units).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Outputs {
    gestures: bool,
    gaze: bool,
    expressions: bool,
}

impl Outputs {
    /// Whether the faces carry gaze (and taps can calibrate it).
    pub(crate) fn gaze(self) -> bool {
        self.gaze
    }
}

impl From<&TrackerConfig> for Outputs {
    fn from(c: &TrackerConfig) -> Self {
        Self {
            gestures: c.gestures && !c.ultra_light,
            gaze: c.gaze && !c.ultra_light,
            expressions: c.expressions && !c.ultra_light,
        }
    }
}

/// The default settings: video mode, one face, default intrinsics, filter on.
#[uniffi::export]
pub fn default_tracker_config() -> TrackerConfig {
    let c = core_track::TrackerConfig::default();
    TrackerConfig {
        running_mode: RunningMode::Video,
        max_faces: c.max_faces as u32,
        camera: None,
        min_face_size_px: DetectorConfig::default().min_face_px.round() as u32,
        min_detection_score: c.min_detection_score,
        min_detection_confidence: c.min_detection_confidence,
        min_tracking_confidence: c.min_face_confidence,
        min_match_score: c.min_ncc_score,
        search_margin: c.search_margin,
        flow_filter: c.flow_filter,
        gaze_filter: false,
        shape_frames: c.shape_frames as u32,
        mirror_average: None,
        ultra_light: false,
        gestures: true,
        gaze: true,
        expressions: true,
    }
}

/// The ultra-light mode's settings (`TrackerConfig.ultra_light` on, detections accepted on the
/// detector's score, tracked windows kept while the gradient points' mean confidence is at least
/// 0.3); the rest as `default_tracker_config()`.
#[uniffi::export]
pub fn ultra_light_tracker_config() -> TrackerConfig {
    let c = core_track::TrackerConfig::ultra_light();
    TrackerConfig {
        ultra_light: true,
        min_detection_confidence: c.min_detection_confidence,
        min_tracking_confidence: c.min_face_confidence,
        ..default_tracker_config()
    }
}

/// The embedded models' tracker for `config`; in image mode whatever its mode with `stills`.
pub(crate) fn build_tracker(
    config: &TrackerConfig,
    stills: bool,
) -> Result<Tracker, MonotrackError> {
    let (mut core, det) = to_core(config)?;
    if stills {
        core.mode = core_track::Mode::Image;
    }
    // The core's choice by mode unless the caller made one.
    let mut t = Tracker::with_detector_config(core, det)?;
    if let Some(on) = config.mirror_average {
        t.estimator_mut().set_mirror_average(on);
    }
    t.set_gaze_config(GazeConfig {
        filter: config.gaze_filter.then(GazeFilter::default),
        ..GazeConfig::default()
    });
    Ok(t)
}

fn to_core(
    c: &TrackerConfig,
) -> Result<(core_track::TrackerConfig, DetectorConfig), MonotrackError> {
    if !(16..=4096).contains(&c.min_face_size_px) {
        return Err(MonotrackError::InvalidConfig {
            msg: format!(
                "min_face_size_px must be 16..=4096, got {}",
                c.min_face_size_px
            ),
        });
    }
    let core = core_track::TrackerConfig {
        mode: match c.running_mode {
            RunningMode::Image => core_track::Mode::Image,
            RunningMode::Video => core_track::Mode::Video,
        },
        max_faces: c.max_faces as usize,
        camera: c.camera.map(Intrinsics::from),
        flow_filter: c.flow_filter,
        shape_frames: c.shape_frames as usize,
        min_detection_score: c.min_detection_score,
        min_detection_confidence: c.min_detection_confidence,
        min_redetection_confidence: c.min_detection_confidence
            * (core_track::DEFAULT_MIN_REDETECTION_CONFIDENCE
                / core_track::DEFAULT_MIN_DETECTION_CONFIDENCE),
        min_face_confidence: c.min_tracking_confidence,
        min_ncc_score: c.min_match_score,
        search_margin: c.search_margin,
        landmarks: if c.ultra_light {
            core_track::LandmarkMode::Gradient
        } else {
            core_track::LandmarkMode::M3
        },
        gaze: Outputs::from(c).gaze,
        msbp: MsbpConfig {
            animation_units: Outputs::from(c).expressions,
            ..MsbpConfig::default()
        },
        ..core_track::TrackerConfig::default()
    };
    core.validate()?;
    let det = core_track::detector_config_for(
        &core,
        DetectorConfig {
            min_face_px: c.min_face_size_px as f32,
            ..DetectorConfig::default()
        },
    );
    Ok((core, det))
}

/// An axis-aligned box, pixels of the upright image.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Rect {
    /// Left.
    pub x: f32,
    /// Top.
    pub y: f32,
    /// Width.
    pub width: f32,
    /// Height.
    pub height: f32,
}

impl From<CoreRect> for Rect {
    fn from(r: CoreRect) -> Self {
        Self {
            x: r.x,
            y: r.y,
            width: r.w,
            height: r.h,
        }
    }
}

/// How a face's region was found this frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum FaceState {
    /// By the whole-frame detector.
    Detected,
    /// By the fast (NCC) tracker.
    Tracked,
}

/// Gesture probabilities (mouth: smile, frown, kiss, neutral; brows: raise, frown, neutral).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Gestures {
    /// Smile.
    pub smile: f32,
    /// Mouth frown.
    pub frown: f32,
    /// Kiss (pucker).
    pub kiss: f32,
    /// Neutral mouth.
    pub mouth_neutral: f32,
    /// Raised brows.
    pub brow_raise: f32,
    /// Frowning brows.
    pub brow_frown: f32,
    /// Neutral brows.
    pub brow_neutral: f32,
}

/// Unit gaze vectors, camera frame (looking at the camera is about (0, 0, −1)).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Gaze {
    /// The subject's left eye.
    pub left: Vec3,
    /// The subject's right eye.
    pub right: Vec3,
    /// Both eyes.
    pub combined: Vec3,
}

/// One face of a frame.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct Face {
    /// Stable while the track lasts.
    pub id: u64,
    /// Detected or tracked.
    pub state: FaceState,
    /// Face box (the tight box of the 68 landmarks' convention).
    pub bbox: Rect,
    /// Detector score (detected) or face confidence (tracked), 0..1.
    pub score: f32,
    /// 68 points, iBUG order, pixels of the upright image.
    pub landmarks: Vec<Point2>,
    /// Per landmark, 0..1, how much the estimator stands by it (the fit's weight): 1 for every
    /// M3 point; in the ultra-light mode the gradient detector's confidences, 0 for the points it
    /// does not measure.
    pub landmark_confidence: Vec<f32>,
    /// Most probable head-yaw class, degrees (−60, −30, 0, 30, 60).
    pub yaw_class_deg: i32,
    /// Yaw class probabilities in that order.
    pub yaw_probs: Vec<f32>,
    /// Gestures; `None` when `TrackerConfig.gestures` is off or in the ultra-light mode.
    pub gestures: Option<Gestures>,
    /// M3's gaze directions; `None` when `TrackerConfig.gaze` is off or in the ultra-light mode.
    pub gaze: Option<Gaze>,
    /// Head pose.
    pub pose: HeadPose,
    /// The 11 shape units.
    pub shape_units: ShapeUnits,
    /// The 6 action (animation) units; `None` when `TrackerConfig.expressions` is off or in the
    /// ultra-light mode.
    pub action_units: Option<ActionUnits>,
    /// RMS reprojection error of the 3D fit, pixels.
    pub fit_rms_px: f64,
    /// Where the face looks: the gaze ray from between the eyes, and the target it lands on when
    /// targets are set (`FaceTracker::set_gaze_targets`); `None` when `TrackerConfig.gaze` is off
    /// or in the ultra-light mode.
    pub point_of_gaze: Option<PointOfGaze>,
    /// The fitted face model's 68 vertices (iBUG order, the landmarks' points on the 3D face),
    /// camera frame, millimetres: with `face_mesh_triangles()` and the intrinsics, the mesh an AR
    /// overlay draws over the upright image.
    pub vertices_mm: Vec<Vec3>,
}

fn v3(v: &[f32; 3]) -> Vec3 {
    Vec3 {
        x: f64::from(v[0]),
        y: f64::from(v[1]),
        z: f64::from(v[2]),
    }
}

impl Face {
    /// From the core's face; `targets` name the gaze targets, `out` says which outputs it carries.
    fn from_tracked(f: &TrackedFace, targets: &[Target], out: Outputs) -> Self {
        let l = &f.landmarks;
        Self {
            id: f.id,
            state: match f.state {
                core_track::FaceState::Detected => FaceState::Detected,
                core_track::FaceState::Tracked => FaceState::Tracked,
            },
            bbox: f.rect.into(),
            score: f.score,
            landmarks: l
                .points
                .iter()
                .map(|p| Point2 { x: p[0], y: p[1] })
                .collect(),
            landmark_confidence: l.weights.to_vec(),
            yaw_class_deg: l.yaw_class_deg(),
            yaw_probs: l.yaw_probs.to_vec(),
            gestures: out.gestures.then(|| Gestures {
                smile: l.mouth[0],
                frown: l.mouth[1],
                kiss: l.mouth[2],
                mouth_neutral: l.mouth[3],
                brow_raise: l.brows[0],
                brow_frown: l.brows[1],
                brow_neutral: l.brows[2],
            }),
            gaze: out.gaze.then(|| Gaze {
                left: v3(&l.gaze_left),
                right: v3(&l.gaze_right),
                combined: v3(&l.gaze_combined),
            }),
            pose: HeadPose::from(&f.fit.pose),
            shape_units: ShapeUnits::from(&f.fit.shape[..]),
            action_units: out
                .expressions
                .then(|| ActionUnits::from(&f.fit.animation[..])),
            fit_rms_px: f.fit.report.rms_px,
            point_of_gaze: f.gaze.as_ref().map(|g| PointOfGaze::from_core(g, targets)),
            vertices_mm: {
                f.fit
                    .posed_vertices()
                    .iter()
                    .map(|p| Vec3 {
                        x: p.x,
                        y: p.y,
                        z: p.z,
                    })
                    .collect()
            },
        }
    }
}

/// The face model's mesh over its 68 vertices (`Face::vertices_mm`, and so over the 68 landmarks):
/// vertex indices, three per triangle. The triangles' winding is not consistent: draw them with
/// back-face culling off.
#[uniffi::export]
pub fn face_mesh_triangles() -> Vec<u32> {
    FaceModel::builtin()
        .triangles()
        .iter()
        .flat_map(|t| t.iter().map(|&i| u32::from(i)))
        .collect()
}

/// Per-stage wall time of one call, microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Record)]
pub struct StageTimings {
    /// Frame → upright luma.
    pub convert_us: u64,
    /// Whole-frame detector.
    pub detect_us: u64,
    /// Fast tracker (NCC search + face check).
    pub track_us: u64,
    /// M3 landmarks.
    pub landmarks_us: u64,
    /// Optical-flow filter.
    pub flow_us: u64,
    /// 3D fit.
    pub fit_us: u64,
    /// Point of gaze.
    pub gaze_us: u64,
    /// The whole call.
    pub total_us: u64,
}

/// The faces of one frame.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct TrackingResult {
    /// Upright frame width (after rotation).
    pub frame_width: u32,
    /// Upright frame height.
    pub frame_height: u32,
    /// Faces, in a stable order while tracks last.
    pub faces: Vec<Face>,
    /// Per-stage timings.
    pub timings: StageTimings,
}

pub(crate) fn result(
    r: &core_track::TrackingResult,
    w: u32,
    h: u32,
    targets: &[Target],
    out: Outputs,
) -> TrackingResult {
    let t = &r.timings;
    TrackingResult {
        frame_width: w,
        frame_height: h,
        faces: r
            .faces
            .iter()
            .map(|f| Face::from_tracked(f, targets, out))
            .collect(),
        timings: StageTimings {
            convert_us: t.image_us,
            detect_us: t.detect_us,
            track_us: t.region_us.saturating_sub(t.detect_us),
            landmarks_us: t.landmarks_us,
            flow_us: t.flow_us,
            fit_us: t.fit_us,
            gaze_us: t.gaze_us,
            total_us: t.total_us,
        },
    }
}

struct State {
    config: TrackerConfig,
    video: Tracker,
    /// For `process_image` in video running mode: a separate image-mode tracker, made on first
    /// use, so stills never disturb the video tracks (in image running mode `video` serves).
    stills: Option<Tracker>,
}

/// The face tracker (thread-safe: calls are serialised by a Mutex; feed it from one camera thread).
#[derive(uniffi::Object)]
pub struct FaceTracker {
    state: Mutex<State>,
}

fn upright_size(desc: &FrameDesc) -> (u32, u32) {
    if desc.rotation_degrees % 180 == 90 {
        (desc.height, desc.width)
    } else {
        (desc.width, desc.height)
    }
}

impl FaceTracker {
    fn lock(&self) -> MutexGuard<'_, State> {
        // A panic inside a call (caught by uniffi) poisons the lock; the state may be half-updated,
        // so the tracks are dropped and the tracker goes on from a clean slate.
        match self.state.lock() {
            Ok(g) => g,
            Err(poisoned) => {
                let mut g = poisoned.into_inner();
                g.video.reset();
                g.stills = None;
                self.state.clear_poison();
                g
            }
        }
    }
}

#[uniffi::export]
impl FaceTracker {
    /// Loads the models and builds a tracker.
    ///
    /// # Errors
    /// `InvalidConfig` for out-of-range settings, `ModelLoad` if the embedded models cannot load.
    #[uniffi::constructor]
    pub fn new(config: TrackerConfig) -> Result<Arc<Self>, MonotrackError> {
        guard(|| {
            let video = build_tracker(&config, false)?;
            Ok(Arc::new(Self {
                state: Mutex::new(State {
                    config,
                    video,
                    stills: None,
                }),
            }))
        })
    }

    /// Processes one camera frame taken at `timestamp_ns` (video mode: strictly increasing).
    ///
    /// # Errors
    /// `InvalidFrame` when the description does not match the bytes or the timestamp does not
    /// increase in video mode.
    pub fn process_frame(
        &self,
        bytes: &[u8],
        desc: FrameDesc,
        timestamp_ns: i64,
    ) -> Result<TrackingResult, MonotrackError> {
        guard(|| {
            let (w, h) = upright_size(&desc);
            let frame = Frame::new(bytes, desc.try_into()?)?;
            let mut g = self.lock();
            g.video
                .process_frame(&frame, timestamp_ns)
                .map_err(|e| match e {
                    monotrack_core::Error::InvalidInput(msg) => {
                        MonotrackError::InvalidFrame { msg }
                    }
                    e => e.into(),
                })?;
            let v = &g.video;
            Ok(result(
                v.result(),
                w,
                h,
                v.gaze_targets(),
                Outputs::from(&g.config),
            ))
        })
    }

    /// Processes a still image: detection on every call, no video track touched.
    ///
    /// # Errors
    /// `InvalidFrame` when the description does not match the bytes.
    pub fn process_image(
        &self,
        bytes: &[u8],
        desc: FrameDesc,
    ) -> Result<TrackingResult, MonotrackError> {
        guard(|| {
            let (w, h) = upright_size(&desc);
            let frame = Frame::new(bytes, desc.try_into()?)?;
            let mut g = self.lock();
            let out = Outputs::from(&g.config);
            let stills = if g.config.running_mode == RunningMode::Image {
                // The tracker is an image-mode one already: no second one.
                &mut g.video
            } else {
                if g.stills.is_none() {
                    let mut t = build_tracker(&g.config, true)?;
                    t.set_gaze_targets(g.video.gaze_targets().to_vec());
                    g.stills = Some(t);
                }
                g.stills.as_mut().ok_or_else(|| MonotrackError::Internal {
                    msg: "no image tracker".into(),
                })?
            };
            stills.process_frame(&frame, 0)?;
            Ok(result(stills.result(), w, h, stills.gaze_targets(), out))
        })
    }

    /// Ends every track and forgets the user's shape and the timestamp history.
    pub fn reset(&self) {
        guard_infallible(|| {
            let mut g = self.lock();
            g.video.reset();
            if let Some(s) = g.stills.as_mut() {
                s.reset();
            }
        });
    }

    /// The settings this tracker was built with.
    pub fn config(&self) -> TrackerConfig {
        self.lock().config
    }

    /// Sets the targets each face's point of gaze is located among (screens, mirrors, zones),
    /// replacing any before; an empty list turns location off. The tap calibration stays.
    ///
    /// # Errors
    /// `InvalidConfig` for a bad target (fewer than 3 corners, not planar, not finite) or a
    /// repeated id.
    pub fn set_gaze_targets(&self, targets: Vec<GazeTarget>) -> Result<(), MonotrackError> {
        guard(|| {
            let core = crate::gaze::to_core(&targets)?;
            let mut g = self.lock();
            if let Some(s) = g.stills.as_mut() {
                s.set_gaze_targets(core.clone());
            }
            g.video.set_gaze_targets(core);
            Ok(())
        })
    }

    /// Tells the tracker the user looked at `point` on the target `target_id` at `timestamp_ns`
    /// (the time of a tap or button press, in the frames' clock): the gaze of the frame nearest
    /// that time teaches a per-user correction, applied from the next frame. Returns the taps
    /// learnt from so far. Video mode (`process_frame`).
    ///
    /// # Errors
    /// `InvalidConfig` for an unknown target or a non-finite point, `InvalidFrame` when no frame
    /// with a face lies within 250 ms of `timestamp_ns`.
    pub fn add_calibration_point(
        &self,
        target_id: String,
        point: PlanePoint,
        timestamp_ns: i64,
    ) -> Result<u32, MonotrackError> {
        guard(|| {
            let mut g = self.lock();
            let ids = g.video.gaze_targets().iter().map(|t| t.id.as_str());
            let index = crate::gaze::tap_target(ids, &target_id, &point)?;
            let n = g
                .video
                .add_calibration_point(index, [point.u_mm, point.v_mm], timestamp_ns)
                .map_err(|e| match e {
                    monotrack_core::Error::InvalidInput(msg) => {
                        MonotrackError::InvalidFrame { msg }
                    }
                    e => e.into(),
                })?;
            Ok(n as u32)
        })
    }

    /// Forgets the tap calibration (a new user).
    pub fn reset_gaze_calibration(&self) {
        guard_infallible(|| self.lock().video.reset_gaze_calibration());
    }
}

/// One stage's statistics, microseconds.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct StageStat {
    /// `tracking/<stage>` or `redetect/<stage>`.
    pub name: String,
    /// Median.
    pub median_us: f64,
    /// 90th percentile.
    pub p90_us: f64,
    /// Mean.
    pub mean_us: f64,
}

/// One stage's median and 90th percentile, microseconds.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct StagePercentiles {
    /// Median.
    pub median_us: f64,
    /// 90th percentile.
    pub p90_us: f64,
}

/// Per-stage times of one kind of frame, camera bytes to result (see `run_camera_benchmark`).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct FrameStageTimes {
    /// Camera bytes → upright luma.
    pub convert: StagePercentiles,
    /// Face region: NCC + face check on tracked frames, the detector on detected ones.
    pub region: StagePercentiles,
    /// M3 landmarks.
    pub landmarks: StagePercentiles,
    /// Optical-flow filter.
    pub flow: StagePercentiles,
    /// 3D fit.
    pub fit: StagePercentiles,
    /// The whole call.
    pub total: StagePercentiles,
}

/// What `run_camera_benchmark` measured (the JSON of `monotrack bench --json`).
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct CameraBenchReport {
    /// Which kernel forms ran: `native` or `portable` (the process's kernel choice,
    /// `monotrack_core::kernels::choice`).
    pub path: String,
    /// The CPU, in words.
    pub cpu: String,
    /// Frames in the clip.
    pub frames: u32,
    /// Frames whose faces were all tracked.
    pub tracked: FrameStageTimes,
    /// Frames that ran the whole-frame detector and found the face.
    pub detected: FrameStageTimes,
}

impl From<monotrack_core::bench::FrameStages> for FrameStageTimes {
    fn from(s: monotrack_core::bench::FrameStages) -> Self {
        let p = |p: monotrack_core::bench::Percentiles| StagePercentiles {
            median_us: p.median_us,
            p90_us: p.p90_us,
        };
        Self {
            convert: p(s.convert),
            region: p(s.region),
            landmarks: p(s.landmarks),
            flow: p(s.flow),
            fit: p(s.fit),
            total: p(s.total),
        }
    }
}

/// The benchmark from camera frames to result (the same code as `monotrack bench`): a clip of
/// `frames` frames with the face of `source_luma` (a `source_width`×`source_height` upright 8-bit
/// picture, e.g. the app's own sample face) moving, each frame laid out as `camera` describes
/// (format, strides, rotation, mirroring: what the app's camera delivers), tracked once in video
/// mode and once with the detector on every frame; per-stage median and p90.
///
/// # Errors
/// `InvalidFrame` for a bad `camera` description or a source whose size does not match its
/// bytes, `InvalidConfig` for fewer than 2 or too many frames or a source without a face.
#[uniffi::export]
pub fn run_camera_benchmark(
    source_luma: Vec<u8>,
    source_width: u32,
    source_height: u32,
    camera: FrameDesc,
    frames: u32,
) -> Result<CameraBenchReport, MonotrackError> {
    guard(|| {
        let source = monotrack_core::image::GrayImage::from_vec(
            source_width as usize,
            source_height as usize,
            source_luma,
        )
        .filter(|s| s.width() > 0 && s.height() > 0)
        .ok_or_else(|| MonotrackError::InvalidFrame {
            msg: format!(
                "the source picture must be a non-empty {source_width}x{source_height} luma buffer"
            ),
        })?;
        let r = monotrack_core::bench::run_camera_benchmark(
            &source,
            &camera.try_into()?,
            frames,
            &core_track::TrackerConfig::default(),
        )?;
        Ok(CameraBenchReport {
            path: r.path.to_string(),
            cpu: r.cpu,
            frames: r.frames,
            tracked: r.tracked.into(),
            detected: r.detected.into(),
        })
    })
}

/// What `run_benchmark` measured.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct BenchReport {
    /// Where it ran (OS / architecture).
    pub device: String,
    /// Iterations per path.
    pub iterations: u32,
    /// Building the tracker (loading and optimising the embedded models), microseconds: what an
    /// app's `FaceTracker` constructor costs, and why it belongs off the main thread.
    pub model_load_us: f64,
    /// Per-stage statistics: the tracking path, then the re-detect path (empty stages measure 0
    /// when the frame holds no face).
    pub stages: Vec<StageStat>,
}

/// The shared benchmark (the same code as `monotrack bench`): `iterations` tracked frames and
/// `iterations` re-detect frames of this frame, per-stage median / p90 / mean.
///
/// # Errors
/// `InvalidFrame` for a bad frame, `InvalidConfig` for 0 or too many iterations.
#[uniffi::export]
pub fn run_benchmark(
    bytes: &[u8],
    desc: FrameDesc,
    iterations: u32,
) -> Result<BenchReport, MonotrackError> {
    guard(|| {
        let frame = Frame::new(bytes, desc.try_into()?)?;
        let r = monotrack_core::bench::run_benchmark(
            &frame,
            iterations,
            &core_track::TrackerConfig::default(),
        )?;
        Ok(BenchReport {
            device: format!("{} {}", std::env::consts::OS, std::env::consts::ARCH),
            iterations: r.iterations,
            model_load_us: r.load_us,
            stages: r
                .stages
                .into_iter()
                .map(|s| StageStat {
                    name: s.name,
                    median_us: s.median_us,
                    p90_us: s.p90_us,
                    mean_us: s.mean_us,
                })
                .collect(),
        })
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::types::PixelFormat;
    use monotrack_core::camera::Rotation;

    /// A packed 8-bit frame of `w`×`h` turned by `rotation` (then mirrored).
    pub(crate) fn gray_desc(w: usize, h: usize, rotation: u32, mirrored: bool) -> FrameDesc {
        FrameDesc {
            width: w as u32,
            height: h as u32,
            format: PixelFormat::Gray8,
            row_stride: w as u32,
            uv_row_stride: 0,
            uv_pixel_stride: 0,
            rotation_degrees: rotation,
            mirrored,
        }
    }

    /// The upright test picture: the sample face cropped to a landscape 512×400 (so quarter turns
    /// swap the axes).
    pub(crate) fn upright_face() -> (Vec<u8>, usize, usize) {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/data/astronaut.jpg");
        let img = image::open(path).unwrap().to_luma8();
        let (w, h) = (512usize, 400usize);
        let mut out = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                out[y * w + x] = img.get_pixel(x as u32, (y + 40) as u32)[0];
            }
        }
        (out, w, h)
    }

    /// The sensor buffer that `rotation` then `mirrored` make into `upright` (the inverse of
    /// `Frame::to_luma`'s mapping), with its width and height.
    fn sensor_buffer(
        upright: &[u8],
        uw: usize,
        uh: usize,
        rotation: u32,
        mirrored: bool,
    ) -> (Vec<u8>, usize, usize) {
        let (bw, bh) = if rotation % 180 == 90 {
            (uh, uw)
        } else {
            (uw, uh)
        };
        let mut buf = vec![0u8; bw * bh];
        for oy in 0..uh {
            for ox in 0..uw {
                let cx = if mirrored { uw - 1 - ox } else { ox };
                let (x, y) = match rotation {
                    0 => (cx, oy),
                    90 => (oy, bh - 1 - cx),
                    180 => (bw - 1 - cx, bh - 1 - oy),
                    _ => (bw - 1 - oy, cx),
                };
                buf[y * bw + x] = upright[oy * uw + ox];
            }
        }
        (buf, bw, bh)
    }

    fn pose_of(
        buf: &[u8],
        w: usize,
        h: usize,
        rotation: u32,
        mirrored: bool,
        k: Intrinsics,
    ) -> HeadPose {
        let config = TrackerConfig {
            camera: Some(CameraIntrinsics {
                fx: k.fx,
                fy: k.fy,
                cx: k.cx,
                cy: k.cy,
            }),
            ..default_tracker_config()
        };
        let tracker = FaceTracker::new(config).unwrap();
        let desc = gray_desc(w, h, rotation, mirrored);
        let r = tracker.process_frame(buf, desc, 1).unwrap();
        assert_eq!(r.faces.len(), 1, "rotation {rotation} mirrored {mirrored}");
        r.faces[0].pose.clone()
    }

    /// The same scene delivered in each of the four sensor orientations, mirrored or not, with the
    /// sensor's intrinsics for each buffer, gives the same pose in the upright camera frame.
    #[test]
    fn sensor_intrinsics_turn_with_the_frame() {
        let (upright, uw, uh) = upright_face();
        // Off-centre and non-square on purpose: a convention slip moves the pose.
        let k_upright = Intrinsics {
            fx: 520.0,
            fy: 545.0,
            cx: 0.42 * uw as f64,
            cy: 0.58 * uh as f64,
        };
        let reference = pose_of(&upright, uw, uh, 0, false, k_upright);
        for rotation in [0u32, 90, 180, 270] {
            for mirrored in [false, true] {
                let (buf, bw, bh) = sensor_buffer(&upright, uw, uh, rotation, mirrored);
                let rot = Rotation::from_degrees(rotation as i32).unwrap();
                let undo = Rotation::from_degrees(360 - rotation as i32).unwrap();
                let m = if mirrored {
                    k_upright.mirrored(uw as u32)
                } else {
                    k_upright
                };
                // The sensor's intrinsics: the upright ones taken back through the mirror and turn.
                let k_sensor = m.rotated(uw as u32, uh as u32, undo);
                let back = k_sensor.for_upright(bw as u32, bh as u32, rot, mirrored);
                for (a, b) in [
                    (back.fx, k_upright.fx),
                    (back.fy, k_upright.fy),
                    (back.cx, k_upright.cx),
                    (back.cy, k_upright.cy),
                ] {
                    assert!((a - b).abs() < 1e-9, "{rotation} {mirrored}: {back:?}");
                }
                let pose = pose_of(&buf, bw, bh, rotation, mirrored, k_sensor);
                let t = |p: &HeadPose| [p.translation_mm.x, p.translation_mm.y, p.translation_mm.z];
                for (a, b) in t(&pose).iter().zip(t(&reference)) {
                    assert!((a - b).abs() < 1e-3, "{rotation} {mirrored}: t {a} vs {b}");
                }
                for (a, b) in pose.rotation.iter().zip(&reference.rotation) {
                    assert!((a - b).abs() < 1e-6, "{rotation} {mirrored}: R {a} vs {b}");
                }
                if rotation == 90 && !mirrored {
                    // Passing the upright intrinsics as if they were the sensor's (the mistake the
                    // convention exists to prevent) moves the face by millimetres.
                    let wrong = pose_of(&buf, bw, bh, rotation, mirrored, k_upright);
                    let d = t(&wrong)
                        .iter()
                        .zip(t(&reference))
                        .map(|(a, b)| (a - b).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    assert!(d > 1.0, "the test cannot tell conventions apart: {d} mm");
                }
            }
        }
    }

    /// The posed vertices project onto the landmarks (within the fit's error), and the mesh
    /// indexes them.
    #[test]
    fn vertices_and_mesh_overlay_the_face() {
        let (upright, w, h) = upright_face();
        let k = Intrinsics::default_for(w as u32, h as u32).unwrap();
        let face = {
            let tracker = FaceTracker::new(default_tracker_config()).unwrap();
            let desc = gray_desc(w, h, 0, false);
            tracker.process_frame(&upright, desc, 1).unwrap().faces[0].clone()
        };
        assert_eq!(face.vertices_mm.len(), 68);
        let se: f64 = face
            .vertices_mm
            .iter()
            .zip(&face.landmarks)
            .map(|(v, l)| {
                let (u, vv) = k.project(v.x, v.y, v.z);
                (u - f64::from(l.x)).powi(2) + (vv - f64::from(l.y)).powi(2)
            })
            .sum();
        let rms = (se / 68.0).sqrt();
        assert!(
            rms < 2.0 * face.fit_rms_px + 0.5 && rms < 8.0,
            "rms {rms} px, fit {}",
            face.fit_rms_px
        );
        let mesh = face_mesh_triangles();
        assert!(mesh.len() >= 90 * 3 && mesh.len().is_multiple_of(3));
        assert!(mesh.iter().all(|&i| i < 68));
    }

    /// The output toggles: off, the face carries no gestures, gaze or action units and taps are
    /// refused, while the landmarks, pose and shape stay those of the full tracker (the
    /// expressions' solves only move the action units and, through them, the fit a little).
    #[test]
    fn output_toggles_leave_their_fields_out() {
        let (upright, w, h) = upright_face();
        let desc = gray_desc(w, h, 0, false);
        let full = FaceTracker::new(default_tracker_config()).unwrap();
        let want = full.process_frame(&upright, desc, 1).unwrap().faces[0].clone();
        let lean = FaceTracker::new(TrackerConfig {
            gestures: false,
            gaze: false,
            expressions: false,
            ..default_tracker_config()
        })
        .unwrap();
        let screen = crate::gaze::screen_target("phone".into(), 70.0, 150.0, 35.0, -8.0).unwrap();
        lean.set_gaze_targets(vec![screen]).unwrap();
        let f = lean.process_frame(&upright, desc, 1).unwrap().faces[0].clone();
        assert!(f.gestures.is_none() && f.gaze.is_none() && f.point_of_gaze.is_none());
        assert!(f.action_units.is_none());
        assert!(want.gestures.is_some() && want.point_of_gaze.is_some());
        assert!(want.action_units.is_some());
        assert_eq!(f.landmarks, want.landmarks);
        assert!(
            (f.pose.yaw_deg - want.pose.yaw_deg).abs() < 3.0,
            "{:?}",
            f.pose
        );
        let (z, want_z) = (f.pose.translation_mm.z, want.pose.translation_mm.z);
        assert!((z - want_z).abs() < 0.05 * want_z, "{z} vs {want_z} mm");
        let tap = PlanePoint {
            u_mm: 35.0,
            v_mm: 50.0,
        };
        assert!(matches!(
            lean.add_calibration_point("phone".into(), tap, 1),
            Err(MonotrackError::InvalidConfig { .. })
        ));
    }

    /// In the image running mode stills go through the one tracker built: no second one.
    #[test]
    fn the_redetection_bar_follows_the_detection_bar() {
        let (core, _) = to_core(&default_tracker_config()).unwrap();
        assert_eq!(
            core.min_redetection_confidence,
            core_track::DEFAULT_MIN_REDETECTION_CONFIDENCE
        );
        let strict = TrackerConfig {
            min_detection_confidence: 0.99,
            ..default_tracker_config()
        };
        let (core, _) = to_core(&strict).unwrap();
        assert!(core.min_redetection_confidence > 0.8 && core.min_redetection_confidence < 0.99);
        let (core, _) = to_core(&ultra_light_tracker_config()).unwrap();
        assert_eq!(core.min_redetection_confidence, 0.0);
    }

    #[test]
    fn image_mode_builds_one_tracker() {
        let (upright, w, h) = upright_face();
        let tracker = FaceTracker::new(TrackerConfig {
            running_mode: RunningMode::Image,
            ..default_tracker_config()
        })
        .unwrap();
        let r = tracker
            .process_image(&upright, gray_desc(w, h, 0, false))
            .unwrap();
        assert_eq!(r.faces.len(), 1);
        assert!(tracker.lock().stills.is_none());
    }

    /// The ultra-light tracker finds and follows the face without M3: 27 landmarks with a
    /// confidence, the rest 0, a pose from FFBP near the full pipeline's (same face, within a
    /// quarter of its distance and 20° of yaw/pitch/roll), and the M3-only outputs at rest.
    #[test]
    fn ultra_light_tracker_follows_the_face() {
        let (upright, w, h) = upright_face();
        let desc = gray_desc(w, h, 0, false);
        let full = FaceTracker::new(default_tracker_config()).unwrap();
        let want = full.process_frame(&upright, desc, 1).unwrap().faces[0].clone();
        let config = ultra_light_tracker_config();
        assert!(config.ultra_light && !default_tracker_config().ultra_light);
        let light = FaceTracker::new(config).unwrap();
        for ts in 1..=3 {
            let r = light.process_frame(&upright, desc, ts).unwrap();
            assert_eq!(r.faces.len(), 1, "frame {ts}");
            let f = &r.faces[0];
            let measured = f.landmark_confidence.iter().filter(|&&c| c > 0.0).count();
            assert!((20..=27).contains(&measured), "{measured} points measured");
            assert!(
                f.landmark_confidence
                    .iter()
                    .all(|c| (0.0..=1.0).contains(c))
            );
            let (t, u) = (&f.pose.translation_mm, &want.pose.translation_mm);
            let d = ((t.x - u.x).powi(2) + (t.y - u.y).powi(2) + (t.z - u.z).powi(2)).sqrt();
            let dist = (u.x * u.x + u.y * u.y + u.z * u.z).sqrt();
            assert!(d < 0.25 * dist, "frame {ts}: {t:?} vs {u:?}");
            for (a, b) in [
                (f.pose.yaw_deg, want.pose.yaw_deg),
                (f.pose.pitch_deg, want.pose.pitch_deg),
                (f.pose.roll_deg, want.pose.roll_deg),
            ] {
                assert!(
                    (a - b).abs() < 20.0,
                    "frame {ts}: {:?} vs {:?}",
                    f.pose,
                    want.pose
                );
            }
            assert!(f.gestures.is_none() && f.gaze.is_none() && f.point_of_gaze.is_none());
            assert!(f.action_units.is_none());
        }
        assert_eq!(want.landmark_confidence, vec![1.0; 68]);
    }

    /// One tracker shared by threads (uniffi objects are shared across threads): stills always
    /// find the face, video calls succeed or report a timestamp that lost the race, nothing else.
    #[test]
    fn one_tracker_serves_several_threads() {
        let (upright, w, h) = upright_face();
        let tracker = FaceTracker::new(default_tracker_config()).unwrap();
        let desc = gray_desc(w, h, 0, false);
        let clock = std::sync::atomic::AtomicI64::new(0);
        std::thread::scope(|scope| {
            for t in 0..4u32 {
                let (tracker, upright, clock) = (&tracker, &upright, &clock);
                scope.spawn(move || {
                    for _ in 0..3 {
                        if t.is_multiple_of(2) {
                            let r = tracker.process_image(upright, desc).unwrap();
                            assert_eq!(r.faces.len(), 1);
                        } else {
                            let ts =
                                clock.fetch_add(1_000_000, std::sync::atomic::Ordering::SeqCst);
                            match tracker.process_frame(upright, desc, ts + 1) {
                                Ok(r) => assert_eq!(r.faces.len(), 1),
                                Err(MonotrackError::InvalidFrame { msg }) => {
                                    assert!(msg.contains("increasing"), "{msg}")
                                }
                                Err(e) => panic!("{e}"),
                            }
                        }
                    }
                });
            }
        });
    }

    /// Targets set on the tracker: each face carries its point of gaze; a tap teaches the
    /// correction, after which the same view lands on the tapped point.
    #[test]
    fn gaze_lands_on_targets_and_a_tap_calibrates_it() {
        let (upright, w, h) = upright_face();
        let tracker = FaceTracker::new(default_tracker_config()).unwrap();
        let desc = gray_desc(w, h, 0, false);
        let screen = crate::gaze::screen_target("phone".into(), 70.0, 150.0, 35.0, -8.0).unwrap();
        tracker.set_gaze_targets(vec![screen]).unwrap();
        let ms = 1_000_000;
        let f = tracker
            .process_frame(&upright, desc, 10 * ms)
            .unwrap()
            .faces[0]
            .clone();
        let g = f.point_of_gaze.as_ref().unwrap();
        assert!((200.0..3000.0).contains(&g.origin_mm.z), "{g:?}");
        let d = &g.direction;
        assert!(((d.x * d.x + d.y * d.y + d.z * d.z).sqrt() - 1.0).abs() < 1e-9);
        let hit = g.target.as_ref().unwrap();
        assert_eq!(hit.nearest, "phone");
        // The origin lies between the fitted eyes: on the face, above the nose tip's height.
        assert!(g.origin_mm.y < f.vertices_mm[30].y, "{g:?}");
        assert!(matches!(
            tracker.add_calibration_point(
                "tv".into(),
                PlanePoint {
                    u_mm: 1.0,
                    v_mm: 1.0
                },
                10 * ms
            ),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        assert!(matches!(
            tracker.add_calibration_point(
                "phone".into(),
                PlanePoint {
                    u_mm: 1.0,
                    v_mm: 1.0
                },
                900 * ms
            ),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        let tap = PlanePoint {
            u_mm: 35.0,
            v_mm: 50.0,
        };
        assert_eq!(
            tracker
                .add_calibration_point("phone".into(), tap, 12 * ms)
                .unwrap(),
            1
        );
        let after = tracker
            .process_frame(&upright, desc, 43 * ms)
            .unwrap()
            .faces[0]
            .clone();
        let h = after.point_of_gaze.unwrap().target.unwrap();
        let miss = ((h.point.u_mm - tap.u_mm).powi(2) + (h.point.v_mm - tap.v_mm).powi(2)).sqrt();
        assert!(h.hit && miss < 10.0, "{h:?}: {miss} mm from the tap");
        tracker.reset_gaze_calibration();
        // Targets can be cleared; a bad one is refused.
        tracker.set_gaze_targets(vec![]).unwrap();
        let r = tracker.process_frame(&upright, desc, 76 * ms).unwrap();
        assert!(r.faces[0].point_of_gaze.as_ref().unwrap().target.is_none());
        let flat = crate::gaze::GazeTarget {
            id: "flat".into(),
            corners_mm: vec![
                Vec3 {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0
                };
                3
            ],
        };
        assert!(matches!(
            tracker.set_gaze_targets(vec![flat]),
            Err(MonotrackError::InvalidConfig { .. })
        ));
    }
}
