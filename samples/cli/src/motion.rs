//! `monotrack compare-motion --reference R.jsonl --trial T.jsonl --weights W.json [--json]
//! [--plot DIR]`: a trial motion scored against a reference (`core::motion`, CONTRACT.md
//! "Motion command").

use crate::track::Canvas;
use monotrack_core::body::{JOINT_NAMES, N_JOINTS};
use monotrack_core::image::GrayImage;
use monotrack_core::motion::{MotionConfig, MotionReport, Pose3, Weights, compare, joint_words};
use serde_json::{Value, json};
use std::path::Path;

/// Reads `body-fit` output lines: each `joints3d_mm` must hold all 15 joints.
fn read_sequence(path: &Path) -> Result<Vec<Pose3>, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let at = |what: String| format!("{}:{}: {what}", path.display(), n + 1);
        let v: Value =
            serde_json::from_str(line).map_err(|e| at(format!("malformed JSON: {e}")))?;
        let joints = v
            .get("joints3d_mm")
            .and_then(Value::as_object)
            .ok_or_else(|| at("no \"joints3d_mm\" object (body-fit output lines)".into()))?;
        let mut pose = [[0.0; 3]; N_JOINTS];
        for (j, name) in JOINT_NAMES.iter().enumerate() {
            let p = joints
                .get(*name)
                .and_then(Value::as_array)
                .filter(|a| a.len() == 3)
                .ok_or_else(|| at(format!("joints3d_mm.{name} missing or not [x, y, z]")))?;
            for (c, x) in p.iter().enumerate() {
                pose[j][c] = x
                    .as_f64()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| at(format!("joints3d_mm.{name}[{c}] is not a finite number")))?;
            }
        }
        out.push(pose);
    }
    if out.is_empty() {
        return Err(format!("{}: no poses", path.display()));
    }
    Ok(out)
}

fn round(v: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (v * p).round() / p
}

/// The CONTRACT.md `--json` object.
pub fn report_json(r: &MotionReport) -> Value {
    json!({
        "overall": round(r.overall, 4),
        "phases": r.phases.iter().map(|p| json!({
            "name": p.name, "score": round(p.score, 4), "nominal": round(p.nominal, 4)})).collect::<Vec<_>>(),
        "features": r.features.iter().map(|f| json!({
            "phase": f.phase, "joint": f.joint.name(), "feature": f.feature.name(),
            "score": round(f.score, 4), "weight": f.weight})).collect::<Vec<_>>(),
        "worst": {"phase": r.worst.phase, "joint": r.worst.joint.name(),
                  "feature": r.worst.feature.name(), "score": round(r.worst.score, 4)},
        "alignment": {"shift": r.shift, "path": r.path.iter().map(|&(a, b)| [a, b]).collect::<Vec<_>>()},
    })
}

const W: usize = 640;
const H: usize = 360;
const MARGIN: f64 = 24.0;
/// The title's and legend's height, pixels (a 3×5 font at scale 2, with a gap).
const TEXT_ROW: f64 = 16.0;
const TEXT_RGB: [u8; 3] = [20, 20, 20];
const REFERENCE_RGB: [u8; 3] = [30, 90, 200];
const TRIAL_RGB: [u8; 3] = [230, 120, 20];
const PHASE_RGB: [u8; 3] = [225, 225, 225];
const AXIS_RGB: [u8; 3] = [90, 90, 90];
const SCORE_RGB: [u8; 3] = [40, 160, 60];

/// One PNG per weighted feature: a title (phase, joint, feature, similarity), the reference (blue)
/// and the trial carried onto the reference's frames (orange) over the whole reference, the
/// feature's phase shaded, a bar whose green length is the similarity, a legend with the plotted
/// range and the frames. The file name says the same: `NN_phase_joint_feature_score.png`.
fn plot(r: &MotionReport, weights: &Weights, dir: &Path) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let white = GrayImage::from_vec(W, H, vec![255; W * H]).ok_or("plot canvas")?;
    for (k, f) in r.features.iter().enumerate() {
        let mut c = Canvas::from_gray(&white);
        let n = f.reference.len().max(2);
        let (lo, hi) = f
            .reference
            .iter()
            .chain(&f.trial)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let span = (hi - lo).max(1e-6);
        // Rows from the top: title, similarity bar, plot, legend.
        let (top, bottom) = (MARGIN + TEXT_ROW + 12.0, H as f64 - MARGIN - TEXT_ROW);
        let x = |i: usize| MARGIN + (W as f64 - 2.0 * MARGIN) * i as f64 / (n - 1) as f64;
        let y = |v: f64| bottom - (bottom - top) * (v - lo) / span;
        let unit = match f.feature {
            monotrack_core::motion::Feature::LinearVelocity => "MM/S",
            monotrack_core::motion::Feature::AngularVelocity => "DEG/S",
            monotrack_core::motion::Feature::LinearAcceleration => "MM/S2",
            _ => "DEG",
        };
        let title = format!(
            "{}: {} {}  SIMILARITY {:.2}",
            f.phase,
            joint_words(f.joint),
            f.feature.words(),
            f.score
        );
        c.text(MARGIN as i64, (MARGIN * 0.25) as i64, &title, 2, TEXT_RGB);
        if let Some(p) = weights.phases.iter().find(|p| p.name == f.phase) {
            let (x0, x1) = (x(p.start_frame), x(p.end_frame));
            let mut xx = x0;
            while xx <= x1 {
                c.line([xx, top], [xx, bottom], PHASE_RGB);
                xx += 1.0;
            }
        }
        c.line([MARGIN, bottom], [W as f64 - MARGIN, bottom], AXIS_RGB);
        c.line([MARGIN, top], [MARGIN, bottom], AXIS_RGB);
        for (series, rgb) in [(&f.reference, REFERENCE_RGB), (&f.trial, TRIAL_RGB)] {
            for i in 1..series.len() {
                let (a, b) = ([x(i - 1), y(series[i - 1])], [x(i), y(series[i])]);
                c.line(a, b, rgb);
                c.line([a[0], a[1] + 1.0], [b[0], b[1] + 1.0], rgb);
            }
        }
        let bar = MARGIN + (W as f64 - 2.0 * MARGIN) * f.score.clamp(0.0, 1.0);
        for dy in 0..6 {
            let yy = MARGIN + TEXT_ROW - 8.0 + f64::from(dy);
            c.line([MARGIN, yy], [W as f64 - MARGIN, yy], PHASE_RGB);
            c.line([MARGIN, yy], [bar, yy], SCORE_RGB);
        }
        let legend_y = (H as f64 - MARGIN - TEXT_ROW + 8.0) as i64;
        c.text(MARGIN as i64, legend_y, "REFERENCE", 2, REFERENCE_RGB);
        c.text(MARGIN as i64 + 88, legend_y, "TRIAL", 2, TRIAL_RGB);
        let range = format!("{lo:.1} TO {hi:.1} {unit}, FRAMES 0-{}", n - 1);
        c.text(MARGIN as i64 + 144, legend_y, &range, 2, TEXT_RGB);
        let safe = |s: &str| {
            s.chars()
                .map(|ch| {
                    if ch.is_ascii_alphanumeric() || ch == '-' {
                        ch
                    } else {
                        '_'
                    }
                })
                .collect::<String>()
        };
        let name = format!(
            "{k:02}_{}_{}_{}_{:.2}.png",
            safe(&f.phase),
            safe(&joint_words(f.joint).replace(' ', "-")),
            f.feature.name(),
            f.score
        );
        c.save_png(&dir.join(name))?;
    }
    Ok(())
}

/// Runs the subcommand; prints the report (or its JSON) to stdout.
pub fn run(
    reference: &Path,
    trial: &Path,
    weights: &Path,
    json_out: bool,
    plot_dir: Option<&Path>,
    fps: f64,
) -> Result<(), String> {
    let r = read_sequence(reference)?;
    let t = read_sequence(trial)?;
    let wbytes =
        std::fs::read(weights).map_err(|e| format!("cannot read {}: {e}", weights.display()))?;
    let w = Weights::from_json(&wbytes).map_err(|e| format!("{}: {e}", weights.display()))?;
    let config = MotionConfig {
        fps,
        ..MotionConfig::default()
    };
    let rep = compare(&r, &t, &w, &config).map_err(|e| e.to_string())?;
    if let Some(dir) = plot_dir {
        plot(&rep, &w, dir)?;
    }
    if json_out {
        println!("{}", report_json(&rep));
    } else {
        print!("{}", rep.summary());
    }
    Ok(())
}
