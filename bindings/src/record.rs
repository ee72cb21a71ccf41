//! Recording through the FFI (`bindings/API.md`, "Record and replay"): `FaceTracker` writes what it
//! is given to a file on the device (`monotrack_core::record`), which `monotrack replay FILE`
//! runs again on a desktop, checking every result bit for bit.

use crate::MonotrackError;
use crate::error::{guard, guard_infallible};
use crate::tracker::FaceTracker;
use monotrack_core::record::RecordingSummary as CoreSummary;
use std::io::BufWriter;

/// What a stopped recording holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Record)]
pub struct RecordingSummary {
    /// Frames recorded: every frame tracked while recording (in the live-stream mode, those the
    /// worker took).
    pub frames: u64,
    /// Live-stream frames dropped while recording (submitted while the worker was busy): noted
    /// in the file, not recorded.
    pub dropped_frames: u64,
    /// The file's size.
    pub bytes: u64,
    /// Recording stopped early because the next frame would have passed `max_bytes`.
    pub truncated: bool,
}

impl From<CoreSummary> for RecordingSummary {
    fn from(s: CoreSummary) -> Self {
        Self {
            frames: s.frames,
            dropped_frames: s.dropped_frames,
            bytes: s.bytes,
            truncated: s.truncated,
        }
    }
}

#[uniffi::export]
impl FaceTracker {
    /// Starts recording into a new file at `path` (replaced if it exists), at most `max_bytes`
    /// bytes: the tracker's settings now; from the next call on, every frame it tracks (bytes,
    /// description, timestamp) with a digest of its result, the live stream's dropped frames,
    /// gaze targets, taps and resets. A recording starts a new stream: the next frame detects
    /// the faces afresh (ids go on counting). When the next frame would pass `max_bytes`,
    /// recording stops there and the file says it was truncated. Nothing is recorded unless
    /// this is called.
    ///
    /// # Errors
    /// `InvalidState` while a recording runs or after `shutdown`; `InvalidConfig` when
    /// `max_bytes` cannot hold even the settings; `Io` when the file cannot be created.
    pub fn start_recording(&self, path: String, max_bytes: u64) -> Result<(), MonotrackError> {
        guard(|| {
            let switch = self.recording()?;
            // Before the file is created: a second start must not empty the running one's file.
            if switch.is_recording() {
                return Err(MonotrackError::InvalidState {
                    msg: "a recording is already running: stop it first".into(),
                });
            }
            let file = std::fs::File::create(&path).map_err(|e| MonotrackError::Io {
                msg: format!("cannot create the recording {path}: {e}"),
            })?;
            let started = switch.start(Box::new(BufWriter::new(file)), max_bytes);
            if started.is_err() {
                let _ = std::fs::remove_file(&path);
            }
            Ok(started?)
        })
    }

    /// Stops recording: the file is complete (and flushed) when this returns. In the live-stream
    /// mode a frame being tracked is recorded whole first. `shutdown` also ends a running
    /// recording, without a summary.
    ///
    /// # Errors
    /// `InvalidState` when no recording runs or after `shutdown`; `Io` when writing failed (the
    /// file is incomplete).
    pub fn stop_recording(&self) -> Result<RecordingSummary, MonotrackError> {
        guard(|| Ok(self.recording()?.stop()?.into()))
    }

    /// Whether a recording runs.
    pub fn is_recording(&self) -> bool {
        let mut on = false;
        guard_infallible(|| on = self.recording().is_ok_and(|s| s.is_recording()));
        on
    }
}

#[cfg(test)]
mod tests {
    use crate::options::{FaceTrackerOptions, RunningMode};
    use crate::tracker::tests::tracker;
    use crate::types::{FrameDesc, PixelFormat};
    use crate::{LiveStreamListener, LiveStreamResult, MonotrackError};
    use monotrack_core::record::{Event, Recording};
    use std::sync::{Arc, mpsc};

    fn scratch(name: &str) -> String {
        std::env::temp_dir()
            .join(format!("monotrack-ffi-{name}-{}.mtrec", std::process::id()))
            .display()
            .to_string()
    }

    fn gray(w: u32, h: u32) -> (Vec<u8>, FrameDesc) {
        let bytes = (0..w * h).map(|i| (i * 13 % 251) as u8).collect();
        let desc = FrameDesc {
            width: w,
            height: h,
            format: PixelFormat::Gray8,
            row_stride: w,
            uv_row_stride: 0,
            uv_pixel_stride: 0,
            rotation_degrees: 0,
            mirrored: false,
        };
        (bytes, desc)
    }

    /// Start, frames, stop: the file reads back with those frames; the calls out of turn are
    /// typed errors, and a bad path is `Io`.
    #[test]
    fn a_video_tracker_records_its_frames() {
        let t = tracker(FaceTrackerOptions {
            running_mode: Some(RunningMode::Video),
            ..FaceTrackerOptions::default()
        });
        assert!(!t.is_recording());
        assert!(matches!(
            t.stop_recording(),
            Err(MonotrackError::InvalidState { .. })
        ));
        let path = scratch("video");
        assert!(matches!(
            t.start_recording(path.clone(), 10),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        assert!(!std::path::Path::new(&path).exists(), "no file is left");
        assert!(matches!(
            t.start_recording("/nonexistent-dir/x.mtrec".into(), 1 << 20),
            Err(MonotrackError::Io { .. })
        ));
        let (bytes, desc) = gray(64, 48);
        t.detect_for_video(&bytes, desc, 1).unwrap();
        t.start_recording(path.clone(), 1 << 20).unwrap();
        assert!(t.is_recording());
        assert!(matches!(
            t.start_recording(path.clone(), 1 << 20),
            Err(MonotrackError::InvalidState { .. })
        ));
        for ms in 2..5 {
            t.detect_for_video(&bytes, desc, ms).unwrap();
        }
        t.reset();
        let s = t.stop_recording().unwrap();
        let file = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!((s.frames, s.dropped_frames, s.truncated), (3, 0, false));
        assert_eq!(s.bytes, file.len() as u64);
        let rec = Recording::parse(&file).unwrap();
        assert_eq!(rec.frames(), 3);
        let events: Vec<Event<'_>> = rec.events().map(Result::unwrap).collect();
        assert!(matches!(
            events.last(),
            Some(Event::End { truncated: false })
        ));
        assert!(events.iter().any(|e| matches!(e, Event::Reset(_))));
        t.shutdown();
        assert!(matches!(
            t.start_recording(path, 1 << 20),
            Err(MonotrackError::InvalidState { .. })
        ));
    }

    struct Count(mpsc::Sender<u64>);

    impl LiveStreamListener for Count {
        fn on_result(&self, result: LiveStreamResult) {
            let _ = self.0.send(result.frames_dropped);
        }
        fn on_error(&self, _: i64, _: u64, e: MonotrackError) {
            panic!("{e}");
        }
    }

    /// In the live-stream mode the worker records; shutting down ends the file properly.
    #[test]
    fn a_live_stream_records_on_its_worker_and_shutdown_ends_the_file() {
        let (tx, rx) = mpsc::channel();
        let t = crate::FaceTracker::new(
            FaceTrackerOptions {
                running_mode: Some(RunningMode::LiveStream),
                ..FaceTrackerOptions::default()
            },
            Some(Arc::new(Count(tx))),
        )
        .unwrap();
        let path = scratch("live");
        t.start_recording(path.clone(), 1 << 20).unwrap();
        let (bytes, desc) = gray(64, 48);
        t.detect_async(&bytes, desc, 1).unwrap();
        rx.recv_timeout(std::time::Duration::from_secs(60)).unwrap();
        t.shutdown();
        let file = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(Recording::parse(&file).unwrap().frames(), 1);
    }
}
