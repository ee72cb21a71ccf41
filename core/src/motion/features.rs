//! The features a motion is scored on, per joint and frame.

use super::filter::SavitzkyGolay;
use super::{Pose3, dot, norm, sub};
use crate::body::Joint;
use crate::math::Libm;

/// A feature of one joint over time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feature {
    /// Flexion / extension, degrees, 0 straight: elbows and knees (the bend between the two
    /// bones), shoulders and hips (the limb against the trunk's downward axis), the thorax (the
    /// neck against the spine).
    Flexion,
    /// Abduction / adduction, degrees, positive away from the body: shoulders and hips (the limb
    /// out of the body's sagittal plane).
    Abduction,
    /// Speed relative to the pelvis, mm/s (every joint but the pelvis).
    LinearVelocity,
    /// Rate of change of the flexion angle, degrees/s (where flexion is defined).
    AngularVelocity,
    /// Magnitude of the acceleration relative to the pelvis, mm/s² (every joint but the pelvis):
    /// the Savitzky–Golay second derivative of the smoothed trajectory.
    LinearAcceleration,
}

impl Feature {
    /// The weights file's name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Flexion => "flexion",
            Self::Abduction => "abduction",
            Self::LinearVelocity => "linear_velocity",
            Self::AngularVelocity => "angular_velocity",
            Self::LinearAcceleration => "linear_acceleration",
        }
    }

    /// In words, for reports.
    pub fn words(self) -> &'static str {
        match self {
            Self::Flexion => "flexion",
            Self::Abduction => "abduction",
            Self::LinearVelocity => "speed",
            Self::AngularVelocity => "angular speed",
            Self::LinearAcceleration => "acceleration",
        }
    }

    /// From the weights file's name.
    pub fn from_name(name: &str) -> Option<Self> {
        [
            Self::Flexion,
            Self::Abduction,
            Self::LinearVelocity,
            Self::AngularVelocity,
            Self::LinearAcceleration,
        ]
        .into_iter()
        .find(|f| f.name() == name)
    }

    /// Whether the joint has this feature.
    pub fn defined_for(self, joint: Joint) -> bool {
        use Joint::*;
        match self {
            Self::Flexion | Self::AngularVelocity => matches!(
                joint,
                Thorax | LShoulder | RShoulder | LElbow | RElbow | LHip | RHip | LKnee | RKnee
            ),
            Self::Abduction => matches!(joint, LShoulder | RShoulder | LHip | RHip),
            Self::LinearVelocity | Self::LinearAcceleration => joint != Pelvis,
        }
    }
}

fn angle_deg(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let n = norm(a) * norm(b);
    if n > 1e-12 {
        (dot(a, b) / n).clamp(-1.0, 1.0).macos().to_degrees()
    } else {
        0.0
    }
}

fn flexion(joint: Joint, p: &Pose3) -> f64 {
    use Joint::*;
    let at = |j: Joint| p[j.index()];
    let down = sub(&at(Pelvis), &at(Thorax));
    match joint {
        LElbow | RElbow | LKnee | RKnee => {
            let (a, b) = match joint {
                LElbow => (LShoulder, LWrist),
                RElbow => (RShoulder, RWrist),
                LKnee => (LHip, LAnkle),
                _ => (RHip, RAnkle),
            };
            180.0 - angle_deg(&sub(&at(a), &at(joint)), &sub(&at(b), &at(joint)))
        }
        LShoulder => angle_deg(&sub(&at(LElbow), &at(LShoulder)), &down),
        RShoulder => angle_deg(&sub(&at(RElbow), &at(RShoulder)), &down),
        LHip => angle_deg(&sub(&at(LKnee), &at(LHip)), &down),
        RHip => angle_deg(&sub(&at(RKnee), &at(RHip)), &down),
        Thorax => angle_deg(&sub(&at(Head), &at(Thorax)), &sub(&at(Thorax), &at(Pelvis))),
        _ => 0.0,
    }
}

fn abduction(joint: Joint, p: &Pose3) -> f64 {
    use Joint::*;
    let at = |j: Joint| p[j.index()];
    let (lateral, limb, outward) = match joint {
        LShoulder => (
            sub(&at(LShoulder), &at(RShoulder)),
            sub(&at(LElbow), &at(LShoulder)),
            1.0,
        ),
        RShoulder => (
            sub(&at(LShoulder), &at(RShoulder)),
            sub(&at(RElbow), &at(RShoulder)),
            -1.0,
        ),
        LHip => (sub(&at(LHip), &at(RHip)), sub(&at(LKnee), &at(LHip)), 1.0),
        RHip => (sub(&at(LHip), &at(RHip)), sub(&at(RKnee), &at(RHip)), -1.0),
        _ => return 0.0,
    };
    let n = norm(&lateral) * norm(&limb);
    if n > 1e-12 {
        (outward * dot(&lateral, &limb) / n)
            .clamp(-1.0, 1.0)
            .masin()
            .to_degrees()
    } else {
        0.0
    }
}

/// The feature of `joint` per frame, from smoothed positions `pos` and their per-frame
/// derivative `vel`; `dt` seconds per frame.
pub(crate) fn series(
    feature: Feature,
    joint: Joint,
    pos: &[Pose3],
    vel: &[Pose3],
    sg: &SavitzkyGolay,
    dt: f64,
) -> Vec<f64> {
    match feature {
        Feature::Flexion => pos.iter().map(|p| flexion(joint, p)).collect(),
        Feature::Abduction => pos.iter().map(|p| abduction(joint, p)).collect(),
        Feature::LinearVelocity => vel.iter().map(|v| norm(&v[joint.index()]) / dt).collect(),
        Feature::AngularVelocity => {
            let f: Vec<f64> = pos.iter().map(|p| flexion(joint, p)).collect();
            sg.apply(&f, 1).into_iter().map(|v| v / dt).collect()
        }
        Feature::LinearAcceleration => {
            let axes = [0, 1, 2].map(|c| {
                let x: Vec<f64> = pos.iter().map(|p| p[joint.index()][c]).collect();
                sg.apply(&x, 2)
            });
            (0..pos.len())
                .map(|i| norm(&[axes[0][i], axes[1][i], axes[2][i]]) / (dt * dt))
                .collect()
        }
    }
}

/// The reference's lowest value and the range SSIM's constants scale with: its spread, at least
/// a feature-typical floor so a nearly still reference does not make every jitter a difference.
pub(crate) fn dynamic_range(feature: Feature, r: &[f64]) -> (f64, f64) {
    let (lo, hi) = r
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let floor = match feature {
        Feature::Flexion | Feature::Abduction => 10.0,
        Feature::LinearVelocity => 100.0,
        Feature::AngularVelocity => 30.0,
        Feature::LinearAcceleration => 1000.0,
    };
    (lo, (hi - lo).max(floor))
}
