//! The bindings an app developer gets, generated the way the platform builds generate them
//! (uniffi library mode, ios/build-xcframework.sh and android/'s Gradle task) from the FFI library
//! this test build made: both languages must carry the surface the platform wrappers
//! (ios/Sources/Monotrack, android/monotrack) call. The generated code itself is compiled and run
//! against the library by bindings/tests/run-swift.sh and run-kotlin.sh.

use std::path::{Path, PathBuf};
use std::process::Command;

fn ffi_library() -> PathBuf {
    // The FFI library is a dev-dependency, so this test build builds it: beside the bin where cargo
    // was asked for it, else in the build's deps/ folder (cdylibs carry no hash in their names).
    let dir = Path::new(env!("CARGO_BIN_EXE_uniffi-bindgen"))
        .parent()
        .unwrap();
    let name = if cfg!(target_os = "macos") {
        "libmonotrack_ffi.dylib"
    } else if cfg!(windows) {
        "monotrack_ffi.dll"
    } else {
        "libmonotrack_ffi.so"
    };
    let lib = [dir.join(name), dir.join("deps").join(name)]
        .into_iter()
        .find(|p| p.is_file());
    lib.unwrap_or_else(|| panic!("{name} was not built in {}", dir.display()))
}

/// Generates into a folder of the calling test's own (`test`): the tests run in parallel.
fn generate(language: &str, test: &str) -> PathBuf {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{test}-{language}"));
    let _ = std::fs::remove_dir_all(&out);
    let status = Command::new(env!("CARGO_BIN_EXE_uniffi-bindgen"))
        .args(["generate", "--library"])
        .arg(ffi_library())
        .args(["--language", language, "--no-format", "--out-dir"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success(), "uniffi-bindgen {language}: {status}");
    out
}

fn files(dir: &Path) -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> = walk(dir)
        .into_iter()
        .map(|p| {
            let rel = p.strip_prefix(dir).unwrap().display().to_string();
            (rel, std::fs::read_to_string(&p).unwrap())
        })
        .collect();
    v.sort();
    v
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// What the wrappers call, by the name each language gives it.
fn assert_surface(language: &str, symbols: &[&str]) {
    let text: String = files(&generate(language, "surface"))
        .into_iter()
        .map(|(_, t)| t)
        .collect();
    let missing: Vec<&&str> = symbols.iter().filter(|s| !text.contains(**s)).collect();
    assert!(
        missing.is_empty(),
        "missing in the generated {language}: {missing:?}"
    );
}

#[test]
fn swift_has_what_the_ios_wrapper_calls() {
    assert_surface(
        "swift",
        &[
            "func detect(",
            "func detectForVideo(",
            "func detectAsync(",
            "func reset()",
            "class FaceTracker",
            "protocol LiveStreamListener",
            "struct FaceTrackerOptions",
            "func frameByteCount(",
            "func headAxes(",
            "func gazeArrows(",
            "func runBenchmark(",
            "enum MonotrackError",
        ],
    );
}

#[test]
fn kotlin_has_what_the_android_wrapper_calls() {
    assert_surface(
        "kotlin",
        &[
            "package io.monotrack",
            "fun `detect`(",
            "fun `detectForVideo`(",
            "fun `detectAsync`(",
            "fun `reset`()",
            "class FaceTracker",
            "interface LiveStreamListener",
            "data class FaceTrackerOptions",
            "fun `frameByteCount`(",
            "fun `headAxes`(",
            "fun `gazeArrows`(",
            "fun `runBenchmark`(",
            "sealed class MonotrackException",
        ],
    );
}
