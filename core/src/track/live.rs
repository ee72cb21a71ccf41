//! Live-stream mode: frames handed over from the camera thread, tracked on one worker thread,
//! results delivered to a listener. The camera thread never waits for tracking: while the worker is
//! busy the newest frame waits in one slot and replaces any older frame there (latest wins), and
//! each result says how many frames were dropped since the previous one.
//!
//! Frames are copied into buffers the stream keeps (two, swapped between the camera thread and the
//! worker), because a camera's buffer goes back to the camera when the call returns; after the
//! first frames nothing is allocated per frame. Results come out in timestamp order, on the worker
//! thread.

use super::{FaceTracker, LandmarkEstimator, RegionDetector, TrackingResult};
use crate::error::{Error, Result};
use crate::gaze::Target;
use crate::image::{Frame, FrameDesc};
use crate::record::MAX_DROPPED_TIMESTAMPS;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::{self, JoinHandle, ThreadId};

/// Receives the stream's results, on the worker thread, in timestamp order.
pub trait LiveListener: Send {
    /// The faces of the frame taken at `timestamp_ns` and described by `frame`; `frames_dropped`
    /// frames submitted since the previous delivery (result or error) were skipped because the
    /// worker was busy.
    /// `targets` are the gaze targets the result's points of gaze were located among.
    fn on_result(
        &mut self,
        timestamp_ns: i64,
        frames_dropped: u64,
        frame: &FrameDesc,
        result: &TrackingResult,
        targets: &[Target],
    );

    /// Tracking the frame taken at `timestamp_ns` failed (a bug caught as [`Error::Internal`], or
    /// an error of the pipeline); the stream goes on with the next frame.
    fn on_error(&mut self, timestamp_ns: i64, frames_dropped: u64, error: Error);
}

/// What the worker runs on each frame: a [`FaceTracker`] (the SDK's), or in tests a stand-in.
pub trait FrameProcessor: Send + 'static {
    /// Tracks `frame`, taken at `timestamp_ns`.
    ///
    /// # Errors
    /// As [`FaceTracker::process_frame`].
    fn process(&mut self, frame: &Frame<'_>, timestamp_ns: i64) -> Result<&TrackingResult>;

    /// Ends every track: after a caught panic (whose state is unknown) and on [`LiveStream::reset`].
    fn reset(&mut self);

    /// The last result, and the gaze targets it was located among.
    fn last(&self) -> (&TrackingResult, &[Target]);

    /// Sets the gaze targets ([`FaceTracker::set_gaze_targets`]).
    fn set_gaze_targets(&mut self, targets: Vec<Target>);

    /// The gaze targets set.
    fn gaze_targets(&self) -> &[Target];

    /// A tap on gaze target `target` ([`FaceTracker::add_calibration_point`]).
    ///
    /// # Errors
    /// As [`FaceTracker::add_calibration_point`].
    fn add_calibration_point(
        &mut self,
        target: usize,
        point_mm: [f64; 2],
        timestamp_ns: i64,
    ) -> Result<usize>;

    /// Forgets the tap calibration ([`FaceTracker::reset_gaze_calibration`]).
    fn reset_gaze_calibration(&mut self);

    /// `frames` frames were dropped before the one about to be processed; `timestamps_ns` are the
    /// first of their timestamps (at most [`MAX_DROPPED_TIMESTAMPS`]). For a recorder
    /// ([`crate::record::RecordingTracker`]); nothing by default.
    fn frames_dropped(&mut self, frames: u64, timestamps_ns: &[i64]) {
        let _ = (frames, timestamps_ns);
    }
}

impl<D, L> FrameProcessor for FaceTracker<D, L>
where
    D: RegionDetector + Send + 'static,
    L: LandmarkEstimator + Send + 'static,
{
    fn process(&mut self, frame: &Frame<'_>, timestamp_ns: i64) -> Result<&TrackingResult> {
        self.process_frame(frame, timestamp_ns)
    }

    fn reset(&mut self) {
        FaceTracker::reset(self);
    }

    fn last(&self) -> (&TrackingResult, &[Target]) {
        (self.result(), FaceTracker::gaze_targets(self))
    }

    fn set_gaze_targets(&mut self, targets: Vec<Target>) {
        FaceTracker::set_gaze_targets(self, targets);
    }

    fn gaze_targets(&self) -> &[Target] {
        FaceTracker::gaze_targets(self)
    }

    fn add_calibration_point(
        &mut self,
        target: usize,
        point_mm: [f64; 2],
        timestamp_ns: i64,
    ) -> Result<usize> {
        FaceTracker::add_calibration_point(self, target, point_mm, timestamp_ns)
    }

    fn reset_gaze_calibration(&mut self) {
        FaceTracker::reset_gaze_calibration(self);
    }
}

/// What [`LiveStream::submit`] did with a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Submitted {
    /// The worker was idle or finishing a frame: this one is next.
    Queued,
    /// A frame already waited: this one took its place (the older one is dropped).
    Replaced,
}

/// One waiting frame: its bytes (a buffer kept across frames), description and timestamp.
#[derive(Debug, Default)]
struct Pending {
    bytes: Vec<u8>,
    desc: Option<FrameDesc>,
    timestamp_ns: i64,
}

#[derive(Debug, Default)]
struct Slot {
    /// The frame waiting for the worker (`desc` set), or an empty buffer to fill.
    waiting: Pending,
    /// Frames replaced in the slot since the last delivery.
    dropped: u64,
    /// The first of their timestamps (capacity [`MAX_DROPPED_TIMESTAMPS`], never grown).
    dropped_ns: Vec<i64>,
    /// The last accepted timestamp: submitted frames must come after it.
    last_timestamp_ns: Option<i64>,
    /// Gaze targets for the worker to take before its next frame.
    targets: Option<Vec<Target>>,
    /// Whether the worker ends every track before its next frame ([`LiveStream::reset`]).
    reset_tracks: bool,
    /// Whether the worker forgets the tap calibration before its next frame (before `taps`).
    reset_calibration: bool,
    /// Taps (target, point in mm, time) for the worker to learn from before its next frame.
    taps: Vec<(usize, [f64; 2], i64)>,
    shutdown: bool,
}

#[derive(Debug, Default)]
struct Shared {
    slot: Mutex<Slot>,
    wake: Condvar,
}

impl Slot {
    /// Counts the waiting frame, taken at `timestamp_ns`, as dropped.
    fn drop_waiting(&mut self, timestamp_ns: i64) {
        self.dropped += 1;
        if self.dropped_ns.len() < self.dropped_ns.capacity() {
            self.dropped_ns.push(timestamp_ns);
        }
    }
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Slot> {
        // Nothing runs user code or panics while the slot is held; recover anyway.
        self.slot.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// A tracker running on its own worker thread (see the module docs). Dropping it (or
/// [`Self::close`]) stops the worker: a frame being tracked finishes and is delivered, a waiting
/// one is dropped, and no listener call happens afterwards.
#[derive(Debug)]
pub struct LiveStream {
    shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
    worker_id: ThreadId,
}

impl LiveStream {
    /// Starts the worker with `tracker` (a [`FaceTracker`] in video mode) and `listener`.
    ///
    /// # Errors
    /// [`Error::Internal`] when the operating system refuses a thread.
    pub fn start(tracker: impl FrameProcessor, listener: Box<dyn LiveListener>) -> Result<Self> {
        let shared = Arc::new(Shared::default());
        shared
            .lock()
            .dropped_ns
            .reserve_exact(MAX_DROPPED_TIMESTAMPS);
        let for_worker = Arc::clone(&shared);
        let worker = thread::Builder::new()
            .name("monotrack-live".into())
            .spawn(move || run_worker(&for_worker, tracker, listener))
            .map_err(|e| Error::Internal(format!("cannot start the live-stream worker: {e}")))?;
        let worker_id = worker.thread().id();
        Ok(Self {
            shared,
            worker: Some(worker),
            worker_id,
        })
    }

    /// Hands `frame`, taken at `timestamp_ns`, to the worker and returns at once (the bytes are
    /// copied).
    ///
    /// # Errors
    /// [`Error::InvalidTimestamp`] when `timestamp_ns` is not after the last submitted frame's
    /// (since the start or the last [`Self::reset`]), [`Error::InvalidInput`] when the stream is
    /// closed.
    pub fn submit(&self, frame: &Frame<'_>, timestamp_ns: i64) -> Result<Submitted> {
        let mut slot = self.shared.lock();
        if slot.shutdown {
            return Err(Error::InvalidInput("the live stream is closed".into()));
        }
        if let Some(last) = slot.last_timestamp_ns
            && timestamp_ns <= last
        {
            return Err(Error::InvalidTimestamp(format!(
                "live-stream frames need strictly increasing timestamps: got {timestamp_ns} ns after {last} ns"
            )));
        }
        slot.last_timestamp_ns = Some(timestamp_ns);
        let outcome = if slot.waiting.desc.is_some() {
            let replaced = slot.waiting.timestamp_ns;
            slot.drop_waiting(replaced);
            Submitted::Replaced
        } else {
            Submitted::Queued
        };
        let w = &mut slot.waiting;
        w.bytes.clear();
        // Frame::new checked the length; the slice past it is not the frame's.
        let len = frame.desc().required_len()?.min(frame.data().len());
        w.bytes.extend_from_slice(&frame.data()[..len]);
        w.desc = Some(*frame.desc());
        w.timestamp_ns = timestamp_ns;
        drop(slot);
        self.shared.wake.notify_one();
        Ok(outcome)
    }

    /// Sets the gaze targets; frames tracked from the next one on use them.
    pub fn set_gaze_targets(&self, targets: Vec<Target>) {
        self.shared.lock().targets = Some(targets);
    }

    /// A tap on gaze target `target` at `point_mm` at `timestamp_ns` (the frames' clock), learnt
    /// before the next frame is tracked ([`FaceTracker::add_calibration_point`]). A tap the
    /// tracker cannot use (no face within 250 ms of it, an unknown target) reaches the listener's
    /// `on_error` with the tap's timestamp.
    pub fn add_calibration_point(&self, target: usize, point_mm: [f64; 2], timestamp_ns: i64) {
        self.shared
            .lock()
            .taps
            .push((target, point_mm, timestamp_ns));
    }

    /// Forgets the tap calibration before the next frame (taps added after this call stay).
    pub fn reset_gaze_calibration(&self) {
        let mut slot = self.shared.lock();
        slot.reset_calibration = true;
        slot.taps.clear();
    }

    /// Ends every track and forgets the user's shape before the next frame, drops a frame still
    /// waiting, and starts the timestamp clock again (a camera restart may go back in time).
    pub fn reset(&self) {
        let mut slot = self.shared.lock();
        slot.reset_tracks = true;
        slot.last_timestamp_ns = None;
        if slot.waiting.desc.take().is_some() {
            let dropped = slot.waiting.timestamp_ns;
            slot.drop_waiting(dropped);
        }
    }

    /// Stops the worker (see the type's docs) and waits for it, unless called from the listener
    /// itself (on the worker thread), where it only asks the worker to stop after this delivery.
    pub fn close(&mut self) {
        self.shared.lock().shutdown = true;
        self.shared.wake.notify_all();
        if thread::current().id() == self.worker_id {
            return;
        }
        if let Some(worker) = self.worker.take() {
            // The worker catches the pipeline's and the listener's panics itself.
            let _ = worker.join();
        }
    }
}

impl Drop for LiveStream {
    fn drop(&mut self) {
        self.close();
    }
}

fn run_worker(
    shared: &Shared,
    mut tracker: impl FrameProcessor,
    mut listener: Box<dyn LiveListener>,
) {
    let mut working = Pending::default();
    let mut taps = Vec::new();
    let mut dropped_ns = Vec::with_capacity(MAX_DROPPED_TIMESTAMPS);
    loop {
        let (dropped, targets) = {
            let mut slot = shared.lock();
            while slot.waiting.desc.is_none() && !slot.shutdown {
                slot = shared.wake.wait(slot).unwrap_or_else(|p| p.into_inner());
            }
            if slot.shutdown {
                return;
            }
            std::mem::swap(&mut slot.waiting, &mut working);
            if std::mem::take(&mut slot.reset_tracks) {
                tracker.reset();
            }
            if std::mem::take(&mut slot.reset_calibration) {
                tracker.reset_gaze_calibration();
            }
            std::mem::swap(&mut slot.taps, &mut taps);
            dropped_ns.clear();
            std::mem::swap(&mut slot.dropped_ns, &mut dropped_ns);
            (std::mem::take(&mut slot.dropped), slot.targets.take())
        };
        if let Some(t) = targets {
            tracker.set_gaze_targets(t);
        }
        for (target, point, at) in taps.drain(..) {
            if let Err(e) = tracker.add_calibration_point(target, point, at) {
                let _ = catch_unwind(AssertUnwindSafe(|| listener.on_error(at, 0, e)));
            }
        }
        let Some(desc) = working.desc.take() else {
            continue;
        };
        if dropped > 0 {
            tracker.frames_dropped(dropped, &dropped_ns);
        }
        let ts = working.timestamp_ns;
        let delivered = catch_unwind(AssertUnwindSafe(|| {
            match Frame::new(&working.bytes, desc).and_then(|f| tracker.process(&f, ts).map(|_| ()))
            {
                Ok(()) => {
                    let (result, targets) = tracker.last();
                    listener.on_result(ts, dropped, &desc, result, targets);
                }
                Err(e) => listener.on_error(ts, dropped, e),
            }
        }));
        if let Err(panic) = delivered {
            // A panic in the pipeline or the listener: the tracker may be half-updated, so its
            // tracks start again, and the listener hears of it if it can.
            tracker.reset();
            let msg = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            let _ = catch_unwind(AssertUnwindSafe(|| {
                listener.on_error(ts, dropped, Error::Internal(format!("panic: {msg}")));
            }));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::PixelFormat;
    use std::sync::mpsc;
    use std::time::Duration;

    #[derive(Debug, PartialEq)]
    enum Event {
        Result(i64, u64),
        Error(i64, u64, String),
    }

    /// A stand-in tracker: takes `delay` per frame, fails on frames whose first byte is 1 and
    /// panics on 2 (the tracker's own behaviour is tested in `track` and `tests/`).
    struct Slow {
        delay: Duration,
        result: TrackingResult,
        resets: Arc<Mutex<u32>>,
        /// Per `frames_dropped` call: the count and the timestamps kept.
        drops: Drops,
    }

    impl FrameProcessor for Slow {
        fn process(&mut self, frame: &Frame<'_>, _ts: i64) -> Result<&TrackingResult> {
            thread::sleep(self.delay);
            match frame.data()[0] {
                1 => Err(Error::InvalidInput("refused".into())),
                2 => panic!("boom"),
                _ => Ok(&self.result),
            }
        }
        fn reset(&mut self) {
            *self.resets.lock().unwrap() += 1;
        }
        fn last(&self) -> (&TrackingResult, &[Target]) {
            (&self.result, &[])
        }
        fn set_gaze_targets(&mut self, _: Vec<Target>) {}
        fn gaze_targets(&self) -> &[Target] {
            &[]
        }
        fn add_calibration_point(&mut self, target: usize, _: [f64; 2], _: i64) -> Result<usize> {
            if target == 0 {
                Ok(1)
            } else {
                Err(Error::InvalidInput(format!("no gaze target {target}")))
            }
        }
        fn reset_gaze_calibration(&mut self) {}
        fn frames_dropped(&mut self, frames: u64, timestamps_ns: &[i64]) {
            self.drops
                .lock()
                .unwrap()
                .push((frames, timestamps_ns.to_vec()));
        }
    }

    struct ToChannel(mpsc::Sender<Event>);

    impl LiveListener for ToChannel {
        fn on_result(
            &mut self,
            ts: i64,
            dropped: u64,
            _: &FrameDesc,
            _: &TrackingResult,
            _: &[Target],
        ) {
            let _ = self.0.send(Event::Result(ts, dropped));
        }
        fn on_error(&mut self, ts: i64, dropped: u64, error: Error) {
            let _ = self.0.send(Event::Error(ts, dropped, error.to_string()));
        }
    }

    type Drops = Arc<Mutex<Vec<(u64, Vec<i64>)>>>;

    fn stream_with_drops(
        delay_ms: u64,
    ) -> (LiveStream, mpsc::Receiver<Event>, Arc<Mutex<u32>>, Drops) {
        let resets = Arc::new(Mutex::new(0));
        let drops = Drops::default();
        let slow = Slow {
            delay: Duration::from_millis(delay_ms),
            result: TrackingResult::default(),
            resets: Arc::clone(&resets),
            drops: Arc::clone(&drops),
        };
        let (tx, rx) = mpsc::channel();
        let live = LiveStream::start(slow, Box::new(ToChannel(tx))).unwrap();
        (live, rx, resets, drops)
    }

    fn stream(delay_ms: u64) -> (LiveStream, mpsc::Receiver<Event>, Arc<Mutex<u32>>) {
        let (live, rx, resets, _) = stream_with_drops(delay_ms);
        (live, rx, resets)
    }

    fn gray(first: u8) -> (Vec<u8>, FrameDesc) {
        let mut bytes = vec![0u8; 8 * 4];
        bytes[0] = first;
        (bytes, FrameDesc::packed(8, 4, PixelFormat::Gray8))
    }

    #[test]
    fn frames_are_dropped_while_busy_and_results_stay_in_order() {
        let (mut live, rx, _) = stream(20);
        let (bytes, desc) = gray(0);
        let frame = Frame::new(&bytes, desc).unwrap();
        let mut replaced = 0;
        for ts in 1..=30 {
            if live.submit(&frame, ts).unwrap() == Submitted::Replaced {
                replaced += 1;
            }
            thread::sleep(Duration::from_millis(2));
        }
        assert!(
            live.submit(&frame, 30).is_err(),
            "a repeated timestamp is refused"
        );
        let mut last = 0;
        let (mut delivered, mut dropped) = (0u64, 0u64);
        while last < 30 {
            match rx.recv_timeout(Duration::from_secs(10)).unwrap() {
                Event::Result(ts, d) => {
                    assert!(ts > last, "out of order: {ts} after {last}");
                    last = ts;
                    delivered += 1;
                    dropped += d;
                }
                e => panic!("unexpected {e:?}"),
            }
        }
        live.close();
        assert!(
            replaced > 5,
            "a 20 ms tracker fed every 2 ms drops frames ({replaced})"
        );
        assert_eq!(dropped, replaced, "every replaced frame is counted once");
        assert_eq!(
            delivered + dropped,
            30,
            "every frame is delivered or counted dropped"
        );
        assert!(live.submit(&frame, 31).is_err(), "closed");
    }

    /// The tracker hears of every drop before the frame taken after it, with the dropped
    /// frames' own timestamps (a recorder writes them), a reset's dropped frame included.
    #[test]
    fn the_tracker_is_told_of_each_drop_with_its_timestamps() {
        let (mut live, rx, _, drops) = stream_with_drops(15);
        let (bytes, desc) = gray(0);
        let frame = Frame::new(&bytes, desc).unwrap();
        for ts in 1..=20 {
            live.submit(&frame, ts).unwrap();
            thread::sleep(Duration::from_millis(1));
        }
        // A reset drops the frame waiting (if one is), and the next frame tells of it.
        live.reset();
        live.submit(&frame, 1_000).unwrap();
        let mut delivered = Vec::new();
        while delivered.last() != Some(&1_000) {
            match rx.recv_timeout(Duration::from_secs(10)).unwrap() {
                Event::Result(ts, _) => delivered.push(ts),
                e => panic!("unexpected {e:?}"),
            }
        }
        live.close();
        let drops = drops.lock().unwrap();
        let told: Vec<i64> = drops.iter().flat_map(|(_, t)| t.iter().copied()).collect();
        assert_eq!(
            drops.iter().map(|(n, _)| *n).sum::<u64>(),
            told.len() as u64,
            "few drops at a time: every timestamp is kept"
        );
        assert!(
            !told.is_empty(),
            "a 15 ms tracker fed every millisecond drops frames"
        );
        let mut all: Vec<i64> = delivered.iter().chain(&told).copied().collect();
        all.sort_unstable();
        let submitted: Vec<i64> = (1..=20).chain([1_000]).collect();
        assert_eq!(all, submitted, "each frame delivered or told dropped, once");
    }

    #[test]
    fn errors_and_panics_reach_the_listener_and_the_stream_goes_on() {
        let (mut live, rx, resets) = stream(0);
        for (ts, first) in [(1, 1u8), (2, 2), (3, 0)] {
            let (bytes, desc) = gray(first);
            live.submit(&Frame::new(&bytes, desc).unwrap(), ts).unwrap();
            // One at a time, so none is dropped.
            let e = rx.recv_timeout(Duration::from_secs(10)).unwrap();
            match (ts, e) {
                (1, Event::Error(1, 0, msg)) => assert!(msg.contains("refused"), "{msg}"),
                (2, Event::Error(2, 0, msg)) => assert!(msg.contains("panic: boom"), "{msg}"),
                (3, Event::Result(3, 0)) => {}
                (ts, e) => panic!("frame {ts}: {e:?}"),
            }
        }
        assert_eq!(*resets.lock().unwrap(), 1, "the panic reset the tracker");
        live.close();
    }

    #[test]
    fn closing_while_busy_waits_for_the_frame_and_drops_the_waiting_one() {
        let (mut live, rx, _) = stream(100);
        let (bytes, desc) = gray(0);
        let frame = Frame::new(&bytes, desc).unwrap();
        live.submit(&frame, 1).unwrap();
        thread::sleep(Duration::from_millis(20));
        live.submit(&frame, 2).unwrap();
        live.close();
        live.close();
        let events: Vec<Event> = rx.try_iter().collect();
        assert_eq!(
            events,
            vec![Event::Result(1, 0)],
            "frame 1 finished, frame 2 dropped"
        );
    }

    /// Taps reach the worker's tracker before the next frame; one it refuses reaches the
    /// listener as an error with the tap's time, and the stream goes on.
    #[test]
    fn taps_are_learnt_before_the_next_frame_and_bad_ones_are_reported() {
        let (mut live, rx, _) = stream(0);
        let (bytes, desc) = gray(0);
        let frame = Frame::new(&bytes, desc).unwrap();
        live.add_calibration_point(0, [1.0, 2.0], 5);
        live.add_calibration_point(3, [1.0, 2.0], 7);
        live.submit(&frame, 10).unwrap();
        let events: Vec<Event> = (0..2)
            .map(|_| rx.recv_timeout(Duration::from_secs(10)).unwrap())
            .collect();
        assert!(
            matches!(&events[..], [Event::Error(7, 0, msg), Event::Result(10, 0)] if msg.contains("no gaze target 3")),
            "{events:?}"
        );
        // A reset drops the taps not yet taken.
        live.add_calibration_point(3, [1.0, 2.0], 11);
        live.reset_gaze_calibration();
        live.submit(&frame, 12).unwrap();
        let e = rx.recv_timeout(Duration::from_secs(10)).unwrap();
        assert_eq!(e, Event::Result(12, 0));
        live.close();
    }

    /// A reset ends the tracks on the worker before its next frame and starts the clock again:
    /// an earlier timestamp (a restarted camera) is taken after it, refused before it.
    #[test]
    fn a_reset_reaches_the_worker_and_restarts_the_clock() {
        let (mut live, rx, resets) = stream(0);
        let (bytes, desc) = gray(0);
        let frame = Frame::new(&bytes, desc).unwrap();
        live.submit(&frame, 100).unwrap();
        assert_eq!(
            rx.recv_timeout(Duration::from_secs(10)).unwrap(),
            Event::Result(100, 0)
        );
        assert!(matches!(
            live.submit(&frame, 5),
            Err(Error::InvalidTimestamp(_))
        ));
        live.reset();
        live.submit(&frame, 5).unwrap();
        assert_eq!(
            rx.recv_timeout(Duration::from_secs(10)).unwrap(),
            Event::Result(5, 0)
        );
        assert_eq!(*resets.lock().unwrap(), 1, "the worker's tracker was reset");
        live.close();
    }
}
