//! `monotrack track --record FILE` and `monotrack replay FILE` (CONTRACT.md): a recording of the
//! frames `track` tracked replays to the lines `track` printed, every frame identical; a recording
//! cut at its size limit replays its first frames; a damaged file is a clear error, and a
//! recorded result that does not match is named.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("monotrack-record-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn monotrack(args: &[&Path]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_monotrack"))
        .args(args)
        .output()
        .expect("run monotrack")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Four frames of the sample face moving right, as PNG files.
fn frames(dir: &Path) -> PathBuf {
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let img = image::open(repo().join("samples/data/astronaut.jpg"))
        .unwrap()
        .to_rgb8();
    for i in 0..4u32 {
        let crop = image::imageops::crop_imm(&img, 24 - 6 * i, 16, 448, 448).to_image();
        crop.save(frames.join(format!("f{i}.png"))).unwrap();
    }
    frames
}

/// The output lines without their timings (which no two runs share).
fn lines(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let mut v: Value = serde_json::from_str(l).unwrap();
            v.as_object_mut().unwrap().remove("timings_us");
            v
        })
        .collect()
}

const TARGETS: &str = r#"{"targets": [
  {"id": "phone", "corners_mm": [[-35, 8, 0], [35, 8, 0], [35, 158, 0], [-35, 158, 0]]}
]}"#;

#[test]
fn a_recording_replays_to_what_track_printed() {
    let dir = scratch("replay");
    let frames = frames(&dir);
    let targets = dir.join("targets.json");
    std::fs::write(&targets, TARGETS).unwrap();
    let (rec, tracked, replayed) = (
        dir.join("rec.mtrec"),
        dir.join("track.jsonl"),
        dir.join("replay.jsonl"),
    );
    let o = monotrack(&[
        "track".as_ref(),
        &frames,
        "--targets".as_ref(),
        &targets,
        "--record".as_ref(),
        &rec,
        "--out".as_ref(),
        &tracked,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("recorded 4 frames"), "{}", stderr(&o));
    let o = monotrack(&["replay".as_ref(), &rec, "--out".as_ref(), &replayed]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("4 of 4 frames identical"),
        "{}",
        stderr(&o)
    );
    let (want, got) = (lines(&tracked), lines(&replayed));
    assert_eq!(want.len(), 4);
    assert_eq!(got, want);
    assert!(
        want.iter()
            .all(|l| l["faces"].as_array().unwrap().len() == 1)
    );
    assert!(want[3]["faces"][0]["target"].is_object(), "{}", want[3]);

    // Under a limit that holds one frame: the first line, and the file says it was cut.
    let (small, small_out) = (dir.join("small.mtrec"), dir.join("small.jsonl"));
    let o = monotrack(&[
        "track".as_ref(),
        &frames,
        "--record".as_ref(),
        &small,
        "--record-max-bytes".as_ref(),
        "300000".as_ref(),
        "--out".as_ref(),
        &dir.join("unused.jsonl"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("truncated"), "{}", stderr(&o));
    assert!(std::fs::metadata(&small).unwrap().len() <= 300_000);
    let o = monotrack(&["replay".as_ref(), &small, "--out".as_ref(), &small_out]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("1 of 1 frames identical"), "{err}");
    assert!(err.contains("truncated at its size limit"), "{err}");
    let first = lines(&small_out);
    assert_eq!(first.len(), 1);
    // Without --targets the face has no point of gaze; the rest is the same frame's.
    let mut want0 = want[0].clone();
    want0["faces"][0].as_object_mut().unwrap().remove("target");
    for k in ["origin_mm", "direction"] {
        want0["faces"][0]["gaze"].as_object_mut().unwrap().remove(k);
    }
    assert_eq!(first[0], want0);

    // A recorded digest that does not match: the frame is named, and the exit status says so.
    let mut bytes = std::fs::read(&rec).unwrap();
    let mut at = 12;
    let mut results = Vec::new();
    while at < bytes.len() {
        let len = u32::from_le_bytes(bytes[at + 1..at + 5].try_into().unwrap()) as usize;
        if bytes[at] == 4 {
            results.push(at);
        }
        at += 5 + len;
    }
    assert_eq!(results.len(), 4);
    bytes[results[2] + 6] ^= 1;
    let altered = dir.join("altered.mtrec");
    std::fs::write(&altered, &bytes).unwrap();
    let o = monotrack(&["replay".as_ref(), &altered, "--out".as_ref(), &replayed]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("3 of 4 frames identical"), "{err}");
    assert!(
        err.contains("frames that differ from the recording: 2"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_damaged_recording_is_a_clear_error() {
    let dir = scratch("damaged");
    let garbage = dir.join("garbage.mtrec");
    std::fs::write(&garbage, b"not a recording at all").unwrap();
    let o = monotrack(&["replay".as_ref(), &garbage]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("invalid recording"), "{}", stderr(&o));
    // A real recording cut short (an app that died while recording).
    let frames = frames(&dir);
    let rec = dir.join("rec.mtrec");
    let o = monotrack(&[
        "track".as_ref(),
        &frames,
        "--record".as_ref(),
        &rec,
        "--out".as_ref(),
        &dir.join("out.jsonl"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(&rec).unwrap();
    std::fs::write(&rec, &bytes[..bytes.len() - 1000]).unwrap();
    let o = monotrack(&["replay".as_ref(), &rec]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(
        err.contains("invalid recording") && err.contains("past the end"),
        "{err}"
    );
    assert!(
        o.stdout.is_empty(),
        "nothing is replayed from a damaged file"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
