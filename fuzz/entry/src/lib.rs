//! What the fuzz targets run on one input, in one place for both of their runners: cargo-fuzz
//! (`fuzz/fuzz_targets/*.rs`, nightly, AddressSanitizer, coverage-guided; `fuzz/run.sh`) and the
//! stable test `tests/corpora.rs`, which replays the committed corpora and the seeds on every test
//! run. Each `run` panics on a contract break (a panic inside the SDK, or an FFI call that returns
//! `MonotrackError::Internal`); any other outcome of bad input is a pass.

pub mod bytes;
pub mod fit_inputs;
pub mod frames;
pub mod json_inputs;
pub mod model_bundle;
pub mod recording;

/// What a target runs on one input.
pub type Entry = fn(&[u8]);

/// The targets by name, as `fuzz/Cargo.toml` names its binaries.
pub const TARGETS: [(&str, Entry); 5] = [
    ("frames", frames::run),
    ("json_inputs", json_inputs::run),
    ("fit_inputs", fit_inputs::run),
    ("model_bundle", model_bundle::run),
    ("recording", recording::run),
];

/// The inputs `fuzz/run.sh` seeds a target with besides its committed corpus, built from the
/// shipped files: for `model_bundle` the built-in bundle and, per network, the bundle with that
/// network cut to half its bytes (sealed with a right checksum), for `json_inputs` the shipped face model, pose prior and M3 configuration and the
/// default configs behind their selector bytes, for `recording` recordings the library's writer
/// makes (every chunk kind; one cut at its size limit).
pub fn seeds(target: &str) -> Vec<(String, Vec<u8>)> {
    let with = |selector: u8, bytes: &[u8]| [&[selector], bytes].concat();
    match target {
        "model_bundle" => {
            use monotrack_core::model::bundle::ModelBundle;
            let builtin = ModelBundle::builtin();
            let mut seeds = vec![("seed-builtin".to_string(), builtin.to_bytes())];
            for (name, _) in builtin.files().filter(|(n, _)| n.ends_with(".onnx")) {
                let files = builtin
                    .files()
                    .map(|(n, b)| {
                        let b = if n == name { &b[..b.len() / 2] } else { b };
                        (n.to_string(), b.to_vec())
                    })
                    .collect();
                if let Ok(b) = ModelBundle::from_files(files) {
                    seeds.push((format!("seed-half-{name}"), b.to_bytes()));
                }
            }
            seeds
        }
        "json_inputs" => {
            let file = |rel: &str| {
                let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../core");
                std::fs::read(root.join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
            };
            let tracker = serde_json::to_vec(&monotrack_core::track::TrackerConfig::default());
            let detector = serde_json::to_vec(&monotrack_core::detect::DetectorConfig::default());
            vec![
                ("seed-tracker-config".into(), with(0, &tracker.unwrap())),
                ("seed-detector-config".into(), with(1, &detector.unwrap())),
                (
                    "seed-face-model".into(),
                    with(2, &file("models/face_model/face_model.json")),
                ),
                (
                    "seed-pose-prior".into(),
                    with(3, &file("models/body/pose_prior.json")),
                ),
                ("seed-m3".into(), with(4, &file("models/m3/m3.json"))),
            ]
        }
        "recording" => recording_seeds(),
        _ => Vec::new(),
    }
}

fn recording_seeds() -> Vec<(String, Vec<u8>)> {
    use monotrack_core::gaze::{GazeCalibration, Target};
    use monotrack_core::image::{Frame, FrameDesc, PixelFormat};
    use monotrack_core::record::{Header, ModelIdentity, Recorder, ResetKind, StreamStart};
    let header = Header {
        library_version: "0.0.0-seed".into(),
        arch: "aarch64".into(),
        kernels: "native".into(),
        cpu: "a seed".into(),
        tracker: Default::default(),
        detector: Default::default(),
        mirror_average: false,
        gaze: Default::default(),
        models: ModelIdentity {
            builtin: true,
            checksum: 0,
        },
    };
    let start = StreamStart {
        next_face_id: 1,
        frame_index: 0,
        whole_frame_turns: 0,
        calibration: GazeCalibration::from_tap_offsets(&[[[0.01, 0.02], [0.03, 0.04]]])
            .unwrap_or_default(),
    };
    let gray: Vec<u8> = (0..48).collect();
    let desc = FrameDesc::packed(8, 6, PixelFormat::Gray8);
    let write = |max_bytes: u64| -> Vec<u8> {
        let Ok(mut r) = Recorder::new(Vec::new(), max_bytes, &header) else {
            return Vec::new();
        };
        let screen = Target::screen("phone", 70.0, 150.0, [35.0, -8.0]).ok();
        r.begin(&start, screen.as_slice());
        if let Ok(frame) = Frame::new(&gray, desc) {
            for ts in 0..3 {
                r.frame(&frame, ts);
                r.result((ts != 1).then_some(ts as u64));
            }
        }
        r.dropped(2, &[5, 6]);
        r.tap(0, [35.0, 50.0], 2);
        r.reset(ResetKind::Tracks);
        r.reset(ResetKind::GazeCalibration);
        r.finish_into().map(|(bytes, _)| bytes).unwrap_or_default()
    };
    let whole = write(1 << 20);
    let cut = write(whole.len() as u64 - 100);
    vec![
        ("seed-every-kind".into(), whole),
        ("seed-truncated".into(), cut),
    ]
}
