//! # monotrack-core
//!
//! The pure-Rust core of the monotrack SDK: frames in, faces (box, 68 landmarks, metric head pose,
//! shape and expression units, gestures, gaze) and bodies out. It knows nothing of any FFI; the
//! `bindings` crate is the only foreign-function layer.
//!
//! Conventions (pixels, camera axes, pose, Euler angles, landmark order) are fixed once in
//! `CONTRACT.md` (the repository root) and restated in [`camera`]; every module refers to them.
//!
//! Modules follow the pipeline (see `ARCHITECTURE.md`):
//! [`image`] → `detect` → `landmarks` → `track` → [`model`] / [`fit`] → results; and apart from
//! faces, `body` and `motion`. [`record`] writes what a tracker was given to a file and replays it.

// Tests compare with the platform's maths library (core::math, core/clippy.toml).
#![cfg_attr(test, allow(clippy::disallowed_methods))]

pub mod bench;
pub mod body;
pub mod camera;
pub mod detect;
pub mod error;
pub mod fit;
pub mod gaze;
pub mod image;
pub mod kernels;
pub mod landmarks;
pub mod math;
pub mod metrics;
pub mod model;
pub mod motion;
pub mod nn;
pub mod overlay;
pub mod record;
pub mod track;

pub use error::{Error, Result};
pub use track::{FaceTracker, TrackerConfig, TrackingResult};
