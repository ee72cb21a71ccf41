//! Measures CLFBA per frame (thesis Table 5.5): pose only (EPnP + IK + refinement, dimensions
//! known), pose + scale (DIRECT-L over the global scale, then the pose) and pose + dimensions
//! (DIRECT-L, then COBYLA over the twelve lengths, then the pose), all on one frame: a walking-like
//! model pose of a body 8 % larger than the mean, seen by a HumanEva-like camera 4 m away, with
//! fixed ±1 px noise on the 2D joints.
// Inputs made with the platform's maths library are fine here (core/clippy.toml).
#![allow(clippy::disallowed_methods)]

use criterion::{Criterion, criterion_group, criterion_main};
use monotrack_core::body::skeleton::{N_POSE, P_LARM, P_LLEG, P_RARM, P_RLEG, log_so3};
use monotrack_core::body::{
    BodyCamera, BodyFitConfig, BodyFitter, Convention, DimensionEstimator, Dimensions,
    FullSkeleton, Joints2d, N_JOINTS, PosePrior, Skeleton, hanim,
};
use monotrack_core::camera::Intrinsics;
use nalgebra::{Matrix3, Vector3};
use std::hint::black_box;

fn camera() -> BodyCamera {
    let tilt = 10f64.to_radians();
    let z = Vector3::new(0.0, tilt.cos(), -tilt.sin());
    let x = Vector3::new(1.0, 0.0, 0.0);
    let y = z.cross(&x);
    let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
    let c = Vector3::new(0.0, -4000.0, 1500.0);
    BodyCamera::new(
        Intrinsics::new(760.0, 760.0, 320.0, 240.0).unwrap(),
        r,
        -(r * c),
    )
    .unwrap()
}

fn observation(skel: &Skeleton, cam: &BodyCamera) -> Joints2d {
    let mut p = [0.0; N_POSE];
    let r0 = Matrix3::from_columns(&[
        Vector3::new(0.8, 0.6, 0.0),
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.6, -0.8, 0.0),
    ]);
    p[0..3].copy_from_slice(log_so3(&r0).as_slice());
    p[P_LARM..P_LARM + 4].copy_from_slice(&[-0.3, -1.2, 0.2, 0.6]);
    p[P_RARM..P_RARM + 4].copy_from_slice(&[0.2, 1.3, -0.1, 0.3]);
    p[P_LLEG..P_LLEG + 4].copy_from_slice(&[-0.35, 0.05, 0.0, 0.2]);
    p[P_RLEG..P_RLEG + 4].copy_from_slice(&[0.25, -0.05, 0.0, 0.5]);
    let mut x = [Vector3::zeros(); N_JOINTS];
    skel.forward(&p, &mut x);
    p[5] = skel.ankle_height - x[10].z.min(x[13].z);
    skel.forward(&p, &mut x);
    Joints2d::full(std::array::from_fn(|i| {
        let q = cam.project(&x[i]);
        [
            q[0] + ((i * 7) % 5) as f64 * 0.5 - 1.0,
            q[1] + ((i * 3) % 5) as f64 * 0.5 - 1.0,
        ]
    }))
}

fn bench(c: &mut Criterion) {
    let conv = Convention::HumanEva;
    let cam = camera();
    let truth = Skeleton::new(Dimensions::mean(conv).scaled(1.08), conv).unwrap();
    let obs = observation(&truth, &cam);
    let fitter = BodyFitter::default();
    c.bench_function("body_pose_only", |b| {
        b.iter(|| fitter.fit(black_box(&obs), &cam, &truth).unwrap())
    });
    // A tracked frame: refined from the previous frame's pose (here the same frame's fit: a
    // still subject).
    let last = fitter.fit(&obs, &cam, &truth).unwrap().pose;
    c.bench_function("body_pose_tracked", |b| {
        b.iter(|| {
            fitter
                .fit_tracked(black_box(&obs), &cam, &truth, Some(&last))
                .unwrap()
        })
    });
    // The same refined in the full 54-DoF model.
    let full = BodyFitter::new(BodyFitConfig {
        full_model: true,
        ..Default::default()
    });
    c.bench_function("body_pose_only_full_model", |b| {
        b.iter(|| full.fit(black_box(&obs), &cam, &truth).unwrap())
    });
    let fs = FullSkeleton::new(truth);
    let full_init = hanim::embed(&fitter.initialise(&obs, &cam, &truth).unwrap());
    let mut posed = hanim::Posed::default();
    c.bench_function("body_full_forward_kinematics", |b| {
        b.iter(|| fs.forward(black_box(&full_init), &mut posed))
    });
    // The same with the isotropic prior used before the learnt one (weight 3 px per radian).
    let neutral = BodyFitter {
        config: BodyFitConfig {
            prior_weight_px: 3.0,
            ..Default::default()
        },
        prior: PosePrior::neutral(),
    };
    c.bench_function("body_pose_only_neutral_prior", |b| {
        b.iter(|| neutral.fit(black_box(&obs), &cam, &truth).unwrap())
    });
    // The two halves of a pose fit: EPnP + IK initialisation, then the LM refinement.
    c.bench_function("body_pose_initialise", |b| {
        b.iter(|| fitter.initialise(black_box(&obs), &cam, &truth).unwrap())
    });
    let init = fitter.initialise(&obs, &cam, &truth).unwrap();
    c.bench_function("body_pose_refine", |b| {
        b.iter(|| {
            fitter
                .fit_from(black_box(&obs), &cam, &truth, &init)
                .unwrap()
        })
    });
    let mut joints = [Vector3::zeros(); N_JOINTS];
    c.bench_function("body_forward_kinematics", |b| {
        b.iter(|| truth.forward(black_box(&init), &mut joints))
    });
    let scale_only = DimensionEstimator {
        separate_dimensions: false,
        ..Default::default()
    };
    let mean = Dimensions::mean(conv);
    c.bench_function("body_pose_and_scale", |b| {
        b.iter(|| {
            let est = scale_only
                .estimate(
                    &fitter,
                    std::slice::from_ref(black_box(&obs)),
                    &cam,
                    &mean,
                    conv,
                )
                .unwrap();
            let skel = Skeleton::new(est.dimensions, conv).unwrap();
            fitter.fit(&obs, &cam, &skel).unwrap()
        })
    });
    let full = DimensionEstimator::default();
    c.bench_function("body_pose_and_dimensions", |b| {
        b.iter(|| {
            let est = full
                .estimate(
                    &fitter,
                    std::slice::from_ref(black_box(&obs)),
                    &cam,
                    &mean,
                    conv,
                )
                .unwrap();
            let skel = Skeleton::new(est.dimensions, conv).unwrap();
            fitter.fit(&obs, &cam, &skel).unwrap()
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
