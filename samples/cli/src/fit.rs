//! `monotrack fit IN.jsonl [--out OUT.jsonl] [--method msbp|ffbp]`: fits the deformable 3D model to
//! given landmarks (CONTRACT.md). One output line per input line; a malformed line yields
//! `{"line": N, "error": "..."}` in its place, a message on stderr, and exit status 1 at the end.

use crate::json::{CameraJson, intrinsics, put_eyes, put_fit};
use crate::{LineSink, read_lines};
use monotrack_core::fit::{Ffbp, FfbpConfig, Msbp, MsbpConfig};
use monotrack_core::model::N_LANDMARKS;
use serde::Deserialize;
use serde_json::{Map, Value, json};
use std::path::Path;
use std::time::Instant;

/// Fitting method.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Method {
    /// Full perspective multi-step fit (default).
    Msbp,
    /// Weak perspective, ultra-light.
    Ffbp,
}

#[derive(Deserialize)]
struct FaceIn {
    landmarks68: Vec<Option<[f64; 2]>>,
}

#[derive(Deserialize)]
struct LineIn {
    width: u32,
    height: u32,
    camera: Option<CameraJson>,
    faces: Vec<FaceIn>,
}

struct Fitters {
    msbp: Msbp,
    ffbp: Ffbp,
}

fn fit_line(text: &str, method: Method, f: &mut Fitters) -> Result<Value, String> {
    let line: LineIn = serde_json::from_str(text).map_err(|e| format!("malformed JSON: {e}"))?;
    let cam = intrinsics(line.camera, line.width, line.height).map_err(|e| e.to_string())?;
    let t0 = Instant::now();
    let mut faces = Vec::with_capacity(line.faces.len());
    for (k, face) in line.faces.iter().enumerate() {
        if face.landmarks68.len() != N_LANDMARKS {
            return Err(format!(
                "face {k}: landmarks68 has {} points, expected {N_LANDMARKS}",
                face.landmarks68.len()
            ));
        }
        let mut pts = [[0.0; 2]; N_LANDMARKS];
        let mut w = [1.0; N_LANDMARKS];
        for (i, p) in face.landmarks68.iter().enumerate() {
            match p {
                Some(p) => pts[i] = *p,
                None => w[i] = 0.0, // a detector without this point (gradient mode): not fitted
            }
        }
        let fit = match method {
            Method::Msbp => f.msbp.fit(&pts, Some(&w), &cam, None),
            Method::Ffbp => f.ffbp.fit(&pts, Some(&w), &cam),
        }
        .map_err(|e| format!("face {k}: {e}"))?;
        let mut out = Map::new();
        let pts32 = pts.map(|[x, y]| [x as f32, y as f32]);
        put_eyes(&mut out, &pts32, &w.map(|v| v as f32));
        put_fit(&mut out, &fit);
        faces.push(Value::Object(out));
    }
    let us = t0.elapsed().as_micros() as u64;
    Ok(json!({
        "width": line.width, "height": line.height, "faces": faces,
        "timings_us": {"fit": us, "total": us},
    }))
}

/// Runs the subcommand; returns whether every line succeeded.
pub fn run(input: &Path, out: Option<&Path>, method: Method) -> Result<bool, String> {
    let mut sink = LineSink::new(out)?;
    let mut f = Fitters {
        msbp: Msbp::new(MsbpConfig::default()),
        ffbp: Ffbp::new(FfbpConfig::default()),
    };
    let mut ok = true;
    for (n, text) in read_lines(input)? {
        let v = fit_line(&text, method, &mut f).unwrap_or_else(|e| {
            eprintln!("{}:{n}: {e}", input.display());
            ok = false;
            json!({"line": n, "error": e})
        });
        sink.write(&v)?;
    }
    Ok(ok)
}
