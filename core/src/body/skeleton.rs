//! The kinematic body model in its reduced form (the subspace of [`super::hanim`]'s 21-joint,
//! 54-DoF model the fitter works in): body dimensions, joint-definition conventions, the joint-angle
//! pose vector, forward kinematics and the swing–twist joint limits.
//!
//! The skeleton has the 15 output joints (see [`super::Joint`]) and 27 degrees of freedom: 6 at the
//! root; 3 at the lumbar spine; 2 at the neck (its twist cannot be seen from a single head point);
//! per arm 3 at the shoulder (swing and twist) and 1 at the elbow (flexion); per leg 3 at the hip
//! and 1 at the knee (flexion only). Every ball joint is parameterised by swing–twist: a twist
//! about the segment's rest axis followed by a swing whose rotation vector lies in the plane
//! perpendicular to it, so the biomechanical limits are an elliptical cone on the two swing
//! components (one radius per quadrant) plus a twist interval (thesis Fig. 5.4).
//!
//! Body-local frames: x towards the subject's left, y up, z forward. Rest pose: a T-pose (arms
//! along ±x, legs and spine along ∓y). Right-side limits are the left-side limits mirrored in the
//! sagittal plane: a mirror negates the right arm's swing components and twist and the right
//! leg's abduction swing and twist (rotation vectors are pseudo-vectors).

use crate::math::Libm;
use nalgebra::{Matrix3, Rotation3, Vector3};

use super::N_JOINTS;
use crate::error::{Error, Result};

/// Number of pose parameters.
pub const N_POSE: usize = 27;
/// Number of body-part length parameters in [`Dimensions`].
pub const N_DIMS: usize = 12;
/// Number of joint-limit terms (see [`Skeleton::limit_violations`]).
pub const N_LIMITS: usize = 15;

/// Root rotation (rotation vector, body-local → world), 3 parameters.
pub const P_ROOT_ROT: usize = 0;
/// Root translation (world, mm), 3 parameters.
pub const P_ROOT_POS: usize = 3;
/// Lumbar spine: swing about x (flexion +) and z (lateral), twist about y.
pub const P_SPINE: usize = 6;
/// Neck: swing about x (flexion +) and z (lateral).
pub const P_NECK: usize = 9;
/// Left arm: shoulder swing about y and z, twist about the arm, elbow flexion.
pub const P_LARM: usize = 11;
/// Right arm (mirrored parameterisation of the left one).
pub const P_RARM: usize = 15;
/// Left leg: hip swing about x and z, twist about the thigh, knee flexion.
pub const P_LLEG: usize = 19;
/// Right leg.
pub const P_RLEG: usize = 23;

/// Index of each body-part length in [`Dimensions::lengths`].
pub mod dim {
    /// Pelvis → thorax.
    pub const BACK: usize = 0;
    /// Thorax → head.
    pub const NECK: usize = 1;
    /// Shoulder to shoulder.
    pub const SHOULDER_WIDTH: usize = 2;
    /// Hip to hip.
    pub const HIP_WIDTH: usize = 3;
    /// Left shoulder → elbow.
    pub const L_UPPER_ARM: usize = 4;
    /// Right shoulder → elbow.
    pub const R_UPPER_ARM: usize = 5;
    /// Left elbow → wrist.
    pub const L_FOREARM: usize = 6;
    /// Right elbow → wrist.
    pub const R_FOREARM: usize = 7;
    /// Left hip → knee.
    pub const L_THIGH: usize = 8;
    /// Right hip → knee.
    pub const R_THIGH: usize = 9;
    /// Left knee → ankle.
    pub const L_SHIN: usize = 10;
    /// Right knee → ankle.
    pub const R_SHIN: usize = 11;
    /// The left and right lengths of each limb segment (upper arm, forearm, thigh, shin).
    pub const LEFT_RIGHT: [(usize, usize); 4] = [
        (L_UPPER_ARM, R_UPPER_ARM),
        (L_FOREARM, R_FOREARM),
        (L_THIGH, R_THIGH),
        (L_SHIN, R_SHIN),
    ];
    /// The names used in JSON output, in index order.
    pub const NAMES: [&str; super::N_DIMS] = [
        "back",
        "neck",
        "shoulder_width",
        "hip_width",
        "left_upper_arm",
        "right_upper_arm",
        "left_forearm",
        "right_forearm",
        "left_thigh",
        "right_thigh",
        "left_shin",
        "right_shin",
    ];
}

/// The twelve body-part lengths, millimetres (indices in [`dim`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dimensions {
    /// Lengths in mm.
    pub lengths: [f64; N_DIMS],
}

impl Dimensions {
    /// The mean adult of `convention`'s data set (see [`Convention::mean_lengths_mm`]): the
    /// starting dimensions and the proportions the dimension search is pulled towards.
    pub fn mean(convention: Convention) -> Self {
        Self {
            lengths: convention.mean_lengths_mm(),
        }
    }

    /// Every length multiplied by `s`.
    pub fn scaled(&self, s: f64) -> Self {
        Self {
            lengths: self.lengths.map(|l| l * s),
        }
    }

    /// Checks every length is finite and within [10 mm, 2 m].
    ///
    /// # Errors
    /// [`Error::InvalidInput`] naming the length.
    pub fn validate(&self) -> Result<()> {
        for (i, l) in self.lengths.iter().enumerate() {
            if !(l.is_finite() && (10.0..=2000.0).contains(l)) {
                return Err(Error::InvalidInput(format!(
                    "body dimension {} = {l} mm is outside [10, 2000]",
                    dim::NAMES[i]
                )));
            }
        }
        Ok(())
    }
}

/// Joint-definition conventions of 15-joint data sets: where their "hip", "shoulder", "head"
/// points sit relative to the pelvis and thorax. These are properties of how a data set defines its
/// joints (marker placement), not of the subject.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Convention {
    /// HumanEva-I (and CONTRACT.md's `body-fit`): the hip points sit 50 mm in front of the pelvis
    /// and 93 mm apart, the shoulders slightly behind and below the thorax.
    #[default]
    HumanEva,
    /// Human3.6M: the pelvis is the midpoint of the hips.
    Human36M,
}

/// The numbers behind a [`Convention`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConventionConstants {
    /// Hips below the pelvis (negative: above), mm, along the body's up axis.
    pub hip_drop_mm: f64,
    /// Hips in front of the pelvis, mm.
    pub hip_forward_mm: f64,
    /// Shoulders below the thorax, mm.
    pub shoulder_drop_mm: f64,
    /// Shoulders in front of the thorax, mm.
    pub shoulder_forward_mm: f64,
    /// Height of the ankle joint above the floor when the foot is flat on it, mm (for the mean
    /// body; scaled with the shin).
    pub ankle_height_mm: f64,
}

impl Convention {
    /// The mean body of the convention's data set, in [`dim`] order (mm): per-subject mean bone
    /// lengths of its training subjects, averaged over the subjects, left and right averaged, rounded
    /// to the millimetre.
    ///
    /// The two data sets place their joints differently enough that one table cannot serve both:
    /// HumanEva's shoulder points sit 1.19 upper arms apart (Human3.6M 0.98), its hip points 93 mm
    /// apart (271), its "head" 319 mm above the thorax (178), and its legs are 1.43 times its arms
    /// (Human3.6M 1.69). With Human3.6M's proportions as the prior for HumanEva, the estimated
    /// shins came out far too long and the shoulders too narrow.
    ///
    /// HumanEva-I: Train subjects S1–S3 (every 10th mocap frame of every chunk; `body_humaneva`
    /// recomputes and checks this table, and evaluates with leave-one-subject-out tables instead,
    /// since HumanEva-I has no other subjects). Human3.6M: S1, S5–S8 (`body_h36m` likewise).
    pub fn mean_lengths_mm(self) -> [f64; N_DIMS] {
        let (back, neck, shoulders, hips, upper_arm, forearm, thigh, shin) = match self {
            Self::HumanEva => (484.0, 319.0, 349.0, 93.0, 294.0, 280.0, 421.0, 400.0),
            Self::Human36M => (487.0, 178.0, 276.0, 271.0, 282.0, 250.0, 452.0, 447.0),
        };
        // [`dim`] order: back, neck, shoulders, hips, then each limb segment left and right.
        [
            back, neck, shoulders, hips, upper_arm, upper_arm, forearm, forearm, thigh, thigh,
            shin, shin,
        ]
    }

    /// The constants. HumanEva-I's were measured on its Train split's mocap joints (means in the
    /// pelvis frame over S1-S3; their spread across subjects is under 5 mm, i.e. they are fixed by
    /// the joint definitions); Human3.6M's likewise over S1, S5-S8. Ankle heights: the median
    /// height of the lower ankle over each data set.
    pub fn constants(self) -> ConventionConstants {
        match self {
            Self::HumanEva => ConventionConstants {
                hip_drop_mm: 4.0,
                hip_forward_mm: 50.0,
                shoulder_drop_mm: 20.0,
                shoulder_forward_mm: -35.0,
                ankle_height_mm: 88.0,
            },
            Self::Human36M => ConventionConstants {
                hip_drop_mm: 0.0,
                hip_forward_mm: 0.0,
                shoulder_drop_mm: 54.0,
                shoulder_forward_mm: -8.0,
                ankle_height_mm: 80.0,
            },
        }
    }
}

/// A limit on a ball joint in swing–twist form, in the left-side parameterisation: the swing's two
/// rotation-vector components (a, b) lie inside the ellipse with radii `a_neg`/`a_pos` and
/// `b_neg`/`b_pos` (per sign), the twist in `twist`. Radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwingTwistLimit {
    /// Radius of the swing cone for a < 0.
    pub a_neg: f64,
    /// Radius for a > 0.
    pub a_pos: f64,
    /// Radius for b < 0.
    pub b_neg: f64,
    /// Radius for b > 0.
    pub b_pos: f64,
    /// Twist interval.
    pub twist: (f64, f64),
}

impl SwingTwistLimit {
    const fn deg(a_neg: f64, a_pos: f64, b_neg: f64, b_pos: f64, t0: f64, t1: f64) -> Self {
        const D: f64 = std::f64::consts::PI / 180.0;
        Self {
            a_neg: a_neg * D,
            a_pos: a_pos * D,
            b_neg: b_neg * D,
            b_pos: b_pos * D,
            twist: (t0 * D, t1 * D),
        }
    }

    /// How far (a, b) lies outside the swing cone, as a fraction of the cone's radius (0 inside).
    pub fn swing_excess(&self, a: f64, b: f64) -> f64 {
        let ra = if a < 0.0 { self.a_neg } else { self.a_pos };
        let rb = if b < 0.0 { self.b_neg } else { self.b_pos };
        let e = ((a / ra).powi(2) + (b / rb).powi(2)).sqrt();
        (e - 1.0).max(0.0)
    }

    /// The swing (a, b) scaled back onto the cone when outside it (unchanged inside).
    pub fn clamp_swing(&self, a: f64, b: f64) -> (f64, f64) {
        let e = self.swing_excess(a, b);
        if e > 0.0 {
            (a / (1.0 + e), b / (1.0 + e))
        } else {
            (a, b)
        }
    }

    /// How far the twist lies outside its interval, radians (0 inside).
    pub fn twist_excess(&self, t: f64) -> f64 {
        (self.twist.0 - t).max(0.0) + (t - self.twist.1).max(0.0)
    }
}

/// Biomechanical ranges of motion (left side), degrees → radians. From the usual clinical ranges
/// (American Academy of Orthopaedic Surgeons' joint-motion tables), widened by about 10° because the
/// swing–twist ellipse only approximates the real cone.
pub mod limits {
    use super::SwingTwistLimit;
    /// Lumbar spine: a = flexion(+)/extension(−) about x, b = lateral bend about z; twist about y.
    pub const SPINE: SwingTwistLimit = SwingTwistLimit::deg(35.0, 90.0, 40.0, 40.0, -45.0, 45.0);
    /// Neck: a = flexion(+)/extension(−), b = lateral bend.
    pub const NECK: SwingTwistLimit = SwingTwistLimit::deg(60.0, 70.0, 50.0, 50.0, 0.0, 0.0);
    /// Left shoulder from the T-pose: a = swing about y (− forward, + backward), b = swing about z
    /// (+ up, − down).
    pub const SHOULDER: SwingTwistLimit =
        SwingTwistLimit::deg(140.0, 60.0, 110.0, 110.0, -100.0, 100.0);
    /// Left hip from standing: a = swing about x (− flexion forward, + extension backward),
    /// b = swing about z (+ abduction, − adduction).
    pub const HIP: SwingTwistLimit = SwingTwistLimit::deg(130.0, 40.0, 35.0, 55.0, -50.0, 50.0);
    /// Elbow flexion interval, radians (no hyperextension beyond 5°).
    pub const ELBOW: (f64, f64) = (-5.0 * DEG, 155.0 * DEG);
    /// Knee flexion interval, radians.
    pub const KNEE: (f64, f64) = (-5.0 * DEG, 155.0 * DEG);
    const DEG: f64 = std::f64::consts::PI / 180.0;
}

/// The skeleton of one body: its dimensions and convention, with the bone vectors precomputed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Skeleton {
    /// Body-part lengths.
    pub dims: Dimensions,
    /// Joint-definition convention.
    pub convention: Convention,
    hip_l: Vector3<f64>,
    hip_r: Vector3<f64>,
    sh_l: Vector3<f64>,
    sh_r: Vector3<f64>,
    /// Height of the ankle joints above the floor when standing on it, mm.
    pub ankle_height: f64,
}

/// Rotation by angle `t` about x.
#[inline]
pub(crate) fn rot_x(t: f64) -> Matrix3<f64> {
    let (s, c) = t.msin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

/// Rotation by angle `t` about y.
#[inline]
pub(crate) fn rot_y(t: f64) -> Matrix3<f64> {
    let (s, c) = t.msin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

/// Rotation matrix of a rotation vector.
#[inline]
pub fn exp_so3(v: Vector3<f64>) -> Matrix3<f64> {
    Rotation3::from_scaled_axis(v).into_inner()
}

/// Rotation vector of a rotation matrix.
#[inline]
pub fn log_so3(m: &Matrix3<f64>) -> Vector3<f64> {
    Rotation3::from_matrix_unchecked(*m).scaled_axis()
}

impl Skeleton {
    /// A skeleton with these dimensions.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] for lengths outside their range (see [`Dimensions::validate`]).
    pub fn new(dims: Dimensions, convention: Convention) -> Result<Self> {
        dims.validate()?;
        let c = convention.constants();
        let l = &dims.lengths;
        // Convention offsets scale with the body (a smaller body has a smaller pelvis).
        let s = l[dim::BACK] / Dimensions::mean(convention).lengths[dim::BACK];
        let hw = l[dim::HIP_WIDTH] / 2.0;
        let sw = l[dim::SHOULDER_WIDTH] / 2.0;
        let shin = 0.5 * (l[dim::L_SHIN] + l[dim::R_SHIN]);
        let mean_shin = Dimensions::mean(convention).lengths[dim::L_SHIN];
        Ok(Self {
            dims,
            convention,
            hip_l: Vector3::new(hw, -c.hip_drop_mm * s, c.hip_forward_mm * s),
            hip_r: Vector3::new(-hw, -c.hip_drop_mm * s, c.hip_forward_mm * s),
            sh_l: Vector3::new(sw, -c.shoulder_drop_mm * s, c.shoulder_forward_mm * s),
            sh_r: Vector3::new(-sw, -c.shoulder_drop_mm * s, c.shoulder_forward_mm * s),
            ankle_height: c.ankle_height_mm * shin / mean_shin,
        })
    }

    /// Length of dimension `i` (see [`dim`]).
    #[inline]
    pub fn len(&self, i: usize) -> f64 {
        self.dims.lengths[i]
    }

    /// Hip offset from the pelvis in the pelvis frame (`left` or right).
    pub fn hip_offset(&self, left: bool) -> Vector3<f64> {
        if left { self.hip_l } else { self.hip_r }
    }

    /// Shoulder offset from the thorax in the chest frame.
    pub fn shoulder_offset(&self, left: bool) -> Vector3<f64> {
        if left { self.sh_l } else { self.sh_r }
    }

    /// The torso template in the pelvis frame with a straight spine: pelvis, thorax, lshoulder,
    /// rshoulder, lhip, rhip.
    pub fn torso_template(&self) -> [Vector3<f64>; 6] {
        let thorax = Vector3::new(0.0, self.len(dim::BACK), 0.0);
        [
            Vector3::zeros(),
            thorax,
            thorax + self.sh_l,
            thorax + self.sh_r,
            self.hip_l,
            self.hip_r,
        ]
    }

    /// Forward kinematics: joint positions (world, mm) of pose `p`.
    pub fn forward(&self, p: &[f64; N_POSE], out: &mut [Vector3<f64>; N_JOINTS]) {
        let v = |i: usize| Vector3::new(p[i], p[i + 1], p[i + 2]);
        let r0 = exp_so3(v(P_ROOT_ROT));
        let pelvis = v(P_ROOT_POS);
        let rs = r0 * self.spine_rotation(p);
        let thorax = pelvis + rs * Vector3::new(0.0, self.len(dim::BACK), 0.0);
        let rn = rs * exp_so3(Vector3::new(p[P_NECK], 0.0, p[P_NECK + 1]));
        out[0] = pelvis;
        out[1] = thorax;
        out[14] = thorax + rn * Vector3::new(0.0, self.len(dim::NECK), 0.0);
        for left in [true, false] {
            let (base, sh, el, wr) = if left {
                (P_LARM, 2, 3, 4)
            } else {
                (P_RARM, 5, 6, 7)
            };
            out[sh] = thorax + rs * self.shoulder_offset(left);
            let (ra, re) = self.arm_rotations(left, &p[base..base + 4]);
            let ra = rs * ra;
            let sgn = if left { 1.0 } else { -1.0 };
            let (lu, lf) = if left {
                (self.len(dim::L_UPPER_ARM), self.len(dim::L_FOREARM))
            } else {
                (self.len(dim::R_UPPER_ARM), self.len(dim::R_FOREARM))
            };
            out[el] = out[sh] + ra * Vector3::new(sgn * lu, 0.0, 0.0);
            out[wr] = out[el] + ra * re * Vector3::new(sgn * lf, 0.0, 0.0);

            let (base, hip, kn, an) = if left {
                (P_LLEG, 8, 9, 10)
            } else {
                (P_RLEG, 11, 12, 13)
            };
            out[hip] = pelvis + r0 * self.hip_offset(left);
            let (rl, rk) = self.leg_rotations(&p[base..base + 4]);
            let rl = r0 * rl;
            let (lt, ls) = if left {
                (self.len(dim::L_THIGH), self.len(dim::L_SHIN))
            } else {
                (self.len(dim::R_THIGH), self.len(dim::R_SHIN))
            };
            out[kn] = out[hip] + rl * Vector3::new(0.0, -lt, 0.0);
            out[an] = out[kn] + rl * rk * Vector3::new(0.0, -ls, 0.0);
        }
    }

    /// Lumbar rotation (pelvis frame → chest frame).
    pub fn spine_rotation(&self, p: &[f64; N_POSE]) -> Matrix3<f64> {
        exp_so3(Vector3::new(p[P_SPINE], 0.0, p[P_SPINE + 1])) * rot_y(p[P_SPINE + 2])
    }

    /// Shoulder rotation (chest frame → upper-arm frame) and elbow rotation for arm parameters
    /// `a = [swing_y, swing_z, twist, flexion]`.
    pub fn arm_rotations(&self, left: bool, a: &[f64]) -> (Matrix3<f64>, Matrix3<f64>) {
        let sgn = if left { 1.0 } else { -1.0 };
        let swing = exp_so3(Vector3::new(0.0, a[0], a[1]));
        // The twist is about the rest axis ±x.
        let twist = rot_x(sgn * a[2]);
        (swing * twist, rot_y(-sgn * a[3]))
    }

    /// Hip rotation (pelvis frame → thigh frame) and knee rotation for leg parameters
    /// `l = [swing_x, swing_z, twist, flexion]`.
    pub fn leg_rotations(&self, l: &[f64]) -> (Matrix3<f64>, Matrix3<f64>) {
        let swing = exp_so3(Vector3::new(l[0], 0.0, l[1]));
        (swing * rot_y(l[2]), rot_x(l[3]))
    }

    /// Joint-limit violations of pose `p`, written into `out` ([`N_LIMITS`] non-negative values: spine swing
    /// and twist, neck swing, and per limb (L arm, R arm, L leg, R leg) swing, twist and hinge).
    /// Swing excesses are fractions of the cone radius, twist and hinge excesses radians.
    pub fn limit_violations(&self, p: &[f64; N_POSE], out: &mut [f64; N_LIMITS]) {
        out[0] = limits::SPINE.swing_excess(p[P_SPINE], p[P_SPINE + 1]);
        out[1] = limits::SPINE.twist_excess(p[P_SPINE + 2]);
        out[2] = limits::NECK.swing_excess(p[P_NECK], p[P_NECK + 1]);
        let mut k = 3;
        for (base, left) in [(P_LARM, true), (P_RARM, false)] {
            let m = if left { 1.0 } else { -1.0 };
            out[k] = limits::SHOULDER.swing_excess(m * p[base], m * p[base + 1]);
            out[k + 1] = limits::SHOULDER.twist_excess(m * p[base + 2]);
            out[k + 2] = hinge_excess(limits::ELBOW, p[base + 3]);
            k += 3;
        }
        for (base, left) in [(P_LLEG, true), (P_RLEG, false)] {
            let m = if left { 1.0 } else { -1.0 };
            out[k] = limits::HIP.swing_excess(p[base], m * p[base + 1]);
            out[k + 1] = limits::HIP.twist_excess(m * p[base + 2]);
            out[k + 2] = hinge_excess(limits::KNEE, p[base + 3]);
            k += 3;
        }
    }

    /// Total joint-limit violation (sum of [`Skeleton::limit_violations`]).
    pub fn limit_violation(&self, p: &[f64; N_POSE]) -> f64 {
        let mut v = [0.0; N_LIMITS];
        self.limit_violations(p, &mut v);
        v.iter().sum()
    }
}

/// The neutral pose of the joints below the root (standing, arms hanging slightly forward, elbows
/// a little bent): the mean of the isotropic [`super::PosePrior::neutral`] (the prior before the
/// learnt one) and where `prior::fit_to_joints` holds what mocap joints cannot show (the twist of a
/// straight limb). Root entries are unused.
pub const NEUTRAL: [f64; N_POSE] = {
    let mut n = [0.0; N_POSE];
    n[P_LARM + 1] = -1.3;
    n[P_LARM + 3] = 0.3;
    n[P_RARM + 1] = 1.3;
    n[P_RARM + 3] = 0.3;
    n
};

/// Forward-difference step of pose parameter `i` for the finite-difference Jacobians of the body
/// problems: 1e-3 mm for the root position, 1e-6 rad for every angle.
pub(crate) fn pose_fd_step(i: usize) -> f64 {
    if (P_ROOT_POS..P_ROOT_POS + 3).contains(&i) {
        1e-3
    } else {
        1e-6
    }
}

/// First pose parameter the prior applies to (everything after the root).
pub const P_PRIOR_START: usize = P_SPINE;

/// How far `t` lies outside `range`.
#[inline]
pub fn hinge_excess(range: (f64, f64), t: f64) -> f64 {
    (range.0 - t).max(0.0) + (t - range.1).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn skel() -> Skeleton {
        Skeleton::new(Dimensions::mean(Convention::Human36M), Convention::Human36M).unwrap()
    }

    #[test]
    fn forward_kinematics_keeps_bone_lengths_and_rest_pose_shape() {
        let s = skel();
        let mut p = [0.0; N_POSE];
        let mut x = [Vector3::zeros(); N_JOINTS];
        s.forward(&p, &mut x);
        // T-pose: left wrist far to the left (+x), ankles straight below the hips.
        assert!((x[4].x - x[2].x - 282.0 - 250.0).abs() < 1e-9);
        assert!((x[10].y - x[8].y + 452.0 + 447.0).abs() < 1e-9);
        // Random pose: bone lengths unchanged.
        for (i, v) in p.iter_mut().enumerate() {
            *v = ((i * 7919) % 13) as f64 * 0.17 - 1.0;
        }
        s.forward(&p, &mut x);
        let bone = |a: usize, b: usize| (x[a] - x[b]).norm();
        assert!((bone(3, 2) - 282.0).abs() < 1e-9);
        assert!((bone(4, 3) - 250.0).abs() < 1e-9);
        assert!((bone(7, 6) - 250.0).abs() < 1e-9);
        assert!((bone(9, 8) - 452.0).abs() < 1e-9);
        assert!((bone(13, 12) - 447.0).abs() < 1e-9);
        assert!((bone(1, 0) - 487.0).abs() < 1e-9);
        assert!((bone(14, 1) - 178.0).abs() < 1e-9);
    }

    #[test]
    fn hinges_bend_the_natural_way_and_limits_flag_the_other() {
        let s = skel();
        let mut p = [0.0; N_POSE];
        p[P_LARM + 3] = 1.2;
        p[P_RARM + 3] = 1.2;
        p[P_LLEG + 3] = 1.2;
        p[P_RLEG + 3] = 1.2;
        let mut x = [Vector3::zeros(); N_JOINTS];
        s.forward(&p, &mut x);
        // Elbows bring the wrists forward (+z), knees take the ankles backward (−z).
        assert!(x[4].z > 100.0 && x[7].z > 100.0);
        assert!(x[10].z < -100.0 && x[13].z < -100.0);
        assert_eq!(s.limit_violation(&p), 0.0);
        p[P_RLEG + 3] = -0.8;
        assert!(s.limit_violation(&p) > 0.5);
    }

    #[test]
    fn mirrored_poses_have_equal_limit_violations() {
        let s = skel();
        let mut l = [0.0; N_POSE];
        l[P_LARM] = -2.3;
        l[P_LARM + 1] = 1.9;
        l[P_LARM + 2] = 1.9;
        l[P_LLEG] = 0.8;
        l[P_LLEG + 1] = -0.9;
        l[P_LLEG + 2] = 1.2;
        let mut r = [0.0; N_POSE];
        r[P_RARM] = -l[P_LARM];
        r[P_RARM + 1] = -l[P_LARM + 1];
        r[P_RARM + 2] = -l[P_LARM + 2];
        r[P_RLEG] = l[P_LLEG];
        r[P_RLEG + 1] = -l[P_LLEG + 1];
        r[P_RLEG + 2] = -l[P_LLEG + 2];
        let (vl, vr) = (s.limit_violation(&l), s.limit_violation(&r));
        assert!(vl > 0.1 && (vl - vr).abs() < 1e-12, "{vl} {vr}");
        // And the joint positions mirror (x → −x).
        let (mut xl, mut xr) = ([Vector3::zeros(); N_JOINTS], [Vector3::zeros(); N_JOINTS]);
        s.forward(&l, &mut xl);
        s.forward(&r, &mut xr);
        for (a, b) in [(3, 6), (4, 7), (9, 12), (10, 13)] {
            let m = Vector3::new(-xl[a].x, xl[a].y, xl[a].z);
            assert!((m - xr[b]).norm() < 1e-9, "{a}: {m:?} vs {:?}", xr[b]);
        }
    }
}
