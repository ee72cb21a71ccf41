//! FFBP — Fast Face-model Bundle-adjustment-like Pose fit (thesis Alg. 6, eqs. 4.1–4.6): the
//! ultra-light mode.
//!
//! Weak perspective: a model point X projects to M·[X; 1] with the 2×4 matrix
//! M = [s·r1ᵀ, a; s·r2ᵀ, b] (eq. 4.4; r1, r2 the first two rows of R). POS (one POSIT iteration:
//! the least-squares affine camera, orthonormalised) initialises R, s and the position (a, b); the
//! position is then held, and Levenberg–Marquardt refines rotation, scale, shape and animation units
//! together with per-landmark confidence weights ([`super::ffbp_default_weights`]).
//! The metric pose follows from s = f / tz: tz = f̄ / s, (tx, ty) = ((a, b) − (cx, cy)) / s.

use super::pose::{Pose, angles_from_rotation, rotation_and_derivatives, rotation_from_angles};
use super::solver::{LeastSquares, LevenbergMarquardt, Termination, accumulate_row, symmetrize};
use super::{FaceFit, FitReport, LandmarkWeights, validate_inputs};
use crate::camera::Intrinsics;
use crate::error::{Error, Result};
use crate::model::{FaceModel, N_ANIM, N_LANDMARKS, N_SHAPE};
use nalgebra::{Matrix3, Matrix4, SMatrix, SVector, Vector3, Vector4};

const NP: usize = 3 + 1 + N_SHAPE + N_ANIM;

/// FFBP settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FfbpConfig {
    /// Per-landmark confidence weights (thesis defaults; multiplied with caller weights).
    pub weights: LandmarkWeights,
    /// Prior weight on shape units, px² per unit².
    pub shape_prior: f64,
    /// Prior weight on animation units, px² per unit².
    pub animation_prior: f64,
    /// LM iteration cap.
    pub max_iterations: u32,
}

impl Default for FfbpConfig {
    fn default() -> Self {
        Self {
            weights: super::ffbp_default_weights(),
            shape_prior: 1.0,
            animation_prior: 0.5,
            max_iterations: 30,
        }
    }
}

/// The FFBP fitter.
#[derive(Debug, Clone)]
pub struct Ffbp {
    model: &'static FaceModel,
    config: FfbpConfig,
}

struct WeakProblem<'a> {
    model: &'a FaceModel,
    obs: &'a [[f64; 2]; N_LANDMARKS],
    w: &'a [f64; N_LANDMARKS],
    pos: [f64; 2],
    shape_prior: f64,
    anim_prior: f64,
}

impl WeakProblem<'_> {
    /// Deformed vertex i for parameters x.
    fn vertex(&self, x: &SVector<f64, NP>, i: usize) -> Vector3<f64> {
        let mut p = self.model.mean()[i];
        for (k, u) in self.model.shape_units().iter().enumerate() {
            p += u.displacement[i] * x[4 + k];
        }
        for (k, u) in self.model.animation_units().iter().enumerate() {
            p += u.displacement[i] * x[4 + N_SHAPE + k];
        }
        p
    }

    fn priors(&self, x: &SVector<f64, NP>) -> f64 {
        let s: f64 = (0..N_SHAPE).map(|k| x[4 + k].powi(2)).sum();
        let a: f64 = (0..N_ANIM).map(|k| x[4 + N_SHAPE + k].powi(2)).sum();
        self.shape_prior * s + self.anim_prior * a
    }
}

impl LeastSquares<NP> for WeakProblem<'_> {
    fn cost(&self, x: &SVector<f64, NP>) -> f64 {
        let r = rotation_from_angles(&Vector3::new(x[0], x[1], x[2]));
        let s = x[3];
        let mut c = 0.0;
        for i in 0..N_LANDMARKS {
            if self.w[i] > 0.0 {
                let p = r * self.vertex(x, i);
                let du = s * p.x + self.pos[0] - self.obs[i][0];
                let dv = s * p.y + self.pos[1] - self.obs[i][1];
                c += self.w[i] * (du * du + dv * dv);
            }
        }
        0.5 * c + self.priors(x)
    }

    fn normal_equations(
        &self,
        x: &SVector<f64, NP>,
        jtj: &mut SMatrix<f64, NP, NP>,
        jtr: &mut SVector<f64, NP>,
    ) -> f64 {
        let (r, dr) = rotation_and_derivatives(&Vector3::new(x[0], x[1], x[2]));
        let s = x[3];
        jtj.fill(0.0);
        jtr.fill(0.0);
        let mut cost = 0.0;
        for i in 0..N_LANDMARKS {
            let w = self.w[i];
            if w <= 0.0 {
                continue;
            }
            let g = self.vertex(x, i);
            let p = r * g;
            let res = [
                s * p.x + self.pos[0] - self.obs[i][0],
                s * p.y + self.pos[1] - self.obs[i][1],
            ];
            let sw = w.sqrt();
            let dg = [dr[0] * g, dr[1] * g, dr[2] * g];
            for (k, &rk) in res.iter().enumerate() {
                // Most unit columns are zero for a given landmark; accumulate_row skips them.
                let mut j = SVector::<f64, NP>::zeros();
                for a in 0..3 {
                    j[a] = s * dg[a][k] * sw;
                }
                j[3] = p[k] * sw;
                let rk_row = r.row(k);
                for (q, u) in self
                    .model
                    .shape_units()
                    .iter()
                    .chain(self.model.animation_units())
                    .enumerate()
                {
                    let d = &u.displacement[i];
                    if d.x != 0.0 || d.y != 0.0 || d.z != 0.0 {
                        j[4 + q] = s * rk_row.dot(&d.transpose()) * sw;
                    }
                }
                accumulate_row(jtj, jtr, &j, rk * sw);
                cost += w * rk * rk;
            }
        }
        symmetrize(jtj);
        // Priors as residuals sqrt(2λ)·τ, so that ½ r² = λ τ².
        for k in 0..N_SHAPE + N_ANIM {
            let lam = if k < N_SHAPE {
                self.shape_prior
            } else {
                self.anim_prior
            };
            let idx = 4 + k;
            jtj[(idx, idx)] += 2.0 * lam;
            jtr[idx] += 2.0 * lam * x[idx];
        }
        0.5 * cost + self.priors(x)
    }
}

/// POS: least-squares affine camera from model points to image points, orthonormalised.
/// Returns (R, s, [a, b]).
fn pos_init(
    g: &[Vector3<f64>; N_LANDMARKS],
    obs: &[[f64; 2]; N_LANDMARKS],
    w: &[f64; N_LANDMARKS],
) -> Result<(Matrix3<f64>, f64, [f64; 2])> {
    let mut ata = Matrix4::<f64>::zeros();
    let mut atu = Vector4::<f64>::zeros();
    let mut atv = Vector4::<f64>::zeros();
    for i in 0..N_LANDMARKS {
        if w[i] > 0.0 {
            let a = Vector4::new(g[i].x, g[i].y, g[i].z, 1.0);
            ata += a * a.transpose() * w[i];
            atu += a * (obs[i][0] * w[i]);
            atv += a * (obs[i][1] * w[i]);
        }
    }
    let chol = ata
        .cholesky()
        .ok_or_else(|| Error::InvalidInput("landmarks too degenerate for POS".into()))?;
    let m1 = chol.solve(&atu);
    let m2 = chol.solve(&atv);
    let (v1, v2) = (
        m1.fixed_rows::<3>(0).into_owned(),
        m2.fixed_rows::<3>(0).into_owned(),
    );
    let (s1, s2) = (v1.norm(), v2.norm());
    if !(s1 > 0.0 && s2 > 0.0) {
        return Err(Error::InvalidInput(
            "landmarks too degenerate for POS".into(),
        ));
    }
    let r1 = v1 / s1;
    let r3 = r1.cross(&(v2 / s2)).normalize();
    let r2 = r3.cross(&r1);
    let r = Matrix3::from_rows(&[r1.transpose(), r2.transpose(), r3.transpose()]);
    Ok((r, 0.5 * (s1 + s2), [m1[3], m2[3]]))
}

impl Ffbp {
    /// A fitter over the built-in face model.
    pub fn new(config: FfbpConfig) -> Self {
        Self {
            model: FaceModel::builtin(),
            config,
        }
    }

    /// Fits to 68 landmarks; `weights` (0 = missing) multiply the configured confidence weights.
    ///
    /// # Errors
    /// As [`super::Msbp::fit`], plus [`Error::InvalidInput`] when the landmarks are too degenerate
    /// for the POS initialisation.
    pub fn fit(
        &mut self,
        landmarks: &[[f64; 2]; N_LANDMARKS],
        weights: Option<&LandmarkWeights>,
        camera: &Intrinsics,
    ) -> Result<FaceFit> {
        let caller = validate_inputs(landmarks, weights, camera)?;
        let mut w = self.config.weights;
        for (wi, c) in w.iter_mut().zip(&caller) {
            *wi *= c;
        }
        let (r0, s0, pos) = pos_init(self.model.mean(), landmarks, &w)?;
        let th = angles_from_rotation(&r0);
        let mut x = SVector::<f64, NP>::zeros();
        x[0] = th.x;
        x[1] = th.y;
        x[2] = th.z;
        x[3] = s0;
        let problem = WeakProblem {
            model: self.model,
            obs: landmarks,
            w: &w,
            pos,
            shape_prior: self.config.shape_prior,
            anim_prior: self.config.animation_prior,
        };
        let lm = LevenbergMarquardt {
            max_iterations: self.config.max_iterations,
            ..Default::default()
        };
        let rep = lm.minimize(&problem, &mut x);
        let s = x[3];
        let f = 0.5 * (camera.fx + camera.fy);
        let tz = f / s;
        let translation = Vector3::new(
            (pos[0] - camera.cx) * tz / camera.fx,
            (pos[1] - camera.cy) * tz / camera.fy,
            tz,
        );
        // Weak perspective sees the face along its line of sight, not along the optical axis: turn
        // the fitted rotation by the rotation taking the optical axis onto that ray, or off-centre
        // faces come out rotated towards the image centre.
        let ray = translation.normalize();
        let line_of_sight = nalgebra::Rotation3::rotation_between(&Vector3::z(), &ray)
            .map(|r| *r.matrix())
            .unwrap_or_else(Matrix3::identity);
        let pose = Pose {
            rotation: line_of_sight * rotation_from_angles(&Vector3::new(x[0], x[1], x[2])),
            translation,
        };
        let shape: [f64; N_SHAPE] = std::array::from_fn(|k| x[4 + k]);
        let anim: [f64; N_ANIM] = std::array::from_fn(|k| x[4 + N_SHAPE + k]);
        let rms_px =
            super::rms_reprojection(self.model, &shape, &anim, &pose, camera, landmarks, &caller);
        let termination = if rms_px.is_finite() && s > 0.0 {
            rep.termination
        } else {
            Termination::NonFinite
        };
        let uncertainty = super::uncertainty::scaled(
            super::uncertainty::pose_uncertainty_raw(
                self.model, &shape, &anim, &pose, camera, landmarks, &w,
            ),
            &super::uncertainty::POSE_UNCERTAINTY_SCALE_ULTRA_LIGHT,
        );
        Ok(FaceFit {
            pose,
            shape,
            animation: anim,
            uncertainty,
            report: FitReport {
                iterations: rep.iterations,
                rms_px,
                termination,
                converged: termination.converged(),
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weak_jacobian_matches_finite_differences() {
        let m = FaceModel::builtin();
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let truth = Pose::from_euler_deg(25.0, -10.0, 6.0, Vector3::new(10.0, 5.0, 600.0));
        let mut obs = [[0.0; 2]; N_LANDMARKS];
        m.project_into(
            &[0.2; N_SHAPE],
            &[0.1; N_ANIM],
            &truth.rotation,
            &truth.translation,
            &cam,
            &mut obs,
        );
        let w = super::super::ffbp_default_weights();
        let p = WeakProblem {
            model: m,
            obs: &obs,
            w: &w,
            pos: [330.0, 250.0],
            shape_prior: 1.0,
            anim_prior: 0.5,
        };
        let x = SVector::<f64, NP>::from_fn(|i, _| match i {
            0..=2 => 0.1 * (i as f64 + 1.0),
            3 => 0.9,
            _ => 0.05 * (i as f64 - 10.0),
        });
        let mut jtj = SMatrix::zeros();
        let mut jtr = SVector::zeros();
        let c = p.normal_equations(&x, &mut jtj, &mut jtr);
        assert!((c - p.cost(&x)).abs() < 1e-9 * c.max(1.0));
        let h = 1e-6;
        for k in 0..NP {
            let mut a = x;
            let mut b = x;
            a[k] += h;
            b[k] -= h;
            let fd = (p.cost(&a) - p.cost(&b)) / (2.0 * h);
            assert!(
                (fd - jtr[k]).abs() <= 1e-4 * jtr[k].abs().max(1.0),
                "k={k}: {fd} vs {}",
                jtr[k]
            );
        }
    }

    #[test]
    fn recovers_rotation_of_a_distant_face() {
        let m = FaceModel::builtin();
        let cam = Intrinsics::default_for(1280, 720).unwrap();
        let truth = Pose::from_euler_deg(-30.0, 15.0, 10.0, Vector3::new(-50.0, 30.0, 1200.0));
        let mut obs = [[0.0; 2]; N_LANDMARKS];
        m.project_into(
            &[0.0; N_SHAPE],
            &[0.0; N_ANIM],
            &truth.rotation,
            &truth.translation,
            &cam,
            &mut obs,
        );
        let fit = Ffbp::new(FfbpConfig::default())
            .fit(&obs, None, &cam)
            .unwrap();
        assert!(
            fit.pose.rotation_angle_to(&truth) < 3.0,
            "{:?}",
            fit.pose.euler_deg()
        );
        assert!((fit.pose.translation.z / truth.translation.z - 1.0).abs() < 0.05);
    }
}
