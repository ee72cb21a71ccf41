use super::filter::{SavitzkyGolay, ssim};
use super::*;
use crate::math::Libm;

/// A golf-like swing: the right arm swings forward and back in the sagittal plane with its elbow
/// bending, the left knee flexes; `phase(t)` in 0..1 drives it, `bend` adds to the right elbow.
fn pose(phase: f64, bend: f64, offset: [f64; 3], size: f64) -> Pose3 {
    use Joint::*;
    let s = |v: [f64; 3]| add(&scale(&v, size), &offset);
    let mut p = [[0.0; 3]; N_JOINTS];
    let th = (60.0 * (std::f64::consts::TAU * phase).msin()).to_radians();
    let el = (35.0 + 30.0 * (std::f64::consts::TAU * phase).mcos() + bend).to_radians();
    let kn = (20.0 + 20.0 * (std::f64::consts::TAU * phase).msin()).to_radians();
    p[Pelvis.index()] = s([0.0, 0.0, 900.0]);
    p[Thorax.index()] = s([0.0, 0.0, 1400.0]);
    p[Head.index()] = s([0.0, 20.0, 1620.0]);
    p[LShoulder.index()] = s([180.0, 0.0, 1380.0]);
    p[LElbow.index()] = s([200.0, 0.0, 1100.0]);
    p[LWrist.index()] = s([210.0, 60.0, 860.0]);
    p[RShoulder.index()] = s([-180.0, 0.0, 1380.0]);
    let upper = [0.0, th.msin(), -th.mcos()];
    let fore = [0.0, (th + el).msin(), -(th + el).mcos()];
    p[RElbow.index()] = add(&p[RShoulder.index()], &scale(&upper, 290.0 * size));
    p[RWrist.index()] = add(&p[RElbow.index()], &scale(&fore, 250.0 * size));
    p[LHip.index()] = s([100.0, 0.0, 900.0]);
    p[LKnee.index()] = add(
        &p[LHip.index()],
        &scale(&[0.0, kn.msin(), -kn.mcos()], 420.0 * size),
    );
    p[LAnkle.index()] = add(&p[LKnee.index()], &scale(&[0.0, 0.0, -1.0], 400.0 * size));
    p[RHip.index()] = s([-100.0, 0.0, 900.0]);
    p[RKnee.index()] = s([-100.0, 0.0, 480.0]);
    p[RAnkle.index()] = s([-100.0, 0.0, 80.0]);
    p
}

fn swing(
    frames: usize,
    warp: impl Fn(f64) -> f64,
    bend: f64,
    offset: [f64; 3],
    size: f64,
) -> Vec<Pose3> {
    (0..frames)
        .map(|i| pose(warp(i as f64 / (frames - 1) as f64), bend, offset, size))
        .collect()
}

fn weights() -> Weights {
    Weights::from_json(
        br#"{"phases": [{"name": "back-swing", "start_frame": 0, "end_frame": 44},
                        {"name": "follow-through", "start_frame": 45, "end_frame": 89}],
             "features": [
               {"phase": "back-swing", "joint": "relbow", "feature": "flexion", "weight": 2},
               {"phase": "back-swing", "joint": "rshoulder", "feature": "flexion", "weight": 1},
               {"phase": "back-swing", "joint": "lknee", "feature": "flexion", "weight": 1},
               {"phase": "follow-through", "joint": "rwrist", "feature": "linear_velocity", "weight": 1},
               {"phase": "follow-through", "joint": "relbow", "feature": "angular_velocity", "weight": 1},
               {"phase": "follow-through", "joint": "rshoulder", "feature": "abduction", "weight": 1}]}"#,
    )
    .unwrap()
}

#[test]
fn savitzky_golay_is_exact_on_cubics_to_the_ends() {
    let sg = SavitzkyGolay::new(9, 3);
    let f = |t: f64| 2.0 - 0.5 * t + 0.03 * t * t - 0.001 * t * t * t;
    let df = |t: f64| -0.5 + 0.06 * t - 0.003 * t * t;
    let ddf = |t: f64| 0.06 - 0.006 * t;
    let x: Vec<f64> = (0..30).map(|i| f(f64::from(i))).collect();
    let (v, d, dd) = (sg.apply(&x, 0), sg.apply(&x, 1), sg.apply(&x, 2));
    for i in 0..30 {
        assert!((v[i] - x[i]).abs() < 1e-9, "{i}");
        assert!((d[i] - df(i as f64)).abs() < 1e-9, "{i}");
        assert!((dd[i] - ddf(i as f64)).abs() < 1e-9, "{i}");
    }
    // Shorter than the window: fitted whole.
    assert_eq!(sg.apply(&x[..4], 0).len(), 4);
}

#[test]
fn ssim_is_one_for_equal_series_and_falls_with_differences() {
    let x: Vec<f64> = (0..40)
        .map(|i| (f64::from(i) * 0.3).msin() * 30.0 + 90.0)
        .collect();
    let w = [0.5, 0.4, 0.1];
    assert!((ssim(&x, &x, 9, 60.0, w) - 1.0).abs() < 1e-12);
    let shallow: Vec<f64> = x.iter().map(|v| 90.0 + (v - 90.0) * 0.5).collect();
    let flipped: Vec<f64> = x.iter().map(|v| 180.0 - v).collect();
    let a = ssim(&x, &shallow, 9, 60.0, w);
    let b = ssim(&x, &flipped, 9, 60.0, w);
    assert!(a < 0.99 && b < a, "{a} {b}");
}

#[test]
fn a_warped_shifted_bigger_copy_scores_high_and_the_warp_is_recovered() {
    let r = swing(90, |t| t, 0.0, [0.0; 3], 1.0);
    // Slower start, faster end; a person 15 % bigger, elsewhere; 12 idle frames before.
    let warp = |t: f64| t.mpowf(1.3);
    let mut t = vec![pose(0.0, 0.0, [500.0, -300.0, 0.0], 1.15); 12];
    t.extend(swing(100, warp, 0.0, [500.0, -300.0, 0.0], 1.15));
    let rep = compare(&r, &t, &weights(), &MotionConfig::default()).unwrap();
    assert!(rep.overall >= 0.95, "{}", rep.summary());
    // Path error: each reference frame's matched trial frames against the true correspondence.
    let truth = |i: usize| {
        let phase = i as f64 / 89.0;
        12.0 + phase.mpowf(1.0 / 1.3) * 99.0
    };
    let err: Vec<f64> = rep
        .path
        .iter()
        .map(|&(i, j)| (j as f64 - truth(i)).abs())
        .collect();
    let mean = err.iter().sum::<f64>() / err.len() as f64;
    assert!(mean < 2.0, "mean path error {mean} frames");
    assert_eq!(rep.path.first().map(|p| p.0), Some(0));
    assert_eq!(rep.path.last().map(|p| p.0), Some(89));
    // Without the warp the global alignment alone finds the 12 idle frames.
    let mut plain = vec![pose(0.0, 0.0, [500.0, -300.0, 0.0], 1.15); 12];
    plain.extend(swing(90, |t| t, 0.0, [500.0, -300.0, 0.0], 1.15));
    let rep2 = compare(&r, &plain, &weights(), &MotionConfig::default()).unwrap();
    // Within 2 frames: the idle pose is also the swing's first pose.
    assert!((10..=14).contains(&rep2.shift), "shift {}", rep2.shift);
    let same = compare(&r, &r, &weights(), &MotionConfig::default()).unwrap();
    assert!((same.overall - 1.0).abs() < 1e-9);
}

#[test]
fn a_growing_fault_in_one_joint_lowers_the_score_and_is_blamed() {
    let r = swing(90, |t| t, 0.0, [0.0; 3], 1.0);
    let mut last = 1.0;
    for bend in [10.0, 25.0, 45.0, 70.0] {
        let t = swing(90, |t| t, bend, [0.0; 3], 1.0);
        let rep = compare(&r, &t, &weights(), &MotionConfig::default()).unwrap();
        assert!(
            rep.overall < last,
            "bend {bend}: {} after {last}",
            rep.overall
        );
        last = rep.overall;
        assert_eq!(
            rep.worst.joint,
            Joint::RElbow,
            "bend {bend}: {}",
            rep.summary()
        );
    }
    assert!(last < 0.9, "{last}");
}

#[test]
fn bad_inputs_are_typed_errors() {
    let r = swing(90, |t| t, 0.0, [0.0; 3], 1.0);
    let cfg = MotionConfig::default();
    assert!(compare(&r, &r[..4], &weights(), &cfg).is_err());
    let mut nan = r.clone();
    nan[5][3][1] = f64::NAN;
    assert!(
        matches!(compare(&r, &nan, &weights(), &cfg), Err(Error::InvalidInput(m)) if m.contains("frame 5"))
    );
    let short = &r[..60];
    assert!(
        matches!(compare(short, &r, &weights(), &cfg), Err(Error::InvalidConfig(m)) if m.contains("follow-through"))
    );
    for (json, needle) in [
        (r#"{"phases": [], "features": []}"#, "no phases"),
        (
            r#"{"phases": [{"name": "a", "start_frame": 0, "end_frame": 5}], "features": [{"phase": "a", "joint": "knee", "feature": "flexion", "weight": 1}]}"#,
            "unknown joint",
        ),
        (
            r#"{"phases": [{"name": "a", "start_frame": 0, "end_frame": 5}], "features": [{"phase": "a", "joint": "lknee", "feature": "twist", "weight": 1}]}"#,
            "unknown feature",
        ),
        (
            r#"{"phases": [{"name": "a", "start_frame": 0, "end_frame": 5}], "features": [{"phase": "b", "joint": "lknee", "feature": "flexion", "weight": 1}]}"#,
            "no phase named",
        ),
        (
            r#"{"phases": [{"name": "a", "start_frame": 0, "end_frame": 5}], "features": [{"phase": "a", "joint": "lwrist", "feature": "flexion", "weight": 1}]}"#,
            "has no flexion",
        ),
        (
            r#"{"phases": [{"name": "a", "start_frame": 0, "end_frame": 5}], "features": [{"phase": "a", "joint": "lknee", "feature": "flexion", "weight": -1}]}"#,
            "weight",
        ),
        (
            r#"{"phases": [{"name": "a", "start_frame": 6, "end_frame": 5}], "features": [{"phase": "a", "joint": "lknee", "feature": "flexion", "weight": 1}]}"#,
            "after end_frame",
        ),
        ("not json", "weights JSON"),
    ] {
        match Weights::from_json(json.as_bytes()) {
            Err(Error::InvalidConfig(m)) => assert!(m.contains(needle), "{m} lacks {needle}"),
            other => panic!("{json}: {other:?}"),
        }
    }
}

/// The shipped example weights (every feature kind, acceleration included) score a 90-frame
/// swing against itself as equal and a copy whose arm swings faster lower.
#[test]
fn the_example_weights_score_a_swing() {
    let w = Weights::from_json(include_bytes!("../../../examples/motion_weights.json")).unwrap();
    let r = swing(90, |t| t, 0.0, [0.0; 3], 1.0);
    let same = compare(&r, &r, &w, &MotionConfig::default()).unwrap();
    assert!(same.overall > 0.99, "{}", same.summary());
    let faster = swing(90, |t| (t * 1.25).min(1.0), 0.0, [0.0; 3], 1.0);
    let rep = compare(&r, &faster, &w, &MotionConfig::default()).unwrap();
    assert!(rep.overall < same.overall, "{}", rep.summary());
}
