//! CLFBA — contextualised learning-free body adjustment (thesis chapter 5): 3D body pose and body
//! dimensions from 2D joints seen by one camera whose pose relative to the floor is known.
//!
//! The pipeline, per frame (see [`fit::BodyFitter`]):
//! 1. the camera: fully known ([`BodyCamera`]) or calibrated from four image points of a floor
//!    rectangle of known size ([`calib::calibrate_floor`]: DLT homography → focal length and
//!    extrinsics → Levenberg–Marquardt refinement);
//! 2. the central body (pelvis, thorax, shoulders, hips) placed by EPnP ([`epnp`]) on the torso
//!    template of the [`skeleton`];
//! 3. the limbs and head by viewpoint-dependent inverse kinematics ([`ik`]): each joint on its
//!    viewing ray at its segment's length from its parent, the two depth solutions chosen by the
//!    swing–twist joint limits and the floor; the lower foot's depth set by floor contact;
//! 4. a Levenberg–Marquardt refinement of all joint angles on the objective (reprojection error in
//!    px² plus joint-limit, floor and contact penalties expressed in pixels, and the learnt pose
//!    prior of [`prior`]).
//!
//! The kinematic model is the thesis' 21-joint, 54-DoF hierarchy ([`hanim`], with its posing
//! features); steps 2–4 work in its reduced form ([`skeleton`]: 15 joints, 27 DoF, the spine bending
//! at one joint, clavicles, pelvis girdle, wrists and ankles at rest), which it contains exactly, and
//! [`BodyFitConfig::full_model`] adds a refinement in all 54 DoF.
//!
//! Body dimensions are estimated once per sequence on its first frames
//! ([`fit::DimensionEstimator`]): DIRECT-L over the global scale, then COBYLA over the twelve
//! body-part lengths.
//!
//! Conventions: the world frame is the caller's (a floor calibration makes its own: origin at the
//! first corner, z up); the floor is the plane z = 0 of the world frame and z points up. Units are
//! millimetres; the camera maps a world point X to camera coordinates R·X + t (CONTRACT.md). The
//! body-local frame used by the kinematic model has x towards the subject's left, y up and z
//! forward (right-handed).

pub mod calib;
pub mod epnp;
pub mod fit;
pub mod hanim;
pub mod ik;
pub mod optim;
pub mod prior;
pub mod skeleton;

pub use calib::{BodyCamera, FloorCalibration, calibrate_floor};
pub use fit::{BodyFit, BodyFitConfig, BodyFitter, DimensionEstimate, DimensionEstimator};
pub use hanim::{FullSkeleton, HJoint};
pub use prior::PosePrior;
pub use skeleton::{Convention, Dimensions, Skeleton};

/// Number of joints in the output (the HumanEva-I 15-joint set).
pub const N_JOINTS: usize = 15;

/// The 15 joints, in the order of every `[_; N_JOINTS]` array of this module (VideoPose3D's
/// `humaneva15` order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(usize)]
pub enum Joint {
    /// Root of the skeleton, the pelvis.
    Pelvis = 0,
    /// Top of the spine (base of the neck).
    Thorax = 1,
    /// Left shoulder.
    LShoulder = 2,
    /// Left elbow.
    LElbow = 3,
    /// Left wrist.
    LWrist = 4,
    /// Right shoulder.
    RShoulder = 5,
    /// Right elbow.
    RElbow = 6,
    /// Right wrist.
    RWrist = 7,
    /// Left hip.
    LHip = 8,
    /// Left knee.
    LKnee = 9,
    /// Left ankle.
    LAnkle = 10,
    /// Right hip.
    RHip = 11,
    /// Right knee.
    RKnee = 12,
    /// Right ankle.
    RAnkle = 13,
    /// Head.
    Head = 14,
}

/// The CONTRACT.md joint names, in [`Joint`] order.
pub const JOINT_NAMES: [&str; N_JOINTS] = [
    "pelvis",
    "thorax",
    "lshoulder",
    "lelbow",
    "lwrist",
    "rshoulder",
    "relbow",
    "rwrist",
    "lhip",
    "lknee",
    "lankle",
    "rhip",
    "rknee",
    "rankle",
    "head",
];

/// Each joint's parent in the kinematic tree (`usize::MAX` for the root).
pub const PARENTS: [usize; N_JOINTS] = [usize::MAX, 0, 1, 2, 3, 1, 5, 6, 0, 8, 9, 0, 11, 12, 1];

impl Joint {
    /// All joints in order.
    pub const ALL: [Joint; N_JOINTS] = [
        Joint::Pelvis,
        Joint::Thorax,
        Joint::LShoulder,
        Joint::LElbow,
        Joint::LWrist,
        Joint::RShoulder,
        Joint::RElbow,
        Joint::RWrist,
        Joint::LHip,
        Joint::LKnee,
        Joint::LAnkle,
        Joint::RHip,
        Joint::RKnee,
        Joint::RAnkle,
        Joint::Head,
    ];

    /// The index into `[_; N_JOINTS]` arrays.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The CONTRACT.md name.
    pub fn name(self) -> &'static str {
        JOINT_NAMES[self as usize]
    }

    /// The joint with a CONTRACT.md name.
    pub fn from_name(name: &str) -> Option<Joint> {
        JOINT_NAMES
            .iter()
            .position(|n| *n == name)
            .map(|i| Joint::ALL[i])
    }
}

/// 2D joint observations of one frame: pixel positions (CONTRACT.md image convention) and a weight
/// per joint (0 = missing).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Joints2d {
    /// Pixel positions; ignored where the weight is 0.
    pub points: [[f64; 2]; N_JOINTS],
    /// Per-joint weights in [0, 1]; 0 marks a missing joint.
    pub weights: [f64; N_JOINTS],
}

impl Joints2d {
    /// All joints present with weight 1.
    pub fn full(points: [[f64; 2]; N_JOINTS]) -> Self {
        Self {
            points,
            weights: [1.0; N_JOINTS],
        }
    }

    /// Whether joint `j` is observed.
    pub fn has(&self, j: Joint) -> bool {
        self.weights[j.index()] > 0.0
    }

    /// Checks the observations are usable: weights finite in [0, 1], observed points finite, and the
    /// torso joints the EPnP step needs (both hips, both shoulders) present.
    ///
    /// # Errors
    /// [`crate::Error::InvalidInput`] naming the offending joint.
    pub fn validate(&self) -> crate::Result<()> {
        for j in Joint::ALL {
            let w = self.weights[j.index()];
            if !(w.is_finite() && (0.0..=1.0).contains(&w)) {
                return Err(crate::Error::InvalidInput(format!(
                    "joint {}: weight {w} outside [0, 1]",
                    j.name()
                )));
            }
            let p = self.points[j.index()];
            if w > 0.0 && !(p[0].is_finite() && p[1].is_finite()) {
                return Err(crate::Error::InvalidInput(format!(
                    "joint {}: non-finite position {p:?}",
                    j.name()
                )));
            }
        }
        for j in [Joint::LHip, Joint::RHip, Joint::LShoulder, Joint::RShoulder] {
            if !self.has(j) {
                return Err(crate::Error::InvalidInput(format!(
                    "joint {} is required (the torso is placed from both hips and both shoulders)",
                    j.name()
                )));
            }
        }
        Ok(())
    }
}
