//! Measures the whole M3 per face (level-1 crop and net, brows, both eyes, mouth: warps, filters,
//! networks and merge), one thread, and level 1 alone (the tracker's face check). The image is a
//! synthetic 640×480 pattern with a 200 px face box: every stage's cost is independent of the
//! pixel values (fixed-size warps, filters and networks).

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::image::{GrayImage, Rect};
use monotrack_core::landmarks::{FaceLandmarks, M3};
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
    c.bench_function("m3_level1_face_confidence", |b| {
        b.iter(|| {
            m3.face_confidence(black_box(&img), black_box(&face))
                .unwrap()
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
