//! Corrupt model bytes: M3 loaded from the shipped configuration with one network's ONNX bytes
//! replaced by the fuzzer's (seeded with the shipped files, `fuzz/README.md`).
use monotrack_core::landmarks::{EMBEDDED_FILES, M3};

/// One input of the `model_bytes` target.
pub fn run(data: &[u8]) {
    let Some((&which, onnx)) = data.split_first() else {
        return;
    };
    let nets: Vec<&str> = EMBEDDED_FILES
        .iter()
        .map(|(n, _)| *n)
        .filter(|n| n.ends_with(".onnx"))
        .collect();
    let target = nets[usize::from(which) % nets.len()];
    let files: Vec<(&str, &[u8])> = EMBEDDED_FILES
        .iter()
        .map(|&(n, b)| if n == target { (n, onnx) } else { (n, b) })
        .collect();
    let json = files
        .iter()
        .find(|(n, _)| *n == "m3.json")
        .map(|(_, b)| *b)
        .unwrap_or(&[]);
    let _ = M3::from_bytes(json, &files);
}
