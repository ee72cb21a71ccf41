//! Motion comparison (`core::motion`) on Human3.6M: a sequence against a time-warped, shifted,
//! translated copy of itself recovers the warp and scores high; a growing fault in one joint
//! lowers the score and is blamed; another person doing the same action scores between those and
//! the same person doing another action. Needs `../shared` (skips with a printed reason).

mod body_common;

use body_common::*;
use monotrack_core::body::Joint;
use monotrack_core::motion::{MotionConfig, Pose3, Weights, compare};
use serde::Deserialize;

#[derive(Deserialize)]
struct Motion {
    fps: f64,
    sequences: Vec<Seq>,
}

#[derive(Deserialize)]
struct Seq {
    subject: String,
    action: String,
    joints3d_mm: Vec<Pose3>,
}

fn weights(frames: usize) -> Weights {
    let third = frames / 3;
    let phases: Vec<String> = (0..3)
        .map(|k| {
            let end = if k == 2 {
                frames - 1
            } else {
                (k + 1) * third - 1
            };
            format!(
                r#"{{"name": "part {}", "start_frame": {}, "end_frame": {end}}}"#,
                k + 1,
                k * third
            )
        })
        .collect();
    let mut features = Vec::new();
    for k in 1..=3 {
        for (joint, feature) in [
            ("relbow", "flexion"),
            ("lelbow", "flexion"),
            ("rknee", "flexion"),
            ("lknee", "flexion"),
            ("rshoulder", "flexion"),
            ("lshoulder", "abduction"),
            ("rwrist", "linear_velocity"),
            ("lankle", "linear_velocity"),
        ] {
            features.push(format!(
                r#"{{"phase": "part {k}", "joint": "{joint}", "feature": "{feature}", "weight": 1}}"#
            ));
        }
    }
    let json = format!(
        r#"{{"phases": [{}], "features": [{}]}}"#,
        phases.join(","),
        features.join(",")
    );
    Weights::from_json(json.as_bytes()).unwrap()
}

fn lerp(a: &Pose3, b: &Pose3, t: f64) -> Pose3 {
    std::array::from_fn(|j| std::array::from_fn(|c| a[j][c] + (b[j][c] - a[j][c]) * t))
}

/// The right forearm turned by `deg` in the arm's plane (the elbow bent more).
fn bend_right_elbow(p: &Pose3, deg: f64) -> Pose3 {
    let (s, e, w) = (
        Joint::RShoulder.index(),
        Joint::RElbow.index(),
        Joint::RWrist.index(),
    );
    let v = v3(&p[e]) - v3(&p[s]);
    let f = v3(&p[w]) - v3(&p[e]);
    let axis = v.cross(&f);
    let mut out = *p;
    if axis.norm() > 1e-9 {
        let r = nalgebra::Rotation3::from_axis_angle(
            &nalgebra::Unit::new_normalize(axis),
            deg.to_radians(),
        );
        let nw = v3(&p[e]) + r * f;
        out[w] = [nw.x, nw.y, nw.z];
    }
    out
}

#[test]
#[cfg_attr(not(shared_data), ignore = "needs ../shared/data")]
fn human36m_warps_faults_and_people() {
    let dir = converted("motion_h36m");
    let m: Motion = load(&dir, "motion.json");
    let find = |s: &str, a: &str| {
        &m.sequences
            .iter()
            .find(|q| q.subject == s && q.action == a)
            .unwrap()
            .joints3d_mm
    };
    let reference = find("S1", "Walking");
    let n = reference.len();
    let cfg = MotionConfig {
        fps: m.fps,
        // Half a second at 10 fps.
        sg_window: 5,
        sg_order: 2,
        ssim_window: 5,
        ..MotionConfig::default()
    };
    let w = weights(n);

    // Warped (slow start, fast end), 10 idle frames before, moved 0.5 m.
    let k = n + 10;
    let tau = |i: usize| (n - 1) as f64 * (i as f64 / (k - 1) as f64).powf(1.2);
    let mut trial: Vec<Pose3> = vec![reference[0]; 10];
    for i in 0..k {
        let t = tau(i);
        let (a, f) = (t.floor() as usize, t.fract());
        trial.push(lerp(&reference[a], &reference[(a + 1).min(n - 1)], f));
    }
    for joint in trial.iter_mut().flatten() {
        joint[0] += 400.0;
        joint[1] -= 200.0;
    }
    let rep = compare(reference, &trial, &w, &cfg).unwrap();
    // Truth: reference frame r sits at trial frame 10 + tau⁻¹(r).
    let truth = |r: usize| 10.0 + (k - 1) as f64 * (r as f64 / (n - 1) as f64).powf(1.0 / 1.2);
    let err: Vec<f64> = rep
        .path
        .iter()
        .map(|&(r, t)| (t as f64 - truth(r)).abs())
        .collect();
    let mean_err = err.iter().sum::<f64>() / err.len() as f64;
    let self_score = rep.overall;
    eprintln!(
        "H3.6M S1 Walking ({n} frames) vs its warped, shifted, moved copy: overall {self_score:.3}, \
         shift {}, mean path error {mean_err:.2} frames",
        rep.shift
    );
    assert!(self_score >= 0.95, "{}", rep.summary());
    assert!(mean_err < 2.0, "mean path error {mean_err} frames");

    // A growing fault in the right elbow, from the unchanged sequence (which scores 1).
    let mut last = compare(reference, reference, &w, &cfg).unwrap().overall;
    assert!((last - 1.0).abs() < 1e-9);
    let mut faults = Vec::new();
    for deg in [10.0, 20.0, 35.0, 50.0] {
        let bent: Vec<Pose3> = reference.iter().map(|p| bend_right_elbow(p, deg)).collect();
        let r = compare(reference, &bent, &w, &cfg).unwrap();
        faults.push((deg, r.overall));
        assert!(r.overall < last, "{deg}°: {} after {last}", r.overall);
        assert_eq!(r.worst.joint, Joint::RElbow, "{deg}°: {}", r.summary());
        last = r.overall;
    }
    eprintln!("right elbow bent by (deg, overall): {faults:.3?}");

    // Another person walking; the same person eating.
    let other_person = compare(reference, find("S5", "Walking"), &w, &cfg)
        .unwrap()
        .overall;
    let other_action = compare(reference, find("S1", "Eating"), &w, &cfg)
        .unwrap()
        .overall;
    eprintln!("S5 Walking {other_person:.3}, S1 Eating {other_action:.3}");
    assert!(
        self_score > other_person && other_person > other_action,
        "{self_score} {other_person} {other_action}"
    );
}
