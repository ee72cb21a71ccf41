//! Measures a motion comparison of 10 s at 30 fps: a 300-frame reference against a 320-frame
//! trial (an arm swing, the trial slower and with the elbow bent more), twelve weighted features
//! over three phases.
// Inputs made with the platform's maths library are fine here (core/clippy.toml).
#![allow(clippy::disallowed_methods)]

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::body::{Joint, N_JOINTS};
use monotrack_core::motion::{MotionConfig, Pose3, Weights, compare};
use std::hint::black_box;

fn pose(phase: f64, bend: f64) -> Pose3 {
    let tau = std::f64::consts::TAU;
    let th = (50.0 * (tau * phase).sin()).to_radians();
    let el = (30.0 + 25.0 * (tau * phase).cos() + bend).to_radians();
    let kn = (20.0 + 20.0 * (tau * phase).sin()).to_radians();
    let mut p: Pose3 = [[0.0; 3]; N_JOINTS];
    let set = |p: &mut Pose3, j: Joint, v: [f64; 3]| p[j.index()] = v;
    set(&mut p, Joint::Pelvis, [0.0, 0.0, 900.0]);
    set(&mut p, Joint::Thorax, [0.0, 0.0, 1400.0]);
    set(&mut p, Joint::Head, [0.0, 20.0, 1620.0]);
    set(&mut p, Joint::LShoulder, [180.0, 0.0, 1380.0]);
    set(&mut p, Joint::LElbow, [200.0, 0.0, 1100.0]);
    set(&mut p, Joint::LWrist, [210.0, 60.0, 860.0]);
    set(&mut p, Joint::RShoulder, [-180.0, 0.0, 1380.0]);
    set(
        &mut p,
        Joint::RElbow,
        [-180.0, 290.0 * th.sin(), 1380.0 - 290.0 * th.cos()],
    );
    let e = p[Joint::RElbow.index()];
    set(
        &mut p,
        Joint::RWrist,
        [
            e[0],
            e[1] + 250.0 * (th + el).sin(),
            e[2] - 250.0 * (th + el).cos(),
        ],
    );
    set(&mut p, Joint::LHip, [100.0, 0.0, 900.0]);
    set(
        &mut p,
        Joint::LKnee,
        [100.0, 420.0 * kn.sin(), 900.0 - 420.0 * kn.cos()],
    );
    let k = p[Joint::LKnee.index()];
    set(&mut p, Joint::LAnkle, [k[0], k[1], k[2] - 400.0]);
    set(&mut p, Joint::RHip, [-100.0, 0.0, 900.0]);
    set(&mut p, Joint::RKnee, [-100.0, 0.0, 480.0]);
    set(&mut p, Joint::RAnkle, [-100.0, 0.0, 80.0]);
    p
}

fn bench(c: &mut Criterion) {
    let seq = |n: usize, bend: f64| -> Vec<Pose3> {
        (0..n)
            .map(|i| pose(i as f64 / (n - 1) as f64, bend))
            .collect()
    };
    let (reference, trial) = (seq(300, 0.0), seq(320, 15.0));
    let mut features = Vec::new();
    for phase in ["address", "swing", "finish"] {
        for (joint, feature) in [
            ("relbow", "flexion"),
            ("rshoulder", "flexion"),
            ("lknee", "flexion"),
            ("rwrist", "linear_velocity"),
        ] {
            features.push(format!(
                r#"{{"phase": "{phase}", "joint": "{joint}", "feature": "{feature}", "weight": 1}}"#
            ));
        }
    }
    let json = format!(
        r#"{{"phases": [{{"name": "address", "start_frame": 0, "end_frame": 99}},
            {{"name": "swing", "start_frame": 100, "end_frame": 199}},
            {{"name": "finish", "start_frame": 200, "end_frame": 299}}], "features": [{}]}}"#,
        features.join(",")
    );
    let w = Weights::from_json(json.as_bytes()).unwrap();
    let cfg = MotionConfig::default();
    c.bench_function("compare_motion_10s_30fps", |b| {
        b.iter(|| compare(black_box(&reference), black_box(&trial), &w, &cfg).unwrap())
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
