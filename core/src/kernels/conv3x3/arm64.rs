//! NEON form of the 3×3 convolution block: `fmla` on four-lane vectors, `ld1r` broadcasts.

use super::{Block, Depthwise, Lanes};
use std::arch::aarch64::{
    float32x4_t, vdupq_n_f32, vfmaq_f32, vld1q_dup_f32, vld1q_f32, vmaxnmq_f32, vst1q_f32,
};

impl Lanes for float32x4_t {
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller's contract (four values at `p`).
        unsafe { vld1q_f32(p) }
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn splat(p: *const f32) -> Self {
        // SAFETY: the caller's contract (one value at `p`).
        unsafe { vld1q_dup_f32(p) }
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    fn mul_add(self, w: Self, x: Self) -> Self {
        // SAFETY: NEON is baseline on aarch64.
        unsafe { vfmaq_f32(self, w, x) }
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    fn relu(self) -> Self {
        // `fmaxnm` with +0: a NaN lane gives the number (+0), and −0 is below +0.
        // SAFETY: NEON is baseline on aarch64.
        unsafe { vmaxnmq_f32(self, vdupq_n_f32(0.0)) }
    }

    #[inline(always)]
    fn to_array(self) -> [f32; 4] {
        let mut a = [0.0; 4];
        #[allow(unsafe_code)]
        // SAFETY: `a` holds the four values stored.
        unsafe {
            vst1q_f32(a.as_mut_ptr(), self)
        };
        a
    }
}

/// [`Block::body`] in NEON registers.
///
/// # Safety
/// As [`Block::body`].
#[target_feature(enable = "neon")]
#[allow(unsafe_code)]
pub(super) unsafe fn run<const P: usize>(
    block: &Block<'_>,
    at_in: &[usize; P],
    at_out: &[usize; P],
    out: &mut [f32],
) {
    // SAFETY: the caller's contract; NEON is baseline on aarch64.
    unsafe { block.body::<float32x4_t, P>(at_in, at_out, out) }
}

/// [`Depthwise::body`] in NEON registers.
///
/// # Safety
/// As [`Depthwise::body`].
#[target_feature(enable = "neon")]
#[allow(unsafe_code)]
pub(super) unsafe fn run_depthwise<const P: usize>(
    dw: &Depthwise<'_>,
    at_in: &[usize; P],
    at_out: &[usize; P],
    out: &mut [f32],
) {
    // SAFETY: the caller's contract; NEON is baseline on aarch64.
    unsafe { dw.body::<float32x4_t, P>(at_in, at_out, out) }
}
