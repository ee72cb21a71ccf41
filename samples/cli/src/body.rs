//! `monotrack body-fit IN.jsonl [--out OUT.jsonl]`: 3D body pose and dimensions from 2D joints with
//! a known or floor-calibrated camera (CONTRACT.md). One output line per input line, same order; a
//! malformed line yields `{"line": N, "error": "..."}` in its place, a message on stderr, and exit
//! status 1 at the end.
//!
//! Lines sharing a `"sequence"` share body dimensions, estimated once on the sequence's first
//! `--dimension-frames` valid lines; a line without one is its own sequence. Input extensions:
//! `"width"`/`"height"` (the principal point of a floor calibration is the image centre; without
//! them a floor calibration needs `camera` intrinsics). With `"camera"` holding `rotation` and
//! `translation_mm`, the world frame is the caller's and its floor must be z = 0 with z up; with
//! `"floor"`, the world frame is the floor rectangle's (origin at corner 0, x towards corner 1, z up).

use crate::{LineSink, read_lines};
use monotrack_core::body::calib::{calibrate_floor, calibrate_floor_extrinsics};
use monotrack_core::body::skeleton::{N_POSE, dim};
use monotrack_core::body::{
    BodyCamera, BodyFitConfig, BodyFitter, Convention, DimensionEstimator, Dimensions, JOINT_NAMES,
    Joint, Joints2d, N_JOINTS, Skeleton,
};
use monotrack_core::camera::Intrinsics;
use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;
use serde_json::{Map, Value, json};
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

/// Joint-definition convention of the input joints.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum ConventionArg {
    /// HumanEva-I's joint definitions (default; CONTRACT.md's names).
    Humaneva,
    /// Human3.6M's (pelvis at the hips' midpoint, wider hips).
    H36m,
}

impl From<ConventionArg> for Convention {
    fn from(c: ConventionArg) -> Self {
        match c {
            ConventionArg::Humaneva => Convention::HumanEva,
            ConventionArg::H36m => Convention::Human36M,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraIn {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    rotation: Option<[[f64; 3]; 3]>,
    translation_mm: Option<[f64; 3]>,
}

#[derive(Deserialize)]
struct FloorIn {
    corners_px: [[f64; 2]; 4],
    size_mm: [f64; 2],
}

#[derive(Deserialize)]
struct LineIn {
    frame: Option<Value>,
    sequence: Option<Value>,
    camera: Option<CameraIn>,
    floor: Option<FloorIn>,
    width: Option<u32>,
    height: Option<u32>,
    joints2d: HashMap<String, Option<[f64; 2]>>,
}

/// A parsed, checked line.
struct Frame {
    frame: Value,
    sequence: Option<Value>,
    camera: BodyCamera,
    calibrated: bool,
    calibrate_us: u64,
    joints: Joints2d,
}

fn parse_line(text: &str) -> Result<Frame, String> {
    let line: LineIn = serde_json::from_str(text).map_err(|e| format!("malformed JSON: {e}"))?;
    let mut joints = Joints2d {
        points: [[0.0; 2]; N_JOINTS],
        weights: [0.0; N_JOINTS],
    };
    for (name, p) in &line.joints2d {
        let j = Joint::from_name(name).ok_or_else(|| {
            format!(
                "unknown joint {name:?} (expected one of {})",
                JOINT_NAMES.join(", ")
            )
        })?;
        if let Some(p) = p {
            joints.points[j.index()] = *p;
            joints.weights[j.index()] = 1.0;
        }
    }
    joints.validate().map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    let (camera, calibrated) = match (&line.camera, &line.floor) {
        (
            Some(CameraIn {
                fx,
                fy,
                cx,
                cy,
                rotation: Some(r),
                translation_mm: Some(t),
            }),
            _,
        ) => {
            let k = Intrinsics::new(*fx, *fy, *cx, *cy).map_err(|e| e.to_string())?;
            let rot = Matrix3::from_fn(|i, j| r[i][j]);
            let cam = BodyCamera::new(k, rot, Vector3::new(t[0], t[1], t[2]))
                .map_err(|e| e.to_string())?;
            (cam, false)
        }
        (Some(c), Some(f)) => {
            if c.rotation.is_some() || c.translation_mm.is_some() {
                return Err("camera: give both rotation and translation_mm, or neither".into());
            }
            let k = Intrinsics::new(c.fx, c.fy, c.cx, c.cy).map_err(|e| e.to_string())?;
            let cal = calibrate_floor_extrinsics(&f.corners_px, f.size_mm, &k)
                .map_err(|e| format!("floor: {e}"))?;
            (cal.camera, true)
        }
        (None, Some(f)) => {
            let (Some(w), Some(h)) = (line.width, line.height) else {
                return Err(
                    "floor calibration needs the image size (\"width\", \"height\") for the principal point, or \"camera\" intrinsics"
                        .into(),
                );
            };
            if w == 0 || h == 0 {
                return Err(format!("image size {w}x{h} is empty"));
            }
            let cal = calibrate_floor(
                &f.corners_px,
                f.size_mm,
                [f64::from(w) / 2.0, f64::from(h) / 2.0],
            )
            .map_err(|e| format!("floor: {e}"))?;
            (cal.camera, true)
        }
        (Some(_), None) => {
            return Err(
                "camera without rotation/translation_mm needs a \"floor\" to place it".into(),
            );
        }
        (None, None) => {
            return Err("need \"camera\" (with rotation, translation_mm) or \"floor\"".into());
        }
    };
    Ok(Frame {
        frame: line.frame.unwrap_or(Value::Null),
        sequence: line.sequence,
        camera,
        calibrated,
        calibrate_us: t0.elapsed().as_micros() as u64,
        joints,
    })
}

fn round(v: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (v * p).round() / p
}

fn camera_json(c: &BodyCamera) -> Value {
    let k = &c.intrinsics;
    json!({
        "fx": round(k.fx, 3), "fy": round(k.fy, 3), "cx": round(k.cx, 3), "cy": round(k.cy, 3),
        "rotation": (0..3).map(|i| (0..3).map(|j| round(c.rotation[(i, j)], 7)).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "translation_mm": [round(c.translation.x, 2), round(c.translation.y, 2), round(c.translation.z, 2)],
    })
}

/// Runs the subcommand; returns whether every line succeeded.
pub fn run(
    input: &Path,
    out: Option<&Path>,
    dimension_frames: usize,
    convention: ConventionArg,
    config: BodyFitConfig,
) -> Result<bool, String> {
    let prior_weight_px = config.prior_weight_px;
    if !(prior_weight_px.is_finite() && prior_weight_px >= 0.0) {
        return Err(format!(
            "--prior-weight must be finite and >= 0, got {prior_weight_px}"
        ));
    }
    let convention: Convention = convention.into();
    let lines = read_lines(input)?;
    let parsed: Vec<(usize, Result<Frame, String>)> =
        lines.iter().map(|(n, t)| (*n, parse_line(t))).collect();
    // Sequence key → indices of its valid lines, in order. Lines without a sequence stand alone.
    let mut groups: Vec<(Option<String>, Vec<usize>)> = Vec::new();
    for (i, (_, f)) in parsed.iter().enumerate() {
        let Ok(f) = f else { continue };
        let key = f.sequence.as_ref().map(|v| v.to_string());
        match key
            .as_ref()
            .and_then(|k| groups.iter_mut().find(|(g, _)| g.as_ref() == Some(k)))
        {
            Some((_, v)) => v.push(i),
            None => groups.push((key, vec![i])),
        }
    }
    let fitter = BodyFitter::new(config);
    let estimator = DimensionEstimator::default();
    // Per valid line: its skeleton (or an error from the estimation) and the estimation time.
    let mut skeletons: HashMap<usize, Result<(Skeleton, u64), String>> = HashMap::new();
    for (_, idx) in &groups {
        let first: Vec<usize> = idx.iter().copied().take(dimension_frames.max(1)).collect();
        let frames: Vec<Joints2d> = first
            .iter()
            .filter_map(|&i| parsed[i].1.as_ref().ok().map(|f| f.joints))
            .collect();
        let Some(Ok(cam)) = first
            .first()
            .map(|&i| parsed[i].1.as_ref().map(|f| f.camera))
        else {
            continue;
        };
        let t0 = Instant::now();
        let est = estimator
            .estimate(
                &fitter,
                &frames,
                &cam,
                &Dimensions::mean(convention),
                convention,
            )
            .and_then(|e| Skeleton::new(e.dimensions, convention))
            .map_err(|e| format!("dimension estimation: {e}"));
        let us = t0.elapsed().as_micros() as u64;
        for (k, &i) in idx.iter().enumerate() {
            skeletons.insert(i, est.clone().map(|s| (s, if k == 0 { us } else { 0 })));
        }
    }
    let mut sink = LineSink::new(out)?;
    let mut ok = true;
    // Each sequence's last pose: its next frame is refined from it (`BodyFitter::fit_tracked`).
    let mut previous: HashMap<String, [f64; N_POSE]> = HashMap::new();
    for (i, (n, f)) in parsed.iter().enumerate() {
        let result = f.as_ref().map_err(|e| e.clone()).and_then(|f| {
            let (skel, dim_us) = skeletons
                .get(&i)
                .cloned()
                .unwrap_or_else(|| Err("no dimensions".into()))?;
            let key = f.sequence.as_ref().map(|v| v.to_string());
            let prev = key.as_ref().and_then(|k| previous.get(k));
            let (v, pose) = fit_line(f, &fitter, &skel, dim_us, prev)?;
            if let Some(k) = key {
                previous.insert(k, pose);
            }
            Ok(v)
        });
        let v = result.unwrap_or_else(|e| {
            eprintln!("{}:{n}: {e}", input.display());
            ok = false;
            json!({"line": n, "error": e})
        });
        sink.write(&v)?;
    }
    Ok(ok)
}

/// One output line and the fitted pose.
fn fit_line(
    f: &Frame,
    fitter: &BodyFitter,
    skel: &Skeleton,
    dim_us: u64,
    previous: Option<&[f64; N_POSE]>,
) -> Result<(Value, [f64; N_POSE]), String> {
    let t0 = Instant::now();
    let fit = fitter
        .fit_tracked(&f.joints, &f.camera, skel, previous)
        .map_err(|e| e.to_string())?;
    let pose_us = t0.elapsed().as_micros() as u64;
    let joints: Map<String, Value> = JOINT_NAMES
        .iter()
        .zip(&fit.joints)
        .map(|(n, p)| {
            (
                n.to_string(),
                json!([round(p.x, 1), round(p.y, 1), round(p.z, 1)]),
            )
        })
        .collect();
    let dims: Map<String, Value> = dim::NAMES
        .iter()
        .zip(&skel.dims.lengths)
        .map(|(n, l)| (n.to_string(), json!(round(*l, 1))))
        .collect();
    let mut out = Map::new();
    out.insert("frame".into(), f.frame.clone());
    if let Some(s) = &f.sequence {
        out.insert("sequence".into(), s.clone());
    }
    out.insert("joints3d_mm".into(), Value::Object(joints));
    out.insert("dimensions_mm".into(), Value::Object(dims));
    out.insert(
        "reprojection_rms_px".into(),
        json!(round(fit.reprojection_rms_px, 3)),
    );
    out.insert(
        "contact".into(),
        fit.contact.map_or(Value::Null, |j| json!(j.name())),
    );
    if f.calibrated {
        out.insert("camera".into(), camera_json(&f.camera));
    }
    out.insert(
        "timings_us".into(),
        json!({"calibrate": f.calibrate_us, "dimensions": dim_us, "pose": pose_us,
               "total": f.calibrate_us + dim_us + pose_us}),
    );
    Ok((Value::Object(out), fit.pose))
}
