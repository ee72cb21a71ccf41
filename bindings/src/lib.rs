//! # monotrack-ffi
//!
//! The SDK's only FFI layer: small uniffi records and one `FaceTracker` object over
//! `monotrack-core`, from which Kotlin and Swift are generated. "The bridging layer is not API":
//! everything here is a thin wrapper; behaviour lives in the core.

uniffi::setup_scaffolding!();

mod error;

pub use error::MonotrackError;

/// The SDK version (the crate version of `monotrack-ffi`, equal to the core's).
#[uniffi::export]
pub fn sdk_version() -> String {
    env!("CARGO_PKG_VERSION").to_string()
}
