//! MSBP — Multi-Step Bundle-adjustment-like Pose and deformation fit (thesis Alg. 7, eqs. 4.7–4.12).
//!
//! Parameters b = [tx, ty, tz, θx, θy, θz, τsu, τau]. Per outer iteration:
//! 1. Levenberg–Marquardt on the 6 pose parameters, normalised to [-1, 1] (eq. 4.11; back by
//!    eq. 4.12), using every weighted landmark;
//! 2. BFGS on all shape units with the pose fixed, using only the landmarks shape units move;
//! 3. BFGS on each animation unit in turn, using only that unit's landmarks.
//!
//! Projection is full perspective through the caller's intrinsics.
//!
//! Initialisation departs from the thesis' fixed [0, 0, Z0, 0, 0, 0] where no previous pose exists:
//! depth comes from the ratio of model to image landmark spread and x, y from the landmarks'
//! centroid, and step 1 is run from three yaw seeds (0, ±40°) keeping the best — a single frontal
//! seed falls into the mirrored local minimum for |yaw| ≳ 50° (seen in the synthetic round trips).
//! With a previous pose (tracking) it starts from that pose alone.

use super::pose::{Pose, angles_from_rotation, rotation_and_derivatives};
use super::solver::{
    Bfgs, LeastSquares, LevenbergMarquardt, Objective, SolverReport, Termination, accumulate_row,
    symmetrize,
};
use super::{FaceFit, FitReport, LandmarkWeights, validate_inputs};
use crate::camera::Intrinsics;
use crate::error::Result;
use crate::model::{FaceModel, N_ANIM, N_LANDMARKS, N_SHAPE, Unit};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

/// MSBP settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MsbpConfig {
    /// Nearest plausible face distance, mm (normalisation range of tz).
    pub z_near_mm: f64,
    /// Farthest plausible face distance, mm.
    pub z_far_mm: f64,
    /// Half-range of tx, ty in the normalised space, mm.
    pub xy_range_mm: f64,
    /// Rounds of the three steps (1 is enough when tracking from the previous frame's fit).
    pub outer_iterations: u32,
    /// Weight of the Gaussian prior on shape units, px² per unit² (keeps τ near 0 when the face is
    /// small and the landmarks noisy; ±1 is the plausible range, so a unit costs 1 px² at its edge).
    pub shape_prior: f64,
    /// Weight of the prior on animation units, px² per unit².
    pub animation_prior: f64,
    /// Whether step 3 fits the animation units (expressions). Off, they stay 0 and each round
    /// skips its six one-unit solves: pose and shape only, for apps that draw no expressions.
    pub animation_units: bool,
    /// Yaw seeds (degrees) for step 1 when there is no previous pose.
    pub yaw_seeds_deg: [f64; 3],
    /// Step-1 solver.
    #[serde(skip)]
    pub lm: LevenbergMarquardt,
    /// Steps 2–3 solver.
    #[serde(skip)]
    pub bfgs: Bfgs,
}

impl Default for MsbpConfig {
    fn default() -> Self {
        Self {
            z_near_mm: 150.0,
            z_far_mm: 3000.0,
            xy_range_mm: 1500.0,
            outer_iterations: 3,
            shape_prior: 1.0,
            animation_prior: 0.5,
            animation_units: true,
            yaw_seeds_deg: [0.0, -40.0, 40.0],
            lm: LevenbergMarquardt::default(),
            bfgs: Bfgs::default(),
        }
    }
}

/// The MSBP fitter. Holds its buffers; reuse one per tracked face.
#[derive(Debug, Clone)]
pub struct Msbp {
    model: &'static FaceModel,
    config: MsbpConfig,
    fixed_shape: Option<[f64; N_SHAPE]>,
}

/// Perspective projection of camera-frame point c, with ∂(u, v)/∂c rows.
#[inline]
fn project_with_jacobian(cam: &Intrinsics, c: &Vector3<f64>) -> ([f64; 2], [Vector3<f64>; 2]) {
    let iz = 1.0 / c.z;
    let u = cam.fx * c.x * iz + cam.cx;
    let v = cam.fy * c.y * iz + cam.cy;
    (
        [u, v],
        [
            Vector3::new(cam.fx * iz, 0.0, -cam.fx * c.x * iz * iz),
            Vector3::new(0.0, cam.fy * iz, -cam.fy * c.y * iz * iz),
        ],
    )
}

/// The normalised pose space of eqs. 4.11–4.12: translations map to [-1, 1] over the configured
/// ranges, angles over [-π, π], so LM's damping treats millimetres and radians alike.
#[derive(Debug, Clone, Copy)]
struct PoseSpace {
    t_center: Vector3<f64>,
    t_half: Vector3<f64>,
}

const ANGLE_HALF_RANGE: f64 = std::f64::consts::PI;

impl PoseSpace {
    fn new(cfg: &MsbpConfig) -> Self {
        Self {
            t_center: Vector3::new(0.0, 0.0, 0.5 * (cfg.z_near_mm + cfg.z_far_mm)),
            t_half: Vector3::new(
                cfg.xy_range_mm,
                cfg.xy_range_mm,
                0.5 * (cfg.z_far_mm - cfg.z_near_mm),
            ),
        }
    }

    /// Eq. 4.11: (t, θ) → x ∈ [-1, 1]⁶.
    fn normalise(&self, t: &Vector3<f64>, th: &Vector3<f64>) -> SVector<f64, 6> {
        SVector::<f64, 6>::from_fn(|i, _| {
            if i < 3 {
                (t[i] - self.t_center[i]) / self.t_half[i]
            } else {
                th[i - 3] / ANGLE_HALF_RANGE
            }
        })
    }

    /// Eq. 4.12: x → (t, θ).
    fn denormalise(&self, x: &SVector<f64, 6>) -> (Vector3<f64>, Vector3<f64>) {
        let t = self.t_center
            + self
                .t_half
                .component_mul(&x.fixed_rows::<3>(0).into_owned());
        let th = x.fixed_rows::<3>(3).into_owned() * ANGLE_HALF_RANGE;
        (t, th)
    }

    fn problem<'a>(
        self,
        g: &'a [Vector3<f64>; N_LANDMARKS],
        obs: &'a [[f64; 2]; N_LANDMARKS],
        w: &'a [f64; N_LANDMARKS],
        cam: &'a Intrinsics,
    ) -> PoseProblem<'a> {
        PoseProblem {
            g,
            obs,
            w,
            cam,
            space: self,
        }
    }
}

/// Step 1: pose in normalised coordinates.
struct PoseProblem<'a> {
    g: &'a [Vector3<f64>; N_LANDMARKS],
    obs: &'a [[f64; 2]; N_LANDMARKS],
    w: &'a [f64; N_LANDMARKS],
    cam: &'a Intrinsics,
    space: PoseSpace,
}

impl LeastSquares<6> for PoseProblem<'_> {
    fn cost(&self, x: &SVector<f64, 6>) -> f64 {
        let (t, th) = self.space.denormalise(x);
        let r = super::pose::rotation_from_angles(&th);
        let mut cost = 0.0;
        for i in 0..N_LANDMARKS {
            if self.w[i] > 0.0 {
                let c = r * self.g[i] + t;
                if c.z <= 1.0 {
                    return f64::INFINITY;
                }
                let (u, v) = self.cam.project(c.x, c.y, c.z);
                cost += self.w[i] * ((u - self.obs[i][0]).powi(2) + (v - self.obs[i][1]).powi(2));
            }
        }
        0.5 * cost
    }

    fn normal_equations(
        &self,
        x: &SVector<f64, 6>,
        jtj: &mut SMatrix<f64, 6, 6>,
        jtr: &mut SVector<f64, 6>,
    ) -> f64 {
        let (t, th) = self.space.denormalise(x);
        let (r, dr) = rotation_and_derivatives(&th);
        jtj.fill(0.0);
        jtr.fill(0.0);
        let mut cost = 0.0;
        for i in 0..N_LANDMARKS {
            let w = self.w[i];
            if w <= 0.0 {
                continue;
            }
            let c = r * self.g[i] + t;
            if c.z <= 1.0 {
                return f64::INFINITY;
            }
            let (p, dp) = project_with_jacobian(self.cam, &c);
            let dc = [dr[0] * self.g[i], dr[1] * self.g[i], dr[2] * self.g[i]];
            let sw = w.sqrt();
            for k in 0..2 {
                let res = p[k] - self.obs[i][k];
                let mut j = SVector::<f64, 6>::zeros();
                for a in 0..3 {
                    j[a] = dp[k][a] * self.space.t_half[a] * sw;
                    j[3 + a] = dp[k].dot(&dc[a]) * ANGLE_HALF_RANGE * sw;
                }
                accumulate_row(jtj, jtr, &j, res * sw);
                cost += w * res * res;
            }
        }
        symmetrize(jtj);
        0.5 * cost
    }
}

/// Steps 2 and 3: N deformation units with everything else fixed, on a landmark subset.
struct UnitsProblem<'a, const N: usize> {
    base: &'a [Vector3<f64>; N_LANDMARKS],
    units: [&'a Unit; N],
    pairs: &'a [usize],
    obs: &'a [[f64; 2]; N_LANDMARKS],
    w: &'a [f64; N_LANDMARKS],
    cam: &'a Intrinsics,
    r: Matrix3<f64>,
    t: Vector3<f64>,
    prior: f64,
}

impl<const N: usize> UnitsProblem<'_, N> {
    fn eval(&self, x: &SVector<f64, N>, mut grad: Option<&mut SVector<f64, N>>) -> f64 {
        let mut f = self.prior * x.norm_squared();
        if let Some(g) = grad.as_deref_mut() {
            *g = x * (2.0 * self.prior);
        }
        for &i in self.pairs {
            let w = self.w[i];
            if w <= 0.0 {
                continue;
            }
            let mut p = self.base[i];
            for (u, &tau) in self.units.iter().zip(x.iter()) {
                p += u.displacement[i] * tau;
            }
            let c = self.r * p + self.t;
            if c.z <= 1.0 {
                return f64::INFINITY;
            }
            let (uv, dp) = project_with_jacobian(self.cam, &c);
            let ru = uv[0] - self.obs[i][0];
            let rv = uv[1] - self.obs[i][1];
            f += w * (ru * ru + rv * rv);
            if let Some(g) = grad.as_deref_mut() {
                // ∂f/∂τk = 2w (ru ∂u/∂c + rv ∂v/∂c) · R · S_k,i
                let dc = (dp[0] * ru + dp[1] * rv) * (2.0 * w);
                let dg = self.r.transpose() * dc;
                for (k, u) in self.units.iter().enumerate() {
                    g[k] += dg.dot(&u.displacement[i]);
                }
            }
        }
        f
    }
}

impl<const N: usize> Objective<N> for UnitsProblem<'_, N> {
    fn value(&self, x: &SVector<f64, N>) -> f64 {
        self.eval(x, None)
    }
    fn value_and_gradient(&self, x: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        self.eval(x, Some(grad))
    }
    /// Gauss–Newton: 2λI + 2 Σ w JᵢᵀJᵢ with Jᵢ = ∂(u, v)/∂c · R · Sᵢ.
    fn hessian_approximation(&self, x: &SVector<f64, N>, hess: &mut SMatrix<f64, N, N>) -> bool {
        *hess = SMatrix::identity() * (2.0 * self.prior);
        for &i in self.pairs {
            let w = self.w[i];
            if w <= 0.0 {
                continue;
            }
            let mut p = self.base[i];
            for (u, &tau) in self.units.iter().zip(x.iter()) {
                p += u.displacement[i] * tau;
            }
            let c = self.r * p + self.t;
            if c.z <= 1.0 {
                return false;
            }
            let (_, dp) = project_with_jacobian(self.cam, &c);
            let (gu, gv) = (self.r.transpose() * dp[0], self.r.transpose() * dp[1]);
            let ju = SVector::<f64, N>::from_fn(|k, _| gu.dot(&self.units[k].displacement[i]));
            let jv = SVector::<f64, N>::from_fn(|k, _| gv.dot(&self.units[k].displacement[i]));
            *hess += (ju * ju.transpose() + jv * jv.transpose()) * (2.0 * w);
        }
        true
    }
}

/// Inverse-curvature guess for BFGS's first step: 1 / (2 Σ w ‖∂uv/∂τ‖²) at τ = 0, roughly.
fn bfgs_h0(cam: &Intrinsics, depth: f64) -> f64 {
    let px_per_mm = cam.fx / depth.max(1.0);
    1.0 / (2.0 * 8.0 * px_per_mm * px_per_mm * 4.0).max(1e-6)
}

impl Msbp {
    /// A fitter over the built-in face model.
    pub fn new(config: MsbpConfig) -> Self {
        Self::with_model(FaceModel::builtin(), config)
    }

    /// A fitter over a given model.
    pub fn with_model(model: &'static FaceModel, config: MsbpConfig) -> Self {
        Self {
            model,
            config,
            fixed_shape: None,
        }
    }

    /// Holds the shape units at `shape` (a known user's shape) or frees them (`None`).
    pub fn set_fixed_shape(&mut self, shape: Option<[f64; N_SHAPE]>) {
        self.fixed_shape = shape;
    }

    /// The held shape, if any.
    pub fn fixed_shape(&self) -> Option<&[f64; N_SHAPE]> {
        self.fixed_shape.as_ref()
    }

    /// Settings.
    pub fn config(&self) -> &MsbpConfig {
        &self.config
    }

    /// Fits the model to 68 landmarks (pixels). `weights` (≥ 0, 0 = missing point; default all 1),
    /// `init` = the previous frame's fit to track from.
    ///
    /// # Errors
    /// [`crate::Error::InvalidCamera`] / [`crate::Error::InvalidInput`] for bad intrinsics, NaN
    /// landmarks with non-zero weight, negative weights or fewer than 6 usable landmarks.
    pub fn fit(
        &mut self,
        landmarks: &[[f64; 2]; N_LANDMARKS],
        weights: Option<&LandmarkWeights>,
        camera: &Intrinsics,
        init: Option<&FaceFit>,
    ) -> Result<FaceFit> {
        let w = validate_inputs(landmarks, weights, camera)?;
        let cfg = self.config;
        let model = self.model;
        let mut shape = self
            .fixed_shape
            .or_else(|| init.map(|f| f.shape))
            .unwrap_or([0.0; N_SHAPE]);
        let mut anim = init.map(|f| f.animation).unwrap_or([0.0; N_ANIM]);
        let mut g = [Vector3::zeros(); N_LANDMARKS];
        model.shape_into(&shape, &anim, &mut g);

        let space = PoseSpace::new(&cfg);

        let mut iterations = 0u32;
        // Overwritten by the first round's step 1 (there is always at least one round).
        let mut last = SolverReport {
            iterations: 0,
            cost: f64::INFINITY,
            termination: Termination::MaxIterations,
        };
        let mut x = match init {
            Some(f) => {
                space.normalise(&f.pose.translation, &angles_from_rotation(&f.pose.rotation))
            }
            None => seeded_pose(&space, &g, landmarks, &w, camera, &cfg, &mut iterations),
        };

        let h_cam = camera;
        for _ in 0..cfg.outer_iterations.max(1) {
            // Step 1: pose.
            let problem = space.problem(&g, landmarks, &w, camera);
            last = cfg.lm.minimize(&problem, &mut x);
            iterations += last.iterations;
            let (t, th) = space.denormalise(&x);
            let r = super::pose::rotation_from_angles(&th);
            let h0 = bfgs_h0(h_cam, t.z);

            let units = UnitSteps {
                model,
                cfg: &cfg,
                obs: landmarks,
                w: &w,
                cam: camera,
                r,
                t,
                h0,
            };
            // Step 2: all shape units, shape pairs only.
            if self.fixed_shape.is_none() {
                iterations += units.fit_shape(&mut shape, &anim);
            }
            // Step 3: each animation unit in turn, its own pairs only.
            if cfg.animation_units {
                iterations += units.fit_animation(&shape, &mut anim);
            }
            model.shape_into(&shape, &anim, &mut g);
        }
        // Final pose refinement with the final deformation, so pose and units agree. Skipped when
        // tracking: the next frame's step 1 does it, and it would add a pose solve to every
        // tracked frame's fit.
        if init.is_none() {
            let problem = space.problem(&g, landmarks, &w, camera);
            last = cfg.lm.minimize(&problem, &mut x);
            iterations += last.iterations;
        }
        let (t, th) = space.denormalise(&x);
        let pose = Pose {
            rotation: super::pose::rotation_from_angles(&th),
            translation: t,
        };
        let rms_px = super::rms_reprojection(model, &shape, &anim, &pose, camera, landmarks, &w);
        let termination = if rms_px.is_finite() {
            last.termination
        } else {
            Termination::NonFinite
        };
        let uncertainty = super::uncertainty::scaled(
            super::uncertainty::pose_uncertainty_raw(
                model, &shape, &anim, &pose, camera, landmarks, &w,
            ),
            &super::uncertainty::POSE_UNCERTAINTY_SCALE,
        );
        Ok(FaceFit {
            pose,
            shape,
            animation: anim,
            uncertainty,
            report: FitReport {
                iterations,
                rms_px,
                termination,
                converged: termination.converged(),
            },
        })
    }
}

/// The pose of a first fit (no previous frame): LM from each of the config's yaw seeds, the
/// lowest cost kept; adds the solver's iterations to `iterations`.
fn seeded_pose(
    space: &PoseSpace,
    g: &[Vector3<f64>; N_LANDMARKS],
    obs: &[[f64; 2]; N_LANDMARKS],
    w: &[f64; N_LANDMARKS],
    camera: &Intrinsics,
    cfg: &MsbpConfig,
    iterations: &mut u32,
) -> SVector<f64, 6> {
    let t0 = initial_translation(g, obs, w, camera, cfg);
    let mut best: Option<(f64, SVector<f64, 6>)> = None;
    for &yaw in &cfg.yaw_seeds_deg {
        let mut x = space.normalise(&t0, &Vector3::new(0.0, yaw.to_radians(), 0.0));
        let problem = space.problem(g, obs, w, camera);
        let rep = cfg.lm.minimize(&problem, &mut x);
        *iterations += rep.iterations;
        if best.is_none_or(|(c, _)| rep.cost < c) {
            best = Some((rep.cost, x));
        }
    }
    best.map(|(_, x)| x).unwrap_or_default()
}

/// Steps 2 and 3 of a round: the deformation units fitted at the round's pose.
struct UnitSteps<'a> {
    model: &'static FaceModel,
    cfg: &'a MsbpConfig,
    obs: &'a [[f64; 2]; N_LANDMARKS],
    w: &'a [f64; N_LANDMARKS],
    cam: &'a Intrinsics,
    r: Matrix3<f64>,
    t: Vector3<f64>,
    /// BFGS's initial inverse Hessian scale at this depth.
    h0: f64,
}

impl UnitSteps<'_> {
    /// Step 2: all shape units together on the shape pairs; returns the solver's iterations.
    fn fit_shape(&self, shape: &mut [f64; N_SHAPE], anim: &[f64; N_ANIM]) -> u32 {
        let model = self.model;
        let mut base = [Vector3::zeros(); N_LANDMARKS];
        model.shape_into(&[0.0; N_SHAPE], anim, &mut base);
        let units: [&Unit; N_SHAPE] = std::array::from_fn(|k| &model.shape_units()[k]);
        let problem = UnitsProblem {
            base: &base,
            units,
            pairs: model.shape_landmarks(),
            obs: self.obs,
            w: self.w,
            cam: self.cam,
            r: self.r,
            t: self.t,
            prior: self.cfg.shape_prior,
        };
        let mut tau = SVector::<f64, N_SHAPE>::from(*shape);
        let rep = self.cfg.bfgs.minimize(&problem, &mut tau, self.h0);
        *shape = tau.into();
        rep.iterations
    }

    /// Step 3: each animation unit in turn on its own pairs, the others held; returns the
    /// solver's iterations.
    fn fit_animation(&self, shape: &[f64; N_SHAPE], anim: &mut [f64; N_ANIM]) -> u32 {
        let model = self.model;
        let mut iterations = 0;
        for k in 0..N_ANIM {
            let mut others = *anim;
            others[k] = 0.0;
            let mut base = [Vector3::zeros(); N_LANDMARKS];
            model.shape_into(shape, &others, &mut base);
            let unit = &model.animation_units()[k];
            let problem = UnitsProblem {
                base: &base,
                units: [unit],
                pairs: &unit.landmarks,
                obs: self.obs,
                w: self.w,
                cam: self.cam,
                r: self.r,
                t: self.t,
                prior: self.cfg.animation_prior,
            };
            let mut a = SVector::<f64, 1>::new(anim[k]);
            let rep = self.cfg.bfgs.minimize(&problem, &mut a, self.h0);
            iterations += rep.iterations;
            anim[k] = a[0];
        }
        iterations
    }
}

/// Depth from the ratio of model to image landmark spread; x, y from the landmarks' centroid.
fn initial_translation(
    g: &[Vector3<f64>; N_LANDMARKS],
    obs: &[[f64; 2]; N_LANDMARKS],
    w: &[f64; N_LANDMARKS],
    cam: &Intrinsics,
    cfg: &MsbpConfig,
) -> Vector3<f64> {
    let sw: f64 = w.iter().sum();
    let (mut mu, mut mv, mut mg) = (0.0, 0.0, Vector3::zeros());
    for i in 0..N_LANDMARKS {
        if w[i] > 0.0 {
            mu += w[i] * obs[i][0];
            mv += w[i] * obs[i][1];
            mg += g[i] * w[i];
        }
    }
    mu /= sw;
    mv /= sw;
    mg /= sw;
    let (mut si, mut sm) = (0.0, 0.0);
    for i in 0..N_LANDMARKS {
        if w[i] > 0.0 {
            si += w[i] * ((obs[i][0] - mu).powi(2) + (obs[i][1] - mv).powi(2));
            sm += w[i] * ((g[i].x - mg.x).powi(2) + (g[i].y - mg.y).powi(2));
        }
    }
    let f = 0.5 * (cam.fx + cam.fy);
    let z = if si > 0.0 {
        (f * (sm / si).sqrt()).clamp(cfg.z_near_mm, cfg.z_far_mm)
    } else {
        0.5 * (cfg.z_near_mm + cfg.z_far_mm)
    };
    Vector3::new(
        (mu - cam.cx) * z / cam.fx - mg.x,
        (mv - cam.cy) * z / cam.fy - mg.y,
        z - mg.z,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Camera, noisy observations, weights, a deformed model shape.
    type Setup = (
        Intrinsics,
        [[f64; 2]; N_LANDMARKS],
        [f64; N_LANDMARKS],
        [Vector3<f64>; N_LANDMARKS],
    );

    fn setup() -> Setup {
        let cam = Intrinsics::default_for(1280, 720).unwrap();
        let pose = Pose::from_euler_deg(20.0, -10.0, 5.0, Vector3::new(30.0, -20.0, 700.0));
        let m = FaceModel::builtin();
        let shape = [0.3, -0.2, 0.1, 0.0, 0.5, -0.4, 0.2, 0.1, -0.3, 0.2, 0.4];
        let anim = [0.4, 0.1, 0.0, -0.2, 0.3, 0.1];
        let mut obs = [[0.0; 2]; N_LANDMARKS];
        m.project_into(
            &shape,
            &anim,
            &pose.rotation,
            &pose.translation,
            &cam,
            &mut obs,
        );
        for (i, o) in obs.iter_mut().enumerate() {
            o[0] += ((i * 7) % 5) as f64 * 0.3 - 0.6;
            o[1] += ((i * 3) % 5) as f64 * 0.3 - 0.6;
        }
        let mut g = [Vector3::zeros(); N_LANDMARKS];
        m.shape_into(&[0.1; N_SHAPE], &[0.2; N_ANIM], &mut g);
        (cam, obs, [1.0; N_LANDMARKS], g)
    }

    /// Step 1's analytic normal equations equal those from a finite-difference Jacobian.
    #[test]
    fn pose_jacobian_matches_finite_differences() {
        let (cam, obs, w, g) = setup();
        let cfg = MsbpConfig::default();
        let p = PoseSpace::new(&cfg).problem(&g, &obs, &w, &cam);
        let x = SVector::<f64, 6>::new(0.02, -0.01, -0.6, 0.05, 0.1, -0.03);
        let mut jtj = SMatrix::zeros();
        let mut jtr = SVector::zeros();
        p.normal_equations(&x, &mut jtj, &mut jtr);
        // Jᵀr = ∇(½‖r‖²): compare with central differences of the cost.
        let h = 1e-7;
        for k in 0..6 {
            let mut a = x;
            let mut b = x;
            a[k] += h;
            b[k] -= h;
            let fd = (p.cost(&a) - p.cost(&b)) / (2.0 * h);
            assert!(
                (fd - jtr[k]).abs() <= 1e-5 * jtr[k].abs().max(1.0),
                "k={k}: fd {fd} vs {}",
                jtr[k]
            );
        }
    }

    /// Steps 2–3's analytic gradient equals central differences.
    #[test]
    fn units_gradient_matches_finite_differences() {
        let (cam, obs, w, g) = setup();
        let m = FaceModel::builtin();
        let pose = Pose::from_euler_deg(15.0, -5.0, 3.0, Vector3::new(20.0, -10.0, 650.0));
        let units: [&Unit; N_SHAPE] = std::array::from_fn(|k| &m.shape_units()[k]);
        let p = UnitsProblem {
            base: &g,
            units,
            pairs: m.shape_landmarks(),
            obs: &obs,
            w: &w,
            cam: &cam,
            r: pose.rotation,
            t: pose.translation,
            prior: 1.0,
        };
        let x = SVector::<f64, N_SHAPE>::from_fn(|i, _| 0.1 * i as f64 - 0.4);
        let mut grad = SVector::zeros();
        p.value_and_gradient(&x, &mut grad);
        let h = 1e-6;
        for k in 0..N_SHAPE {
            let mut a = x;
            let mut b = x;
            a[k] += h;
            b[k] -= h;
            let fd = (p.value(&a) - p.value(&b)) / (2.0 * h);
            assert!(
                (fd - grad[k]).abs() <= 1e-4 * grad[k].abs().max(1.0),
                "k={k}"
            );
        }
    }

    #[test]
    fn recovers_a_noiseless_pose() {
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let truth = Pose::from_euler_deg(-35.0, 12.0, -8.0, Vector3::new(-40.0, 25.0, 600.0));
        let m = FaceModel::builtin();
        let mut obs = [[0.0; 2]; N_LANDMARKS];
        m.project_into(
            &[0.0; N_SHAPE],
            &[0.0; N_ANIM],
            &truth.rotation,
            &truth.translation,
            &cam,
            &mut obs,
        );
        let fit = Msbp::new(MsbpConfig::default())
            .fit(&obs, None, &cam, None)
            .unwrap();
        assert!(
            fit.pose.rotation_angle_to(&truth) < 0.05,
            "{:?}",
            fit.pose.euler_deg()
        );
        assert!((fit.pose.translation - truth.translation).norm() < 1.0);
        assert!(fit.report.rms_px < 0.01 && fit.report.converged);
    }

    /// With the animation units off, a smiling face's pose is still found, its units stay 0, and
    /// the fit is poorer than with them on (the expression is left unexplained).
    #[test]
    fn animation_units_off_fit_pose_and_shape_only() {
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let truth = Pose::from_euler_deg(10.0, -5.0, 3.0, Vector3::new(10.0, -20.0, 550.0));
        let m = FaceModel::builtin();
        let mut anim = [0.0; N_ANIM];
        anim[0] = 0.8;
        anim[3] = -0.6;
        let mut obs = [[0.0; 2]; N_LANDMARKS];
        m.project_into(
            &[0.0; N_SHAPE],
            &anim,
            &truth.rotation,
            &truth.translation,
            &cam,
            &mut obs,
        );
        let fit = |animation_units| {
            Msbp::new(MsbpConfig {
                animation_units,
                ..MsbpConfig::default()
            })
            .fit(&obs, None, &cam, None)
            .unwrap()
        };
        let (on, off) = (fit(true), fit(false));
        assert_eq!(off.animation, [0.0; N_ANIM]);
        assert!(
            on.animation.iter().any(|a| a.abs() > 0.1),
            "{:?}",
            on.animation
        );
        assert!(
            off.pose.rotation_angle_to(&truth) < 1.0,
            "{:?}",
            off.pose.euler_deg()
        );
        assert!(
            on.report.rms_px < off.report.rms_px,
            "{} vs {}",
            on.report.rms_px,
            off.report.rms_px
        );
    }
}
