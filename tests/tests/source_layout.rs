//! The core's layout rules, checked on its source so that a change that breaks one fails here
//! rather than in review: every `std::arch`, `target_feature` and `unsafe` use lives under
//! `core/src/kernels/`; the pipeline modules (`detect`, `landmarks`, `track`) hold no graph
//! parsing, protobuf types or tract; the kernel choice's environment variable is read in
//! `kernels/choice.rs` only.

use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir` (or `dir` itself, a file), recursively, in a fixed order.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    if dir.is_file() {
        return vec![dir.to_path_buf()];
    }
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

fn core_src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../core/src")
}

/// The lines of the files under `core/src/<under>` (every file when empty) outside `except`
/// that contain any of `needles`, as `path:line: text`.
fn offending(under: &str, except: &[&str], needles: &[&str]) -> Vec<String> {
    let root = core_src();
    let mut hits = Vec::new();
    for file in rust_files(&root.join(under)) {
        let rel = file.strip_prefix(&root).expect("under core/src");
        let rel = rel.to_string_lossy().replace('\\', "/");
        if except.iter().any(|e| rel.starts_with(e)) {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("a source file");
        for (i, line) in text.lines().enumerate() {
            if needles.iter().any(|n| line.contains(n)) {
                hits.push(format!("core/src/{rel}:{}: {}", i + 1, line.trim()));
            }
        }
    }
    hits
}

#[test]
fn simd_and_unsafe_live_under_the_kernels_folder_only() {
    let hits = offending(
        "",
        &["kernels/"],
        &[
            "std::arch",
            "target_feature",
            "unsafe",
            "is_x86_feature_detected",
        ],
    );
    assert!(
        hits.is_empty(),
        "outside core/src/kernels:\n{}",
        hits.join("\n")
    );
    // The rule holds something: the kernels do use them.
    assert!(!offending("kernels", &[], &["target_feature"]).is_empty());
}

#[test]
fn pipeline_modules_hold_no_graph_parsing_or_tract() {
    for module in ["detect", "landmarks", "track"] {
        let hits = offending(module, &[], &["tract_", "onnx::pb", "prost", "ModelProto"]);
        assert!(hits.is_empty(), "in the pipeline:\n{}", hits.join("\n"));
    }
    assert!(!offending("nn", &[], &["onnx::pb"]).is_empty());
}

#[test]
fn the_kernel_choice_is_read_from_the_environment_in_one_place() {
    let hits = offending("", &["kernels/choice.rs"], &["env::var(\"MONOTRACK_"]);
    assert!(hits.is_empty(), "{}", hits.join("\n"));
    assert_eq!(
        offending(
            "kernels/choice.rs",
            &[],
            &["env::var(\"MONOTRACK_KERNELS\")"]
        )
        .len(),
        1
    );
}
