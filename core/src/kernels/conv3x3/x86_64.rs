//! The x86-64 twin of the NEON form of the 3×3 convolution block: the same four-lane vectors
//! (128-bit `vfmadd231ps`, `vbroadcastss`), so x86-64's portable path does the phone's work with
//! the phone's vector width, and gives its bits.

use super::{Block, Depthwise, Lanes};
use std::arch::x86_64::{
    __m128, _mm_broadcast_ss, _mm_fmadd_ps, _mm_loadu_ps, _mm_max_ps, _mm_setzero_ps, _mm_storeu_ps,
};

impl Lanes for __m128 {
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller's contract (four values at `p`); SSE is baseline on x86-64.
        unsafe { _mm_loadu_ps(p) }
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn splat(p: *const f32) -> Self {
        // SAFETY: the caller's contract (one value at `p`); only reached from the
        // `target_feature` functions below, which enable AVX.
        unsafe { _mm_broadcast_ss(&*p) }
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    fn mul_add(self, w: Self, x: Self) -> Self {
        // SAFETY: only reached from the `target_feature` functions below, which enable FMA.
        unsafe { _mm_fmadd_ps(w, x, self) }
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    fn relu(self) -> Self {
        // `maxps` gives its second operand (+0) unless the first is greater: NaN and −0 too.
        // SAFETY: SSE is baseline on x86-64.
        unsafe { _mm_max_ps(self, _mm_setzero_ps()) }
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    fn to_array(self) -> [f32; 4] {
        let mut a = [0.0; 4];
        // SAFETY: `a` holds the four values stored.
        unsafe { _mm_storeu_ps(a.as_mut_ptr(), self) };
        a
    }
}

/// [`Block::body`] on 128-bit registers with FMA (sixteen vector registers).
///
/// # Safety
/// As [`Block::body`]; the CPU has AVX and FMA.
#[target_feature(enable = "avx,fma")]
#[allow(unsafe_code)]
pub(super) unsafe fn run<const P: usize>(
    block: &Block<'_>,
    at_in: &[usize; P],
    at_out: &[usize; P],
    out: &mut [f32],
) {
    // SAFETY: the caller's contract.
    unsafe { block.body::<__m128, P>(at_in, at_out, out) }
}

/// [`run`] with AVX-512VL's thirty-two vector registers, as many as NEON has.
///
/// # Safety
/// As [`Block::body`]; the CPU has AVX, FMA, AVX-512F and AVX-512VL.
#[target_feature(enable = "avx,fma,avx512f,avx512vl")]
#[allow(unsafe_code)]
pub(super) unsafe fn run_wide_file<const P: usize>(
    block: &Block<'_>,
    at_in: &[usize; P],
    at_out: &[usize; P],
    out: &mut [f32],
) {
    // SAFETY: the caller's contract.
    unsafe { block.body::<__m128, P>(at_in, at_out, out) }
}

/// [`Depthwise::body`] on 128-bit registers with FMA.
///
/// # Safety
/// As [`Depthwise::body`]; the CPU has AVX and FMA.
#[target_feature(enable = "avx,fma")]
#[allow(unsafe_code)]
pub(super) unsafe fn run_depthwise<const P: usize>(
    dw: &Depthwise<'_>,
    at_in: &[usize; P],
    at_out: &[usize; P],
    out: &mut [f32],
) {
    // SAFETY: the caller's contract.
    unsafe { dw.body::<__m128, P>(at_in, at_out, out) }
}

/// [`run_depthwise`] with AVX-512VL's thirty-two vector registers.
///
/// # Safety
/// As [`Depthwise::body`]; the CPU has AVX, FMA, AVX-512F and AVX-512VL.
#[target_feature(enable = "avx,fma,avx512f,avx512vl")]
#[allow(unsafe_code)]
pub(super) unsafe fn run_depthwise_wide_file<const P: usize>(
    dw: &Depthwise<'_>,
    at_in: &[usize; P],
    at_out: &[usize; P],
    out: &mut [f32],
) {
    // SAFETY: the caller's contract.
    unsafe { dw.body::<__m128, P>(at_in, at_out, out) }
}
