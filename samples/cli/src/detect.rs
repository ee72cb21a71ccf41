//! `monotrack detect IN.jsonl [--out OUT.jsonl] [--min-face PX] [--threshold P] [--face-prob | --cascade]`: the
//! SDK's face detector on still images (an extension of CONTRACT.md). Input lines are
//! `{"image": path}` (absolute, or relative to IN.jsonl's folder), as for `landmarks`; output lines are
//! `{"image", "width", "height", "faces": [{"box": [x, y, w, h], "score": s}], "timings_us": {"detect"}}`
//! with boxes in the M3 convention (tight box of the 68 landmarks). With `--face-prob` every face
//! also carries `"face_prob"`, M3 level 1's face probability on that box: the check `landmarks` and
//! the tracker apply to every detection (they keep faces with `face_prob` at least
//! `track::DEFAULT_MIN_DETECTION_CONFIDENCE`, 0.95), so the cascade's
//! operating points can be measured; its time is not in `timings_us.detect`. With `--cascade` the
//! faces are those the SDK's detection cascade accepts (`track::check_detections`: the check on
//! the box of level 1's points, which replaces the detector's box; face probability at least 0.95,
//! ranked, overlaps merged), each with its `face_prob`, and `timings_us` also carries `check`, the
//! cascade's time. A line that fails
//! yields `{"line": N, "error": "..."}`, a message on stderr, and exit status 1 at the end.

use crate::{LineSink, read_lines};
use monotrack_core::detect::DetectorConfig;
use monotrack_core::image::GrayImage;
use monotrack_core::landmarks::{FaceLandmarks, M3};
use monotrack_core::track::{
    DEFAULT_MIN_DETECTION_CONFIDENCE, ModelDetector, RegionDetector, check_detections,
};
use serde::Deserialize;
use serde_json::{Value, json};
use std::path::Path;
use std::time::Instant;

#[derive(Deserialize)]
struct LineIn {
    image: String,
}

fn round2(v: f32) -> f64 {
    (v as f64 * 100.0).round() / 100.0
}

fn round4(v: f32) -> f64 {
    (v as f64 * 1e4).round() / 1e4
}

/// What is run after the detector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// The detector's faces alone.
    None,
    /// Each detector face with M3 level 1's face probability on its box.
    FaceProb,
    /// The faces the SDK's detection cascade accepts.
    Cascade,
}

/// Runs the subcommand; returns whether every line succeeded.
pub fn run(
    input: &Path,
    out: Option<&Path>,
    config: DetectorConfig,
    check: Check,
) -> Result<bool, String> {
    let mut sink = LineSink::new(out)?;
    // The tracker's form of the detector: (box, score) pairs, what the cascade takes.
    let mut det = ModelDetector::new(config).map_err(|e| e.to_string())?;
    let mut accepted = Vec::new();
    let mut scratch = FaceLandmarks::default();
    let mut m3 = if check != Check::None {
        Some(M3::new().map_err(|e| e.to_string())?)
    } else {
        None
    };
    let base = input.parent().unwrap_or(Path::new("."));
    let mut found = Vec::new();
    let mut ok = true;
    for (n, text) in read_lines(input)? {
        let res = (|| -> Result<Value, String> {
            let line: LineIn =
                serde_json::from_str(&text).map_err(|e| format!("malformed JSON: {e}"))?;
            let path = base.join(&line.image);
            let mut img = GrayImage::default();
            crate::luma::load_luma(&path, &mut img)?;
            let t0 = Instant::now();
            det.detect(&img, &mut found).map_err(|e| e.to_string())?;
            let us = t0.elapsed().as_micros() as u64;
            let mut faces = Vec::with_capacity(found.len());
            let mut timings = json!({"detect": us});
            match (check, m3.as_mut()) {
                (Check::Cascade, Some(m3)) => {
                    let t1 = Instant::now();
                    check_detections(
                        m3,
                        &img,
                        &mut found,
                        DEFAULT_MIN_DETECTION_CONFIDENCE,
                        &mut scratch,
                        &mut accepted,
                    )
                    .map_err(|e| e.to_string())?;
                    timings["check"] = json!(t1.elapsed().as_micros() as u64);
                    for &(r, score, prob, _) in &accepted {
                        faces.push(json!({
                            "box": [round2(r.x), round2(r.y), round2(r.w), round2(r.h)],
                            "score": round4(score),
                            "face_prob": round4(prob),
                        }));
                    }
                }
                (_, mut m3) => {
                    for &(r, score) in &found {
                        let mut face = json!({
                            "box": [round2(r.x), round2(r.y), round2(r.w), round2(r.h)],
                            "score": round4(score),
                        });
                        if let Some(m3) = m3.as_deref_mut() {
                            let p = m3.face_confidence(&img, &r).map_err(|e| e.to_string())?;
                            face["face_prob"] = json!(round4(p));
                        }
                        faces.push(face);
                    }
                }
            }
            Ok(json!({
                "image": line.image, "width": img.width(), "height": img.height(),
                "faces": faces, "timings_us": timings,
            }))
        })();
        let v = res.unwrap_or_else(|e| {
            eprintln!("{}:{n}: {e}", input.display());
            ok = false;
            json!({"line": n, "error": e})
        });
        sink.write(&v)?;
    }
    Ok(ok)
}
