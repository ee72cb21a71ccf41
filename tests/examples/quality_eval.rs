//! The quality reasons on clips made to have each fault (`monotrack_tests::qualityeval`), and the
//! turned reason on the annotated faces that are turned, with the cost of judging quality.
//!
//! ```text
//! cargo run --profile bench -p monotrack-tests --example quality_eval -- [--out FILE] [--clips N]
//! ```
//! Per fault: one clip of 10 frames per validation face (faces68, 68-point box ≥ 100 px), the
//! rate at which the fault's reason fires (on clean clips: any reason), the frames with a face,
//! and every reason's count. Turned: no clip can turn a photographed head, so the faces of both
//! faces68 splits whose annotated 68 points fit (MSBP) to more than the thresholds' yaw or pitch
//! run as stills (image mode), and the rate at which `turned` fires on them is reported, with the
//! same rate on the faces fitted within 15° of frontal. Cost: the quality of one face and of one
//! frame, timed over repeated calls on a validation face at 640×480 (`quality::face_quality`,
//! `quality::frame_reasons`; the same code on every kernel path). Writes `metrics/quality_eval.json`.

use monotrack_core::camera::Intrinsics;
use monotrack_core::fit::{Msbp, MsbpConfig};
use monotrack_core::image::Rect;
use monotrack_core::model::N_LANDMARKS;
use monotrack_core::track::quality::{
    FaceEvidence, QualityConfig, QualityReason, SharpnessHistory, face_quality, frame_reasons,
};
use monotrack_core::track::{Mode, Tracker, TrackerConfig};
use monotrack_tests::qualityeval::{Fault, run_fault};
use monotrack_tests::shared_data;
use monotrack_tests::synth::{Sequence, load_split_faces, load_validation_faces};
use serde_json::{Map, Value, json};
use std::time::Instant;

fn round(v: f64, d: i32) -> f64 {
    let p = 10f64.powi(d);
    (v * p).round() / p
}

/// (faces past the thresholds, of them with `turned`, frontal faces, of them with `turned`).
fn turned(data: &std::path::Path) -> (usize, usize, usize, usize, usize) {
    let cfg = QualityConfig::default();
    let mut msbp = Msbp::new(MsbpConfig::default());
    let mut tracker = Tracker::with_default_models(TrackerConfig {
        mode: Mode::Image,
        ..TrackerConfig::default()
    })
    .unwrap();
    tracker.estimator_mut().set_mirror_average(false);
    let (mut n_turned, mut fired, mut n_frontal, mut frontal_fired, mut found) = (0, 0, 0, 0, 0);
    for validation in [false, true] {
        for f in load_split_faces(data, validation, usize::MAX, 0.0).unwrap() {
            let cam =
                Intrinsics::default_for(f.image.width() as u32, f.image.height() as u32).unwrap();
            let mut pts = [[0.0f64; 2]; N_LANDMARKS];
            for (o, p) in pts.iter_mut().zip(&f.landmarks) {
                *o = [f64::from(p[0]), f64::from(p[1])];
            }
            let (yaw, pitch, _) = msbp.fit(&pts, None, &cam, None).unwrap().pose.euler_deg();
            let is_turned = yaw.abs() > f64::from(cfg.max_yaw_deg)
                || pitch.abs() > f64::from(cfg.max_pitch_deg);
            let is_frontal = yaw.abs() < 15.0 && pitch.abs() < 15.0;
            if !(is_turned || is_frontal) {
                continue;
            }
            let truth = Rect::bounding(&f.landmarks);
            let r = tracker.process(&f.image, 0).unwrap();
            let hit = r
                .faces
                .iter()
                .filter(|x| Rect::bounding(&x.landmarks.points).iou(&truth) >= 0.3)
                .any(|x| x.quality.reasons.contains(QualityReason::Turned));
            let any = r
                .faces
                .iter()
                .any(|x| Rect::bounding(&x.landmarks.points).iou(&truth) >= 0.3);
            if is_turned {
                n_turned += 1;
                fired += usize::from(hit);
                found += usize::from(any);
            } else {
                n_frontal += 1;
                frontal_fired += usize::from(hit);
            }
        }
    }
    (n_turned, fired, found, n_frontal, frontal_fired)
}

/// Mean microseconds of one face's quality and of one frame's reasons.
fn cost(faces: &[monotrack_tests::synth::FaceSample]) -> (f64, f64) {
    let seq = Sequence::new(
        monotrack_tests::qualityeval::clip_config(Fault::Clean, 2, 3),
        faces.to_vec(),
    )
    .unwrap();
    let mut img = Default::default();
    let truth = seq.render(0, &mut img);
    let cfg = QualityConfig::default();
    let lm = monotrack_core::landmarks::FaceLandmarks {
        points: truth.landmarks,
        face_prob: 1.0,
        ..Default::default()
    };
    let evidence = FaceEvidence {
        points: &lm.points,
        yaw_pitch_deg: (5.0, 3.0),
        face_probability: 1.0,
        fit_rms_px: 2.0,
    };
    let n = 20_000;
    let mut h = SharpnessHistory::default();
    let t = Instant::now();
    let mut acc = 0.0f32;
    for _ in 0..n {
        acc += face_quality(&img, std::hint::black_box(&evidence), &cfg, &mut h).score;
    }
    let face_us = t.elapsed().as_secs_f64() * 1e6 / f64::from(n);
    let mut h = SharpnessHistory::default();
    let t = Instant::now();
    let mut bits = 0usize;
    for _ in 0..n {
        bits += frame_reasons(std::hint::black_box(&img), &cfg, &mut h, 1, false)
            .iter()
            .count();
    }
    let frame_us = t.elapsed().as_secs_f64() * 1e6 / f64::from(n);
    std::hint::black_box((acc, bits));
    (face_us, frame_us)
}

/// The metrics file's `cost`: the two figures with the profile, CPU and kernel path they were
/// measured with, and the command that measures them alone.
fn cost_entry(face_us: f64, frame_us: f64) -> Value {
    let profile = if cfg!(debug_assertions) {
        "test"
    } else {
        "bench"
    };
    let path = monotrack_core::kernels::kernel_path().as_str();
    json!({
        "face_us": round(face_us, 3),
        "frame_us": round(frame_us, 3),
        "profile": profile,
        "cpu": monotrack_core::kernels::cpu_name(),
        "path": path,
        "command": format!("MONOTRACK_KERNELS={path} cargo run --profile {profile} -p monotrack-tests --example quality_eval -- --cost-only"),
    })
}

/// `--cost-only`: measures what judging quality costs and writes it into the metrics file's
/// `cost`, leaving the fire rates as they are. Run it in the bench profile with
/// `MONOTRACK_KERNELS=portable` for the figure MODEL_CARD gives (quality has no kernel of its own:
/// the path is named so the figure sits beside the frame's on that path).
fn write_cost(path: &std::path::Path, faces: &[monotrack_tests::synth::FaceSample]) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut metrics: Value = serde_json::from_str(&text).unwrap();
    // The lower of three runs: the machine's other load only adds.
    let (mut face_us, mut frame_us) = (f64::MAX, f64::MAX);
    for _ in 0..3 {
        let (f, fr) = cost(faces);
        face_us = face_us.min(f);
        frame_us = frame_us.min(fr);
    }
    let cost = cost_entry(face_us, frame_us);
    println!(
        "cost: {face_us:.2} µs per face, {frame_us:.2} µs per frame ({})",
        cost["profile"]
    );
    metrics["cost"] = cost;
    std::fs::write(path, serde_json::to_string_pretty(&metrics).unwrap() + "\n")
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    println!("wrote {}", path.display());
}

fn main() {
    let mut out = "metrics/quality_eval.json".to_string();
    let mut clips: Option<usize> = None;
    let mut cost_only = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = args.next().expect("--out FILE"),
            "--clips" => clips = Some(args.next().expect("--clips N").parse().expect("N")),
            "--cost-only" => cost_only = true,
            _ => panic!("unknown argument {a}"),
        }
    }
    let data = shared_data();
    let faces = load_validation_faces(&data, usize::MAX, 100.0).unwrap();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    if cost_only {
        write_cost(&root.join(&out), &faces);
        return;
    }
    let clips = clips.unwrap_or(faces.len());
    println!("{} validation faces, {clips} clips per fault", faces.len());
    println!("| fault | frames | with a face | fires | mean score | every reason's count |");
    println!("|---|---|---|---|---|---|");
    let mut per_fault = Map::new();
    for fault in Fault::ALL {
        let s = run_fault(fault, &faces, clips, TrackerConfig::default(), 11).unwrap();
        let counts: Map<String, Value> = QualityReason::ALL
            .iter()
            .zip(s.per_reason)
            .filter(|(_, n)| *n > 0)
            .map(|(r, n)| (r.name().to_string(), json!(n)))
            .collect();
        println!(
            "| {} | {} | {} | {:.1} % | {:.3} | {} |",
            fault.name(),
            s.frames,
            s.with_face,
            100.0 * s.rate(),
            s.mean_score,
            Value::Object(counts.clone())
        );
        per_fault.insert(
            fault.name().to_string(),
            json!({"frames": s.frames, "with_face": s.with_face, "fired": s.fired,
                   "rate": round(s.rate(), 4), "mean_score": round(s.mean_score, 4),
                   "reasons": counts}),
        );
    }
    let (n_turned, fired, found, n_frontal, frontal_fired) = turned(&data);
    println!(
        "turned: {fired} of {n_turned} faces fitted past the thresholds ({found} found); on {n_frontal} faces within 15° of frontal, {frontal_fired}"
    );
    let (face_us, frame_us) = cost(&faces);
    println!(
        "cost: {face_us:.2} µs per face, {frame_us:.2} µs per frame (this CPU, any kernel path)"
    );
    let metrics = json!({
        "what": "quality reasons on synthetic clips of faces68 validation faces made to have each fault (tests/src/qualityeval.rs); a fault fires when its reason is among the first face's or the frame's reasons; clean: any reason",
        "command": format!("cargo run -p monotrack-tests --example quality_eval -- --clips {clips} (the {} profile)", if cfg!(debug_assertions) { "test" } else { "bench" }),
        "clips_per_fault": clips,
        "frames_per_clip": monotrack_tests::qualityeval::CLIP_FRAMES,
        "faults": per_fault,
        "turned": {"faces_past_thresholds": n_turned, "found": found, "fired": fired,
                   "frontal_faces": n_frontal, "frontal_fired": frontal_fired},
        "cost": cost_entry(face_us, frame_us),
    });
    let path = root.join(&out);
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&metrics).unwrap() + "\n",
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    println!("wrote {}", path.display());
}
