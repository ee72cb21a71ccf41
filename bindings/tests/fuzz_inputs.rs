//! Bad input through the FFI surface gives a typed error, never a panic: thousands of seeded random
//! calls of every exported function and method with malformed sizes, strides, formats, rotations,
//! non-finite numbers, huge values and random bytes. A panic would reach Kotlin/Swift as an
//! `Internal` exception at best, so any panic here fails the test.

use monotrack_ffi::*;
use std::panic::{AssertUnwindSafe, catch_unwind};

/// SplitMix64: deterministic everywhere.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
    /// A float that is often ordinary, sometimes extreme or non-finite.
    fn float(&mut self, scale: f64) -> f64 {
        match self.below(12) {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => -1e30,
            3 => 0.0,
            _ => (self.next() as f64 / u64::MAX as f64 - 0.3) * scale,
        }
    }
    fn small(&mut self) -> u32 {
        match self.below(6) {
            0 => 0,
            1 => 1,
            2 => u32::MAX,
            _ => self.below(700) as u32,
        }
    }
}

fn format(r: &mut Rng) -> PixelFormat {
    [
        PixelFormat::Rgba8,
        PixelFormat::Bgra8,
        PixelFormat::Rgb8,
        PixelFormat::Gray8,
        PixelFormat::Nv21,
        PixelFormat::Nv12,
        PixelFormat::I420,
    ][r.below(7) as usize]
}

fn desc(r: &mut Rng) -> FrameDesc {
    let (w, h) = (r.small().min(400), r.small().min(300));
    FrameDesc {
        width: w,
        height: h,
        format: format(r),
        row_stride: if r.below(2) == 0 { w * 4 } else { r.small() },
        uv_row_stride: r.small(),
        uv_pixel_stride: r.below(4) as u32,
        rotation_degrees: [0, 90, 180, 270, 45, 360][r.below(6) as usize],
        mirrored: r.below(2) == 0,
    }
}

fn bytes(r: &mut Rng, d: &FrameDesc) -> Vec<u8> {
    // Often exactly what a plausible layout needs, sometimes one short, sometimes random.
    let guess = (d.row_stride.min(4000) as usize) * (d.height.min(300) as usize) * 2;
    let n = match r.below(3) {
        0 => guess,
        1 => guess.saturating_sub(1),
        _ => r.below(200_000) as usize,
    };
    (0..n).map(|i| (i as u64 ^ r.next()) as u8).collect()
}

fn point(r: &mut Rng) -> Point2 {
    Point2 {
        x: r.float(2000.0) as f32,
        y: r.float(2000.0) as f32,
    }
}

fn intrinsics(r: &mut Rng) -> CameraIntrinsics {
    CameraIntrinsics {
        fx: r.float(2000.0),
        fy: r.float(2000.0),
        cx: r.float(1000.0),
        cy: r.float(1000.0),
    }
}

fn no_panic(what: &str, case: usize, f: impl FnOnce()) {
    if catch_unwind(AssertUnwindSafe(f)).is_err() {
        panic!("{what} panicked on case {case}");
    }
}

/// The FFI turns a panic into `MonotrackError::Internal` (`error::guard`), so a panic inside a
/// call shows up here as that error: bad input must give the other, typed errors.
fn typed<T>(what: &str, case: usize, r: Result<T, MonotrackError>) {
    if let Err(MonotrackError::Internal { msg }) = r {
        panic!("{what} failed internally on case {case}: {msg}");
    }
}

static LIVE_INTERNAL: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// A live-stream listener that drops what it gets (the fuzzing is of the inputs).
struct Ignore;

impl LiveStreamListener for Ignore {
    fn on_result(&self, _: LiveStreamResult) {}
    fn on_error(&self, _: i64, _: u64, error: MonotrackError) {
        // Read by the test after the worker stopped (a panic here would only reach the worker).
        if matches!(error, MonotrackError::Internal { .. }) {
            LIVE_INTERNAL.store(true, std::sync::atomic::Ordering::SeqCst);
        }
    }
}

#[test]
fn frames_and_trackers_never_panic() {
    let mut r = Rng(1);
    let mode = |m| FaceTrackerOptions {
        running_mode: Some(m),
        ..FaceTrackerOptions::default()
    };
    let tracker = FaceTracker::new(mode(RunningMode::Video), None).unwrap();
    let image = FaceTracker::new(mode(RunningMode::Image), None).unwrap();
    let live = FaceTracker::new(
        mode(RunningMode::LiveStream),
        Some(std::sync::Arc::new(Ignore)),
    )
    .unwrap();
    let mut ok_frames = 0;
    for case in 0..300 {
        let d = desc(&mut r);
        let b = bytes(&mut r, &d);
        no_panic("luma_image", case, || {
            ok_frames += usize::from(luma_image(&b, d).is_ok());
        });
        let ts = r.next() as i64;
        no_panic("detect_for_video", case, || {
            typed(
                "detect_for_video",
                case,
                tracker.detect_for_video(&b, d, ts),
            );
        });
        no_panic("detect_async", case, || {
            typed("detect_async", case, live.detect_async(&b, d, ts));
        });
        no_panic("detect", case, || {
            typed("detect", case, image.detect(&b, d));
        });
        no_panic("frame rules", case, || {
            typed("upright_size", case, upright_size(d));
            typed("frame_byte_count", case, frame_byte_count(d));
        });
        let cfg = FaceTrackerOptions {
            running_mode: Some([RunningMode::Image, RunningMode::Video][r.below(2) as usize]),
            num_faces: r.small(),
            min_face_detection_confidence: r.float(1.5) as f32,
            min_face_presence_confidence: r.float(1.5) as f32,
            min_tracking_confidence: r.float(1.5) as f32,
            output_action_units: r.below(2) == 0,
            output_facial_transformation_matrixes: r.below(2) == 0,
            output_gestures: r.below(2) == 0,
            output_gaze: r.below(2) == 0,
            camera: (r.below(2) == 0).then(|| intrinsics(&mut r)),
            models: None,
            tuning: TrackerTuning {
                min_face_size_px: r.small(),
                min_match_score: r.float(3.0) as f32 - 1.0,
                search_margin: r.float(6.0) as f32 - 1.0,
                flow_filter: r.below(2) == 0,
                gaze_filter: r.below(2) == 1,
                shape_frames: r.small(),
                mirror_average: [None, Some(false), Some(true)][r.below(3) as usize],
                ultra_light: r.below(2) == 0,
                quality: QualityThresholds {
                    dark_luma: r.float(300.0) as f32 - 20.0,
                    blur_drop: r.float(1.5) as f32,
                    max_yaw_deg: r.float(200.0) as f32,
                    ..QualityThresholds::default()
                },
            },
        };
        no_panic("FaceTracker::new", case, || {
            typed("FaceTracker::new", case, FaceTracker::new(cfg, None));
        });
        let (w, h) = (r.small(), r.small());
        no_panic("default_camera", case, || {
            typed("default_camera", case, default_camera(w, h));
        });
    }
    live.shutdown();
    assert!(
        !LIVE_INTERNAL.load(std::sync::atomic::Ordering::SeqCst),
        "the live worker failed internally"
    );
    // Some cases must be valid, or the error paths alone were exercised.
    assert!(ok_frames >= 20, "only {ok_frames} valid frames");
}

#[test]
fn fits_never_panic() {
    let mut r = Rng(2);
    let mut ok_fits = 0;
    for case in 0..300 {
        let n = [68, 68, 68, 0, 67, 69][r.below(6) as usize];
        // A quarter garbage (non-finite, extreme); otherwise scattered finite points in a box,
        // which a fit must take without failing (whatever the pose it finds).
        let garbage = r.below(4) == 0;
        let pts: Vec<Point2> = (0..n)
            .map(|i| {
                if garbage {
                    point(&mut r)
                } else {
                    Point2 {
                        x: 250.0 + (i % 9) as f32 * 15.0 + r.below(10) as f32,
                        y: 180.0 + (i / 9) as f32 * 15.0 + r.below(10) as f32,
                    }
                }
            })
            .collect();
        let cam = (r.below(2) == 0).then(|| intrinsics(&mut r));
        let method = if r.below(2) == 0 {
            FitMethod::Msbp
        } else {
            FitMethod::Ffbp
        };
        let (w, h) = (r.small(), r.small());
        no_panic("fit_landmarks", case, || {
            ok_fits += usize::from(fit_landmarks(pts, w, h, cam, method).is_ok());
        });
    }
    assert!(ok_fits >= 20, "only {ok_fits} fits ran");
}

#[test]
fn body_calls_never_panic() {
    let mut r = Rng(3);
    let joints = monotrack_core::body::Joint::ALL.map(BodyJoint::from);
    // A valid camera so that fits get past construction and meet random joints.
    let camera = BodyCameraPose {
        intrinsics: CameraIntrinsics {
            fx: 1000.0,
            fy: 1000.0,
            cx: 320.0,
            cy: 240.0,
        },
        rotation: vec![1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0],
        translation_mm: Vec3 {
            x: 0.0,
            y: 1200.0,
            z: 3000.0,
        },
    };
    let body = BodyTracker::new(
        camera.clone(),
        BodyTrackerConfig {
            dimension_frames: 2,
            ..default_body_tracker_config()
        },
    )
    .unwrap();
    let body_full = BodyTracker::new(
        camera.clone(),
        BodyTrackerConfig {
            dimension_frames: 2,
            full_model: true,
            ..default_body_tracker_config()
        },
    )
    .unwrap();
    let mut ok_bodies = 0;
    for case in 0..200 {
        let corners: Vec<Point2> = (0..[4, 4, 3, 5][r.below(4) as usize])
            .map(|_| point(&mut r))
            .collect();
        let k = (r.below(2) == 0).then(|| intrinsics(&mut r));
        let (sw, sd, w, h) = (r.float(5000.0), r.float(5000.0), r.small(), r.small());
        no_panic("calibrate_floor_camera", case, || {
            typed(
                "calibrate_floor_camera",
                case,
                calibrate_floor_camera(corners, sw, sd, w, h, k),
            );
        });
        let mut cam = camera.clone();
        if r.below(2) == 0 {
            let n = [9, 9, 8, 0][r.below(4) as usize];
            cam.rotation = (0..n).map(|_| r.float(2.0)).collect();
            cam.translation_mm.z = r.float(5000.0);
            cam.intrinsics = intrinsics(&mut r);
        }
        let cfg = BodyTrackerConfig {
            dimension_frames: r.small().min(4),
            convention: if r.below(2) == 0 {
                BodyConvention::HumanEva
            } else {
                BodyConvention::Human36m
            },
            assume_contact: r.below(2) == 0,
            prior_weight_px: r.float(10.0),
            full_model: r.below(2) == 0,
        };
        no_panic("BodyTracker::new", case, || {
            typed("BodyTracker::new", case, BodyTracker::new(cam, cfg));
        });
        // Mostly plausible bodies (jittered around a standing figure), sometimes garbage.
        let mut obs = Vec::new();
        for (i, j) in joints.iter().enumerate() {
            if r.below(8) == 0 {
                continue;
            }
            let position = if r.below(10) == 0 {
                point(&mut r)
            } else {
                Point2 {
                    x: 320.0 + ((i % 3) as f32 - 1.0) * 30.0 + r.below(20) as f32,
                    y: 100.0 + i as f32 * 20.0 + r.below(20) as f32,
                }
            };
            obs.push(BodyJoint2d {
                joint: *j,
                position,
            });
        }
        // Every other case goes to the tracker that refines in the full 54-DoF model.
        let tracker = if case % 2 == 0 { &body } else { &body_full };
        no_panic("BodyTracker::fit", case, || {
            ok_bodies += usize::from(tracker.fit(obs).is_ok());
        });
        if r.below(20) == 0 {
            body.reset();
            body_full.reset();
        }
    }
    assert!(ok_bodies >= 20, "only {ok_bodies} body fits ran");
}
