//! Motion comparison through the FFI (`bindings/API.md`): `compare_motion` for two recorded
//! sequences and `MotionSession` for a live `BodyTracker` sequence scored when it ends
//! (`monotrack_core::motion`).

use crate::MonotrackError;
use crate::body::{BodyJoint, BodyJoint3d};
use crate::error::{guard, guard_infallible};
use monotrack_core::body::{Joint, N_JOINTS};
use monotrack_core::motion::{self as core_motion, MotionConfig, Pose3, Weights};
use std::sync::{Arc, Mutex};

/// One pose of a motion: the 15 joints' 3D positions (mm), each once, any order — what
/// `BodyFitResult.joints` holds.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct MotionFrame {
    /// The joints.
    pub joints: Vec<BodyJoint3d>,
}

/// A feature a motion is scored on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum MotionFeature {
    /// Flexion / extension angle, degrees.
    Flexion,
    /// Abduction / adduction angle, degrees.
    Abduction,
    /// Speed relative to the pelvis, mm/s.
    LinearVelocity,
    /// Rate of change of the flexion angle, degrees/s.
    AngularVelocity,
    /// Magnitude of the acceleration relative to the pelvis, mm/s².
    LinearAcceleration,
}

impl From<core_motion::Feature> for MotionFeature {
    fn from(f: core_motion::Feature) -> Self {
        match f {
            core_motion::Feature::Flexion => Self::Flexion,
            core_motion::Feature::Abduction => Self::Abduction,
            core_motion::Feature::LinearVelocity => Self::LinearVelocity,
            core_motion::Feature::AngularVelocity => Self::AngularVelocity,
            core_motion::Feature::LinearAcceleration => Self::LinearAcceleration,
        }
    }
}

/// A phase's result.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct MotionPhaseScore {
    /// The phase.
    pub name: String,
    /// Weighted sum of its features' similarities.
    pub score: f64,
    /// The sum of its features' weights (the best possible score).
    pub nominal: f64,
}

/// One weighted feature's result.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct MotionFeatureScore {
    /// The phase.
    pub phase: String,
    /// The joint.
    pub joint: BodyJoint,
    /// The feature.
    pub feature: MotionFeature,
    /// Similarity 0..1.
    pub score: f64,
    /// Its weight.
    pub weight: f64,
}

/// A reference frame and the trial frame it corresponds to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Record)]
pub struct FramePair {
    /// Frame of the reference.
    pub reference_frame: u32,
    /// Frame of the trial.
    pub trial_frame: u32,
}

/// A trial scored against a reference.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct MotionReport {
    /// All phases' scores over their nominal scores, 0..1.
    pub overall: f64,
    /// Per phase.
    pub phases: Vec<MotionPhaseScore>,
    /// Per weighted feature.
    pub features: Vec<MotionFeatureScore>,
    /// What to fix: the lowest-scoring feature of the lowest-scoring phase.
    pub worst: MotionFeatureScore,
    /// Global alignment: trial frame = reference frame + shift.
    pub shift: i64,
    /// Dense frame correspondences.
    pub path: Vec<FramePair>,
    /// The coach's summary in words ("To fix: right elbow flexion in back-swing").
    pub summary: String,
}

fn to_pose(f: &MotionFrame, index: usize, what: &str) -> Result<Pose3, MonotrackError> {
    let mut pose = [[0.0; 3]; N_JOINTS];
    let mut seen = [false; N_JOINTS];
    for j in &f.joints {
        let i = Joint::from(j.joint).index();
        if seen[i] {
            return Err(MonotrackError::InvalidConfig {
                msg: format!("{what} frame {index}: joint {:?} given twice", j.joint),
            });
        }
        seen[i] = true;
        pose[i] = [j.position_mm.x, j.position_mm.y, j.position_mm.z];
    }
    if let Some(missing) = seen.iter().position(|s| !s) {
        return Err(MonotrackError::InvalidConfig {
            msg: format!(
                "{what} frame {index}: joint {:?} missing (all 15 are needed)",
                BodyJoint::from(Joint::ALL[missing])
            ),
        });
    }
    Ok(pose)
}

fn to_poses(frames: &[MotionFrame], what: &str) -> Result<Vec<Pose3>, MonotrackError> {
    frames
        .iter()
        .enumerate()
        .map(|(i, f)| to_pose(f, i, what))
        .collect()
}

fn config(fps: f64) -> Result<MotionConfig, MonotrackError> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(MonotrackError::InvalidConfig {
            msg: format!("fps must be finite and > 0, got {fps}"),
        });
    }
    Ok(MotionConfig {
        fps,
        ..MotionConfig::default()
    })
}

fn report(r: &core_motion::MotionReport) -> MotionReport {
    let feature = |f: &core_motion::FeatureScore| MotionFeatureScore {
        phase: f.phase.clone(),
        joint: f.joint.into(),
        feature: f.feature.into(),
        score: f.score,
        weight: f.weight,
    };
    let worst = r
        .features
        .iter()
        .find(|f| {
            f.phase == r.worst.phase && f.joint == r.worst.joint && f.feature == r.worst.feature
        })
        .map(feature)
        .unwrap_or(MotionFeatureScore {
            phase: r.worst.phase.clone(),
            joint: r.worst.joint.into(),
            feature: r.worst.feature.into(),
            score: r.worst.score,
            weight: 0.0,
        });
    MotionReport {
        overall: r.overall,
        phases: r
            .phases
            .iter()
            .map(|p| MotionPhaseScore {
                name: p.name.clone(),
                score: p.score,
                nominal: p.nominal,
            })
            .collect(),
        features: r.features.iter().map(feature).collect(),
        worst,
        shift: r.shift,
        path: r
            .path
            .iter()
            .map(|&(a, b)| FramePair {
                reference_frame: a as u32,
                trial_frame: b as u32,
            })
            .collect(),
        summary: r.summary(),
    }
}

/// Scores `trial` against `reference` (both at `fps`) with the phases and weighted features of
/// `weights_json` (the CLI's `W.json`, CONTRACT.md).
///
/// # Errors
/// `InvalidConfig` for bad weights (named field), a frame without all 15 joints, or a bad `fps`;
/// `InvalidFrame` for a sequence too short (under 9 frames) or with non-finite joints.
#[uniffi::export]
pub fn compare_motion(
    reference: Vec<MotionFrame>,
    trial: Vec<MotionFrame>,
    weights_json: String,
    fps: f64,
) -> Result<MotionReport, MonotrackError> {
    guard(|| {
        let cfg = config(fps)?;
        let w = Weights::from_json(weights_json.as_bytes())?;
        let r = to_poses(&reference, "reference")?;
        let t = to_poses(&trial, "trial")?;
        let rep = core_motion::compare(&r, &t, &w, &cfg).map_err(|e| match e {
            monotrack_core::Error::InvalidInput(msg) => MonotrackError::InvalidFrame { msg },
            e => e.into(),
        })?;
        Ok(report(&rep))
    })
}

/// A live sequence scored against a reference when it ends: add each frame's joints as the
/// `BodyTracker` gives them, then `finish`.
#[derive(uniffi::Object)]
pub struct MotionSession {
    reference: Vec<Pose3>,
    weights: Weights,
    config: MotionConfig,
    trial: Mutex<Vec<Pose3>>,
}

#[uniffi::export]
impl MotionSession {
    /// A session against `reference` (at `fps`, as the live frames will be) with `weights_json`.
    ///
    /// # Errors
    /// As `compare_motion` for the reference and the weights (phases are checked against the
    /// reference here).
    #[uniffi::constructor]
    pub fn new(
        reference: Vec<MotionFrame>,
        weights_json: String,
        fps: f64,
    ) -> Result<Arc<Self>, MonotrackError> {
        guard(|| {
            let config = config(fps)?;
            let weights = Weights::from_json(weights_json.as_bytes())?;
            let reference = to_poses(&reference, "reference")?;
            weights.validate(Some(reference.len()))?;
            Ok(Arc::new(Self {
                reference,
                weights,
                config,
                trial: Mutex::new(Vec::new()),
            }))
        })
    }

    /// Appends one live frame; returns the frames so far.
    ///
    /// # Errors
    /// `InvalidConfig` for a frame without all 15 joints (or one twice).
    pub fn add_frame(&self, frame: MotionFrame) -> Result<u32, MonotrackError> {
        guard(|| {
            let mut t = self.trial.lock().unwrap_or_else(|p| p.into_inner());
            let pose = to_pose(&frame, t.len(), "trial")?;
            t.push(pose);
            Ok(t.len() as u32)
        })
    }

    /// Scores the frames added so far against the reference and starts a new sequence.
    ///
    /// # Errors
    /// `InvalidFrame` when too few frames were added (under 9) or some are not finite.
    pub fn finish(&self) -> Result<MotionReport, MonotrackError> {
        guard(|| {
            let trial = std::mem::take(&mut *self.trial.lock().unwrap_or_else(|p| p.into_inner()));
            let rep = core_motion::compare(&self.reference, &trial, &self.weights, &self.config)
                .map_err(|e| match e {
                    monotrack_core::Error::InvalidInput(msg) => {
                        MonotrackError::InvalidFrame { msg }
                    }
                    e => e.into(),
                })?;
            Ok(report(&rep))
        })
    }

    /// Drops the frames added so far.
    pub fn reset(&self) {
        guard_infallible(|| self.trial.lock().unwrap_or_else(|p| p.into_inner()).clear());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Vec3;

    fn frame(phase: f64, bend: f64) -> MotionFrame {
        let th = (50.0 * (std::f64::consts::TAU * phase).sin()).to_radians();
        let el = (30.0 + 25.0 * (std::f64::consts::TAU * phase).cos() + bend).to_radians();
        let sh = [-180.0, 0.0, 1380.0];
        let elbow = [sh[0], sh[1] + 290.0 * th.sin(), sh[2] - 290.0 * th.cos()];
        let wrist = [
            elbow[0],
            elbow[1] + 250.0 * (th + el).sin(),
            elbow[2] - 250.0 * (th + el).cos(),
        ];
        let pos: [[f64; 3]; N_JOINTS] = [
            [0.0, 0.0, 900.0],
            [0.0, 0.0, 1400.0],
            [180.0, 0.0, 1380.0],
            [200.0, 0.0, 1100.0],
            [210.0, 60.0, 860.0],
            sh,
            elbow,
            wrist,
            [100.0, 0.0, 900.0],
            [100.0, 30.0, 480.0],
            [100.0, 0.0, 80.0],
            [-100.0, 0.0, 900.0],
            [-100.0, 0.0, 480.0],
            [-100.0, 0.0, 80.0],
            [0.0, 20.0, 1620.0],
        ];
        MotionFrame {
            joints: Joint::ALL
                .iter()
                .zip(pos)
                .map(|(j, p)| BodyJoint3d {
                    joint: (*j).into(),
                    position_mm: Vec3 {
                        x: p[0],
                        y: p[1],
                        z: p[2],
                    },
                })
                .collect(),
        }
    }

    const WEIGHTS: &str = r#"{"phases": [{"name": "swing", "start_frame": 0, "end_frame": 39}],
        "features": [{"phase": "swing", "joint": "relbow", "feature": "flexion", "weight": 1},
                     {"phase": "swing", "joint": "rwrist", "feature": "linear_velocity", "weight": 1}]}"#;

    #[test]
    fn recorded_and_live_sequences_score_alike() {
        let seq = |n: usize, bend: f64| -> Vec<MotionFrame> {
            (0..n)
                .map(|i| frame(i as f64 / (n - 1) as f64, bend))
                .collect()
        };
        let reference = seq(40, 0.0);
        let trial = seq(44, 25.0);
        let rep = compare_motion(reference.clone(), trial.clone(), WEIGHTS.into(), 30.0).unwrap();
        assert!(rep.overall < 0.95);
        assert_eq!(rep.worst.joint, BodyJoint::RElbow);
        assert!(rep.summary.contains("right elbow"));
        let live = MotionSession::new(reference.clone(), WEIGHTS.into(), 30.0).unwrap();
        for f in trial {
            live.add_frame(f).unwrap();
        }
        assert_eq!(live.finish().unwrap(), rep);
        // finish started a new sequence: too short now.
        assert!(matches!(
            live.finish(),
            Err(MonotrackError::InvalidFrame { .. })
        ));
        let mut broken = reference[0].clone();
        broken.joints.pop();
        assert!(matches!(
            live.add_frame(broken),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        assert!(matches!(
            compare_motion(reference.clone(), reference.clone(), "{}".into(), 30.0),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        assert!(matches!(
            compare_motion(reference.clone(), reference, WEIGHTS.into(), f64::NAN),
            Err(MonotrackError::InvalidConfig { .. })
        ));
    }
}
