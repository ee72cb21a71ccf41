//! EPnP (Lepetit, Moreno-Noguer & Fua 2009) in its planar form, for placing the central body.
//!
//! The torso template (pelvis, thorax, shoulders, hips) is close to planar — the whole torso is
//! only a few centimetres deep — so the points are expressed in three control points spanning their
//! best-fit plane (the paper's planar case). The camera-frame control points lie in the null space
//! of a 2n×9 system; the one- and two-vector kernel solutions are both tried (scale from the known
//! control-point distances) and the one with the lower reprojection error of the real, non-planar
//! template is kept. Nothing allocates: at most [`MAX_POINTS`] points.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::optim::{MAX_RESIDUALS, NumericLeastSquares, Residuals};
use super::skeleton::exp_so3;
use crate::camera::Intrinsics;
use crate::error::{Error, Result};
use crate::fit::solver::LevenbergMarquardt;

/// Most points one call accepts.
pub const MAX_POINTS: usize = 8;

/// A pose body → camera: X_cam = R·X + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation.
    pub rotation: Matrix3<f64>,
    /// Translation, same unit as the template.
    pub translation: Vector3<f64>,
}

/// Estimates the pose of `template` (body frame) from its pixel projections `image`; points whose
/// `weights` entry is 0 are ignored. Needs at least four points.
///
/// # Errors
/// [`Error::InvalidInput`] for fewer than four usable points, more than [`MAX_POINTS`], a
/// template without planar extent, or a configuration whose kernel gives no valid pose.
pub fn solve_planar(
    template: &[Vector3<f64>],
    image: &[[f64; 2]],
    weights: &[f64],
    k: &Intrinsics,
) -> Result<(Pose, f64)> {
    let n = template.len();
    if n > MAX_POINTS || image.len() != n || weights.len() != n {
        return Err(Error::InvalidInput(format!(
            "EPnP takes up to {MAX_POINTS} points with matching image points and weights"
        )));
    }
    let used = weights.iter().filter(|w| **w > 0.0).count();
    if used < 4 {
        return Err(Error::InvalidInput(format!(
            "EPnP needs at least 4 points, got {used}"
        )));
    }
    let wsum: f64 = weights.iter().filter(|w| **w > 0.0).sum();
    let mut c = Vector3::zeros();
    for i in 0..n {
        if weights[i] > 0.0 {
            c += template[i] * weights[i];
        }
    }
    c /= wsum;
    let mut cov = Matrix3::zeros();
    for i in 0..n {
        if weights[i] > 0.0 {
            let d = template[i] - c;
            cov += d * d.transpose() * weights[i];
        }
    }
    cov /= wsum;
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let (s1, s2) = (
        eig.eigenvalues[order[0]].max(0.0).sqrt(),
        eig.eigenvalues[order[1]].max(0.0).sqrt(),
    );
    if s2 < 1e-6 * s1.max(1e-300) || s1 == 0.0 {
        return Err(Error::InvalidInput(
            "EPnP template points are collinear".into(),
        ));
    }
    let e1 = eig.eigenvectors.column(order[0]).into_owned();
    let e2 = eig.eigenvectors.column(order[1]).into_owned();
    let mut alphas = [[0.0; 3]; MAX_POINTS];
    let mut planar = [Vector3::zeros(); MAX_POINTS];
    let mut mtm = SMatrix::<f64, 9, 9>::zeros();
    for i in 0..n {
        let d = template[i] - c;
        let (a, b) = (d.dot(&e1), d.dot(&e2));
        planar[i] = c + e1 * a + e2 * b;
        let al = [1.0 - a / s1 - b / s2, a / s1, b / s2];
        alphas[i] = al;
        if weights[i] <= 0.0 {
            continue;
        }
        let x = (image[i][0] - k.cx) / k.fx;
        let y = (image[i][1] - k.cy) / k.fy;
        let mut r1 = SMatrix::<f64, 9, 1>::zeros();
        let mut r2 = SMatrix::<f64, 9, 1>::zeros();
        for j in 0..3 {
            r1[3 * j] = al[j];
            r1[3 * j + 2] = -al[j] * x;
            r2[3 * j + 1] = al[j];
            r2[3 * j + 2] = -al[j] * y;
        }
        mtm += (r1 * r1.transpose() + r2 * r2.transpose()) * weights[i];
    }
    let me = mtm.symmetric_eigen();
    let mut ev = [0usize; 9];
    for (i, e) in ev.iter_mut().enumerate() {
        *e = i;
    }
    ev.sort_by(|&a, &b| me.eigenvalues[a].total_cmp(&me.eigenvalues[b]));
    let v1 = me.eigenvectors.column(ev[0]).into_owned();
    let v2 = me.eigenvectors.column(ev[1]).into_owned();
    let ctrl =
        |v: &SMatrix<f64, 9, 1>, j: usize| Vector3::new(v[3 * j], v[3 * j + 1], v[3 * j + 2]);
    let pairs = [(0, 1), (0, 2), (1, 2)];
    let dist = [s1, s2, (s1 * s1 + s2 * s2).sqrt()];

    let mut best: Option<(Pose, f64)> = None;
    let mut consider = |cc: [Vector3<f64>; 3]| {
        if let Some(pose) = pose_from_controls(&cc, &alphas[..n], &planar[..n], weights) {
            let err = reprojection_rms(&pose, template, image, weights, k);
            if err.is_finite() && best.is_none_or(|(_, e)| err < e) {
                best = Some((pose, err));
            }
        }
    };
    // N = 1: x = β·v1, β from the control-point distances.
    {
        let (mut num, mut den) = (0.0, 0.0);
        for (p, &(a, b)) in pairs.iter().enumerate() {
            let dv = (ctrl(&v1, a) - ctrl(&v1, b)).norm();
            num += dist[p] * dv;
            den += dv * dv;
        }
        if den > 0.0 {
            let beta = num / den;
            consider([0, 1, 2].map(|j| ctrl(&v1, j) * beta));
        }
    }
    // N = 2: x = β1·v1 + β2·v2; the three distances are linear in (β1², β1β2, β2²).
    {
        let mut l = Matrix3::zeros();
        let mut rhs = Vector3::zeros();
        for (p, &(a, b)) in pairs.iter().enumerate() {
            let da = ctrl(&v1, a) - ctrl(&v1, b);
            let db = ctrl(&v2, a) - ctrl(&v2, b);
            l[(p, 0)] = da.dot(&da);
            l[(p, 1)] = 2.0 * da.dot(&db);
            l[(p, 2)] = db.dot(&db);
            rhs[p] = dist[p] * dist[p];
        }
        if let Some(sol) = l.lu().solve(&rhs) {
            let b1 = sol[0].abs().sqrt();
            if b1 > 0.0 {
                let b2 = sol[1] / b1;
                consider([0, 1, 2].map(|j| ctrl(&v1, j) * b1 + ctrl(&v2, j) * b2));
            }
        }
    }
    let (pose, _) = best
        .ok_or_else(|| Error::InvalidInput("EPnP found no pose in front of the camera".into()))?;
    // Gauss–Newton (LM) on the real, non-planar template, as the EPnP paper recommends.
    let problem = RefineProblem {
        template,
        image,
        weights,
        k,
        pose,
    };
    let mut x = SVector::<f64, 6>::zeros();
    LevenbergMarquardt {
        max_iterations: 10,
        cost_tolerance: 1e-6,
        ..Default::default()
    }
    .minimize(&NumericLeastSquares(&problem), &mut x);
    let refined = problem.pose_at(&x);
    let err = reprojection_rms(&refined, template, image, weights, k);
    Ok((refined, err))
}

struct RefineProblem<'a> {
    template: &'a [Vector3<f64>],
    image: &'a [[f64; 2]],
    weights: &'a [f64],
    k: &'a Intrinsics,
    pose: Pose,
}

impl RefineProblem<'_> {
    fn pose_at(&self, x: &SVector<f64, 6>) -> Pose {
        Pose {
            rotation: exp_so3(Vector3::new(x[0], x[1], x[2])) * self.pose.rotation,
            translation: self.pose.translation + Vector3::new(x[3], x[4], x[5]),
        }
    }
}

impl Residuals<6> for RefineProblem<'_> {
    fn residuals(&self, x: &SVector<f64, 6>, r: &mut [f64; MAX_RESIDUALS]) -> usize {
        let p = self.pose_at(x);
        let k = self.k;
        for i in 0..self.template.len() {
            let c = p.rotation * self.template[i] + p.translation;
            let w = self.weights[i].max(0.0).sqrt();
            if c.z > 1e-6 {
                r[2 * i] = w * (k.fx * c.x / c.z + k.cx - self.image[i][0]);
                r[2 * i + 1] = w * (k.fy * c.y / c.z + k.cy - self.image[i][1]);
            } else {
                r[2 * i] = w * 1e4;
                r[2 * i + 1] = w * 1e4;
            }
        }
        2 * self.template.len()
    }
    fn step(&self, i: usize) -> f64 {
        if i < 3 { 1e-7 } else { 1e-4 }
    }
}

/// Camera-frame points from the control points, sign fixed so they lie in front of the camera, then
/// the rigid transform planar template → those points (Kabsch).
fn pose_from_controls(
    cc: &[Vector3<f64>; 3],
    alphas: &[[f64; 3]],
    planar: &[Vector3<f64>],
    weights: &[f64],
) -> Option<Pose> {
    let n = alphas.len();
    let mut cam = [Vector3::zeros(); MAX_POINTS];
    let mut zsum = 0.0;
    for i in 0..n {
        cam[i] = cc[0] * alphas[i][0] + cc[1] * alphas[i][1] + cc[2] * alphas[i][2];
        zsum += cam[i].z;
    }
    let sgn = if zsum < 0.0 { -1.0 } else { 1.0 };
    for c in &mut cam[..n] {
        *c *= sgn;
    }
    let (r, t, _) = rigid_transform(planar, &cam[..n], weights)?;
    (t.z > 0.0).then_some(Pose {
        rotation: r,
        translation: t,
    })
}

/// The rotation R and translation t minimising Σ wᵢ‖R·srcᵢ + t − dstᵢ‖² (Kabsch, proper rotation
/// only; points with wᵢ ≤ 0 are ignored), with the singular values of the cross-covariance (for
/// callers that reject degenerate point sets). `None` when the SVD fails or R is not finite.
pub(crate) fn rigid_transform(
    src: &[Vector3<f64>],
    dst: &[Vector3<f64>],
    weights: &[f64],
) -> Option<(Matrix3<f64>, Vector3<f64>, Vector3<f64>)> {
    let (mut sb, mut db, mut w) = (Vector3::zeros(), Vector3::zeros(), 0.0);
    for ((s, d), &wi) in src.iter().zip(dst).zip(weights) {
        if wi > 0.0 {
            sb += s * wi;
            db += d * wi;
            w += wi;
        }
    }
    sb /= w;
    db /= w;
    let mut h = Matrix3::zeros();
    for ((s, d), &wi) in src.iter().zip(dst).zip(weights) {
        if wi > 0.0 {
            h += (s - sb) * (d - db).transpose() * wi;
        }
    }
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let v = vt.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let t = db - r * sb;
    r.iter()
        .all(|x| x.is_finite())
        .then_some((r, t, svd.singular_values))
}

/// Weighted RMS reprojection error, px.
pub fn reprojection_rms(
    pose: &Pose,
    template: &[Vector3<f64>],
    image: &[[f64; 2]],
    weights: &[f64],
    k: &Intrinsics,
) -> f64 {
    let (mut s, mut w) = (0.0, 0.0);
    for i in 0..template.len() {
        if weights[i] <= 0.0 {
            continue;
        }
        let c = pose.rotation * template[i] + pose.translation;
        if c.z <= 0.0 {
            return f64::INFINITY;
        }
        let u = k.fx * c.x / c.z + k.cx - image[i][0];
        let v = k.fy * c.y / c.z + k.cy - image[i][1];
        s += weights[i] * (u * u + v * v);
        w += weights[i];
    }
    (s / w).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_torso_pose_from_exact_projections() {
        // A torso-like template with a little depth (not exactly planar).
        let tpl = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.0, 480.0, 0.0),
            Vector3::new(150.0, 460.0, -35.0),
            Vector3::new(-150.0, 460.0, -35.0),
            Vector3::new(50.0, -4.0, 50.0),
            Vector3::new(-50.0, -4.0, 50.0),
        ];
        let k = Intrinsics::new(1000.0, 1000.0, 320.0, 240.0).unwrap();
        for (rv, t) in [
            (
                Vector3::new(3.0, 0.2, 0.1),
                Vector3::new(100.0, -200.0, 4000.0),
            ),
            (
                Vector3::new(2.8, -0.9, 0.3),
                Vector3::new(-300.0, 100.0, 3000.0),
            ),
            (Vector3::new(0.1, 1.4, 2.9), Vector3::new(0.0, 0.0, 5000.0)),
        ] {
            let r = exp_so3(rv);
            let img: Vec<[f64; 2]> = tpl
                .iter()
                .map(|p| {
                    let c = r * p + t;
                    [k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy]
                })
                .collect();
            let (pose, err) = solve_planar(&tpl, &img, &[1.0; 6], &k).unwrap();
            assert!(err < 1e-3, "{err}");
            assert!((pose.translation - t).norm() < 1.0, "{pose:?} vs {t}");
            let dr = (pose.rotation.transpose() * r).trace();
            let ang = ((dr - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees();
            assert!(ang < 0.01, "rotation error {ang}°");
        }
    }

    #[test]
    fn too_few_points_is_an_error() {
        let k = Intrinsics::new(1000.0, 1000.0, 320.0, 240.0).unwrap();
        let tpl = [Vector3::new(0.0, 0.0, 0.0); 4];
        assert!(solve_planar(&tpl, &[[0.0, 0.0]; 4], &[1.0, 1.0, 1.0, 0.0], &k).is_err());
        assert!(solve_planar(&tpl, &[[0.0, 0.0]; 4], &[1.0; 4], &k).is_err());
    }
}
