//! Tracking measurements with the shipped models (detector + M3 + MSBP): correct-frame
//! rate, per-frame time per stage and still-face jitter for tracking vs re-detect-every-frame, on
//! synthetic sequences made from faces68 validation images and, optionally, on a real video scored
//! against reference landmarks.
//!
//! ```text
//! cargo run --profile bench -p monotrack-tests --example track_eval -- \
//!     [--video ../shared/data/video/obama_3ddfa_demo.mp4 --reference REF.jsonl] [--mirror-average]
//!     [--only ROW] [--passes N] [--camera-frames] [--ultra-light]
//!     [--scale A] [--roll DEG] [--roll-offset DEG] [--translation PX] [--period FRAMES]
//!     [--segments N] [--brightness A] [--blur] [--flow-pull P] [--plain-lk]
//!     [--min-face-confidence C] [--min-detection-confidence C] [--min-redetection-confidence C]
//! ```
//! `--ultra-light` runs the ultra-light mode's rows instead (`TrackerConfig::ultra_light`:
//! tracking, tracking with the flow filter off, and re-detect every frame). Each row's `box IoU`
//! is the reported region's mean overlap with the truth's box (the tight box of its 68 points):
//! how well the region follows the face's place and size, apart from the landmarks. The synthetic motion's relative scale amplitude
//! (`--scale`, default 0.12), roll amplitude (`--roll`, default 12°), translation amplitude
//! (`--translation`, default 50 px) and shortest period (`--period`, default 60 frames; the
//! top speed is 2π·amplitude / period per frame) can be set, and `--roll-offset` holds each
//! segment's head tilted by that much, alternately either way (default 0°). `--segments N` makes
//! the clip N segments of 60 frames long (default 6), each on one of 24 validation faces drawn at
//! random: more segments, a steadier figure. `--brightness A` swings each frame's brightness by
//! ±A over 90 frames and `--blur` box-blurs fast frames (radius a quarter of the face's motion
//! since the last frame, up to 4 px): a phone camera's exposure and smear on a moving face.
//! The clip's luma images go to `process` (every frame a buffer no earlier step read);
//! `--camera-frames` passes them as `Gray8` camera frames instead (`process_frame`, which copies
//! each into the tracker's luma buffer: the `image` column, counted in the frame's total).
//! `--mirror-average` runs M3 in its mirror-average mode (`core/models/M3_IO.md`).
//! `--flow-pull P` sets the tracking rows' `TrackerConfig::flow_pull` (0: the thesis' filter);
//! `--plain-lk` turns the flow's brightness offset off (`LkConfig::offset_invariant`).
//! `--min-face-confidence C` sets the tracking rows' `TrackerConfig::min_face_confidence` (the
//! face check a tracked window must pass) and `--min-detection-confidence C` its
//! `min_detection_confidence` (the one a new detection must pass), `--min-redetection-confidence
//! C` its `min_redetection_confidence` (the one a detection where a face was just lost must pass).
//! `--m3-dir DIR` runs M3 from the `m3.json` and network files in DIR instead of the embedded
//! ones (a training run's output), so retrained nets are measured on these clips without a rebuild.
//! `--only ROW` runs only the table's row ROW (0 = tracking, 3 = re-detect every frame) and
//! `--passes N` repeats each measured pass N times (the row shows the last), for `perf record`.
//! `REF.jsonl` comes from `tests/scripts/video_reference.py VIDEO REF.jsonl` (dlib's 68 points as
//! pseudo ground truth). Video frames are decoded with `ffmpeg` (rgb24, CONTRACT luma). Prints
//! markdown tables; timings are single-threaded means over all frames on this machine.

use monotrack_core::image::GrayImage;
use monotrack_core::image::rgb_to_contract_luma;
use monotrack_core::landmarks::M3;
use monotrack_core::track::flow::LkConfig;
use monotrack_core::track::models::Landmarker;
use monotrack_core::track::{Mode, Tracker, TrackerConfig};
use monotrack_tests::shared_data_if_present;
use monotrack_tests::synth::{SeqConfig, load_validation_faces};
use monotrack_tests::trackeval::{
    ClipFrame, Input, run_clip_with, synthetic_clip, table_header, table_row,
};
use std::io::Read;
use std::process::{Command, Stdio};

/// NME below which a frame counts as correct (see `tests/tests/track_models.rs`).
const CORRECT_NME: f32 = 0.10;

fn configs(ultra_light: bool, opt: &Options) -> Vec<(&'static str, TrackerConfig)> {
    let tune = |defaults: TrackerConfig| TrackerConfig {
        flow_pull: opt.flow_pull.unwrap_or(defaults.flow_pull),
        min_face_confidence: opt
            .min_face_confidence
            .unwrap_or(defaults.min_face_confidence),
        min_detection_confidence: opt
            .min_detection_confidence
            .unwrap_or(defaults.min_detection_confidence),
        min_redetection_confidence: opt
            .min_redetection_confidence
            .unwrap_or(defaults.min_redetection_confidence),
        lk: LkConfig {
            offset_invariant: defaults.lk.offset_invariant && !opt.plain_lk,
            ..defaults.lk
        },
        ..defaults
    };
    if ultra_light {
        let video = tune(TrackerConfig::ultra_light());
        return vec![
            ("ultra-light tracking", video),
            (
                "ultra-light tracking, flow filter off",
                TrackerConfig {
                    flow_filter: false,
                    ..video
                },
            ),
            (
                "ultra-light, re-detect every frame (image mode)",
                TrackerConfig {
                    mode: Mode::Image,
                    ..video
                },
            ),
        ];
    }
    let video = tune(TrackerConfig::default());
    vec![
        (
            "tracking (default: re-detect in the frame of a loss)",
            video,
        ),
        (
            "tracking, re-detect on the next frame (thesis)",
            TrackerConfig {
                redetect_immediately: false,
                ..video
            },
        ),
        (
            "tracking, flow filter off",
            TrackerConfig {
                flow_filter: false,
                ..video
            },
        ),
        (
            "re-detect every frame (image mode)",
            TrackerConfig {
                mode: Mode::Image,
                ..video
            },
        ),
    ]
}

/// What `main` reads from the command line besides the video.
struct Options {
    mirror_average: bool,
    ultra_light: bool,
    only: Option<usize>,
    passes: usize,
    input: Input,
    flow_pull: Option<f32>,
    plain_lk: bool,
    min_face_confidence: Option<f32>,
    min_detection_confidence: Option<f32>,
    min_redetection_confidence: Option<f32>,
    /// M3's `m3.json` and network files (file name, bytes), when not the embedded ones.
    m3_files: Option<Vec<(String, Vec<u8>)>>,
}

/// Every file in `dir` as (name, bytes): `M3::from_bytes` takes the ones `m3.json` names.
fn m3_files(dir: &str) -> Result<Vec<(String, Vec<u8>)>, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("--m3-dir {dir}: {e}"))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| e.to_string())?.path();
        if path.is_file()
            && let Some(name) = path.file_name().and_then(|n| n.to_str())
        {
            files.push((
                name.to_string(),
                std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?,
            ));
        }
    }
    Ok(files)
}

/// M3 from `files` (`m3_files`).
fn m3_from(files: &[(String, Vec<u8>)]) -> Result<M3, String> {
    let named: Vec<(&str, &[u8])> = files
        .iter()
        .map(|(n, b)| (n.as_str(), b.as_slice()))
        .collect();
    let json = named
        .iter()
        .find(|(n, _)| *n == "m3.json")
        .map(|(_, b)| *b)
        .ok_or("--m3-dir: no m3.json")?;
    M3::from_bytes(json, &named).map_err(|e| e.to_string())
}

fn report(title: &str, clip: &[ClipFrame], opt: &Options) -> Result<(), String> {
    println!("\n### {title}\n\n{}", table_header());
    for (row, (name, cfg)) in configs(opt.ultra_light, opt).into_iter().enumerate() {
        if opt.only.is_some_and(|only| only != row) {
            continue;
        }
        let mut tracker = Tracker::with_default_models(cfg).map_err(|e| e.to_string())?;
        if let Some(files) = &opt.m3_files
            && !opt.ultra_light
        {
            *tracker.estimator_mut() = Landmarker::M3(Box::new(m3_from(files)?));
        }
        tracker
            .estimator_mut()
            .set_mirror_average(opt.mirror_average);
        // Warm-up pass (plans, buffers), then the measured pass.
        let mut run =
            || run_clip_with(&mut tracker, clip, CORRECT_NME, opt.input).map_err(|e| e.to_string());
        run()?;
        let mut s = run()?;
        for _ in 1..opt.passes {
            s = run()?;
        }
        println!("{}", table_row(name, &s));
        eprintln!(
            "{name}: a face reported on {} of {} scored frames; {} frames without one where the \
             face is wholly in the frame",
            s.with_face, s.scored, s.no_face_visible
        );
    }
    Ok(())
}

fn video_clip(video: &str, reference: &str) -> Result<Vec<ClipFrame>, String> {
    let probe = Command::new("ffprobe")
        .args(["-v", "error", "-select_streams", "v:0", "-show_entries"])
        .args(["stream=width,height", "-of", "csv=p=0", video])
        .output()
        .map_err(|e| format!("ffprobe: {e}"))?;
    let dims = String::from_utf8_lossy(&probe.stdout);
    let mut it = dims.trim().split(',').map(|v| v.parse::<usize>());
    let (Some(Ok(w)), Some(Ok(h))) = (it.next(), it.next()) else {
        return Err(format!("ffprobe gave {dims:?}"));
    };
    let mut child = Command::new("ffmpeg")
        .args([
            "-v", "error", "-i", video, "-f", "rawvideo", "-pix_fmt", "rgb24", "-",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("ffmpeg: {e}"))?;
    let mut raw = Vec::new();
    child
        .stdout
        .take()
        .ok_or("no ffmpeg stdout")?
        .read_to_end(&mut raw)
        .map_err(|e| e.to_string())?;
    child.wait().map_err(|e| e.to_string())?;
    let text = std::fs::read_to_string(reference).map_err(|e| format!("{reference}: {e}"))?;
    let mut truth = Vec::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let v: serde_json::Value = serde_json::from_str(line).map_err(|e| e.to_string())?;
        let pts = v["landmarks68"].as_array().map(|a| {
            let mut p = [[0.0f32; 2]; 68];
            for (o, q) in p.iter_mut().zip(a) {
                *o = [
                    q[0].as_f64().unwrap_or(f64::NAN) as f32,
                    q[1].as_f64().unwrap_or(f64::NAN) as f32,
                ];
            }
            p
        });
        truth.push(pts);
    }
    let n = raw.len() / (w * h * 3);
    if n != truth.len() {
        return Err(format!("{n} frames but {} reference lines", truth.len()));
    }
    Ok(raw
        .chunks_exact(w * h * 3)
        .zip(truth)
        .map(|(rgb, t)| {
            let mut image = GrayImage::new(w, h);
            rgb_to_contract_luma(rgb, image.data_mut());
            ClipFrame {
                image,
                truth: t,
                still_run: None,
            }
        })
        .collect())
}

/// The value after `name` in `args`, parsed; `None` when `name` is not given.
fn parsed<T: std::str::FromStr>(args: &[String], name: &str) -> Result<Option<T>, String>
where
    T::Err: std::fmt::Display,
{
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(|v| v.parse().map_err(|e| format!("{name} {v}: {e}")))
        .transpose()
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| parsed::<String>(&args, name).ok().flatten();
    let number = |name: &str| parsed::<usize>(&args, name);
    let real = |name: &str| parsed::<f32>(&args, name);
    let opt = Options {
        mirror_average: args.iter().any(|a| a == "--mirror-average"),
        ultra_light: args.iter().any(|a| a == "--ultra-light"),
        only: number("--only")?,
        passes: number("--passes")?.unwrap_or(1).max(1),
        input: if args.iter().any(|a| a == "--camera-frames") {
            Input::Gray8Frame
        } else {
            Input::Luma
        },
        flow_pull: real("--flow-pull")?,
        plain_lk: args.iter().any(|a| a == "--plain-lk"),
        min_face_confidence: real("--min-face-confidence")?,
        min_detection_confidence: real("--min-detection-confidence")?,
        min_redetection_confidence: real("--min-redetection-confidence")?,
        m3_files: arg("--m3-dir").map(|d| m3_files(&d)).transpose()?,
    };
    println!(
        "correct frame: NME (inter-ocular) < {CORRECT_NME}; M3 mirror average {}; input {:?}; \
         {} kernels on {} (MONOTRACK_KERNELS=portable: the phone's)",
        opt.mirror_average,
        opt.input,
        monotrack_core::kernels::kernel_path().as_str(),
        monotrack_core::kernels::cpu_name()
    );
    if let Some(data) = shared_data_if_present() {
        let faces = load_validation_faces(&data, 24, 100.0)?;
        let cfg = SeqConfig::eval_clips();
        let float = |name: &str, default: f32| -> Result<f32, String> {
            Ok(real(name)?.unwrap_or(default))
        };
        let cfg = SeqConfig {
            scale_amplitude: float("--scale", cfg.scale_amplitude)?,
            rotation_deg: float("--roll", cfg.rotation_deg)?,
            roll_offset_deg: float("--roll-offset", cfg.roll_offset_deg)?,
            translation_px: float("--translation", cfg.translation_px)?,
            min_period_frames: float("--period", cfg.min_period_frames)?,
            segments: number("--segments")?.unwrap_or(cfg.segments),
            brightness_amplitude: float("--brightness", cfg.brightness_amplitude)?,
            motion_blur: args.iter().any(|a| a == "--blur"),
            ..cfg
        };
        let clip = synthetic_clip(cfg, faces)?;
        report(
            &format!(
                "synthetic: {} frames 640x480, {} segments (cuts), faces 100-200 px, sensor noise 2 grey levels",
                clip.len(),
                cfg.segments
            ),
            &clip,
            &opt,
        )?;
    } else {
        println!("../shared/data not found: synthetic sequences skipped");
    }
    if let (Some(video), Some(reference)) = (arg("--video"), arg("--reference")) {
        let clip = video_clip(&video, &reference)?;
        let (w, h) = (clip[0].image.width(), clip[0].image.height());
        report(
            &format!(
                "{video}: {} frames {w}x{h}, reference {reference}",
                clip.len()
            ),
            &clip,
            &opt,
        )?;
    }
    Ok(())
}
