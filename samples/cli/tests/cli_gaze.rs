//! `--targets T.json` on `landmarks` and `track`: each face's point of gaze (CONTRACT.md, "Options
//! shared by face commands"), on the committed sample face.

use serde_json::Value;
use std::path::PathBuf;
use std::process::Command;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("monotrack-gaze-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A phone screen below the camera (as `screen_target` makes it) and a far wall behind the
/// subject: the wall can never be hit.
const TARGETS: &str = r#"{"targets": [
  {"id": "phone", "corners_mm": [[-35, 8, 0], [35, 8, 0], [35, 158, 0], [-35, 158, 0]]},
  {"id": "wall", "corners_mm": [[-500, -500, 3000], [500, -500, 3000], [500, 500, 3000]]}
]}"#;

fn check_face(f: &Value) {
    let origin = f["gaze"]["origin_mm"].as_array().unwrap();
    assert_eq!(origin.len(), 3);
    assert!(
        (200.0..3000.0).contains(&origin[2].as_f64().unwrap()),
        "{origin:?}"
    );
    // The target is where the printed ray lands: `point_mm` measured from corner 0 along the
    // phone's first edge (+x) and across it (+y), on its plane z = 0.
    let dir: Vec<f64> = f["gaze"]["direction"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!((dir.iter().map(|v| v * v).sum::<f64>().sqrt() - 1.0).abs() < 1e-5);
    let o: Vec<f64> = origin.iter().map(|v| v.as_f64().unwrap()).collect();
    let t = &f["target"];
    if t["hit"].as_bool().unwrap() {
        let s = -o[2] / dir[2];
        let (x, y) = (o[0] + s * dir[0], o[1] + s * dir[1]);
        let p = t["point_mm"].as_array().unwrap();
        let (u, v) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
        assert!(
            (x + 35.0 - u).abs() < 0.05 && (y - 8.0 - v).abs() < 0.05,
            "the ray lands at ({x}, {y}), the target says {p:?}"
        );
    }
    let keys: Vec<&str> = t.as_object().unwrap().keys().map(|k| k.as_str()).collect();
    assert_eq!(keys, ["distance_mm", "hit", "id", "nearest", "point_mm"]);
    assert_eq!(t["point_mm"].as_array().unwrap().len(), 2);
    // The sample face looks at about the camera: the phone below it is nearest, never the wall.
    assert_eq!(t["nearest"], "phone");
    assert_eq!(t["hit"].as_bool().unwrap(), t["id"] == "phone");
    assert!(t["distance_mm"].as_f64().unwrap() >= 0.0);
    // The rest of the FACE is there too, the head transform and the eyes included.
    assert_eq!(f["transform"].as_array().unwrap().len(), 16);
    for e in ["left_open", "right_open"] {
        assert!(f["eyes"][e].as_f64().unwrap() > 0.5, "{e}: {}", f["eyes"]);
    }
}

#[test]
fn landmarks_and_track_add_the_point_of_gaze() {
    let dir = scratch("cli");
    let targets = dir.join("targets.json");
    std::fs::write(&targets, TARGETS).unwrap();
    let image = repo().join("samples/data/astronaut.jpg");
    let input = dir.join("in.jsonl");
    std::fs::write(
        &input,
        format!("{{\"image\": {:?}}}\n", image.display().to_string()),
    )
    .unwrap();
    let exe = env!("CARGO_BIN_EXE_monotrack");
    let out = Command::new(exe)
        .arg("landmarks")
        .arg(&input)
        .arg("--targets")
        .arg(&targets)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).unwrap();
    check_face(&v["faces"][0]);

    // Without --targets nothing is added.
    let plain = Command::new(exe)
        .arg("landmarks")
        .arg(&input)
        .output()
        .unwrap();
    let v: Value = serde_json::from_slice(&plain.stdout).unwrap();
    assert!(v["faces"][0].get("target").is_none());
    assert!(v["faces"][0]["gaze"].get("origin_mm").is_none());

    // Track over a two-frame directory.
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    for i in 0..2 {
        std::fs::copy(&image, frames.join(format!("f{i}.jpg"))).unwrap();
    }
    let out = Command::new(exe)
        .arg("track")
        .arg(&frames)
        .arg("--targets")
        .arg(&targets)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    for l in &lines {
        check_face(&l["faces"][0]);
    }

    // Targets with the gaze stage turned off by the config: refused, not silently left out.
    let no_gaze = dir.join("no_gaze.json");
    std::fs::write(&no_gaze, r#"{"gaze": false}"#).unwrap();
    let out = Command::new(exe)
        .arg("track")
        .arg(&frames)
        .arg("--targets")
        .arg(&targets)
        .arg("--config")
        .arg(&no_gaze)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("needs the gaze stage"));

    // A bad targets file is a clear error, not a crash.
    std::fs::write(
        &targets,
        r#"{"targets": [{"id": "x", "corners_mm": [[0,0,0],[1,0,0]]}]}"#,
    )
    .unwrap();
    let out = Command::new(exe)
        .arg("landmarks")
        .arg(&input)
        .arg("--targets")
        .arg(&targets)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("3 or more corners"));
    std::fs::remove_dir_all(&dir).unwrap();
}
