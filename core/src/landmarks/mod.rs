//! Landmarks: M3, the multi-level, multi-task landmark and gesture networks (thesis section 3.3).
//!
//! Level 1 runs on the face crop and gives 32 landmarks, a 5-class head yaw and a face confidence;
//! level-2 zone networks (brows, eye — one model, the left eye mirrored — and mouth, plus this
//! project's face zone for the jaw and nose, nose zone for the nose alone on the face zone's
//! nostril corners and `mouth_fine` zone for the lips on the mouth zone's corners) run on
//! similarity-normalised patches plus the level-1 yaw and give their zone's landmarks, gestures
//! and gaze; the two are merged into the 68-point iBUG order (the face zone's points averaged
//! with level 1's, `level1_weight`, and the
//! `mouth_fine` zone's with the mouth zone's, `prior_weight`; a zone running later replaces an
//! earlier one's points), and the merged points carry the annotations' x offset (`x_offset_iod`,
//! which training on mirrored faces hides from the nets). The preprocessing contract shared with
//! the training scripts is `models/M3_IO.md`.
//!
//! [`M3`] holds the seven networks (embedded with `include_bytes!`, optimised once by tract when it
//! is built) and every buffer one face needs, so [`M3::estimate`] allocates nothing after its first
//! call beyond the per-run output tensors tract itself creates. Preprocessing lives in [`warp`]
//! (affine crop/patch sampling) and [`filter`] (bilateral filter, histogram equalisation); each
//! network's one-channel first layer runs outside tract (`crate::nn::stem`, found in the graph at load).
//! One face = one call; run one `M3` per thread (it is `Send`).

pub mod eyes;
pub mod filter;
pub mod gradient;
mod m3;
mod prior;
pub mod warp;

pub use gradient::{
    GRADIENT_NAMES, GRADIENT_TO_68, GradientConfig, GradientDetector, GradientPoints, N_GRADIENT,
};
pub use m3::{
    BilateralConfig, EMBEDDED_FILES, LEVEL1_BOX_TOP, Level1Config, M3, M3Config, RefSource,
    ZoneConfig, embedded_file,
};
pub use prior::{PriorZoneConfig, ShapePriorConfig};

/// Number of landmarks in the merged output (iBUG 68).
pub const N_POINTS: usize = 68;

/// The index of each point's mirror image under a left–right flip of the face (iBUG 68 order:
/// jaw point 0 ↔ 16, brow 17 ↔ 26, the nose ridge on itself, …); `models/train/m3data.py` holds the
/// same table as `MIRROR68`.
pub const MIRROR68: [usize; N_POINTS] = [
    16, 15, 14, 13, 12, 11, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0, // jaw
    26, 25, 24, 23, 22, 21, 20, 19, 18, 17, // brows
    27, 28, 29, 30, 35, 34, 33, 32, 31, // nose
    45, 44, 43, 42, 47, 46, 39, 38, 37, 36, 41, 40, // eyes
    54, 53, 52, 51, 50, 49, 48, 59, 58, 57, 56, 55, // outer lips
    64, 63, 62, 61, 60, 67, 66, 65, // inner lips
];

/// Yaw classes of level 1, degrees (−60: < −60°, −30: −60..−30°, 0: −30..30°, 30: 30..60°,
/// 60: > 60°).
pub const YAW_CLASSES_DEG: [i32; 5] = [-60, -30, 0, 30, 60];

/// Mouth gesture names, in [`FaceLandmarks::mouth`] order.
pub const MOUTH_GESTURES: [&str; 4] = ["smile", "frown", "kiss", "neutral"];

/// Brow gesture names, in [`FaceLandmarks::brows`] order.
pub const BROW_GESTURES: [&str; 3] = ["raise", "frown", "neutral"];

/// Everything M3 says about one face. Filled in place by the detector (no allocation per call).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceLandmarks {
    /// 68 points in image pixels (CONTRACT pixel convention), iBUG order.
    pub points: [[f32; 2]; N_POINTS],
    /// Level-1 yaw class probabilities, [`YAW_CLASSES_DEG`] order.
    pub yaw_probs: [f32; 5],
    /// Level-1 face/not-face probability of the crop.
    pub face_prob: f32,
    /// Mouth gesture probabilities, [`MOUTH_GESTURES`] order.
    pub mouth: [f32; 4],
    /// Brow gesture probabilities, [`BROW_GESTURES`] order.
    pub brows: [f32; 3],
    /// Unit gaze vector of the subject's left eye (points 42–47), camera frame.
    pub gaze_left: [f32; 3],
    /// Unit gaze vector of the subject's right eye (points 36–41), camera frame.
    pub gaze_right: [f32; 3],
    /// Normalised sum of both eyes' gaze vectors, camera frame.
    pub gaze_combined: [f32; 3],
    /// Per point, the estimator's confidence in 0..1, which the 3D fit uses as its weight: 1 for
    /// every M3 point; for the gradient detector its points' confidences, and 0 for the points it
    /// has no counterpart of (those hold the mean face placed on the found points).
    pub weights: [f32; N_POINTS],
}

impl Default for FaceLandmarks {
    fn default() -> Self {
        Self {
            points: [[0.0; 2]; N_POINTS],
            yaw_probs: [0.0; 5],
            face_prob: 0.0,
            mouth: [0.0; 4],
            brows: [0.0; 3],
            gaze_left: [0.0, 0.0, 1.0],
            gaze_right: [0.0, 0.0, 1.0],
            gaze_combined: [0.0, 0.0, 1.0],
            weights: [1.0; N_POINTS],
        }
    }
}

impl FaceLandmarks {
    /// The most probable yaw class, degrees.
    pub fn yaw_class_deg(&self) -> i32 {
        let mut best = 0;
        for i in 1..5 {
            if self.yaw_probs[i] > self.yaw_probs[best] {
                best = i;
            }
        }
        YAW_CLASSES_DEG[best]
    }
}
