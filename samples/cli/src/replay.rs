//! `monotrack replay FILE [--out OUT.jsonl] [--models BUNDLE]` (CONTRACT.md): a recording
//! (`monotrack_core::record`, `core/src/record/FORMAT.md`) run again through a tracker built from
//! its header, on the recorded kernel path where this CPU has it, printing the `track` line of
//! every recorded frame and checking each result against the recorded digest.

use crate::LineSink;
use crate::track::frame_json;
use monotrack_core::model::bundle::ModelBundle;
use monotrack_core::record::{Recording, Replay};
use serde_json::json;
use std::path::Path;

/// Replays `input`; `kernels_given`: the command line chose the kernels (`--kernels`), which then
/// stand. Returns whether every checked frame was identical to the recording.
///
/// # Errors
/// A message when the file cannot be read or is no valid recording, when its models are not at
/// hand, or an output cannot be written.
pub fn run(
    input: &Path,
    out: Option<&Path>,
    models: Option<&Path>,
    kernels_given: bool,
) -> Result<bool, String> {
    let name = input.display();
    let bytes = std::fs::read(input).map_err(|e| format!("cannot read {name}: {e}"))?;
    let recording = Recording::parse(&bytes).map_err(|e| format!("{name}: {e}"))?;
    let h = recording.header();
    eprintln!(
        "monotrack: {name}: {} frames recorded by monotrack {} on {} ({}, {} kernels)",
        recording.frames(),
        h.library_version,
        h.arch,
        h.cpu,
        h.kernels
    );
    if h.library_version != env!("CARGO_PKG_VERSION") {
        eprintln!(
            "monotrack: recorded by another version than this one ({}): results may differ",
            env!("CARGO_PKG_VERSION")
        );
    }
    if kernels_given {
        eprintln!("monotrack: --kernels chose the kernels, not the recording");
    } else {
        let (choice, note) = h.replay_kernels().map_err(|e| format!("{name}: {e}"))?;
        monotrack_core::kernels::select(choice).map_err(|e| e.to_string())?;
        if let Some(note) = note {
            eprintln!("monotrack: {note}");
        }
    }
    eprintln!(
        "monotrack: replaying on the {} path ({})",
        monotrack_core::kernels::choice(),
        monotrack_core::kernels::cpu_name()
    );
    let bundle = match models {
        Some(p) => {
            let b = std::fs::read(p).map_err(|e| format!("cannot read {}: {e}", p.display()))?;
            Some(ModelBundle::from_bytes(&b).map_err(|e| format!("{}: {e}", p.display()))?)
        }
        None => None,
    };
    let mut replay =
        Replay::new(&recording, bundle.as_ref()).map_err(|e| format!("{name}: {e}"))?;
    let mut sink = LineSink::new(out)?;
    let (mut identical, mut checked) = (0u64, 0u64);
    let mut differ = Vec::new();
    while let Some(f) = replay.next_frame().map_err(|e| format!("{name}: {e}"))? {
        // The line `track` writes for the frame (its number: the frame's place in the recording,
        // which is `track`'s own for a recording it made).
        match &f.result {
            Ok(r) => {
                let targets = Some(f.targets).filter(|t| !t.is_empty());
                let mut line = frame_json(r, targets);
                line["frame"] = json!(f.index);
                sink.write(&line)?;
            }
            Err(e) => {
                eprintln!("monotrack: frame {}: {e}", f.index);
                sink.write(&json!({"frame": f.index, "error": e.to_string()}))?;
            }
        }
        match f.identical() {
            Some(true) => {
                checked += 1;
                identical += 1;
            }
            Some(false) => {
                checked += 1;
                differ.push(f.index);
            }
            None => {}
        }
    }
    drop(sink);
    eprintln!("monotrack: {identical} of {checked} frames identical");
    let unchecked = recording.frames() - recording.checked_frames();
    if unchecked > 0 {
        eprintln!(
            "monotrack: {unchecked} frames have no recorded result to check (the recording \
             tracker panicked on them)"
        );
    }
    if recording.truncated() {
        eprintln!(
            "monotrack: the recording was truncated at its size limit: it holds the first {} \
             frames",
            recording.frames()
        );
    }
    if !differ.is_empty() {
        let list: Vec<String> = differ.iter().map(u64::to_string).collect();
        eprintln!(
            "monotrack: frames that differ from the recording: {}",
            list.join(", ")
        );
    }
    Ok(differ.is_empty())
}
