//! The full kinematic model of thesis 5.1.2 (Fig. 5.3): an H-Anim-style hierarchy of 21 joints
//! with 54 degrees of freedom, its swing–twist limits, forward kinematics and the posing features
//! (the IK behaviours of the thesis: a limb's end-effector moves both segments, an elbow or knee
//! feature turns the limb about its root–end axis, a head feature bends the neck first and the
//! spine for the rest, a hip feature rotates the pelvis about the root).
//!
//! The hierarchy (H-Anim names; degrees of freedom in brackets):
//!
//! ```text
//! humanoid_root [6] ─┬─ sacroiliac [3] ─┬─ l_hip [3] ─ l_knee [1] ─ l_ankle [2] ─ (l_toe)
//!                    │                  └─ r_hip [3] ─ r_knee [1] ─ r_ankle [2] ─ (r_toe)
//!                    └─ vl5 [3] ─ vl1 [3] ─ vt6 [3] ─┬─ vc7 [3] ─ skullbase [3] ─ (head)
//!                                                    ├─ l_sternoclavicular [2] ─ l_shoulder [3]
//!                                                    │    ─ l_elbow [2] ─ l_wrist [2] ─ (l_hand)
//!                                                    └─ r_sternoclavicular [2] ─ … (right arm)
//! ```
//!
//! Three degrees of freedom per joint except: the root (6), the sternoclavicular joints (swing
//! only, no twist), the elbows (flexion and twist), the wrists (no twist), the knees (flexion
//! only) and the ankles (no twist: the foot's turn is the hip's). That is 6 + 3 + 2·(3 + 1 + 2) +
//! 5·3 + 2·(2 + 3 + 2 + 2) = 54. The body-part lengths are the twelve of [`Dimensions`]; the back
//! (root → vc7) and the neck (vc7 → head) are distributed over their segments in fixed shares
//! ([`BACK_SHARES`], [`NECK_SHARES`]); hands and feet are in fixed proportion to the forearm and
//! shin ([`HAND_RATIO`], [`FOOT_RATIO`]).
//!
//! The full pose vector is the reduced model's 27 parameters ([`super::skeleton`], same layout and
//! meaning) followed by 27 extra ones (`X_*`). With the extras at zero the full model's 15 output
//! joints are exactly the reduced model's ([`embed`]): the reduced model is the full one with the
//! spine bending at vl5 only, the neck at vc7 only, the clavicles, pelvis girdle, wrists and ankles
//! at rest. Conventions as in [`super::skeleton`]: body-local frame x left, y up, z forward; right
//! side parameters are the left side's mirrored (a mirror in the sagittal plane negates the limb
//! swing components about y and z and the limb twists), and limits are given for the left side.

use crate::math::Libm;
use nalgebra::{Matrix3, Rotation3, Vector3};

use nalgebra::SVector;

use super::ik;
use super::optim::{MAX_RESIDUALS, NumericLeastSquares, Residuals};
use super::skeleton::*;
use super::{Joint, N_JOINTS};
use crate::fit::solver::LevenbergMarquardt;

/// Number of joints of the full model.
pub const N_HJOINTS: usize = 21;
/// Number of full-model pose parameters.
pub const N_FULL_POSE: usize = 54;
/// Number of end sites (points without degrees of freedom at the end of a chain).
pub const N_END_SITES: usize = 5;
/// Number of joint-limit terms of the full model ([`FullSkeleton::limit_violations`]).
pub const N_FULL_LIMITS: usize = N_LIMITS + 17;

/// Pelvis girdle about the root (sacroiliac): swing about x and z, twist about y.
pub const X_SACROILIAC: usize = N_POSE;
/// Lumbar–thoracic junction (vl1): swing about x and z, twist about y.
pub const X_VL1: usize = N_POSE + 3;
/// Mid-thoracic (vt6): swing about x and z, twist about y.
pub const X_VT6: usize = N_POSE + 6;
/// Twist of the lower neck (vc7) about its axis (its swing is the reduced model's neck).
pub const X_VC7_TWIST: usize = N_POSE + 9;
/// Skull base: nod about x, tilt about z, turn about y.
pub const X_SKULLBASE: usize = N_POSE + 10;
/// Left sternoclavicular joint: swing about y (protraction −) and z (elevation +).
pub const X_LSC: usize = N_POSE + 13;
/// Right sternoclavicular joint (mirrored).
pub const X_RSC: usize = N_POSE + 15;
/// Left forearm twist (pronation / supination) about the forearm.
pub const X_LELBOW_TWIST: usize = N_POSE + 17;
/// Right forearm twist (mirrored).
pub const X_RELBOW_TWIST: usize = N_POSE + 18;
/// Left wrist: swing about y and z.
pub const X_LWRIST: usize = N_POSE + 19;
/// Right wrist (mirrored).
pub const X_RWRIST: usize = N_POSE + 21;
/// Left ankle: swing about x (plantar flexion −, toes down) and z (inversion).
pub const X_LANKLE: usize = N_POSE + 23;
/// Right ankle (mirrored).
pub const X_RANKLE: usize = N_POSE + 25;

/// The 21 joints, in the order of every `[_; N_HJOINTS]` array of this module.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(usize)]
#[allow(missing_docs)]
pub enum HJoint {
    HumanoidRoot = 0,
    Sacroiliac,
    LHip,
    LKnee,
    LAnkle,
    RHip,
    RKnee,
    RAnkle,
    Vl5,
    Vl1,
    Vt6,
    Vc7,
    Skullbase,
    LSternoclavicular,
    LShoulder,
    LElbow,
    LWrist,
    RSternoclavicular,
    RShoulder,
    RElbow,
    RWrist,
}

/// H-Anim names of the joints, in [`HJoint`] order.
pub const HJOINT_NAMES: [&str; N_HJOINTS] = [
    "humanoid_root",
    "sacroiliac",
    "l_hip",
    "l_knee",
    "l_ankle",
    "r_hip",
    "r_knee",
    "r_ankle",
    "vl5",
    "vl1",
    "vt6",
    "vc7",
    "skullbase",
    "l_sternoclavicular",
    "l_shoulder",
    "l_elbow",
    "l_wrist",
    "r_sternoclavicular",
    "r_shoulder",
    "r_elbow",
    "r_wrist",
];

/// Parent of each joint (`None` for the root).
pub const PARENT: [Option<usize>; N_HJOINTS] = [
    None,
    Some(0),
    Some(1),
    Some(2),
    Some(3),
    Some(1),
    Some(5),
    Some(6),
    Some(0),
    Some(8),
    Some(9),
    Some(10),
    Some(11),
    Some(10),
    Some(13),
    Some(14),
    Some(15),
    Some(10),
    Some(17),
    Some(18),
    Some(19),
];

/// Degrees of freedom of each joint (sum [`N_FULL_POSE`]).
pub const DOF: [usize; N_HJOINTS] = [
    6, 3, 3, 1, 2, 3, 1, 2, 3, 3, 3, 3, 3, 2, 3, 2, 2, 2, 3, 2, 2,
];

/// End sites, in the order of [`Posed::ends`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(usize)]
#[allow(missing_docs)]
pub enum EndSite {
    Head = 0,
    LHand,
    RHand,
    LToe,
    RToe,
}

/// Shares of the back length on the segments root → vl1, vl1 → vt6, vt6 → vc7: lumbar spine,
/// lower and upper thoracic spine at roughly their vertebral heights. They do not move the output
/// joints while vl1 and vt6 rest.
pub const BACK_SHARES: [f64; 3] = [0.35, 0.35, 0.30];
/// Shares of the neck length on vc7 → skullbase and skullbase → head point.
pub const NECK_SHARES: [f64; 2] = [0.35, 0.65];
/// The sternoclavicular joint sits this fraction of the way from the thorax to the shoulder.
pub const SC_FRACTION: f64 = 0.3;
/// Hand length (wrist → fingertip) per forearm length (Winter's segment tables: 0.108 vs 0.146 of
/// the stature).
pub const HAND_RATIO: f64 = 0.74;
/// How far the toes reach in front of the ankle per shin length (foot 0.152 of the stature with the
/// ankle about a quarter of it from the heel, shin 0.246).
pub const FOOT_RATIO: f64 = 0.46;

/// Ranges of motion of the extra joints (left side), from the same clinical tables as
/// [`limits`], widened alike.
pub mod full_limits {
    use super::SwingTwistLimit;
    const D: f64 = std::f64::consts::PI / 180.0;
    const fn deg(
        a_neg: f64,
        a_pos: f64,
        b_neg: f64,
        b_pos: f64,
        t0: f64,
        t1: f64,
    ) -> SwingTwistLimit {
        SwingTwistLimit {
            a_neg: a_neg * D,
            a_pos: a_pos * D,
            b_neg: b_neg * D,
            b_pos: b_pos * D,
            twist: (t0 * D, t1 * D),
        }
    }
    /// Pelvis girdle relative to the root: tilt, obliquity, rotation.
    pub const SACROILIAC: SwingTwistLimit = deg(15.0, 15.0, 12.0, 12.0, -15.0, 15.0);
    /// Each of the two thoracic segments (vl1, vt6).
    pub const THORACIC: SwingTwistLimit = deg(15.0, 25.0, 15.0, 15.0, -20.0, 20.0);
    /// Twist of the lower neck, radians.
    pub const VC7_TWIST: (f64, f64) = (-35.0 * D, 35.0 * D);
    /// Skull base: nod, tilt, and the atlanto-axial turn.
    pub const SKULLBASE: SwingTwistLimit = deg(20.0, 25.0, 10.0, 10.0, -50.0, 50.0);
    /// Sternoclavicular: a = swing about y (− protraction), b = swing about z (+ elevation).
    pub const STERNOCLAVICULAR: SwingTwistLimit = deg(25.0, 25.0, 10.0, 40.0, 0.0, 0.0);
    /// Forearm twist from the shoulder's, radians.
    pub const ELBOW_TWIST: (f64, f64) = (-90.0 * D, 90.0 * D);
    /// Wrist: a = swing about y, b = swing about z.
    pub const WRIST: SwingTwistLimit = deg(75.0, 80.0, 25.0, 35.0, 0.0, 0.0);
    /// Ankle: a = swing about x (− plantar flexion), b = swing about z (inversion / eversion).
    pub const ANKLE: SwingTwistLimit = deg(55.0, 25.0, 25.0, 25.0, 0.0, 0.0);
}

/// Standard deviations (radians) of the zero-mean prior on the 27 extra parameters, in `X_*`
/// order, used when fitting in the full model. The learnt prior covers the first 27 parameters
/// only: no training set here has the points that would show the extras (a clavicle, a vertebra,
/// a hand or toe), so they get a fixed Gaussian. Those that move an output joint (sacroiliac, vl1,
/// vt6, skull-base swings, clavicles) are tight (6–9°): the 15 joints can trade them for the
/// reduced model's own parameters, and the reduced parameters are the ones the data taught. Those
/// that move no output joint (twists about a segment's own axis, wrists, ankles) are loose: only
/// their limits and the floor (toes) decide them.
pub const EXTRA_PRIOR_STD: [f64; N_FULL_POSE - N_POSE] = [
    0.1, 0.1, 0.1, // sacroiliac
    0.1, 0.1, 0.1, // vl1
    0.1, 0.1, 0.1, // vt6
    0.5, // vc7 twist
    0.15, 0.15, 0.5, // skull base (nod, tilt, turn)
    0.1, 0.1, 0.1, 0.1, // clavicles
    0.5, 0.5, // forearm twists
    0.5, 0.5, 0.5, 0.5, // wrists
    0.3, 0.3, 0.3, 0.3, // ankles
];

/// Forward-kinematics output: joint positions (world, mm), each joint's frame (body-local axes of
/// the segments it moves → world) and the end sites.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Posed {
    /// Joint positions, [`HJoint`] order.
    pub joints: [Vector3<f64>; N_HJOINTS],
    /// Joint frames after the joint's own rotation.
    pub frames: [Matrix3<f64>; N_HJOINTS],
    /// End sites, [`EndSite`] order.
    pub ends: [Vector3<f64>; N_END_SITES],
}

impl Default for Posed {
    fn default() -> Self {
        Self {
            joints: [Vector3::zeros(); N_HJOINTS],
            frames: [Matrix3::identity(); N_HJOINTS],
            ends: [Vector3::zeros(); N_END_SITES],
        }
    }
}

impl Posed {
    /// The 15 output joints ([`Joint`] order): the thorax is vc7, the head the head end site.
    pub fn output_joints(&self) -> [Vector3<f64>; N_JOINTS] {
        let j = &self.joints;
        let mut o = [Vector3::zeros(); N_JOINTS];
        o[Joint::Pelvis.index()] = j[HJoint::HumanoidRoot as usize];
        o[Joint::Thorax.index()] = j[HJoint::Vc7 as usize];
        o[Joint::Head.index()] = self.ends[EndSite::Head as usize];
        for (out, h) in [
            (Joint::LShoulder, HJoint::LShoulder),
            (Joint::LElbow, HJoint::LElbow),
            (Joint::LWrist, HJoint::LWrist),
            (Joint::RShoulder, HJoint::RShoulder),
            (Joint::RElbow, HJoint::RElbow),
            (Joint::RWrist, HJoint::RWrist),
            (Joint::LHip, HJoint::LHip),
            (Joint::LKnee, HJoint::LKnee),
            (Joint::LAnkle, HJoint::LAnkle),
            (Joint::RHip, HJoint::RHip),
            (Joint::RKnee, HJoint::RKnee),
            (Joint::RAnkle, HJoint::RAnkle),
        ] {
            o[out.index()] = j[h as usize];
        }
        o
    }
}

/// The full pose of a reduced one: the same 27 parameters, the extras at rest.
pub fn embed(p: &[f64; N_POSE]) -> [f64; N_FULL_POSE] {
    let mut f = [0.0; N_FULL_POSE];
    f[..N_POSE].copy_from_slice(p);
    f
}

/// The reduced model's part of a full pose (exactly the reduced pose of the same output joints
/// when the extras rest).
pub fn reduced(p: &[f64; N_FULL_POSE]) -> [f64; N_POSE] {
    let mut r = [0.0; N_POSE];
    r.copy_from_slice(&p[..N_POSE]);
    r
}

/// Swing about x and z then twist about y, from `s[0..3]`.
#[inline]
fn swing_twist_y(s: &[f64]) -> Matrix3<f64> {
    exp_so3(Vector3::new(s[0], 0.0, s[1])) * rot_y(s[2])
}

/// A limb of the full model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(missing_docs)]
pub enum Limb {
    LArm,
    RArm,
    LLeg,
    RLeg,
}

struct LimbSpec {
    left: bool,
    arm: bool,
    base: usize,
    root: usize,
    mid: usize,
    end: usize,
    upper: usize,
    lower: usize,
}

impl Limb {
    fn spec(self) -> LimbSpec {
        let (left, arm) = match self {
            Self::LArm => (true, true),
            Self::RArm => (false, true),
            Self::LLeg => (true, false),
            Self::RLeg => (false, false),
        };
        let h = |j: HJoint| j as usize;
        match (left, arm) {
            (true, true) => LimbSpec {
                left,
                arm,
                base: P_LARM,
                root: h(HJoint::LShoulder),
                mid: h(HJoint::LElbow),
                end: h(HJoint::LWrist),
                upper: dim::L_UPPER_ARM,
                lower: dim::L_FOREARM,
            },
            (false, true) => LimbSpec {
                left,
                arm,
                base: P_RARM,
                root: h(HJoint::RShoulder),
                mid: h(HJoint::RElbow),
                end: h(HJoint::RWrist),
                upper: dim::R_UPPER_ARM,
                lower: dim::R_FOREARM,
            },
            (true, false) => LimbSpec {
                left,
                arm,
                base: P_LLEG,
                root: h(HJoint::LHip),
                mid: h(HJoint::LKnee),
                end: h(HJoint::LAnkle),
                upper: dim::L_THIGH,
                lower: dim::L_SHIN,
            },
            (false, false) => LimbSpec {
                left,
                arm,
                base: P_RLEG,
                root: h(HJoint::RHip),
                mid: h(HJoint::RKnee),
                end: h(HJoint::RAnkle),
                upper: dim::R_THIGH,
                lower: dim::R_SHIN,
            },
        }
    }
}

/// A swing–twist-about-y joint of the spine and neck chain (skull base first), for the head
/// feature.
#[derive(Clone, Copy)]
struct ChainJoint {
    /// Parameter indices of swing a (about x), swing b (about z), twist (about y).
    params: [usize; 3],
    swing: SwingTwistLimit,
    twist: (f64, f64),
}

const CHAIN: [ChainJoint; 5] = [
    ChainJoint {
        params: [X_SKULLBASE, X_SKULLBASE + 1, X_SKULLBASE + 2],
        swing: full_limits::SKULLBASE,
        twist: full_limits::SKULLBASE.twist,
    },
    ChainJoint {
        params: [P_NECK, P_NECK + 1, X_VC7_TWIST],
        swing: limits::NECK,
        twist: full_limits::VC7_TWIST,
    },
    ChainJoint {
        params: [X_VT6, X_VT6 + 1, X_VT6 + 2],
        swing: full_limits::THORACIC,
        twist: full_limits::THORACIC.twist,
    },
    ChainJoint {
        params: [X_VL1, X_VL1 + 1, X_VL1 + 2],
        swing: full_limits::THORACIC,
        twist: full_limits::THORACIC.twist,
    },
    ChainJoint {
        params: [P_SPINE, P_SPINE + 1, P_SPINE + 2],
        swing: limits::SPINE,
        twist: limits::SPINE.twist,
    },
];

/// The head feature bends the spine only when the neck leaves the head further than this from its
/// target, mm.
pub const HEAD_TOLERANCE_MM: f64 = 0.5;
/// Millimetres of residual per unit of limit excess in the head feature's solves (a full cone
/// radius or a radian): near-hard.
const HEAD_LIMIT_WEIGHT_MM: f64 = 1000.0;
/// Millimetres of residual per radian a joint moves in the head feature: a light pull that settles
/// the redundant directions (twists, how a bend is shared) on the least motion.
const HEAD_DAMPING_MM: f64 = 1.0;
const HEAD_LM: LevenbergMarquardt = LevenbergMarquardt {
    max_iterations: 100,
    cost_tolerance: 1e-12,
    step_tolerance: 1e-12,
    initial_lambda: 1e-3,
};

/// The head feature's least-squares problem over `N` chain parameters.
struct HeadProblem<'a, const N: usize> {
    fs: &'a FullSkeleton,
    pose: [f64; N_FULL_POSE],
    idx: [usize; N],
    chain: &'a [ChainJoint],
    target: Vector3<f64>,
    x0: SVector<f64, N>,
}

impl<const N: usize> Residuals<N> for HeadProblem<'_, N> {
    fn residuals(&self, x: &SVector<f64, N>, r: &mut [f64; MAX_RESIDUALS]) -> usize {
        let mut p = self.pose;
        for (k, &i) in self.idx.iter().enumerate() {
            p[i] = x[k];
        }
        let mut o = Posed::default();
        self.fs.forward(&p, &mut o);
        let d = o.ends[EndSite::Head as usize] - self.target;
        r[..3].copy_from_slice(d.as_slice());
        let mut k = 3;
        for cj in self.chain {
            let [ia, ib, it] = cj.params;
            r[k] = HEAD_LIMIT_WEIGHT_MM * cj.swing.swing_excess(p[ia], p[ib]);
            r[k + 1] = HEAD_LIMIT_WEIGHT_MM * hinge_excess(cj.twist, p[it]);
            k += 2;
        }
        for i in 0..N {
            r[k] = HEAD_DAMPING_MM * (x[i] - self.x0[i]);
            k += 1;
        }
        k
    }

    fn step(&self, _: usize) -> f64 {
        1e-7
    }
}

/// The full model of one body: a [`Skeleton`] (dimensions and convention) seen as 21 joints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FullSkeleton {
    /// The reduced skeleton it extends (dimensions, convention, torso offsets).
    pub base: Skeleton,
}

impl FullSkeleton {
    /// The full model of `base`.
    pub fn new(base: Skeleton) -> Self {
        Self { base }
    }

    /// Forward kinematics of full pose `p` into `o`.
    pub fn forward(&self, p: &[f64; N_FULL_POSE], o: &mut Posed) {
        use HJoint as H;
        let b = &self.base;
        let v3 = |i: usize| Vector3::new(p[i], p[i + 1], p[i + 2]);
        let up = |l: f64| Vector3::new(0.0, l, 0.0);
        let r0 = exp_so3(v3(P_ROOT_ROT));
        let root = v3(P_ROOT_POS);
        o.joints[H::HumanoidRoot as usize] = root;
        o.frames[H::HumanoidRoot as usize] = r0;

        // Pelvis girdle and legs.
        let girdle = r0 * swing_twist_y(&p[X_SACROILIAC..]);
        o.joints[H::Sacroiliac as usize] = root;
        o.frames[H::Sacroiliac as usize] = girdle;
        for limb in [Limb::LLeg, Limb::RLeg] {
            let s = limb.spec();
            let (xa, toe) = if s.left {
                (X_LANKLE, EndSite::LToe)
            } else {
                (X_RANKLE, EndSite::RToe)
            };
            o.joints[s.root] = root + girdle * b.hip_offset(s.left);
            let (rl, rk) = b.leg_rotations(&p[s.base..s.base + 4]);
            let thigh = girdle * rl;
            let shin = thigh * rk;
            let foot = shin * exp_so3(Vector3::new(p[xa], 0.0, p[xa + 1]));
            let ls = b.len(s.lower);
            o.joints[s.mid] = o.joints[s.root] + thigh * up(-b.len(s.upper));
            o.joints[s.end] = o.joints[s.mid] + shin * up(-ls);
            o.frames[s.root] = thigh;
            o.frames[s.mid] = shin;
            o.frames[s.end] = foot;
            o.ends[toe as usize] =
                o.joints[s.end] + foot * Vector3::new(0.0, -b.ankle_height, FOOT_RATIO * ls);
        }

        // Spine, neck, head.
        let back = b.len(dim::BACK);
        let r_vl5 = r0 * swing_twist_y(&p[P_SPINE..]);
        let r_vl1 = r_vl5 * swing_twist_y(&p[X_VL1..]);
        let chest = r_vl1 * swing_twist_y(&p[X_VT6..]);
        o.joints[H::Vl5 as usize] = root;
        o.joints[H::Vl1 as usize] = root + r_vl5 * up(BACK_SHARES[0] * back);
        o.joints[H::Vt6 as usize] = o.joints[H::Vl1 as usize] + r_vl1 * up(BACK_SHARES[1] * back);
        o.joints[H::Vc7 as usize] = o.joints[H::Vt6 as usize] + chest * up(BACK_SHARES[2] * back);
        o.frames[H::Vl5 as usize] = r_vl5;
        o.frames[H::Vl1 as usize] = r_vl1;
        o.frames[H::Vt6 as usize] = chest;
        let neck = b.len(dim::NECK);
        let r_neck =
            chest * exp_so3(Vector3::new(p[P_NECK], 0.0, p[P_NECK + 1])) * rot_y(p[X_VC7_TWIST]);
        let r_head = r_neck * swing_twist_y(&p[X_SKULLBASE..]);
        o.frames[H::Vc7 as usize] = r_neck;
        o.frames[H::Skullbase as usize] = r_head;
        o.joints[H::Skullbase as usize] =
            o.joints[H::Vc7 as usize] + r_neck * up(NECK_SHARES[0] * neck);
        o.ends[EndSite::Head as usize] =
            o.joints[H::Skullbase as usize] + r_head * up(NECK_SHARES[1] * neck);

        // Clavicles and arms.
        let thorax = o.joints[H::Vc7 as usize];
        for limb in [Limb::LArm, Limb::RArm] {
            let s = limb.spec();
            let sgn = if s.left { 1.0 } else { -1.0 };
            let (sc, xsc, xt, xw, hand) = if s.left {
                (
                    H::LSternoclavicular,
                    X_LSC,
                    X_LELBOW_TWIST,
                    X_LWRIST,
                    EndSite::LHand,
                )
            } else {
                (
                    H::RSternoclavicular,
                    X_RSC,
                    X_RELBOW_TWIST,
                    X_RWRIST,
                    EndSite::RHand,
                )
            };
            let off = b.shoulder_offset(s.left);
            let clavicle = chest * exp_so3(Vector3::new(0.0, p[xsc], p[xsc + 1]));
            o.joints[sc as usize] =
                thorax + chest * Vector3::new(SC_FRACTION * off.x, off.y, off.z);
            o.frames[sc as usize] = clavicle;
            o.joints[s.root] = o.joints[sc as usize]
                + clavicle * Vector3::new((1.0 - SC_FRACTION) * off.x, 0.0, 0.0);
            let (ra, re) = b.arm_rotations(s.left, &p[s.base..s.base + 4]);
            let upper = clavicle * ra;
            let fore = upper * re * rot_x(sgn * p[xt]);
            let palm = fore * exp_so3(Vector3::new(0.0, p[xw], p[xw + 1]));
            let lf = b.len(s.lower);
            o.joints[s.mid] =
                o.joints[s.root] + upper * Vector3::new(sgn * b.len(s.upper), 0.0, 0.0);
            o.joints[s.end] = o.joints[s.mid] + fore * Vector3::new(sgn * lf, 0.0, 0.0);
            o.frames[s.root] = upper;
            o.frames[s.mid] = fore;
            o.frames[s.end] = palm;
            o.ends[hand as usize] =
                o.joints[s.end] + palm * Vector3::new(sgn * HAND_RATIO * lf, 0.0, 0.0);
        }
    }

    /// Joint-limit violations of full pose `p` ([`N_FULL_LIMITS`] non-negative values): the reduced
    /// model's [`N_LIMITS`], then sacroiliac swing and twist, vl1 and vt6 swing and twist, vc7
    /// twist, skull-base swing and twist, the clavicles' swings, the forearm twists, the wrists'
    /// and the ankles' swings (left before right). Units as in [`Skeleton::limit_violations`].
    pub fn limit_violations(&self, p: &[f64; N_FULL_POSE], out: &mut [f64; N_FULL_LIMITS]) {
        use full_limits as fl;
        let mut base = [0.0; N_LIMITS];
        self.base.limit_violations(&reduced(p), &mut base);
        out[..N_LIMITS].copy_from_slice(&base);
        let mut k = N_LIMITS;
        let mut push = |v: f64| {
            out[k] = v;
            k += 1;
        };
        for (x, lim) in [
            (X_SACROILIAC, fl::SACROILIAC),
            (X_VL1, fl::THORACIC),
            (X_VT6, fl::THORACIC),
        ] {
            push(lim.swing_excess(p[x], p[x + 1]));
            push(lim.twist_excess(p[x + 2]));
        }
        push(hinge_excess(fl::VC7_TWIST, p[X_VC7_TWIST]));
        push(fl::SKULLBASE.swing_excess(p[X_SKULLBASE], p[X_SKULLBASE + 1]));
        push(fl::SKULLBASE.twist_excess(p[X_SKULLBASE + 2]));
        for (x, m) in [(X_LSC, 1.0), (X_RSC, -1.0)] {
            push(fl::STERNOCLAVICULAR.swing_excess(m * p[x], m * p[x + 1]));
        }
        for (x, m) in [(X_LELBOW_TWIST, 1.0), (X_RELBOW_TWIST, -1.0)] {
            push(hinge_excess(fl::ELBOW_TWIST, m * p[x]));
        }
        for (x, m) in [(X_LWRIST, 1.0), (X_RWRIST, -1.0)] {
            push(fl::WRIST.swing_excess(m * p[x], m * p[x + 1]));
        }
        for (x, m) in [(X_LANKLE, 1.0), (X_RANKLE, -1.0)] {
            push(fl::ANKLE.swing_excess(p[x], m * p[x + 1]));
        }
        debug_assert_eq!(k, N_FULL_LIMITS);
    }

    /// Total joint-limit violation (sum of [`FullSkeleton::limit_violations`]).
    pub fn limit_violation(&self, p: &[f64; N_FULL_POSE]) -> f64 {
        let mut v = [0.0; N_FULL_LIMITS];
        self.limit_violations(p, &mut v);
        v.iter().sum()
    }

    /// End-effector feature: the limb's root stays, both its segments move so its end (wrist or
    /// ankle) reaches `target` — straight towards it when out of reach — and the limb keeps its
    /// swivel (the middle joint goes to the point of its possible circle nearest where it was).
    /// Returns the distance left between end and target, mm.
    pub fn reach(&self, p: &mut [f64; N_FULL_POSE], limb: Limb, target: &Vector3<f64>) -> f64 {
        let mut o = Posed::default();
        self.forward(p, &mut o);
        let mid = o.joints[limb.spec().mid];
        self.place_limb(p, &o, limb, target, &mid)
    }

    /// Intermediate-joint feature (elbow or knee): the limb turns about its root–end axis so that
    /// the middle joint comes as close to `target` as the segment lengths allow; root and end stay.
    pub fn swivel(&self, p: &mut [f64; N_FULL_POSE], limb: Limb, target: &Vector3<f64>) {
        let mut o = Posed::default();
        self.forward(p, &mut o);
        let end = o.joints[limb.spec().end];
        self.place_limb(p, &o, limb, &end, target);
    }

    /// Places a limb's end at `end` (or as near as its lengths allow) with its middle joint at the
    /// point of the possible circle nearest `mid_hint`; returns the end's remaining distance. `o`
    /// is `p` posed.
    fn place_limb(
        &self,
        p: &mut [f64; N_FULL_POSE],
        o: &Posed,
        limb: Limb,
        end: &Vector3<f64>,
        mid_hint: &Vector3<f64>,
    ) -> f64 {
        let s = limb.spec();
        let a = o.joints[s.root];
        let parent = o.frames[PARENT[s.root].unwrap_or(0)];
        let (r1, r2) = (self.base.len(s.upper), self.base.len(s.lower));
        let ab = end - a;
        let d = ab.norm();
        if d < 1e-9 {
            return 0.0;
        }
        let (m, e) = match ik::sphere_circle(&a, r1, end, r2) {
            // Out of reach (or too close): straight towards the target.
            None => {
                let n = ab / d;
                (a + n * r1, a + n * (r1 + r2))
            }
            Some((c, n, h)) => {
                let m = ik::circle_point_nearest(&c, &n, h, mid_hint)
                    // The hint is on the axis: keep the current bend direction.
                    .or_else(|| ik::circle_point_nearest(&c, &n, h, &o.joints[s.mid]))
                    .unwrap_or_else(|| {
                        let mut v = n.cross(&Vector3::z());
                        if v.norm() < 1e-9 {
                            v = n.cross(&Vector3::x());
                        }
                        c + v.normalize() * h
                    });
                (m, *end)
            }
        };
        let q = ik::limb_angles(s.left, s.arm, &parent, &(m - a), &(e - m));
        p[s.base..s.base + 4].copy_from_slice(&q);
        (e - end).norm()
    }

    /// Head feature: moves the head point towards `target` by bending the neck (vc7, skull base)
    /// within its limits, and the spine (vt6, vl1, vl5) only for what the neck cannot do. Each
    /// stage is a small Levenberg–Marquardt solve (head position, limit excesses, a light pull to
    /// where the joints were), then every joint is clamped onto its limits. Returns the distance
    /// left, mm.
    pub fn move_head(&self, p: &mut [f64; N_FULL_POSE], target: &Vector3<f64>) -> f64 {
        let left = self.head_stage::<6>(p, &CHAIN[..2], target);
        if left < HEAD_TOLERANCE_MM {
            return left;
        }
        self.head_stage::<15>(p, &CHAIN, target)
    }

    fn head_stage<const N: usize>(
        &self,
        p: &mut [f64; N_FULL_POSE],
        chain: &[ChainJoint],
        target: &Vector3<f64>,
    ) -> f64 {
        let mut idx = [0usize; N];
        for (k, i) in chain.iter().flat_map(|c| c.params).enumerate() {
            idx[k] = i;
        }
        let x0 = SVector::<f64, N>::from_fn(|k, _| p[idx[k]]);
        let problem = HeadProblem {
            fs: self,
            pose: *p,
            idx,
            chain,
            target: *target,
            x0,
        };
        let mut x = x0;
        HEAD_LM.minimize(&NumericLeastSquares(&problem), &mut x);
        for (k, &i) in idx.iter().enumerate() {
            p[i] = x[k];
        }
        for cj in chain {
            let [ia, ib, it] = cj.params;
            (p[ia], p[ib]) = cj.swing.clamp_swing(p[ia], p[ib]);
            p[it] = p[it].clamp(cj.twist.0, cj.twist.1);
        }
        let mut o = Posed::default();
        self.forward(p, &mut o);
        (o.ends[EndSite::Head as usize] - target).norm()
    }

    /// Hip feature: rotates the pelvis girdle (sacroiliac) about the root so that the hip joint
    /// points from the root towards `target`, within the girdle's limits; the legs follow, the root
    /// and the upper body stay. Returns the hip's distance from the target, mm.
    pub fn move_hip(&self, p: &mut [f64; N_FULL_POSE], left: bool, target: &Vector3<f64>) -> f64 {
        let hip = if left { HJoint::LHip } else { HJoint::RHip } as usize;
        let mut o = Posed::default();
        self.forward(p, &mut o);
        let root = o.joints[0];
        if let Some(delta) = Rotation3::rotation_between(&(o.joints[hip] - root), &(target - root))
        {
            let girdle = HJoint::Sacroiliac as usize;
            let local = o.frames[0].transpose() * delta.into_inner() * o.frames[girdle];
            let params = [X_SACROILIAC, X_SACROILIAC + 1, X_SACROILIAC + 2];
            let lim = full_limits::SACROILIAC;
            set_swing_twist_y(p, &params, &local, &lim, lim.twist);
        }
        self.forward(p, &mut o);
        (o.joints[hip] - target).norm()
    }
}

/// Writes the swing (about x, z) – twist (about y) parameters of rotation `local` into `params`,
/// the swing scaled back onto its limit cone and the twist clamped to its interval.
fn set_swing_twist_y(
    p: &mut [f64; N_FULL_POSE],
    params: &[usize; 3],
    local: &Matrix3<f64>,
    swing_limit: &SwingTwistLimit,
    twist: (f64, f64),
) {
    let y = Vector3::y();
    let sw = ik::swing_between(&y, &(local * y).normalize());
    let t_m = exp_so3(sw).transpose() * local;
    (p[params[0]], p[params[1]]) = swing_limit.clamp_swing(sw.x, sw.z);
    p[params[2]] = t_m[(0, 2)].matan2(t_m[(0, 0)]).clamp(twist.0, twist.1);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn full(conv: Convention) -> FullSkeleton {
        FullSkeleton::new(Skeleton::new(Dimensions::mean(conv), conv).unwrap())
    }

    /// A pose well inside the limits with every parameter moved.
    fn sample_pose() -> [f64; N_FULL_POSE] {
        let mut p = [0.0; N_FULL_POSE];
        p[P_ROOT_ROT..P_ROOT_ROT + 3].copy_from_slice(&[0.3, -1.1, 0.2]);
        p[P_ROOT_POS..P_ROOT_POS + 3].copy_from_slice(&[100.0, -200.0, 950.0]);
        p[P_SPINE..P_SPINE + 3].copy_from_slice(&[0.3, 0.1, 0.2]);
        p[P_NECK..P_NECK + 2].copy_from_slice(&[0.2, -0.1]);
        p[P_LARM..P_LARM + 4].copy_from_slice(&[-0.5, -0.9, 0.4, 1.0]);
        p[P_RARM..P_RARM + 4].copy_from_slice(&[0.7, 1.2, -0.3, 0.6]);
        p[P_LLEG..P_LLEG + 4].copy_from_slice(&[-0.6, 0.2, 0.3, 0.9]);
        p[P_RLEG..P_RLEG + 4].copy_from_slice(&[0.2, -0.1, -0.2, 0.4]);
        for (i, v) in p[N_POSE..].iter_mut().enumerate() {
            // Small, mixed signs, inside every extra limit (the tightest cone is 10°).
            *v = 0.12 * (((i * 7) % 5) as f64 - 2.0) / 2.0;
        }
        p
    }

    #[test]
    fn the_hierarchy_has_21_joints_and_54_degrees_of_freedom() {
        assert_eq!(DOF.iter().sum::<usize>(), N_FULL_POSE);
        assert_eq!(X_RANKLE + 2, N_FULL_POSE);
        // Parents come before their children, so one forward pass in index order suffices.
        for (j, p) in PARENT.iter().enumerate().skip(1) {
            assert!(p.unwrap() < j, "{}", HJOINT_NAMES[j]);
        }
        assert_eq!(PARENT[0], None);
    }

    #[test]
    fn embedding_reproduces_the_reduced_model_exactly() {
        for conv in [Convention::HumanEva, Convention::Human36M] {
            let fs = full(conv);
            let p = reduced(&sample_pose());
            let mut want = [Vector3::zeros(); N_JOINTS];
            fs.base.forward(&p, &mut want);
            let mut o = Posed::default();
            fs.forward(&embed(&p), &mut o);
            let got = o.output_joints();
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).norm() < 1e-9, "{g:?} vs {w:?}");
            }
        }
    }

    #[test]
    fn segments_keep_their_lengths_and_extras_move_what_they_should() {
        let fs = full(Convention::HumanEva);
        let p0 = sample_pose();
        let (mut a, mut b) = (Posed::default(), Posed::default());
        fs.forward(&embed(&reduced(&p0)), &mut a);
        fs.forward(&p0, &mut b);
        // Every joint-to-parent distance is the same with and without the extras.
        for (j, parent) in PARENT.iter().enumerate().skip(1) {
            let pj = parent.unwrap();
            let la = (a.joints[j] - a.joints[pj]).norm();
            let lb = (b.joints[j] - b.joints[pj]).norm();
            assert!((la - lb).abs() < 1e-9, "{}: {la} vs {lb}", HJOINT_NAMES[j]);
        }
        // The back and neck are the dimension lengths when straight.
        let mut rest = [0.0; N_FULL_POSE];
        fs.forward(&rest, &mut a);
        let back = (a.joints[HJoint::Vc7 as usize] - a.joints[0]).norm();
        let neck = (a.ends[EndSite::Head as usize] - a.joints[HJoint::Vc7 as usize]).norm();
        assert!((back - fs.base.len(dim::BACK)).abs() < 1e-9);
        assert!((neck - fs.base.len(dim::NECK)).abs() < 1e-9);
        // The sacroiliac moves the hips and not the shoulders; a clavicle its shoulder only.
        rest[X_SACROILIAC + 1] = 0.15;
        fs.forward(&rest, &mut b);
        assert!((b.joints[HJoint::LHip as usize] - a.joints[HJoint::LHip as usize]).norm() > 1.0);
        assert!(
            (b.joints[HJoint::LShoulder as usize] - a.joints[HJoint::LShoulder as usize]).norm()
                < 1e-9
        );
        rest[X_SACROILIAC + 1] = 0.0;
        rest[X_LSC + 1] = 0.3;
        fs.forward(&rest, &mut b);
        let lsh = HJoint::LShoulder as usize;
        // Elevation raises the shoulder.
        assert!(b.joints[lsh].y - a.joints[lsh].y > 10.0);
        assert!(
            (b.joints[HJoint::RShoulder as usize] - a.joints[HJoint::RShoulder as usize]).norm()
                < 1e-9
        );
    }

    #[test]
    fn limits_are_zero_inside_and_mirror_left_to_right() {
        let fs = full(Convention::HumanEva);
        assert_eq!(fs.limit_violation(&sample_pose()), 0.0);
        // A left side and its mirror image.
        let mut l = [0.0; N_FULL_POSE];
        l[P_LARM..P_LARM + 4].copy_from_slice(&[-0.4, -0.8, 0.5, 0.9]);
        l[P_LLEG..P_LLEG + 4].copy_from_slice(&[-0.7, 0.3, 0.2, 0.6]);
        l[X_LSC] = -0.6;
        l[X_LSC + 1] = 0.9;
        l[X_LELBOW_TWIST] = 1.9;
        l[X_LWRIST] = 0.5;
        l[X_LWRIST + 1] = 0.8;
        l[X_LANKLE] = -1.2;
        l[X_LANKLE + 1] = 0.3;
        let mut r = [0.0; N_FULL_POSE];
        for i in 0..3 {
            r[P_RARM + i] = -l[P_LARM + i];
        }
        r[P_RARM + 3] = l[P_LARM + 3];
        r[P_RLEG] = l[P_LLEG];
        r[P_RLEG + 1] = -l[P_LLEG + 1];
        r[P_RLEG + 2] = -l[P_LLEG + 2];
        r[P_RLEG + 3] = l[P_LLEG + 3];
        r[X_RSC] = -l[X_LSC];
        r[X_RSC + 1] = -l[X_LSC + 1];
        r[X_RELBOW_TWIST] = -l[X_LELBOW_TWIST];
        r[X_RWRIST] = -l[X_LWRIST];
        r[X_RWRIST + 1] = -l[X_LWRIST + 1];
        r[X_RANKLE] = l[X_LANKLE];
        r[X_RANKLE + 1] = -l[X_LANKLE + 1];
        let (vl, vr) = (fs.limit_violation(&l), fs.limit_violation(&r));
        assert!(vl > 0.5 && (vl - vr).abs() < 1e-12, "{vl} {vr}");
        let (mut a, mut b) = (Posed::default(), Posed::default());
        fs.forward(&l, &mut a);
        fs.forward(&r, &mut b);
        let mirror = |v: Vector3<f64>| Vector3::new(-v.x, v.y, v.z);
        for (x, y) in [
            (
                a.joints[HJoint::LShoulder as usize],
                b.joints[HJoint::RShoulder as usize],
            ),
            (
                a.joints[HJoint::LWrist as usize],
                b.joints[HJoint::RWrist as usize],
            ),
            (
                a.ends[EndSite::LHand as usize],
                b.ends[EndSite::RHand as usize],
            ),
            (
                a.joints[HJoint::LAnkle as usize],
                b.joints[HJoint::RAnkle as usize],
            ),
            (
                a.ends[EndSite::LToe as usize],
                b.ends[EndSite::RToe as usize],
            ),
        ] {
            assert!((mirror(x) - y).norm() < 1e-9, "{x:?} vs {y:?}");
        }
    }

    #[test]
    fn end_effector_feature_moves_both_segments_and_keeps_the_swivel() {
        let fs = full(Convention::HumanEva);
        for limb in [Limb::LArm, Limb::RArm, Limb::LLeg, Limb::RLeg] {
            let s = limb.spec();
            let mut p = sample_pose();
            let mut o = Posed::default();
            fs.forward(&p, &mut o);
            let (root, mid0, end0) = (o.joints[s.root], o.joints[s.mid], o.joints[s.end]);
            let target = root + (end0 - root) * 0.9 + Vector3::new(20.0, -20.0, 20.0);
            let left = fs.reach(&mut p, limb, &target);
            fs.forward(&p, &mut o);
            assert!(left < 1e-6, "{limb:?}: {left}");
            assert!((o.joints[s.end] - target).norm() < 1e-6);
            assert!((o.joints[s.root] - root).norm() < 1e-9);
            // Both segments moved, and the elbow / knee stayed on the side it was.
            assert!((o.joints[s.mid] - mid0).norm() > 1.0);
            assert!((o.joints[s.mid] - mid0).norm() < 100.0, "{limb:?}");
            // Out of reach: straight towards it.
            let far = root + (target - root).normalize() * 5000.0;
            let left = fs.reach(&mut p, limb, &far);
            let reach = fs.base.len(s.upper) + fs.base.len(s.lower);
            assert!((left - (5000.0 - reach)).abs() < 1e-6, "{left}");
        }
    }

    #[test]
    fn elbow_and_knee_features_turn_the_limb_about_its_root_end_axis() {
        let fs = full(Convention::HumanEva);
        for limb in [Limb::LArm, Limb::LLeg, Limb::RArm, Limb::RLeg] {
            let s = limb.spec();
            let mut p = sample_pose();
            let mut o = Posed::default();
            fs.forward(&p, &mut o);
            let (root, mid0, end0) = (o.joints[s.root], o.joints[s.mid], o.joints[s.end]);
            let target = mid0 + Vector3::new(0.0, 0.0, 300.0);
            fs.swivel(&mut p, limb, &target);
            fs.forward(&p, &mut o);
            assert!((o.joints[s.root] - root).norm() < 1e-9);
            assert!((o.joints[s.end] - end0).norm() < 1e-6, "{limb:?}");
            let (d0, d1) = ((mid0 - target).norm(), (o.joints[s.mid] - target).norm());
            assert!(d1 < d0 - 10.0, "{limb:?}: {d0} → {d1}");
            // The middle joint is the circle point nearest the target: no other swivel is nearer.
            let axis = (end0 - root).normalize();
            for k in [-0.2, 0.2] {
                let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), k);
                let m = root + r * (o.joints[s.mid] - root);
                assert!((m - target).norm() >= d1 - 1e-9);
            }
        }
    }

    #[test]
    fn head_feature_prefers_the_neck_and_bends_the_spine_for_the_rest() {
        let fs = full(Convention::HumanEva);
        let spine = [
            P_SPINE,
            P_SPINE + 1,
            P_SPINE + 2,
            X_VL1,
            X_VL1 + 1,
            X_VL1 + 2,
            X_VT6,
            X_VT6 + 1,
            X_VT6 + 2,
        ];
        let mut p = [0.0; N_FULL_POSE];
        p[P_ROOT_POS + 1] = 1000.0;
        let mut o = Posed::default();
        fs.forward(&p, &mut o);
        let head0 = o.ends[EndSite::Head as usize];
        // A nod forward (where a 14° lower-neck and an 11° skull-base flexion put the head): the
        // neck alone does it.
        let mut nod = p;
        nod[P_NECK] = 0.25;
        nod[X_SKULLBASE] = 0.2;
        fs.forward(&nod, &mut o);
        let near = o.ends[EndSite::Head as usize];
        assert!((near - head0).norm() > 50.0);
        let left = fs.move_head(&mut p, &near);
        assert!(left < HEAD_TOLERANCE_MM, "{left}");
        assert!(spine.iter().all(|&i| p[i] == 0.0));
        assert_eq!(fs.limit_violation(&p), 0.0);
        // Head down to the hips' height in front: the spine must bend, within its limits.
        let mut q = [0.0; N_FULL_POSE];
        q[P_ROOT_POS + 1] = 1000.0;
        let far = o.joints[0] + Vector3::new(0.0, -50.0, 700.0);
        let left = fs.move_head(&mut q, &far);
        assert!(spine.iter().any(|&i| q[i].abs() > 0.1));
        assert!(fs.limit_violation(&q) < 1e-9, "{}", fs.limit_violation(&q));
        let mut neck_only = [0.0; N_FULL_POSE];
        neck_only[P_ROOT_POS + 1] = 1000.0;
        let neck_left = fs.head_stage::<6>(&mut neck_only, &CHAIN[..2], &far);
        assert!(left < neck_left - 100.0, "{left} vs neck only {neck_left}");
    }

    #[test]
    fn hip_feature_rotates_the_pelvis_about_the_root() {
        let fs = full(Convention::Human36M);
        let mut p = sample_pose();
        let mut a = Posed::default();
        fs.forward(&p, &mut a);
        let lhip = HJoint::LHip as usize;
        let up = a.frames[0] * Vector3::y();
        let target = a.joints[lhip] + up * 40.0;
        let d0 = (a.joints[lhip] - target).norm();
        let left = fs.move_hip(&mut p, true, &target);
        let mut b = Posed::default();
        fs.forward(&p, &mut b);
        assert!(left < d0 - 20.0, "{d0} → {left}");
        assert!((b.joints[0] - a.joints[0]).norm() < 1e-9);
        for j in [HJoint::Vc7, HJoint::LShoulder, HJoint::RWrist] {
            assert!((b.joints[j as usize] - a.joints[j as usize]).norm() < 1e-9);
        }
        // The other hip drops: the girdle turned about the root.
        let rhip = HJoint::RHip as usize;
        assert!((b.joints[rhip] - a.joints[rhip]).dot(&up) < -10.0);
        assert!(fs.limit_violation(&p) < 1e-12);
    }
}
