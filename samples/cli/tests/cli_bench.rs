//! `monotrack bench`: the JSON of CONTRACT.md ("Benchmark command") from camera frames as phones
//! deliver them, for every format and orientation the phone apps feed.

use std::process::Command;

fn bench(args: &[&str]) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_monotrack"))
        .args(["bench", "--frames", "8", "--json"])
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn bench_reports_every_stage_from_camera_frames() {
    for args in [
        &[][..],
        &["--format", "nv21", "--rotation", "270", "--mirrored"][..],
        &["--format", "nv12", "--rotation", "0"][..],
        &["--format", "gray8"][..],
        &["--format", "i420", "--rotation", "180"][..],
        &["--format", "rgba", "--rotation", "90"][..],
    ] {
        let v = bench(args);
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        assert_eq!(
            keys,
            [
                "cpu",
                "detected",
                "frames",
                "model_load_us",
                "path",
                "tracked"
            ],
            "{args:?}"
        );
        assert!(["native", "portable"].contains(&v["path"].as_str().unwrap()));
        assert!(!v["cpu"].as_str().unwrap().is_empty());
        assert_eq!(v["frames"], 8);
        assert!(v["model_load_us"].as_f64().unwrap() > 0.0);
        for kind in ["tracked", "detected"] {
            let stages = v[kind].as_object().unwrap();
            let names: Vec<&str> = stages.keys().map(|k| k.as_str()).collect();
            assert_eq!(
                names,
                ["convert", "fit", "flow", "landmarks", "region", "total"],
                "{args:?} {kind}"
            );
            for (name, s) in stages {
                let (m, p) = (
                    s["median_us"].as_f64().unwrap(),
                    s["p90_us"].as_f64().unwrap(),
                );
                assert!(m >= 0.0 && p >= m, "{args:?} {kind} {name}: {s}");
            }
            let total = stages["total"]["median_us"].as_f64().unwrap();
            let landmarks = stages["landmarks"]["median_us"].as_f64().unwrap();
            assert!(landmarks > 0.0 && total >= landmarks, "{args:?} {kind}");
        }
    }
}

#[test]
fn bench_times_the_ultra_light_mode() {
    let v = bench(&["--landmarks", "gradient"]);
    assert!(v["model_load_us"].as_f64().unwrap() > 0.0);
    for kind in ["tracked", "detected"] {
        let stage = |name: &str| v[kind][name]["median_us"].as_f64().unwrap();
        // The gradient detector is the ultra-light mode's face check: its time is the region's
        // (CONTRACT.md), and no landmark network runs after it.
        assert_eq!(stage("landmarks"), 0.0, "{kind}");
        assert!(stage("region") > 0.0 && stage("fit") > 0.0, "{kind}");
        assert!(stage("total") >= stage("region"), "{kind}");
    }
}

#[test]
fn bench_rejects_bad_arguments() {
    for args in [
        &["--landmarks", "dlib"][..],
        &["--rotation", "45"][..],
        &["--format", "yuyv"][..],
        &["--frames", "1"][..],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_monotrack"))
            .arg("bench")
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        assert!(!out.stderr.is_empty(), "{args:?}");
    }
}
