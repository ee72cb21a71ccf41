//! Per-part accuracy of the gradient detector next to the mean face it falls back to, on faces68
//! faces with ground-truth boxes: the harness for tuning `core::landmarks::gradient`.
//!
//! ```text
//! cargo run --profile bench -p monotrack-core --example gradient_parts -- ../shared/data [tune|val]
//! ```
//!
//! `tune` (the default) reads faces68 lines with `i % 10 == 5`, which are in the training split
//! and left out of the geometry's fit (`core/models/train/fit_gradient_geometry.py`); `val`
//! reads the validation split (`i % 10 == 0`). NME divides by the outer eye corners. Prints each
//! part's NME, the eye centres' errors (against the mean of each eye's six points), NME by
//! confidence and per-face quantiles. With `GP_DUMP=DIR` it draws each face whose worse eye
//! centre is off by more than a tenth of the eye distance (truth green, points red, eye centres
//! cyan against yellow) into DIR.
// Inputs made with the platform's maths library are fine here (core/clippy.toml).
#![allow(clippy::disallowed_methods)]

use monotrack_core::image::{GrayImage, Rect, rgb_to_contract_luma};
use monotrack_core::landmarks::{GRADIENT_TO_68, GradientDetector, GradientPoints};
use std::time::Instant;

const PARTS: [(&str, &[usize]); 5] = [
    ("contour", &[1, 15, 4, 12, 6, 10, 8]),
    ("brows", &[17, 19, 21, 22, 24, 26]),
    ("eyes", &[36, 39, 42, 45]),
    ("nose", &[30, 31, 33, 35]),
    ("mouth", &[48, 51, 54, 57, 62, 66]),
];

fn main() {
    let mut args = std::env::args().skip(1);
    let data = std::path::PathBuf::from(args.next().unwrap_or_else(|| "../shared/data".into()));
    let rest: Vec<_> = args.collect();
    let split = rest.first().cloned().unwrap_or_else(|| "tune".into());
    let want = if split == "val" { 0 } else { 5 };
    let text = std::fs::read_to_string(data.join("faces68/train.jsonl")).expect("faces68");
    let mut det = GradientDetector::new();
    let mut out = GradientPoints::default();
    // Per 68-point index: summed error / iod, detector and prior; per face: all27 both.
    let mut err = [[0f64; 2]; 68];
    let mut n = 0usize;
    let mut per_face = Vec::new();
    let mut us = Vec::new();
    let mut eyec = [0f64; 2];
    let mut eyes_all = [Vec::new(), Vec::new()];
    let mut bins = [(0f64, 0f64, 0usize); 5];
    for (i, line) in text.lines().enumerate() {
        if i % 10 != want {
            continue;
        }
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        let img = image::open(data.join("faces68").join(v["image"].as_str().unwrap()))
            .unwrap()
            .to_rgb8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        let mut gray = vec![0u8; w * h];
        rgb_to_contract_luma(img.as_raw(), &mut gray);
        let gray = GrayImage::from_vec(w, h, gray).unwrap();
        for f in v["faces"].as_array().unwrap() {
            let pts: Vec<[f32; 2]> = f["landmarks68"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| [p[0].as_f64().unwrap() as f32, p[1].as_f64().unwrap() as f32])
                .collect();
            let bx = Rect::bounding(&pts);
            let iod = ((pts[36][0] - pts[45][0]).hypot(pts[36][1] - pts[45][1])) as f64;
            let t = Instant::now();
            det.detect(&gray, &bx, 0.0, &mut out).unwrap();
            us.push(t.elapsed().as_secs_f64() * 1e6);
            let prior = GradientPoints::mean_face(&bx);
            let (mut a, mut b) = (0f64, 0f64);
            for (g, m) in GRADIENT_TO_68.iter().enumerate() {
                if let Some(k) = *m {
                    for (j, p) in [out.points[g], prior.points[g]].iter().enumerate() {
                        let e = ((p[0] - pts[k][0]).hypot(p[1] - pts[k][1])) as f64 / iod;
                        err[k][j] += e;
                        if j == 0 { a += e / 27.0 } else { b += e / 27.0 }
                    }
                }
            }
            per_face.push((a, b));
            for (eye, first) in [36, 42].into_iter().enumerate() {
                let gc = eye_centre(&pts, first);
                for (j, q) in [&out, &prior].iter().enumerate() {
                    let c = q.eye_centres[eye];
                    let e = ((c[0] - gc[0]).hypot(c[1] - gc[1])) as f64 / iod;
                    eyec[j] += e;
                    eyes_all[j].push(e);
                }
            }
            for (g, m) in GRADIENT_TO_68.iter().enumerate() {
                if let Some(k) = *m {
                    let e = ((out.points[g][0] - pts[k][0]).hypot(out.points[g][1] - pts[k][1]))
                        as f64
                        / iod;
                    let e0 = ((prior.points[g][0] - pts[k][0])
                        .hypot(prior.points[g][1] - pts[k][1])) as f64
                        / iod;
                    let b = ((out.confidence[g] * 4.999) as usize).min(4);
                    bins[b].0 += e;
                    bins[b].1 += e0;
                    bins[b].2 += 1;
                }
            }
            if let Ok(dir) = std::env::var("GP_DUMP") {
                let e = (0..2)
                    .map(|e| {
                        let g = eye_centre(&pts, 36 + 6 * e);
                        let c = out.eye_centres[e];
                        (c[0] - g[0]).hypot(c[1] - g[1]) / iod as f32
                    })
                    .fold(0f32, f32::max);
                if e > 0.1 {
                    dump(
                        &img,
                        &bx,
                        &pts,
                        &out,
                        &format!("{dir}/{n:03}_{:.0}.png", 100.0 * e),
                    );
                }
            }
            n += 1;
        }
    }
    let nf = n as f64;
    let mut all = [0f64; 2];
    println!("{split}: {n} faces");
    for (name, idx) in PARTS {
        let d: f64 = idx.iter().map(|&k| err[k][0]).sum::<f64>() / (nf * idx.len() as f64);
        let p: f64 = idx.iter().map(|&k| err[k][1]).sum::<f64>() / (nf * idx.len() as f64);
        println!(
            "{name:8} detector {:6.2} %  prior {:6.2} %",
            100.0 * d,
            100.0 * p
        );
        let pts: Vec<String> = idx
            .iter()
            .map(|&k| {
                format!(
                    "{k}:{:.1}/{:.1}",
                    100.0 * err[k][0] / nf,
                    100.0 * err[k][1] / nf
                )
            })
            .collect();
        println!("         {}", pts.join(" "));
    }
    for e in err.iter() {
        all[0] += e[0];
        all[1] += e[1];
    }
    println!(
        "eye centres detector {:.2} % prior {:.2} %",
        50.0 * eyec[0] / nf,
        50.0 * eyec[1] / nf
    );
    for (j, v) in eyes_all.iter_mut().enumerate() {
        v.sort_by(f64::total_cmp);
        let under = |t: f64| v.iter().filter(|&&e| e < t).count() as f64 / v.len() as f64;
        println!(
            "eye centres {}: median {:.1} %, p90 {:.1} %, under 5 % {:.0} %, under 10 % {:.0} %",
            ["detector", "prior"][j],
            100.0 * v[v.len() / 2],
            100.0 * v[v.len() * 9 / 10],
            100.0 * under(0.05),
            100.0 * under(0.1)
        );
    }
    for (i, b) in bins.iter().enumerate() {
        println!(
            "conf {:.1}-{:.1}: {} points, detector {:.2} % prior {:.2} %",
            i as f32 * 0.2,
            i as f32 * 0.2 + 0.2,
            b.2,
            100.0 * b.0 / b.2.max(1) as f64,
            100.0 * b.1 / b.2.max(1) as f64
        );
    }
    let mut pa: Vec<f64> = per_face.iter().map(|p| p.0).collect();
    let mut pb: Vec<f64> = per_face.iter().map(|p| p.1).collect();
    pa.sort_by(f64::total_cmp);
    pb.sort_by(f64::total_cmp);
    let q = |v: &[f64], f: f64| 100.0 * v[((v.len() - 1) as f64 * f) as usize];
    println!(
        "per face detector p25 {:.1} p50 {:.1} p75 {:.1} p90 {:.1}; prior {:.1} {:.1} {:.1} {:.1}",
        q(&pa, 0.25),
        q(&pa, 0.5),
        q(&pa, 0.75),
        q(&pa, 0.9),
        q(&pb, 0.25),
        q(&pb, 0.5),
        q(&pb, 0.75),
        q(&pb, 0.9)
    );
    let better = per_face.iter().filter(|(a, b)| a < b).count();
    us.sort_by(f64::total_cmp);
    println!(
        "all27    detector {:6.2} %  prior {:6.2} %  (detector better on {better} of {n}); {:.0} us/face median",
        100.0 * all[0] / (27.0 * nf),
        100.0 * all[1] / (27.0 * nf),
        us[us.len() / 2]
    );
}

/// The mean of an eye's six points from iBUG index `first`.
fn eye_centre(pts: &[[f32; 2]], first: usize) -> [f32; 2] {
    let s = pts[first..first + 6]
        .iter()
        .fold([0f32; 2], |a, p| [a[0] + p[0], a[1] + p[1]]);
    [s[0] / 6.0, s[1] / 6.0]
}

/// Draws the crop around `bx`: truth green, detector red (bright with confidence), as a PNG.
fn dump(img: &image::RgbImage, bx: &Rect, gt: &[[f32; 2]], out: &GradientPoints, path: &str) {
    let m = 0.4 * bx.w.max(bx.h);
    let (x0, y0) = ((bx.x - m).max(0.0) as u32, (bx.y - m).max(0.0) as u32);
    let x1 = ((bx.x + bx.w + m) as u32).min(img.width());
    let y1 = ((bx.y + bx.h + m) as u32).min(img.height());
    let mut c = image::imageops::crop_imm(img, x0, y0, x1 - x0, y1 - y0).to_image();
    let mut put = |p: [f32; 2], col: [u8; 3]| {
        let (x, y) = (p[0] as i64 - x0 as i64, p[1] as i64 - y0 as i64);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (u, v) = (x + dx, y + dy);
                if u >= 0 && v >= 0 && (u as u32) < c.width() && (v as u32) < c.height() {
                    c.put_pixel(u as u32, v as u32, image::Rgb(col));
                }
            }
        }
    };
    for (g, m) in GRADIENT_TO_68.iter().enumerate() {
        if let Some(k) = *m {
            put(gt[k], [0, 255, 0]);
        }
        let b = (80.0 + 175.0 * out.confidence[g]) as u8;
        put(out.points[g], [b, 0, if m.is_some() { 0 } else { 255 }]);
    }
    let mut put2 = |p: [f32; 2], col: [u8; 3]| {
        let (x, y) = (p[0] as i64 - x0 as i64, p[1] as i64 - y0 as i64);
        if x >= 0 && y >= 0 && (x as u32) < c.width() && (y as u32) < c.height() {
            c.put_pixel(x as u32, y as u32, image::Rgb(col));
        }
    };
    for e in 0..2 {
        let g = eye_centre(gt, 36 + 6 * e);
        put2(g, [255, 255, 0]);
        put2(out.eye_centres[e], [0, 255, 255]);
    }
    let s = (256.0 / c.width().max(c.height()) as f32).max(1.0);
    let c = image::imageops::resize(
        &c,
        (c.width() as f32 * s) as u32,
        (c.height() as f32 * s) as u32,
        image::imageops::FilterType::Nearest,
    );
    c.save(path).unwrap();
}
