//! Accuracy metrics shared by tests and benchmarks.

use crate::model::N_LANDMARKS;
use nalgebra::{Matrix3, Vector3};

/// Right outer eye corner (iBUG index) used as NME's normaliser together with [`LEFT_OUTER_EYE`].
pub const RIGHT_OUTER_EYE: usize = 36;
/// Left outer eye corner.
pub const LEFT_OUTER_EYE: usize = 45;
/// Nose base (bottom of the nose between the nostrils).
pub const NOSE_BASE: usize = 33;

/// Normalised mean error: mean point-to-point distance over the given indices divided by the
/// ground truth's outer-eye-corner distance (points 36/45; CONTRACT.md). `None` when the inter-ocular
/// distance is zero or no index is given.
pub fn nme(
    pred: &[[f64; 2]],
    truth: &[[f64; 2]],
    indices: impl IntoIterator<Item = usize>,
) -> Option<f64> {
    let d = outer_eye_distance(truth);
    let (mut s, mut n) = (0.0, 0usize);
    for i in indices {
        s += ((pred[i][0] - truth[i][0]).powi(2) + (pred[i][1] - truth[i][1]).powi(2)).sqrt();
        n += 1;
    }
    (d > 0.0 && n > 0).then(|| s / n as f64 / d)
}

/// Distance between the outer eye corners (points 36 and 45) of 68 iBUG points: NME's normaliser
/// and M3's unit for its label offset.
pub fn outer_eye_distance(points: &[[f64; 2]]) -> f64 {
    ((points[LEFT_OUTER_EYE][0] - points[RIGHT_OUTER_EYE][0]).powi(2)
        + (points[LEFT_OUTER_EYE][1] - points[RIGHT_OUTER_EYE][1]).powi(2))
    .sqrt()
}

/// NME over all 68 points.
pub fn nme68(pred: &[[f64; 2]; N_LANDMARKS], truth: &[[f64; 2]; N_LANDMARKS]) -> Option<f64> {
    nme(pred, truth, 0..N_LANDMARKS)
}

/// Orthonormal face frame from the plane through the outer eye corners and the nose base
/// (thesis eq. 4.13): x along the eye line, z the plane normal, y completing the frame.
pub fn face_frame(points: &[Vector3<f64>; N_LANDMARKS]) -> Matrix3<f64> {
    let a = points[RIGHT_OUTER_EYE];
    let b = points[LEFT_OUTER_EYE];
    let c = points[NOSE_BASE];
    let x = (b - a).normalize();
    let z = x.cross(&(c - a)).normalize();
    let y = z.cross(&x);
    Matrix3::from_columns(&[x, y, z])
}

/// The thesis' rotation error (degrees): the angle of the Rodrigues vector of the rotation between
/// the estimated and true face frames ([`face_frame`]), each built from 3D landmark positions in
/// the camera frame.
pub fn rotation_error_deg(
    est: &[Vector3<f64>; N_LANDMARKS],
    truth: &[Vector3<f64>; N_LANDMARKS],
) -> f64 {
    let r = face_frame(est) * face_frame(truth).transpose();
    crate::fit::pose::rotation_angle_deg(&r)
}

/// RMS distance (same units as the input) between two 3D shapes after the similarity (rotation,
/// translation, scale) that best aligns `est` onto `truth` (Umeyama's Procrustes solution).
pub fn procrustes_shape_error(est: &[Vector3<f64>], truth: &[Vector3<f64>]) -> f64 {
    let n = est.len().min(truth.len());
    if n == 0 {
        return 0.0;
    }
    let me: Vector3<f64> = est[..n].iter().sum::<Vector3<f64>>() / n as f64;
    let mt: Vector3<f64> = truth[..n].iter().sum::<Vector3<f64>>() / n as f64;
    let mut cov = Matrix3::zeros();
    let mut var_e = 0.0;
    for (e, t) in est[..n].iter().zip(&truth[..n]) {
        let (de, dt) = (e - me, t - mt);
        cov += dt * de.transpose();
        var_e += de.norm_squared();
    }
    let svd = cov.svd(true, true);
    let (u, vt) = (svd.u.unwrap_or_default(), svd.v_t.unwrap_or_default());
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * vt;
    let scale = if var_e > 0.0 {
        (svd.singular_values
            .component_mul(&Vector3::new(1.0, 1.0, d[(2, 2)])))
        .sum()
            / var_e
    } else {
        1.0
    };
    let s: f64 = est[..n]
        .iter()
        .zip(&truth[..n])
        .map(|(e, t)| ((r * (e - me)) * scale + mt - t).norm_squared())
        .sum();
    (s / n as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::Pose;
    use crate::model::FaceModel;

    #[test]
    fn nme_of_a_known_offset() {
        let mut truth = [[0.0; 2]; N_LANDMARKS];
        truth[LEFT_OUTER_EYE] = [100.0, 0.0];
        let mut pred = truth;
        for p in pred.iter_mut() {
            p[0] += 3.0;
        }
        assert!((nme68(&pred, &truth).unwrap() - 0.03).abs() < 1e-12);
    }

    #[test]
    fn rotation_error_sees_a_known_rotation() {
        let g = *FaceModel::builtin().mean();
        let p = Pose::from_euler_deg(10.0, 0.0, 0.0, Vector3::zeros());
        let rotated: [Vector3<f64>; N_LANDMARKS] = std::array::from_fn(|i| p.rotation * g[i]);
        assert!((rotation_error_deg(&rotated, &g) - 10.0).abs() < 1e-9);
    }

    #[test]
    fn procrustes_ignores_similarity() {
        let g = FaceModel::builtin().mean();
        let p = Pose::from_euler_deg(20.0, -10.0, 30.0, Vector3::new(5.0, 6.0, 7.0));
        let moved: Vec<Vector3<f64>> = g
            .iter()
            .map(|x| (p.rotation * x) * 1.7 + p.translation)
            .collect();
        assert!(procrustes_shape_error(&moved, g) < 1e-9);
        let mut bent = g.to_vec();
        bent[30].z -= 10.0;
        assert!(procrustes_shape_error(&bent, g) > 0.5);
    }
}
