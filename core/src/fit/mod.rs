//! Fitting the deformable face model ([`crate::model`]) to 2D landmarks.
//!
//! - [`Msbp`]: full perspective, multi-step (pose by LM, shape by BFGS, each animation unit by BFGS);
//!   the SDK's default.
//! - [`Ffbp`]: weak perspective with POS initialisation, the ultra-light mode.
//!
//! Both return a [`FaceFit`] carrying a [`FitReport`] (iterations, RMS reprojection error in pixels,
//! termination reason); non-convergence is a status there, not an error. Neither allocates per call.

mod ffbp;
mod msbp;
pub mod pose;
pub mod solver;
pub mod uncertainty;

pub use ffbp::{Ffbp, FfbpConfig};
pub use msbp::{Msbp, MsbpConfig};
pub use pose::Pose;
pub use solver::Termination;
pub use uncertainty::PoseUncertainty;

use crate::camera::Intrinsics;
use crate::error::{Error, Result};
use crate::model::{FaceModel, N_ANIM, N_LANDMARKS, N_SHAPE};

/// Per-landmark confidence weights (≥ 0; 0 marks a missing landmark).
pub type LandmarkWeights = [f64; N_LANDMARKS];

/// Fewest landmarks with non-zero weight a fit accepts (6 pose parameters need ≥ 3 points; 6 keeps
/// the problem well-posed with noise).
pub const MIN_LANDMARKS: usize = 6;

/// What a fit did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitReport {
    /// Solver iterations over all steps.
    pub iterations: u32,
    /// RMS reprojection error over the landmarks with non-zero weight, pixels (full perspective).
    pub rms_px: f64,
    /// Termination of the last pose solve.
    pub termination: Termination,
    /// Whether that solve ended at a minimum.
    pub converged: bool,
}

/// A fitted face: pose, shape units, animation units, report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaceFit {
    /// Head pose (model → camera).
    pub pose: Pose,
    /// Shape units τsu, in [`crate::model::SHAPE_UNIT_NAMES`] order.
    pub shape: [f64; N_SHAPE],
    /// Animation units τau, in [`crate::model::ANIM_UNIT_NAMES`] order.
    pub animation: [f64; N_ANIM],
    /// Solver report.
    pub report: FitReport,
    /// Standard deviations of the reported pose ([`uncertainty`]).
    pub uncertainty: PoseUncertainty,
}

impl FaceFit {
    /// The shipped face model deformed by this fit's units and placed by its pose: the 68 vertices
    /// in camera coordinates, mm ([`FaceModel::posed_into`]).
    pub fn posed_vertices(&self) -> [nalgebra::Vector3<f64>; N_LANDMARKS] {
        let mut v = [nalgebra::Vector3::zeros(); N_LANDMARKS];
        FaceModel::builtin().posed_into(
            &self.shape,
            &self.animation,
            &self.pose.rotation,
            &self.pose.translation,
            &mut v,
        );
        v
    }
}

/// FFBP's default confidence weights (thesis): 1.0 eyes, mouth, nose top and base; 0.8 brows and
/// contour; 0.2 nostrils.
pub fn ffbp_default_weights() -> LandmarkWeights {
    let mut w = [1.0; N_LANDMARKS];
    for v in w.iter_mut().take(27) {
        *v = 0.8; // contour 0–16, brows 17–26
    }
    for i in [31, 32, 34, 35] {
        w[i] = 0.2;
    }
    w
}

fn validate_inputs(
    landmarks: &[[f64; 2]; N_LANDMARKS],
    weights: Option<&LandmarkWeights>,
    camera: &Intrinsics,
) -> Result<LandmarkWeights> {
    camera.validate()?;
    let w = weights.copied().unwrap_or([1.0; N_LANDMARKS]);
    let mut n = 0;
    for (i, (p, &wi)) in landmarks.iter().zip(&w).enumerate() {
        if !wi.is_finite() || wi < 0.0 {
            return Err(Error::InvalidInput(format!(
                "landmark weight {i} is {wi}; weights must be finite and >= 0"
            )));
        }
        if wi > 0.0 {
            if !(p[0].is_finite() && p[1].is_finite()) {
                return Err(Error::InvalidInput(format!(
                    "landmark {i} is not finite ({}, {})",
                    p[0], p[1]
                )));
            }
            n += 1;
        }
    }
    if n < MIN_LANDMARKS {
        return Err(Error::InvalidInput(format!(
            "{n} usable landmarks; a fit needs at least {MIN_LANDMARKS}"
        )));
    }
    Ok(w)
}

/// RMS full-perspective reprojection error (pixels) over landmarks with non-zero weight.
pub fn rms_reprojection(
    model: &FaceModel,
    shape: &[f64; N_SHAPE],
    anim: &[f64; N_ANIM],
    pose: &Pose,
    camera: &Intrinsics,
    landmarks: &[[f64; 2]; N_LANDMARKS],
    weights: &LandmarkWeights,
) -> f64 {
    let mut proj = [[0.0; 2]; N_LANDMARKS];
    model.project_into(
        shape,
        anim,
        &pose.rotation,
        &pose.translation,
        camera,
        &mut proj,
    );
    let (mut s, mut n) = (0.0, 0usize);
    for i in 0..N_LANDMARKS {
        if weights[i] > 0.0 {
            s += (proj[i][0] - landmarks[i][0]).powi(2) + (proj[i][1] - landmarks[i][1]).powi(2);
            n += 1;
        }
    }
    (s / n.max(1) as f64).sqrt()
}

/// Robust estimate of a user's shape: the per-unit median of the first `frames` per-frame estimates.
/// Tracking fits the shape freely for those frames, then holds the median.
#[derive(Debug, Clone)]
pub struct ShapeAccumulator {
    frames: usize,
    samples: Vec<[f64; N_SHAPE]>,
    scratch: Vec<f64>,
}

impl ShapeAccumulator {
    /// Collects up to `frames` estimates (at least 1).
    pub fn new(frames: usize) -> Self {
        let frames = frames.max(1);
        Self {
            frames,
            samples: Vec::with_capacity(frames),
            scratch: Vec::with_capacity(frames),
        }
    }

    /// Adds one frame's shape estimate (ignored once full or when not finite).
    pub fn push(&mut self, shape: &[f64; N_SHAPE]) {
        if self.samples.len() < self.frames && shape.iter().all(|v| v.is_finite()) {
            self.samples.push(*shape);
        }
    }

    /// Whether enough frames were collected.
    pub fn is_complete(&self) -> bool {
        self.samples.len() >= self.frames
    }

    /// Number of estimates so far.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether no estimate was added yet.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Forgets all estimates (new track / new user).
    pub fn clear(&mut self) {
        self.samples.clear();
    }

    /// Per-unit median of the estimates so far (`None` when empty).
    pub fn median(&mut self) -> Option<[f64; N_SHAPE]> {
        if self.samples.is_empty() {
            return None;
        }
        let mut out = [0.0; N_SHAPE];
        for (k, o) in out.iter_mut().enumerate() {
            self.scratch.clear();
            self.scratch.extend(self.samples.iter().map(|s| s[k]));
            self.scratch.sort_by(f64::total_cmp);
            let n = self.scratch.len();
            *o = if n % 2 == 1 {
                self.scratch[n / 2]
            } else {
                0.5 * (self.scratch[n / 2 - 1] + self.scratch[n / 2])
            };
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_accumulator_takes_the_median() {
        let mut acc = ShapeAccumulator::new(3);
        assert!(acc.median().is_none());
        acc.push(&[1.0; N_SHAPE]);
        acc.push(&[100.0; N_SHAPE]); // an outlier frame
        acc.push(&[f64::NAN; N_SHAPE]); // ignored
        assert!(!acc.is_complete());
        acc.push(&[2.0; N_SHAPE]);
        assert!(acc.is_complete());
        acc.push(&[3.0; N_SHAPE]); // full: ignored
        assert_eq!(acc.median().unwrap(), [2.0; N_SHAPE]);
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        let cam = Intrinsics::default_for(640, 480).unwrap();
        let mut lm = [[100.0; 2]; N_LANDMARKS];
        lm[3][0] = f64::NAN;
        let mut msbp = Msbp::new(MsbpConfig::default());
        assert!(matches!(
            msbp.fit(&lm, None, &cam, None),
            Err(Error::InvalidInput(_))
        ));
        // The NaN point is fine when its weight is 0.
        let mut w = [1.0; N_LANDMARKS];
        w[3] = 0.0;
        assert!(msbp.fit(&lm, Some(&w), &cam, None).is_ok());
        let bad_cam = Intrinsics {
            fx: f64::NAN,
            ..cam
        };
        assert!(matches!(
            msbp.fit(&lm, Some(&w), &bad_cam, None),
            Err(Error::InvalidCamera(_))
        ));
        let few = [0.0; N_LANDMARKS];
        assert!(matches!(
            msbp.fit(&lm, Some(&few), &cam, None),
            Err(Error::InvalidInput(_))
        ));
        let mut ffbp = Ffbp::new(FfbpConfig::default());
        assert!(matches!(
            ffbp.fit(&lm, None, &cam),
            Err(Error::InvalidInput(_))
        ));
    }
}
