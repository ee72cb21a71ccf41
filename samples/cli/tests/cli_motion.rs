//! `monotrack compare-motion`: CONTRACT.md's JSON, the readable report, the plots, and clear errors
//! for bad input, on a synthetic arm swing written as body-fit output lines.

use monotrack_core::body::JOINT_NAMES;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One frame of a right-arm swing (`phase` 0..1), the elbow bent `bend` degrees more.
fn frame(phase: f64, bend: f64) -> Value {
    let th = (50.0 * (std::f64::consts::TAU * phase).sin()).to_radians();
    let el = (30.0 + 25.0 * (std::f64::consts::TAU * phase).cos() + bend).to_radians();
    let sh = [-180.0, 0.0, 1380.0];
    let elbow = [sh[0], sh[1] + 290.0 * th.sin(), sh[2] - 290.0 * th.cos()];
    let wrist = [
        elbow[0],
        elbow[1] + 250.0 * (th + el).sin(),
        elbow[2] - 250.0 * (th + el).cos(),
    ];
    let pos: [[f64; 3]; 15] = [
        [0.0, 0.0, 900.0],
        [0.0, 0.0, 1400.0],
        [180.0, 0.0, 1380.0],
        [200.0, 0.0, 1100.0],
        [210.0, 60.0, 860.0],
        sh,
        elbow,
        wrist,
        [100.0, 0.0, 900.0],
        [100.0, 30.0, 480.0],
        [100.0, 0.0, 80.0],
        [-100.0, 0.0, 900.0],
        [-100.0, 0.0, 480.0],
        [-100.0, 0.0, 80.0],
        [0.0, 20.0, 1620.0],
    ];
    let joints: serde_json::Map<String, Value> = JOINT_NAMES
        .iter()
        .zip(pos)
        .map(|(n, p)| (n.to_string(), json!(p)))
        .collect();
    json!({"joints3d_mm": joints})
}

fn write_seq(path: &Path, frames: usize, bend: f64) {
    let text: String = (0..frames)
        .map(|i| {
            let mut v = frame(i as f64 / (frames - 1) as f64, bend);
            v["frame"] = json!(i);
            v.to_string() + "\n"
        })
        .collect();
    std::fs::write(path, text).unwrap();
}

const WEIGHTS: &str = r#"{"phases": [{"name": "back-swing", "start_frame": 0, "end_frame": 29},
  {"name": "down-swing", "start_frame": 30, "end_frame": 59}],
 "features": [{"phase": "back-swing", "joint": "relbow", "feature": "flexion", "weight": 2},
  {"phase": "back-swing", "joint": "rshoulder", "feature": "flexion", "weight": 1},
  {"phase": "down-swing", "joint": "rwrist", "feature": "linear_velocity", "weight": 1},
  {"phase": "down-swing", "joint": "relbow", "feature": "angular_velocity", "weight": 1}]}"#;

fn run(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_monotrack"))
        .arg("compare-motion")
        .args(args)
        .output()
        .unwrap()
}

fn keys(v: &Value) -> Vec<String> {
    v.as_object().unwrap().keys().cloned().collect()
}

#[test]
fn compare_motion_reports_json_text_and_plots() {
    let dir: PathBuf =
        std::env::temp_dir().join(format!("monotrack-motion-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (r, t, w, plots) = (
        dir.join("r.jsonl"),
        dir.join("t.jsonl"),
        dir.join("w.json"),
        dir.join("plots"),
    );
    write_seq(&r, 60, 0.0);
    write_seq(&t, 66, 30.0);
    std::fs::write(&w, WEIGHTS).unwrap();
    let base = [
        "--reference".as_ref(),
        r.as_os_str(),
        "--trial".as_ref(),
        t.as_os_str(),
        "--weights".as_ref(),
        w.as_os_str(),
    ];
    let mut args = base.to_vec();
    args.extend(["--json".as_ref(), "--plot".as_ref(), plots.as_os_str()]);
    let out = run(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        keys(&v),
        ["alignment", "features", "overall", "phases", "worst"]
    );
    assert_eq!(keys(&v["alignment"]), ["path", "shift"]);
    assert_eq!(keys(&v["phases"][0]), ["name", "nominal", "score"]);
    assert_eq!(
        keys(&v["features"][0]),
        ["feature", "joint", "phase", "score", "weight"]
    );
    assert_eq!(keys(&v["worst"]), ["feature", "joint", "phase", "score"]);
    let overall = v["overall"].as_f64().unwrap();
    assert!((0.0..1.0).contains(&overall), "{overall}");
    assert_eq!(v["worst"]["joint"], "relbow");
    assert_eq!(v["phases"][0]["nominal"], 3.0);
    let path = v["alignment"]["path"].as_array().unwrap();
    assert_eq!(path.first().unwrap()[0], 0);
    assert_eq!(path.last().unwrap()[0], 59);
    let pngs: Vec<String> = std::fs::read_dir(&plots)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(pngs.len(), 4, "{pngs:?}");
    assert!(
        pngs.iter()
            .any(|p| p.starts_with("00_back-swing_right-elbow_flexion_")),
        "{pngs:?}"
    );

    // The readable report names what to fix.
    let out = run(&base);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("To fix: right elbow"), "{text}");

    // Bad input: a missing joint (line and field named), an unknown feature.
    let lines = std::fs::read_to_string(&t).unwrap();
    std::fs::write(&t, lines.replacen("\"head\"", "\"nose\"", 1)).unwrap();
    let out = run(&base);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("t.jsonl:1") && err.contains("joints3d_mm.head"),
        "{err}"
    );
    write_seq(&t, 66, 30.0);
    std::fs::write(&w, WEIGHTS.replace("linear_velocity", "speed")).unwrap();
    let out = run(&base);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown feature \"speed\""));
    std::fs::write(
        &w,
        WEIGHTS.replace("\"end_frame\": 59", "\"end_frame\": 80"),
    )
    .unwrap();
    let out = run(&base);
    assert!(String::from_utf8_lossy(&out.stderr).contains("the reference has 60 frames"));
    std::fs::write(&r, "").unwrap();
    let out = run(&base);
    assert!(String::from_utf8_lossy(&out.stderr).contains("no poses"));
    std::fs::remove_dir_all(&dir).unwrap();
}
