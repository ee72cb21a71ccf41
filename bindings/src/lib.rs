//! # monotrack-ffi
//!
//! The SDK's only FFI layer: small uniffi records and functions over `monotrack-core`, from which
//! Kotlin and Swift are generated. "The bridging layer is not API": everything here is a thin
//! wrapper; behaviour lives in the core. Frames cross as borrowed bytes (`&[u8]`: a direct
//! `java.nio.ByteBuffer` in Kotlin) plus a `FrameDesc`. A Rust panic surfaces as an exception
//! (uniffi catches unwinding panics; every profile keeps `panic = "unwind"`).
//!
//! Exported: the `FaceTracker` object (detector → fast tracker → M3 → flow filter → MSBP) in
//! MediaPipe's three running modes with `FaceTrackerOptions`, the shared benchmarks, frame
//! conversion and the frame and overlay rules (upright size, byte counts, default intrinsics,
//! projections), the 3D fit of given landmarks, and body fitting (floor calibration,
//! `BodyTracker`) (`API.md`).

uniffi::setup_scaffolding!();

mod body;
mod bundle;
mod error;
mod gaze;
mod live;
mod motion;
mod options;
mod overlay;
mod record;
mod tracker;
mod types;

pub use body::*;
pub use bundle::*;
pub use error::MonotrackError;
use error::guard;
pub use gaze::*;
pub use live::*;
pub use motion::*;
pub use options::*;
pub use overlay::*;
pub use record::*;
pub use tracker::*;
pub use types::*;

use monotrack_core::camera::Intrinsics;
use monotrack_core::fit::{Ffbp, FfbpConfig, Msbp, MsbpConfig};
use monotrack_core::image::{Frame, GrayImage};
use monotrack_core::model::N_LANDMARKS;

/// The SDK version (the crate version of `monotrack-ffi`, equal to the core's).
#[uniffi::export]
pub fn sdk_version() -> String {
    env!("CARGO_PKG_VERSION").to_string()
}

/// The upright luma image the pipeline would see for this frame: validates the description against
/// the bytes, applies rotation and mirroring. Meant for checking an integration's frame plumbing.
///
/// # Errors
/// `InvalidFrame` when the description does not match the bytes.
#[uniffi::export]
pub fn luma_image(bytes: &[u8], desc: FrameDesc) -> Result<LumaImage, MonotrackError> {
    guard(|| {
        let frame = Frame::new(bytes, desc.try_into()?)?;
        let mut out = GrayImage::default();
        frame.to_luma(&mut out);
        Ok(LumaImage {
            width: out.width() as u32,
            height: out.height() as u32,
            pixels: out.data().to_vec(),
        })
    })
}

/// The intrinsics the SDK assumes for a `width`×`height` upright image when none are given
/// (fx = fy = 0.9·max side, centred principal point).
///
/// # Errors
/// `InvalidConfig` for a zero size.
#[uniffi::export]
pub fn default_camera(width: u32, height: u32) -> Result<CameraIntrinsics, MonotrackError> {
    guard(|| Ok(Intrinsics::default_for(width, height)?.into()))
}

/// Fits the deformable 3D face model to 68 landmarks (pixels, iBUG order; a point with a NaN
/// coordinate counts as missing) of a `width`×`height` image.
///
/// # Errors
/// `InvalidConfig` for a wrong landmark count, bad intrinsics or too few usable points.
#[uniffi::export]
pub fn fit_landmarks(
    landmarks: Vec<Point2>,
    width: u32,
    height: u32,
    camera: Option<CameraIntrinsics>,
    method: FitMethod,
) -> Result<FitResult, MonotrackError> {
    guard(|| {
        if landmarks.len() != N_LANDMARKS {
            return Err(MonotrackError::InvalidConfig {
                msg: format!("expected {N_LANDMARKS} landmarks, got {}", landmarks.len()),
            });
        }
        let cam = match camera {
            Some(c) => Intrinsics::from(c),
            None => Intrinsics::default_for(width, height)?,
        };
        let mut pts = [[0.0; 2]; N_LANDMARKS];
        let mut w = [1.0; N_LANDMARKS];
        for (i, p) in landmarks.iter().enumerate() {
            if p.x.is_nan() || p.y.is_nan() {
                w[i] = 0.0;
            } else {
                pts[i] = [f64::from(p.x), f64::from(p.y)];
            }
        }
        let fit = match method {
            FitMethod::Msbp => Msbp::new(MsbpConfig::default()).fit(&pts, Some(&w), &cam, None)?,
            FitMethod::Ffbp => Ffbp::new(FfbpConfig::default()).fit(&pts, Some(&w), &cam)?,
        };
        Ok(FitResult::from(&fit))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_errors_are_typed() {
        let desc = FrameDesc {
            width: 4,
            height: 2,
            format: PixelFormat::Rgba8,
            row_stride: 16,
            uv_row_stride: 0,
            uv_pixel_stride: 0,
            rotation_degrees: 90,
            mirrored: false,
        };
        let img = luma_image(&[200; 32], desc).unwrap();
        assert_eq!((img.width, img.height, img.pixels.len()), (2, 4, 8));
        assert!(matches!(
            luma_image(&[0; 31], desc),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        let bad = FrameDesc {
            rotation_degrees: 45,
            ..desc
        };
        assert!(matches!(
            luma_image(&[0; 32], bad),
            Err(MonotrackError::InvalidFrame { .. })
        ));
    }

    #[test]
    fn camera_benchmark_errors_are_typed() {
        let camera = FrameDesc {
            width: 64,
            height: 48,
            format: PixelFormat::Nv21,
            row_stride: 64,
            uv_row_stride: 64,
            uv_pixel_stride: 2,
            rotation_degrees: 90,
            mirrored: false,
        };
        // The source's bytes do not match its size.
        assert!(matches!(
            run_camera_benchmark(vec![0; 10], 4, 4, camera, 10),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        assert!(matches!(
            run_camera_benchmark(vec![], 0, 0, camera, 10),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        // A bad camera description and too few frames.
        let bad = FrameDesc {
            uv_pixel_stride: 1,
            ..camera
        };
        assert!(matches!(
            run_camera_benchmark(vec![0; 16], 4, 4, bad, 10),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        assert!(matches!(
            run_camera_benchmark(vec![0; 16], 4, 4, camera, 1),
            Err(MonotrackError::InvalidConfig { .. })
        ));
    }

    #[test]
    fn fit_errors_are_typed() {
        let r = fit_landmarks(
            vec![Point2 { x: 1.0, y: 1.0 }; 3],
            640,
            480,
            None,
            FitMethod::Msbp,
        );
        assert!(matches!(r, Err(MonotrackError::InvalidConfig { .. })));
        let cam = CameraIntrinsics {
            fx: f64::NAN,
            fy: 1.0,
            cx: 0.0,
            cy: 0.0,
        };
        let r = fit_landmarks(
            vec![Point2 { x: 1.0, y: 1.0 }; 68],
            640,
            480,
            Some(cam),
            FitMethod::Ffbp,
        );
        assert!(matches!(r, Err(MonotrackError::InvalidConfig { .. })));
    }
}
