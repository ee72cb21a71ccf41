//! Golden end-to-end cases of M3 with the embedded models: committed project-made images and boxes
//! with the outputs of the Python reference inference (onnxruntime + OpenCV preprocessing), so a
//! change in preprocessing, tract or the weights is caught. Inputs, provenance and tolerances:
//! `tests/data/m3_golden/make_golden.py` (rerun it whenever the models are retrained).

use monotrack_core::image::{Frame, FrameDesc, GrayImage, PixelFormat, Rect};
use monotrack_core::landmarks::{FaceLandmarks, M3};
use serde::Deserialize;
use std::path::PathBuf;

/// Landmark tolerance, pixels (faces are ~100 px; `make_golden.py`).
const POINT_TOL_PX: f64 = 0.5;
/// Probability tolerance (`make_golden.py`).
const PROB_TOL: f64 = 0.02;
/// Gaze component tolerance (`make_golden.py`).
const GAZE_TOL: f64 = 0.02;

#[derive(Deserialize)]
struct Gaze {
    left: [f64; 3],
    right: [f64; 3],
    combined: [f64; 3],
}

#[derive(Deserialize)]
struct Case {
    image: String,
    #[serde(rename = "box")]
    bbox: [f32; 4],
    /// M3's mode (`M3::set_mirror_average`).
    mirror_average: bool,
    landmarks68: Vec<[f64; 2]>,
    yaw_probs: Vec<f64>,
    face_prob: f64,
    mouth: Vec<f64>,
    brows: Vec<f64>,
    gaze: Gaze,
}

#[derive(Deserialize)]
struct Expected {
    cases: Vec<Case>,
}

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/m3_golden")
}

fn load_gray(name: &str) -> GrayImage {
    let rgb = image::open(dir().join(name)).unwrap().to_rgb8();
    let desc = FrameDesc::packed(rgb.width(), rgb.height(), PixelFormat::Rgb8);
    let mut out = GrayImage::default();
    Frame::new(rgb.as_raw(), desc).unwrap().to_luma(&mut out);
    out
}

fn max_diff(got: impl IntoIterator<Item = f64>, want: &[f64]) -> f64 {
    got.into_iter()
        .zip(want)
        .map(|(g, w)| (g - w).abs())
        .fold(0.0, f64::max)
}

#[test]
fn m3_matches_the_python_reference() {
    let exp: Expected =
        serde_json::from_str(&std::fs::read_to_string(dir().join("expected.json")).unwrap())
            .unwrap();
    let mut m3 = M3::new().unwrap();
    let mut out = FaceLandmarks::default();
    for c in &exp.cases {
        let img = load_gray(&c.image);
        let [x, y, w, h] = c.bbox;
        m3.set_mirror_average(c.mirror_average);
        m3.estimate(&img, &Rect::new(x, y, w, h), &mut out).unwrap();
        let pts = out
            .points
            .iter()
            .zip(&c.landmarks68)
            .map(|(g, w)| (f64::from(g[0]) - w[0]).hypot(f64::from(g[1]) - w[1]))
            .fold(0.0, f64::max);
        let f = |v: &[f32]| v.iter().map(|x| f64::from(*x)).collect::<Vec<_>>();
        let probs = [
            max_diff(f(&out.yaw_probs), &c.yaw_probs),
            (f64::from(out.face_prob) - c.face_prob).abs(),
            max_diff(f(&out.mouth), &c.mouth),
            max_diff(f(&out.brows), &c.brows),
        ]
        .into_iter()
        .fold(0.0, f64::max);
        let gaze = [
            max_diff(f(&out.gaze_left), &c.gaze.left),
            max_diff(f(&out.gaze_right), &c.gaze.right),
            max_diff(f(&out.gaze_combined), &c.gaze.combined),
        ]
        .into_iter()
        .fold(0.0, f64::max);
        println!(
            "{} {:?} mirror_average {}: max point error {pts:.4} px, probabilities {probs:.5}, gaze {gaze:.5}",
            c.image, c.bbox, c.mirror_average
        );
        assert!(pts <= POINT_TOL_PX, "{}: points off by {pts} px", c.image);
        assert!(
            probs <= PROB_TOL,
            "{}: probabilities off by {probs}",
            c.image
        );
        assert!(gaze <= GAZE_TOL, "{}: gaze off by {gaze}", c.image);
    }
}
