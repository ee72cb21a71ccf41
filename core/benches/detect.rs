//! Measures `FaceDetector::detect` on a 640×480 luma frame with one face:
//! `samples/data/astronaut.jpg` scaled to 320×320 and pasted into a textured gray frame — at the
//! default config and at min face 16, 24 and 32 px (network inputs 400×300, 267×200, 200×150, plus
//! the 128×96 second pass below 32 px).
//! Also `score_window` on that face (the tracker's check).

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::detect::{Detection, DetectorConfig, FaceDetector};
use monotrack_core::image::GrayImage;
use std::hint::black_box;

fn frame() -> GrayImage {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../samples/data/astronaut.jpg");
    let img = image::open(path)
        .expect("samples/data/astronaut.jpg")
        .into_luma8();
    let img = image::imageops::resize(&img, 320, 320, image::imageops::FilterType::Triangle);
    let (w, h) = (640usize, 480usize);
    // Background texture so the detector sees structure everywhere, not a flat field.
    let mut data: Vec<u8> = (0..w * h)
        .map(|i| (((i % w) * 7 + (i / w) * 13) % 97 + 80) as u8)
        .collect();
    for y in 0..320 {
        for x in 0..320 {
            data[(y + 100) * w + x + 250] = img.get_pixel(x as u32, y as u32).0[0];
        }
    }
    GrayImage::from_vec(w, h, data).unwrap()
}

fn bench(c: &mut Criterion) {
    let img = frame();
    let mut det = FaceDetector::new().unwrap();
    let mut out: Vec<Detection> = Vec::new();
    det.detect(&img, &mut out).unwrap();
    assert!(!out.is_empty(), "the bench frame's face must be found");
    let face = out[0].rect;
    c.bench_function("detect_640x480", |b| {
        b.iter(|| det.detect(black_box(&img), &mut out).unwrap())
    });
    for min_face in [16.0f32, 24.0, 32.0] {
        let mut det = FaceDetector::with_config(DetectorConfig {
            min_face_px: min_face,
            ..DetectorConfig::default()
        })
        .unwrap();
        c.bench_function(&format!("detect_640x480_min_face_{min_face}"), |b| {
            b.iter(|| det.detect(black_box(&img), &mut out).unwrap())
        });
    }
    c.bench_function("score_window", |b| {
        b.iter(|| det.score_window(black_box(&img), face).unwrap())
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(3));
    targets = bench
}
criterion_main!(benches);
