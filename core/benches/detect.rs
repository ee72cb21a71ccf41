//! Measures `FaceDetector::detect` on a 640×480 luma frame with one face:
//! `samples/data/astronaut.jpg` scaled to 320×320 and pasted into a textured gray frame — at the
//! default config and at min face 16, 24 and 32 px (network inputs 400×300, 267×200, 200×150, plus
//! the 128×96 second pass below 32 px).
//! Also `score_window` on that face (the tracker's check), and the SDK's whole detection (detector +
//! M3's re-boxed face check, `track::check_detections`) at the default operating point and at the
//! small-faces point (`track::SMALL_FACES_MIN_FACE_PX`).

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::Result;
use monotrack_core::detect::{Detection, DetectorConfig, FaceDetector};
use monotrack_core::image::{GrayImage, Rect};
use monotrack_core::landmarks::{FaceLandmarks, M3};
use monotrack_core::track::{
    DEFAULT_MIN_DETECTION_CONFIDENCE, DEFAULT_MIN_DETECTION_SCORE, LandmarkEstimator,
    ModelDetector, RegionDetector, SMALL_FACES_MIN_DETECTION_SCORE, SMALL_FACES_MIN_FACE_PX,
    check_detections,
};
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

/// The SDK's detection as the tracker runs it, with its buffers.
#[derive(Default)]
struct Cascade {
    /// The detector's faces (box, score), as the tracker's `RegionDetector` gives them.
    candidates: Vec<(Rect, f32)>,
    scratch: FaceLandmarks,
    accepted: Vec<(Rect, f32, f32, FaceLandmarks)>,
}

/// M3 without [`LandmarkEstimator::face_box`]: the cascade as it ran before re-boxing (the check on
/// the detector's box alone), to time what re-boxing costs.
struct NoRebox<'a>(&'a mut M3);

impl LandmarkEstimator for NoRebox<'_> {
    fn estimate(&mut self, image: &GrayImage, face: &Rect, out: &mut FaceLandmarks) -> Result<()> {
        self.0.estimate(image, face, out)
    }

    fn face_confidence(
        &mut self,
        image: &GrayImage,
        face: &Rect,
        out: &mut FaceLandmarks,
    ) -> Result<f32> {
        self.0.level1(image, face, out)
    }
}

impl Cascade {
    fn run<L: LandmarkEstimator>(&mut self, det: &mut ModelDetector, m3: &mut L, img: &GrayImage) {
        det.detect(img, &mut self.candidates).unwrap();
        check_detections(
            m3,
            img,
            &mut self.candidates,
            DEFAULT_MIN_DETECTION_CONFIDENCE,
            &mut self.scratch,
            &mut self.accepted,
        )
        .unwrap();
    }
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
    let mut m3 = M3::new().unwrap();
    let mut cascade = Cascade::default();
    for (name, min_face_px, score) in [
        (
            "detect_cascade_640x480",
            DetectorConfig::default().min_face_px,
            DEFAULT_MIN_DETECTION_SCORE,
        ),
        (
            "detect_cascade_640x480_small_faces",
            SMALL_FACES_MIN_FACE_PX,
            SMALL_FACES_MIN_DETECTION_SCORE,
        ),
    ] {
        let mut det = ModelDetector::new(DetectorConfig {
            min_face_px,
            score_threshold: score,
            ..DetectorConfig::default()
        })
        .unwrap();
        cascade.run(&mut det, &mut m3, &img);
        assert!(
            cascade
                .accepted
                .first()
                .is_some_and(|a| a.0.iou(&face) > 0.5),
            "{name}: the face is accepted first"
        );
        c.bench_function(name, |b| {
            b.iter(|| cascade.run(&mut det, &mut m3, black_box(&img)))
        });
        let checks = cascade.candidates.len();
        let mut plain = NoRebox(&mut m3);
        c.bench_function(&format!("{name}_no_rebox"), |b| {
            b.iter(|| cascade.run(&mut det, &mut plain, black_box(&img)))
        });
        eprintln!("{name}: {checks} candidates");
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(3));
    targets = bench
}
criterion_main!(benches);
