//! Live-stream mode (`bindings/API.md`): `LiveFaceTracker` takes camera frames without waiting for
//! them to be tracked and delivers results to a `LiveStreamListener` the app implements, from one
//! worker thread (`monotrack_core::track::live`).

use crate::MonotrackError;
use crate::error::{guard, guard_infallible};
use crate::gaze::{GazeTarget, PlanePoint};
use crate::tracker::{Outputs, TrackerConfig, TrackingResult, build_tracker, result};
use crate::types::FrameDesc;
use monotrack_core::gaze::Target;
use monotrack_core::image::{Frame, FrameDesc as CoreFrameDesc};
use monotrack_core::track::live::{LiveListener, LiveStream, Submitted};
use monotrack_core::track::{self as core_track};
use std::sync::{Arc, Mutex};

/// One live-stream result.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct LiveStreamResult {
    /// The timestamp the frame was submitted with.
    pub timestamp_ns: i64,
    /// Frames submitted since the previous delivery that were skipped because the tracker was
    /// busy (the newest frame is never the one skipped).
    pub frames_dropped: u64,
    /// The frame's faces.
    pub result: TrackingResult,
}

/// Receives a `LiveFaceTracker`'s results, implemented by the app. Calls come from the tracker's
/// worker thread, one at a time, in timestamp order; a slow listener makes the tracker skip
/// frames, so hand the result to the UI thread and return. An exception thrown here is caught and
/// does not stop the stream.
#[uniffi::export(with_foreign)]
pub trait LiveStreamListener: Send + Sync {
    /// The faces of one frame.
    fn on_result(&self, result: LiveStreamResult);
    /// Tracking the frame taken at `timestamp_ns` failed, or a tap at that time could not be used
    /// (`LiveFaceTracker::add_calibration_point`); the stream goes on with the next frame.
    fn on_error(&self, timestamp_ns: i64, frames_dropped: u64, error: MonotrackError);
}

/// Hands the core's deliveries to the app's listener as FFI records with the config's outputs.
struct Forward(Arc<dyn LiveStreamListener>, Outputs);

impl LiveListener for Forward {
    fn on_result(
        &mut self,
        timestamp_ns: i64,
        frames_dropped: u64,
        frame: &CoreFrameDesc,
        r: &core_track::TrackingResult,
        targets: &[Target],
    ) {
        let (w, h) = frame.upright_size();
        self.0.on_result(LiveStreamResult {
            timestamp_ns,
            frames_dropped,
            result: result(r, w as u32, h as u32, targets, self.1),
        });
    }

    fn on_error(&mut self, timestamp_ns: i64, frames_dropped: u64, error: monotrack_core::Error) {
        // As `FaceTracker`'s calls: what the input of a frame or a tap could not give (a frame
        // the tracker refuses, a tap with no face near its time) is `InvalidFrame`.
        let error = match error {
            monotrack_core::Error::InvalidInput(msg) => MonotrackError::InvalidFrame { msg },
            e => e.into(),
        };
        self.0.on_error(timestamp_ns, frames_dropped, error);
    }
}

/// The face tracker in live-stream mode: `process_async` copies the frame and returns at once;
/// one worker thread tracks (as in video mode) and calls the listener. While it is busy the newest
/// frame waits and replaces any older waiting one (latest wins).
#[derive(uniffi::Object)]
pub struct LiveFaceTracker {
    config: TrackerConfig,
    /// The ids of the gaze targets set, in order (taps name their target by id).
    target_ids: Mutex<Vec<String>>,
    /// `None` once shut down.
    stream: Mutex<Option<LiveStream>>,
}

#[uniffi::export]
impl LiveFaceTracker {
    /// Loads the models and starts the worker. `config.running_mode` is not read: a live stream
    /// always tracks between frames.
    ///
    /// # Errors
    /// `InvalidConfig` for out-of-range settings, `ModelLoad` if the embedded models cannot load,
    /// `Internal` if no thread can be started.
    #[uniffi::constructor]
    pub fn new(
        config: TrackerConfig,
        listener: Arc<dyn LiveStreamListener>,
    ) -> Result<Arc<Self>, MonotrackError> {
        guard(|| {
            let video = TrackerConfig {
                running_mode: crate::tracker::RunningMode::Video,
                ..config
            };
            let tracker = build_tracker(&video, false)?;
            let stream =
                LiveStream::start(tracker, Box::new(Forward(listener, Outputs::from(&config))))?;
            Ok(Arc::new(Self {
                config,
                target_ids: Mutex::new(Vec::new()),
                stream: Mutex::new(Some(stream)),
            }))
        })
    }

    /// Submits one camera frame taken at `timestamp_ns` (strictly increasing) and returns without
    /// waiting: the bytes are copied, so the camera's buffer can be released on return. Returns
    /// `true` when a frame that was still waiting has been replaced by this one.
    ///
    /// # Errors
    /// `InvalidFrame` when the description does not match the bytes, the timestamp does not
    /// increase, or the tracker was shut down.
    pub fn process_async(
        &self,
        bytes: &[u8],
        desc: FrameDesc,
        timestamp_ns: i64,
    ) -> Result<bool, MonotrackError> {
        guard(|| {
            let frame = Frame::new(bytes, desc.try_into()?)?;
            let g = self.stream.lock().unwrap_or_else(|p| p.into_inner());
            let stream = g.as_ref().ok_or_else(|| MonotrackError::InvalidFrame {
                msg: "the live tracker was shut down".into(),
            })?;
            match stream.submit(&frame, timestamp_ns) {
                Ok(s) => Ok(s == Submitted::Replaced),
                Err(monotrack_core::Error::InvalidInput(msg)) => {
                    Err(MonotrackError::InvalidFrame { msg })
                }
                Err(e) => Err(e.into()),
            }
        })
    }

    /// Stops the worker: a frame being tracked finishes and is delivered, a waiting one is
    /// dropped, and the listener is not called afterwards. Idempotent; later frames are refused.
    /// Called from the listener itself, it returns at once and the worker stops after that call.
    pub fn shutdown(&self) {
        guard_infallible(|| {
            let taken = self.stream.lock().unwrap_or_else(|p| p.into_inner()).take();
            // Dropped outside the lock: the drop waits for the worker.
            drop(taken);
        });
    }

    /// The settings this tracker was built with.
    pub fn config(&self) -> TrackerConfig {
        self.config
    }

    /// Sets the gaze targets (as `FaceTracker::set_gaze_targets`), from the next frame the
    /// worker takes.
    ///
    /// # Errors
    /// `InvalidConfig` for a bad target or a repeated id.
    pub fn set_gaze_targets(&self, targets: Vec<GazeTarget>) -> Result<(), MonotrackError> {
        guard(|| {
            let core = crate::gaze::to_core(&targets)?;
            *self.target_ids.lock().unwrap_or_else(|p| p.into_inner()) =
                targets.iter().map(|t| t.id.clone()).collect();
            if let Some(s) = self
                .stream
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .as_ref()
            {
                s.set_gaze_targets(core);
            }
            Ok(())
        })
    }

    /// Tells the tracker the user looked at `point` on the target `target_id` at `timestamp_ns`
    /// (as `FaceTracker::add_calibration_point`, in the frames' clock). The tap is learnt on the
    /// worker before the next frame; one it cannot use (no frame with a face within 250 ms of
    /// it) reaches the listener's `on_error` with the tap's timestamp.
    ///
    /// # Errors
    /// `InvalidConfig` for an unknown target, a non-finite point, or the gaze output turned off
    /// (`TrackerConfig.gaze`); `InvalidFrame` once shut down.
    pub fn add_calibration_point(
        &self,
        target_id: String,
        point: PlanePoint,
        timestamp_ns: i64,
    ) -> Result<(), MonotrackError> {
        guard(|| {
            if !Outputs::from(&self.config).gaze() {
                return Err(MonotrackError::InvalidConfig {
                    msg: "the gaze output is off (TrackerConfig.gaze): taps cannot calibrate it"
                        .into(),
                });
            }
            let index = crate::gaze::tap_target(
                self.target_ids
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .iter()
                    .map(String::as_str),
                &target_id,
                &point,
            )?;
            let g = self.stream.lock().unwrap_or_else(|p| p.into_inner());
            let stream = g.as_ref().ok_or_else(|| MonotrackError::InvalidFrame {
                msg: "the live tracker was shut down".into(),
            })?;
            stream.add_calibration_point(index, [point.u_mm, point.v_mm], timestamp_ns);
            Ok(())
        })
    }

    /// Forgets the tap calibration (a new user), before the next frame.
    pub fn reset_gaze_calibration(&self) {
        guard_infallible(|| {
            if let Some(s) = self
                .stream
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .as_ref()
            {
                s.reset_gaze_calibration();
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracker::default_tracker_config;
    use crate::types::PixelFormat;
    use std::sync::mpsc;
    use std::time::Duration;

    struct Channel(Mutex<mpsc::Sender<Result<LiveStreamResult, MonotrackError>>>);

    impl LiveStreamListener for Channel {
        fn on_result(&self, result: LiveStreamResult) {
            let _ = self.0.lock().unwrap().send(Ok(result));
        }
        fn on_error(&self, _: i64, _: u64, error: MonotrackError) {
            let _ = self.0.lock().unwrap().send(Err(error));
        }
    }

    #[test]
    fn frames_go_through_the_worker_and_bad_ones_are_refused_at_once() {
        let (tx, rx) = mpsc::channel();
        let live =
            LiveFaceTracker::new(default_tracker_config(), Arc::new(Channel(Mutex::new(tx))))
                .unwrap();
        let desc = FrameDesc {
            width: 64,
            height: 48,
            format: PixelFormat::Gray8,
            row_stride: 64,
            uv_row_stride: 0,
            uv_pixel_stride: 0,
            rotation_degrees: 90,
            mirrored: false,
        };
        assert!(matches!(
            live.process_async(&[0; 10], desc, 1),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        live.process_async(&[90; 64 * 48], desc, 5).unwrap();
        assert!(matches!(
            live.process_async(&[90; 64 * 48], desc, 5),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        let r = rx.recv_timeout(Duration::from_secs(60)).unwrap().unwrap();
        assert_eq!(r.timestamp_ns, 5);
        assert_eq!((r.result.frame_width, r.result.frame_height), (48, 64));
        assert!(r.result.faces.is_empty());
        live.shutdown();
        live.shutdown();
        assert!(live.process_async(&[90; 64 * 48], desc, 6).is_err());
    }

    /// Taps on a live tracker: learnt on the worker, the next frame's point of gaze lands near the
    /// tap; an unusable tap (no face near its time) reaches `on_error`; unknown targets and taps
    /// with the gaze output off are refused at once.
    #[test]
    fn taps_calibrate_the_live_tracker() {
        use crate::tracker::tests::{gray_desc, upright_face};
        let (upright, w, h) = upright_face();
        let desc = gray_desc(w, h, 0, false);
        let (tx, rx) = mpsc::channel();
        let live =
            LiveFaceTracker::new(default_tracker_config(), Arc::new(Channel(Mutex::new(tx))))
                .unwrap();
        let screen = crate::gaze::screen_target("phone".into(), 70.0, 150.0, 35.0, -8.0).unwrap();
        live.set_gaze_targets(vec![screen]).unwrap();
        let ms = 1_000_000;
        let next = |ts: i64| {
            live.process_async(&upright, desc, ts).unwrap();
            rx.recv_timeout(Duration::from_secs(60)).unwrap()
        };
        assert!(next(10 * ms).unwrap().result.faces.len() == 1);
        let tap = PlanePoint {
            u_mm: 35.0,
            v_mm: 50.0,
        };
        assert!(matches!(
            live.add_calibration_point("tv".into(), tap, 10 * ms),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        live.add_calibration_point("phone".into(), tap, 12 * ms)
            .unwrap();
        let after = next(43 * ms).unwrap();
        let h = after.result.faces[0]
            .point_of_gaze
            .as_ref()
            .unwrap()
            .target
            .clone()
            .unwrap();
        let miss = ((h.point.u_mm - tap.u_mm).powi(2) + (h.point.v_mm - tap.v_mm).powi(2)).sqrt();
        assert!(h.hit && miss < 10.0, "{h:?}: {miss} mm from the tap");
        // No frame near this tap: reported, and the stream goes on.
        live.add_calibration_point("phone".into(), tap, 900 * ms)
            .unwrap();
        assert!(matches!(
            next(950 * ms),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        assert!(rx.recv_timeout(Duration::from_secs(60)).unwrap().is_ok());
        live.reset_gaze_calibration();
        live.shutdown();
        let off = LiveFaceTracker::new(
            TrackerConfig {
                gaze: false,
                ..default_tracker_config()
            },
            Arc::new(Channel(Mutex::new(mpsc::channel().0))),
        )
        .unwrap();
        assert!(matches!(
            off.add_calibration_point("phone".into(), tap, 1),
            Err(MonotrackError::InvalidConfig { .. })
        ));
    }
}
