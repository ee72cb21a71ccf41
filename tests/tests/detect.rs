//! The face detector (`core::detect`) end to end on real images.
//!
//! - Golden: `samples/data/astronaut.jpg` (public domain, one face), at the high-precision operating
//!   point [`GOLDEN_CONFIG`] (min face 16 px, threshold 0.9), gives exactly one face whose box
//!   matches [`ASTRONAUT_BOX`] at IoU ≥ [`GOLDEN_MIN_IOU`]. The expected box is the detector's own
//!   output when the committed model was trained (identical to the Python/onnxruntime reference
//!   decoder in `train.py` to 0.1 px), checked by eye: the brow-to-chin face box of the M3
//!   convention, a little tight on this face (it ends ~5 px above the chin and inside the jaw line;
//!   IoU 0.89 with the previous model's box; over the validation split the box calibration of
//!   `eval_peers.py` is identity within 2 %). The tolerance allows small numeric drift (other tract
//!   versions, SIMD paths) but not a different face or box convention. At the default config the
//!   model also fires on the helmet visor (score 0.67, below the face's 0.93; a known false
//!   positive recorded in `models/MODEL_CARD.md`).
//! - faces68 validation split (`core/models/M3_IO.md`: line i when i % 10 == 0), min face 16 px,
//!   threshold 0.5:
//!   recall at IoU ≥ 0.5 against the tight landmark boxes stays above [`VAL_MIN_RECALL`]. Skips with
//!   a printed reason when `../shared` is absent.

use monotrack_core::detect::{DetectorConfig, FaceDetector};
use monotrack_core::image::{GrayImage, Rect, rgb_to_contract_luma};
use serde::Deserialize;
use std::path::Path;

/// Expected astronaut face box `[x, y, w, h]` (see the module docs).
const ASTRONAUT_BOX: [f32; 4] = [180.0, 88.1, 88.7, 89.2];
/// Settings of the golden case (see the module docs).
const GOLDEN_CONFIG: DetectorConfig = DetectorConfig {
    score_threshold: 0.9,
    nms_iou: 0.4,
    min_face_px: 16.0,
    max_faces: 32,
};
/// IoU with [`ASTRONAUT_BOX`] the golden detection must reach.
const GOLDEN_MIN_IOU: f32 = 0.9;
/// Recall floor on the validation split at min face 16 px, threshold 0.5: measured 0.9531
/// (122 of 128 faces, this test at commit time) minus a margin of 3 faces (119 / 128 = 0.9297).
const VAL_MIN_RECALL: f64 = 0.929;

/// Luma per `core/models/M3_IO.md`: 0.299 R + 0.587 G + 0.114 B, rounded.
fn read_luma(path: &Path) -> GrayImage {
    let img = image::open(path).unwrap().into_rgb8();
    let mut out = GrayImage::new(img.width() as usize, img.height() as usize);
    rgb_to_contract_luma(img.as_raw(), out.data_mut());
    out
}

#[test]
fn astronaut_golden() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/data/astronaut.jpg");
    let img = read_luma(&path);
    let mut det = FaceDetector::with_config(GOLDEN_CONFIG).unwrap();
    let mut out = Vec::new();
    det.detect(&img, &mut out).unwrap();
    eprintln!("astronaut: {out:?}");
    assert_eq!(out.len(), 1, "{out:?}");
    let [x, y, w, h] = ASTRONAUT_BOX;
    let iou = out[0].rect.iou(&Rect::new(x, y, w, h));
    assert!(iou >= GOLDEN_MIN_IOU, "IoU {iou} with the expected box");
}

#[derive(Deserialize)]
struct Face {
    landmarks68: Vec<[f32; 2]>,
}
#[derive(Deserialize)]
struct Line {
    image: String,
    faces: Vec<Face>,
}

#[test]
fn faces68_validation_recall() {
    let Some(data) = monotrack_tests::shared_data_or_skip("faces68_validation_recall") else {
        return;
    };
    let train = std::fs::read_to_string(data.join("faces68/train.jsonl")).unwrap();
    let mut det = FaceDetector::with_config(DetectorConfig {
        min_face_px: 16.0,
        score_threshold: 0.5,
        ..Default::default()
    })
    .unwrap();
    let (mut n_faces, mut hits, mut n_images, mut n_dets) = (0usize, 0usize, 0usize, 0usize);
    let mut out = Vec::new();
    for (i, text) in train.lines().enumerate() {
        if i % 10 != 0 {
            continue;
        }
        let line: Line = serde_json::from_str(text).unwrap();
        let img = read_luma(&data.join("faces68").join(&line.image));
        det.detect(&img, &mut out).unwrap();
        n_images += 1;
        n_dets += out.len();
        let mut used = vec![false; out.len()];
        for f in &line.faces {
            let (mut x0, mut y0, mut x1, mut y1) = (f32::MAX, f32::MAX, f32::MIN, f32::MIN);
            for p in &f.landmarks68 {
                x0 = x0.min(p[0]);
                y0 = y0.min(p[1]);
                x1 = x1.max(p[0]);
                y1 = y1.max(p[1]);
            }
            let gt = Rect::new(x0, y0, x1 - x0, y1 - y0);
            n_faces += 1;
            let best = (0..out.len())
                .filter(|&k| !used[k])
                .map(|k| (k, out[k].rect.iou(&gt)))
                .max_by(|a, b| a.1.total_cmp(&b.1));
            if let Some((k, v)) = best.filter(|b| b.1 >= 0.5) {
                debug_assert!(v >= 0.5);
                used[k] = true;
                hits += 1;
            }
        }
    }
    let recall = hits as f64 / n_faces as f64;
    eprintln!(
        "faces68 validation: {n_images} images, {n_faces} faces, recall {recall:.4} (IoU >= 0.5), \
         {n_dets} detections (unmatched ones include unannotated background faces)"
    );
    assert!(
        recall >= VAL_MIN_RECALL,
        "recall {recall} < {VAL_MIN_RECALL}"
    );
}
