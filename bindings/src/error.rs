//! The one public error type, converted from the core's rich error in exactly one place.

use monotrack_core::Error as CoreError;

/// Errors surfaced to Kotlin (`MonotrackException`) and Swift (`MonotrackError`). Few variants on
/// purpose: apps branch on the kind, the message says what exactly was wrong.
#[derive(Debug, thiserror::Error, uniffi::Error)]
pub enum MonotrackError {
    /// The frame's bytes do not match its description (size, strides, format, zero size), or its
    /// timestamp went backwards in video mode.
    #[error("invalid frame: {msg}")]
    InvalidFrame {
        /// What was wrong.
        msg: String,
    },
    /// A configuration or input value out of range (intrinsics, thresholds, landmarks, JSON).
    #[error("invalid config: {msg}")]
    InvalidConfig {
        /// What was wrong.
        msg: String,
    },
    /// Model bytes could not be loaded.
    #[error("model load: {msg}")]
    ModelLoad {
        /// What was wrong.
        msg: String,
    },
    /// A bug: an internal invariant broke or a panic was caught.
    #[error("internal: {msg}")]
    Internal {
        /// What was wrong.
        msg: String,
    },
}

impl From<CoreError> for MonotrackError {
    fn from(e: CoreError) -> Self {
        let msg = e.to_string();
        match e {
            CoreError::InvalidFrame(_) => Self::InvalidFrame { msg },
            CoreError::InvalidCamera(_)
            | CoreError::InvalidInput(_)
            | CoreError::InvalidConfig(_) => Self::InvalidConfig { msg },
            CoreError::ModelLoad(_) => Self::ModelLoad { msg },
            CoreError::Internal(_) => Self::Internal { msg },
        }
    }
}
