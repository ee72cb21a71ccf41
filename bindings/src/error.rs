//! The one public error type, converted from the core's rich error in exactly one place.

use monotrack_core::Error as CoreError;

/// Errors surfaced to Kotlin (`MonotrackException`) and Swift (`MonotrackError`). Few variants on
/// purpose: apps branch on the kind, the message says what exactly was wrong.
#[derive(Debug, thiserror::Error, uniffi::Error)]
pub enum MonotrackError {
    /// The frame's bytes do not match its description (size, strides, format, zero size), or a
    /// tap has no frame with a face near its time.
    #[error("invalid frame: {msg}")]
    InvalidFrame {
        /// What was wrong.
        msg: String,
    },
    /// A frame's timestamp is not after the previous frame's (video and live-stream modes): a
    /// restarted camera or a repeated frame. Nothing was tracked; `reset()` starts the clock again.
    #[error("invalid timestamp: {msg}")]
    InvalidTimestamp {
        /// What was wrong.
        msg: String,
    },
    /// A call the tracker cannot take now: one of another running mode, or any after
    /// `shutdown()`.
    #[error("invalid state: {msg}")]
    InvalidState {
        /// What was wrong.
        msg: String,
    },
    /// A configuration or input value out of range (intrinsics, thresholds, landmarks, JSON).
    #[error("invalid config: {msg}")]
    InvalidConfig {
        /// What was wrong.
        msg: String,
    },
    /// A model bundle of a format version this library does not read.
    #[error("model bundle version: {msg}")]
    BundleVersion {
        /// What was wrong.
        msg: String,
    },
    /// A model bundle whose checksum does not match its bytes (a damaged file).
    #[error("model bundle checksum: {msg}")]
    BundleChecksum {
        /// What was wrong.
        msg: String,
    },
    /// Model bytes could not be loaded (a corrupt or incompatible network, a bundle that is no
    /// bundle).
    #[error("model load: {msg}")]
    ModelLoad {
        /// What was wrong.
        msg: String,
    },
    /// Writing a recording failed (`FaceTracker::start_recording`, `stop_recording`): the file
    /// cannot be created, or the disk is full.
    #[error("i/o: {msg}")]
    Io {
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
            CoreError::InvalidTimestamp(_) => Self::InvalidTimestamp { msg },
            CoreError::InvalidState(_) => Self::InvalidState { msg },
            CoreError::Io(_) => Self::Io { msg },
            // Apps hand the FFI no recording to read (`monotrack replay` reads them): should one
            // reach it, it is input that cannot be used.
            CoreError::InvalidCamera(_)
            | CoreError::InvalidInput(_)
            | CoreError::InvalidConfig(_)
            | CoreError::InvalidRecording(_) => Self::InvalidConfig { msg },
            CoreError::ModelLoad(_) => Self::ModelLoad { msg },
            CoreError::BundleVersion(_) => Self::BundleVersion { msg },
            CoreError::BundleChecksum(_) => Self::BundleChecksum { msg },
            CoreError::Internal(_) => Self::Internal { msg },
        }
    }
}

/// A core error where the caller's input is a frame or a tap: what it could not give (a tap with
/// no face near its time) is `InvalidFrame`.
pub(crate) fn input_as_frame(e: CoreError) -> MonotrackError {
    match e {
        CoreError::InvalidInput(msg) => MonotrackError::InvalidFrame { msg },
        e => e.into(),
    }
}

/// Runs one FFI call, turning a panic into [`MonotrackError::Internal`]: every fallible exported
/// function's body goes through here, so Kotlin and Swift see the SDK's own error type (never
/// uniffi's `InternalException` / `rustPanic`) and an app's `catch` of `MonotrackException`
/// covers everything the SDK raises. The objects' mutexes recover from the poisoning a caught
/// panic leaves (their tracks restart).
pub(crate) fn guard<T>(
    call: impl FnOnce() -> Result<T, MonotrackError>,
) -> Result<T, MonotrackError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(call)).unwrap_or_else(|payload| {
        Err(MonotrackError::Internal {
            msg: format!("panic: {}", panic_message(payload.as_ref())),
        })
    })
}

/// Runs an FFI call that returns no error: a panic is swallowed (after the panic hook has
/// reported it), since the foreign side has no error to receive and an unwinding panic must not
/// cross into it.
pub(crate) fn guard_infallible(call: impl FnOnce()) {
    let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(call));
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("(no message)")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_becomes_an_internal_error() {
        let r: Result<(), _> = guard(|| panic!("broken invariant {}", 7));
        match r {
            Err(MonotrackError::Internal { msg }) => assert!(msg.contains("broken invariant 7")),
            other => panic!("expected Internal, got {other:?}"),
        }
        let r: Result<u8, _> = guard(|| panic!("static"));
        assert!(matches!(r, Err(MonotrackError::Internal { msg }) if msg.contains("static")));
        assert_eq!(guard(|| Ok(3)).unwrap(), 3);
        guard_infallible(|| panic!("swallowed"));
    }
}
