//! The recording file (FORMAT.md): [`Recorder`] writes it, [`Recording`] reads it.

use crate::camera::Rotation;
use crate::detect::DetectorConfig;
use crate::error::{Error, Result};
use crate::gaze::{GazeCalibration, GazeConfig, MAX_CALIBRATION_TAPS, Target};
use crate::image::{Frame, FrameDesc, PixelFormat};
use crate::model::bundle::ModelBundle;
use crate::track::models::StreamStart;
use crate::track::{Tracker, TrackerConfig};
use serde::{Deserialize, Serialize};
use std::io::Write;

/// The first bytes of every recording.
pub const MAGIC: &[u8; 8] = b"MTRECORD";

/// The format version this library writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// Most dropped frames' timestamps one `dropped` chunk holds (the rest are only counted).
pub const MAX_DROPPED_TIMESTAMPS: usize = 64;

/// A chunk's kind and length.
const CHUNK_HEAD: u64 = 5;
/// The `end` chunk, for which room is always kept.
const END_CHUNK: u64 = CHUNK_HEAD + 1;
/// The `result` chunk, for which room is kept with each frame.
const RESULT_CHUNK: u64 = CHUNK_HEAD + 9;
/// A `frame` chunk's fields before the bytes.
const FRAME_FIELDS: usize = 32;
/// The magic and the version.
const PREAMBLE: usize = MAGIC.len() + 4;

const HEADER: u8 = 1;
const START: u8 = 2;
const FRAME: u8 = 3;
const RESULT: u8 = 4;
const DROPPED: u8 = 5;
const GAZE_TARGETS: u8 = 6;
const TAP: u8 = 7;
const RESET: u8 = 8;
const END: u8 = 9;

/// Which models a recorded tracker ran on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ModelIdentity {
    /// The library's own models.
    pub builtin: bool,
    /// The CRC-32 a bundle file of the models ends with ([`ModelBundle::checksum`]).
    pub checksum: u32,
}

impl ModelIdentity {
    /// The library's own models.
    pub fn builtin() -> Self {
        Self {
            builtin: true,
            checksum: ModelBundle::builtin_checksum(),
        }
    }

    /// The models of `bundle` (built-in when it holds exactly the library's own).
    pub fn of(bundle: &ModelBundle) -> Self {
        let checksum = bundle.checksum();
        Self {
            builtin: checksum == ModelBundle::builtin_checksum(),
            checksum,
        }
    }
}

/// The `header` chunk: what a replay builds its tracker from (FORMAT.md, "The header").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The recording library's version.
    pub library_version: String,
    /// The recording process's CPU architecture (`std::env::consts::ARCH`).
    pub arch: String,
    /// The kernel choice it ran ([`crate::kernels::KernelChoice`]'s text).
    pub kernels: String,
    /// The CPU in words.
    pub cpu: String,
    /// The tracker's settings.
    pub tracker: TrackerConfig,
    /// Its detector's settings.
    pub detector: DetectorConfig,
    /// M3's mirror-average mode.
    pub mirror_average: bool,
    /// The point-of-gaze settings.
    pub gaze: GazeConfig,
    /// The models.
    pub models: ModelIdentity,
}

impl Header {
    /// The header of a recording of `tracker`, which runs on `models`, in this process.
    pub fn for_tracker(tracker: &Tracker, models: ModelIdentity) -> Self {
        Self {
            library_version: env!("CARGO_PKG_VERSION").to_string(),
            arch: std::env::consts::ARCH.to_string(),
            kernels: crate::kernels::choice().to_string(),
            cpu: crate::kernels::cpu_name(),
            tracker: *tracker.config(),
            detector: *tracker.detector().detector().config(),
            mirror_average: tracker.estimator().m3().is_some_and(|m| m.mirror_average()),
            gaze: *tracker.gaze_config(),
            models,
        }
    }
}

/// What a recording holds, as its writer counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RecordingSummary {
    /// Frames recorded.
    pub frames: u64,
    /// Frames a live stream dropped while recording (submitted, not tracked).
    pub dropped_frames: u64,
    /// Bytes written, the `end` chunk included once the recording is finished.
    pub bytes: u64,
    /// Whether recording stopped at the size limit.
    pub truncated: bool,
}

/// What a `reset` chunk says was reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetKind {
    /// Every track ended ([`crate::track::FaceTracker::reset`]).
    Tracks,
    /// The tap calibration forgotten ([`crate::track::FaceTracker::reset_gaze_calibration`]).
    GazeCalibration,
}

/// Writes a recording (FORMAT.md) to `W`, within `max_bytes`. Recording never disturbs tracking:
/// a chunk past the limit ends the recording (truncated), a write error ends it too and is
/// reported by [`Self::finish`]. Nothing is allocated per frame. Dropping it unfinished writes the
/// `end` chunk, so the file stays readable.
pub struct Recorder<W: Write = Box<dyn Write + Send>> {
    /// `None` once finished.
    out: Option<W>,
    max_bytes: u64,
    written: u64,
    frames: u64,
    dropped: u64,
    truncated: bool,
    failed: Option<String>,
    begun: bool,
    /// The last chunk was a frame, whose result may follow.
    result_due: bool,
}

impl<W: Write> std::fmt::Debug for Recorder<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("max_bytes", &self.max_bytes)
            .field("summary", &self.summary())
            .field("failed", &self.failed)
            .finish_non_exhaustive()
    }
}

fn io(e: &std::io::Error) -> Error {
    Error::Io(format!("writing the recording: {e}"))
}

impl<W: Write> Recorder<W> {
    /// Starts a recording in `out` with `header`; the file may hold at most `max_bytes` bytes.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] when `max_bytes` leaves no room for the header and the `end`
    /// chunk; [`Error::Io`] when writing fails.
    pub fn new(mut out: W, max_bytes: u64, header: &Header) -> Result<Self> {
        let json = serde_json::to_vec(header)
            .map_err(|e| Error::Internal(format!("recording header: {e}")))?;
        let need = PREAMBLE as u64 + CHUNK_HEAD + json.len() as u64 + END_CHUNK;
        if need > max_bytes {
            return Err(Error::InvalidConfig(format!(
                "a recording of at most {max_bytes} bytes leaves no room: its header and end \
                 take {need}"
            )));
        }
        let len = u32::try_from(json.len())
            .map_err(|_| Error::Internal("recording header too long".into()))?;
        out.write_all(MAGIC).map_err(|e| io(&e))?;
        out.write_all(&FORMAT_VERSION.to_le_bytes())
            .map_err(|e| io(&e))?;
        out.write_all(&[HEADER]).map_err(|e| io(&e))?;
        out.write_all(&len.to_le_bytes()).map_err(|e| io(&e))?;
        out.write_all(&json).map_err(|e| io(&e))?;
        Ok(Self {
            out: Some(out),
            max_bytes,
            written: need - END_CHUNK,
            frames: 0,
            dropped: 0,
            truncated: false,
            failed: None,
            begun: false,
            result_due: false,
        })
    }

    /// Whether [`Self::begin`] was called.
    pub fn is_begun(&self) -> bool {
        self.begun
    }

    /// What was written so far.
    pub fn summary(&self) -> RecordingSummary {
        RecordingSummary {
            frames: self.frames,
            dropped_frames: self.dropped,
            bytes: self.written,
            truncated: self.truncated,
        }
    }

    /// Writes one chunk of `parts` when it fits with `keep` more bytes and the `end` chunk after
    /// it; otherwise recording stops (truncated). Returns whether it was written.
    fn put(&mut self, kind: u8, parts: &[&[u8]], keep: u64) -> bool {
        if self.truncated || self.failed.is_some() {
            return false;
        }
        let Some(out) = self.out.as_mut() else {
            return false;
        };
        let len: u64 = parts.iter().map(|p| p.len() as u64).sum();
        let total = CHUNK_HEAD + len + keep + END_CHUNK;
        let Ok(len32) = u32::try_from(len) else {
            self.truncated = true;
            return false;
        };
        if self.written.saturating_add(total) > self.max_bytes {
            self.truncated = true;
            return false;
        }
        let mut head = [kind, 0, 0, 0, 0];
        head[1..].copy_from_slice(&len32.to_le_bytes());
        let written = out
            .write_all(&head)
            .and_then(|()| parts.iter().try_for_each(|p| out.write_all(p)));
        match written {
            Ok(()) => {
                self.written += CHUNK_HEAD + len;
                true
            }
            Err(e) => {
                self.failed = Some(e.to_string());
                false
            }
        }
    }

    /// The `start` chunk, and the targets set as a `gaze_targets` chunk when there are any: call
    /// once, before anything else.
    pub fn begin(&mut self, start: &StreamStart, targets: &[Target]) {
        self.begun = true;
        self.result_due = false;
        let taps = start.calibration.tap_offsets();
        let mut fields = [0u8; 24];
        fields[..8].copy_from_slice(&start.next_face_id.to_le_bytes());
        fields[8..16].copy_from_slice(&start.frame_index.to_le_bytes());
        fields[16..20].copy_from_slice(&start.whole_frame_turns.to_le_bytes());
        let n = taps.len().min(MAX_CALIBRATION_TAPS);
        fields[20..].copy_from_slice(&(n as u32).to_le_bytes());
        let mut offsets = [0u8; 32 * MAX_CALIBRATION_TAPS];
        for (chunk, tap) in offsets.chunks_exact_mut(32).zip(&taps[..n]) {
            for (c, v) in chunk.chunks_exact_mut(8).zip(tap.iter().flatten()) {
                c.copy_from_slice(&v.to_le_bytes());
            }
        }
        self.put(START, &[&fields, &offsets[..32 * n]], 0);
        if !targets.is_empty() {
            self.gaze_targets(targets);
        }
    }

    /// A `frame` chunk: `frame` as the tracker is about to read it, taken at `timestamp_ns`.
    /// Room for its result is kept with it.
    pub fn frame(&mut self, frame: &Frame<'_>, timestamp_ns: i64) {
        self.result_due = false;
        let d = frame.desc();
        let (Ok(len), Ok(row), Ok(crow), Ok(cpix)) = (
            d.required_len(),
            u32::try_from(d.row_stride),
            u32::try_from(d.chroma_row_stride),
            u32::try_from(d.chroma_pixel_stride),
        ) else {
            // A description no u32 field holds also has more bytes than a chunk can.
            self.truncated = true;
            return;
        };
        let Some(bytes) = frame.data().get(..len) else {
            self.truncated = true;
            return;
        };
        let mut f = [0u8; FRAME_FIELDS];
        f[..8].copy_from_slice(&timestamp_ns.to_le_bytes());
        f[8..12].copy_from_slice(&d.width.to_le_bytes());
        f[12..16].copy_from_slice(&d.height.to_le_bytes());
        f[16] = format_code(d.format);
        f[17..19].copy_from_slice(&(d.rotation.degrees() as u16).to_le_bytes());
        f[19] = u8::from(d.mirrored);
        f[20..24].copy_from_slice(&row.to_le_bytes());
        f[24..28].copy_from_slice(&crow.to_le_bytes());
        f[28..32].copy_from_slice(&cpix.to_le_bytes());
        if self.put(FRAME, &[&f, bytes], RESULT_CHUNK) {
            self.frames += 1;
            self.result_due = true;
        }
    }

    /// The `result` chunk of the frame just recorded: `digest` ([`super::result_digest`]), or
    /// `None` when the tracker returned an error. Nothing when that frame was not recorded.
    pub fn result(&mut self, digest: Option<u64>) {
        if !std::mem::take(&mut self.result_due) {
            return;
        }
        let mut f = [0u8; 9];
        f[0] = u8::from(digest.is_some());
        f[1..].copy_from_slice(&digest.unwrap_or(0).to_le_bytes());
        // The frame kept its room: this fits.
        self.put(RESULT, &[&f], 0);
    }

    /// A `dropped` chunk: `frames` frames dropped before the next one taken, the first of whose
    /// timestamps are `timestamps_ns` (at most [`MAX_DROPPED_TIMESTAMPS`] are kept).
    pub fn dropped(&mut self, frames: u64, timestamps_ns: &[i64]) {
        self.result_due = false;
        if frames == 0 {
            return;
        }
        let n = timestamps_ns
            .len()
            .min(MAX_DROPPED_TIMESTAMPS)
            .min(usize::try_from(frames).unwrap_or(usize::MAX));
        let mut f = [0u8; 12];
        f[..8].copy_from_slice(&frames.to_le_bytes());
        f[8..].copy_from_slice(&(n as u32).to_le_bytes());
        let mut ts = [0u8; 8 * MAX_DROPPED_TIMESTAMPS];
        for (c, t) in ts.chunks_exact_mut(8).zip(&timestamps_ns[..n]) {
            c.copy_from_slice(&t.to_le_bytes());
        }
        if self.put(DROPPED, &[&f, &ts[..8 * n]], 0) {
            self.dropped += frames;
        }
    }

    /// A `gaze_targets` chunk: `targets` set, replacing any before.
    pub fn gaze_targets(&mut self, targets: &[Target]) {
        self.result_due = false;
        let mut b = Vec::new();
        b.extend_from_slice(&(targets.len() as u32).to_le_bytes());
        for t in targets {
            let id = t.id.as_bytes();
            let id = &id[..id.len().min(usize::from(u16::MAX))];
            b.extend_from_slice(&(id.len() as u16).to_le_bytes());
            b.extend_from_slice(id);
            b.extend_from_slice(&(t.corners().len() as u32).to_le_bytes());
            for c in t.corners() {
                for v in c.iter() {
                    b.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        self.put(GAZE_TARGETS, &[&b], 0);
    }

    /// A `tap` chunk: `add_calibration_point(target, point_mm, timestamp_ns)`.
    pub fn tap(&mut self, target: usize, point_mm: [f64; 2], timestamp_ns: i64) {
        self.result_due = false;
        let mut f = [0u8; 28];
        f[..4].copy_from_slice(&u32::try_from(target).unwrap_or(u32::MAX).to_le_bytes());
        f[4..12].copy_from_slice(&point_mm[0].to_le_bytes());
        f[12..20].copy_from_slice(&point_mm[1].to_le_bytes());
        f[20..].copy_from_slice(&timestamp_ns.to_le_bytes());
        self.put(TAP, &[&f], 0);
    }

    /// A `reset` chunk.
    pub fn reset(&mut self, what: ResetKind) {
        self.result_due = false;
        let code = match what {
            ResetKind::Tracks => 0,
            ResetKind::GazeCalibration => 1,
        };
        self.put(RESET, &[&[code]], 0);
    }

    /// Writes the `end` chunk and flushes, giving the writer back.
    fn close(&mut self) -> Option<W> {
        let mut out = self.out.take()?;
        if self.failed.is_none() {
            let end = [END, 1, 0, 0, 0, u8::from(self.truncated)];
            match out.write_all(&end).and_then(|()| out.flush()) {
                Ok(()) => self.written += END_CHUNK,
                Err(e) => self.failed = Some(e.to_string()),
            }
        }
        Some(out)
    }

    /// Ends the recording (the `end` chunk) and flushes it.
    ///
    /// # Errors
    /// [`Error::Io`] when any write failed: the file is incomplete.
    pub fn finish(mut self) -> Result<RecordingSummary> {
        drop(self.close());
        match &self.failed {
            None => Ok(self.summary()),
            Some(e) => Err(Error::Io(format!(
                "writing the recording failed after {} frames: {e}",
                self.frames
            ))),
        }
    }

    /// [`Self::finish`], giving the writer back too (a test's buffer).
    ///
    /// # Errors
    /// As [`Self::finish`].
    pub fn finish_into(mut self) -> Result<(W, RecordingSummary)> {
        let out = self
            .close()
            .ok_or_else(|| Error::Internal("recording finished twice".into()))?;
        match &self.failed {
            None => Ok((out, self.summary())),
            Some(e) => Err(Error::Io(format!("writing the recording failed: {e}"))),
        }
    }
}

impl<W: Write> Drop for Recorder<W> {
    fn drop(&mut self) {
        drop(self.close());
    }
}

fn format_code(f: PixelFormat) -> u8 {
    match f {
        PixelFormat::Rgba8 => 0,
        PixelFormat::Bgra8 => 1,
        PixelFormat::Rgb8 => 2,
        PixelFormat::Gray8 => 3,
        PixelFormat::Nv21 => 4,
        PixelFormat::Nv12 => 5,
        PixelFormat::I420 => 6,
    }
}

fn format_of(code: u8) -> Option<PixelFormat> {
    Some(match code {
        0 => PixelFormat::Rgba8,
        1 => PixelFormat::Bgra8,
        2 => PixelFormat::Rgb8,
        3 => PixelFormat::Gray8,
        4 => PixelFormat::Nv21,
        5 => PixelFormat::Nv12,
        6 => PixelFormat::I420,
        _ => return None,
    })
}

/// A recorded frame: bytes borrowed from the file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordedFrame<'a> {
    /// The caller's timestamp, nanoseconds.
    pub timestamp_ns: i64,
    /// Its description.
    pub desc: FrameDesc,
    /// Its bytes (exactly what the description covers).
    pub bytes: &'a [u8],
}

impl<'a> RecordedFrame<'a> {
    /// The frame, for a tracker.
    ///
    /// # Errors
    /// None for a frame of a parsed recording (checked when read); [`Error::InvalidFrame`]
    /// otherwise.
    pub fn frame(&self) -> Result<Frame<'a>> {
        Frame::new(self.bytes, self.desc)
    }
}

/// A `dropped` chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DroppedFrames<'a> {
    /// Frames dropped.
    pub frames: u64,
    timestamps: &'a [u8],
}

impl<'a> DroppedFrames<'a> {
    /// The timestamps kept, nanoseconds: the first dropped frames'.
    pub fn timestamps_ns(&self) -> impl Iterator<Item = i64> + 'a {
        self.timestamps
            .chunks_exact(8)
            .map(|c| i64::from_le_bytes(c.try_into().unwrap_or_default()))
    }
}

/// A `tap` chunk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tap {
    /// The target's index among those set.
    pub target: u32,
    /// The point tapped, (u, v) mm on the target.
    pub point_mm: [f64; 2],
    /// When, nanoseconds (the frames' clock).
    pub timestamp_ns: i64,
}

/// One chunk after the header.
#[derive(Debug, Clone, PartialEq)]
pub enum Event<'a> {
    /// The `start` chunk.
    Start(StreamStart),
    /// A frame the tracker tracked.
    Frame(RecordedFrame<'a>),
    /// The previous frame's outcome: its result's digest, `None` for an error.
    Result(Option<u64>),
    /// Frames a live stream dropped before the next frame.
    Dropped(DroppedFrames<'a>),
    /// Gaze targets set.
    GazeTargets(Vec<Target>),
    /// A tap.
    Tap(Tap),
    /// A reset.
    Reset(ResetKind),
    /// The end.
    End {
        /// Recording stopped at the size limit.
        truncated: bool,
    },
}

fn invalid(at: usize, what: impl std::fmt::Display) -> Error {
    Error::InvalidRecording(format!("at byte {at}: {what}"))
}

/// Little-endian fields off the front of one chunk's payload.
struct Fields<'a> {
    rest: &'a [u8],
    /// The chunk's offset in the file, for messages.
    at: usize,
    name: &'static str,
}

impl<'a> Fields<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        if n > self.rest.len() {
            return Err(invalid(
                self.at,
                format!("the {} chunk is too short", self.name),
            ));
        }
        let (head, rest) = self.rest.split_at(n);
        self.rest = rest;
        Ok(head)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        Ok(self.take(N)?.try_into().unwrap_or([0; N]))
    }

    fn u8(&mut self) -> Result<u8> {
        Ok(self.array::<1>()?[0])
    }

    fn u16(&mut self) -> Result<u16> {
        Ok(u16::from_le_bytes(self.array()?))
    }

    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array()?))
    }

    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array()?))
    }

    fn i64(&mut self) -> Result<i64> {
        Ok(i64::from_le_bytes(self.array()?))
    }

    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array()?))
    }

    fn flag(&mut self, what: &str) -> Result<bool> {
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(invalid(self.at, format!("{what} is {v}, not 0 or 1"))),
        }
    }

    fn done(&self) -> Result<()> {
        if self.rest.is_empty() {
            Ok(())
        } else {
            Err(invalid(
                self.at,
                format!(
                    "the {} chunk has {} bytes more than it holds",
                    self.name,
                    self.rest.len()
                ),
            ))
        }
    }

    /// A `u32` count of items of at least `min_size` bytes each, checked against the bytes
    /// left, so that a corrupt count allocates nothing.
    fn count(&mut self, min_size: usize, what: &str) -> Result<usize> {
        let n = self.u32()? as usize;
        if n.saturating_mul(min_size) > self.rest.len() {
            return Err(invalid(
                self.at,
                format!("{n} {what} do not fit in the {} chunk", self.name),
            ));
        }
        Ok(n)
    }
}

fn chunk_name(kind: u8) -> &'static str {
    match kind {
        HEADER => "header",
        START => "start",
        FRAME => "frame",
        RESULT => "result",
        DROPPED => "dropped",
        GAZE_TARGETS => "gaze_targets",
        TAP => "tap",
        RESET => "reset",
        END => "end",
        _ => "unknown",
    }
}

/// The chunks of a recording after its header, in order, each checked (FORMAT.md); the first
/// error ends them.
#[derive(Debug, Clone)]
pub struct Events<'a> {
    bytes: &'a [u8],
    pos: usize,
    started: bool,
    after_frame: bool,
    done: bool,
}

impl<'a> Events<'a> {
    fn read(&mut self) -> Result<Event<'a>> {
        let at = self.pos;
        let rest = self.bytes.get(at..).unwrap_or_default();
        if rest.is_empty() {
            return Err(invalid(
                at,
                "the file ends without its end chunk: it was cut off",
            ));
        }
        let Some((head, body)) = rest.split_first_chunk::<5>() else {
            return Err(invalid(at, "a chunk's kind and length are cut off"));
        };
        let kind = head[0];
        let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
        if len > body.len() {
            return Err(invalid(
                at,
                format!(
                    "a {} chunk of {len} bytes runs past the end of the file ({} left)",
                    chunk_name(kind),
                    body.len()
                ),
            ));
        }
        self.pos = at + 5 + len;
        let after_frame = std::mem::take(&mut self.after_frame);
        let mut f = Fields {
            rest: &body[..len],
            at,
            name: chunk_name(kind),
        };
        let needs_start = matches!(kind, FRAME | RESULT | DROPPED | GAZE_TARGETS | TAP | RESET);
        if needs_start && !self.started {
            return Err(invalid(
                at,
                format!("a {} chunk before the start chunk", chunk_name(kind)),
            ));
        }
        let event = match kind {
            HEADER => return Err(invalid(at, "a second header chunk")),
            START => {
                if self.started {
                    return Err(invalid(at, "a second start chunk"));
                }
                self.started = true;
                let next_face_id = f.u64()?;
                let frame_index = f.u64()?;
                let whole_frame_turns = f.u32()?;
                let n = f.count(32, "calibration taps")?;
                let mut taps = Vec::with_capacity(n.min(MAX_CALIBRATION_TAPS));
                for _ in 0..n {
                    taps.push([[f.f64()?, f.f64()?], [f.f64()?, f.f64()?]]);
                }
                f.done()?;
                let calibration = GazeCalibration::from_tap_offsets(&taps)
                    .map_err(|e| invalid(at, format!("the start chunk's calibration: {e}")))?;
                Event::Start(StreamStart {
                    next_face_id,
                    frame_index,
                    whole_frame_turns,
                    calibration,
                })
            }
            FRAME => {
                let timestamp_ns = f.i64()?;
                let width = f.u32()?;
                let height = f.u32()?;
                let code = f.u8()?;
                let format = format_of(code)
                    .ok_or_else(|| invalid(at, format!("pixel format {code} is unknown")))?;
                let deg = f.u16()?;
                let rotation = Rotation::from_degrees(i32::from(deg))
                    .map_err(|_| invalid(at, format!("rotation {deg}° is not a quarter turn")))?;
                let mirrored = f.flag("mirrored")?;
                let desc = FrameDesc {
                    width,
                    height,
                    format,
                    row_stride: f.u32()? as usize,
                    chroma_row_stride: f.u32()? as usize,
                    chroma_pixel_stride: f.u32()? as usize,
                    rotation,
                    mirrored,
                };
                let bytes = f.rest;
                let need = desc
                    .required_len()
                    .map_err(|e| invalid(at, format!("the frame's description: {e}")))?;
                if need != bytes.len() {
                    return Err(invalid(
                        at,
                        format!(
                            "the frame's description covers {need} bytes; the chunk holds {}",
                            bytes.len()
                        ),
                    ));
                }
                Frame::new(bytes, desc)
                    .map_err(|e| invalid(at, format!("the frame's description: {e}")))?;
                self.after_frame = true;
                Event::Frame(RecordedFrame {
                    timestamp_ns,
                    desc,
                    bytes,
                })
            }
            RESULT => {
                if !after_frame {
                    return Err(invalid(at, "a result chunk that does not follow a frame"));
                }
                let ok = f.flag("the result's status")?;
                let digest = f.u64()?;
                f.done()?;
                if !ok && digest != 0 {
                    return Err(invalid(at, "a failed frame's result carries a digest"));
                }
                Event::Result(ok.then_some(digest))
            }
            DROPPED => {
                let frames = f.u64()?;
                let n = f.count(8, "timestamps")?;
                if n > MAX_DROPPED_TIMESTAMPS || n as u64 > frames || frames == 0 {
                    return Err(invalid(
                        at,
                        format!("{n} timestamps of {frames} dropped frames"),
                    ));
                }
                let timestamps = f.take(8 * n)?;
                f.done()?;
                Event::Dropped(DroppedFrames { frames, timestamps })
            }
            GAZE_TARGETS => {
                let n = f.count(6, "targets")?;
                let mut targets: Vec<Target> = Vec::new();
                for _ in 0..n {
                    let id_len = usize::from(f.u16()?);
                    let id = std::str::from_utf8(f.take(id_len)?)
                        .map_err(|_| invalid(at, "a target's id is not UTF-8"))?;
                    if targets.iter().any(|t| t.id == id) {
                        return Err(invalid(at, format!("target id {id:?} given twice")));
                    }
                    let corners = f.count(24, "corners")?;
                    let mut c = Vec::with_capacity(corners);
                    for _ in 0..corners {
                        c.push([f.f64()?, f.f64()?, f.f64()?]);
                    }
                    targets.push(
                        Target::new(id, &c)
                            .map_err(|e| invalid(at, format!("a gaze target: {e}")))?,
                    );
                }
                f.done()?;
                Event::GazeTargets(targets)
            }
            TAP => {
                let target = f.u32()?;
                let point_mm = [f.f64()?, f.f64()?];
                let timestamp_ns = f.i64()?;
                f.done()?;
                Event::Tap(Tap {
                    target,
                    point_mm,
                    timestamp_ns,
                })
            }
            RESET => {
                let what = match f.u8()? {
                    0 => ResetKind::Tracks,
                    1 => ResetKind::GazeCalibration,
                    v => return Err(invalid(at, format!("reset kind {v} is unknown"))),
                };
                f.done()?;
                Event::Reset(what)
            }
            END => {
                let truncated = f.flag("truncated")?;
                f.done()?;
                if self.pos != self.bytes.len() {
                    return Err(invalid(
                        self.pos,
                        format!("{} bytes after the end chunk", self.bytes.len() - self.pos),
                    ));
                }
                Event::End { truncated }
            }
            k => return Err(invalid(at, format!("chunk kind {k} is unknown"))),
        };
        Ok(event)
    }
}

impl<'a> Iterator for Events<'a> {
    type Item = Result<Event<'a>>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let r = self.read();
        self.done = matches!(r, Err(_) | Ok(Event::End { .. }));
        Some(r)
    }
}

/// A recording file, read and checked whole ([`Self::parse`]).
#[derive(Debug, Clone)]
pub struct Recording<'a> {
    header: Header,
    header_json: &'a [u8],
    events: Events<'a>,
    frames: u64,
    results: u64,
    dropped_frames: u64,
    truncated: bool,
}

impl<'a> Recording<'a> {
    /// Reads `bytes` and checks every chunk (FORMAT.md). Borrows the frames' bytes; allocates
    /// only what the header and the gaze targets hold, never more than the file's own bytes
    /// justify.
    ///
    /// # Errors
    /// [`Error::InvalidRecording`] naming the first problem and its byte offset: no magic, another
    /// format version, a chunk cut off, out of order or out of range, a header whose settings are
    /// out of range, a file without its end chunk.
    pub fn parse(bytes: &'a [u8]) -> Result<Self> {
        if bytes.len() < PREAMBLE || &bytes[..MAGIC.len()] != MAGIC {
            return Err(Error::InvalidRecording(
                "not a monotrack recording (no MTRECORD magic)".into(),
            ));
        }
        let version =
            u32::from_le_bytes(bytes[MAGIC.len()..PREAMBLE].try_into().unwrap_or_default());
        if version != FORMAT_VERSION {
            return Err(Error::InvalidRecording(format!(
                "recording format version {version}; this library reads version {FORMAT_VERSION}"
            )));
        }
        let rest = &bytes[PREAMBLE..];
        let Some((head, body)) = rest.split_first_chunk::<5>() else {
            return Err(invalid(PREAMBLE, "the header chunk is cut off"));
        };
        if head[0] != HEADER {
            return Err(invalid(
                PREAMBLE,
                format!(
                    "the first chunk is a {} chunk, not the header",
                    chunk_name(head[0])
                ),
            ));
        }
        let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
        let header_json = body
            .get(..len)
            .ok_or_else(|| invalid(PREAMBLE, "the header chunk runs past the end of the file"))?;
        let header: Header = serde_json::from_slice(header_json)
            .map_err(|e| invalid(PREAMBLE, format!("the header: {e}")))?;
        header
            .tracker
            .validate()
            .map_err(|e| invalid(PREAMBLE, format!("the header's tracker settings: {e}")))?;
        let events = Events {
            bytes,
            pos: PREAMBLE + 5 + len,
            started: false,
            after_frame: false,
            done: false,
        };
        let mut r = Self {
            header,
            header_json,
            events: events.clone(),
            frames: 0,
            results: 0,
            dropped_frames: 0,
            truncated: false,
        };
        for e in events {
            match e? {
                Event::Frame(_) => r.frames += 1,
                Event::Result(_) => r.results += 1,
                Event::Dropped(d) => r.dropped_frames = r.dropped_frames.saturating_add(d.frames),
                Event::End { truncated } => r.truncated = truncated,
                _ => {}
            }
        }
        Ok(r)
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The header's JSON as it was written.
    pub fn header_json(&self) -> &'a [u8] {
        self.header_json
    }

    /// The chunks after the header, in order (each already checked by [`Self::parse`]).
    pub fn events(&self) -> Events<'a> {
        self.events.clone()
    }

    /// Frames recorded.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Frames recorded with their result's digest.
    pub fn checked_frames(&self) -> u64 {
        self.results
    }

    /// Frames a live stream dropped while recording.
    pub fn dropped_frames(&self) -> u64 {
        self.dropped_frames
    }

    /// Whether recording stopped at its size limit.
    pub fn truncated(&self) -> bool {
        self.truncated
    }
}
