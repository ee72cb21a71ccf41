//! The statistical pose prior: a Gaussian over the joint angles below the root (spine, neck, limbs),
//! learnt from motion capture, and the 3D fit of the kinematic model to mocap joints it is learnt
//! from.
//!
//! Why: from one view the 2D joints leave directions almost free (a limb turning towards the
//! camera, the torso's lean in depth). A single-frame fit started at the *true* pose drifts along
//! them to fit the 2D noise (HumanEva-I Train, mocap dimensions: the model fits the mocap 3D
//! closely, while the 2D fit started there ends far from it, less far with this prior than with
//! the isotropic one; `humaneva_pose_prior_experiments`, `models/train/RESEARCH_LOG.md`, "Body
//! defaults"). An isotropic pull towards one neutral pose decides those
//! directions arbitrarily; the Gaussian decides them the way people move (its covariance knows,
//! for instance, that a flexed knee comes with a flexed hip).
//!
//! The prior's residuals are `W (p − μ)`, `Wᵀ W = Σ⁻¹` (W the inverse of Σ's Cholesky factor), so
//! one unit is one standard deviation of the data; [`super::BodyFitConfig::prior_weight_px`] turns
//! them into pixels.

use nalgebra::{SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};
use std::sync::OnceLock;

use super::N_JOINTS;
use super::epnp;
use super::ik;
use super::optim::{MAX_RESIDUALS, NumericLeastSquares, Residuals};
use super::skeleton::*;
use crate::error::{Error, Result};
use crate::fit::solver::LevenbergMarquardt;

/// Number of pose parameters the prior covers (everything after the root's six).
pub const N_PRIOR: usize = N_POSE - P_PRIOR_START;

static SHIPPED_JSON: &[u8] = include_bytes!("../../models/body/pose_prior.json");
const PRIOR_FORMAT: &str = "monotrack-body-pose-prior";
const PRIOR_VERSION: u32 = 1;

/// A Gaussian over the non-root pose parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct PosePrior {
    mean: SVector<f64, N_PRIOR>,
    covariance: SMatrix<f64, N_PRIOR, N_PRIOR>,
    /// Inverse Cholesky factor of the covariance (lower triangular).
    whiten: SMatrix<f64, N_PRIOR, N_PRIOR>,
}

/// The file format (`core/models/body/pose_prior.json`).
#[derive(Serialize, Deserialize)]
struct PriorFile {
    format: String,
    version: u32,
    /// Where the statistics come from (free text for people).
    source: String,
    /// Number of poses the statistics were taken over.
    poses: usize,
    /// Parameter names, in order (checked on load so a reordered skeleton cannot misread a file).
    parameters: Vec<String>,
    mean: Vec<f64>,
    covariance: Vec<Vec<f64>>,
}

/// Names of the prior's parameters, in pose-vector order from [`P_PRIOR_START`].
pub const PARAMETER_NAMES: [&str; N_PRIOR] = [
    "spine_flexion",
    "spine_lateral",
    "spine_twist",
    "neck_flexion",
    "neck_lateral",
    "l_shoulder_swing_y",
    "l_shoulder_swing_z",
    "l_shoulder_twist",
    "l_elbow_flexion",
    "r_shoulder_swing_y",
    "r_shoulder_swing_z",
    "r_shoulder_twist",
    "r_elbow_flexion",
    "l_hip_swing_x",
    "l_hip_swing_z",
    "l_hip_twist",
    "l_knee_flexion",
    "r_hip_swing_x",
    "r_hip_swing_z",
    "r_hip_twist",
    "r_knee_flexion",
];

impl PosePrior {
    /// The prior shipped with the SDK (Human3.6M, see `core/models/body/README.md`), parsed once.
    pub fn shipped() -> &'static PosePrior {
        static PRIOR: OnceLock<PosePrior> = OnceLock::new();
        PRIOR.get_or_init(|| {
            // Checked by the `shipped_prior_loads` test, so this cannot fail in a released build.
            Self::from_json(SHIPPED_JSON).expect("embedded pose prior is valid")
        })
    }

    /// The isotropic prior used before the learnt one: mean [`NEUTRAL`], one radian per standard
    /// deviation on every parameter, no correlations.
    pub fn neutral() -> Self {
        let eye = SMatrix::identity();
        Self {
            mean: non_root(&NEUTRAL),
            covariance: eye,
            whiten: eye,
        }
    }

    /// A prior from mean and covariance.
    ///
    /// # Errors
    /// [`Error::ModelLoad`] for non-finite values or a covariance that is not symmetric positive
    /// definite.
    pub fn new(
        mean: SVector<f64, N_PRIOR>,
        covariance: SMatrix<f64, N_PRIOR, N_PRIOR>,
    ) -> Result<Self> {
        if mean.iter().chain(covariance.iter()).any(|v| !v.is_finite()) {
            return Err(Error::ModelLoad("pose prior: non-finite value".into()));
        }
        let asym = (covariance - covariance.transpose()).abs().max();
        if asym > 1e-9 * covariance.abs().max().max(1.0) {
            return Err(Error::ModelLoad(
                "pose prior: covariance is not symmetric".into(),
            ));
        }
        let chol = covariance.cholesky().ok_or_else(|| {
            Error::ModelLoad("pose prior: covariance is not positive definite".into())
        })?;
        let l = chol.l();
        let whiten = l
            .solve_lower_triangular(&SMatrix::identity())
            .ok_or_else(|| Error::ModelLoad("pose prior: singular covariance".into()))?;
        Ok(Self {
            mean,
            covariance,
            whiten,
        })
    }

    /// The Gaussian of `poses` (mean and covariance of their non-root parameters), with `min_std`
    /// radians of independent spread added to every parameter so that a parameter the data never
    /// moves (e.g. a twist the 15 joints cannot show) keeps a finite, usable precision.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for fewer than two poses, non-finite values or `min_std ≤ 0`.
    pub fn from_poses(poses: &[[f64; N_POSE]], min_std: f64) -> Result<Self> {
        if poses.len() < 2 {
            return Err(Error::InvalidInput(
                "a pose prior needs at least two poses".into(),
            ));
        }
        if !(min_std.is_finite() && min_std > 0.0) {
            return Err(Error::InvalidInput(format!(
                "pose prior: min_std must be positive, got {min_std}"
            )));
        }
        let n = poses.len() as f64;
        let mean = poses.iter().map(non_root).sum::<SVector<f64, N_PRIOR>>() / n;
        let mut cov = SMatrix::<f64, N_PRIOR, N_PRIOR>::zeros();
        for p in poses {
            let d = non_root(p) - mean;
            cov += d * d.transpose();
        }
        cov /= n - 1.0;
        for i in 0..N_PRIOR {
            cov[(i, i)] += min_std * min_std;
        }
        Self::new(mean, cov).map_err(|e| Error::InvalidInput(e.to_string()))
    }

    /// Parses a prior file (the format [`PosePrior::to_json`] writes).
    ///
    /// # Errors
    /// [`Error::ModelLoad`] for malformed JSON, another format or version, parameter names that do
    /// not match this skeleton, wrong sizes, or an invalid covariance.
    pub fn from_json(bytes: &[u8]) -> Result<Self> {
        let f: PriorFile = serde_json::from_slice(bytes)
            .map_err(|e| Error::ModelLoad(format!("pose prior JSON: {e}")))?;
        if f.format != PRIOR_FORMAT || f.version != PRIOR_VERSION {
            return Err(Error::ModelLoad(format!(
                "pose prior format {} v{} is not {PRIOR_FORMAT} v{PRIOR_VERSION}",
                f.format, f.version
            )));
        }
        if f.parameters.len() != N_PRIOR
            || f.parameters
                .iter()
                .zip(PARAMETER_NAMES)
                .any(|(a, b)| a != b)
        {
            return Err(Error::ModelLoad(
                "pose prior: parameter names differ from this skeleton's".into(),
            ));
        }
        if f.mean.len() != N_PRIOR
            || f.covariance.len() != N_PRIOR
            || f.covariance.iter().any(|r| r.len() != N_PRIOR)
        {
            return Err(Error::ModelLoad(format!(
                "pose prior: mean and covariance must be {N_PRIOR} and {N_PRIOR}x{N_PRIOR}"
            )));
        }
        Self::new(
            SVector::from_column_slice(&f.mean),
            SMatrix::from_fn(|i, j| f.covariance[i][j]),
        )
    }

    /// Writes the prior as JSON, with `source` describing the data and `poses` their count.
    pub fn to_json(&self, source: &str, poses: usize) -> String {
        let f = PriorFile {
            format: PRIOR_FORMAT.into(),
            version: PRIOR_VERSION,
            source: source.into(),
            poses,
            parameters: PARAMETER_NAMES.iter().map(|s| s.to_string()).collect(),
            // Six decimals: 1e-6 rad, far below anything the fit resolves.
            mean: self.mean.iter().map(|v| round6(*v)).collect(),
            covariance: (0..N_PRIOR)
                .map(|i| {
                    (0..N_PRIOR)
                        .map(|j| round6(self.covariance[(i, j)]))
                        .collect()
                })
                .collect(),
        };
        serde_json::to_string_pretty(&f).expect("plain numbers and strings serialise")
    }

    /// The mean pose's non-root parameters.
    pub fn mean(&self) -> &SVector<f64, N_PRIOR> {
        &self.mean
    }

    /// The covariance.
    pub fn covariance(&self) -> &SMatrix<f64, N_PRIOR, N_PRIOR> {
        &self.covariance
    }

    /// Writes the whitened residuals `W (p − μ)` of pose `p` (standard deviations).
    #[inline]
    pub fn residuals(&self, p: &[f64; N_POSE], out: &mut [f64]) {
        let mut d = [0.0; N_PRIOR];
        for (i, v) in d.iter_mut().enumerate() {
            *v = p[P_PRIOR_START + i] - self.mean[i];
        }
        // W is lower triangular: row i needs d[..=i] only.
        for (i, o) in out.iter_mut().take(N_PRIOR).enumerate() {
            let mut s = 0.0;
            for (j, dj) in d.iter().enumerate().take(i + 1) {
                s += self.whiten[(i, j)] * dj;
            }
            *o = s;
        }
    }

    /// Squared Mahalanobis distance of pose `p` from the mean.
    pub fn distance2(&self, p: &[f64; N_POSE]) -> f64 {
        let mut r = [0.0; N_PRIOR];
        self.residuals(p, &mut r);
        r.iter().map(|v| v * v).sum()
    }
}

/// The parameters of `p` the prior covers.
fn non_root(p: &[f64; N_POSE]) -> SVector<f64, N_PRIOR> {
    SVector::from_fn(|i, _| p[P_PRIOR_START + i])
}

fn round6(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

/// The pose whose joints come closest (least squares, mm) to given 3D joints, e.g. a mocap frame,
/// within the joint limits: IK on the true segment directions, then Levenberg–Marquardt on the
/// joint distances. Returns the pose and its RMS joint distance, mm.
///
/// # Errors
/// [`Error::InvalidInput`] for non-finite joints or a torso too degenerate to orient.
pub fn fit_to_joints(
    skel: &Skeleton,
    joints: &[Vector3<f64>; N_JOINTS],
) -> Result<([f64; N_POSE], f64)> {
    if joints.iter().any(|j| !j.iter().all(|v| v.is_finite())) {
        return Err(Error::InvalidInput("mocap joints must be finite".into()));
    }
    // Root: the rigid transform of the straight-spine torso template onto pelvis, thorax,
    // shoulders, hips.
    let tpl = skel.torso_template();
    let torso = [0usize, 1, 2, 5, 8, 11].map(|i| joints[i]);
    let (r0, pelvis, sv) = epnp::rigid_transform(&tpl, &torso, &[1.0; 6])
        .ok_or_else(|| Error::InvalidInput("mocap torso is degenerate".into()))?;
    if sv.iter().filter(|v| **v < 1e-6).count() > 1 {
        return Err(Error::InvalidInput("mocap torso is degenerate".into()));
    }
    let mut p = [0.0; N_POSE];
    p[P_ROOT_ROT..P_ROOT_ROT + 3].copy_from_slice(log_so3(&r0).as_slice());
    p[P_ROOT_POS..P_ROOT_POS + 3].copy_from_slice(pelvis.as_slice());
    let n = ik::neck_angles(&r0, &(joints[14] - joints[1]));
    p[P_NECK] = n[0];
    p[P_NECK + 1] = n[1];
    // The spine is straight here, so the chest frame is the pelvis frame.
    for (left, arm, base, a, b, c) in [
        (true, true, P_LARM, 2, 3, 4),
        (false, true, P_RARM, 5, 6, 7),
        (true, false, P_LLEG, 8, 9, 10),
        (false, false, P_RLEG, 11, 12, 13),
    ] {
        let q = ik::limb_angles(
            left,
            arm,
            &r0,
            &(joints[b] - joints[a]),
            &(joints[c] - joints[b]),
        );
        p[base..base + 4].copy_from_slice(&q);
    }
    let problem = JointFit { skel, joints };
    let lm = LevenbergMarquardt {
        max_iterations: 100,
        cost_tolerance: 1e-10,
        step_tolerance: 1e-10,
        initial_lambda: 1e-3,
    };
    let mut v = SVector::<f64, N_POSE>::from_column_slice(&p);
    lm.minimize(&NumericLeastSquares(&problem), &mut v);
    p.copy_from_slice(v.as_slice());
    let mut x = [Vector3::zeros(); N_JOINTS];
    skel.forward(&p, &mut x);
    let ms = x
        .iter()
        .zip(joints)
        .map(|(a, b)| (a - b).norm_squared())
        .sum::<f64>()
        / N_JOINTS as f64;
    Ok((p, ms.sqrt()))
}

/// Weight of joint-limit excess in [`fit_to_joints`], mm per unit (as in the 2D fit, limits act as
/// near-hard constraints).
const JOINT_FIT_LIMIT_MM: f64 = 200.0;
/// Pull towards [`NEUTRAL`] in [`fit_to_joints`], mm per radian: tiny, so it only holds what the
/// joints cannot show (the twist of a straight limb).
const JOINT_FIT_NEUTRAL_MM: f64 = 1.0;

struct JointFit<'a> {
    skel: &'a Skeleton,
    joints: &'a [Vector3<f64>; N_JOINTS],
}

impl Residuals<N_POSE> for JointFit<'_> {
    fn residuals(&self, x: &SVector<f64, N_POSE>, r: &mut [f64; MAX_RESIDUALS]) -> usize {
        let mut p = [0.0; N_POSE];
        p.copy_from_slice(x.as_slice());
        let mut j = [Vector3::zeros(); N_JOINTS];
        self.skel.forward(&p, &mut j);
        let mut k = 0;
        for (a, b) in j.iter().zip(self.joints) {
            for c in 0..3 {
                r[k] = a[c] - b[c];
                k += 1;
            }
        }
        let mut lim = [0.0; N_LIMITS];
        self.skel.limit_violations(&p, &mut lim);
        for v in lim {
            r[k] = JOINT_FIT_LIMIT_MM * v;
            k += 1;
        }
        for i in P_PRIOR_START..N_POSE {
            r[k] = JOINT_FIT_NEUTRAL_MM * (p[i] - NEUTRAL[i]);
            k += 1;
        }
        k
    }

    fn step(&self, i: usize) -> f64 {
        pose_fd_step(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::{Convention, Dimensions};

    fn skel() -> Skeleton {
        Skeleton::new(Dimensions::mean(Convention::Human36M), Convention::Human36M).unwrap()
    }

    #[test]
    fn shipped_prior_loads() {
        let p = PosePrior::shipped();
        // Standard deviations between 0.05 rad (the added floor) and π.
        for (i, name) in PARAMETER_NAMES.iter().enumerate() {
            let s = p.covariance()[(i, i)].sqrt();
            assert!((0.05..std::f64::consts::PI).contains(&s), "{name} {s}");
        }
        // Knees bend forward on average, never backward.
        assert!(p.mean()[P_LLEG + 3 - P_PRIOR_START] > 0.0);
        let back = PosePrior::from_json(p.to_json("x", 1).as_bytes()).unwrap();
        assert!((back.whiten - p.whiten).abs().max() < 1e-3);
    }

    #[test]
    fn whitening_inverts_the_covariance() {
        let p = PosePrior::shipped();
        let w = p.whiten;
        let info = w.transpose() * w;
        let id = info * p.covariance();
        assert!(
            (id - SMatrix::<f64, N_PRIOR, N_PRIOR>::identity())
                .abs()
                .max()
                < 1e-6
        );
        // The mean pose is at distance 0, one standard deviation along a parameter alone at ≥ 1.
        let mut m = NEUTRAL;
        for i in 0..N_PRIOR {
            m[P_PRIOR_START + i] = p.mean()[i];
        }
        assert!(p.distance2(&m) < 1e-18);
        m[P_LARM + 3] +=
            p.covariance()[(P_LARM + 3 - P_PRIOR_START, P_LARM + 3 - P_PRIOR_START)].sqrt();
        assert!(p.distance2(&m) >= 1.0 - 1e-9);
    }

    #[test]
    fn bad_prior_files_are_typed_errors() {
        let good = PosePrior::shipped().to_json("x", 1);
        for bad in [
            "{".to_string(),
            good.replace("monotrack-body-pose-prior", "other"),
            good.replace("spine_flexion", "spine"),
            good.replacen("\"covariance\": [", "\"covariance\": [[1.0],", 1),
        ] {
            assert!(
                matches!(
                    PosePrior::from_json(bad.as_bytes()),
                    Err(Error::ModelLoad(_))
                ),
                "{bad:.80}"
            );
        }
        // Not positive definite.
        let mut cov = SMatrix::<f64, N_PRIOR, N_PRIOR>::identity();
        cov[(3, 3)] = -1.0;
        assert!(PosePrior::new(SVector::zeros(), cov).is_err());
        assert!(PosePrior::from_poses(&[[0.0; N_POSE]], 0.1).is_err());
        assert!(PosePrior::from_poses(&[[0.0; N_POSE]; 3], 0.0).is_err());
        let mut nan = [[0.0; N_POSE]; 3];
        nan[1][10] = f64::NAN;
        assert!(PosePrior::from_poses(&nan, 0.1).is_err());
    }

    #[test]
    fn joint_fit_recovers_a_pose_within_the_limits() {
        let s = skel();
        let mut p = NEUTRAL;
        p[P_ROOT_ROT..P_ROOT_ROT + 3].copy_from_slice(&[0.1, 0.7, -0.05]);
        p[P_ROOT_POS..P_ROOT_POS + 3].copy_from_slice(&[300.0, -200.0, 950.0]);
        p[P_SPINE] = 0.2;
        p[P_SPINE + 2] = 0.15;
        p[P_NECK] = 0.3;
        p[P_LARM..P_LARM + 4].copy_from_slice(&[0.4, -0.9, 0.3, 1.1]);
        p[P_RARM..P_RARM + 4].copy_from_slice(&[-0.2, 1.0, 0.1, 0.6]);
        p[P_LLEG..P_LLEG + 4].copy_from_slice(&[-0.5, 0.1, 0.05, 0.9]);
        p[P_RLEG..P_RLEG + 4].copy_from_slice(&[0.3, -0.05, 0.0, 0.2]);
        assert_eq!(s.limit_violation(&p), 0.0);
        let mut x = [Vector3::zeros(); N_JOINTS];
        s.forward(&p, &mut x);
        let (q, rms) = fit_to_joints(&s, &x).unwrap();
        assert!(rms < 0.5, "rms {rms} mm");
        let mut y = [Vector3::zeros(); N_JOINTS];
        s.forward(&q, &mut y);
        for (a, b) in x.iter().zip(&y) {
            assert!((a - b).norm() < 1.5);
        }
        let mut bad = x;
        bad[3].x = f64::NAN;
        assert!(fit_to_joints(&s, &bad).is_err());
    }
}
