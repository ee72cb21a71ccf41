//! `monotrack landmarks IN.jsonl [--out OUT.jsonl]`: M3 landmarks, gestures, gaze and the MSBP
//! fit for every face of every image (CONTRACT.md), M3 in mirror-average mode unless
//! `--single-pass` (still images: the mode is more accurate on given and on detected boxes,
//! `core/models/MODEL_CARD.md`; the video tracker, where it would run on every frame, stays
//! single-pass). With
//! `faces` boxes in a line, M3 runs on those boxes only (no detection); without, the SDK's
//! detection finds them (the tracker's defaults, or with `--small-faces` its small-faces operating
//! point, `track::SMALL_FACES_MIN_FACE_PX`). One output line per input line; a bad line yields
//! `{"line": N, "error": "..."}` in its place, a message on stderr, and exit status 1 at the end.
//!
//! `--landmarks gradient` is the ultra-light mode: no landmark network is loaded; the learning-free
//! gradient detector gives 32 points (`landmarks32`, `confidence32`), `landmarks68` holds those
//! with a 68-point counterpart at their index and `null` elsewhere, the fit is FFBP weighted by
//! the points' confidences, and the fields only M3 gives (yaw, gestures, gaze) are `null`.
//! Detected faces are those the detector scores at or above the tracker's detection score (no
//! face classifier runs).

use crate::json::{CameraJson, intrinsics, put_eyes, put_fit, put_point_of_gaze, put_quality};
use crate::{LineSink, read_lines};
use monotrack_core::detect::DetectorConfig;
use monotrack_core::fit::{Ffbp, FfbpConfig, Msbp, MsbpConfig};
use monotrack_core::gaze::{Target, point_of_gaze};
use monotrack_core::image::{GrayImage, Rect};
use monotrack_core::landmarks::{
    BROW_GESTURES, FaceLandmarks, GradientDetector, GradientPoints, M3, MOUTH_GESTURES, N_POINTS,
};
use monotrack_core::track::quality::{FaceEvidence, QualityConfig, SharpnessHistory, face_quality};
use monotrack_core::track::{
    DEFAULT_MIN_DETECTION_CONFIDENCE, ModelDetector, RegionDetector,
    SMALL_FACES_MIN_DETECTION_SCORE, SMALL_FACES_MIN_FACE_PX, TrackerConfig, check_detections,
    detector_config_for,
};
use serde::Deserialize;
use serde_json::{Map, Value, json};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Deserialize)]
struct FaceIn {
    #[serde(rename = "box")]
    bbox: [f32; 4],
}

#[derive(Deserialize)]
struct LineIn {
    image: String,
    camera: Option<CameraJson>,
    faces: Option<Vec<FaceIn>>,
}

/// A face to finish: its box, the detector's score (none for a given box) and, for a detected
/// face, level 1's output from the face check.
type FaceToDo = (Rect, Option<f32>, Option<FaceLandmarks>);

/// Which landmark detector a face command runs (CONTRACT.md `--landmarks`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Landmarker {
    /// The M3 networks (default).
    M3,
    /// The learning-free 32-point gradient detector with the FFBP fit (ultra-light mode).
    Gradient,
}

/// Everything reused from line to line.
struct Pipeline {
    /// M3, loaded in M3 mode only.
    m3: Option<M3>,
    gradient: GradientDetector,
    points32: GradientPoints,
    msbp: Msbp,
    ffbp: Ffbp,
    gray: GrayImage,
    lm: FaceLandmarks,
    /// Created on the first line without boxes (lines with boxes never pay for it).
    detector: Option<ModelDetector>,
    /// The detector's faces (box, score), as the tracker's [`RegionDetector`] gives them.
    candidates: Vec<(Rect, f32)>,
    accepted: Vec<(Rect, f32, f32, FaceLandmarks)>,
    /// Detect at the small-faces operating point.
    small_faces: bool,
}

impl Pipeline {
    /// Face boxes, scores and level-1 outputs of the whole image, found as the tracker finds them
    /// (default settings).
    fn detect(&mut self) -> Result<Vec<FaceToDo>, String> {
        if self.detector.is_none() {
            // The tracker's cascade: candidates down to its detection score, accepted by M3's
            // face check at its detection confidence; the defaults or the small-faces point.
            let (tracker, detector) = if self.small_faces {
                (
                    TrackerConfig {
                        min_detection_score: SMALL_FACES_MIN_DETECTION_SCORE,
                        ..Default::default()
                    },
                    DetectorConfig {
                        min_face_px: SMALL_FACES_MIN_FACE_PX,
                        ..Default::default()
                    },
                )
            } else {
                (TrackerConfig::default(), DetectorConfig::default())
            };
            let config = detector_config_for(&tracker, detector);
            self.detector = Some(ModelDetector::new(config).map_err(|e| e.to_string())?);
        }
        let det = self.detector.as_mut().ok_or("detector unavailable")?;
        det.detect(&self.gray, &mut self.candidates)
            .map_err(|e| e.to_string())?;
        let Some(m3) = self.m3.as_mut() else {
            // Ultra-light: no face classifier; the detector's score decides, as the tracker's
            // cascade's first gate does.
            let min = if self.small_faces {
                SMALL_FACES_MIN_DETECTION_SCORE
            } else {
                TrackerConfig::default().min_detection_score
            };
            return Ok(self
                .candidates
                .iter()
                .filter(|c| c.1 >= min)
                .map(|&(rect, score)| (rect, Some(score), None))
                .collect());
        };
        // As in the tracker: a detection must also pass M3's face classifier, which rejects the
        // face-like clutter the compact detector scores high (core/models/MODEL_CARD.md), on the
        // box of level 1's points. The check's level-1 output is kept, so an accepted face only
        // needs level 2 (`M3::refine`), as in the tracker.
        check_detections(
            m3,
            &self.gray,
            &mut self.candidates,
            DEFAULT_MIN_DETECTION_CONFIDENCE,
            &mut self.lm,
            &mut self.accepted,
        )
        .map_err(|e| e.to_string())?;
        let faces = self
            .accepted
            .iter()
            .map(|&(rect, score, _, level1)| (rect, Some(score), Some(level1)))
            .collect();
        Ok(faces)
    }
}

fn round(v: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (v * p).round() / p
}

fn probs(names: &[&str], p: &[f32]) -> Value {
    Value::Object(
        names
            .iter()
            .zip(p)
            .map(|(n, v)| (n.to_string(), json!(round(f64::from(*v), 4))))
            .collect(),
    )
}

fn vec3(v: &[f32; 3]) -> Value {
    json!(
        v.iter()
            .map(|x| round(f64::from(*x), 4))
            .collect::<Vec<_>>()
    )
}

/// The CONTRACT's FACE object without the fit fields. A point the estimator does not measure
/// (weight 0: the gradient detector has 27 of the 68) is `null`, and with such points the fields
/// only M3 gives are `null` too.
fn face_json(rect: &Rect, score: f32, lm: &FaceLandmarks) -> Map<String, Value> {
    let mut face = Map::new();
    face.insert(
        "box".into(),
        json!([rect.x, rect.y, rect.w, rect.h].map(|v| round(f64::from(v), 2))),
    );
    face.insert("score".into(), json!(round(f64::from(score), 4)));
    face.insert(
        "landmarks68".into(),
        json!(
            lm.points
                .iter()
                .zip(&lm.weights)
                .map(|(p, w)| if *w == 0.0 {
                    Value::Null
                } else {
                    json!([round(f64::from(p[0]), 3), round(f64::from(p[1]), 3)])
                })
                .collect::<Vec<_>>()
        ),
    );
    face.insert("face_prob".into(), json!(round(f64::from(lm.face_prob), 4)));
    put_eyes(&mut face, &lm.points, &lm.weights);
    if lm.weights.contains(&0.0) {
        for k in ["yaw_class_deg", "yaw_probs", "gestures", "gaze"] {
            face.insert(k.into(), Value::Null);
        }
        return face;
    }
    face.insert("yaw_class_deg".into(), json!(lm.yaw_class_deg()));
    face.insert(
        "yaw_probs".into(),
        json!(
            lm.yaw_probs
                .iter()
                .map(|p| round(f64::from(*p), 4))
                .collect::<Vec<_>>()
        ),
    );
    face.insert(
        "gestures".into(),
        json!({"mouth": probs(&MOUTH_GESTURES, &lm.mouth), "brows": probs(&BROW_GESTURES, &lm.brows)}),
    );
    face.insert(
        "gaze".into(),
        json!({"left": vec3(&lm.gaze_left), "right": vec3(&lm.gaze_right),
               "combined": vec3(&lm.gaze_combined)}),
    );
    face
}

/// [`face_json`] of the gradient detector's face, with its own 32 points, their confidences and
/// the roll it found.
fn gradient_face_json(
    rect: &Rect,
    score: f32,
    lm: &FaceLandmarks,
    g: &GradientPoints,
) -> Map<String, Value> {
    let mut face = face_json(rect, score, lm);
    face.insert(
        "landmarks32".into(),
        json!(
            g.points
                .iter()
                .map(|p| [round(f64::from(p[0]), 3), round(f64::from(p[1]), 3)])
                .collect::<Vec<_>>()
        ),
    );
    face.insert(
        "confidence32".into(),
        json!(
            g.confidence
                .iter()
                .map(|c| round(f64::from(*c), 3))
                .collect::<Vec<_>>()
        ),
    );
    face.insert("roll_deg".into(), json!(round(f64::from(g.roll_deg), 2)));
    face
}

/// A still's face quality, as the tracker judges a face in image mode (no recent frames).
fn still_quality(
    gray: &GrayImage,
    lm: &FaceLandmarks,
    fit: &monotrack_core::fit::FaceFit,
    m3: bool,
) -> monotrack_core::track::quality::FaceQuality {
    face_quality(
        gray,
        &FaceEvidence::of(lm, fit, m3),
        &QualityConfig::default(),
        &mut SharpnessHistory::default(),
    )
}

fn landmarks_line(
    text: &str,
    base: &Path,
    p: &mut Pipeline,
    targets: Option<&[Target]>,
) -> Result<Value, String> {
    let t_start = Instant::now();
    let line: LineIn = serde_json::from_str(text).map_err(|e| format!("malformed JSON: {e}"))?;
    let path = {
        let pb = PathBuf::from(&line.image);
        if pb.is_absolute() { pb } else { base.join(pb) }
    };
    crate::luma::load_luma(&path, &mut p.gray)?;
    let (w, h) = (p.gray.width() as u32, p.gray.height() as u32);
    let cam = intrinsics(line.camera, w, h).map_err(|e| e.to_string())?;
    let t_detect = Instant::now();
    let boxes: Vec<FaceToDo> = match &line.faces {
        Some(faces) => faces
            .iter()
            .map(|f| {
                let [x, y, bw, bh] = f.bbox;
                (Rect::new(x, y, bw, bh), None, None)
            })
            .collect(),
        None => p.detect()?,
    };
    let detect_us = if line.faces.is_some() {
        0
    } else {
        t_detect.elapsed().as_micros() as u64
    };
    let (mut landmarks_us, mut fit_us) = (0u64, 0u64);
    let mut faces = Vec::with_capacity(boxes.len());
    for (k, (rect, det_score, checked)) in boxes.iter().enumerate() {
        let t0 = Instant::now();
        let Some(m3) = p.m3.as_mut() else {
            p.gradient
                .detect(&p.gray, rect, 0.0, &mut p.points32)
                .map_err(|e| format!("face {k}: {e}"))?;
            p.points32.to_landmarks(&mut p.lm);
            landmarks_us += t0.elapsed().as_micros() as u64;
            let (mut pts, mut w) = ([[0.0f64; 2]; N_POINTS], [0.0f64; N_POINTS]);
            for ((d, wd), (s, ws)) in pts
                .iter_mut()
                .zip(&mut w)
                .zip(p.lm.points.iter().zip(&p.lm.weights))
            {
                *d = [f64::from(s[0]), f64::from(s[1])];
                *wd = f64::from(*ws);
            }
            let t1 = Instant::now();
            let fit = p
                .ffbp
                .fit(&pts, Some(&w), &cam)
                .map_err(|e| format!("face {k}: fit: {e}"))?;
            fit_us += t1.elapsed().as_micros() as u64;
            let mut face = gradient_face_json(
                rect,
                det_score.unwrap_or(p.lm.face_prob),
                &p.lm,
                &p.points32,
            );
            put_fit(&mut face, &fit);
            put_quality(&mut face, &still_quality(&p.gray, &p.lm, &fit, false));
            faces.push(Value::Object(face));
            continue;
        };
        // A detected face's level 1 ran in the face check (timed under `detect`).
        match checked {
            Some(level1) => {
                p.lm = *level1;
                m3.refine(&p.gray, &mut p.lm)
            }
            None => m3.estimate(&p.gray, rect, &mut p.lm),
        }
        .map_err(|e| format!("face {k}: {e}"))?;
        landmarks_us += t0.elapsed().as_micros() as u64;
        let mut pts = [[0.0f64; 2]; N_POINTS];
        for (d, s) in pts.iter_mut().zip(&p.lm.points) {
            *d = [f64::from(s[0]), f64::from(s[1])];
        }
        let t1 = Instant::now();
        let fit = p
            .msbp
            .fit(&pts, None, &cam, None)
            .map_err(|e| format!("face {k}: fit: {e}"))?;
        fit_us += t1.elapsed().as_micros() as u64;
        // Given boxes have no detection score: the level-1 face confidence stands in for it.
        let mut face = face_json(rect, det_score.unwrap_or(p.lm.face_prob), &p.lm);
        put_fit(&mut face, &fit);
        put_quality(&mut face, &still_quality(&p.gray, &p.lm, &fit, true));
        if let Some(t) = targets {
            // A still: no calibration, no filter.
            let g = point_of_gaze(
                &p.lm,
                &fit,
                &Default::default(),
                &Default::default(),
                None,
                t,
            );
            put_point_of_gaze(&mut face, &g, t);
        }
        faces.push(Value::Object(face));
    }
    Ok(json!({
        "image": line.image, "width": w, "height": h, "faces": faces,
        "timings_us": {"detect": detect_us, "landmarks": landmarks_us, "fit": fit_us,
                       "total": t_start.elapsed().as_micros() as u64},
    }))
}

/// Runs the subcommand (M3 in mirror-average mode with `mirror_average`, detection at the
/// small-faces operating point with `small_faces`); returns whether every
/// line succeeded.
pub fn run(
    input: &Path,
    out: Option<&Path>,
    mirror_average: bool,
    small_faces: bool,
    targets: Option<&Path>,
    landmarker: Landmarker,
) -> Result<bool, String> {
    let targets = targets.map(crate::json::load_targets).transpose()?;
    if targets.is_some() && landmarker == Landmarker::Gradient {
        return Err("--targets needs the eyes' gaze, which only --landmarks m3 gives".into());
    }
    let lines = read_lines(input)?;
    let base = input
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."));
    let mut sink = LineSink::new(out)?;
    let mut p = Pipeline {
        m3: match landmarker {
            Landmarker::M3 => Some(M3::new().map_err(|e| e.to_string())?),
            Landmarker::Gradient => None,
        },
        gradient: GradientDetector::new(),
        points32: GradientPoints::default(),
        msbp: Msbp::new(MsbpConfig::default()),
        ffbp: Ffbp::new(FfbpConfig::default()),
        gray: GrayImage::default(),
        lm: FaceLandmarks::default(),
        detector: None,
        candidates: Vec::new(),
        accepted: Vec::new(),
        small_faces,
    };
    if let Some(m3) = p.m3.as_mut() {
        m3.set_mirror_average(mirror_average);
    }
    let mut ok = true;
    for (n, text) in lines {
        let v = landmarks_line(&text, &base, &mut p, targets.as_deref()).unwrap_or_else(|e| {
            eprintln!("{}:{n}: {e}", input.display());
            ok = false;
            json!({"line": n, "error": e})
        });
        sink.write(&v)?;
    }
    Ok(ok)
}
