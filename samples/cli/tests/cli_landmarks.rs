//! The `landmarks` subcommand end to end on the committed sample image: CONTRACT fields and
//! ranges, relative image paths, the no-detector error for lines without boxes, and malformed
//! lines reported with their line numbers without a panic.

use std::path::PathBuf;
use std::process::Command;

/// The astronaut's face in `samples/data/astronaut.jpg` (the tight box of its 68 points, by eye).
const ASTRONAUT_BOX: [f64; 4] = [172.0, 90.0, 104.0, 94.0];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn monotrack(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_monotrack"))
        .args(args)
        .output()
        .expect("run monotrack")
}

/// A fresh temporary folder holding a copy of the sample image (`astronaut.jpg`), for manifests
/// with relative paths.
fn dir_with_astronaut(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("monotrack-cli-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(
        root().join("samples/data/astronaut.jpg"),
        dir.join("astronaut.jpg"),
    )
    .unwrap();
    dir
}

/// Whether a FACE's box (`{"box": [x, y, w, h], ...}`) has its centre inside [`ASTRONAUT_BOX`].
fn centred_on_the_face(face: &serde_json::Value) -> bool {
    let r: Vec<f64> = face["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let (cx, cy) = (r[0] + r[2] / 2.0, r[1] + r[3] / 2.0);
    let b = ASTRONAUT_BOX;
    cx > b[0] && cx < b[0] + b[2] && cy > b[1] && cy < b[1] + b[3]
}

/// The CONTRACT's `transform`: 16 numbers, a rotation over `translation_mm`, last row 0 0 0 1.
fn check_transform(f: &serde_json::Value) {
    let m: Vec<f64> = f["transform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(m.len(), 16);
    assert_eq!(m[12..], [0.0, 0.0, 0.0, 1.0]);
    for i in 0..3 {
        assert_eq!(
            m[4 * i + 3],
            f["pose"]["translation_mm"][i].as_f64().unwrap()
        );
        for j in 0..3 {
            let dot: f64 = (0..3).map(|k| m[4 * i + k] * m[4 * j + k]).sum();
            assert!((dot - f64::from(u8::from(i == j))).abs() < 1e-4, "{m:?}");
        }
    }
}

fn norm(v: &serde_json::Value) -> f64 {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap().powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn landmarks_on_given_boxes_follow_the_contract() {
    let dir = dir_with_astronaut("lm");
    let input = dir.join("in.jsonl");
    let b = ASTRONAUT_BOX;
    let good = format!(
        r#"{{"image": "astronaut.jpg", "faces": [{{"box": [{}, {}, {}, {}]}}]}}"#,
        b[0], b[1], b[2], b[3]
    );
    let cam = format!(
        r#"{{"image": "astronaut.jpg", "camera": {{"fx": 400, "fy": 400, "cx": 256, "cy": 256}}, "faces": [{{"box": [{}, {}, {}, {}]}}, {{"box": [10, 10, 60, 60]}}]}}"#,
        b[0], b[1], b[2], b[3]
    );
    std::fs::write(
        &input,
        format!(
            "{good}\n{cam}\n{{\"image\": \"astronaut.jpg\"}}\n{{broken\n{{\"image\": \"missing.jpg\", \"faces\": []}}\n{{\"image\": \"astronaut.jpg\", \"faces\": [{{\"box\": [1, 1, 0, 5]}}]}}\n"
        ),
    )
    .unwrap();
    let out_path = dir.join("out.jsonl");
    let out = monotrack(&[
        "landmarks",
        input.to_str().unwrap(),
        "--out",
        out_path.to_str().unwrap(),
    ]);
    assert_eq!(
        out.status.code(),
        Some(1),
        "bad lines make the exit status 1"
    );
    let text = std::fs::read_to_string(&out_path).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 6, "one output line per input line");

    for (l, n_faces) in [(&lines[0], 1), (&lines[1], 2)] {
        assert_eq!(l["image"], "astronaut.jpg");
        assert_eq!(
            (l["width"].as_u64(), l["height"].as_u64()),
            (Some(512), Some(512))
        );
        let faces = l["faces"].as_array().unwrap();
        assert_eq!(faces.len(), n_faces);
        for f in faces {
            let pts = f["landmarks68"].as_array().unwrap();
            assert_eq!(pts.len(), 68);
            assert!(pts.iter().all(|p| p[0].as_f64().unwrap().is_finite()));
            let yaw: f64 = f["yaw_probs"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| p.as_f64().unwrap())
                .sum();
            assert!((yaw - 1.0).abs() < 1e-3, "yaw probabilities sum to {yaw}");
            assert!([-60, -30, 0, 30, 60].contains(&f["yaw_class_deg"].as_i64().unwrap()));
            let score = f["score"].as_f64().unwrap();
            assert!((0.0..=1.0).contains(&score));
            let mouth = f["gestures"]["mouth"].as_object().unwrap();
            assert_eq!(mouth.len(), 4);
            let s: f64 = mouth.values().map(|v| v.as_f64().unwrap()).sum();
            assert!((s - 1.0).abs() < 1e-3);
            assert_eq!(f["gestures"]["brows"].as_object().unwrap().len(), 3);
            for g in ["left", "right", "combined"] {
                assert!((norm(&f["gaze"][g]) - 1.0).abs() < 1e-3, "gaze {g}");
            }
            assert_eq!(f["pose"]["rotation"].as_array().unwrap().len(), 3);
            check_transform(f);
            // The sample face's eyes are open.
            for e in ["left_open", "right_open"] {
                let p = f["eyes"][e].as_f64().unwrap();
                assert!(p > 0.5 && p <= 1.0, "{e} {p}");
            }
            assert_eq!(f["eyes"].as_object().unwrap().len(), 2);
            assert_eq!(f["shape_units"].as_object().unwrap().len(), 11);
            assert_eq!(f["action_units"].as_object().unwrap().len(), 6);
            assert!(f["fit_rms_px"].as_f64().unwrap().is_finite());
        }
        let t = &l["timings_us"];
        for k in ["detect", "landmarks", "fit", "total"] {
            assert!(t[k].as_u64().is_some(), "timings_us.{k}");
        }
        assert_eq!(t["detect"], 0, "given boxes: no detection");
    }
    // The given box is kept as is.
    let got: Vec<f64> = lines[0]["faces"][0]["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(got, ASTRONAUT_BOX.to_vec());
    // Same image and box, other camera: same landmarks, other pose depth.
    assert_eq!(
        lines[0]["faces"][0]["landmarks68"],
        lines[1]["faces"][0]["landmarks68"]
    );

    let err = |i: usize| lines[i]["error"].as_str().unwrap().to_string();
    // No boxes: the detector (+ M3's face check) finds the face, inside the box given above, and
    // only it: the helmet visor in the lower right is a false positive of the detector (score
    // 0.67) that the level-1 face check must reject (it passed at 0.97 before level 1 was trained
    // with the detector's false positives as negatives — MODEL_CARD.md, face check).
    let detected = lines[2]["faces"].as_array().unwrap();
    assert_eq!(detected.len(), 1, "{}", lines[2]);
    let nose = &detected[0]["landmarks68"][30];
    let (nx, ny) = (nose[0].as_f64().unwrap(), nose[1].as_f64().unwrap());
    assert!(
        nx > b[0] && nx < b[0] + b[2] && ny > b[1] && ny < b[1] + b[3],
        "{}",
        lines[2]
    );
    assert!(lines[2]["timings_us"]["detect"].as_u64().unwrap() > 0);
    assert!(err(3).contains("malformed JSON"));
    assert!(err(4).contains("missing.jpg"));
    assert!(err(5).contains("invalid input"), "{}", err(5));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(stderr.contains(":4:") && stderr.contains(":5:") && stderr.contains(":6:"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn mirror_average_is_the_default_and_moves_the_points_within_the_contract() {
    let dir = dir_with_astronaut("mirror");
    let input = dir.join("in.jsonl");
    let b = ASTRONAUT_BOX;
    std::fs::write(
        &input,
        format!(
            r#"{{"image": "astronaut.jpg", "faces": [{{"box": [{}, {}, {}, {}]}}]}}"#,
            b[0], b[1], b[2], b[3]
        ),
    )
    .unwrap();
    let run = |extra: &[&str]| {
        let out_path = dir.join("out.jsonl");
        let mut args = vec![
            "landmarks",
            input.to_str().unwrap(),
            "--out",
            out_path.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        assert!(monotrack(&args).status.success());
        let text = std::fs::read_to_string(&out_path).unwrap();
        let line: serde_json::Value = serde_json::from_str(text.trim()).unwrap();
        line["faces"][0].clone()
    };
    // Mirror average is the default; `--mirror-average` still names it.
    let (plain, averaged) = (run(&["--single-pass"]), run(&[]));
    assert_eq!(run(&["--mirror-average"]), averaged);
    let pts = |f: &serde_json::Value| -> Vec<f64> {
        f["landmarks68"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|p| p.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()))
            .collect()
    };
    let (p, q) = (pts(&plain), pts(&averaged));
    assert_eq!(q.len(), 136);
    let moved = p
        .iter()
        .zip(&q)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    // The mode moves points, by less than the nets' own error on this ~100 px face.
    assert!(moved > 0.01 && moved < 10.0, "largest move {moved} px");
    // Yaw and the face score are level 1's first run in both modes.
    assert_eq!(plain["yaw_probs"], averaged["yaw_probs"]);
    assert_eq!(plain["score"], averaged["score"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn detect_reports_the_face_check_on_request() {
    let dir = dir_with_astronaut("detect");
    let manifest = dir.join("in.jsonl");
    std::fs::write(&manifest, "{\"image\": \"astronaut.jpg\"}\n{broken\n").unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["detect", manifest.to_str().unwrap()];
        args.extend_from_slice(extra);
        let out = monotrack(&args);
        assert_eq!(out.status.code(), Some(1), "the broken line fails the run");
        let text = String::from_utf8(out.stdout).unwrap();
        let lines: Vec<serde_json::Value> = text
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(lines.len(), 2);
        assert!(
            lines[1]["error"]
                .as_str()
                .unwrap()
                .contains("malformed JSON")
        );
        lines[0]["faces"].as_array().unwrap().clone()
    };
    let plain = run(&[]);
    assert!(!plain.is_empty());
    assert!(plain.iter().all(|f| f.get("face_prob").is_none()));
    // Down to score 0.3, so the detector's clutter is in the list for the check to judge.
    let checked = run(&["--face-prob", "--threshold", "0.3"]);
    let mut on_face = 0;
    for f in &checked {
        let p = f["face_prob"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&p), "{f}");
        // The check as `landmarks` and the tracker apply it to new detections.
        let accept = f64::from(monotrack_core::track::DEFAULT_MIN_DETECTION_CONFIDENCE);
        if centred_on_the_face(f) {
            on_face += 1;
            assert!(p >= accept, "the face passes the check: {f}");
        } else {
            assert!(p < accept, "clutter fails the check: {f}");
        }
    }
    assert_eq!(on_face, 1, "{checked:?}");
    // The cascade itself at the SDK's default threshold: only the accepted faces, the face on its
    // own box (at 0.3 the mission patch, detector 0.38, passes the check on its re-boxed crop).
    let cascade = run(&["--cascade", "--threshold", "0.4"]);
    assert_eq!(cascade.len(), 1, "{cascade:?}");
    let f = &cascade[0];
    assert!(f["face_prob"].as_f64().unwrap() >= 0.95, "{f}");
    assert!(centred_on_the_face(f), "{f}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn small_faces_detects_the_face_first_and_keeps_the_contract() {
    let dir = dir_with_astronaut("small");
    let input = dir.join("in.jsonl");
    std::fs::write(&input, "{\"image\": \"astronaut.jpg\"}\n").unwrap();
    let out = monotrack(&["landmarks", "--small-faces", input.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line: serde_json::Value =
        serde_json::from_str(String::from_utf8(out.stdout).unwrap().trim()).unwrap();
    let faces = line["faces"].as_array().unwrap();
    // The face ranks first (detector score × face check). At this operating point the mission
    // patch on the suit (detector 0.38, face check 0.96 on its re-boxed crop) is accepted too:
    // the cost of reaching 17 px faces (core/models/MODEL_CARD.md, face detector).
    assert!(!faces.is_empty() && faces.len() <= 2, "{line}");
    assert!(centred_on_the_face(&faces[0]), "{line}");
    assert_eq!(faces[0]["landmarks68"].as_array().unwrap().len(), 68);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--landmarks gradient`: the CONTRACT's gradient-mode FACE (32 points with confidences, 68 with
/// `null` where there is no counterpart, a fit and its transform, no M3 fields or eyes), its points around the face M3
/// finds on the same box, and the detector's faces without a box.
#[test]
fn gradient_mode_follows_the_contract_on_the_face() {
    let dir = dir_with_astronaut("grad");
    let input = dir.join("in.jsonl");
    let b = ASTRONAUT_BOX;
    std::fs::write(
        &input,
        format!(
            "{{\"image\": \"astronaut.jpg\", \"faces\": [{{\"box\": [{}, {}, {}, {}]}}]}}\n{{\"image\": \"astronaut.jpg\"}}\n",
            b[0], b[1], b[2], b[3]
        ),
    )
    .unwrap();
    let run = |mode: &str| {
        let out = monotrack(&["landmarks", input.to_str().unwrap(), "--landmarks", mode]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .collect::<Vec<_>>()
    };
    let (grad, m3) = (run("gradient"), run("m3"));
    let g = &grad[0]["faces"][0];
    let m = &m3[0]["faces"][0];
    let l32 = g["landmarks32"].as_array().unwrap();
    let c32 = g["confidence32"].as_array().unwrap();
    assert_eq!((l32.len(), c32.len()), (32, 32));
    assert!(
        c32.iter()
            .all(|c| (0.0..=1.0).contains(&c.as_f64().unwrap()))
    );
    let l68 = g["landmarks68"].as_array().unwrap();
    assert_eq!(l68.len(), 68);
    let present: Vec<usize> = (0..68).filter(|&k| !l68[k].is_null()).collect();
    assert_eq!(present.len(), 27, "{present:?}");
    for k in ["yaw_class_deg", "yaw_probs", "gestures", "gaze", "eyes"] {
        assert!(g[k].is_null(), "{k}");
    }
    assert!(g["pose"].is_object() && g["fit_rms_px"].as_f64().unwrap().is_finite());
    check_transform(g);
    // On the face M3 finds on the same box: the points' mean within three quarters of the eye
    // distance of M3's, each point within two eye distances. (A bound on gross failure only: on
    // real faces the detector is far less accurate than M3, core/models/gradient_metrics.json.)
    let pt = |v: &serde_json::Value| [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()];
    let m68 = m["landmarks68"].as_array().unwrap();
    let iod = {
        let (a, b) = (pt(&m68[36]), pt(&m68[45]));
        (a[0] - b[0]).hypot(a[1] - b[1])
    };
    let centre = |pts: &mut dyn Iterator<Item = [f64; 2]>| {
        let v: Vec<[f64; 2]> = pts.collect();
        let n = v.len() as f64;
        [
            v.iter().map(|p| p[0]).sum::<f64>() / n,
            v.iter().map(|p| p[1]).sum::<f64>() / n,
        ]
    };
    let cg = centre(&mut present.iter().map(|&k| pt(&l68[k])));
    let cm = centre(&mut present.iter().map(|&k| pt(&m68[k])));
    assert!(
        (cg[0] - cm[0]).hypot(cg[1] - cm[1]) < 0.75 * iod,
        "{cg:?} vs {cm:?}"
    );
    for &k in &present {
        let (a, b) = (pt(&l68[k]), pt(&m68[k]));
        assert!((a[0] - b[0]).hypot(a[1] - b[1]) < 2.0 * iod, "point {k}");
    }
    // Without a box the detector finds the face (no face classifier in this mode).
    let faces = grad[1]["faces"].as_array().unwrap();
    assert!(faces.iter().any(centred_on_the_face), "{faces:?}");
    // No gaze without M3.
    let targets = dir.join("t.json");
    std::fs::write(
        &targets,
        r#"{"targets": [{"id": "s", "corners_mm": [[0,0,0],[1,0,0],[0,1,0]]}]}"#,
    )
    .unwrap();
    let out = monotrack(&[
        "landmarks",
        input.to_str().unwrap(),
        "--landmarks",
        "gradient",
        "--targets",
        targets.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
}

/// `track --landmarks gradient`: the ultra-light tracker over a frame directory; each FACE's
/// `landmarks68` has the 27 measured points and `null` elsewhere, the M3-only fields and `eyes`
/// are `null`, and there is a fit with its transform.
#[test]
fn track_in_gradient_mode_reports_the_measured_points() {
    let dir = dir_with_astronaut("track-grad");
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    for i in 0..3 {
        std::fs::copy(
            dir.join("astronaut.jpg"),
            frames.join(format!("{i:03}.jpg")),
        )
        .unwrap();
    }
    let out = monotrack(&["track", frames.to_str().unwrap(), "--landmarks", "gradient"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3);
    for line in &lines {
        let face = &line["faces"][0];
        assert!(centred_on_the_face(face), "{face}");
        let l68 = face["landmarks68"].as_array().unwrap();
        assert_eq!(l68.iter().filter(|p| !p.is_null()).count(), 27);
        assert!(face["gestures"].is_null() && face["gaze"].is_null() && face["eyes"].is_null());
        assert!(face["fit_rms_px"].as_f64().unwrap().is_finite());
        check_transform(face);
    }
}
