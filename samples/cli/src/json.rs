//! JSON pieces shared by the subcommands: camera parsing and the CONTRACT's FACE fields.

use monotrack_core::camera::Intrinsics;
use monotrack_core::fit::FaceFit;
use monotrack_core::gaze::{PointOfGaze, Target, targets_from_json};
use monotrack_core::landmarks::N_POINTS;
use monotrack_core::landmarks::eyes::eye_openness;
use monotrack_core::model::{ANIM_UNIT_NAMES, SHAPE_UNIT_NAMES};
use monotrack_core::track::quality::{FaceQuality, QualityReasons};
use serde::Deserialize;
use serde_json::{Map, Value, json};

/// `"camera": {"fx", "fy", "cx", "cy"}` as in CONTRACT.md.
#[derive(Debug, Clone, Copy, Deserialize)]
pub struct CameraJson {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// The caller's camera, or the CONTRACT default for a `width`×`height` image.
pub fn intrinsics(
    camera: Option<CameraJson>,
    width: u32,
    height: u32,
) -> monotrack_core::Result<Intrinsics> {
    match camera {
        Some(c) => Intrinsics::new(c.fx, c.fy, c.cx, c.cy),
        None => Intrinsics::default_for(width, height),
    }
}

fn round(v: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (v * p).round() / p
}

/// Reads the targets file of `--targets` (`T.json`, CONTRACT.md).
///
/// # Errors
/// A message naming the file when it cannot be read or is not a valid targets file.
pub fn load_targets(path: &std::path::Path) -> Result<Vec<Target>, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    targets_from_json(&bytes).map_err(|e| format!("{}: {e}", path.display()))
}

/// With `--targets`: adds `origin_mm` to the FACE's `gaze` object and its `target` object
/// (CONTRACT.md, "Options shared by face commands").
pub fn put_point_of_gaze(face: &mut Map<String, Value>, g: &PointOfGaze, targets: &[Target]) {
    let (o, d) = (&g.ray.origin, &g.ray.direction);
    if let Some(Value::Object(gaze)) = face.get_mut("gaze") {
        gaze.insert(
            "origin_mm".into(),
            json!([round(o.x, 2), round(o.y, 2), round(o.z, 2)]),
        );
        // The ray the target was located with: the eyes' (calibrated) or, where they are not
        // trusted, the head's; `combined` stays M3's own eye estimate.
        gaze.insert(
            "direction".into(),
            json!([round(d.x, 6), round(d.y, 6), round(d.z, 6)]),
        );
    }
    let Some(h) = g.hit else {
        return;
    };
    let name = |i: usize| targets.get(i).map(|t| t.id.clone()).unwrap_or_default();
    face.insert(
        "target".into(),
        json!({
            "id": h.target.map(name),
            "hit": h.target.is_some(),
            "point_mm": [round(h.point_mm[0], 2), round(h.point_mm[1], 2)],
            "nearest": name(h.nearest),
            "distance_mm": round(h.distance_mm, 2),
        }),
    );
}

/// Adds `eyes` to a FACE object: each of the subject's eyes' openness from its six landmarks, or
/// `null` when any of the twelve is not measured (weight 0: the gradient detector has no lid
/// midpoints).
pub fn put_eyes(face: &mut Map<String, Value>, points: &[[f32; 2]; N_POINTS], weights: &[f32]) {
    let measured = weights
        .get(36..48)
        .is_some_and(|w| w.iter().all(|w| *w > 0.0));
    let eyes = if measured {
        let o = eye_openness(points);
        json!({"left_open": round(f64::from(o.left), 4), "right_open": round(f64::from(o.right), 4)})
    } else {
        Value::Null
    };
    face.insert("eyes".into(), eyes);
}

/// Adds `pose`, `transform`, `shape_units`, `action_units`, `fit_rms_px` (and `fit_report`) to a
/// FACE object.
pub fn put_fit(face: &mut Map<String, Value>, fit: &FaceFit) {
    let r = &fit.pose.rotation;
    let t = &fit.pose.translation;
    let (yaw, pitch, roll) = fit.pose.euler_deg();
    face.insert(
        "pose".into(),
        json!({
            "rotation": (0..3).map(|i| (0..3).map(|j| round(r[(i, j)], 6)).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "translation_mm": [round(t.x, 2), round(t.y, 2), round(t.z, 2)],
            "yaw_deg": round(yaw, 3), "pitch_deg": round(pitch, 3), "roll_deg": round(roll, 3),
        }),
    );
    // Rotation entries to the same digits as `rotation`, the translation's as `translation_mm`.
    let m = fit.pose.transform();
    face.insert(
        "transform".into(),
        json!(
            m.iter()
                .enumerate()
                .map(|(k, v)| round(*v, if k % 4 == 3 { 2 } else { 6 }))
                .collect::<Vec<_>>()
        ),
    );
    let units = |names: &[&str], vals: &[f64]| {
        Value::Object(
            names
                .iter()
                .zip(vals)
                .map(|(n, v)| (n.to_string(), json!(round(*v, 4))))
                .collect(),
        )
    };
    face.insert("shape_units".into(), units(&SHAPE_UNIT_NAMES, &fit.shape));
    face.insert(
        "action_units".into(),
        units(&ANIM_UNIT_NAMES, &fit.animation),
    );
    let u = &fit.uncertainty;
    face.insert(
        "uncertainty".into(),
        json!({
            "rotation_deg": u.rotation_deg.iter().map(|v| round(*v, 3)).collect::<Vec<_>>(),
            "translation_mm": u.translation_mm.iter().map(|v| round(*v, 2)).collect::<Vec<_>>(),
        }),
    );
    face.insert("fit_rms_px".into(), json!(round(fit.report.rms_px, 3)));
    face.insert(
        "fit_report".into(),
        json!({
            "iterations": fit.report.iterations,
            "termination": format!("{:?}", fit.report.termination),
            "converged": fit.report.converged,
        }),
    );
}

/// CONTRACT's reason names of `reasons`, in their fixed order.
pub fn reasons_json(reasons: QualityReasons) -> Value {
    json!(reasons.iter().map(|r| r.name()).collect::<Vec<_>>())
}

/// A FACE's `"quality": {"score", "reasons"}`.
pub fn put_quality(face: &mut Map<String, Value>, q: &FaceQuality) {
    face.insert(
        "quality".into(),
        json!({"score": round(f64::from(q.score), 4), "reasons": reasons_json(q.reasons)}),
    );
}
