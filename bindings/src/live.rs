//! The live-stream mode's listener (`bindings/API.md`): a `FaceTracker` built with
//! `RunningMode::LiveStream` takes camera frames without waiting for them to be tracked and
//! delivers results to a `LiveStreamListener` the app implements, from one worker thread
//! (`monotrack_core::track::live`).

use crate::MonotrackError;
use crate::tracker::{ResultShape, TrackingResult, result};
use monotrack_core::gaze::Target;
use monotrack_core::image::FrameDesc as CoreFrameDesc;
use monotrack_core::track::live::LiveListener;
use monotrack_core::track::{self as core_track};
use std::sync::Arc;

/// One live-stream result.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct LiveStreamResult {
    /// The timestamp the frame was submitted with, milliseconds.
    pub timestamp_ms: i64,
    /// Frames submitted since the previous delivery that were skipped because the tracker was
    /// busy (the newest frame is never the one skipped).
    pub frames_dropped: u64,
    /// The frame's faces.
    pub result: TrackingResult,
}

/// Receives a live-stream tracker's results (MediaPipe's result listener), implemented by the
/// app. Calls come from the tracker's worker thread, one at a time, in timestamp order; a slow
/// listener makes the tracker skip frames, so hand the result to the UI thread and return. An
/// exception thrown here is caught and does not stop the stream.
#[uniffi::export(with_foreign)]
pub trait LiveStreamListener: Send + Sync {
    /// The faces of one frame.
    fn on_result(&self, result: LiveStreamResult);
    /// Tracking the frame taken at `timestamp_ms` failed, or a tap at that time could not be used
    /// (`FaceTracker::add_calibration_point`); the stream goes on with the next frame.
    fn on_error(&self, timestamp_ms: i64, frames_dropped: u64, error: MonotrackError);
}

/// Hands the core's deliveries to the app's listener as FFI records with the options' outputs.
pub(crate) struct Forward {
    listener: Arc<dyn LiveStreamListener>,
    shape: ResultShape,
}

impl Forward {
    pub(crate) fn new(listener: Arc<dyn LiveStreamListener>, shape: ResultShape) -> Self {
        Self { listener, shape }
    }
}

/// The core's nanoseconds as the milliseconds they were submitted in.
fn milliseconds(timestamp_ns: i64) -> i64 {
    timestamp_ns.div_euclid(1_000_000)
}

impl LiveListener for Forward {
    fn on_result(
        &mut self,
        timestamp_ns: i64,
        frames_dropped: u64,
        frame: &CoreFrameDesc,
        r: &core_track::TrackingResult,
        targets: &[Target],
    ) {
        let timestamp_ms = milliseconds(timestamp_ns);
        match result(r, frame, targets, self.shape) {
            Ok(result) => self.listener.on_result(LiveStreamResult {
                timestamp_ms,
                frames_dropped,
                result,
            }),
            Err(e) => self.listener.on_error(timestamp_ms, frames_dropped, e),
        }
    }

    fn on_error(&mut self, timestamp_ns: i64, frames_dropped: u64, error: monotrack_core::Error) {
        // As the synchronous calls: what a frame's or a tap's input could not give (a tap with no
        // face near its time) is `InvalidFrame`.
        self.listener.on_error(
            milliseconds(timestamp_ns),
            frames_dropped,
            crate::error::input_as_frame(error),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gaze::PlanePoint;
    use crate::options::{FaceTrackerOptions, RunningMode};
    use crate::tracker::FaceTracker;
    use crate::types::{FrameDesc, PixelFormat};
    use std::sync::Mutex;
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

    fn live_tracker(options: FaceTrackerOptions, tx: Channel) -> Arc<FaceTracker> {
        let options = FaceTrackerOptions {
            running_mode: Some(RunningMode::LiveStream),
            ..options
        };
        FaceTracker::new(options, Some(Arc::new(tx))).unwrap()
    }

    #[test]
    fn frames_go_through_the_worker_and_bad_ones_are_refused_at_once() {
        let (tx, rx) = mpsc::channel();
        let live = live_tracker(FaceTrackerOptions::default(), Channel(Mutex::new(tx)));
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
            live.detect_async(&[0; 10], desc, 1),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        assert!(matches!(
            live.detect_for_video(&[90; 64 * 48], desc, 1),
            Err(MonotrackError::InvalidState { .. })
        ));
        live.detect_async(&[90; 64 * 48], desc, 5).unwrap();
        assert!(matches!(
            live.detect_async(&[90; 64 * 48], desc, 5),
            Err(MonotrackError::InvalidTimestamp { .. })
        ));
        let r = rx.recv_timeout(Duration::from_secs(60)).unwrap().unwrap();
        assert_eq!(r.timestamp_ms, 5);
        assert_eq!((r.result.frame_width, r.result.frame_height), (48, 64));
        assert!(r.result.faces.is_empty());
        // A reset restarts the clock (a camera restart may go back in time).
        live.reset();
        live.detect_async(&[90; 64 * 48], desc, 2).unwrap();
        let r = rx.recv_timeout(Duration::from_secs(60)).unwrap().unwrap();
        assert_eq!(r.timestamp_ms, 2);
        live.shutdown();
        live.shutdown();
        assert!(matches!(
            live.detect_async(&[90; 64 * 48], desc, 6),
            Err(MonotrackError::InvalidState { .. })
        ));
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
        let live = live_tracker(FaceTrackerOptions::default(), Channel(Mutex::new(tx)));
        let screen = crate::gaze::screen_target("phone".into(), 70.0, 150.0, 35.0, -8.0).unwrap();
        live.set_gaze_targets(vec![screen]).unwrap();
        let ms = 1;
        let next = |ts: i64| {
            live.detect_async(&upright, desc, ts).unwrap();
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
        assert_eq!(
            live.add_calibration_point("phone".into(), tap, 12 * ms)
                .unwrap(),
            None
        );
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
        let off = live_tracker(
            FaceTrackerOptions {
                output_gaze: false,
                ..FaceTrackerOptions::default()
            },
            Channel(Mutex::new(mpsc::channel().0)),
        );
        assert!(matches!(
            off.add_calibration_point("phone".into(), tap, 1),
            Err(MonotrackError::InvalidConfig { .. })
        ));
    }
}
