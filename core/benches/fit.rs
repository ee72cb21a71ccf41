//! Measures the 3D fits per face: MSBP from scratch (three yaw seeds, three rounds — a single
//! image), MSBP when tracking (one round from the previous frame's fit, shape held — the per-frame
//! cost in video), and FFBP. Landmarks: the model projected at yaw 25°, 700 mm, with fixed noise.

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::camera::Intrinsics;
use monotrack_core::fit::{Ffbp, FfbpConfig, Msbp, MsbpConfig, Pose};
use monotrack_core::model::{FaceModel, N_ANIM, N_LANDMARKS, N_SHAPE};
use nalgebra::Vector3;
use std::hint::black_box;

fn landmarks(cam: &Intrinsics) -> [[f64; 2]; N_LANDMARKS] {
    let pose = Pose::from_euler_deg(25.0, -8.0, 4.0, Vector3::new(30.0, -15.0, 700.0));
    let mut obs = [[0.0; 2]; N_LANDMARKS];
    FaceModel::builtin().project_into(
        &[0.3; N_SHAPE],
        &[0.2; N_ANIM],
        &pose.rotation,
        &pose.translation,
        cam,
        &mut obs,
    );
    for (i, p) in obs.iter_mut().enumerate() {
        p[0] += ((i * 7) % 5) as f64 * 0.4 - 0.8;
        p[1] += ((i * 3) % 5) as f64 * 0.4 - 0.8;
    }
    obs
}

fn bench(c: &mut Criterion) {
    let cam = Intrinsics::default_for(640, 480).unwrap();
    let obs = landmarks(&cam);
    let mut msbp = Msbp::new(MsbpConfig::default());
    c.bench_function("msbp_single_image", |b| {
        b.iter(|| msbp.fit(black_box(&obs), None, &cam, None).unwrap())
    });
    let prev = msbp.fit(&obs, None, &cam, None).unwrap();
    let mut tracking = Msbp::new(MsbpConfig {
        outer_iterations: 1,
        ..Default::default()
    });
    tracking.set_fixed_shape(Some(prev.shape));
    c.bench_function("msbp_tracking_frame", |b| {
        b.iter(|| {
            tracking
                .fit(black_box(&obs), None, &cam, Some(&prev))
                .unwrap()
        })
    });
    let mut ffbp = Ffbp::new(FfbpConfig::default());
    c.bench_function("ffbp", |b| {
        b.iter(|| ffbp.fit(black_box(&obs), None, &cam).unwrap())
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30).measurement_time(std::time::Duration::from_secs(3));
    targets = bench
}
criterion_main!(benches);
