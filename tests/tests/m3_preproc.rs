//! Golden tests of the M3 preprocessing (`core::landmarks::{warp, filter}`) against OpenCV, the
//! library the training side of `core/models/M3_IO.md` calls. Fixtures and tolerances:
//! `tests/data/m3_preproc/make_golden.py` (its docstring says where every expected value comes from).

use monotrack_core::image::GrayImage;
use monotrack_core::landmarks::filter::{Bilateral, equalize_hist};
use monotrack_core::landmarks::warp::{Affine, sample};
use serde::Deserialize;
use std::path::PathBuf;

/// Warps: at most this fraction of pixels one level off OpenCV (`make_golden.py`).
const WARP_MAX_OFF_FRACTION: f64 = 0.02;
/// The sampler's f32 path (`core::landmarks::warp`) puts a rare pixel one level off the f64
/// contract on irregular maps; this bound leaves a wide margin above that rate. The `border`
/// case's round coefficients (2.1, 0.4) put many of its values right at a .5 tie, where f32 and
/// f64 may round apart: there each pixel off is checked to be such a tie instead.
const WARP_MAX_OFF_CONTRACT: f64 = 0.0015;
/// How near a .5 tie the contract's f64 value must lie where the f32 path rounds it apart.
const WARP_TIE: f64 = 1e-3;

/// The contract's f64 value of patch pixel (u, v) before rounding (`core::landmarks::warp`).
fn contract_value(src: &GrayImage, m: &[f64; 6], u: usize, v: usize) -> f64 {
    let (iw, ih) = (src.width() as f64, src.height() as f64);
    let (uc, vc) = (u as f64 + 0.5, v as f64 + 0.5);
    let x = (m[0] * uc + m[1] * vc + m[2] - 0.5).clamp(-1.0, iw);
    let y = (m[3] * uc + m[4] * vc + m[5] - 0.5).clamp(-1.0, ih);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |x: f64, y: f64| {
        f64::from(src.get(
            x.clamp(0.0, iw - 1.0) as usize,
            y.clamp(0.0, ih - 1.0) as usize,
        ))
    };
    (1.0 - fy) * ((1.0 - fx) * at(x0, y0) + fx * at(x0 + 1.0, y0))
        + fy * ((1.0 - fx) * at(x0, y0 + 1.0) + fx * at(x0 + 1.0, y0 + 1.0))
}
/// Bilateral filter: at most this fraction of pixels one level off OpenCV (`make_golden.py`).
const BILATERAL_MAX_OFF_FRACTION: f64 = 0.05;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/m3_preproc")
}

/// Reads a binary PGM (P5, maxval 255) as written by `make_golden.py`.
fn pgm(name: &str) -> GrayImage {
    let bytes = std::fs::read(dir().join(name)).unwrap();
    let mut fields = Vec::new();
    let mut pos = 0;
    while fields.len() < 4 {
        while bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        fields.push(String::from_utf8(bytes[start..pos].to_vec()).unwrap());
    }
    assert_eq!(fields[0], "P5");
    assert_eq!(fields[3], "255");
    let (w, h): (usize, usize) = (fields[1].parse().unwrap(), fields[2].parse().unwrap());
    GrayImage::from_vec(w, h, bytes[pos + 1..].to_vec()).unwrap()
}

/// Prints and asserts that `got` is within one level of `want` everywhere and differs on at most
/// the fraction `max_off` of the pixels.
fn assert_within_one(label: &str, got: &[u8], want: &[u8], max_off: f64) {
    assert_eq!(got.len(), want.len(), "{label}");
    let max = got
        .iter()
        .zip(want)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    let off = got.iter().zip(want).filter(|(a, b)| a != b).count() as f64 / got.len() as f64;
    println!("{label}: max {max}, {:.3} % off", 100.0 * off);
    assert!(max <= 1 && off <= max_off, "{label}: {max} / {off}");
}

#[derive(Deserialize)]
struct Warp {
    name: String,
    width: usize,
    height: usize,
    map: [[f64; 3]; 2],
}

#[derive(Deserialize)]
struct Cases {
    patch_sizes: Vec<[usize; 2]>,
    warps: Vec<Warp>,
}

fn cases() -> Cases {
    serde_json::from_str(&std::fs::read_to_string(dir().join("cases.json")).unwrap()).unwrap()
}

#[test]
fn warps_match_the_contract_within_rounding_and_opencv_within_one_level() {
    let src = pgm("src.pgm");
    let mut out = Vec::new();
    for c in cases().warps {
        let m = c.map;
        let map = Affine {
            m: [m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2]],
        };
        sample(&src, &map, c.width, c.height, &mut out).unwrap();
        let exact = pgm(&format!("warp_{}_exact.pgm", c.name));
        let ties = c.name == "border";
        assert_within_one(
            &format!("warp {} vs the f64 contract", c.name),
            &out,
            exact.data(),
            if ties { 1.0 } else { WARP_MAX_OFF_CONTRACT },
        );
        for (i, (a, b)) in out.iter().zip(exact.data()).enumerate() {
            if a != b {
                let val = contract_value(&src, &map.m, i % c.width, i / c.width);
                assert!(
                    (val - val.floor() - 0.5).abs() < WARP_TIE,
                    "warp {} pixel {i}: {a} vs {b}, contract value {val}",
                    c.name
                );
            }
        }
        assert_within_one(
            &format!("warp {} vs OpenCV", c.name),
            &out,
            pgm(&format!("warp_{}.pgm", c.name)).data(),
            WARP_MAX_OFF_FRACTION,
        );
    }
}

#[test]
fn bilateral_and_equalize_match_opencv() {
    let mut bf = Bilateral::new(5, 20.0, 3.0);
    for [w, h] in cases().patch_sizes {
        let tag = format!("{w}x{h}");
        let patch = pgm(&format!("patch_{tag}.pgm"));
        let want = pgm(&format!("bilateral_{tag}.pgm"));
        let mut got = vec![0; w * h];
        bf.apply(patch.data(), w, h, &mut got);
        assert_within_one(
            &format!("bilateral {tag} vs OpenCV"),
            &got,
            want.data(),
            BILATERAL_MAX_OFF_FRACTION,
        );

        let mut eq = want.data().to_vec();
        equalize_hist(&mut eq);
        assert_eq!(
            eq,
            pgm(&format!("equalize_{tag}.pgm")).data(),
            "equalize {tag}"
        );
    }
}
