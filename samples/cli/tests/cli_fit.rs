//! The `fit` subcommand end to end: the committed example, and malformed lines reported with their
//! line numbers without a panic.

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

#[test]
fn fit_example_recovers_the_known_poses() {
    let input = root().join("examples/fit_example.jsonl");
    let out = monotrack(&["fit", input.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let truth_lines = std::fs::read_to_string(&input).unwrap();
    for (got, want) in text.lines().zip(truth_lines.lines()) {
        let got: serde_json::Value = serde_json::from_str(got).unwrap();
        let want: serde_json::Value = serde_json::from_str(want).unwrap();
        let face = &got["faces"][0];
        for key in ["yaw_deg", "pitch_deg", "roll_deg"] {
            let (g, w) = (
                face["pose"][key].as_f64().unwrap(),
                want["truth"][key].as_f64().unwrap(),
            );
            assert!((g - w).abs() < 1.5, "{key}: {g} vs {w}");
        }
        let z = face["pose"]["translation_mm"][2].as_f64().unwrap();
        let zt = want["truth"]["translation_mm"][2].as_f64().unwrap();
        assert!((z / zt - 1.0).abs() < 0.03, "depth {z} vs {zt}");
        assert_eq!(face["shape_units"].as_object().unwrap().len(), 11);
        assert_eq!(face["action_units"].as_object().unwrap().len(), 6);
        assert!(face["pose"]["rotation"].as_array().unwrap().len() == 3);
        assert!(face["fit_rms_px"].as_f64().unwrap() < 2.0);
        // `transform` holds the head rotation the reported angles are those of (R = Rz·Ry·Rx).
        let m: Vec<f64> = face["transform"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(m.len(), 16);
        assert_eq!(m[12..], [0.0, 0.0, 0.0, 1.0]);
        let (yaw, pitch, roll) = (
            (-m[8]).asin().to_degrees(),
            m[9].atan2(m[10]).to_degrees(),
            m[4].atan2(m[0]).to_degrees(),
        );
        for (key, v) in [("yaw_deg", yaw), ("pitch_deg", pitch), ("roll_deg", roll)] {
            let reported = face["pose"][key].as_f64().unwrap();
            assert!((v - reported).abs() < 0.01, "{key}: {v} vs {reported}");
        }
        // The model's mean face has open eyes.
        for e in ["left_open", "right_open"] {
            assert!(face["eyes"][e].as_f64().unwrap() > 0.5, "{e}");
        }
    }
    // The first face looks straight into the camera: the identity rotation.
    let first: serde_json::Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    let m = &first["faces"][0]["transform"];
    for (i, j) in [(0, 0), (1, 1), (2, 2)] {
        assert!(m[4 * i + j].as_f64().unwrap() > 0.999, "{m}");
    }
    assert_eq!(text.lines().count(), 3);
}

#[test]
fn malformed_lines_are_reported_not_panicked() {
    let dir = std::env::temp_dir().join(format!("monotrack-cli-fit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let input = dir.join("bad.jsonl");
    let good = std::fs::read_to_string(root().join("examples/fit_example.jsonl")).unwrap();
    let good = good.lines().next().unwrap();
    let nan_cam = good.replacen(
        "{\"width\"",
        "{\"camera\": {\"fx\": -1, \"fy\": 500, \"cx\": 1, \"cy\": 1}, \"width\"",
        1,
    );
    std::fs::write(
        &input,
        format!(
            "{good}\n{{not json\n{{\"width\": 640, \"height\": 480, \"faces\": [{{\"landmarks68\": [[1, 2]]}}]}}\n{nan_cam}\n"
        ),
    )
    .unwrap();
    let out = monotrack(&["fit", input.to_str().unwrap(), "--method", "ffbp"]);
    assert_eq!(out.status.code(), Some(1));
    let stdout = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 4, "one output line per input line");
    assert!(lines[0]["faces"].is_array());
    assert_eq!(lines[1]["line"], 2);
    assert!(
        lines[1]["error"]
            .as_str()
            .unwrap()
            .contains("malformed JSON")
    );
    assert!(lines[2]["error"].as_str().unwrap().contains("expected 68"));
    assert!(lines[3]["error"].as_str().unwrap().contains("camera"));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains(":2:") && stderr.contains(":3:") && stderr.contains(":4:"));
    let _ = std::fs::remove_dir_all(&dir);
}
