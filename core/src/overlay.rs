//! What an overlay draws over the upright image, in its pixels: the head's axes and the eyes'
//! gaze arrows. One definition for the CLI's overlays and, through the FFI, for apps.

use crate::camera::Intrinsics;
use crate::model::N_LANDMARKS;
use nalgebra::{Matrix3, Vector3};

/// The head frame's axes drawn from its origin, pixels: `x` towards the subject's left, `y`
/// down the face, `z` into the head (the frame of [`crate::fit::Pose::transform`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadAxes {
    /// The head frame's origin.
    pub origin: [f64; 2],
    /// Tip of the x axis.
    pub x: [f64; 2],
    /// Tip of the y axis.
    pub y: [f64; 2],
    /// Tip of the z axis.
    pub z: [f64; 2],
}

/// `p` (camera frame, mm) in pixels; `None` on or behind the camera plane, where no pixel shows it.
pub fn project(camera: &Intrinsics, p: &Vector3<f64>) -> Option<[f64; 2]> {
    (p.z > 0.0 && p.iter().all(|c| c.is_finite())).then(|| {
        let (u, v) = camera.project(p.x, p.y, p.z);
        [u, v]
    })
}

/// The head frame's axes, `length_mm` long, projected through `camera`, for the head at
/// `rotation` (the head frame's, [`crate::fit::Pose::head_rotation`]) and `translation` (mm); `None` when an
/// end lies behind the camera.
pub fn head_axes(
    rotation: &Matrix3<f64>,
    translation: &Vector3<f64>,
    camera: &Intrinsics,
    length_mm: f64,
) -> Option<HeadAxes> {
    let (r, t) = (rotation, *translation);
    let tip = |j: usize| project(camera, &(t + length_mm * r.column(j)));
    Some(HeadAxes {
        origin: project(camera, &t)?,
        x: tip(0)?,
        y: tip(1)?,
        z: tip(2)?,
    })
}

/// The first and last landmark of each eye: the subject's right eye, then the left.
const EYES: [std::ops::Range<usize>; 2] = [36..42, 42..48];

/// Gaze arrows for drawing, `[from, to]` per eye (the subject's right eye, then the left): from
/// the eye's landmark centroid along the gaze direction's image-plane part, `length_px` long for
/// a gaze across the optical axis (a sketch for an overlay, not a measurement).
pub fn gaze_arrows(
    points: &[[f32; 2]; N_LANDMARKS],
    right: &[f32; 3],
    left: &[f32; 3],
    length_px: f32,
) -> [[[f32; 2]; 2]; 2] {
    let arrow = |eye: &std::ops::Range<usize>, g: &[f32; 3]| {
        let n = eye.len() as f32;
        let (sx, sy) = points[eye.clone()]
            .iter()
            .fold((0.0, 0.0), |(x, y), p| (x + p[0], y + p[1]));
        let from = [sx / n, sy / n];
        [
            from,
            [from[0] + length_px * g[0], from[1] + length_px * g[1]],
        ]
    };
    [arrow(&EYES[0], right), arrow(&EYES[1], left)]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frontal head 500 mm ahead: its x axis points to image right, y down, z straight away
    /// (onto the origin's pixel); behind the camera nothing is drawn.
    #[test]
    fn axes_of_a_frontal_head_follow_the_image_axes() {
        let k = Intrinsics::default_for(640, 480).unwrap();
        let (frontal, t) = (Matrix3::identity(), Vector3::new(0.0, 0.0, 500.0));
        let a = head_axes(&frontal, &t, &k, 50.0).unwrap();
        assert!((a.origin[0] - 320.0).abs() < 1e-9 && (a.origin[1] - 240.0).abs() < 1e-9);
        assert!(a.x[0] > a.origin[0] + 10.0 && (a.x[1] - a.origin[1]).abs() < 1e-9);
        assert!(a.y[1] > a.origin[1] + 10.0 && (a.y[0] - a.origin[0]).abs() < 1e-9);
        assert!((a.z[0] - a.origin[0]).abs() < 1e-9 && (a.z[1] - a.origin[1]).abs() < 1e-9);
        assert!(head_axes(&frontal, &-t, &k, 50.0).is_none());
        assert!(project(&k, &Vector3::new(0.0, f64::NAN, 10.0)).is_none());
    }

    #[test]
    fn gaze_arrows_start_at_the_eye_centroids() {
        let mut p = [[0.0f32; 2]; N_LANDMARKS];
        for (k, q) in p[36..42].iter_mut().enumerate() {
            *q = [100.0 + k as f32, 50.0];
        }
        for (k, q) in p[42..48].iter_mut().enumerate() {
            *q = [200.0, 60.0 + k as f32];
        }
        let [r, l] = gaze_arrows(&p, &[0.5, -0.5, -0.7], &[0.0, 1.0, 0.0], 20.0);
        assert_eq!(r, [[102.5, 50.0], [112.5, 40.0]]);
        assert_eq!(l, [[200.0, 62.5], [200.0, 82.5]]);
    }
}
