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

use crate::error::{Error, Result};
use crate::image::Frame;
use crate::track::{Mode, StageTimings, Tracker, TrackerConfig};
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
