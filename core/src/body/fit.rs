//! Fitting the body to one frame's 2D joints (thesis 5.2, Alg. 11) and estimating the body's
//! dimensions over the first frames of a sequence (Alg. 10).
//!
//! The objective (the thesis' eq. 5.1, in our terms) is the sum of squared residuals, all in pixels:
//! reprojection of each observed joint, joint-limit excesses ([`LIMIT_WEIGHT_PX`] per cone radius or
//! radian), floor penetration and — for the foot in contact — the ankle's height error, the last
//! two converted to pixels at the joint's depth — and the pose prior's whitened residuals times
//! [`BodyFitConfig::prior_weight_px`]. It is reported per observed joint (px²).

use crate::math::Libm;
use nalgebra::{Matrix3, SVector, Vector3};
use std::cell::RefCell;

use super::calib::BodyCamera;
use super::epnp;
use super::hanim::{self, EndSite, FullSkeleton, N_FULL_LIMITS, N_FULL_POSE, Posed};
use super::ik;
use super::optim::cobyla::{Cobyla, CobylaTermination};
use super::optim::direct::{DirectL, DirectTermination};
use super::optim::{MAX_RESIDUALS, NumericLeastSquares, Residuals};
use super::prior::{N_PRIOR, PosePrior};
use super::skeleton::*;
use super::{Joint, Joints2d, N_JOINTS};
use crate::error::{Error, Result};
use crate::fit::solver::{LeastSquares, LevenbergMarquardt, SolverReport};

/// Pixels of residual per unit of joint-limit excess (a full cone radius, or one radian): large, so
/// that limits act as near-hard constraints, but finite, so LM can cross a limit to a better basin.
pub const LIMIT_WEIGHT_PX: f64 = 200.0;
/// Weight of floor penetration and contact-height residuals relative to their pixel size at the
/// joint's depth (1 = a millimetre below the floor costs what a millimetre of image-plane error
/// costs there).
pub const FLOOR_WEIGHT: f64 = 1.0;
/// In the IK's choice between depth candidates, the weight of the squared prior distance (standard
/// deviations², [`PosePrior::distance2`]) against joint-limit excess: limits decide first, the
/// prior breaks ties. (0.05 per rad² before, with the isotropic prior; a standard deviation of the
/// learnt one is 0.14–0.76 rad, hence the smaller factor. Not tuned: the refinement re-scores every
/// branch with the full objective anyway.)
const IK_PRIOR_WEIGHT: f64 = 0.01;
/// Lowest height a non-ankle joint may take (knees may kneel), mm.
const MIN_JOINT_HEIGHT_MM: f64 = 30.0;
/// Ankles may sink this far below their standing height before the floor term acts (foot rolling
/// onto toes or heel lowers the ankle by up to about this much in HumanEva and Human3.6M).
const ANKLE_SINK_MM: f64 = 40.0;

/// Settings of [`BodyFitter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyFitConfig {
    /// The refinement's solver settings.
    pub lm: LevenbergMarquardt,
    /// Assume the lower foot touches the floor (true for standing, walking, most activities; false
    /// for jumps or seated subjects).
    pub assume_contact: bool,
    /// Pixels of residual per standard deviation of the pose prior ([`PosePrior`]): it decides
    /// what the 2D joints leave open (depth-ambiguous limbs, twists), and little else.
    pub prior_weight_px: f64,
    /// Refine, after the reduced model's fit, in the full 21-joint, 54-DoF model ([`hanim`]):
    /// clavicles, pelvis girdle and a three-joint spine and two-joint neck free within their
    /// limits. [`BodyFit::full_pose`] then holds that pose and the joints come from it.
    pub full_model: bool,
    /// Multiplies [`hanim::EXTRA_PRIOR_STD`] in the full model's refinement (1 = as shipped).
    pub extra_prior_scale: f64,
    /// In sequences ([`BodyFitter::fit_tracked`]) a frame is refined from the previous frame's
    /// pose; when that fit's objective exceeds this (px² per observed joint) the frame is also
    /// fitted from scratch (EPnP + IK) and the lower objective wins.
    pub refit_cost_px2: f64,
}

impl Default for BodyFitConfig {
    fn default() -> Self {
        Self {
            lm: LevenbergMarquardt {
                max_iterations: 15,
                // Relative cost decrease per step: beyond 1e-3 the joints move by well under a pixel.
                cost_tolerance: 1e-3,
                step_tolerance: 1e-6,
                initial_lambda: 1e-3,
            },
            assume_contact: true,
            prior_weight_px: DEFAULT_PRIOR_WEIGHT_PX,
            full_model: false,
            extra_prior_scale: 1.0,
            refit_cost_px2: DEFAULT_REFIT_COST_PX2,
        }
    }
}

/// Default of [`BodyFitConfig::prior_weight_px`].
pub const DEFAULT_PRIOR_WEIGHT_PX: f64 = 5.0;

/// Default of [`BodyFitConfig::refit_cost_px2`], chosen on HumanEva-I Train: lower thresholds
/// refit more frames from scratch for no gain after Procrustes, higher ones lose accuracy; at this
/// one a minority of the frames that have a previous one are also fitted from scratch
/// (`models/train/RESEARCH_LOG.md`, "Body defaults").
pub const DEFAULT_REFIT_COST_PX2: f64 = 40.0;

/// One frame's fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyFit {
    /// Joint positions, world frame, mm.
    pub joints: [Vector3<f64>; N_JOINTS],
    /// The pose vector (see [`super::skeleton`]); with [`BodyFitConfig::full_model`], the first 27
    /// parameters of [`BodyFit::full_pose`].
    pub pose: [f64; N_POSE],
    /// The full model's pose ([`hanim`]) when fitted in it.
    pub full_pose: Option<[f64; N_FULL_POSE]>,
    /// RMS reprojection error over the observed joints, px.
    pub reprojection_rms_px: f64,
    /// The objective per observed joint (reprojection plus penalties), px².
    pub cost_px2: f64,
    /// The foot assumed on the floor, if any.
    pub contact: Option<Joint>,
    /// The refinement's report.
    pub report: SolverReport,
}

/// Fits the body to 2D joints. Holds no per-frame heap state: everything lives on the stack.
#[derive(Debug, Clone)]
pub struct BodyFitter {
    /// Settings.
    pub config: BodyFitConfig,
    /// The pose prior (default: [`PosePrior::shipped`]).
    pub prior: PosePrior,
}

impl Default for BodyFitter {
    fn default() -> Self {
        Self::new(BodyFitConfig::default())
    }
}

struct PoseProblem<'a> {
    skel: &'a Skeleton,
    prior: &'a PosePrior,
    prior_weight: f64,
    cam: &'a BodyCamera,
    obs: &'a Joints2d,
    contact: Option<usize>,
}

impl Residuals<N_POSE> for PoseProblem<'_> {
    fn residuals(&self, x: &SVector<f64, N_POSE>, r: &mut [f64; MAX_RESIDUALS]) -> usize {
        let p = unpack(x);
        let mut j = [Vector3::zeros(); N_JOINTS];
        self.skel.forward(&p, &mut j);
        let depth = reprojection_residuals(self.cam, self.obs, &j, r);
        let mut k = 2 * N_JOINTS;
        let mut lim = [0.0; N_LIMITS];
        self.skel.limit_violations(&p, &mut lim);
        k += limit_residuals(&lim, &mut r[k..]);
        k += floor_residuals(self.skel, self.cam, self.contact, &j, &depth, &mut r[k..]);
        k + prior_residuals(self.prior, self.prior_weight, &p, &mut r[k..])
    }

    fn step(&self, i: usize) -> f64 {
        pose_fd_step(i)
    }
}

/// The parameters of `x` as an array.
#[inline]
fn unpack<const N: usize>(x: &SVector<f64, N>) -> [f64; N] {
    x.data.0[0]
}

/// Writes the joint-limit residuals ([`LIMIT_WEIGHT_PX`] per unit of excess) of violations `lim`
/// into `r`; returns how many.
fn limit_residuals(lim: &[f64], r: &mut [f64]) -> usize {
    for (o, v) in r.iter_mut().zip(lim) {
        *o = LIMIT_WEIGHT_PX * v;
    }
    lim.len()
}

/// Writes the learnt prior's residuals of reduced pose `p`, `weight` px per standard deviation,
/// into `r`; returns how many ([`N_PRIOR`]).
fn prior_residuals(prior: &PosePrior, weight: f64, p: &[f64; N_POSE], r: &mut [f64]) -> usize {
    prior.residuals(p, &mut r[..N_PRIOR]);
    for v in &mut r[..N_PRIOR] {
        *v *= weight;
    }
    N_PRIOR
}

/// Writes the weighted reprojection residuals of the 15 joints into `r[..30]` and returns the
/// joints' depths (clamped to 1 mm).
fn reprojection_residuals(
    cam: &BodyCamera,
    obs: &Joints2d,
    j: &[Vector3<f64>; N_JOINTS],
    r: &mut [f64],
) -> [f64; N_JOINTS] {
    let mut depth = [0.0; N_JOINTS];
    for i in 0..N_JOINTS {
        let c = cam.to_camera(&j[i]);
        // Behind the camera: a large finite residual keeps LM away without NaNs.
        depth[i] = c.z.max(1.0);
        let w = obs.weights[i];
        let (a, b) = if w > 0.0 && c.z > 1.0 {
            let q = cam.project_camera(&c);
            let sw = w.sqrt();
            (
                sw * (q[0] - obs.points[i][0]),
                sw * (q[1] - obs.points[i][1]),
            )
        } else if w > 0.0 {
            (1e4, 1e4)
        } else {
            (0.0, 0.0)
        };
        r[2 * i] = a;
        r[2 * i + 1] = b;
    }
    depth
}

/// Writes the floor-penetration residuals of the 15 joints and the contact foot's height residual
/// into `r` (in pixels at the joint's depth); returns how many (16).
fn floor_residuals(
    skel: &Skeleton,
    cam: &BodyCamera,
    contact: Option<usize>,
    j: &[Vector3<f64>; N_JOINTS],
    depth: &[f64; N_JOINTS],
    r: &mut [f64],
) -> usize {
    let fx = cam.intrinsics.fx;
    let ankle_min = skel.ankle_height - ANKLE_SINK_MM;
    for i in 0..N_JOINTS {
        let min = if i == Joint::LAnkle.index() || i == Joint::RAnkle.index() {
            ankle_min
        } else {
            MIN_JOINT_HEIGHT_MM
        };
        r[i] = FLOOR_WEIGHT * (min - j[i].z).max(0.0) * fx / depth[i];
    }
    r[N_JOINTS] = match contact {
        Some(a) => FLOOR_WEIGHT * (j[a].z - skel.ankle_height) * fx / depth[a],
        None => 0.0,
    };
    N_JOINTS + 1
}

/// The refinement in the full 54-DoF model ([`hanim`]): the reduced objective with the full
/// model's joint limits, the toes kept above the floor, and the extra parameters' zero-mean prior
/// ([`hanim::EXTRA_PRIOR_STD`]) next to the learnt one on the first 27.
struct FullPoseProblem<'a> {
    fs: &'a FullSkeleton,
    prior: &'a PosePrior,
    prior_weight: f64,
    extra_std_scale: f64,
    cam: &'a BodyCamera,
    obs: &'a Joints2d,
    contact: Option<usize>,
}

impl Residuals<N_FULL_POSE> for FullPoseProblem<'_> {
    fn residuals(&self, x: &SVector<f64, N_FULL_POSE>, r: &mut [f64; MAX_RESIDUALS]) -> usize {
        let p = unpack(x);
        let mut posed = Posed::default();
        self.fs.forward(&p, &mut posed);
        let j = posed.output_joints();
        let depth = reprojection_residuals(self.cam, self.obs, &j, r);
        let mut k = 2 * N_JOINTS;
        let mut lim = [0.0; N_FULL_LIMITS];
        self.fs.limit_violations(&p, &mut lim);
        k += limit_residuals(&lim, &mut r[k..]);
        k += floor_residuals(
            &self.fs.base,
            self.cam,
            self.contact,
            &j,
            &depth,
            &mut r[k..],
        );
        let fx = self.cam.intrinsics.fx;
        for toe in [EndSite::LToe, EndSite::RToe] {
            let t = posed.ends[toe as usize];
            let z = self.cam.to_camera(&t).z.max(1.0);
            // The toes may sink as far as the ankles may (foot and ankle points are marker
            // estimates, and the ankle's height allowance already covers a rolling foot).
            r[k] = FLOOR_WEIGHT * (-ANKLE_SINK_MM - t.z).max(0.0) * fx / z;
            k += 1;
        }
        k += prior_residuals(
            self.prior,
            self.prior_weight,
            &hanim::reduced(&p),
            &mut r[k..],
        );
        for (i, s) in hanim::EXTRA_PRIOR_STD.iter().enumerate() {
            r[k] = self.prior_weight * p[N_POSE + i] / (s * self.extra_std_scale);
            k += 1;
        }
        k
    }

    fn step(&self, i: usize) -> f64 {
        if i < N_POSE { pose_fd_step(i) } else { 1e-6 }
    }
}

impl BodyFitter {
    /// A fitter with these settings.
    pub fn new(config: BodyFitConfig) -> Self {
        Self {
            config,
            prior: PosePrior::shipped().clone(),
        }
    }

    /// Fits `skel` to the observations `obs` seen by `cam`: EPnP torso, IK limbs, floor contact,
    /// then the refinement.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for unusable observations (see [`Joints2d::validate`]) or a torso
    /// EPnP cannot place.
    pub fn fit(&self, obs: &Joints2d, cam: &BodyCamera, skel: &Skeleton) -> Result<BodyFit> {
        obs.validate()?;
        let init = self.initialise(obs, cam, skel)?;
        Ok(self.refine(obs, cam, skel, &init))
    }

    /// Refines from a given pose (e.g. the previous frame's, or the same frame's under slightly
    /// different dimensions) instead of the EPnP + IK initialisation.
    ///
    /// # Errors
    /// As [`BodyFitter::fit`].
    pub fn fit_from(
        &self,
        obs: &Joints2d,
        cam: &BodyCamera,
        skel: &Skeleton,
        init: &[f64; N_POSE],
    ) -> Result<BodyFit> {
        obs.validate()?;
        Ok(self.refine(obs, cam, skel, init))
    }

    /// Fits one frame of a sequence: refined from `previous` (the last frame's
    /// [`BodyFit::pose`]) when there is one, and also from scratch ([`BodyFitter::fit`]) when that
    /// fit's objective exceeds [`BodyFitConfig::refit_cost_px2`] — the lower objective wins. The
    /// previous pose keeps each limb on its depth branch from frame to frame, which a single view
    /// cannot tell (HumanEva-I Train, frames tracked against every frame from scratch:
    /// BENCHMARKS.md, "Body (CLFBA)"); the fallback
    /// recovers from a fast move or a wrong branch.
    ///
    /// # Errors
    /// As [`BodyFitter::fit`].
    pub fn fit_tracked(
        &self,
        obs: &Joints2d,
        cam: &BodyCamera,
        skel: &Skeleton,
        previous: Option<&[f64; N_POSE]>,
    ) -> Result<BodyFit> {
        let Some(prev) = previous else {
            return self.fit(obs, cam, skel);
        };
        let warm = self.fit_from(obs, cam, skel, prev)?;
        if warm.cost_px2 <= self.config.refit_cost_px2 {
            return Ok(warm);
        }
        let fresh = self.fit(obs, cam, skel)?;
        Ok(if warm.cost_px2 < fresh.cost_px2 {
            warm
        } else {
            fresh
        })
    }

    /// The initial pose: EPnP for the torso, IK for head and limbs (no refinement).
    ///
    /// # Errors
    /// [`Error::InvalidInput`] when EPnP cannot place the torso.
    pub fn initialise(
        &self,
        obs: &Joints2d,
        cam: &BodyCamera,
        skel: &Skeleton,
    ) -> Result<[f64; N_POSE]> {
        // Torso: pelvis, thorax, lshoulder, rshoulder, lhip, rhip.
        let idx = [
            Joint::Pelvis,
            Joint::Thorax,
            Joint::LShoulder,
            Joint::RShoulder,
            Joint::LHip,
            Joint::RHip,
        ];
        let tpl = skel.torso_template();
        let img = idx.map(|j| obs.points[j.index()]);
        let w = idx.map(|j| obs.weights[j.index()]);
        let (pose, _) = epnp::solve_planar(&tpl, &img, &w, &cam.intrinsics)?;
        // Body → world.
        let rt = cam.rotation.transpose();
        let r0 = rt * pose.rotation;
        let pelvis = rt * (pose.translation - cam.translation);
        let mut p = [0.0; N_POSE];
        let rv = log_so3(&r0);
        p[P_ROOT_ROT..P_ROOT_ROT + 3].copy_from_slice(rv.as_slice());
        p[P_ROOT_POS..P_ROOT_POS + 3].copy_from_slice(pelvis.as_slice());
        let mut x = [Vector3::zeros(); N_JOINTS];
        skel.forward(&p, &mut x);
        let o = cam.center();
        let chest = r0;
        // Head.
        if obs.has(Joint::Head) {
            let d = cam.ray(obs.points[Joint::Head.index()]);
            let (c, _) = ik::ray_sphere(&o, &d, &x[1], skel.len(dim::NECK));
            let best = c
                .iter()
                .map(|h| ik::neck_angles(&chest, &(h - x[1])))
                .min_by(|a, b| {
                    limits::NECK
                        .swing_excess(a[0], a[1])
                        .total_cmp(&limits::NECK.swing_excess(b[0], b[1]))
                })
                .unwrap_or([0.0; 2]);
            p[P_NECK] = best[0];
            p[P_NECK + 1] = best[1];
        }
        // Limbs: every combination of near/far solutions, scored by limits and floor.
        for (left, arm) in [(true, true), (false, true), (true, false), (false, false)] {
            let (base, root, mid, end, l1, l2) = limb_spec(left, arm, skel);
            if !(obs.has(mid) && obs.has(end)) {
                // Unobserved: a neutral pose (arms hanging, legs straight).
                if arm {
                    p[base + 1] = if left { -1.4 } else { 1.4 };
                }
                continue;
            }
            let dm = cam.ray(obs.points[mid.index()]);
            let de = cam.ray(obs.points[end.index()]);
            let (mids, _) = ik::ray_sphere(&o, &dm, &x[root.index()], l1);
            let mut best = (f64::INFINITY, [0.0; 4]);
            for m in &mids {
                let (ends, _) = ik::ray_sphere(&o, &de, m, l2);
                for e in &ends {
                    let parent = if arm { &chest } else { &r0 };
                    let a = ik::limb_angles(left, arm, parent, &(m - x[root.index()]), &(e - m));
                    let mut q = p;
                    q[base..base + 4].copy_from_slice(&a);
                    let mut cost =
                        skel.limit_violation(&q) + IK_PRIOR_WEIGHT * self.prior.distance2(&q);
                    // Joints below the floor are implausible.
                    cost += ((skel.ankle_height - ANKLE_SINK_MM - e.z).max(0.0)
                        + (MIN_JOINT_HEIGHT_MM - m.z).max(0.0))
                        / 100.0;
                    if cost < best.0 {
                        best = (cost, a);
                    }
                }
            }
            p[base..base + 4].copy_from_slice(&best.1);
        }
        if self.config.assume_contact {
            skel.forward(&p, &mut x);
            if let Some(a) = contact_ankle(&x, obs, cam, skel) {
                // The contact foot's depth comes from the floor; its knee from both segments.
                let left = a == Joint::LAnkle;
                let (base, root, mid, end, l1, l2) = limb_spec(left, false, skel);
                let de = cam.ray(obs.points[end.index()]);
                if let Some(e) = ik::ray_plane_z(&o, &de, skel.ankle_height) {
                    let dm = cam.ray(obs.points[mid.index()]);
                    let m = ik::two_sphere_near_ray(&x[root.index()], l1, &e, l2, &o, &dm);
                    let a = ik::leg_angles(left, &r0, &(m - x[root.index()]), &(e - m));
                    let mut q = p;
                    q[base..base + 4].copy_from_slice(&a);
                    let c = |v: &[f64; N_POSE]| {
                        skel.limit_violation(v) + IK_PRIOR_WEIGHT * self.prior.distance2(v)
                    };
                    if c(&q) <= c(&p) + 0.05 {
                        p = q;
                    }
                }
            }
        }
        Ok(p)
    }

    fn refine(
        &self,
        obs: &Joints2d,
        cam: &BodyCamera,
        skel: &Skeleton,
        init: &[f64; N_POSE],
    ) -> BodyFit {
        let mut x = [Vector3::zeros(); N_JOINTS];
        skel.forward(init, &mut x);
        let contact = if self.config.assume_contact {
            contact_ankle(&x, obs, cam, skel)
        } else {
            None
        };
        let problem = PoseProblem {
            skel,
            prior: &self.prior,
            prior_weight: self.config.prior_weight_px,
            cam,
            obs,
            contact: contact.map(Joint::index),
        };
        let ls = NumericLeastSquares(&problem);
        let mut v = SVector::<f64, N_POSE>::from_column_slice(init);
        let mut report = self.config.lm.minimize(&ls, &mut v);
        // The refinement cannot jump between the depth branches of a limb (knee in front of or
        // behind the hip–ankle line as seen from the camera): re-run the IK choice from the refined
        // torso, judged by the full objective, and refine again when a branch wins.
        let mut pose = unpack(&v);
        let cost0 = report.cost;
        let mut best = (cost0, pose);
        for (left, arm) in [(true, true), (false, true), (true, false), (false, false)] {
            let (base, ..) = limb_spec(left, arm, skel);
            for cand in limb_candidates(&best.1, left, arm, obs, cam, skel)
                .into_iter()
                .flatten()
            {
                let mut q = best.1;
                q[base..base + 4].copy_from_slice(&cand);
                let c = ls.cost(&SVector::from_column_slice(&q));
                if c < best.0 {
                    best = (c, q);
                }
            }
        }
        if best.0 < cost0 {
            v = SVector::from_column_slice(&best.1);
            let r2 = self.config.lm.minimize(&ls, &mut v);
            report = SolverReport {
                iterations: report.iterations + r2.iterations,
                ..r2
            };
            pose = unpack(&v);
        }
        if self.config.full_model {
            return self.refine_full(obs, cam, skel, &pose, contact, report);
        }
        skel.forward(&pose, &mut x);
        let mut r = [0.0; MAX_RESIDUALS];
        let m = problem.residuals(&v, &mut r);
        let (reprojection_rms_px, cost_px2) = fit_stats(obs, &r[..m]);
        BodyFit {
            joints: x,
            pose,
            full_pose: None,
            reprojection_rms_px,
            cost_px2,
            contact,
            report,
        }
    }

    /// The full model's refinement from the reduced fit `pose`.
    fn refine_full(
        &self,
        obs: &Joints2d,
        cam: &BodyCamera,
        skel: &Skeleton,
        pose: &[f64; N_POSE],
        contact: Option<Joint>,
        report: SolverReport,
    ) -> BodyFit {
        let fs = FullSkeleton::new(*skel);
        let problem = FullPoseProblem {
            fs: &fs,
            prior: &self.prior,
            prior_weight: self.config.prior_weight_px,
            extra_std_scale: self.config.extra_prior_scale,
            cam,
            obs,
            contact: contact.map(Joint::index),
        };
        let mut v = SVector::<f64, N_FULL_POSE>::from_column_slice(&hanim::embed(pose));
        let r2 = self
            .config
            .lm
            .minimize(&NumericLeastSquares(&problem), &mut v);
        let full = unpack(&v);
        let mut posed = Posed::default();
        fs.forward(&full, &mut posed);
        let mut r = [0.0; MAX_RESIDUALS];
        let m = problem.residuals(&v, &mut r);
        let (reprojection_rms_px, cost_px2) = fit_stats(obs, &r[..m]);
        BodyFit {
            joints: posed.output_joints(),
            pose: hanim::reduced(&full),
            full_pose: Some(full),
            reprojection_rms_px,
            cost_px2,
            contact,
            report: SolverReport {
                iterations: report.iterations + r2.iterations,
                ..r2
            },
        }
    }
}

/// RMS reprojection error (px) and objective per observed joint (px²) from a residual vector
/// whose first 30 entries are the reprojection residuals.
fn fit_stats(obs: &Joints2d, r: &[f64]) -> (f64, f64) {
    let n_obs = obs.weights.iter().filter(|w| **w > 0.0).count().max(1) as f64;
    let reproj: f64 = r[..2 * N_JOINTS].iter().map(|e| e * e).sum();
    let total: f64 = r.iter().map(|e| e * e).sum();
    ((reproj / n_obs).sqrt(), total / n_obs)
}

/// The (up to four) depth-branch configurations of a limb, as its four parameters, with the rest
/// of pose `p` (torso, spine) fixed; `None` where the limb is not observed.
fn limb_candidates(
    p: &[f64; N_POSE],
    left: bool,
    arm: bool,
    obs: &Joints2d,
    cam: &BodyCamera,
    skel: &Skeleton,
) -> [Option<[f64; 4]>; 4] {
    let mut out = [None; 4];
    let (_, root, mid, end, l1, l2) = limb_spec(left, arm, skel);
    if !(obs.has(mid) && obs.has(end)) {
        return out;
    }
    let mut x = [Vector3::zeros(); N_JOINTS];
    skel.forward(p, &mut x);
    let r0 = root_rotation(p);
    let chest = r0 * skel.spine_rotation(p);
    let o = cam.center();
    let dm = cam.ray(obs.points[mid.index()]);
    let de = cam.ray(obs.points[end.index()]);
    let (mids, _) = ik::ray_sphere(&o, &dm, &x[root.index()], l1);
    let mut k = 0;
    for m in &mids {
        let (ends, _) = ik::ray_sphere(&o, &de, m, l2);
        for e in &ends {
            let parent = if arm { &chest } else { &r0 };
            out[k] = Some(ik::limb_angles(
                left,
                arm,
                parent,
                &(m - x[root.index()]),
                &(e - m),
            ));
            k += 1;
        }
    }
    out
}

/// Parameter base, root/mid/end joints and segment lengths of a limb.
fn limb_spec(left: bool, arm: bool, skel: &Skeleton) -> (usize, Joint, Joint, Joint, f64, f64) {
    match (arm, left) {
        (true, true) => (
            P_LARM,
            Joint::LShoulder,
            Joint::LElbow,
            Joint::LWrist,
            skel.len(dim::L_UPPER_ARM),
            skel.len(dim::L_FOREARM),
        ),
        (true, false) => (
            P_RARM,
            Joint::RShoulder,
            Joint::RElbow,
            Joint::RWrist,
            skel.len(dim::R_UPPER_ARM),
            skel.len(dim::R_FOREARM),
        ),
        (false, true) => (
            P_LLEG,
            Joint::LHip,
            Joint::LKnee,
            Joint::LAnkle,
            skel.len(dim::L_THIGH),
            skel.len(dim::L_SHIN),
        ),
        (false, false) => (
            P_RLEG,
            Joint::RHip,
            Joint::RKnee,
            Joint::RAnkle,
            skel.len(dim::R_THIGH),
            skel.len(dim::R_SHIN),
        ),
    }
}

/// The observed ankle (with its knee observed) assumed on the floor. With both observed: the one
/// whose viewing ray meets the floor (at ankle height) closest to its hip, relative to the leg's
/// length. A foot in the air meets the floor beyond its true place, farther than the leg reaches;
/// the initial pose's lower ankle, used before, depends on the IK's depth guesses and picked the
/// lifted foot more often (a larger Procrustes error on HumanEva Train, with estimated and with
/// the true dimensions, and on Human3.6M synthetic).
fn contact_ankle(
    x: &[Vector3<f64>; N_JOINTS],
    obs: &Joints2d,
    cam: &BodyCamera,
    skel: &Skeleton,
) -> Option<Joint> {
    let ok = |a: Joint, k: Joint| obs.has(a) && obs.has(k);
    match (
        ok(Joint::LAnkle, Joint::LKnee),
        ok(Joint::RAnkle, Joint::RKnee),
    ) {
        (true, true) => {
            let o = cam.center();
            let reach = |left: bool| -> f64 {
                let (_, hip, _, ankle, thigh, shin) = limb_spec(left, false, skel);
                ik::ray_plane_z(&o, &cam.ray(obs.points[ankle.index()]), skel.ankle_height)
                    .map_or(f64::INFINITY, |e| {
                        (e - x[hip.index()]).norm() / (thigh + shin)
                    })
            };
            let (left, right) = (reach(true), reach(false));
            Some(if left.is_finite() || right.is_finite() {
                if left <= right {
                    Joint::LAnkle
                } else {
                    Joint::RAnkle
                }
            } else if x[10].z <= x[13].z {
                // Neither ray reaches the floor (camera below ankle height): the lower ankle.
                Joint::LAnkle
            } else {
                Joint::RAnkle
            })
        }
        (true, false) => Some(Joint::LAnkle),
        (false, true) => Some(Joint::RAnkle),
        (false, false) => None,
    }
}

/// The result of a dimension estimation.
#[derive(Debug, Clone, PartialEq)]
pub struct DimensionEstimate {
    /// The estimated dimensions.
    pub dimensions: Dimensions,
    /// The global scale found by DIRECT-L (relative to the starting dimensions).
    pub scale: f64,
    /// Mean objective per frame at the scale alone (px² per joint).
    pub scale_cost_px2: f64,
    /// Mean objective per frame with the separate dimensions (px² per joint).
    pub cost_px2: f64,
    /// Why DIRECT-L stopped.
    pub direct: DirectTermination,
    /// Why COBYLA stopped (`None` when the dimensions were not refined separately).
    pub cobyla: Option<CobylaTermination>,
    /// Objective evaluations (each a pose fit of every frame).
    pub evaluations: usize,
}

/// Estimates body dimensions over a few frames (thesis Alg. 10): DIRECT-L over the global scale,
/// then COBYLA over the twelve separate lengths, each evaluation fitting the pose of every frame
/// (warm-started from the previous evaluation's poses).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DimensionEstimator {
    /// Global-scale search; Alg. 10 stops it at 5 px² (see [`DIMENSION_STOP_PX2`]), a 0.01 change
    /// or 50 iterations.
    pub direct: DirectL,
    /// Separate-lengths search; Alg. 10 stops it at 5 px², a 0.01 change or 100 iterations.
    pub cobyla: Cobyla,
    /// Range of the global scale relative to the starting dimensions.
    pub scale_range: (f64, f64),
    /// Each separate length may move by this fraction around its scaled starting value.
    pub part_range: f64,
    /// Weight (px² per joint) of the squared log-ratio of each length to its scaled starting value:
    /// lengths longer than needed always fit, so without a prior they drift upwards. The starting
    /// value's proportions should be the convention's ([`Dimensions::mean`]). Measured with
    /// leave-one-subject-out proportions on HumanEva and Human3.6M synthetic: without it the PA
    /// error is far larger, and from 100 up it is flat, so 200 stays
    /// (`models/train/RESEARCH_LOG.md`, "Body defaults").
    pub proportion_prior_px2: f64,
    /// Refine the separate lengths (pose + dimensions) or stop after the scale (pose + scale).
    pub separate_dimensions: bool,
}

/// Alg. 10's cost threshold, px² per joint. Not applied by default (the searches' `stop_value`s are
/// −∞): on exact synthetic 2D the objective is flat well below it on the too-large side (a body 8 %
/// too large still fits far below it, in this module's tests), so stopping there returns
/// whichever scale DIRECT-L happens to try first. The 0.01-change and iteration criteria stop the
/// searches instead.
pub const DIMENSION_STOP_PX2: f64 = 5.0;

impl Default for DimensionEstimator {
    fn default() -> Self {
        Self {
            direct: DirectL {
                max_iterations: 50,
                max_evaluations: 60,
                stop_value: f64::NEG_INFINITY,
                improvement_tolerance: 0.01,
                patience: 3,
                // Alg. 10's "0.01 change" read on the scale: stop once the best interval is 1 % of
                // the scale range (±0.3 % of scale). The finer 1e-3 ran to the evaluation cap for
                // a negligible gain in HumanEva Procrustes error.
                size_tolerance: 1e-2,
                epsilon: 1e-4,
            },
            cobyla: Cobyla {
                max_evaluations: 100,
                initial_step: 0.25,
                cost_tolerance: 0.01,
                step_tolerance: 1e-3,
                stop_value: f64::NEG_INFINITY,
            },
            // Adults are within about ±25 % of the mean height.
            scale_range: (0.75, 1.3),
            part_range: 0.2,
            proportion_prior_px2: 200.0,
            separate_dimensions: true,
        }
    }
}

impl DimensionEstimator {
    /// Estimates dimensions from `frames` seen by `cam`, starting from `start`.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for no frames, bad observations or start dimensions;
    /// [`Error::InvalidConfig`] for bad search ranges.
    pub fn estimate(
        &self,
        fitter: &BodyFitter,
        frames: &[Joints2d],
        cam: &BodyCamera,
        start: &Dimensions,
        convention: Convention,
    ) -> Result<DimensionEstimate> {
        if frames.is_empty() {
            return Err(Error::InvalidInput(
                "dimension estimation needs at least one frame".into(),
            ));
        }
        for f in frames {
            f.validate()?;
        }
        start.validate()?;
        if !(self.scale_range.0 > 0.0
            && self.scale_range.0 < self.scale_range.1
            && self.part_range > 0.0
            && self.part_range < 1.0)
        {
            return Err(Error::InvalidConfig(format!(
                "dimension search ranges: scale {:?}, parts ±{}",
                self.scale_range, self.part_range
            )));
        }
        // The search fits in the reduced model: the full model's extra freedom would cost time at
        // every evaluation and cannot change what the lengths explain.
        let reduced_fitter;
        let fitter = if fitter.config.full_model {
            reduced_fitter = BodyFitter {
                config: BodyFitConfig {
                    full_model: false,
                    ..fitter.config
                },
                prior: fitter.prior.clone(),
            };
            &reduced_fitter
        } else {
            fitter
        };
        // Warm starts, one per frame, shared by all evaluations.
        let warm: RefCell<Vec<Option<[f64; N_POSE]>>> = RefCell::new(vec![None; frames.len()]);
        let evaluations = RefCell::new(0usize);
        let objective = |dims: &Dimensions| -> f64 {
            *evaluations.borrow_mut() += 1;
            let Ok(skel) = Skeleton::new(*dims, convention) else {
                return f64::INFINITY;
            };
            let mut warm = warm.borrow_mut();
            let mut sum = 0.0;
            for (k, f) in frames.iter().enumerate() {
                let fit = match warm[k] {
                    Some(init) => fitter.fit_from(f, cam, &skel, &init),
                    None => fitter.fit(f, cam, &skel),
                };
                match fit {
                    Ok(fit) => {
                        sum += fit.cost_px2;
                        warm[k] = Some(fit.pose);
                    }
                    Err(_) => return f64::INFINITY,
                }
            }
            sum / frames.len() as f64
        };
        let scale_rep = self.direct.minimize(
            |s: &[f64]| objective(&start.scaled(s[0])),
            &[self.scale_range.0],
            &[self.scale_range.1],
        )?;
        let scale = scale_rep.x[0];
        let scaled = start.scaled(scale);
        let mut dimensions = scaled;
        let mut cost = scale_rep.value;
        let mut cobyla = None;
        if self.separate_dimensions && scale_rep.value > self.cobyla.stop_value {
            // Re-seed the warm starts at the chosen scale.
            objective(&scaled);
            let lo = vec![(1.0 - self.part_range).mln(); N_DIMS];
            let hi = vec![(1.0 + self.part_range).mln(); N_DIMS];
            let x0 = vec![0.0; N_DIMS];
            let to_dims = |x: &[f64]| {
                let mut d = scaled;
                for (l, v) in d.lengths.iter_mut().zip(x) {
                    *l *= v.mexp();
                }
                d
            };
            let rep = self.cobyla.minimize(
                |x: &[f64]| {
                    let prior: f64 = x.iter().map(|v| v * v).sum::<f64>();
                    objective(&to_dims(x)) + self.proportion_prior_px2 * prior
                },
                &x0,
                &lo,
                &hi,
            )?;
            let prior0 = 0.0;
            if rep.value < scale_rep.value + prior0 {
                dimensions = to_dims(&rep.x);
                cost = rep.value;
            }
            cobyla = Some(rep.termination);
        }
        let evaluations = *evaluations.borrow();
        Ok(DimensionEstimate {
            dimensions,
            scale,
            scale_cost_px2: scale_rep.value,
            cost_px2: cost,
            direct: scale_rep.termination,
            cobyla,
            evaluations,
        })
    }
}

/// The rotation body-local → world of a fitted pose (for callers that want the body's facing).
pub fn root_rotation(pose: &[f64; N_POSE]) -> Matrix3<f64> {
    exp_so3(Vector3::new(
        pose[P_ROOT_ROT],
        pose[P_ROOT_ROT + 1],
        pose[P_ROOT_ROT + 2],
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Intrinsics;

    /// A HumanEva-like camera: 4 m from the subject, 1.5 m high, looking slightly down.
    fn camera() -> BodyCamera {
        let tilt = 10f64.to_radians();
        let z = Vector3::new(0.0, tilt.mcos(), -tilt.msin());
        let x = Vector3::new(1.0, 0.0, 0.0);
        let y = z.cross(&x);
        let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
        let center = Vector3::new(0.0, -4000.0, 1500.0);
        BodyCamera::new(
            Intrinsics::new(760.0, 760.0, 320.0, 240.0).unwrap(),
            r,
            -(r * center),
        )
        .unwrap()
    }

    /// A walking-like pose facing the camera (body z forward = world −y), feet on the floor.
    fn truth_pose(skel: &Skeleton) -> [f64; N_POSE] {
        let mut p = [0.0; N_POSE];
        // Body axes in world: x (left) = world −x... the subject faces the camera: forward = −y,
        // up = +z, left = forward × up... left = up × forward? x = y × z for (x, y, z) = (left, up,
        // forward): left = up × forward = z × (−y) = +x.
        let r0 = Matrix3::from_columns(&[
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.0, -1.0, 0.0),
        ]);
        let rv = log_so3(&r0);
        p[0..3].copy_from_slice(rv.as_slice());
        p[P_SPINE] = 0.1;
        p[P_NECK] = 0.1;
        p[P_LARM..P_LARM + 4].copy_from_slice(&[-0.3, -1.2, 0.2, 0.6]);
        p[P_RARM..P_RARM + 4].copy_from_slice(&[0.2, 1.3, -0.1, 0.3]);
        p[P_LLEG..P_LLEG + 4].copy_from_slice(&[-0.35, 0.05, 0.0, 0.2]);
        p[P_RLEG..P_RLEG + 4].copy_from_slice(&[0.25, -0.05, 0.0, 0.5]);
        // Put the lower ankle on the floor.
        let mut x = [Vector3::zeros(); N_JOINTS];
        skel.forward(&p, &mut x);
        let low = x[10].z.min(x[13].z);
        p[P_ROOT_POS + 2] = skel.ankle_height - low;
        p
    }

    fn observe(cam: &BodyCamera, x: &[Vector3<f64>; N_JOINTS]) -> Joints2d {
        Joints2d::full(std::array::from_fn(|i| cam.project(&x[i])))
    }

    /// The mean HumanEva skeleton at [`truth_pose`] seen by [`camera`]: skeleton, camera, pose,
    /// joints and their exact projections.
    fn exact_scene() -> (
        Skeleton,
        BodyCamera,
        [f64; N_POSE],
        [Vector3<f64>; N_JOINTS],
        Joints2d,
    ) {
        let skel =
            Skeleton::new(Dimensions::mean(Convention::HumanEva), Convention::HumanEva).unwrap();
        let cam = camera();
        let p = truth_pose(&skel);
        let mut x = [Vector3::zeros(); N_JOINTS];
        skel.forward(&p, &mut x);
        let obs = observe(&cam, &x);
        (skel, cam, p, x, obs)
    }

    #[test]
    fn tracked_frames_start_from_the_last_pose_and_fall_back_to_scratch() {
        let (skel, cam, p, x, obs) = exact_scene();
        let fitter = BodyFitter::default();
        let scratch = fitter.fit(&obs, &cam, &skel).unwrap();
        // No previous frame: the scratch fit.
        assert_eq!(
            fitter.fit_tracked(&obs, &cam, &skel, None).unwrap(),
            scratch
        );
        // From the true pose: a good fit, kept without a scratch fit.
        let warm = fitter.fit_tracked(&obs, &cam, &skel, Some(&p)).unwrap();
        let err = |f: &BodyFit| {
            (0..N_JOINTS)
                .map(|i| (f.joints[i] - x[i]).norm())
                .sum::<f64>()
                / N_JOINTS as f64
        };
        println!(
            "warm {:.2} px² {:.1} mm, scratch {:.2} px² {:.1} mm",
            warm.cost_px2,
            err(&warm),
            scratch.cost_px2,
            err(&scratch)
        );
        assert!(warm.cost_px2 <= fitter.config.refit_cost_px2);
        assert_eq!(warm, fitter.fit_from(&obs, &cam, &skel, &p).unwrap());
        // From a pose that has nothing to do with this frame (turned away, 3 m off, knees bent):
        // the warm fit is poor, so the frame is fitted from scratch too and that wins.
        let mut wrong = p;
        wrong[P_ROOT_ROT + 2] += 3.0;
        wrong[P_ROOT_POS] += 3000.0;
        wrong[P_LLEG + 3] = 2.0;
        wrong[P_RLEG + 3] = 2.0;
        let lost = fitter.fit_from(&obs, &cam, &skel, &wrong).unwrap();
        assert!(
            lost.cost_px2 > fitter.config.refit_cost_px2,
            "{}",
            lost.cost_px2
        );
        let tracked = fitter.fit_tracked(&obs, &cam, &skel, Some(&wrong)).unwrap();
        assert_eq!(tracked, scratch);
    }

    #[test]
    fn the_full_model_fits_what_the_reduced_one_cannot() {
        // A body with shrugged clavicles, a tilted pelvis girdle and a bent upper back: the
        // reduced model's rigid torso cannot place shoulders and hips where they are.
        let skel =
            Skeleton::new(Dimensions::mean(Convention::HumanEva), Convention::HumanEva).unwrap();
        let fs = FullSkeleton::new(skel);
        let cam = camera();
        let mut p = hanim::embed(&truth_pose(&skel));
        p[hanim::X_LSC + 1] = 0.3;
        p[hanim::X_RSC + 1] = -0.1;
        p[hanim::X_SACROILIAC + 1] = 0.12;
        p[hanim::X_VT6] = 0.2;
        assert_eq!(fs.limit_violation(&p), 0.0);
        let mut posed = Posed::default();
        fs.forward(&p, &mut posed);
        let x = posed.output_joints();
        let obs = observe(&cam, &x);
        let fit = |full_model: bool| {
            BodyFitter::new(BodyFitConfig {
                prior_weight_px: 0.3,
                full_model,
                ..Default::default()
            })
            .fit(&obs, &cam, &skel)
            .unwrap()
        };
        let err = |f: &BodyFit| {
            (0..N_JOINTS)
                .map(|i| (f.joints[i] - x[i]).norm())
                .sum::<f64>()
                / N_JOINTS as f64
        };
        let (reduced, full) = (fit(false), fit(true));
        println!(
            "reduced: {:.2} px, {:.1} mm; full: {:.2} px, {:.1} mm",
            reduced.reprojection_rms_px,
            err(&reduced),
            full.reprojection_rms_px,
            err(&full)
        );
        assert!(reduced.full_pose.is_none());
        let fp = full.full_pose.unwrap();
        assert_eq!(&fp[..N_POSE], &full.pose[..]);
        assert!(full.reprojection_rms_px < 0.5 * reduced.reprojection_rms_px);
        assert!(err(&full) < err(&reduced));
        // The left clavicle went up, as it did.
        assert!(fp[hanim::X_LSC + 1] > 0.1, "{}", fp[hanim::X_LSC + 1]);
    }

    #[test]
    fn exact_projections_of_the_model_are_fitted_to_millimetres() {
        let (skel, cam, _, x, obs) = exact_scene();
        // The prior weight is the 2D noise the fit expects (px per standard deviation of the
        // prior): the default, made for real keypoints, trades some reprojection for a pose
        // nearer Human3.6M's mean, off in the world frame by up to the bound below (the same
        // basin: the joint angles stay close); a weight for exact input recovers the pose to
        // millimetres.
        for (weight, max_px, max_mm) in [(DEFAULT_PRIOR_WEIGHT_PX, 2.0, 120.0), (0.3, 0.5, 30.0)] {
            let fitter = BodyFitter::new(BodyFitConfig {
                prior_weight_px: weight,
                ..Default::default()
            });
            let fit = fitter.fit(&obs, &cam, &skel).unwrap();
            let err: f64 = (0..N_JOINTS)
                .map(|i| (fit.joints[i] - x[i]).norm())
                .sum::<f64>()
                / N_JOINTS as f64;
            println!(
                "prior weight {weight}: reprojection {:.2} px, mean joint error {err:.1} mm",
                fit.reprojection_rms_px
            );
            assert!(fit.reprojection_rms_px < max_px, "{fit:?}");
            assert!(err < max_mm, "mean joint error {err} mm");
        }
    }

    #[test]
    fn the_scale_is_recovered_from_the_floor() {
        let conv = Convention::HumanEva;
        let truth = Skeleton::new(Dimensions::mean(conv).scaled(1.12), conv).unwrap();
        let cam = camera();
        let p = truth_pose(&truth);
        let mut x = [Vector3::zeros(); N_JOINTS];
        truth.forward(&p, &mut x);
        let obs = observe(&cam, &x);
        let est = DimensionEstimator {
            separate_dimensions: false,
            ..Default::default()
        }
        .estimate(
            &BodyFitter::default(),
            &[obs],
            &cam,
            &Dimensions::mean(conv),
            conv,
        )
        .unwrap();
        assert!((est.scale - 1.12).abs() < 0.03, "{est:?}");
    }

    #[test]
    fn bad_observations_are_typed_errors() {
        let (skel, cam, _, _, mut obs) = exact_scene();
        obs.points[3][0] = f64::NAN;
        assert!(matches!(
            BodyFitter::default().fit(&obs, &cam, &skel),
            Err(Error::InvalidInput(_))
        ));
        // A missing elbow is fine (weight 0), a missing hip is not.
        obs.weights[3] = 0.0;
        assert!(BodyFitter::default().fit(&obs, &cam, &skel).is_ok());
        obs.weights[Joint::LHip.index()] = 0.0;
        assert!(matches!(
            BodyFitter::default().fit(&obs, &cam, &skel),
            Err(Error::InvalidInput(_))
        ));
        assert!(
            DimensionEstimator::default()
                .estimate(
                    &BodyFitter::default(),
                    &[],
                    &cam,
                    &Dimensions::mean(Convention::HumanEva),
                    Convention::HumanEva
                )
                .is_err()
        );
    }
}
