//! Landmarks, intrinsics and floor corners as an app passes them to the fits.
use crate::bytes::{Bytes, typed};
use monotrack_ffi::{CameraIntrinsics, FitMethod, Point2, calibrate_floor_camera, fit_landmarks};

/// One input of the `fit_inputs` target.
pub fn run(data: &[u8]) {
    let mut b = Bytes(data);
    let n = b.below(80) as usize;
    let pts: Vec<Point2> = (0..n)
        .map(|_| Point2 {
            x: b.f64() as f32,
            y: b.f64() as f32,
        })
        .collect();
    let (w, h) = (b.below(5000), b.below(5000));
    let camera = (b.u8() & 1 == 1).then(|| CameraIntrinsics {
        fx: b.f64(),
        fy: b.f64(),
        cx: b.f64(),
        cy: b.f64(),
    });
    let method = if b.u8() & 1 == 0 {
        FitMethod::Msbp
    } else {
        FitMethod::Ffbp
    };
    typed(
        "fit_landmarks",
        fit_landmarks(pts.clone(), w, h, camera, method),
    );
    let corners: Vec<Point2> = pts.into_iter().take(b.below(6) as usize).collect();
    typed(
        "calibrate_floor_camera",
        calibrate_floor_camera(corners, b.f64(), b.f64(), w, h, camera),
    );
}
