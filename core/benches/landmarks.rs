//! Measures the whole M3 per face (level-1 crop and net, brows, both eyes, mouth: warps, filters,
//! networks and merge), one thread, in both modes (default and mirror average), and level 1 alone
//! (the tracker's face check); and the ultra-light mode's gradient detector. The image is a synthetic 640×480 pattern with a 200 px face box:
//! every stage's cost is independent of the pixel values (fixed-size warps, filters and networks).
// Inputs made with the platform's maths library are fine here (core/clippy.toml).
#![allow(clippy::disallowed_methods)]

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::image::{GrayImage, Rect};
use monotrack_core::landmarks::filter::Bilateral;
use monotrack_core::landmarks::warp::{Affine, sample};
use monotrack_core::landmarks::{
    EMBEDDED_FILES, FaceLandmarks, GradientDetector, GradientPoints, M3, embedded_file,
};
use std::hint::black_box;

fn image() -> GrayImage {
    let (w, h) = (640, 480);
    let data = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            (128.0 + 60.0 * (x * 0.05).sin() * (y * 0.07).cos() + ((i * 7919) % 13) as f32) as u8
        })
        .collect();
    GrayImage::from_vec(w, h, data).unwrap()
}

fn bench(c: &mut Criterion) {
    // tract's default executor is single-threaded (the core does not enable `multithread-mm`).
    let img = image();
    let face = Rect::new(220.0, 140.0, 200.0, 210.0);
    let mut m3 = M3::new().unwrap();
    let mut out = FaceLandmarks::default();
    c.bench_function("m3_per_face", |b| {
        b.iter(|| {
            m3.estimate(black_box(&img), black_box(&face), &mut out)
                .unwrap()
        })
    });
    // The same without the shape prior: its cost is the difference (within one run, so the
    // machine's state is shared).
    let json = embedded_file("m3.json").expect("m3.json embedded");
    let mut cfg: serde_json::Value = serde_json::from_slice(json).expect("valid m3.json");
    cfg.as_object_mut()
        .expect("an object")
        .remove("shape_prior");
    let mut no_prior = M3::from_bytes(&serde_json::to_vec(&cfg).unwrap(), EMBEDDED_FILES).unwrap();
    c.bench_function("m3_per_face_without_shape_prior", |b| {
        b.iter(|| {
            no_prior
                .estimate(black_box(&img), black_box(&face), &mut out)
                .unwrap()
        })
    });
    // Mirror-average mode (level 1 and the zones marked in m3.json also run mirrored).
    m3.set_mirror_average(true);
    c.bench_function("m3_per_face_mirror_average", |b| {
        b.iter(|| {
            m3.estimate(black_box(&img), black_box(&face), &mut out)
                .unwrap()
        })
    });
    m3.set_mirror_average(false);
    // The ultra-light mode's gradient detector on the same face (its cost depends a little on the
    // pixels: the roll search may stop early).
    let mut gradient = GradientDetector::new();
    let mut points = GradientPoints::default();
    c.bench_function("gradient_per_face", |b| {
        b.iter(|| {
            gradient
                .detect(black_box(&img), black_box(&face), 0.0, &mut points)
                .unwrap()
        })
    });
    c.bench_function("m3_level1_face_confidence", |b| {
        b.iter(|| {
            m3.face_confidence(black_box(&img), black_box(&face))
                .unwrap()
        })
    });
    // The preprocessing kernels alone: the level-1 crop (64×64 from a 273 px square, as
    // `m3_per_face`; unrotated) and the brows patch (64×32, rotated; bilateral d = 5).
    let crop = Affine::square_crop([320.0, 245.0], 1.3 * 210.0, 64);
    let mut buf = Vec::new();
    c.bench_function("warp_sample_64x64", |b| {
        b.iter(|| sample(black_box(&img), black_box(&crop), 64, 64, &mut buf).unwrap())
    });
    let brows = Affine::similarity([250.0, 200.0], [390.0, 215.0], [8.0, 24.0], [56.0, 24.0])
        .expect("distinct points");
    let mut patch = Vec::new();
    c.bench_function("warp_sample_rotated_64x32", |b| {
        b.iter(|| sample(black_box(&img), black_box(&brows), 64, 32, &mut patch).unwrap())
    });
    // Filled here too: a filtered run (`--bench bilateral`) skips the sampling bench above.
    sample(&img, &brows, 64, 32, &mut patch).unwrap();
    let mut bilateral = Bilateral::new(5, 20.0, 3.0);
    let mut filtered = vec![0; 64 * 32];
    c.bench_function("bilateral_64x32_d5", |b| {
        b.iter(|| bilateral.apply(black_box(&patch), 64, 32, &mut filtered))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
