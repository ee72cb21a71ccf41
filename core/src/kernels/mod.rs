//! The library's hand-written kernels that have a form per instruction set, one folder per
//! kernel, laid out as tract-linalg and XNNPACK lay theirs: `mod.rs` holds the portable form —
//! plain Rust, the reference — the dispatch and the tests every form must pass; `arm64.rs` the
//! NEON form (baseline on aarch64: no run-time check); `x86_64.rs` (and `conv3x3/avx.rs`) the
//! x86-64 forms. The process's kernel choice ([`KernelChoice`], fixed once: [`select`], else
//! `MONOTRACK_KERNELS`) decides between them: the portable path runs on any CPU what an aarch64
//! phone computes, bit for bit. [`cpu`] holds the CPU's identity and the features the forms need.
//! This folder is the only place in the crate with `std::arch`, `target_feature` or `unsafe`.
//!
//! | kernel | portable | aarch64 | x86-64 |
//! |---|---|---|---|
//! | [`plane`]: an 8-bit plane made upright (rotation, mirroring) | 8×8 tiles transposed in `u64` words | 16×16 tiles in NEON registers | 16×16 tiles in SSE2 registers |
//! | [`lk`]: Lucas–Kanade windows (`track::flow`): sampling, gradients, sums | 16 lanes in arrays | 4 registers per lane group | AVX2, AVX-512 (masked loads at the window's edge) |
//! | [`conv3x3`]: a convolution's block of 16 output channels × 6 positions, full (M3 trunks, the detector's 3×3, 1×1 and head layers) or depthwise (the detector's blocks) | `[f32; 4]` lanes, `mul_add` | `fmla` on 4 lanes | the NEON form's 128-bit twin (`x86_64.rs`, portable path); the native path's forms in `avx.rs`: f32 on 256 / 512 bits, bf16 pairs, int8 quads (`crate::nn::conv` chooses) |
//! | [`dense`]: a fully connected layer's product (M3's heads) | f32 FMAs over 32-column chunks, f32 or int8 weights | the portable form | copies compiled for AVX2 + FMA and for FMA; int8 (`vpdpbusd`) on AVX-512 VNNI |
//! | [`warp`]: a patch sampled bilinearly under an affine map (`landmarks::warp`): rotated maps in f32 chunks of 16 pixels, axis-aligned maps row by row in f64 | lanes in arrays; pixel by pixel | the portable form | AVX2 and AVX-512 gathers (rotated), AVX-512 rows (axis-aligned) |
//! | [`bilateral`]: OpenCV's bilateral filter over a padded patch (`landmarks::filter`) | tap by tap over each row | the portable form | AVX2, AVX-512 (one gather of colour weights per tap) |
//!
//! Scalar loops elsewhere that the compiler vectorises (the pyramid, NCC, the shape prior) get a
//! second copy compiled for AVX2 + FMA through [`cpu::with_avx2_copy`], which gives the same bits;
//! on aarch64 they run as compiled for NEON.

pub(crate) mod bilateral;
mod choice;
pub(crate) mod conv3x3;
pub(crate) mod cpu;
pub(crate) mod dense;
pub(crate) mod lk;
pub(crate) mod plane;
pub(crate) mod warp;

pub use choice::{KernelChoice, KernelPath, choice, kernel_path, select};
pub use cpu::cpu_name;
