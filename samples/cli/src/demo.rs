//! `monotrack demo [--overlay DIR] [--frames N]`: the README's main command. Runs the whole
//! pipeline (detector → NCC tracking → M3 → optical-flow filter → MSBP) on a sequence made from the
//! committed public-domain `samples/data/astronaut.jpg` — smooth similarity motion (translation,
//! scale, in-plane rotation) pasted into a 640×480 frame, with a cut to a blank frame and back at
//! the middle to force a re-detection (`monotrack_core::bench::clip`, the clip `monotrack bench`
//! feeds as camera frames) — writes overlay PNGs and prints a per-stage timing table.
//! Nothing is downloaded and `../shared` is not needed.

use crate::LineSink;
use crate::track::{Canvas, draw_overlay, frame_json};
use monotrack_core::TrackerConfig;
use monotrack_core::bench::clip;
use monotrack_core::camera::Intrinsics;
use monotrack_core::image::GrayImage;
use monotrack_core::track::{FaceState, StageTimings, Tracker};
use std::path::Path;

/// The committed public-domain portrait (NASA; see samples/data/README.md).
const ASTRONAUT_JPG: &[u8] = include_bytes!("../../data/astronaut.jpg");
/// Demo frame size: the VGA frames the SDK's speed targets are stated for.
const W: usize = 640;
const H: usize = 480;
/// Frame period of the synthetic clip (30 fps).
const FRAME_NS: i64 = 33_333_333;

/// The demo's source image as luma.
pub(crate) fn source() -> Result<GrayImage, String> {
    let mut out = GrayImage::default();
    crate::luma::decode_luma(ASTRONAUT_JPG, &mut out)
        .map_err(|e| format!("embedded astronaut.jpg: {e}"))?;
    Ok(out)
}

fn median(v: &mut [u64]) -> u64 {
    if v.is_empty() {
        return 0;
    }
    v.sort_unstable();
    v[v.len() / 2]
}

/// Runs the demo; overlays go to `overlay` when given, JSON lines (CONTRACT `track`) to `out`.
pub fn run(frames: usize, overlay: Option<&Path>, out: Option<&Path>) -> Result<bool, String> {
    if frames < 2 {
        return Err("--frames must be at least 2".into());
    }
    let src = source()?;
    let t_load = std::time::Instant::now();
    let mut tracker =
        Tracker::with_default_models(TrackerConfig::default()).map_err(|e| e.to_string())?;
    let load_ms = t_load.elapsed().as_secs_f64() * 1e3;
    if let Some(dir) = overlay {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let mut sink = out.map(|p| LineSink::new(Some(p))).transpose()?;
    let camera = Intrinsics::default_for(W as u32, H as u32).map_err(|e| e.to_string())?;
    let cut = frames / 2;
    let mut frame = GrayImage::default();
    let mut canvas = Canvas::from_gray(&frame);
    let (mut tracked, mut detected): (Vec<StageTimings>, Vec<StageTimings>) = (vec![], vec![]);
    let (mut n_tracked, mut n_detected, mut n_lost) = (0, 0, 0);
    for t in 0..frames {
        clip::render(&src, t, Some(cut), W, H, &mut frame);
        let r = tracker
            .process(&frame, t as i64 * FRAME_NS)
            .map_err(|e| e.to_string())?;
        if r.faces.is_empty() {
            n_lost += 1;
        } else if r.faces.iter().all(|f| f.state == FaceState::Tracked) {
            n_tracked += 1;
            tracked.push(r.timings);
        } else {
            n_detected += 1;
        }
        if r.detector_ran {
            detected.push(r.timings);
        }
        if let Some(s) = sink.as_mut() {
            let mut line = frame_json(r, None);
            line["frame"] = serde_json::json!(t);
            s.write(&line)?;
        }
        if let Some(dir) = overlay {
            canvas.set_gray(&frame);
            draw_overlay(&mut canvas, tracker.result(), &camera);
            canvas.save_png(&dir.join(format!("frame_{t:06}.png")))?;
        }
    }
    println!(
        "monotrack demo: {frames} frames of {W}x{H} made from samples/data/astronaut.jpg (public domain)"
    );
    println!(
        "frames: {n_detected} detected, {n_tracked} tracked, {n_lost} without a face (the blank cut at frame {cut}); models loaded in {load_ms:.1} ms"
    );
    println!(
        "{:<12} {:>16} {:>22}",
        "stage", "tracked frame µs", "detector frame µs"
    );
    type Get = fn(&StageTimings) -> u64;
    let rows: [(&str, Get); 6] = [
        ("detect", |t| t.detect_us),
        ("region", |t| t.region_us),
        ("landmarks", |t| t.landmarks_us),
        ("flow", |t| t.flow_us),
        ("fit", |t| t.fit_us),
        ("total", |t| t.total_us),
    ];
    for (name, get) in rows {
        let mut a: Vec<u64> = tracked.iter().map(get).collect();
        let mut b: Vec<u64> = detected.iter().map(get).collect();
        println!("{name:<12} {:>16} {:>22}", median(&mut a), median(&mut b));
    }
    println!(
        "(medians; debug builds are slower: use `cargo run --release -p monotrack-cli -- demo`)"
    );
    if let Some(dir) = overlay {
        println!("overlays: {}", dir.display());
    }
    Ok(n_tracked > 0)
}
