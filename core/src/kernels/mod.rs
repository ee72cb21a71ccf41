//! The library's hand-written pixel kernels that have a form per instruction set, one folder per
//! kernel: `mod.rs` holds the portable form — plain Rust, the reference — the dispatch and the
//! tests every form must pass; `arm64.rs` the NEON form (baseline on aarch64: no run-time check);
//! `x86_64.rs` the x86-64 form where one pays. [`crate::kernels::kernel_path`] decides between them
//! (`MONOTRACK_KERNELS=portable` runs the portable forms on any CPU, which is what an aarch64 phone
//! computes, bit for bit).
//!
//! | kernel | portable | aarch64 | x86-64 |
//! |---|---|---|---|
//! | [`plane`]: an 8-bit plane made upright (rotation, mirroring) | 8×8 tiles transposed in `u64` words | 16×16 tiles in NEON registers | 16×16 tiles in SSE2 registers |
//! | Lucas–Kanade windows (`track::flow`: sampling, gradients, sums) | 16 lanes in arrays | 4 registers per lane group (`track/flow/arm64.rs`) | AVX2, AVX-512 (in `track/flow.rs`) |
//! | [`conv3x3`]: a convolution's block of 16 output channels × 6 positions, full (M3 trunks, the detector's 3×3, 1×1 and head layers) or depthwise (the detector's blocks) | `[f32; 4]` lanes, `mul_add` | `fmla` on 4 lanes | the NEON form's 128-bit twin (portable path); the native path's own forms for M3 in `conv` (AVX2, AVX-512, bf16, int8) |
//!
//! The patch warps, bilateral filter, fully connected heads and NCC keep their x86-64 forms
//! beside their pipeline modules (`landmarks::{warp, filter, dense}`, `track::ncc`); on aarch64
//! those stages run their portable forms, which the compiler vectorises for NEON. On x86-64's
//! native path the detector's blocks and heads run in tract.

mod choice;
pub(crate) mod conv3x3;
pub(crate) mod cpu;
pub(crate) mod plane;

pub use choice::{KernelChoice, KernelPath, choice, kernel_path, select};
pub use cpu::cpu_name;
