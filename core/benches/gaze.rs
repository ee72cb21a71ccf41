//! Measures the point-of-gaze stage per face: eye centres from the fitted model, the calibrated
//! per-eye rays, the combined ray, and its location among the seven driver zones
//! (`examples/driver_zones.json`) and among one phone screen.

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::fit::{FaceFit, FitReport, Pose, Termination};
use monotrack_core::gaze::{
    GazeCalibration, GazeConfig, GazeRay, Target, point_of_gaze, targets_from_json,
};
use monotrack_core::landmarks::FaceLandmarks;
use monotrack_core::model::{N_ANIM, N_SHAPE};
use nalgebra::Vector3;
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let fit = FaceFit {
        pose: Pose::from_euler_deg(12.0, -6.0, 2.0, Vector3::new(10.0, 20.0, 450.0)),
        shape: [0.2; N_SHAPE],
        animation: [0.1; N_ANIM],
        report: FitReport {
            iterations: 0,
            rms_px: 0.0,
            termination: Termination::CostConverged,
            converged: true,
        },
        uncertainty: Default::default(),
    };
    let lm = FaceLandmarks {
        gaze_right: [0.05, 0.1, -0.99],
        gaze_left: [0.02, 0.12, -0.99],
        ..Default::default()
    };
    let zones = targets_from_json(include_bytes!("../../examples/driver_zones.json")).unwrap();
    let phone = [Target::screen("phone", 70.0, 150.0, [35.0, -8.0]).unwrap()];
    // A calibrated user: the correction is applied too.
    let mut cal = GazeCalibration::default();
    let eyes = [
        GazeRay {
            origin: Vector3::new(-31.0, 0.0, 450.0),
            direction: Vector3::new(0.05, 0.1, -0.99).normalize(),
        },
        GazeRay {
            origin: Vector3::new(31.0, 0.0, 450.0),
            direction: Vector3::new(0.02, 0.12, -0.99).normalize(),
        },
    ];
    cal.add_tap(&eyes, &Vector3::new(0.0, 60.0, 0.0)).unwrap();
    let cfg = GazeConfig::default();
    c.bench_function("gaze_per_face_driver_zones", |b| {
        b.iter(|| point_of_gaze(black_box(&lm), black_box(&fit), &cal, &cfg, None, &zones))
    });
    c.bench_function("gaze_per_face_phone_screen", |b| {
        b.iter(|| point_of_gaze(black_box(&lm), black_box(&fit), &cal, &cfg, None, &phone))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
