//! The `body-fit` subcommand end to end: the committed synthetic walker (floor-calibrated camera)
//! against its true 3D joints, and malformed lines reported with their line numbers without a panic.

use std::path::PathBuf;
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn monotrack(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_monotrack"))
        .args(args)
        .output()
        .expect("run monotrack")
}

const JOINTS: [&str; 15] = [
    "pelvis",
    "thorax",
    "lshoulder",
    "lelbow",
    "lwrist",
    "rshoulder",
    "relbow",
    "rwrist",
    "lhip",
    "lknee",
    "lankle",
    "rhip",
    "rknee",
    "rankle",
    "head",
];

/// Mean world-frame joint error (mm) of `monotrack body-fit` on the committed walker, with `extra`
/// arguments, checking every output line's shape on the way.
fn walker_error(extra: &[&str]) -> f64 {
    let input = root().join("examples/body_fit_example.jsonl");
    let mut args = vec!["body-fit", input.to_str().unwrap()];
    args.extend_from_slice(extra);
    let out = monotrack(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let truth_lines = std::fs::read_to_string(&input).unwrap();
    assert_eq!(text.lines().count(), 6);
    let mut total = 0.0;
    for (got, want) in text.lines().zip(truth_lines.lines()) {
        let got: serde_json::Value = serde_json::from_str(got).unwrap();
        let want: serde_json::Value = serde_json::from_str(want).unwrap();
        assert_eq!(got["frame"], want["frame"]);
        assert_eq!(got["sequence"], "walk");
        let mut err = 0.0;
        for j in JOINTS {
            let g = &got["joints3d_mm"][j];
            let w = &want["truth"]["joints3d_mm"][j];
            let d: f64 = (0..3)
                .map(|k| (g[k].as_f64().unwrap() - w[k].as_f64().unwrap()).powi(2))
                .sum::<f64>()
                .sqrt();
            err += d / 15.0;
        }
        total += err / 6.0;
        assert!(got["reprojection_rms_px"].as_f64().unwrap() < 5.0);
        assert_eq!(got["dimensions_mm"].as_object().unwrap().len(), 12);
        // The floor calibration recovers the focal length the example was made with.
        let f = got["camera"]["fx"].as_f64().unwrap();
        assert!((f / 760.0 - 1.0).abs() < 0.03, "focal {f}");
        for k in ["calibrate", "dimensions", "pose", "total"] {
            assert!(got["timings_us"][k].is_u64(), "{k}");
        }
    }
    total
}

#[test]
fn body_fit_example_recovers_the_walker() {
    // World-frame error without any alignment: camera, scale and pose all estimated. The walker's
    // 2D joints carry 0.5 px of noise, so the prior weight that suits them is about 0.5 px
    // (measured 29.1 mm); the default (5 px, made for detector keypoints and annotations)
    // trades that accuracy for robustness on real data (measured 84.5 mm here).
    let weak = walker_error(&["--prior-weight", "0.5"]);
    assert!(
        weak < 50.0,
        "mean joint error {weak:.1} mm at prior weight 0.5"
    );
    let default = walker_error(&[]);
    assert!(
        default < 120.0,
        "mean joint error {default:.1} mm at the default prior weight"
    );
    // The full 54-DoF model: same output contract, same accuracy class.
    let full = walker_error(&["--prior-weight", "0.5", "--full-model"]);
    eprintln!(
        "walker: {weak:.1} mm reduced, {full:.1} mm full model (prior weight 0.5), {default:.1} mm at the default"
    );
    assert!(
        full < 50.0,
        "mean joint error {full:.1} mm in the full model"
    );
    for bad in ["-1", "NaN", "inf"] {
        let input = root().join("examples/body_fit_example.jsonl");
        let arg = format!("--prior-weight={bad}");
        let out = monotrack(&["body-fit", input.to_str().unwrap(), &arg]);
        assert!(!out.status.success(), "--prior-weight {bad} accepted");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("prior"),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

#[test]
fn malformed_lines_are_reported_not_panicked() {
    let dir = std::env::temp_dir().join(format!("monotrack-cli-body-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("bad.jsonl");
    let good = std::fs::read_to_string(root().join("examples/body_fit_example.jsonl")).unwrap();
    let good = good.lines().next().unwrap().to_string();
    let v: serde_json::Value = serde_json::from_str(&good).unwrap();
    let mut nan_joint = v.clone();
    nan_joint["sequence"] = "other".into();
    nan_joint["joints2d"]["lknee"] = serde_json::json!([1.0, "x"]);
    let mut collinear = v.clone();
    collinear["sequence"] = "third".into();
    collinear["floor"]["corners_px"] = serde_json::json!([[0, 0], [10, 10], [20, 20], [30, 30]]);
    let mut no_hip = v.clone();
    no_hip["sequence"] = "fourth".into();
    no_hip["joints2d"].as_object_mut().unwrap().remove("lhip");
    let mut no_size = v.clone();
    no_size["sequence"] = "fifth".into();
    no_size.as_object_mut().unwrap().remove("width");
    std::fs::write(
        &input,
        format!("{good}\n{{not json\n{nan_joint}\n{collinear}\n{no_hip}\n{no_size}\n"),
    )
    .unwrap();
    let out = monotrack(&["body-fit", input.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let stdout = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 6, "one output line per input line");
    assert!(lines[0]["joints3d_mm"].is_object());
    for (i, what) in [
        (1, "malformed JSON"),
        (2, "malformed JSON"),
        (3, "convex"),
        (4, "lhip"),
        (5, "width"),
    ] {
        assert_eq!(lines[i]["line"], i + 1);
        let e = lines[i]["error"].as_str().unwrap();
        assert!(e.contains(what), "line {}: {e}", i + 1);
    }
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains("bad.jsonl:2:"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}
