//! The shared benchmark: the same code runs from the desktop CLI (`monotrack bench`) and, through
//! the FFI's `run_benchmark`, inside the Android and iOS benchmark apps, so per-stage numbers from
//! a phone and from a desktop are comparable (thesis Tables 4.4/4.5).
//!
//! One frame is processed `iterations` times on the tracking path (video mode: the first call
//! detects, every later one tracks the face by NCC) and `iterations` times on the re-detect path
//! (image mode: whole-frame detection every call), then `iterations` times on the tracking path
//! with M3 in its mirror-average mode (`models/M3_IO.md`), whose cost on a phone decides whether
//! to turn it on there. Each stage's median, 90th percentile and mean are reported in
//! microseconds.
//!
//! [`run_camera_benchmark`] measures what a user's app sees: camera frames as phones deliver them
//! (NV21 in sensor orientation on Android, NV12 on iOS, a Y plane, RGBA), converted and tracked
//! frame after frame on a clip with a moving face ([`clip`]), from the camera bytes to the result.

pub mod clip;

use crate::camera::Rotation;
use crate::error::{Error, Result};
use crate::image::{Frame, FrameDesc, GrayImage, PixelFormat};
use crate::track::{FaceState, Mode, StageTimings, Tracker, TrackerConfig};
use std::time::Instant;

/// Most iterations a benchmark accepts (keeps a device run bounded).
pub const MAX_ITERATIONS: u32 = 100_000;

/// One stage's statistics, microseconds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StageStat {
    /// Stage name (`tracking/landmarks`, `redetect/total`, ...).
    pub name: String,
    /// Median.
    pub median_us: f64,
    /// 90th percentile.
    pub p90_us: f64,
    /// Mean.
    pub mean_us: f64,
}

/// What [`run_benchmark`] measured.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BenchReport {
    /// Iterations per path.
    pub iterations: u32,
    /// Faces found on the frame (0 means the stages after the detector did not run).
    pub faces: u32,
    /// Model load + plan optimisation time, microseconds (once per tracker).
    pub load_us: f64,
    /// Per-stage statistics: `tracking/*`, `redetect/*`, then `tracking_mirror_average/*`.
    pub stages: Vec<StageStat>,
}

fn stats(name: &str, v: &mut [u64]) -> StageStat {
    v.sort_unstable();
    let n = v.len().max(1);
    let pick = |q: f64| {
        v.get(((n - 1) as f64 * q).round() as usize)
            .copied()
            .unwrap_or(0) as f64
    };
    StageStat {
        name: name.to_string(),
        median_us: pick(0.5),
        p90_us: pick(0.9),
        mean_us: v.iter().sum::<u64>() as f64 / n as f64,
    }
}

fn push_stages(prefix: &str, runs: &[StageTimings], out: &mut Vec<StageStat>) {
    type Get = fn(&StageTimings) -> u64;
    let fields: [(&str, Get); 7] = [
        ("image", |t| t.image_us),
        ("region", |t| t.region_us),
        ("detect", |t| t.detect_us),
        ("landmarks", |t| t.landmarks_us),
        ("flow", |t| t.flow_us),
        ("fit", |t| t.fit_us),
        ("total", |t| t.total_us),
    ];
    for (name, get) in fields {
        let mut v: Vec<u64> = runs.iter().map(get).collect();
        out.push(stats(&format!("{prefix}/{name}"), &mut v));
    }
}

/// Runs the tracking path, the re-detect path and the tracking path in mirror-average mode
/// `iterations` times each on `frame`.
///
/// # Errors
/// [`Error::InvalidConfig`] for 0 or more than [`MAX_ITERATIONS`] iterations; model-load and
/// frame errors pass through.
pub fn run_benchmark(
    frame: &Frame<'_>,
    iterations: u32,
    config: &TrackerConfig,
) -> Result<BenchReport> {
    if iterations == 0 || iterations > MAX_ITERATIONS {
        return Err(Error::InvalidConfig(format!(
            "iterations must be 1..={MAX_ITERATIONS}, got {iterations}"
        )));
    }
    let t0 = Instant::now();
    let mut video = Tracker::with_default_models(TrackerConfig {
        mode: Mode::Video,
        ..*config
    })?;
    let load_us = t0.elapsed().as_micros() as f64;
    let mut image = Tracker::with_default_models(TrackerConfig {
        mode: Mode::Image,
        ..*config
    })?;
    // The same landmark work on both paths, so that their ratio is the region's cost; what mirror
    // average (image mode's default) adds is the `tracking_mirror_average` stages' difference.
    image.estimator_mut().set_mirror_average(false);
    let mut mirrored = Tracker::with_default_models(TrackerConfig {
        mode: Mode::Video,
        ..*config
    })?;
    mirrored.estimator_mut().set_mirror_average(true);
    let mut tracking = Vec::with_capacity(iterations as usize);
    let mut redetect = Vec::with_capacity(iterations as usize);
    let mut tracking_mirrored = Vec::with_capacity(iterations as usize);
    // Warm-up: the first video call detects; buffers reach their size.
    let faces = video.process_frame(frame, 0)?.faces.len() as u32;
    image.process_frame(frame, 0)?;
    mirrored.process_frame(frame, 0)?;
    for i in 0..iterations {
        let ts = 1 + i64::from(i);
        tracking.push(video.process_frame(frame, ts)?.timings);
        redetect.push(image.process_frame(frame, ts)?.timings);
        tracking_mirrored.push(mirrored.process_frame(frame, ts)?.timings);
    }
    let mut stages = Vec::with_capacity(21);
    push_stages("tracking", &tracking, &mut stages);
    push_stages("redetect", &redetect, &mut stages);
    push_stages("tracking_mirror_average", &tracking_mirrored, &mut stages);
    Ok(BenchReport {
        iterations,
        faces,
        load_us,
        stages,
    })
}

/// Frame period of the benchmark clip (30 fps), nanoseconds.
const FRAME_NS: i64 = 33_333_333;

/// Most frames [`run_camera_benchmark`] accepts.
pub const MAX_CLIP_FRAMES: u32 = 100_000;

/// One stage's median and 90th percentile, microseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Percentiles {
    /// Median.
    pub median_us: f64,
    /// 90th percentile.
    pub p90_us: f64,
}

/// Per-stage times of one kind of frame: camera bytes → upright luma (`convert`), finding the
/// face region (`region`: NCC + face check on tracked frames, the detector and its checks on
/// detected ones), M3 (`landmarks`), the optical-flow filter (`flow`), the 3D fit (`fit`), and
/// the whole call (`total`).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct FrameStages {
    /// Camera bytes → upright luma.
    pub convert: Percentiles,
    /// Face region.
    pub region: Percentiles,
    /// Landmarks.
    pub landmarks: Percentiles,
    /// Optical-flow filter.
    pub flow: Percentiles,
    /// 3D fit.
    pub fit: Percentiles,
    /// The whole call, camera bytes to result.
    pub total: Percentiles,
}

impl FrameStages {
    fn of(runs: &[StageTimings]) -> Self {
        let pick = |get: fn(&StageTimings) -> u64| {
            let mut v: Vec<u64> = runs.iter().map(get).collect();
            let s = stats("", &mut v);
            Percentiles {
                median_us: s.median_us,
                p90_us: s.p90_us,
            }
        };
        Self {
            convert: pick(|t| t.image_us),
            region: pick(|t| t.region_us),
            landmarks: pick(|t| t.landmarks_us),
            flow: pick(|t| t.flow_us),
            fit: pick(|t| t.fit_us),
            total: pick(|t| t.total_us),
        }
    }
}

/// The Android back camera held in portrait, the benchmark's default camera: 640×480 NV21 in
/// sensor orientation, turned 90° to make it upright.
pub fn android_portrait_camera() -> FrameDesc {
    FrameDesc {
        rotation: Rotation::R90,
        ..FrameDesc::packed(640, 480, PixelFormat::Nv21)
    }
}

/// What [`run_camera_benchmark`] measured (the CLI's `monotrack bench --json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CameraBenchReport {
    /// Which kernel forms ran (`native` or `portable`, [`crate::kernels::kernel_path`]).
    pub path: &'static str,
    /// The CPU, in words ([`crate::kernels::cpu::cpu_name`]).
    pub cpu: String,
    /// Frames in the clip.
    pub frames: u32,
    /// Building the tracker — the embedded networks read, wired and optimised, the detector's
    /// first plan — the first time in this process, microseconds (what an app waits once).
    pub model_load_us: f64,
    /// Frames whose every face was tracked (video mode, the fast tracker).
    pub tracked: FrameStages,
    /// Frames that ran the whole-frame detector and found the face (the clip again in image
    /// mode, M3 single-pass as on tracked frames).
    pub detected: FrameStages,
}

/// Runs the face pipeline on a clip of `frames` frames made from the face picture `source`
/// ([`clip::render`], with a blank frame in the middle), each frame laid out as `camera`
/// describes ([`clip::encode`]; any format, strides and orientation):
/// once in video mode (the tracked frames' stages) and once in image mode (every frame detected).
/// Rendering and laying out happen outside the timed calls.
///
/// # Errors
/// [`Error::InvalidConfig`] for fewer than 2 or more than [`MAX_CLIP_FRAMES`] frames, or a clip
/// on which no frame was tracked or detected; frame and model errors pass through.
pub fn run_camera_benchmark(
    source: &GrayImage,
    camera: &FrameDesc,
    frames: u32,
    config: &TrackerConfig,
) -> Result<CameraBenchReport> {
    if !(2..=MAX_CLIP_FRAMES).contains(&frames) {
        return Err(Error::InvalidConfig(format!(
            "frames must be 2..={MAX_CLIP_FRAMES}, got {frames}"
        )));
    }
    let desc = *camera;
    desc.required_len()?;
    let (ow, oh) = desc.upright_size();
    let cut = Some(frames as usize / 2);
    let (mut upright, mut buf) = (GrayImage::default(), Vec::new());
    let mut model_load_us = 0.0;
    let mut pass = |mode: Mode| -> Result<Vec<StageTimings>> {
        let t0 = Instant::now();
        let mut tracker = Tracker::with_default_models(TrackerConfig { mode, ..*config })?;
        if mode == Mode::Video {
            model_load_us = t0.elapsed().as_secs_f64() * 1e6;
        }
        tracker.estimator_mut().set_mirror_average(false);
        let mut kept = Vec::with_capacity(frames as usize);
        for t in 0..frames as usize {
            clip::render(source, t, cut, ow, oh, &mut upright);
            clip::encode(&upright, &desc, &mut buf)?;
            let r = tracker.process_frame(&Frame::new(&buf, desc)?, t as i64 * FRAME_NS)?;
            let want = match mode {
                Mode::Video => FaceState::Tracked,
                Mode::Image => FaceState::Detected,
            };
            if !r.faces.is_empty() && r.faces.iter().all(|f| f.state == want) {
                kept.push(r.timings);
            }
        }
        Ok(kept)
    };
    let tracked = pass(Mode::Video)?;
    let detected = pass(Mode::Image)?;
    if tracked.is_empty() || detected.is_empty() {
        return Err(Error::InvalidConfig(format!(
            "the clip gave {} tracked and {} detected frames: the source picture needs a face",
            tracked.len(),
            detected.len()
        )));
    }
    Ok(CameraBenchReport {
        path: crate::kernels::kernel_path().as_str(),
        cpu: crate::kernels::cpu::cpu_name(),
        frames,
        model_load_us: model_load_us.round(),
        tracked: FrameStages::of(&tracked),
        detected: FrameStages::of(&detected),
    })
}
