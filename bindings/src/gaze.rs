//! Point of gaze through the FFI (`bindings/API.md`): targets, each face's `PointOfGaze`, and the
//! helpers that build targets (`monotrack_core::gaze`).

use crate::MonotrackError;
use crate::error::guard;
use crate::types::Vec3;
use monotrack_core::gaze::{self as core_gaze, Target};

/// A planar target — a screen, mirror or zone — as corners in the camera frame (mm, in order
/// round the polygon; 3 or more, coplanar). In-plane coordinates on it: `u` from corner 0 towards
/// corner 1, `v` perpendicular, into the polygon.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct GazeTarget {
    /// The app's name for it.
    pub id: String,
    /// Corners, camera frame, millimetres.
    pub corners_mm: Vec<Vec3>,
}

/// A point on a target's plane, millimetres (`u` along its first edge, `v` across it).
#[derive(Debug, Clone, Copy, PartialEq, uniffi::Record)]
pub struct PlanePoint {
    /// Along the first edge, from corner 0.
    pub u_mm: f64,
    /// Across it, into the polygon.
    pub v_mm: f64,
}

/// Where a point of gaze came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, uniffi::Enum)]
pub enum GazeSource {
    /// The eyes.
    Eyes,
    /// The head's facing direction (the eyes' estimates were not trusted: large head rotation or
    /// eyes that disagree).
    Head,
}

/// Where the gaze lands among the targets.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct TargetHit {
    /// The target looked at; `None` when the gaze misses every target.
    pub id: Option<String>,
    /// Whether a target is hit.
    pub hit: bool,
    /// On the hit target; on a miss, where the gaze meets the nearest target's plane (its
    /// centroid when it never meets it in front of the eyes).
    pub point: PlanePoint,
    /// The target hit, or the nearest one.
    pub nearest: String,
    /// 0 on a hit, else how far the gaze passes from the nearest target, mm.
    pub distance_mm: f64,
}

/// Where one face looks.
#[derive(Debug, Clone, PartialEq, uniffi::Record)]
pub struct PointOfGaze {
    /// The gaze ray's start: between the fitted face's eyes, camera frame, mm.
    pub origin_mm: Vec3,
    /// The gaze direction (unit, camera frame), corrected by the tap calibration.
    pub direction: Vec3,
    /// Eyes or head.
    pub source: GazeSource,
    /// 0..1: how far the eyes are trusted (head yaw, agreement of the two eyes, how open they
    /// are); below 0.25 the head direction stands in (`source` is `Head`).
    pub confidence: f64,
    /// Angle between the head's facing direction and the gaze, degrees.
    pub head_to_gaze_deg: f64,
    /// The target looked at or the nearest one; `None` when no targets are set.
    pub target: Option<TargetHit>,
}

fn v3(v: &nalgebra::Vector3<f64>) -> Vec3 {
    Vec3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

impl PointOfGaze {
    /// From the core's, naming targets from `targets` (the list the tracker located among).
    pub(crate) fn from_core(g: &core_gaze::PointOfGaze, targets: &[Target]) -> Self {
        let name = |i: usize| targets.get(i).map(|t| t.id.clone()).unwrap_or_default();
        Self {
            origin_mm: v3(&g.ray.origin),
            direction: v3(&g.ray.direction),
            source: match g.source {
                core_gaze::GazeSource::Eyes => GazeSource::Eyes,
                core_gaze::GazeSource::Head => GazeSource::Head,
            },
            confidence: g.confidence,
            head_to_gaze_deg: g.head_to_gaze_deg,
            target: g.hit.map(|h| TargetHit {
                id: h.target.map(name),
                hit: h.target.is_some(),
                point: PlanePoint {
                    u_mm: h.point_mm[0],
                    v_mm: h.point_mm[1],
                },
                nearest: name(h.nearest),
                distance_mm: h.distance_mm,
            }),
        }
    }
}

/// The core's targets for `targets`.
///
/// # Errors
/// `InvalidConfig` for a bad target or a repeated id.
pub(crate) fn to_core(targets: &[GazeTarget]) -> Result<Vec<Target>, MonotrackError> {
    let mut out: Vec<Target> = Vec::with_capacity(targets.len());
    for t in targets {
        if out.iter().any(|o| o.id == t.id) {
            return Err(MonotrackError::InvalidConfig {
                msg: format!("gaze target id {:?} given twice", t.id),
            });
        }
        let corners: Vec<[f64; 3]> = t.corners_mm.iter().map(|c| [c.x, c.y, c.z]).collect();
        out.push(Target::new(t.id.clone(), &corners)?);
    }
    Ok(out)
}

fn from_core(t: &Target) -> GazeTarget {
    GazeTarget {
        id: t.id.clone(),
        corners_mm: t.corners().iter().map(v3).collect(),
    }
}

/// A device's own screen as a target: `width_mm` × `height_mm` as the user sees it, the camera in
/// its plane `camera_right_mm` right of and `camera_down_mm` below its top-left corner as the user
/// sees it (negative `camera_down_mm` for a camera above the screen), for a front camera whose
/// frames are mirrored (the selfie view). Points on it are the user's screen coordinates in mm
/// from the top-left.
///
/// # Errors
/// `InvalidConfig` for a size that is not finite and positive or a non-finite offset.
#[uniffi::export]
pub fn screen_target(
    id: String,
    width_mm: f64,
    height_mm: f64,
    camera_right_mm: f64,
    camera_down_mm: f64,
) -> Result<GazeTarget, MonotrackError> {
    guard(|| {
        let t = Target::screen(id, width_mm, height_mm, [camera_right_mm, camera_down_mm])?;
        Ok(from_core(&t))
    })
}

/// Targets from the CLI's `T.json` (`{"targets": [{"id", "corners_mm": [[x, y, z], ...]}]}`,
/// `CONTRACT.md`).
///
/// # Errors
/// `InvalidConfig` for malformed JSON, no targets, a repeated id or a bad target.
#[uniffi::export]
pub fn gaze_targets_from_json(json: String) -> Result<Vec<GazeTarget>, MonotrackError> {
    guard(|| {
        Ok(core_gaze::targets_from_json(json.as_bytes())?
            .iter()
            .map(from_core)
            .collect())
    })
}

/// The index of the tapped target `target_id` among the targets' `ids` (in the order they were
/// set), for a tap at a finite `point`.
pub(crate) fn tap_target<'a>(
    mut ids: impl Iterator<Item = &'a str>,
    target_id: &str,
    point: &PlanePoint,
) -> Result<usize, MonotrackError> {
    let index =
        ids.position(|id| id == target_id)
            .ok_or_else(|| MonotrackError::InvalidConfig {
                msg: format!("no gaze target {target_id:?}"),
            })?;
    if !(point.u_mm.is_finite() && point.v_mm.is_finite()) {
        return Err(MonotrackError::InvalidConfig {
            msg: format!("calibration point {point:?} is not finite"),
        });
    }
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_cross_and_bad_ones_are_typed_errors() {
        let s = screen_target("phone".into(), 70.0, 150.0, 35.0, -8.0).unwrap();
        assert_eq!(s.corners_mm.len(), 4);
        assert_eq!((s.corners_mm[0].x, s.corners_mm[0].y), (-35.0, 8.0));
        assert!(matches!(
            screen_target("x".into(), f64::NAN, 1.0, 0.0, 0.0),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        let json = include_str!("../../examples/driver_zones.json");
        let zones = gaze_targets_from_json(json.into()).unwrap();
        assert_eq!(zones.len(), 7);
        assert_eq!(to_core(&zones).unwrap().len(), 7);
        let twice = vec![s.clone(), s];
        assert!(matches!(
            to_core(&twice),
            Err(MonotrackError::InvalidConfig { .. })
        ));
        assert!(matches!(
            gaze_targets_from_json("{\"targets\": 3}".into()),
            Err(MonotrackError::InvalidConfig { .. })
        ));
    }
}
