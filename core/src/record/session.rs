//! The recorder on the shipped tracker ([`RecordingTracker`], switched by [`RecordingSwitch`])
//! and the replay of a recording ([`Replay`]).

use super::digest::result_digest;
use super::format::{
    Event, Events, Header, ModelIdentity, Recorder, Recording, RecordingSummary, ResetKind,
};
use crate::error::{Error, Result};
use crate::gaze::Target;
use crate::image::{Frame, FrameDesc, GrayImage, PixelFormat};
use crate::kernels::{KernelChoice, KernelPath};
use crate::model::bundle::ModelBundle;
use crate::track::live::FrameProcessor;
use crate::track::{Tracker, TrackingResult};
use std::io::Write;
use std::sync::{Arc, Mutex, MutexGuard};

#[derive(Debug)]
struct Shared {
    header: Header,
    recorder: Mutex<Option<Recorder>>,
}

/// Starts and stops the recording of one [`RecordingTracker`], from any thread (a live stream's
/// tracker records on its worker while the app's thread holds the switch).
#[derive(Debug, Clone)]
pub struct RecordingSwitch(Arc<Shared>);

impl RecordingSwitch {
    fn lock(&self) -> MutexGuard<'_, Option<Recorder>> {
        // A panic while tracking a recorded frame leaves the recorder as it was: go on with it.
        self.0.recorder.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Starts recording into `out` (FORMAT.md), at most `max_bytes` bytes in all: the header now,
    /// the stream from the tracker's next call (which ends every track first, FORMAT.md, "The
    /// start of a recording").
    ///
    /// # Errors
    /// [`Error::InvalidState`] while a recording runs; as [`Recorder::new`].
    pub fn start(&self, out: Box<dyn Write + Send>, max_bytes: u64) -> Result<()> {
        let mut recorder = self.lock();
        if recorder.is_some() {
            return Err(Error::InvalidState(
                "a recording is already running: stop it first".into(),
            ));
        }
        *recorder = Some(Recorder::new(out, max_bytes, &self.0.header)?);
        Ok(())
    }

    /// Stops recording: writes the `end` chunk, flushes, and says what the file holds. A frame
    /// being tracked is recorded whole first.
    ///
    /// # Errors
    /// [`Error::InvalidState`] when no recording runs; [`Error::Io`] when a write failed.
    pub fn stop(&self) -> Result<RecordingSummary> {
        let recorder = self
            .lock()
            .take()
            .ok_or_else(|| Error::InvalidState("no recording is running".into()))?;
        recorder.finish()
    }

    /// Whether a recording runs.
    pub fn is_recording(&self) -> bool {
        self.lock().is_some()
    }

    /// The header a recording of this tracker starts with.
    pub fn header(&self) -> &Header {
        &self.0.header
    }
}

/// The shipped [`Tracker`] with a recorder that is off until its [`RecordingSwitch`] starts it.
/// Every call that changes what the tracker computes goes through it — frames, gaze targets, taps,
/// resets — and is recorded while a recording runs; reads go to [`Self::tracker`]. A
/// [`FrameProcessor`], so a live stream's worker records the frames it takes, and the drops.
#[derive(Debug)]
pub struct RecordingTracker {
    tracker: Tracker,
    switch: RecordingSwitch,
}

/// The switch's recorder, its stream begun when it was just started.
fn begun<'s>(
    switch: &'s RecordingSwitch,
    tracker: &mut Tracker,
) -> MutexGuard<'s, Option<Recorder>> {
    let mut recorder = switch.lock();
    if let Some(r) = recorder.as_mut()
        && !r.is_begun()
    {
        let start = tracker.begin_recorded_stream();
        r.begin(&start, tracker.gaze_targets());
    }
    recorder
}

impl RecordingTracker {
    /// `tracker`, which runs on `models`, with its recorder off. Its settings are fixed from now
    /// on (the header says them): change them before.
    pub fn new(tracker: Tracker, models: ModelIdentity) -> Self {
        let header = Header::for_tracker(&tracker, models);
        Self {
            tracker,
            switch: RecordingSwitch(Arc::new(Shared {
                header,
                recorder: Mutex::new(None),
            })),
        }
    }

    /// The switch that starts and stops its recording.
    pub fn switch(&self) -> RecordingSwitch {
        self.switch.clone()
    }

    /// The tracker, to read its results and settings.
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// [`Tracker::process_frame`], recorded: the frame before it is tracked, the result's digest
    /// after.
    ///
    /// # Errors
    /// As [`Tracker::process_frame`].
    pub fn process_frame(
        &mut self,
        frame: &Frame<'_>,
        timestamp_ns: i64,
    ) -> Result<&TrackingResult> {
        let mut recorder = begun(&self.switch, &mut self.tracker);
        if let Some(r) = recorder.as_mut() {
            r.frame(frame, timestamp_ns);
        }
        let out = self.tracker.process_frame(frame, timestamp_ns);
        if let Some(r) = recorder.as_mut() {
            r.result(out.as_ref().ok().map(|res| result_digest(res)));
        }
        out
    }

    /// [`Tracker::process`] on an upright luma image, recorded as the packed `Gray8` frame it is
    /// (which [`Tracker::process_frame`] reads to the same image, so a replay gives the same
    /// results).
    ///
    /// # Errors
    /// As [`Tracker::process`].
    pub fn process_image(
        &mut self,
        image: &GrayImage,
        timestamp_ns: i64,
    ) -> Result<&TrackingResult> {
        let mut recorder = begun(&self.switch, &mut self.tracker);
        if let Some(r) = recorder.as_mut() {
            let desc = FrameDesc::packed(
                image.width() as u32,
                image.height() as u32,
                PixelFormat::Gray8,
            );
            if let Ok(frame) = Frame::new(image.data(), desc) {
                r.frame(&frame, timestamp_ns);
            }
        }
        let out = self.tracker.process(image, timestamp_ns);
        if let Some(r) = recorder.as_mut() {
            r.result(out.as_ref().ok().map(|res| result_digest(res)));
        }
        out
    }

    /// [`Tracker::reset`], recorded.
    pub fn reset(&mut self) {
        if let Some(r) = begun(&self.switch, &mut self.tracker).as_mut() {
            r.reset(ResetKind::Tracks);
        }
        self.tracker.reset();
    }

    /// [`Tracker::set_gaze_targets`], recorded.
    pub fn set_gaze_targets(&mut self, targets: Vec<Target>) {
        if let Some(r) = begun(&self.switch, &mut self.tracker).as_mut() {
            r.gaze_targets(&targets);
        }
        self.tracker.set_gaze_targets(targets);
    }

    /// [`Tracker::add_calibration_point`], recorded (whether the tracker takes the tap or not:
    /// a replay makes the same call).
    ///
    /// # Errors
    /// As [`Tracker::add_calibration_point`].
    pub fn add_calibration_point(
        &mut self,
        target: usize,
        point_mm: [f64; 2],
        timestamp_ns: i64,
    ) -> Result<usize> {
        if let Some(r) = begun(&self.switch, &mut self.tracker).as_mut() {
            r.tap(target, point_mm, timestamp_ns);
        }
        self.tracker
            .add_calibration_point(target, point_mm, timestamp_ns)
    }

    /// [`Tracker::reset_gaze_calibration`], recorded.
    pub fn reset_gaze_calibration(&mut self) {
        if let Some(r) = begun(&self.switch, &mut self.tracker).as_mut() {
            r.reset(ResetKind::GazeCalibration);
        }
        self.tracker.reset_gaze_calibration();
    }
}

impl FrameProcessor for RecordingTracker {
    fn process(&mut self, frame: &Frame<'_>, timestamp_ns: i64) -> Result<&TrackingResult> {
        self.process_frame(frame, timestamp_ns)
    }

    fn reset(&mut self) {
        RecordingTracker::reset(self);
    }

    fn last(&self) -> (&TrackingResult, &[Target]) {
        (self.tracker.result(), self.tracker.gaze_targets())
    }

    fn set_gaze_targets(&mut self, targets: Vec<Target>) {
        RecordingTracker::set_gaze_targets(self, targets);
    }

    fn gaze_targets(&self) -> &[Target] {
        self.tracker.gaze_targets()
    }

    fn add_calibration_point(
        &mut self,
        target: usize,
        point_mm: [f64; 2],
        timestamp_ns: i64,
    ) -> Result<usize> {
        RecordingTracker::add_calibration_point(self, target, point_mm, timestamp_ns)
    }

    fn reset_gaze_calibration(&mut self) {
        RecordingTracker::reset_gaze_calibration(self);
    }

    fn frames_dropped(&mut self, frames: u64, timestamps_ns: &[i64]) {
        if let Some(r) = begun(&self.switch, &mut self.tracker).as_mut() {
            r.dropped(frames, timestamps_ns);
        }
    }
}

impl Header {
    /// The kernel choice that replays this recording on this machine bit for bit, and a note
    /// when none can be promised: the recorded choice on the recorded architecture; the
    /// portable path for a phone's (aarch64) native path, whose NEON forms give the portable
    /// forms' bits, and for a recorded portable path; otherwise the portable path, with the
    /// note.
    ///
    /// # Errors
    /// [`Error::InvalidRecording`] for a kernel choice this library does not know.
    pub fn replay_kernels(&self) -> Result<(KernelChoice, Option<String>)> {
        let recorded = KernelChoice::parse(&self.kernels)
            .map_err(|e| Error::InvalidRecording(format!("the header's kernels: {e}")))?;
        let portable = KernelChoice {
            path: KernelPath::Portable,
            conv: None,
            flow: None,
        };
        let here = std::env::consts::ARCH;
        if self.arch == here {
            let note = (recorded.path == KernelPath::Native
                && self.cpu != crate::kernels::cpu_name())
            .then(|| {
                format!(
                    "recorded on another CPU ({}): its native kernels may differ from this \
                         one's",
                    self.cpu
                )
            });
            return Ok((recorded, note));
        }
        if self.arch == "aarch64" || recorded.path == KernelPath::Portable {
            return Ok((portable, None));
        }
        Ok((
            portable,
            Some(format!(
                "recorded on {} ({} path), which has no counterpart on {here}: replayed on the \
                 portable path, results may differ",
                self.arch,
                recorded.path.as_str()
            )),
        ))
    }
}

/// One frame of a [`Replay`].
#[derive(Debug)]
pub struct ReplayedFrame<'r> {
    /// Its place among the recorded frames, from 0.
    pub index: u64,
    /// Its timestamp, nanoseconds.
    pub timestamp_ns: i64,
    /// Its description.
    pub desc: FrameDesc,
    /// What this replay's tracker made of it.
    pub result: std::result::Result<&'r TrackingResult, Error>,
    /// The gaze targets its points of gaze were located among.
    pub targets: &'r [Target],
    /// The recorded outcome: `Some(Some(digest))` a result, `Some(None)` an error, `None` not
    /// recorded (the recording tracker panicked on the frame).
    pub recorded: Option<Option<u64>>,
}

impl ReplayedFrame<'_> {
    /// This replay's outcome as the recording writes it.
    pub fn digest(&self) -> Option<u64> {
        self.result.as_ref().ok().map(|r| result_digest(r))
    }

    /// Whether this replay gave what was recorded (`None` when nothing was recorded to compare).
    pub fn identical(&self) -> Option<bool> {
        self.recorded.map(|d| d == self.digest())
    }
}

/// A recording run again through a tracker built from its header (FORMAT.md): every call the
/// recorded tracker took, in order, each frame's result given with the recorded digest.
#[derive(Debug)]
pub struct Replay<'a> {
    tracker: Tracker,
    events: Events<'a>,
    /// An event read after a frame that was not its result.
    pending: Option<Event<'a>>,
    frames: u64,
}

impl<'a> Replay<'a> {
    /// A tracker built as the header says, on the library's models or on `bundle` (which must be
    /// the recorded one: a recording of a custom bundle needs it).
    ///
    /// # Errors
    /// [`Error::InvalidRecording`] when the header's settings do not read back to exactly what was
    /// written; [`Error::ModelLoad`] when the recorded models are not at hand (another build's
    /// built-in models, a custom bundle not given or not the recorded one); as
    /// [`Tracker::with_detector_config`] and [`Tracker::with_bundle`].
    pub fn new(recording: &Recording<'a>, bundle: Option<&ModelBundle>) -> Result<Self> {
        let h = recording.header();
        let again =
            serde_json::to_vec(h).map_err(|e| Error::Internal(format!("recording header: {e}")))?;
        if again != recording.header_json() {
            return Err(Error::InvalidRecording(
                "the header's settings do not read back to exactly what was written (another \
                 library version, or an edited file): a replay would not be the recorded tracker"
                    .into(),
            ));
        }
        let mut tracker = match bundle {
            Some(b) if b.checksum() == h.models.checksum => {
                Tracker::with_bundle(h.tracker, h.detector, b)?
            }
            Some(b) => {
                return Err(Error::ModelLoad(format!(
                    "the bundle given (checksum {}) is not the recorded one ({})",
                    b.checksum(),
                    h.models.checksum
                )));
            }
            None if !h.models.builtin => {
                return Err(Error::ModelLoad(format!(
                    "recorded on a custom model bundle (checksum {}): its replay needs that bundle",
                    h.models.checksum
                )));
            }
            None if h.models.checksum != ModelBundle::builtin_checksum() => {
                return Err(Error::ModelLoad(format!(
                    "recorded on the built-in models of another build (library {}, checksum {}; \
                     this build's are {})",
                    h.library_version,
                    h.models.checksum,
                    ModelBundle::builtin_checksum()
                )));
            }
            None => Tracker::with_detector_config(h.tracker, h.detector)?,
        };
        tracker.estimator_mut().set_mirror_average(h.mirror_average);
        tracker.set_gaze_config(h.gaze);
        Ok(Self {
            tracker,
            events: recording.events(),
            pending: None,
            frames: 0,
        })
    }

    /// The replay's tracker (its gaze targets, its settings).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// Runs the recording up to and through its next frame; `None` at its end.
    ///
    /// # Errors
    /// As [`Recording::events`] (none for a parsed recording).
    pub fn next_frame(&mut self) -> Result<Option<ReplayedFrame<'_>>> {
        loop {
            let event = match self.pending.take() {
                Some(e) => e,
                None => match self.events.next() {
                    Some(e) => e?,
                    None => return Ok(None),
                },
            };
            match event {
                Event::Start(s) => self.tracker.resume_recorded_stream(&s),
                Event::GazeTargets(t) => self.tracker.set_gaze_targets(t),
                Event::Tap(t) => {
                    // The recorded tracker may have refused the tap too: the same call either way.
                    let _ = self.tracker.add_calibration_point(
                        t.target as usize,
                        t.point_mm,
                        t.timestamp_ns,
                    );
                }
                Event::Reset(ResetKind::Tracks) => self.tracker.reset(),
                Event::Reset(ResetKind::GazeCalibration) => self.tracker.reset_gaze_calibration(),
                Event::Dropped(_) | Event::Result(_) => {}
                Event::End { .. } => return Ok(None),
                Event::Frame(f) => {
                    let recorded = match self.events.next() {
                        Some(Ok(Event::Result(d))) => Some(d),
                        Some(Ok(other)) => {
                            self.pending = Some(other);
                            None
                        }
                        Some(Err(e)) => return Err(e),
                        None => None,
                    };
                    let index = self.frames;
                    self.frames += 1;
                    let tracked = f.frame().and_then(|frame| {
                        self.tracker
                            .process_frame(&frame, f.timestamp_ns)
                            .map(|_| ())
                    });
                    return Ok(Some(ReplayedFrame {
                        index,
                        timestamp_ns: f.timestamp_ns,
                        desc: f.desc,
                        result: tracked.map(|()| self.tracker.result()),
                        targets: self.tracker.gaze_targets(),
                        recorded,
                    }));
                }
            }
        }
    }
}
