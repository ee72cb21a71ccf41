//! The core's one error type. Rich on purpose: the FFI layer folds it into a small public enum.

use thiserror::Error as ThisError;

/// Everything that can go wrong in the core. "No face found" is never an error (it is an empty
/// result), and non-convergence of a fit is a status in the fit report, not an error.
#[derive(Debug, ThisError, Clone, PartialEq)]
pub enum Error {
    /// A frame whose description does not match its bytes (size, stride, format, zero size).
    #[error("invalid frame: {0}")]
    InvalidFrame(String),
    /// Camera intrinsics that are not finite and positive.
    #[error("invalid camera: {0}")]
    InvalidCamera(String),
    /// A frame timestamp that does not come after the previous frame's (video and live-stream
    /// tracking need strictly increasing times: a camera restart or a repeated frame shows here,
    /// and `reset` starts the clock again).
    #[error("invalid timestamp: {0}")]
    InvalidTimestamp(String),
    /// Any other caller input that cannot be used (wrong number of landmarks, NaN coordinates, ...).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A configuration value out of its documented range.
    #[error("invalid config: {0}")]
    InvalidConfig(String),
    /// An embedded or supplied model (network weights, face model data) that cannot be loaded.
    #[error("model load: {0}")]
    ModelLoad(String),
    /// A model bundle of a format version this library does not read.
    #[error("model bundle version: {0}")]
    BundleVersion(String),
    /// A model bundle whose checksum does not match its bytes (a damaged file).
    #[error("model bundle checksum: {0}")]
    BundleChecksum(String),
    /// A recording file ([`crate::record`]) that is not one this library reads: no magic, another
    /// format version, a chunk cut off or out of place, a field out of range.
    #[error("invalid recording: {0}")]
    InvalidRecording(String),
    /// A call the object cannot take in its present state (a recording started while one runs,
    /// stopped while none does).
    #[error("invalid state: {0}")]
    InvalidState(String),
    /// Writing a recording failed (the disk is full, the file cannot be created).
    #[error("i/o: {0}")]
    Io(String),
    /// A broken internal invariant; a bug if it ever surfaces.
    #[error("internal: {0}")]
    Internal(String),
}

/// Shorthand used across the core.
pub type Result<T, E = Error> = std::result::Result<T, E>;
