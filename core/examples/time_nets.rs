//! Times ONNX networks the way `core::landmarks` runs them (tract, fixed input shapes,
//! `into_optimized`, one thread): the harness behind `core/models/train/RESEARCH_LOG.md`'s "Trunk
//! design (tract time per net)".
//!
//! ```text
//! python3 core/models/train/export_trunks.py /tmp/trunks level1=16s-32s-48s-48c-64s face=...
//! cargo run --release -p monotrack-core --example time_nets -- /tmp/trunks
//! ```
//!
//! Every `NAME.onnx` in the folder whose name is an M3 net (level1, face, brows, mouth, eye, nose, mouth_fine) runs
//! with that net's input shapes on a fixed varied input (a zone named in the folder's `m3.json`
//! with its patch size there; one patch per run, so the eye's two take twice its figure); prints the median and 10th percentile of
//! 300 runs after 20 warm-up runs. Every `detector*.onnx` (face detector candidates,
//! `core::detect`) runs at the network inputs of a 640×480 frame: 200×150 (min face 32 px at 10
//! network pixels), 213×160 and 267×200 (min face 24 px at 8 or 10), 320×240 and 400×300 (min
//! face 16 px at 8 or 10) and the 128×96 second pass.

mod common;

use std::time::Instant;
use tract_onnx::prelude::*;

/// Detector network inputs timed for `detector*.onnx` (height, width).
const DETECTOR_INPUTS: [[usize; 2]; 6] = [
    [150, 200],
    [160, 213],
    [200, 267],
    [240, 320],
    [300, 400],
    [96, 128],
];

const NETS: [(&str, &[&[usize]]); 7] = [
    ("level1", &[&[1, 1, 64, 64]]),
    ("face", &[&[1, 1, 48, 48], &[1, 5]]),
    ("brows", &[&[1, 1, 32, 64], &[1, 5]]),
    ("mouth", &[&[1, 1, 48, 48], &[1, 5]]),
    ("eye", &[&[1, 1, 24, 40], &[1, 5]]),
    ("nose", &[&[1, 1, 40, 24], &[1, 5]]),
    ("mouth_fine", &[&[1, 1, 40, 48], &[1, 5]]),
];

fn main() -> TractResult<()> {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: time_nets DIR (with level1.onnx, face.onnx, ... inside)");
        std::process::exit(2);
    };
    // (label printed, ONNX file stem, input shapes)
    let mut jobs: Vec<(String, String, Vec<Vec<usize>>)> = Vec::new();
    // Zones an `m3.json` in the folder names (other sizes, new zones) replace the table's.
    let zones: Vec<(String, usize, usize)> = std::fs::read(format!("{dir}/m3.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .and_then(|v| v.get("zones")?.as_object().cloned())
        .map(|z| {
            z.iter()
                .filter_map(|(name, c)| {
                    let side = |k: &str| c.get(k)?.as_u64().map(|v| v as usize);
                    Some((name.clone(), side("width")?, side("height")?))
                })
                .collect()
        })
        .unwrap_or_default();
    for (name, w, h) in &zones {
        if std::path::Path::new(&format!("{dir}/{name}.onnx")).exists() {
            jobs.push((
                name.clone(),
                name.clone(),
                vec![vec![1, 1, *h, *w], vec![1, 5]],
            ));
        }
    }
    for (name, shapes) in NETS {
        if zones.iter().any(|(n, _, _)| n == name) {
            continue;
        }
        if std::path::Path::new(&format!("{dir}/{name}.onnx")).exists() {
            jobs.push((
                name.to_string(),
                name.to_string(),
                shapes.iter().map(|s| s.to_vec()).collect(),
            ));
        }
    }
    let mut detectors: Vec<String> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with("detector") && n.ends_with(".onnx"))
        .map(|n| n.trim_end_matches(".onnx").to_string())
        .collect();
    detectors.sort();
    for name in detectors {
        for [h, w] in DETECTOR_INPUTS {
            jobs.push((
                format!("{name}@{w}x{h}"),
                name.clone(),
                vec![vec![1, 1, h, w]],
            ));
        }
    }
    for (name, file, shapes) in jobs {
        let plan = common::load_plan(&format!("{dir}/{file}.onnx"), &shapes)?;
        let inputs = common::patch_like_inputs(&shapes)?;
        for _ in 0..20 {
            plan.run(inputs.clone())?;
        }
        let mut us: Vec<u128> = (0..300)
            .map(|_| {
                let t = Instant::now();
                plan.run(inputs.clone()).map(|_| t.elapsed().as_micros())
            })
            .collect::<TractResult<_>>()?;
        us.sort_unstable();
        println!("{name}: median {} us, p10 {} us", us[150], us[30]);
    }
    Ok(())
}
