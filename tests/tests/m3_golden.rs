//! Golden end-to-end cases of M3 with the embedded models: committed project-made images and boxes
//! with the outputs of the Python reference inference (onnxruntime + OpenCV preprocessing), so a
//! change in preprocessing, tract or the weights is caught. Inputs, provenance and tolerances:
//! `tests/data/m3_golden/make_golden.py` (rerun it whenever the models are retrained).
//!
//! The same cases also hold the outputs of the x86-64 portable path (`x86_64_portable.json`),
//! which every CPU running the portable kernel forms — aarch64 phones among them — must give
//! within float-rounding tolerances: a phone computes what the development machine computed.
//! Recorded on x86-64 with `MONOTRACK_KERNELS=portable MONOTRACK_RECORD_GOLDEN=1 cargo test -p
//! monotrack-tests --test m3_golden` (again whenever the models are retrained).

use monotrack_core::image::{Frame, FrameDesc, GrayImage, PixelFormat, Rect};
use monotrack_core::kernels::{KernelPath, kernel_path};
use monotrack_core::landmarks::{FaceLandmarks, M3};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Landmark tolerance, pixels (faces are ~100 px; `make_golden.py`).
const POINT_TOL_PX: f64 = 0.5;
/// Probability tolerance (`make_golden.py`).
const PROB_TOL: f64 = 0.02;
/// Gaze component tolerance (`make_golden.py`).
const GAZE_TOL: f64 = 0.02;
/// How far the portable path on another CPU may be from the recorded x86-64 portable outputs. M3
/// runs there in the library's own kernels, whose every form computes each value as the same chain
/// of fused multiply-adds (`core/src/kernels/conv3x3`), so the values are the same; what is left
/// is the record's decimal rounding and the platform's maths library (the differences under qemu,
/// aarch64 against the record of an Intel Xeon: BENCHMARKS.md, "Tests on the phone's instruction
/// set").
const CROSS_ISA_POINT_TOL_PX: f64 = 1e-5;
/// The probability and gaze counterpart of [`CROSS_ISA_POINT_TOL_PX`].
const CROSS_ISA_VALUE_TOL: f64 = 1e-6;

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

/// What a run gives for one case, as recorded for the cross-ISA comparison.
#[derive(Serialize, Deserialize, Clone)]
struct Outputs {
    image: String,
    mirror_average: bool,
    landmarks68: Vec<[f64; 2]>,
    /// Yaw probabilities, face probability, mouth and brow gestures, in that order.
    probabilities: Vec<f64>,
    /// Left, right and combined gaze vectors.
    gaze: Vec<f64>,
}

fn outputs(c: &Case, m3: &mut M3, out: &mut FaceLandmarks) -> Outputs {
    let img = load_gray(&c.image);
    let [x, y, w, h] = c.bbox;
    m3.set_mirror_average(c.mirror_average);
    m3.estimate(&img, &Rect::new(x, y, w, h), out).unwrap();
    let f = |v: &[f32]| v.iter().map(|x| f64::from(*x)).collect::<Vec<_>>();
    Outputs {
        image: c.image.clone(),
        mirror_average: c.mirror_average,
        landmarks68: out
            .points
            .iter()
            .map(|p| [f64::from(p[0]), f64::from(p[1])])
            .collect(),
        probabilities: [
            f(&out.yaw_probs),
            vec![f64::from(out.face_prob)],
            f(&out.mouth),
            f(&out.brows),
        ]
        .concat(),
        gaze: [f(&out.gaze_left), f(&out.gaze_right), f(&out.gaze_combined)].concat(),
    }
}

/// Where the portable path is not the native one (x86-64), test-all.sh runs this in its second
/// pass, with `MONOTRACK_KERNELS=portable` and `--include-ignored`.
#[test]
#[cfg_attr(
    not(target_arch = "aarch64"),
    ignore = "the portable path: test-all.sh runs it with MONOTRACK_KERNELS=portable"
)]
fn the_portable_path_gives_the_recorded_x86_64_outputs() {
    assert!(
        kernel_path() == KernelPath::Portable || cfg!(target_arch = "aarch64"),
        "this run takes x86-64's native kernels: run it with MONOTRACK_KERNELS=portable"
    );
    let exp: Expected =
        serde_json::from_str(&std::fs::read_to_string(dir().join("expected.json")).unwrap())
            .unwrap();
    let mut m3 = M3::new().unwrap();
    let mut out = FaceLandmarks::default();
    let got: Vec<Outputs> = exp
        .cases
        .iter()
        .map(|c| outputs(c, &mut m3, &mut out))
        .collect();
    let recorded = dir().join("x86_64_portable.json");
    if cfg!(target_arch = "x86_64") && std::env::var_os("MONOTRACK_RECORD_GOLDEN").is_some() {
        std::fs::write(
            &recorded,
            serde_json::to_string_pretty(&got).unwrap() + "\n",
        )
        .unwrap();
        eprintln!("recorded {}", recorded.display());
    }
    let want: Vec<Outputs> =
        serde_json::from_str(&std::fs::read_to_string(&recorded).unwrap()).unwrap();
    assert_eq!(got.len(), want.len(), "cases");
    for (g, w) in got.iter().zip(&want) {
        assert_eq!((&g.image, g.mirror_average), (&w.image, w.mirror_average));
        let pts = g
            .landmarks68
            .iter()
            .zip(&w.landmarks68)
            .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
            .fold(0.0, f64::max);
        let probs = max_diff(g.probabilities.iter().copied(), &w.probabilities);
        let gaze = max_diff(g.gaze.iter().copied(), &w.gaze);
        println!(
            "{} mirror_average {} against x86-64 portable ({}): points {pts:.2e} px, probabilities {probs:.2e}, gaze {gaze:.2e}",
            g.image,
            g.mirror_average,
            std::env::consts::ARCH
        );
        assert!(
            pts <= CROSS_ISA_POINT_TOL_PX,
            "{}: points off by {pts} px",
            g.image
        );
        assert!(
            probs <= CROSS_ISA_VALUE_TOL,
            "{}: probabilities off by {probs}",
            g.image
        );
        assert!(
            gaze <= CROSS_ISA_VALUE_TOL,
            "{}: gaze off by {gaze}",
            g.image
        );
    }
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

/// Level 1 on a crop turned by the face's roll reads a tilted face as it reads it upright: the
/// astronaut turned by 40° (past the ±25° level 1 was trained on), boxed by its turned golden
/// points' tight box as the tracker boxes a face.
#[test]
fn level1_turned_reads_a_tilted_face_as_an_upright_one() {
    use monotrack_core::landmarks::warp::{Affine, sample};
    let img = load_gray("astronaut.png");
    let exp: Expected =
        serde_json::from_str(&std::fs::read_to_string(dir().join("expected.json")).unwrap())
            .unwrap();
    let c = exp
        .cases
        .iter()
        .find(|c| c.image == "astronaut.png" && !c.mirror_average)
        .unwrap();
    let golden: Vec<[f64; 2]> = c.landmarks68.iter().map(|p| [p[0], p[1]]).collect();
    let (w, h) = (img.width(), img.height());
    let centre = [w as f64 / 2.0, h as f64 / 2.0];
    let nme = |pts: &[[f32; 2]], truth: &[[f64; 2]], idx: &[usize]| {
        let iod = (truth[45][0] - truth[36][0]).hypot(truth[45][1] - truth[36][1]);
        idx.iter()
            .map(|&i| {
                (f64::from(pts[i][0]) - truth[i][0]).hypot(f64::from(pts[i][1]) - truth[i][1])
            })
            .sum::<f64>()
            / idx.len() as f64
            / iod
    };
    let mut m3 = M3::new().unwrap();
    let idx = m3.config().level1.indices68.clone();
    let mut out = FaceLandmarks::default();
    for deg in [-40.0f64, 40.0] {
        let a = deg.to_radians();
        // Output pixel → source pixel: the image turned by −a about its centre, so the face in
        // the output stands turned by +a (image y down).
        let map = Affine {
            m: [
                a.cos(),
                a.sin(),
                centre[0] - a.cos() * centre[0] - a.sin() * centre[1],
                -a.sin(),
                a.cos(),
                centre[1] + a.sin() * centre[0] - a.cos() * centre[1],
            ],
        };
        let mut buf = Vec::new();
        sample(&img, &map, w, h, &mut buf).unwrap();
        let turned = GrayImage::from_vec(w, h, buf).unwrap();
        // Source point → output point: the inverse of `map`.
        let truth: Vec<[f64; 2]> = golden
            .iter()
            .map(|p| {
                let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
                [
                    centre[0] + a.cos() * dx - a.sin() * dy,
                    centre[1] + a.sin() * dx + a.cos() * dy,
                ]
            })
            .collect();
        let roll = (truth[45][1] - truth[36][1]).atan2(truth[45][0] - truth[36][0]);
        assert!((roll - a).abs() < 0.15, "roll {roll} for {a}");
        let pts: Vec<[f32; 2]> = truth.iter().map(|p| [p[0] as f32, p[1] as f32]).collect();
        let tb = Rect::bounding(&pts);
        let upright_conf = m3.level1(&turned, &tb, &mut out).unwrap();
        let upright = nme(&out.points, &truth, &idx);
        let turned_conf = m3
            .level1_turned(&turned, &tb, roll as f32, &mut out)
            .unwrap();
        let turned_nme = nme(&out.points, &truth, &idx);
        eprintln!(
            "{deg}°: upright NME {upright:.4} conf {upright_conf:.3}, turned NME {turned_nme:.4} conf {turned_conf:.3}"
        );
        assert!(
            turned_conf > 0.9,
            "{deg}°: turned face confidence {turned_conf}"
        );
        // A little above what level 1 gives upright on the untouched image.
        assert!(turned_nme < 0.04, "{deg}°: turned level-1 NME {turned_nme}");
        assert!(
            turned_nme < upright,
            "{deg}°: {turned_nme} vs upright {upright}"
        );
    }
}
