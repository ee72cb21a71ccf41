//! The AVX2 + FMA and AVX-512 (F, BW, VL) forms of the Lucas–Kanade window kernels: the
//! portable form's operations in its order on eight lanes a register (AVX2, two registers per
//! lane group) or sixteen (AVX-512, whose masked byte loads let windows reach the image's last
//! column), so the same bits. The callers check the CPU's features before calling.

use super::{LANES, window_inside};
use crate::image::GrayImage;

/// [`super::sample_patch`] for windows whose rows of whole 8-lane groups lie inside the image
/// (`false` otherwise, nothing written: the portable path clamps at the border): the portable
/// path's operations in its order, so the same bits, and the lanes past `size` set to zero, which
/// the portable path leaves as they are (zero: never written there).
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) fn sample_avx2(
    img: &GrayImage,
    x: f32,
    y: f32,
    size: usize,
    stride: usize,
    out: &mut [f32],
) -> bool {
    use crate::kernels::cpu::avx2::load_u8x8;
    use std::arch::x86_64::{
        __m256, _mm256_add_ps, _mm256_and_ps, _mm256_cvtepi32_ps, _mm256_mul_ps, _mm256_set1_ps,
        _mm256_sub_ps,
    };
    let span = size.div_ceil(8) * 8;
    let Some(([ix, iy], [fx, fy])) = window_inside(img, x, y, span, size) else {
        return false;
    };
    assert!(stride >= span && out.len() >= (size - 1) * stride + span);
    let (w, d) = (img.width(), img.data());
    let (vfx, vfy) = (_mm256_set1_ps(fx), _mm256_set1_ps(fy));
    // Row `r` of the image window, cells c..c + 8, interpolated along x.
    let along_x = |r: usize, c: usize| -> __m256 {
        let bytes = &d[(iy + r) * w + ix + c..][..9];
        let a = _mm256_cvtepi32_ps(load_u8x8(bytes));
        let b = _mm256_cvtepi32_ps(load_u8x8(&bytes[1..]));
        _mm256_add_ps(a, _mm256_mul_ps(vfx, _mm256_sub_ps(b, a)))
    };
    for r in 0..size {
        for c in (0..span).step_by(8) {
            let (top, bottom) = (along_x(r, c), along_x(r + 1, c));
            let v = _mm256_add_ps(top, _mm256_mul_ps(vfy, _mm256_sub_ps(bottom, top)));
            store_lanes(out, r * stride + c, _mm256_and_ps(v, first_lanes(size - c)));
        }
    }
    true
}

/// Eight f32 from `s[at..]` (unaligned).
#[target_feature(enable = "avx2,fma")]
#[inline]
fn load_lanes(s: &[f32], at: usize) -> std::arch::x86_64::__m256 {
    let lanes: &[f32; 8] = s[at..at + 8].try_into().expect("lanes");
    // SAFETY: `lanes` is eight readable f32, the width of the unaligned load.
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm256_loadu_ps(lanes.as_ptr())
    }
}

/// Eight f32 into `s[at..]` (unaligned).
#[target_feature(enable = "avx2,fma")]
#[inline]
fn store_lanes(s: &mut [f32], at: usize, v: std::arch::x86_64::__m256) {
    let lanes: &mut [f32; 8] = (&mut s[at..at + 8]).try_into().expect("lanes");
    // SAFETY: `lanes` is eight writable f32, the width of the unaligned store.
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm256_storeu_ps(lanes.as_mut_ptr(), v)
    }
}

/// [`super::reduce`] of the accumulators `acc[row parity][half]` (lanes 0–7 of a lane group in half
/// 0, 8–15 in half 1).
#[target_feature(enable = "avx2,fma")]
#[inline]
fn reduce_avx2(acc: [[std::arch::x86_64::__m256; 2]; 2]) -> f32 {
    use std::arch::x86_64::{_mm256_add_ps, _mm256_castps256_ps128, _mm256_extractf128_ps};
    let lo = _mm256_add_ps(acc[0][0], acc[1][0]);
    let hi = _mm256_add_ps(acc[0][1], acc[1][1]);
    let t8 = _mm256_add_ps(lo, hi);
    reduce_eight(_mm256_castps256_ps128(t8), _mm256_extractf128_ps::<1>(t8))
}

/// The last steps of [`super::reduce`]: lanes k + (k + 4) of the eight in `lo` (0–3) and `hi`
/// (4–7), then + 2, + 1.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn reduce_eight(lo: std::arch::x86_64::__m128, hi: std::arch::x86_64::__m128) -> f32 {
    use std::arch::x86_64::{
        _mm_add_ps, _mm_add_ss, _mm_cvtss_f32, _mm_movehdup_ps, _mm_movehl_ps,
    };
    let t4 = _mm_add_ps(lo, hi);
    let t2 = _mm_add_ps(t4, _mm_movehl_ps(t4, t4));
    _mm_cvtss_f32(_mm_add_ss(t2, _mm_movehdup_ps(t2)))
}

/// A mask of the first `count` of eight lanes (all bits set there, zero in the others; `count`
/// may exceed eight): AND-ing with it zeroes the lanes past a window's width.
#[target_feature(enable = "avx2,fma")]
#[inline]
fn first_lanes(count: usize) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::{
        _mm256_castsi256_ps, _mm256_cmpgt_epi32, _mm256_set1_epi32, _mm256_setr_epi32,
    };
    let count = count.min(8) as i32;
    let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32(count), lane))
}

/// [`super::gradients_portable`] on eight lanes per step, lanes 0–7 and 8–15 of each lane group in
/// two registers of sums: the same operations in the same order (the same bits).
#[target_feature(enable = "avx2,fma")]
pub(super) fn gradients_avx2(
    bordered: &[f32],
    bw: usize,
    n: usize,
    [patch, gx, gy]: [&mut [f32]; 3],
) -> [f32; 3] {
    use std::arch::x86_64::{
        __m256, _mm256_add_ps, _mm256_and_ps, _mm256_mul_ps, _mm256_set1_ps, _mm256_setzero_ps,
        _mm256_sub_ps,
    };
    let st = n.next_multiple_of(LANES);
    assert!(bw >= st + 2 && bordered.len() >= (n + 2) * bw);
    let half = _mm256_set1_ps(0.5);
    // Window row `r`'s cells c0..c0 + 8 stored, and `acc` plus their terms.
    let mut cells = |r: usize, c0: usize, acc: [__m256; 3]| {
        let (up, mid, down) = (r * bw, (r + 1) * bw, (r + 2) * bw);
        let inside = first_lanes(n.saturating_sub(c0));
        let m0 = load_lanes(bordered, mid + c0);
        let m2 = load_lanes(bordered, mid + c0 + 2);
        let u = load_lanes(bordered, up + c0 + 1);
        let dn = load_lanes(bordered, down + c0 + 1);
        let x = _mm256_and_ps(_mm256_mul_ps(half, _mm256_sub_ps(m2, m0)), inside);
        let y = _mm256_and_ps(_mm256_mul_ps(half, _mm256_sub_ps(dn, u)), inside);
        let k = r * st + c0;
        let centre = _mm256_and_ps(load_lanes(bordered, mid + c0 + 1), inside);
        store_lanes(patch, k, centre);
        store_lanes(gx, k, x);
        store_lanes(gy, k, y);
        [
            _mm256_add_ps(acc[0], _mm256_mul_ps(x, x)),
            _mm256_add_ps(acc[1], _mm256_mul_ps(x, y)),
            _mm256_add_ps(acc[2], _mm256_mul_ps(y, y)),
        ]
    };
    // Sums per row parity and half of the lane group, in registers (no run-time indices).
    let zero = [_mm256_setzero_ps(); 3];
    let mut row = |r: usize, [mut lo, mut hi]: [[__m256; 3]; 2]| {
        for c0 in (0..st).step_by(LANES) {
            lo = cells(r, c0, lo);
            hi = cells(r, c0 + 8, hi);
        }
        [lo, hi]
    };
    let (mut even, mut odd) = ([zero; 2], [zero; 2]);
    let mut r = 0;
    while r + 1 < n {
        even = row(r, even);
        odd = row(r + 1, odd);
        r += 2;
    }
    if r < n {
        even = row(r, even);
    }
    std::array::from_fn(|i| reduce_avx2([[even[0][i], even[1][i]], [odd[0][i], odd[1][i]]]))
}

/// [`bordered_gradients_avx512`] on AVX2: each bordered row in two registers (lanes 0–7, 8–15),
/// its cells one and two to the right by shifts across the pair; the window's rows of sixteen
/// image bytes (and one) must lie inside the image (`None` otherwise, as for `n + 2 > 16`). The
/// same bits as the portable path; lanes past the bordered row hold image values here, which only
/// lanes the mask clears read.
#[target_feature(enable = "avx2,fma")]
pub(super) fn bordered_gradients_avx2(
    img: &GrayImage,
    x: f32,
    y: f32,
    n: usize,
    st: usize,
    [patch, gx, gy]: [&mut [f32]; 3],
) -> Option<[f32; 3]> {
    use crate::kernels::cpu::avx2::load_u8x8;
    use std::arch::x86_64::{
        __m256, _mm256_add_ps, _mm256_alignr_epi8, _mm256_and_ps, _mm256_castps_si256,
        _mm256_castsi256_ps, _mm256_cvtepi32_ps, _mm256_mul_ps, _mm256_permute2f128_ps,
        _mm256_set1_ps, _mm256_setzero_ps, _mm256_sub_ps,
    };
    type Row = [__m256; 2];
    let size = n + 2;
    if size > LANES {
        return None;
    }
    let ([ix, iy], [fx, fy]) = window_inside(img, x, y, LANES, size)?;
    assert!(st.is_multiple_of(LANES) && [&*patch, &*gx, &*gy].iter().all(|b| b.len() >= n * st));
    let (w, d) = (img.width(), img.data());
    let (vfx, vfy, half) = (_mm256_set1_ps(fx), _mm256_set1_ps(fy), _mm256_set1_ps(0.5));
    let inside = [first_lanes(n), first_lanes(n.saturating_sub(8))];
    let along_x = |r: usize| -> Row {
        let bytes = &d[(iy + r) * w + ix..][..LANES + 1];
        std::array::from_fn(|h| {
            let a = _mm256_cvtepi32_ps(load_u8x8(&bytes[8 * h..]));
            let b = _mm256_cvtepi32_ps(load_u8x8(&bytes[8 * h + 1..]));
            _mm256_add_ps(a, _mm256_mul_ps(vfx, _mm256_sub_ps(b, a)))
        })
    };
    let bordered = |r: usize, top: Row| -> (Row, Row) {
        let bottom = along_x(r + 1);
        let row = std::array::from_fn(|h| {
            _mm256_add_ps(top[h], _mm256_mul_ps(vfy, _mm256_sub_ps(bottom[h], top[h])))
        });
        (row, bottom)
    };
    // The pair's lanes moved down by one (two): lane k holds cell k + 1 (k + 2), zero past the
    // pair. `permute2f128` brings the next 128-bit half alongside, `alignr` shifts within each.
    let next1 = |v: Row| -> Row {
        let (a, b) = (_mm256_castps_si256(v[0]), _mm256_castps_si256(v[1]));
        let t = _mm256_castps_si256(_mm256_permute2f128_ps::<0x21>(v[0], v[1]));
        let u = _mm256_castps_si256(_mm256_permute2f128_ps::<0x81>(v[1], v[1]));
        [
            _mm256_castsi256_ps(_mm256_alignr_epi8::<4>(t, a)),
            _mm256_castsi256_ps(_mm256_alignr_epi8::<4>(u, b)),
        ]
    };
    let next2 = |v: Row| -> Row {
        let (a, b) = (_mm256_castps_si256(v[0]), _mm256_castps_si256(v[1]));
        let t = _mm256_castps_si256(_mm256_permute2f128_ps::<0x21>(v[0], v[1]));
        let u = _mm256_castps_si256(_mm256_permute2f128_ps::<0x81>(v[1], v[1]));
        [
            _mm256_castsi256_ps(_mm256_alignr_epi8::<8>(t, a)),
            _mm256_castsi256_ps(_mm256_alignr_epi8::<8>(u, b)),
        ]
    };
    // Window row `r` from bordered rows up, mid, down: stored, and `acc[half]` plus its terms.
    let mut row = |r: usize, [up, mid, down]: [Row; 3], acc: [[__m256; 3]; 2]| {
        let (centre, right, up1, down1) = (next1(mid), next2(mid), next1(up), next1(down));
        std::array::from_fn(|h| {
            let x = _mm256_and_ps(
                _mm256_mul_ps(half, _mm256_sub_ps(right[h], mid[h])),
                inside[h],
            );
            let y = _mm256_and_ps(
                _mm256_mul_ps(half, _mm256_sub_ps(down1[h], up1[h])),
                inside[h],
            );
            let k = r * st + 8 * h;
            store_lanes(patch, k, _mm256_and_ps(centre[h], inside[h]));
            store_lanes(gx, k, x);
            store_lanes(gy, k, y);
            [
                _mm256_add_ps(acc[h][0], _mm256_mul_ps(x, x)),
                _mm256_add_ps(acc[h][1], _mm256_mul_ps(x, y)),
                _mm256_add_ps(acc[h][2], _mm256_mul_ps(y, y)),
            ]
        })
    };
    let (even, odd) = walk_bordered_rows!(n, along_x, bordered, row, [[_mm256_setzero_ps(); 3]; 2]);
    Some(std::array::from_fn(|i| {
        reduce_avx2([[even[0][i], even[1][i]], [odd[0][i], odd[1][i]]])
    }))
}

/// [`super::mismatch_portable`] with its sampling, where the window's rows of whole 8-lane groups
/// lie inside the image (`None` otherwise): each row of the next image's window is interpolated
/// along x once and used by the two window rows it lies between, and the sums are taken in the
/// same pass, the portable path's operations in its order (the same bits).
#[target_feature(enable = "avx2,fma")]
pub(super) fn mismatch_avx2(
    img: &GrayImage,
    x: f32,
    y: f32,
    n: usize,
    st: usize,
    [patch, gx, gy]: [&[f32]; 3],
) -> Option<[f32; 3]> {
    use crate::kernels::cpu::avx2::load_u8x8;
    use std::arch::x86_64::{
        __m256, _mm256_add_ps, _mm256_and_ps, _mm256_castsi256_ps, _mm256_cvtepi32_ps,
        _mm256_mul_ps, _mm256_set1_epi32, _mm256_set1_ps, _mm256_setzero_ps, _mm256_sub_ps,
    };
    let ([ix, iy], [fx, fy]) = window_inside(img, x, y, st, n)?;
    assert!(st.is_multiple_of(LANES) && [patch, gx, gy].iter().all(|b| b.len() >= n * st));
    let (w, d) = (img.width(), img.data());
    let (vfx, vfy) = (_mm256_set1_ps(fx), _mm256_set1_ps(fy));
    let abs = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff));
    // Sums [half][term] of even and odd rows. Written as macros, not closures: the compiler kept
    // nested closures out of line here and passed their registers through memory.
    let zero = [[_mm256_setzero_ps(); 3]; 2];
    let (mut even, mut odd) = (zero, zero);
    for c in (0..st).step_by(LANES) {
        let inside = [
            first_lanes(n.saturating_sub(c)),
            first_lanes(n.saturating_sub(c + 8)),
        ];
        // Image row `r`, cells c..c + 16 along x, zero past the window (as the portable path's
        // `moving`).
        macro_rules! along_x {
            ($r:expr) => {{
                let bytes = &d[(iy + $r) * w + ix + c..][..LANES + 1];
                let mut v = [_mm256_setzero_ps(); 2];
                for h in 0..2 {
                    let a = _mm256_cvtepi32_ps(load_u8x8(&bytes[8 * h..]));
                    let b = _mm256_cvtepi32_ps(load_u8x8(&bytes[8 * h + 1..]));
                    let lerp = _mm256_add_ps(a, _mm256_mul_ps(vfx, _mm256_sub_ps(b, a)));
                    v[h] = _mm256_and_ps(lerp, inside[h]);
                }
                v
            }};
        }
        // Window row `r` from image rows `top` and r + 1 into `acc`; `top` becomes row r + 1.
        macro_rules! row {
            ($r:expr, $top:ident, $acc:ident) => {{
                let bottom: [__m256; 2] = along_x!($r + 1);
                for h in 0..2 {
                    let moving = _mm256_add_ps(
                        $top[h],
                        _mm256_mul_ps(vfy, _mm256_sub_ps(bottom[h], $top[h])),
                    );
                    let k = $r * st + c + 8 * h;
                    let diff = _mm256_sub_ps(load_lanes(patch, k), moving);
                    $acc[h][0] = _mm256_add_ps($acc[h][0], _mm256_mul_ps(diff, load_lanes(gx, k)));
                    $acc[h][1] = _mm256_add_ps($acc[h][1], _mm256_mul_ps(diff, load_lanes(gy, k)));
                    $acc[h][2] = _mm256_add_ps($acc[h][2], _mm256_and_ps(diff, abs));
                }
                $top = bottom;
            }};
        }
        let mut top: [__m256; 2] = along_x!(0);
        let mut r = 0;
        while r + 1 < n {
            row!(r, top, even);
            row!(r + 1, top, odd);
            r += 2;
        }
        if r < n {
            row!(r, top, even);
        }
        let _ = top;
    }
    Some(std::array::from_fn(|i| {
        reduce_avx2([[even[0][i], even[1][i]], [odd[0][i], odd[1][i]]])
    }))
}

/// The bytes `row[at..at + count]` (`count ≤ 16`) as f32 in the first `count` of sixteen lanes,
/// zero in the others; reads no byte past them.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
#[inline]
fn load_u8x16_first(row: &[u8], at: usize, count: usize) -> std::arch::x86_64::__m512 {
    use std::arch::x86_64::{_mm_maskz_loadu_epi8, _mm512_cvtepi32_ps, _mm512_cvtepu8_epi32};
    assert!(count <= 16 && at + count <= row.len());
    let mask = ((1u32 << count) - 1) as u16;
    // SAFETY: the mask's lanes read `row[at..at + count]`, inside `row`; masked-off lanes read
    // nothing and do not fault.
    #[allow(unsafe_code)]
    let bytes = unsafe { _mm_maskz_loadu_epi8(mask, row.as_ptr().add(at).cast()) };
    _mm512_cvtepi32_ps(_mm512_cvtepu8_epi32(bytes))
}

/// Sixteen f32 from `s[at..]` (unaligned).
#[target_feature(enable = "avx512f,avx2,fma")]
#[inline]
fn load16(s: &[f32], at: usize) -> std::arch::x86_64::__m512 {
    let lanes: &[f32; 16] = s[at..at + 16].try_into().expect("lanes");
    // SAFETY: `lanes` is sixteen readable f32, the width of the unaligned load.
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm512_loadu_ps(lanes.as_ptr())
    }
}

/// Sixteen f32 into `s[at..]` (unaligned).
#[target_feature(enable = "avx512f,avx2,fma")]
#[inline]
fn store16(s: &mut [f32], at: usize, v: std::arch::x86_64::__m512) {
    let lanes: &mut [f32; 16] = (&mut s[at..at + 16]).try_into().expect("lanes");
    // SAFETY: `lanes` is sixteen writable f32, the width of the unaligned store.
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm512_storeu_ps(lanes.as_mut_ptr(), v)
    }
}

/// [`super::reduce`] of the accumulators of even and odd rows.
#[target_feature(enable = "avx512f,avx2,fma")]
#[inline]
fn reduce_avx512(acc: [std::arch::x86_64::__m512; 2]) -> f32 {
    use std::arch::x86_64::{
        _mm256_add_ps, _mm256_castpd_ps, _mm256_castps256_ps128, _mm256_extractf128_ps,
        _mm512_add_ps, _mm512_castps_pd, _mm512_castps512_ps256, _mm512_extractf64x4_pd,
    };
    let v = _mm512_add_ps(acc[0], acc[1]);
    let hi = _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(v)));
    let t8 = _mm256_add_ps(_mm512_castps512_ps256(v), hi);
    reduce_eight(_mm256_castps256_ps128(t8), _mm256_extractf128_ps::<1>(t8))
}

/// The bordered window's sampling and [`super::gradients_portable`] in one pass, for windows whose
/// bordered rows fit one register (`n + 2 ≤ 16`) and lie inside the image (`None` otherwise):
/// each bordered row is interpolated in a register and its cells one and two to the right come
/// from lane shifts, the same values as the portable path reads from `bordered` (the same bits).
/// Why registers: reading the stored rows back at those offsets made every load straddle two
/// recent stores, which the CPU cannot forward, so each load waited for them to reach the cache.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
pub(super) fn bordered_gradients_avx512(
    img: &GrayImage,
    x: f32,
    y: f32,
    n: usize,
    st: usize,
    [patch, gx, gy]: [&mut [f32]; 3],
) -> Option<[f32; 3]> {
    use std::arch::x86_64::{
        __m512, _mm512_add_ps, _mm512_alignr_epi32, _mm512_castps_si512, _mm512_castsi512_ps,
        _mm512_maskz_mov_ps, _mm512_maskz_mul_ps, _mm512_mul_ps, _mm512_set1_ps, _mm512_setzero_ps,
        _mm512_setzero_si512, _mm512_sub_ps,
    };
    let size = n + 2;
    if size > LANES {
        return None;
    }
    let ([ix, iy], [fx, fy]) = window_inside(img, x, y, size, size)?;
    assert!(st.is_multiple_of(LANES) && [&*patch, &*gx, &*gy].iter().all(|b| b.len() >= n * st));
    let (w, d) = (img.width(), img.data());
    let (vfx, vfy, half) = (_mm512_set1_ps(fx), _mm512_set1_ps(fy), _mm512_set1_ps(0.5));
    let inside = ((1u32 << n) - 1) as u16;
    let along_x = |r: usize| {
        let row = &d[(iy + r) * w + ix..][..size + 1];
        let a = load_u8x16_first(row, 0, size);
        let b = load_u8x16_first(row, 1, size);
        _mm512_add_ps(a, _mm512_mul_ps(vfx, _mm512_sub_ps(b, a)))
    };
    // Bordered row `r` from image rows r (along x: `top`) and r + 1; returns it and row r + 1.
    let bordered = |r: usize, top: __m512| {
        let bottom = along_x(r + 1);
        (
            _mm512_add_ps(top, _mm512_mul_ps(vfy, _mm512_sub_ps(bottom, top))),
            bottom,
        )
    };
    // Lanes moved down by one (two): lane k holds cell k + 1 (k + 2), zero past the register.
    let next1 = |v: __m512| {
        let v = _mm512_castps_si512(v);
        _mm512_castsi512_ps(_mm512_alignr_epi32::<1>(_mm512_setzero_si512(), v))
    };
    let next2 = |v: __m512| {
        let v = _mm512_castps_si512(v);
        _mm512_castsi512_ps(_mm512_alignr_epi32::<2>(_mm512_setzero_si512(), v))
    };
    // Window row `r` between bordered rows `up`, `mid` and `down`: stored, and `acc` plus its
    // terms.
    let mut row = |r: usize, [up, mid, down]: [__m512; 3], acc: [__m512; 3]| {
        let x = _mm512_maskz_mul_ps(inside, half, _mm512_sub_ps(next2(mid), mid));
        let y = _mm512_maskz_mul_ps(inside, half, _mm512_sub_ps(next1(down), next1(up)));
        let k = r * st;
        store16(patch, k, _mm512_maskz_mov_ps(inside, next1(mid)));
        store16(gx, k, x);
        store16(gy, k, y);
        [
            _mm512_add_ps(acc[0], _mm512_mul_ps(x, x)),
            _mm512_add_ps(acc[1], _mm512_mul_ps(x, y)),
            _mm512_add_ps(acc[2], _mm512_mul_ps(y, y)),
        ]
    };
    let (even, odd) = walk_bordered_rows!(n, along_x, bordered, row, [_mm512_setzero_ps(); 3]);
    Some(std::array::from_fn(|i| reduce_avx512([even[i], odd[i]])))
}

/// [`super::mismatch_portable`] with its sampling, for windows inside the image (`None`
/// otherwise), sixteen lanes per step with the window's edge by masked loads; like
/// [`mismatch_avx2`] it interpolates each image row along x once and sums in the same pass (the
/// same bits).
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
pub(super) fn mismatch_avx512(
    img: &GrayImage,
    x: f32,
    y: f32,
    n: usize,
    st: usize,
    [patch, gx, gy]: [&[f32]; 3],
) -> Option<[f32; 3]> {
    use std::arch::x86_64::{
        __m512, _mm512_abs_ps, _mm512_add_ps, _mm512_mul_ps, _mm512_set1_ps, _mm512_setzero_ps,
        _mm512_sub_ps,
    };
    let ([ix, iy], [fx, fy]) = window_inside(img, x, y, n, n)?;
    assert!(st.is_multiple_of(LANES) && [patch, gx, gy].iter().all(|b| b.len() >= n * st));
    let (w, d) = (img.width(), img.data());
    let (vfx, vfy) = (_mm512_set1_ps(fx), _mm512_set1_ps(fy));
    // Sums of even and odd window rows, in registers: rows go in pairs so no sum is indexed by
    // a run-time parity.
    let (mut even, mut odd) = ([_mm512_setzero_ps(); 3], [_mm512_setzero_ps(); 3]);
    for c in (0..st).step_by(LANES) {
        let count = (n - c).min(16);
        let along_x = |r: usize| {
            let row = &d[(iy + r) * w + ix + c..][..count + 1];
            let a = load_u8x16_first(row, 0, count);
            let b = load_u8x16_first(row, 1, count);
            _mm512_add_ps(a, _mm512_mul_ps(vfx, _mm512_sub_ps(b, a)))
        };
        // Window row `r` between image rows `top` and r + 1: that row, and `acc` plus its terms.
        let row = |r: usize, top: __m512, acc: [__m512; 3]| {
            let bottom = along_x(r + 1);
            let moving = _mm512_add_ps(top, _mm512_mul_ps(vfy, _mm512_sub_ps(bottom, top)));
            let k = r * st + c;
            let diff = _mm512_sub_ps(load16(patch, k), moving);
            let acc = [
                _mm512_add_ps(acc[0], _mm512_mul_ps(diff, load16(gx, k))),
                _mm512_add_ps(acc[1], _mm512_mul_ps(diff, load16(gy, k))),
                _mm512_add_ps(acc[2], _mm512_abs_ps(diff)),
            ];
            (bottom, acc)
        };
        let mut top = along_x(0);
        let mut r = 0;
        while r + 1 < n {
            (top, even) = row(r, top, even);
            (top, odd) = row(r + 1, top, odd);
            r += 2;
        }
        if r < n {
            (_, even) = row(r, top, even);
        }
    }
    Some(std::array::from_fn(|i| reduce_avx512([even[i], odd[i]])))
}
