//! The x86-64 forms of the bilateral filter: the portable form's per-pixel sums on eight (AVX2)
//! or sixteen (AVX-512) pixels per register. The portable loop's colour-table lookups are scalar
//! loads; here each tap's lookups are one hardware gather. The sums stay in registers over the
//! taps, and each pixel adds its taps in the same order with the same operations, so the bytes
//! are the same.

use super::Filter;

/// [`Filter::rows`] eight pixels at a time in AVX2 registers, single pixels for each row's tail.
#[target_feature(enable = "avx2,fma")]
pub(super) fn filter_avx2(f: &Filter<'_>, dst: &mut [u8]) {
    let (width, r) = (f.width, f.radius);
    let pw = width + 2 * r;
    for y in 0..f.height {
        let c0 = (y + r) * pw + r;
        let out = &mut dst[y * width..(y + 1) * width];
        let mut x = 0;
        while x + 8 <= width {
            block8(f, c0 + x, &mut out[x..x + 8]);
            x += 8;
        }
        for (x, d) in out.iter_mut().enumerate().skip(x) {
            *d = f.pixel(c0 + x);
        }
    }
}

/// Eight output pixels centred at `padded[c..c + 8]` (see [`filter_avx2`]).
#[target_feature(enable = "avx2,fma")]
#[inline]
fn block8(f: &Filter<'_>, c: usize, out: &mut [u8]) {
    use crate::kernels::cpu::avx2::{load_u8x8 as load8, store_u8x8};
    use std::arch::x86_64::{
        _mm256_abs_epi32, _mm256_add_ps, _mm256_cvtepi32_ps, _mm256_cvttps_epi32, _mm256_div_ps,
        _mm256_i32gather_ps, _mm256_max_ps, _mm256_min_ps, _mm256_mul_ps, _mm256_set1_ps,
        _mm256_setzero_ps, _mm256_sub_epi32,
    };
    let table = f.color_weight.as_ptr();
    let (zero, top) = (_mm256_setzero_ps(), _mm256_set1_ps(255.0));
    let v0 = load8(&f.padded[c..]);
    let (mut sum, mut wsum) = (zero, zero);
    for (&o, &sw) in f.offsets.iter().zip(f.space_weight) {
        let v = load8(&f.padded[(c as isize + o) as usize..]);
        let diff = _mm256_abs_epi32(_mm256_sub_epi32(v, v0));
        #[allow(unsafe_code)]
        // SAFETY: |v − v0| ≤ 255 indexes the 256-entry table.
        let cw = unsafe { _mm256_i32gather_ps::<4>(table, diff) };
        let w = _mm256_mul_ps(_mm256_set1_ps(sw), cw);
        wsum = _mm256_add_ps(wsum, w);
        sum = _mm256_add_ps(sum, _mm256_mul_ps(_mm256_cvtepi32_ps(v), w));
    }
    // `quantize`: the clamp, then truncation (≤ 255 after the clamp, so the packs do not
    // saturate).
    let q = _mm256_min_ps(_mm256_max_ps(_mm256_div_ps(sum, wsum), zero), top);
    store_u8x8(_mm256_cvttps_epi32(q), out);
}

/// [`filter_avx2`] sixteen pixels at a time in 512-bit registers (one 16-lane gather per tap),
/// then eight, then single pixels: each pixel's operations in the same order, so the same bytes.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) fn filter_avx512(f: &Filter<'_>, dst: &mut [u8]) {
    use std::arch::x86_64::{
        __m128i, _mm_loadu_si128, _mm_storeu_si128, _mm512_abs_epi32, _mm512_add_ps,
        _mm512_cvtepi32_epi8, _mm512_cvtepi32_ps, _mm512_cvtepu8_epi32, _mm512_cvttps_epi32,
        _mm512_div_ps, _mm512_i32gather_ps, _mm512_max_ps, _mm512_min_ps, _mm512_mul_ps,
        _mm512_set1_ps, _mm512_setzero_ps, _mm512_sub_epi32,
    };
    let (width, r) = (f.width, f.radius);
    let pw = width + 2 * r;
    let table = f.color_weight.as_ptr();
    let (zero, top) = (_mm512_setzero_ps(), _mm512_set1_ps(255.0));
    let load16 = |at: usize| {
        let bytes: &[u8; 16] = f.padded[at..at + 16].try_into().expect("16 bytes");
        #[allow(unsafe_code)]
        // SAFETY: `bytes` holds the sixteen bytes read (unaligned loads are allowed).
        _mm512_cvtepu8_epi32(unsafe { _mm_loadu_si128(bytes.as_ptr().cast::<__m128i>()) })
    };
    for y in 0..f.height {
        let c0 = (y + r) * pw + r;
        let out = &mut dst[y * width..(y + 1) * width];
        let mut x = 0;
        while x + 16 <= width {
            let c = c0 + x;
            let v0 = load16(c);
            let (mut sum, mut wsum) = (zero, zero);
            for (&o, &sw) in f.offsets.iter().zip(f.space_weight) {
                let v = load16((c as isize + o) as usize);
                let diff = _mm512_abs_epi32(_mm512_sub_epi32(v, v0));
                #[allow(unsafe_code)]
                // SAFETY: |v − v0| ≤ 255 indexes the 256-entry table.
                let cw = unsafe { _mm512_i32gather_ps::<4>(diff, table) };
                let w = _mm512_mul_ps(_mm512_set1_ps(sw), cw);
                wsum = _mm512_add_ps(wsum, w);
                sum = _mm512_add_ps(sum, _mm512_mul_ps(_mm512_cvtepi32_ps(v), w));
            }
            let q = _mm512_min_ps(_mm512_max_ps(_mm512_div_ps(sum, wsum), zero), top);
            let bytes = _mm512_cvtepi32_epi8(_mm512_cvttps_epi32(q));
            let dst16: &mut [u8; 16] = (&mut out[x..x + 16]).try_into().expect("16 bytes");
            #[allow(unsafe_code)]
            // SAFETY: `dst16` holds the sixteen bytes written.
            unsafe {
                _mm_storeu_si128(dst16.as_mut_ptr().cast::<__m128i>(), bytes)
            };
            x += 16;
        }
        if x + 8 <= width {
            block8(f, c0 + x, &mut out[x..x + 8]);
            x += 8;
        }
        for (x, d) in out.iter_mut().enumerate().skip(x) {
            *d = f.pixel(c0 + x);
        }
    }
}
