//! Record and replay: what a tracker was given, written to one file of bounded size, and run again
//! through a tracker built from the same settings, checked result by result.
//!
//! - [`Recorder`] writes the file to any [`std::io::Write`] (a file through a `BufWriter`), within
//!   a byte limit; nothing is allocated per frame.
//! - [`RecordingTracker`] is the shipped [`Tracker`](crate::track::Tracker) with a recorder that
//!   can be switched on and off from any thread ([`RecordingSwitch`]): what the FFI's
//!   `FaceTracker` runs in every mode (a live stream's worker included) and `monotrack track`
//!   runs. Nothing is recorded until [`RecordingSwitch::start`].
//! - [`Recording::parse`] reads a file, refusing every malformed one with
//!   [`Error::InvalidRecording`](crate::Error::InvalidRecording); [`Recording::events`] gives its
//!   chunks as [`Event`]s.
//! - [`Replay`] runs a recording through a tracker built from its header and compares every
//!   result's [`result_digest`] with the recorded one.
//!
#![doc = include_str!("FORMAT.md")]

mod digest;
mod format;
mod session;

pub use crate::track::models::StreamStart;
pub use digest::result_digest;
pub use format::{
    DroppedFrames, Event, Events, FORMAT_VERSION, Header, MAGIC, MAX_DROPPED_TIMESTAMPS,
    ModelIdentity, RecordedFrame, Recorder, Recording, RecordingSummary, ResetKind, Tap,
};
pub use session::{RecordingSwitch, RecordingTracker, Replay, ReplayedFrame};

#[cfg(test)]
mod tests;
