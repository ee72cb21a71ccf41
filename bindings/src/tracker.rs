//! The `FaceTracker` object (`bindings/API.md`): one tracker for the three running modes — the
//! core's `Tracker` behind a Mutex for stills and video (uniffi objects are shared across threads),
//! the core's `LiveStream` for the live stream — its result records, and the shared benchmarks
//! (`monotrack_core::bench`) for the device benchmark apps.

use crate::MonotrackError;
use crate::error::{guard, guard_infallible};
use crate::gaze::{GazeTarget, PlanePoint, PointOfGaze};
use crate::live::{Forward, LiveStreamListener};
use crate::options::{FaceTrackerOptions, Outputs, RunningMode, build_tracker};
use crate::types::{
    ActionUnits, CameraIntrinsics, FaceQuality, FrameDesc, HeadPose, Point2, PoseUncertainty,
    QualityReason, ShapeUnits, Vec3,
};
use monotrack_core::camera::Intrinsics;
use monotrack_core::gaze::Target;
use monotrack_core::image::{Frame, FrameDesc as CoreFrameDesc, Rect as CoreRect};
use monotrack_core::landmarks::eyes::eye_openness;
use monotrack_core::model::FaceModel;
use monotrack_core::record::{ModelIdentity, RecordingSwitch, RecordingTracker};
use monotrack_core::track::live::{LiveStream, Submitted};
use monotrack_core::track::{self as core_track, TrackedFace};
use std::sync::{Arc, Mutex, MutexGuard};

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

/// Gesture probabilities (mouth: smile, kiss, neutral; brows: raise, frown, neutral). The mouth
/// heads' "frown" class is not reported: on the validation faces it is never told apart
/// (`core/models/MODEL_CARD.md`, "Gestures"); its probability stays inside `mouth_neutral`.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct Gestures {
    /// Smile.
    pub smile: f32,
    /// Kiss (pucker).
    pub kiss: f32,
    /// Neutral mouth (including the untold frown class).
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

/// How open each of the subject's own eyes is, 0 (closed) ..= 1 (open), from the eyelid
/// landmarks (`monotrack_core::landmarks::eye_openness`; ML Kit's eye-open probabilities,
/// 1 − ARKit's / MediaPipe's `eyeBlinkLeft/Right`). The subject's left eye is on the image's right
/// for an unmirrored frame.
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct EyeOpenness {
    /// The subject's left eye.
    pub left_open: f32,
    /// The subject's right eye.
    pub right_open: f32,
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
    /// The ultra-light mode only: per landmark, 0..1, the gradient detector's confidence, 0 for
    /// the points it does not measure. `None` with M3, which measures every point.
    pub landmark_confidence: Option<Vec<f32>>,
    /// How open each eye is; `None` in the ultra-light mode, which does not measure the eyelids.
    pub eyes: Option<EyeOpenness>,
    /// Gestures; `None` when `output_gestures` is off or in the ultra-light mode.
    pub gestures: Option<Gestures>,
    /// M3's gaze directions; `None` when `output_gaze` is off or in the ultra-light mode.
    pub gaze: Option<Gaze>,
    /// Head pose: zero yaw, pitch and roll is a face looking straight into the camera, upright.
    pub pose: HeadPose,
    /// How far to trust `pose`: standard deviations of its angles and translation.
    pub uncertainty: PoseUncertainty,
    /// How good the face is for tracking, and the reasons that make it worse (for guiding the
    /// user: "more light", "come closer", "hold still").
    pub quality: FaceQuality,
    /// The 4×4 head-to-camera transform, row-major: `[R | t; 0 0 0 1]` with `pose`'s rotation and
    /// translation (mm), OpenCV camera axes (x right, y down, z forward). `opengl_transform` turns
    /// it into OpenGL / ARKit / SceneKit axes. `None` when
    /// `output_facial_transformation_matrixes` is off.
    pub transform: Option<Vec<f64>>,
    /// The 11 shape units.
    pub shape_units: ShapeUnits,
    /// The 6 action (animation) units; `None` when `output_action_units` is off or in the
    /// ultra-light mode.
    pub action_units: Option<ActionUnits>,
    /// Where the face looks: the gaze ray from between the eyes, and the target it lands on when
    /// targets are set (`FaceTracker::set_gaze_targets`); `None` when `output_gaze` is off or in
    /// the ultra-light mode.
    pub point_of_gaze: Option<PointOfGaze>,
    /// The fitted face model's 68 vertices (iBUG order, the landmarks' points on the 3D face),
    /// camera frame, millimetres: with `face_mesh_triangles()` and the result's `camera`, the mesh
    /// an AR overlay draws over the upright image.
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
    fn from_tracked(f: &TrackedFace, targets: &[Target], out: Outputs, ultra_light: bool) -> Self {
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
            landmark_confidence: ultra_light.then(|| l.weights.to_vec()),
            eyes: (!ultra_light).then(|| {
                let e = eye_openness(&l.points);
                EyeOpenness {
                    left_open: e.left,
                    right_open: e.right,
                }
            }),
            gestures: out.gestures.then(|| Gestures {
                smile: l.mouth[0],
                kiss: l.mouth[2],
                mouth_neutral: l.mouth[1] + l.mouth[3],
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
            uncertainty: PoseUncertainty::from(&f.fit.uncertainty),
            quality: FaceQuality::from(&f.quality),
            transform: out.transform.then(|| f.fit.pose.transform().to_vec()),
            shape_units: ShapeUnits::from(&f.fit.shape[..]),
            action_units: out
                .action_units
                .then(|| ActionUnits::from(&f.fit.animation[..])),
            point_of_gaze: f.gaze.as_ref().map(|g| PointOfGaze::from_core(g, targets)),
            vertices_mm: f
                .fit
                .posed_vertices()
                .iter()
                .map(|p| Vec3 {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                })
                .collect(),
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
    /// The intrinsics of the upright image the pose and vertices refer to (the options' camera
    /// turned with the frame, or `default_camera`): what an overlay projects with.
    pub camera: CameraIntrinsics,
    /// Faces, in a stable order while tracks last.
    pub faces: Vec<Face>,
    /// The frame's own quality reasons: its light and sharpness, `NoFace`, `Lost` (a dark frame
    /// with no face found still says `Dark`).
    pub reasons: Vec<QualityReason>,
    /// Per-stage timings.
    pub timings: StageTimings,
}

/// What a tracker's results carry, fixed at construction.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ResultShape {
    pub(crate) outputs: Outputs,
    pub(crate) ultra_light: bool,
    pub(crate) camera: Option<Intrinsics>,
}

impl From<&FaceTrackerOptions> for ResultShape {
    fn from(o: &FaceTrackerOptions) -> Self {
        Self {
            outputs: Outputs::from(o),
            ultra_light: o.tuning.ultra_light,
            camera: o.camera.map(Intrinsics::from),
        }
    }
}

pub(crate) fn result(
    r: &core_track::TrackingResult,
    frame: &CoreFrameDesc,
    targets: &[Target],
    shape: ResultShape,
) -> Result<TrackingResult, MonotrackError> {
    let t = &r.timings;
    let (w, h) = frame.upright_size();
    let camera = core_track::upright_intrinsics(shape.camera, frame)?;
    Ok(TrackingResult {
        frame_width: w as u32,
        frame_height: h as u32,
        camera: camera.into(),
        faces: r
            .faces
            .iter()
            .map(|f| Face::from_tracked(f, targets, shape.outputs, shape.ultra_light))
            .collect(),
        reasons: crate::types::reasons(r.reasons),
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
    })
}

/// What runs the frames: the tracker itself (image, video), or its worker (live stream).
enum Engine {
    /// The tracker, with its recorder (off until `start_recording`).
    Sync(Box<RecordingTracker>),
    Live {
        stream: LiveStream,
        /// The ids of the gaze targets set, in order (taps name their target by id).
        target_ids: Vec<String>,
        /// The recorder of the worker's tracker.
        recording: RecordingSwitch,
    },
}

/// The face tracker: one object for the three running modes (thread-safe: calls are serialised
/// by a Mutex; feed it from one camera thread).
#[derive(uniffi::Object)]
pub struct FaceTracker {
    options: FaceTrackerOptions,
    shape: ResultShape,
    /// `None` once shut down.
    engine: Mutex<Option<Engine>>,
}

/// A timestamp in milliseconds (MediaPipe's unit) as the core's nanoseconds.
fn nanoseconds(timestamp_ms: i64) -> Result<i64, MonotrackError> {
    timestamp_ms
        .checked_mul(1_000_000)
        .ok_or_else(|| MonotrackError::InvalidTimestamp {
            msg: format!("timestamp {timestamp_ms} ms is out of range"),
        })
}

impl FaceTracker {
    fn lock(&self) -> MutexGuard<'_, Option<Engine>> {
        // A panic inside a call (caught by `guard`) poisons the lock; the state may be
        // half-updated, so the tracks are dropped and the tracker goes on from a clean slate.
        match self.engine.lock() {
            Ok(g) => g,
            Err(poisoned) => {
                let mut g = poisoned.into_inner();
                match g.as_mut() {
                    Some(Engine::Sync(t)) => t.reset(),
                    Some(Engine::Live { stream, .. }) => stream.reset(),
                    None => {}
                }
                self.engine.clear_poison();
                g
            }
        }
    }

    /// The mode a call needs, or `InvalidState` naming the tracker's.
    fn expect_mode(&self, call: &str, want: RunningMode) -> Result<(), MonotrackError> {
        let mode = self.options.mode();
        if mode == want {
            Ok(())
        } else {
            Err(MonotrackError::InvalidState {
                msg: format!(
                    "{call} needs the {want:?} running mode; this tracker runs in {mode:?}"
                ),
            })
        }
    }

    /// Runs `call` on the synchronous tracker, or says why it cannot.
    /// The switch of the tracker's recorder, or `InvalidState` after `shutdown`.
    pub(crate) fn recording(&self) -> Result<RecordingSwitch, MonotrackError> {
        match self.lock().as_ref() {
            Some(Engine::Sync(t)) => Ok(t.switch()),
            Some(Engine::Live { recording, .. }) => Ok(recording.clone()),
            None => Err(shut_down()),
        }
    }

    fn with_sync<T>(
        &self,
        call: impl FnOnce(&mut RecordingTracker) -> Result<T, MonotrackError>,
    ) -> Result<T, MonotrackError> {
        match self.lock().as_mut() {
            Some(Engine::Sync(t)) => call(t),
            Some(Engine::Live { .. }) => Err(MonotrackError::Internal {
                msg: "a synchronous call reached the live stream".into(),
            }),
            None => Err(shut_down()),
        }
    }

    fn track(
        &self,
        bytes: &[u8],
        desc: FrameDesc,
        timestamp_ns: i64,
    ) -> Result<TrackingResult, MonotrackError> {
        let frame = Frame::new(bytes, desc.try_into()?)?;
        self.with_sync(|t| {
            t.process_frame(&frame, timestamp_ns)?;
            let t = t.tracker();
            result(t.result(), frame.desc(), t.gaze_targets(), self.shape)
        })
    }
}

fn shut_down() -> MonotrackError {
    MonotrackError::InvalidState {
        msg: "the tracker was shut down".into(),
    }
}

#[uniffi::export]
impl FaceTracker {
    /// Loads the models and builds a tracker; in the live-stream mode starts its worker, which
    /// delivers to `listener`.
    ///
    /// # Errors
    /// `InvalidConfig` for out-of-range options, a live-stream tracker without a listener or a
    /// listener in another mode; `ModelLoad` if the models cannot load; `Internal` if no thread
    /// can be started.
    #[uniffi::constructor(default(listener = None))]
    pub fn new(
        options: FaceTrackerOptions,
        listener: Option<Arc<dyn LiveStreamListener>>,
    ) -> Result<Arc<Self>, MonotrackError> {
        guard(|| {
            let models = options
                .models
                .as_ref()
                .map_or_else(ModelIdentity::builtin, |b| ModelIdentity::of(&b.inner));
            let tracker = RecordingTracker::new(build_tracker(&options)?, models);
            let shape = ResultShape::from(&options);
            let engine = match (options.mode(), listener) {
                (RunningMode::LiveStream, Some(listener)) => Engine::Live {
                    recording: tracker.switch(),
                    stream: LiveStream::start(tracker, Box::new(Forward::new(listener, shape)))?,
                    target_ids: Vec::new(),
                },
                (RunningMode::LiveStream, None) => {
                    return Err(MonotrackError::InvalidConfig {
                        msg: "the live-stream running mode needs a listener".into(),
                    });
                }
                (_, Some(_)) => {
                    return Err(MonotrackError::InvalidConfig {
                        msg: "a listener is for the live-stream running mode only".into(),
                    });
                }
                (_, None) => Engine::Sync(Box::new(tracker)),
            };
            Ok(Arc::new(Self {
                options,
                shape,
                engine: Mutex::new(Some(engine)),
            }))
        })
    }

    /// Image mode: the faces of one still (every call detects afresh).
    ///
    /// # Errors
    /// `InvalidFrame` when the description does not match the bytes; `InvalidState` in another
    /// mode or after `shutdown`.
    pub fn detect(&self, bytes: &[u8], desc: FrameDesc) -> Result<TrackingResult, MonotrackError> {
        guard(|| {
            self.expect_mode("detect", RunningMode::Image)?;
            self.track(bytes, desc, 0)
        })
    }

    /// Video mode: the faces of one frame taken at `timestamp_ms`, tracked from the frames before.
    ///
    /// # Errors
    /// `InvalidFrame` when the description does not match the bytes; `InvalidTimestamp` when
    /// `timestamp_ms` is not after the previous frame's (since the start or `reset`: a restarted
    /// camera needs a `reset`); `InvalidState` in another mode or after `shutdown`.
    pub fn detect_for_video(
        &self,
        bytes: &[u8],
        desc: FrameDesc,
        timestamp_ms: i64,
    ) -> Result<TrackingResult, MonotrackError> {
        guard(|| {
            self.expect_mode("detect_for_video", RunningMode::Video)?;
            self.track(bytes, desc, nanoseconds(timestamp_ms)?)
        })
    }

    /// Live-stream mode: hands one camera frame taken at `timestamp_ms` to the worker and returns
    /// without waiting (the bytes are copied, so the camera's buffer can be released on return).
    /// Its result, or its error, reaches the listener. While the worker is busy the newest frame
    /// waits and replaces an older waiting one. Returns `true` when this frame replaced one.
    ///
    /// # Errors
    /// `InvalidFrame` when the description does not match the bytes; `InvalidTimestamp` as
    /// `detect_for_video`; `InvalidState` in another mode or after `shutdown`.
    pub fn detect_async(
        &self,
        bytes: &[u8],
        desc: FrameDesc,
        timestamp_ms: i64,
    ) -> Result<bool, MonotrackError> {
        guard(|| {
            self.expect_mode("detect_async", RunningMode::LiveStream)?;
            let ts = nanoseconds(timestamp_ms)?;
            let frame = Frame::new(bytes, desc.try_into()?)?;
            match self.lock().as_ref() {
                Some(Engine::Live { stream, .. }) => {
                    Ok(stream.submit(&frame, ts)? == Submitted::Replaced)
                }
                Some(Engine::Sync(_)) => Err(MonotrackError::Internal {
                    msg: "a live-stream call reached a synchronous tracker".into(),
                }),
                None => Err(shut_down()),
            }
        })
    }

    /// Ends every track and forgets the user's shape and the timestamp history (a camera switch,
    /// a restarted camera, a new person); in the live-stream mode before the next frame, dropping
    /// one still waiting. Every mode.
    pub fn reset(&self) {
        guard_infallible(|| match self.lock().as_mut() {
            Some(Engine::Sync(t)) => t.reset(),
            Some(Engine::Live { stream, .. }) => stream.reset(),
            None => {}
        });
    }

    /// Stops the tracker and frees its models: in the live-stream mode a frame being tracked
    /// finishes and is delivered, a waiting one is dropped, and the listener is not called
    /// afterwards (called from the listener, it returns at once and the worker stops after that
    /// call). Idempotent; later calls are refused with `InvalidState`.
    pub fn shutdown(&self) {
        guard_infallible(|| {
            let taken = self.lock().take();
            // Dropped outside the lock: a live stream's drop waits for its worker.
            drop(taken);
        });
    }

    /// The options this tracker was built with.
    pub fn options(&self) -> FaceTrackerOptions {
        self.options.clone()
    }

    /// Sets the targets each face's point of gaze is located among (screens, mirrors, zones),
    /// replacing any before, from the next frame; an empty list turns location off. The tap
    /// calibration stays.
    ///
    /// # Errors
    /// `InvalidConfig` for a bad target (fewer than 3 corners, not planar, not finite) or a
    /// repeated id; `InvalidState` after `shutdown`.
    pub fn set_gaze_targets(&self, targets: Vec<GazeTarget>) -> Result<(), MonotrackError> {
        guard(|| {
            let core = crate::gaze::to_core(&targets)?;
            match self.lock().as_mut() {
                Some(Engine::Sync(t)) => t.set_gaze_targets(core),
                Some(Engine::Live {
                    stream, target_ids, ..
                }) => {
                    *target_ids = targets.iter().map(|t| t.id.clone()).collect();
                    stream.set_gaze_targets(core);
                }
                None => return Err(shut_down()),
            }
            Ok(())
        })
    }

    /// Tells the tracker the user looked at `point` on the target `target_id` at `timestamp_ms`
    /// (a tap or button press, in the frames' clock): the gaze of the frame nearest that time
    /// teaches a per-user correction, applied from the next frame. Returns the taps learnt from so
    /// far; `None` in the live-stream mode, where the worker learns the tap before its next frame
    /// and one it cannot use reaches the listener's `on_error` with the tap's time.
    ///
    /// # Errors
    /// `InvalidConfig` for an unknown target, a non-finite point or the gaze output off;
    /// `InvalidFrame` (video) when no frame with a face lies within 250 ms of the tap;
    /// `InvalidState` in the image mode or after `shutdown`.
    pub fn add_calibration_point(
        &self,
        target_id: String,
        point: PlanePoint,
        timestamp_ms: i64,
    ) -> Result<Option<u32>, MonotrackError> {
        guard(|| {
            if self.options.mode() == RunningMode::Image {
                return Err(MonotrackError::InvalidState {
                    msg: "taps calibrate a stream: the image running mode has none".into(),
                });
            }
            if !self.shape.outputs.gaze {
                return Err(MonotrackError::InvalidConfig {
                    msg: "the gaze output is off (output_gaze): taps cannot calibrate it".into(),
                });
            }
            let ts = nanoseconds(timestamp_ms)?;
            let at = [point.u_mm, point.v_mm];
            match self.lock().as_mut() {
                Some(Engine::Sync(t)) => {
                    let ids = t.tracker().gaze_targets().iter().map(|t| t.id.as_str());
                    let index = crate::gaze::tap_target(ids, &target_id, &point)?;
                    let n = t
                        .add_calibration_point(index, at, ts)
                        .map_err(crate::error::input_as_frame)?;
                    Ok(Some(n as u32))
                }
                Some(Engine::Live {
                    stream, target_ids, ..
                }) => {
                    let ids = target_ids.iter().map(String::as_str);
                    let index = crate::gaze::tap_target(ids, &target_id, &point)?;
                    stream.add_calibration_point(index, at, ts);
                    Ok(None)
                }
                None => Err(shut_down()),
            }
        })
    }

    /// Forgets the tap calibration (a new user); in the live-stream mode before the next frame
    /// (taps added after the call stay).
    pub fn reset_gaze_calibration(&self) {
        guard_infallible(|| match self.lock().as_mut() {
            Some(Engine::Sync(t)) => t.reset_gaze_calibration(),
            Some(Engine::Live { stream, .. }) => stream.reset_gaze_calibration(),
            None => {}
        });
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
    /// Building the tracker (loading and optimising the models), microseconds.
    pub model_load_us: f64,
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
            model_load_us: r.model_load_us,
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
    /// Faces found on the frame: a frame without one measures the empty stages (0 µs).
    pub faces: u32,
    /// Building the tracker (loading and optimising the embedded models), microseconds: what an
    /// app's `FaceTracker` constructor costs, and why it belongs off the main thread.
    pub model_load_us: f64,
    /// Per-stage statistics: the tracking path, then the re-detect path.
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
            faces: r.faces,
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
    use crate::options::{TrackerTuning, ultra_light_face_tracker_options};
    use crate::types::PixelFormat;

    /// The default options in the video running mode.
    pub(crate) fn video() -> FaceTrackerOptions {
        FaceTrackerOptions {
            running_mode: Some(RunningMode::Video),
            ..FaceTrackerOptions::default()
        }
    }

    pub(crate) fn tracker(options: FaceTrackerOptions) -> Arc<FaceTracker> {
        FaceTracker::new(options, None).unwrap()
    }
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
        let config = FaceTrackerOptions {
            camera: Some(CameraIntrinsics {
                fx: k.fx,
                fy: k.fy,
                cx: k.cx,
                cy: k.cy,
            }),
            ..video()
        };
        let tracker = tracker(config);
        let desc = gray_desc(w, h, rotation, mirrored);
        let r = tracker.detect_for_video(buf, desc, 1).unwrap();
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
        let r = tracker(video())
            .detect_for_video(&upright, gray_desc(w, h, 0, false), 1)
            .unwrap();
        assert_eq!(Intrinsics::from(r.camera), k, "the result names its camera");
        let face = r.faces[0].clone();
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
        assert!(rms < 8.0, "rms {rms} px");
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
        let full = tracker(video());
        let want = full.detect_for_video(&upright, desc, 1).unwrap().faces[0].clone();
        let lean = tracker(FaceTrackerOptions {
            output_gestures: false,
            output_gaze: false,
            output_action_units: false,
            output_facial_transformation_matrixes: false,
            ..video()
        });
        let screen = crate::gaze::screen_target("phone".into(), 70.0, 150.0, 35.0, -8.0).unwrap();
        lean.set_gaze_targets(vec![screen]).unwrap();
        let f = lean.detect_for_video(&upright, desc, 1).unwrap().faces[0].clone();
        assert!(f.gestures.is_none() && f.gaze.is_none() && f.point_of_gaze.is_none());
        assert!(f.action_units.is_none() && f.transform.is_none());
        assert!(want.gestures.is_some() && want.point_of_gaze.is_some());
        assert!(want.action_units.is_some() && want.transform.is_some());
        assert!(f.eyes.is_some() && f.landmark_confidence.is_none());
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

    /// Each mode has its call; another mode's call, and any call after `shutdown`, is refused
    /// with `InvalidState`, and the image mode needs no timestamps.
    #[test]
    fn each_running_mode_takes_its_own_call() {
        let (upright, w, h) = upright_face();
        let desc = gray_desc(w, h, 0, false);
        let stills = tracker(FaceTrackerOptions::default());
        assert_eq!(stills.options().mode(), RunningMode::Image);
        for _ in 0..2 {
            let r = stills.detect(&upright, desc).unwrap();
            assert_eq!(r.faces.len(), 1);
            assert_eq!(r.faces[0].state, FaceState::Detected);
        }
        assert!(matches!(
            stills.detect_for_video(&upright, desc, 1),
            Err(MonotrackError::InvalidState { .. })
        ));
        assert!(matches!(
            stills.detect_async(&upright, desc, 1),
            Err(MonotrackError::InvalidState { .. })
        ));
        let tap = PlanePoint {
            u_mm: 1.0,
            v_mm: 1.0,
        };
        assert!(matches!(
            stills.add_calibration_point("phone".into(), tap, 1),
            Err(MonotrackError::InvalidState { .. })
        ));
        let v = tracker(video());
        assert!(matches!(
            v.detect(&upright, desc),
            Err(MonotrackError::InvalidState { .. })
        ));
        v.shutdown();
        v.shutdown();
        assert!(matches!(
            v.detect_for_video(&upright, desc, 1),
            Err(MonotrackError::InvalidState { .. })
        ));
        v.reset();
        // A live stream needs a listener, and only it takes one.
        let live = FaceTrackerOptions {
            running_mode: Some(RunningMode::LiveStream),
            ..FaceTrackerOptions::default()
        };
        assert!(matches!(
            FaceTracker::new(live, None),
            Err(MonotrackError::InvalidConfig { .. })
        ));
    }

    /// A timestamp that does not increase is an error the app sees (nothing is tracked, no
    /// silent fix); `reset` starts the clock again, as after a camera restart.
    #[test]
    fn a_timestamp_that_does_not_increase_is_refused_until_reset() {
        let (upright, w, h) = upright_face();
        let desc = gray_desc(w, h, 0, false);
        let t = tracker(video());
        assert_eq!(
            t.detect_for_video(&upright, desc, 100).unwrap().faces.len(),
            1
        );
        for ts in [100, 99, -5] {
            assert!(matches!(
                t.detect_for_video(&upright, desc, ts),
                Err(MonotrackError::InvalidTimestamp { .. })
            ));
        }
        assert!(matches!(
            t.detect_for_video(&upright, desc, i64::MAX),
            Err(MonotrackError::InvalidTimestamp { .. })
        ));
        let r = t.detect_for_video(&upright, desc, 133).unwrap();
        assert_eq!(r.faces[0].state, FaceState::Tracked, "the stream goes on");
        t.reset();
        let r = t.detect_for_video(&upright, desc, 5).unwrap();
        assert_eq!(r.faces[0].state, FaceState::Detected, "tracks ended");
    }

    /// The transform is the pose as a matrix; eyes read open on the open-eyed sample face.
    #[test]
    fn transform_and_eyes_follow_the_pose_and_lids() {
        let (upright, w, h) = upright_face();
        let f = tracker(video())
            .detect_for_video(&upright, gray_desc(w, h, 0, false), 1)
            .unwrap()
            .faces[0]
            .clone();
        let m = f.transform.as_ref().unwrap();
        let p = &f.pose;
        for r in 0..3 {
            for c in 0..3 {
                assert_eq!(m[4 * r + c], p.rotation[3 * r + c]);
            }
        }
        let t = &p.translation_mm;
        assert_eq!((m[3], m[7], m[11]), (t.x, t.y, t.z));
        assert_eq!(&m[12..], &[0.0, 0.0, 0.0, 1.0]);
        let e = f.eyes.unwrap();
        assert!(e.left_open > 0.5 && e.right_open > 0.5, "{e:?}");
    }

    /// The ultra-light tracker finds and follows the face without M3: 27 landmarks with a
    /// confidence, the rest 0, a pose from FFBP near the full pipeline's (same face, within a
    /// quarter of its distance and 20° of yaw/pitch/roll), and the M3-only outputs at rest.
    #[test]
    fn ultra_light_tracker_follows_the_face() {
        let (upright, w, h) = upright_face();
        let desc = gray_desc(w, h, 0, false);
        let full = tracker(video());
        let want = full.detect_for_video(&upright, desc, 1).unwrap().faces[0].clone();
        let config = ultra_light_face_tracker_options(RunningMode::Video);
        assert!(config.tuning.ultra_light && !TrackerTuning::default().ultra_light);
        let light = tracker(config);
        for ts in 1..=3 {
            let r = light.detect_for_video(&upright, desc, ts).unwrap();
            assert_eq!(r.faces.len(), 1, "frame {ts}");
            let f = &r.faces[0];
            let confidence = f.landmark_confidence.as_ref().unwrap();
            let measured = confidence.iter().filter(|&&c| c > 0.0).count();
            assert!((20..=27).contains(&measured), "{measured} points measured");
            assert!(confidence.iter().all(|c| (0.0..=1.0).contains(c)));
            assert!(f.eyes.is_none());
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
        assert!(want.landmark_confidence.is_none());
    }

    /// One tracker shared by threads (uniffi objects are shared across threads): every call
    /// succeeds or reports a timestamp that lost the race, nothing else.
    #[test]
    fn one_tracker_serves_several_threads() {
        let (upright, w, h) = upright_face();
        let tracker = tracker(video());
        let desc = gray_desc(w, h, 0, false);
        let clock = std::sync::atomic::AtomicI64::new(0);
        std::thread::scope(|scope| {
            for _ in 0..4u32 {
                let (tracker, upright, clock) = (&tracker, &upright, &clock);
                scope.spawn(move || {
                    for _ in 0..3 {
                        let ts = clock.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                        match tracker.detect_for_video(upright, desc, ts + 1) {
                            Ok(r) => assert_eq!(r.faces.len(), 1),
                            Err(MonotrackError::InvalidTimestamp { msg }) => {
                                assert!(msg.contains("increasing"), "{msg}")
                            }
                            Err(e) => panic!("{e}"),
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
        let tracker = tracker(video());
        let desc = gray_desc(w, h, 0, false);
        let screen = crate::gaze::screen_target("phone".into(), 70.0, 150.0, 35.0, -8.0).unwrap();
        tracker.set_gaze_targets(vec![screen]).unwrap();
        let ms = 1;
        let f = tracker
            .detect_for_video(&upright, desc, 10 * ms)
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
            Some(1)
        );
        let after = tracker
            .detect_for_video(&upright, desc, 43 * ms)
            .unwrap()
            .faces[0]
            .clone();
        let h = after.point_of_gaze.unwrap().target.unwrap();
        let miss = ((h.point.u_mm - tap.u_mm).powi(2) + (h.point.v_mm - tap.v_mm).powi(2)).sqrt();
        assert!(h.hit && miss < 10.0, "{h:?}: {miss} mm from the tap");
        tracker.reset_gaze_calibration();
        // Targets can be cleared; a bad one is refused.
        tracker.set_gaze_targets(vec![]).unwrap();
        let r = tracker.detect_for_video(&upright, desc, 76 * ms).unwrap();
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
