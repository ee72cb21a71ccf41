//! How far to trust a fitted head pose: standard deviations of the reported angles and
//! translation, from the fit's Gauss–Newton covariance.
//!
//! At the fitted pose the reprojection residual's Jacobian J (68 points × 2 rows, 6 pose
//! parameters) gives the least-squares covariance σ²·(JᵀWJ)⁻¹, with σ² the weighted residual
//! variance (the residual sum of squares over its degrees of freedom). That covariance treats the
//! shape and expression units as known and the landmark errors as independent, so it is too
//! small: landmark errors of one face are correlated, and the units absorb part of them. One
//! factor per reported number ([`POSE_UNCERTAINTY_SCALE`]) makes up the difference. The error it
//! is calibrated on is the pose fitted to the SDK's landmarks against the pose fitted to the
//! landmarks people annotated, with the same camera: the part of the pose's error that comes from
//! the landmarks, which is the part that changes from frame to frame. The landmark networks were
//! trained on the faces68 training split, where their errors are smaller than on faces they never
//! saw, so the factors are fitted on half of the validation split and checked on the other half
//! (`tests/examples/uncertainty_eval.rs`, which writes
//! `models/m3/uncertainty_metrics.json`; the test `pose_uncertainty_coverage` in `tests/`). The
//! errors' tails are heavier than a Gaussian's: a factor that puts 68 % within one standard
//! deviation puts fewer than 95 % within two, so each factor brings both coverages as near their
//! Gaussian values as one factor can (least squares over the two).

use super::pose::{Pose, angles_from_rotation, rotation_and_derivatives, rotation_from_angles};
use crate::camera::Intrinsics;
use crate::model::{FaceModel, N_ANIM, N_LANDMARKS, N_SHAPE};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Standard deviations of a fitted pose, as reported: head-frame Euler angles and translation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseUncertainty {
    /// Yaw, pitch and roll ([`Pose::euler_deg`]'s order), degrees.
    pub rotation_deg: [f64; 3],
    /// Translation x, y, z, millimetres.
    pub translation_mm: [f64; 3],
}

/// The calibration factors of [`pose_uncertainty_raw`] for the default landmark mode (M3 single
/// pass with MSBP): yaw, pitch, roll, then x, y, z, fitted on the calibration half of the faces68
/// validation split (the module's introduction; `tests/examples/uncertainty_eval.rs`).
pub const POSE_UNCERTAINTY_SCALE: [f64; 6] = [3.801, 6.413, 5.807, 4.01, 4.434, 6.91];

/// The ultra-light mode's factors (the gradient detector's 32 points and FFBP), fitted the same
/// way on the same faces.
pub const POSE_UNCERTAINTY_SCALE_ULTRA_LIGHT: [f64; 6] = [5.473, 4.597, 5.987, 7.123, 7.515, 4.99];

/// Largest reported standard deviation of an angle, degrees: where the covariance is singular or
/// the angles near their gimbal lock, the angle is unknown, not infinitely uncertain.
pub const MAX_ROTATION_SD_DEG: f64 = 180.0;

/// Largest reported standard deviation of a translation component, millimetres.
pub const MAX_TRANSLATION_SD_MM: f64 = 10_000.0;

/// The uncalibrated standard deviations of `pose` fitted to `landmarks` (pixels) with `weights`
/// (0 = unused) through `camera`, for the model deformed by `shape` and `anim`; multiply by a
/// scale ([`POSE_UNCERTAINTY_SCALE`]) for the reported ones ([`scaled`]). Allocates nothing.
#[allow(clippy::too_many_arguments)]
pub fn pose_uncertainty_raw(
    model: &FaceModel,
    shape: &[f64; N_SHAPE],
    anim: &[f64; N_ANIM],
    pose: &Pose,
    camera: &Intrinsics,
    landmarks: &[[f64; 2]; N_LANDMARKS],
    weights: &[f64; N_LANDMARKS],
) -> PoseUncertainty {
    let mut g = [Vector3::zeros(); N_LANDMARKS];
    model.shape_into(shape, anim, &mut g);
    let th = angles_from_rotation(&pose.rotation);
    let (r, dr) = rotation_and_derivatives(&th);
    let t = pose.translation;
    let mut jtj = SMatrix::<f64, 6, 6>::zeros();
    let (mut rss, mut n) = (0.0, 0usize);
    for i in 0..N_LANDMARKS {
        let w = weights[i];
        if w <= 0.0 || !w.is_finite() {
            continue;
        }
        let c = r * g[i] + t;
        if c.z <= 1.0 {
            return unknown();
        }
        let iz = 1.0 / c.z;
        let p = [
            camera.fx * c.x * iz + camera.cx,
            camera.fy * c.y * iz + camera.cy,
        ];
        let dp = [
            Vector3::new(camera.fx * iz, 0.0, -camera.fx * c.x * iz * iz),
            Vector3::new(0.0, camera.fy * iz, -camera.fy * c.y * iz * iz),
        ];
        let dc = [dr[0] * g[i], dr[1] * g[i], dr[2] * g[i]];
        for k in 0..2 {
            let mut j = SVector::<f64, 6>::zeros();
            for a in 0..3 {
                j[a] = dp[k][a];
                j[3 + a] = dp[k].dot(&dc[a]);
            }
            jtj += w * j * j.transpose();
            rss += w * (p[k] - landmarks[i][k]).powi(2);
        }
        n += 1;
    }
    let dof = (2 * n).saturating_sub(6).max(1) as f64;
    let Some(inv) = jtj.try_inverse() else {
        return unknown();
    };
    let cov = inv * (rss / dof);
    if !cov.iter().all(|v| v.is_finite()) {
        return unknown();
    }
    let translation_mm = std::array::from_fn(|a| sd(cov[(a, a)], MAX_TRANSLATION_SD_MM));
    // The reported angles are the head frame's Euler angles, a function of θ: its Jacobian
    // (central differences) carries θ's covariance over.
    let sub: Matrix3<f64> = cov.fixed_view::<3, 3>(3, 3).into_owned();
    let mut e = Matrix3::zeros();
    let h = 1e-6;
    for a in 0..3 {
        let mut hi = th;
        let mut lo = th;
        hi[a] += h;
        lo[a] -= h;
        let (eh, el) = (euler(&hi, &t), euler(&lo, &t));
        for b in 0..3 {
            let mut d = eh[b] - el[b];
            // Wrapped angles: a step across ±180° is a small step.
            d = (d + 180.0).rem_euclid(360.0) - 180.0;
            e[(b, a)] = d / (2.0 * h);
        }
    }
    let cov_e = e * sub * e.transpose();
    let rotation_deg = std::array::from_fn(|b| sd(cov_e[(b, b)], MAX_ROTATION_SD_DEG));
    PoseUncertainty {
        rotation_deg,
        translation_mm,
    }
}

/// `raw` multiplied by `scale` (yaw, pitch, roll, x, y, z), kept within the largest reported
/// values.
pub fn scaled(raw: PoseUncertainty, scale: &[f64; 6]) -> PoseUncertainty {
    PoseUncertainty {
        rotation_deg: std::array::from_fn(|a| {
            (raw.rotation_deg[a] * scale[a]).min(MAX_ROTATION_SD_DEG)
        }),
        translation_mm: std::array::from_fn(|a| {
            (raw.translation_mm[a] * scale[3 + a]).min(MAX_TRANSLATION_SD_MM)
        }),
    }
}

fn euler(th: &Vector3<f64>, t: &Vector3<f64>) -> [f64; 3] {
    let (y, p, r) = Pose {
        rotation: rotation_from_angles(th),
        translation: *t,
    }
    .euler_deg();
    [y, p, r]
}

fn sd(var: f64, max: f64) -> f64 {
    if var.is_finite() && var >= 0.0 {
        var.sqrt().min(max)
    } else {
        max
    }
}

fn unknown() -> PoseUncertainty {
    PoseUncertainty {
        rotation_deg: [MAX_ROTATION_SD_DEG; 3],
        translation_mm: [MAX_TRANSLATION_SD_MM; 3],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Landmarks of a known pose with Gaussian-like noise of a known size: the covariance's
    /// standard deviations match the spread of poses fitted to many such draws.
    #[test]
    fn the_covariance_matches_the_spread_of_refitted_poses() {
        use crate::fit::{Msbp, MsbpConfig};
        let m = FaceModel::builtin();
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let truth = Pose::from_head_euler_deg(15.0, -5.0, 3.0, Vector3::new(20.0, -10.0, 550.0));
        let (shape, anim) = ([0.0; N_SHAPE], [0.0; N_ANIM]);
        let mut clean = [[0.0; 2]; N_LANDMARKS];
        m.project_into(
            &shape,
            &anim,
            &truth.rotation,
            &truth.translation,
            &cam,
            &mut clean,
        );
        let cfg = MsbpConfig {
            animation_units: false,
            ..MsbpConfig::default()
        };
        let mut msbp = Msbp::new(cfg);
        msbp.set_fixed_shape(Some(shape));
        // A small deterministic generator: sums of uniforms are near enough to Gaussian.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut gauss = || {
            let mut s = 0.0;
            for _ in 0..12 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                s += (state >> 11) as f64 / (1u64 << 53) as f64;
            }
            s - 6.0
        };
        let noise_px = 2.0;
        let draws = 200;
        let mut errs = vec![[0.0; 6]; draws];
        let mut sds = [0.0; 6];
        for e in errs.iter_mut() {
            let mut obs = clean;
            for p in &mut obs {
                p[0] += noise_px * gauss();
                p[1] += noise_px * gauss();
            }
            let fit = msbp.fit(&obs, None, &cam, None).unwrap();
            let u = pose_uncertainty_raw(
                m,
                &fit.shape,
                &fit.animation,
                &fit.pose,
                &cam,
                &obs,
                &[1.0; N_LANDMARKS],
            );
            let (y, p, r) = fit.pose.euler_deg();
            let (ty, tp, tr) = truth.euler_deg();
            let d = fit.pose.translation - truth.translation;
            *e = [y - ty, p - tp, r - tr, d.x, d.y, d.z];
            for a in 0..3 {
                sds[a] += u.rotation_deg[a] / draws as f64;
                sds[3 + a] += u.translation_mm[a] / draws as f64;
            }
        }
        for a in 0..6 {
            let spread = (errs.iter().map(|e| e[a] * e[a]).sum::<f64>() / draws as f64).sqrt();
            let ratio = spread / sds[a];
            assert!(
                (0.75..1.33).contains(&ratio),
                "component {a}: refitted spread {spread:.4}, covariance's sd {:.4}",
                sds[a]
            );
        }
    }

    #[test]
    fn a_singular_problem_reports_the_largest_values_not_nan() {
        let m = FaceModel::builtin();
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let u = pose_uncertainty_raw(
            m,
            &[0.0; N_SHAPE],
            &[0.0; N_ANIM],
            &Pose::default(),
            &cam,
            &[[0.0; 2]; N_LANDMARKS],
            &[0.0; N_LANDMARKS],
        );
        assert_eq!(u.rotation_deg, [MAX_ROTATION_SD_DEG; 3]);
        assert_eq!(u.translation_mm, [MAX_TRANSLATION_SD_MM; 3]);
        let behind = Pose {
            translation: Vector3::new(0.0, 0.0, -100.0),
            ..Pose::default()
        };
        let u = pose_uncertainty_raw(
            m,
            &[0.0; N_SHAPE],
            &[0.0; N_ANIM],
            &behind,
            &cam,
            &[[0.0; 2]; N_LANDMARKS],
            &[1.0; N_LANDMARKS],
        );
        assert!(u.rotation_deg.iter().all(|v| v.is_finite()));
    }
}
