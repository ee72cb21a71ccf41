//! The x86-64 forms of the patch sampling: AVX2 and AVX-512 hardware gathers for rotated maps
//! ([`super::ClampedMap`]), 16-pixel AVX-512 rows for axis-aligned ones
//! ([`super::sample_axis_aligned`]). Each does the portable form's arithmetic in its order, in
//! vector registers, so each gives its bytes.

use super::{AXIS_MAX_SIDE, ClampedMap, Tap, axis_row};

/// [`ClampedMap::sample_body`] with the four taps of eight pixels read by two AVX2 gathers of
/// four bytes each (a tap pair of the upper and of the lower row per pixel), the u8 → f32
/// conversions and the final rounding in vector registers. The body's compiled loop spends its
/// time in scalar conversions, stores of single lanes reloaded as vectors (store-forwarding
/// stalls) and a scalar saturating cast per pixel; the arithmetic and its order are the body's,
/// so the bytes are too.
#[target_feature(enable = "avx2,fma")]
pub(super) fn sample_avx2(
    map: &ClampedMap<'_>,
    data: &[u8],
    iw: usize,
    ih: usize,
    width: usize,
    out: &mut [u8],
) {
    use crate::kernels::cpu::avx2::store_u8x8;
    use std::arch::x86_64::{
        __m256, __m256i, _mm256_add_epi32, _mm256_add_ps, _mm256_and_si256, _mm256_cvtepi32_ps,
        _mm256_cvttps_epi32, _mm256_i32gather_epi32, _mm256_max_ps, _mm256_min_epi32,
        _mm256_min_ps, _mm256_mul_ps, _mm256_mullo_epi32, _mm256_set1_epi32, _mm256_set1_ps,
        _mm256_setr_ps, _mm256_setzero_ps, _mm256_srli_epi32, _mm256_sub_ps,
    };
    const N: usize = ClampedMap::CHUNK;
    assert!(iw >= 2 && ih >= 2 && data.len() == iw * ih);
    let m = map.m;
    let (dx, dy) = (_mm256_set1_ps(m[0] as f32), _mm256_set1_ps(m[3] as f32));
    let ramps = [
        _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
        _mm256_setr_ps(8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0),
    ];
    // The body's offsets within a chunk, `d · k`, computed once.
    let steps = ramps.map(|r| (_mm256_mul_ps(dx, r), _mm256_mul_ps(dy, r)));
    let zero = _mm256_setzero_ps();
    let (x_cap, y_cap) = (
        _mm256_set1_ps((iw - 1) as f32),
        _mm256_set1_ps((ih - 1) as f32),
    );
    let (x0_cap, y0_cap) = (
        _mm256_set1_epi32(iw as i32 - 2),
        _mm256_set1_epi32(ih as i32 - 2),
    );
    let (half, byte, stride) = (
        _mm256_set1_ps(0.5),
        _mm256_set1_epi32(0xff),
        _mm256_set1_epi32(iw as i32),
    );
    // The lower tap pair is read as bytes 2 and 3 of the word two bytes before it, so that
    // the word of the last pair of the image ends at its last byte.
    let upper = data.as_ptr().cast::<i32>();
    let lower = data[iw - 2..].as_ptr().cast::<i32>();
    // Lanes 0..8 of a tap pair word as f32: its first and second byte.
    let taps = |w: __m256i| -> (__m256, __m256) {
        (
            _mm256_cvtepi32_ps(_mm256_and_si256(w, byte)),
            _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32::<8>(w), byte)),
        )
    };
    let mut bytes = [0u8; N];
    for (v, row) in out.chunks_exact_mut(width).enumerate() {
        let vc = v as f64 + 0.5;
        for (c, chunk) in row.chunks_mut(N).enumerate() {
            let uc = (c * N) as f64 + 0.5;
            let x_org = _mm256_set1_ps((m[0] * uc + m[1] * vc + m[2] - 0.5) as f32);
            let y_org = _mm256_set1_ps((m[3] * uc + m[4] * vc + m[5] - 0.5) as f32);
            for (half_chunk, &(sx, sy)) in steps.iter().enumerate() {
                // max first: it returns its second operand (0) for a NaN lane.
                let x = _mm256_min_ps(_mm256_max_ps(_mm256_add_ps(x_org, sx), zero), x_cap);
                let y = _mm256_min_ps(_mm256_max_ps(_mm256_add_ps(y_org, sy), zero), y_cap);
                let x0 = _mm256_min_epi32(_mm256_cvttps_epi32(x), x0_cap);
                let y0 = _mm256_min_epi32(_mm256_cvttps_epi32(y), y0_cap);
                let fx = _mm256_sub_ps(x, _mm256_cvtepi32_ps(x0));
                let fy = _mm256_sub_ps(y, _mm256_cvtepi32_ps(y0));
                let idx = _mm256_add_epi32(_mm256_mullo_epi32(y0, stride), x0);
                #[allow(unsafe_code)]
                // SAFETY: 0 ≤ idx ≤ (ih − 2)·iw + iw − 2 (the clamps above), so the four
                // bytes at `upper + idx` end by (ih − 1)·iw + 1 < iw·ih, and those at
                // `lower + idx` = `upper + iw − 2 + idx` start at iw − 2 ≥ 0 and end by
                // iw·ih − 1.
                let (t, b) = unsafe {
                    (
                        _mm256_i32gather_epi32::<1>(upper, idx),
                        _mm256_i32gather_epi32::<1>(lower, idx),
                    )
                };
                let (p00, p01) = taps(t);
                let (p10, p11) = taps(_mm256_srli_epi32::<16>(b));
                let top = _mm256_add_ps(p00, _mm256_mul_ps(fx, _mm256_sub_ps(p01, p00)));
                let bottom = _mm256_add_ps(p10, _mm256_mul_ps(fx, _mm256_sub_ps(p11, p10)));
                let val = _mm256_add_ps(
                    _mm256_add_ps(top, _mm256_mul_ps(fy, _mm256_sub_ps(bottom, top))),
                    half,
                );
                // val ≥ 0.5: truncation floors it, and the packs saturate at 255 as the
                // body's cast does.
                let dst = &mut bytes[half_chunk * 8..half_chunk * 8 + 8];
                store_u8x8(_mm256_cvttps_epi32(val), dst);
            }
            chunk.copy_from_slice(&bytes[..chunk.len()]);
        }
    }
}

/// [`sample_avx2`] on 16 lanes: one gather per tap pair and row for the whole chunk, the same
/// arithmetic per lane, so the same bytes.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) fn sample_avx512(
    map: &ClampedMap<'_>,
    data: &[u8],
    iw: usize,
    ih: usize,
    width: usize,
    out: &mut [u8],
) {
    use std::arch::x86_64::{
        __m128i, __m512, __m512i, _mm_storeu_si128, _mm512_add_epi32, _mm512_add_ps,
        _mm512_and_si512, _mm512_cvtepi32_ps, _mm512_cvttps_epi32, _mm512_cvtusepi32_epi8,
        _mm512_i32gather_epi32, _mm512_max_ps, _mm512_min_epi32, _mm512_min_ps, _mm512_mul_ps,
        _mm512_mullo_epi32, _mm512_set1_epi32, _mm512_set1_ps, _mm512_setr_ps, _mm512_setzero_ps,
        _mm512_srli_epi32, _mm512_sub_ps,
    };
    const N: usize = ClampedMap::CHUNK;
    assert!(iw >= 2 && ih >= 2 && data.len() == iw * ih);
    let m = map.m;
    let ramp = _mm512_setr_ps(
        0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0,
    );
    let sx = _mm512_mul_ps(_mm512_set1_ps(m[0] as f32), ramp);
    let sy = _mm512_mul_ps(_mm512_set1_ps(m[3] as f32), ramp);
    let zero = _mm512_setzero_ps();
    let (x_cap, y_cap) = (
        _mm512_set1_ps((iw - 1) as f32),
        _mm512_set1_ps((ih - 1) as f32),
    );
    let (x0_cap, y0_cap) = (
        _mm512_set1_epi32(iw as i32 - 2),
        _mm512_set1_epi32(ih as i32 - 2),
    );
    let (half, byte, stride) = (
        _mm512_set1_ps(0.5),
        _mm512_set1_epi32(0xff),
        _mm512_set1_epi32(iw as i32),
    );
    // As in the AVX2 kernel: the lower tap pair is bytes 2 and 3 of the word two bytes
    // before it.
    let upper = data.as_ptr();
    let lower = data[iw - 2..].as_ptr();
    let taps = |w: __m512i| -> (__m512, __m512) {
        (
            _mm512_cvtepi32_ps(_mm512_and_si512(w, byte)),
            _mm512_cvtepi32_ps(_mm512_and_si512(_mm512_srli_epi32::<8>(w), byte)),
        )
    };
    let mut bytes = [0u8; N];
    for (v, row) in out.chunks_exact_mut(width).enumerate() {
        let vc = v as f64 + 0.5;
        for (c, chunk) in row.chunks_mut(N).enumerate() {
            let uc = (c * N) as f64 + 0.5;
            let x_org = _mm512_set1_ps((m[0] * uc + m[1] * vc + m[2] - 0.5) as f32);
            let y_org = _mm512_set1_ps((m[3] * uc + m[4] * vc + m[5] - 0.5) as f32);
            // max first: it returns its second operand (0) for a NaN lane.
            let x = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(x_org, sx), zero), x_cap);
            let y = _mm512_min_ps(_mm512_max_ps(_mm512_add_ps(y_org, sy), zero), y_cap);
            let x0 = _mm512_min_epi32(_mm512_cvttps_epi32(x), x0_cap);
            let y0 = _mm512_min_epi32(_mm512_cvttps_epi32(y), y0_cap);
            let fx = _mm512_sub_ps(x, _mm512_cvtepi32_ps(x0));
            let fy = _mm512_sub_ps(y, _mm512_cvtepi32_ps(y0));
            let idx = _mm512_add_epi32(_mm512_mullo_epi32(y0, stride), x0);
            #[allow(unsafe_code)]
            // SAFETY: as in the AVX2 kernel, 0 ≤ idx ≤ (ih − 2)·iw + iw − 2, so the words
            // at `upper + idx` and `lower + idx` lie inside `data`.
            let (t, b) = unsafe {
                (
                    _mm512_i32gather_epi32::<1>(idx, upper.cast()),
                    _mm512_i32gather_epi32::<1>(idx, lower.cast()),
                )
            };
            let (p00, p01) = taps(t);
            let (p10, p11) = taps(_mm512_srli_epi32::<16>(b));
            let top = _mm512_add_ps(p00, _mm512_mul_ps(fx, _mm512_sub_ps(p01, p00)));
            let bottom = _mm512_add_ps(p10, _mm512_mul_ps(fx, _mm512_sub_ps(p11, p10)));
            let val = _mm512_add_ps(
                _mm512_add_ps(top, _mm512_mul_ps(fy, _mm512_sub_ps(bottom, top))),
                half,
            );
            // val ≥ 0.5: truncation floors it; the narrowing saturates at 255 as the body's
            // cast does.
            #[allow(unsafe_code)]
            // SAFETY: `bytes` holds the 16 bytes stored.
            unsafe {
                _mm_storeu_si128(
                    bytes.as_mut_ptr().cast::<__m128i>(),
                    _mm512_cvtusepi32_epi8(_mm512_cvttps_epi32(val)),
                )
            };
            chunk.copy_from_slice(&bytes[..chunk.len()]);
        }
    }
}

/// Pixels per step of [`axis_row_avx512`]: one 16-lane gather of each tap.
pub(super) const AXIS_LANES: usize = 16;

/// The column taps of [`super::sample_axis_aligned`] as the AVX-512 rows read them: the two
/// taps' indices in a row and their weights `1 − fx` and `fx`.
struct AxisColumns {
    a: [i32; AXIS_MAX_SIDE],
    b: [i32; AXIS_MAX_SIDE],
    wa: [f64; AXIS_MAX_SIDE],
    wb: [f64; AXIS_MAX_SIDE],
}

/// Every output row of [`super::sample_axis_aligned`] (`rows`: per row its source rows' offsets
/// and the second's weight) through [`axis_row_avx512`]: the portable rows spend their time on a
/// scalar conversion and a byte store per pixel.
///
/// # Safety
/// The CPU has AVX-512F, AVX2 and FMA; `data` is the whole `iw`-wide image and its length fits
/// i32; every row tap is the offset of one of its rows and every column tap is below `iw`; there
/// are at least [`AXIS_LANES`] and at most [`AXIS_MAX_SIDE`] columns.
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(unsafe_code)]
pub(super) unsafe fn axis_rows_avx512(
    data: &[u8],
    iw: usize,
    cols: &[Tap],
    rows: &[Tap],
    out: &mut [u8],
) {
    let mut taps = AxisColumns {
        a: [0; AXIS_MAX_SIDE],
        b: [0; AXIS_MAX_SIDE],
        wa: [0.0; AXIS_MAX_SIDE],
        wb: [0.0; AXIS_MAX_SIDE],
    };
    for (c, &(xa, xb, fx)) in cols.iter().enumerate() {
        // Both below iw, which fits i32 (the caller's contract).
        (taps.a[c], taps.b[c]) = (xa as i32, xb as i32);
        (taps.wa[c], taps.wb[c]) = (1.0 - fx, fx);
    }
    for (row, &(ra, rb, fy)) in out.chunks_exact_mut(cols.len()).zip(rows) {
        // SAFETY: the caller's contract, row by row.
        unsafe { axis_row_avx512(data, iw, ra, rb, fy, &taps, cols, row) };
    }
}

/// [`axis_row`] 16 pixels at a time: each tap of 16 pixels is one gather of 32-bit words whose
/// first byte (or, for a row too near the end of the image for a word to fit after the tap, the
/// last byte of the word ending at the tap) is the pixel; then the formula's f64 products and sums
/// in the same order, so the same bytes. The last, partial group overlaps the one before it.
///
/// # Safety
/// The CPU has AVX-512F, AVX2 and FMA; `data` is the whole `iw`-wide image, its length fits i32,
/// `ra` and `rb` are the offsets of two of its rows, and `taps` holds `cols` (at least
/// [`AXIS_LANES`] of them, each below `iw`).
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(unsafe_code, clippy::too_many_arguments)]
unsafe fn axis_row_avx512(
    data: &[u8],
    iw: usize,
    ra: usize,
    rb: usize,
    fy: f64,
    taps: &AxisColumns,
    cols: &[Tap],
    row: &mut [u8],
) {
    use std::arch::x86_64::{
        __m128i, __m512d, __m512i, _mm_storeu_si128, _mm512_add_pd, _mm512_and_si512,
        _mm512_castsi256_si512, _mm512_castsi512_si256, _mm512_cvtepi32_pd, _mm512_cvttpd_epi32,
        _mm512_cvtusepi32_epi8, _mm512_extracti64x4_epi64, _mm512_i32gather_epi32,
        _mm512_inserti64x4, _mm512_loadu_pd, _mm512_loadu_si512, _mm512_mul_pd, _mm512_set1_epi32,
        _mm512_set1_pd, _mm512_srli_epi32,
    };
    let width = row.len();
    assert!(width >= AXIS_LANES && width == cols.len() && width <= AXIS_MAX_SIDE);
    // Where the four bytes after a tap stay inside the image the word starts at the tap;
    // otherwise (the last row) it ends there, which needs three bytes before the row.
    let base = |r: usize| -> Option<(*const u8, bool)> {
        if r + iw + 3 <= data.len() {
            Some((data[r..].as_ptr(), true))
        } else if r >= 3 {
            Some((data[r - 3..].as_ptr(), false))
        } else {
            None
        }
    };
    let (Some((top, top_fwd)), Some((bottom, bottom_fwd))) = (base(ra), base(rb)) else {
        axis_row(data, iw, ra, rb, fy, cols, row);
        return;
    };
    let byte = _mm512_set1_epi32(0xff);
    let pixel = |w: __m512i, forward: bool| -> [__m512d; 2] {
        let v = if forward {
            _mm512_and_si512(w, byte)
        } else {
            _mm512_srli_epi32::<24>(w)
        };
        [
            _mm512_cvtepi32_pd(_mm512_castsi512_si256(v)),
            _mm512_cvtepi32_pd(_mm512_extracti64x4_epi64::<1>(v)),
        ]
    };
    let (gy, fyv, half) = (
        _mm512_set1_pd(1.0 - fy),
        _mm512_set1_pd(fy),
        _mm512_set1_pd(0.5),
    );
    let mut c0 = 0;
    loop {
        let c = c0.min(width - AXIS_LANES);
        // SAFETY: c + 16 ≤ width ≤ AXIS_MAX_SIDE, so the loads stay inside the arrays.
        let (xa, xb) = unsafe {
            (
                _mm512_loadu_si512(taps.a[c..c + AXIS_LANES].as_ptr().cast()),
                _mm512_loadu_si512(taps.b[c..c + AXIS_LANES].as_ptr().cast()),
            )
        };
        // SAFETY: every index is below iw, so each gathered word lies inside `data` (`base`).
        let (p00, p01, p10, p11) = unsafe {
            (
                pixel(_mm512_i32gather_epi32::<1>(xa, top.cast()), top_fwd),
                pixel(_mm512_i32gather_epi32::<1>(xb, top.cast()), top_fwd),
                pixel(_mm512_i32gather_epi32::<1>(xa, bottom.cast()), bottom_fwd),
                pixel(_mm512_i32gather_epi32::<1>(xb, bottom.cast()), bottom_fwd),
            )
        };
        let ints: [_; 2] = std::array::from_fn(|h| {
            let at = c + 8 * h;
            // SAFETY: at + 8 ≤ c + 16 ≤ AXIS_MAX_SIDE.
            let (wa, wb) = unsafe {
                (
                    _mm512_loadu_pd(taps.wa[at..at + 8].as_ptr()),
                    _mm512_loadu_pd(taps.wb[at..at + 8].as_ptr()),
                )
            };
            let upper = _mm512_add_pd(_mm512_mul_pd(wa, p00[h]), _mm512_mul_pd(wb, p01[h]));
            let lower = _mm512_add_pd(_mm512_mul_pd(wa, p10[h]), _mm512_mul_pd(wb, p11[h]));
            let val = _mm512_add_pd(
                _mm512_add_pd(_mm512_mul_pd(gy, upper), _mm512_mul_pd(fyv, lower)),
                half,
            );
            // val ≥ 0.5: truncation floors it, as the scalar cast does.
            _mm512_cvttpd_epi32(val)
        });
        let words = _mm512_inserti64x4::<1>(_mm512_castsi256_si512(ints[0]), ints[1]);
        let dst: &mut [u8; AXIS_LANES] = (&mut row[c..c + AXIS_LANES]).try_into().expect("16");
        // SAFETY: `dst` holds the 16 bytes stored; the narrowing saturates at 255 as the cast.
        unsafe {
            _mm_storeu_si128(
                dst.as_mut_ptr().cast::<__m128i>(),
                _mm512_cvtusepi32_epi8(words),
            )
        };
        c0 += AXIS_LANES;
        if c0 >= width {
            break;
        }
    }
}
