//! Soak test of the face tracker: 10,000 frames of a replayed synthetic sequence (tracking, cuts,
//! losses and re-detections recurring) with the oracle detector and landmark estimator; the
//! process's resident memory must not grow after warm-up. Its own test binary, so no other test's
//! allocations share the process.

use monotrack_core::image::GrayImage;
use monotrack_core::track::{FaceTracker, TrackerConfig};
use monotrack_tests::synth::{
    FrameTruth, OracleDetector, OracleLandmarks, SeqConfig, Sequence, load_validation_faces,
};
use std::cell::Cell;
use std::rc::Rc;

/// Oracle landmark noise, pixels per coordinate (as in `track_synthetic.rs`).
const NOISE_PX: f32 = 1.0;

/// Resident set size in KiB from /proc (Linux); `None` elsewhere.
fn rss_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = s.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4)
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn soak_10k_frames_without_memory_growth() {
    let data = monotrack_tests::shared_data();
    let faces = load_validation_faces(&data, 6, 100.0).unwrap();
    // 3 segments of 40 frames (cuts included), replayed: tracking, losses and re-detections recur.
    let cfg = SeqConfig {
        segments: 3,
        segment_frames: 40,
        still_frames: 10,
        seed: 3,
        ..Default::default()
    };
    let seq = Sequence::new(cfg, faces).unwrap();
    let frames: Vec<(GrayImage, FrameTruth)> = (0..seq.len())
        .map(|i| {
            let mut img = GrayImage::default();
            let t = seq.render(i, &mut img);
            (img, t)
        })
        .collect();
    let truth = Rc::new(Cell::new(FrameTruth::default()));
    let mut tracker = FaceTracker::new(
        OracleDetector::new(truth.clone()),
        OracleLandmarks::new(truth.clone(), NOISE_PX, 5),
        TrackerConfig::default(),
    )
    .unwrap();
    const FRAMES: usize = 10_000;
    const WARM_UP: usize = 500;
    let mut rss_after_warm_up = None;
    let mut with_face = 0;
    for i in 0..FRAMES {
        let (img, t) = &frames[i % frames.len()];
        truth.set(*t);
        let r = tracker.process(img, i as i64 * 33_333_333).unwrap();
        with_face += usize::from(!r.faces.is_empty());
        if i + 1 == WARM_UP {
            rss_after_warm_up = rss_kib();
        }
    }
    let end = rss_kib();
    println!(
        "soak: {FRAMES} frames, {with_face} with a face, {} detector calls, RSS after warm-up {:?} KiB, at the end {:?} KiB",
        tracker.detector().calls,
        rss_after_warm_up,
        end
    );
    // Each replay has 3 segments: the detector runs on each segment's first tracked frame only.
    assert!(tracker.detector().calls <= 3 * FRAMES.div_ceil(frames.len()) + 1);
    assert!(with_face >= FRAMES * 9 / 10);
    if let (Some(a), Some(b)) = (rss_after_warm_up, end) {
        // Allocator noise only: the tracker allocates nothing per frame after warm-up.
        assert!(b <= a + 1024, "RSS grew from {a} KiB to {b} KiB");
    }
}
