//! [`super::int8_product`] on AVX-512 VNNI.

/// [`int8_product`]'s body.
///
/// # Safety
/// The CPU has AVX-512F, BW and VNNI.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
#[allow(unsafe_code)]
pub(crate) fn int8_product_avx512(
    x: &[f32],
    quads: &[u32],
    scale: &[f32],
    bias: &[f32],
    relu: bool,
    quantised: &mut [u32],
    out: &mut [f32],
) -> bool {
    use std::arch::x86_64::*;
    let (np, kq) = (bias.len(), x.len().div_ceil(4));
    assert!(
        np.is_multiple_of(2 * LANES)
            && scale.len() == np
            && quads.len() == kq * np
            && quantised.len() >= 2 * kq
            && out.len() <= np
    );
    let Some(max) = crate::kernels::conv3x3::nonnegative_max(x) else {
        return false;
    };
    let per_step = if max > 0.0 { 65535.0 / max } else { 0.0 };
    let step = _mm512_set1_ps(max / 65535.0);
    // Bytes of `x`'s digits in order are the words' bytes in order (little-endian), zero past `x`.
    let (high, low) = quantised[..2 * kq].split_at_mut(kq);
    for digits in [&mut *high, &mut *low] {
        if let Some(last) = digits.last_mut() {
            *last = 0;
        }
    }
    let (hi, lo) = (
        high.as_mut_ptr().cast::<u8>(),
        low.as_mut_ptr().cast::<u8>(),
    );
    let (f, top, byte) = (
        _mm512_set1_ps(per_step),
        _mm512_set1_epi32(65535),
        _mm512_set1_epi32(255),
    );
    let mut i = 0;
    while i < x.len() {
        let mask = (1u32 << (x.len() - i).min(LANES)).wrapping_sub(1) as u16;
        // SAFETY: the mask's lanes are positions below `x.len() <= 4·kq`: inside `x` and both
        // digit arrays.
        unsafe {
            let v = _mm512_maskz_loadu_ps(mask, x.as_ptr().add(i));
            let q = _mm512_min_epi32(_mm512_cvtps_epi32(_mm512_mul_ps(v, f)), top);
            _mm512_mask_cvtepi32_storeu_epi8(hi.add(i).cast(), mask, _mm512_srli_epi32::<8>(q));
            _mm512_mask_cvtepi32_storeu_epi8(lo.add(i).cast(), mask, _mm512_and_si512(q, byte));
        }
        i += LANES;
    }
    let (high, low) = (&*high, &*low);
    let mut o = 0;
    while o < np {
        if np - o >= 4 * LANES {
            // SAFETY: columns o..o + 64 exist (`np` is checked above).
            unsafe { int8_columns::<4>([high, low], quads, np, o, step, scale, bias, relu, out) };
            o += 4 * LANES;
        } else {
            // SAFETY: `np - o` is a positive multiple of 32 (asserted above).
            unsafe { int8_columns::<2>([high, low], quads, np, o, step, scale, bias, relu, out) };
            o += 2 * LANES;
        }
    }
    true
}

/// f32 lanes of a 512-bit register.
const LANES: usize = 16;

/// Columns `o..o + 16·NJ` of [`int8_product`]: a sum per register and digit, the two chains
/// independent (each waits on its own latency).
///
/// # Safety
/// AVX-512F, BW and VNNI; `o + 16·NJ <= np`, `quads` holds `kq × np` words for the `kq` words of
/// each digit and `scale` and `bias` `np` values.
#[target_feature(enable = "avx512f,avx512bw,avx512vnni")]
#[allow(unsafe_code, clippy::too_many_arguments)]
unsafe fn int8_columns<const NJ: usize>(
    [high, low]: [&[u32]; 2],
    quads: &[u32],
    np: usize,
    o: usize,
    step: std::arch::x86_64::__m512,
    scale: &[f32],
    bias: &[f32],
    relu: bool,
    out: &mut [f32],
) {
    use std::arch::x86_64::*;
    let w = quads.as_ptr();
    let (mut hs, mut ls) = ([_mm512_setzero_si512(); NJ], [_mm512_setzero_si512(); NJ]);
    for (r, (&h, &l)) in high.iter().zip(low).enumerate() {
        let (h, l) = (_mm512_set1_epi32(h as i32), _mm512_set1_epi32(l as i32));
        for j in 0..NJ {
            // SAFETY: word r's columns o + 16j.. lie inside `quads` (the contract).
            let wt = unsafe { _mm512_loadu_si512(w.add(r * np + o + j * LANES).cast()) };
            hs[j] = _mm512_dpbusd_epi32(hs[j], h, wt);
            ls[j] = _mm512_dpbusd_epi32(ls[j], l, wt);
        }
    }
    let radix = _mm512_set1_ps(256.0);
    for j in 0..NJ {
        let c = o + j * LANES;
        if c >= out.len() {
            break;
        }
        // SAFETY: columns c..c + 16 lie inside `scale` and `bias` (the contract).
        let (s, b) = unsafe {
            (
                _mm512_loadu_ps(scale.as_ptr().add(c)),
                _mm512_loadu_ps(bias.as_ptr().add(c)),
            )
        };
        // Each digit's sum is at most 255 · 127 · k: exact in i32; joined in f32.
        let sum = _mm512_fmadd_ps(_mm512_cvtepi32_ps(hs[j]), radix, _mm512_cvtepi32_ps(ls[j]));
        let mut v = _mm512_fmadd_ps(sum, _mm512_mul_ps(s, step), b);
        if relu {
            v = _mm512_max_ps(v, _mm512_setzero_ps());
        }
        let n = (out.len() - c).min(LANES);
        // SAFETY: the mask writes the first n lanes, all inside `out`.
        unsafe { _mm512_mask_storeu_ps(out.as_mut_ptr().add(c), ((1u32 << n) - 1) as u16, v) };
    }
}
