//! Patch filters of `models/M3_IO.md`, with OpenCV's semantics on 8-bit gray images (the training
//! side calls OpenCV): [`Bilateral`] (`cv::bilateralFilter`, BORDER_REFLECT_101) and
//! [`equalize_hist`] (`cv::equalizeHist`).
//!
//! Bit-exactness: the equalisation is exact. The bilateral filter uses OpenCV's weight formulas,
//! float32 sums and truncation to u8 (what the installed OpenCV 5 does); OpenCV's vectorised
//! kernels sum in another order (with fused multiply-adds) and approximate `exp` for the colour
//! table, so a result within float rounding of an integer may land one level off: ±1 on about 3 %
//! of the pixels (measured and checked by the golden tests of `tests/data/m3_preproc/`).

/// `cv::bilateralFilter(src, dst, d, sigma_color, sigma_space, BORDER_REFLECT_101)` for 8-bit
/// gray images, with its tables precomputed and its padded buffer reused.
#[derive(Debug, Clone)]
pub struct Bilateral {
    radius: usize,
    /// Whether OpenCV would copy the input unchanged (a sigma ≤ 1e-6).
    identity: bool,
    color_weight: [f32; 256],
    /// Kernel taps (dy, dx) inside the disc of radius `radius`, row by row as OpenCV lists them.
    taps: Vec<(isize, isize)>,
    space_weight: Vec<f32>,
    padded: Vec<u8>,
    /// `taps` as offsets into `padded` rows of `offsets_width` bytes.
    offsets: Vec<isize>,
    offsets_width: usize,
    /// One output row's running weighted sums and weight sums.
    row_sum: Vec<f32>,
    row_wsum: Vec<f32>,
}

/// OpenCV copies the input when a sigma is at or below this (bilateral_filter.dispatch.cpp).
const SIGMA_EPS: f64 = 1e-6;

impl Bilateral {
    /// Tables for diameter `d` (≤ 0: derived from `sigma_space` as OpenCV does) and the two sigmas.
    pub fn new(d: i32, sigma_color: f64, sigma_space: f64) -> Self {
        let identity = !(sigma_color > SIGMA_EPS && sigma_space > SIGMA_EPS);
        // OpenCV computes both coefficients in float32.
        let gc = (-0.5 / (sigma_color * sigma_color)) as f32;
        let gs = (-0.5 / (sigma_space * sigma_space)) as f32;
        let radius = if d <= 0 {
            (sigma_space * 1.5).round_ties_even().max(1.0) as usize
        } else {
            (d / 2).max(1) as usize
        };
        let mut color_weight = [0f32; 256];
        for (i, w) in color_weight.iter_mut().enumerate() {
            // int·float in float, then float exp, as OpenCV's scalar table loop.
            *w = ((i * i) as f32 * gc).exp();
        }
        let r = radius as isize;
        let mut taps = Vec::new();
        let mut space_weight = Vec::new();
        for i in -r..=r {
            for j in -r..=r {
                let dist = ((i * i + j * j) as f64).sqrt();
                if dist > radius as f64 {
                    continue;
                }
                space_weight.push((dist * dist * f64::from(gs)).exp() as f32);
                taps.push((i, j));
            }
        }
        Self {
            radius,
            identity,
            color_weight,
            taps,
            space_weight,
            padded: Vec::new(),
            offsets: Vec::new(),
            offsets_width: 0,
            row_sum: Vec::new(),
            row_wsum: Vec::new(),
        }
    }

    /// Filters the `width`×`height` image `src` into `dst` (both row-major, `width·height` long).
    /// Panics if the slices are shorter than `width·height` (callers own both sizes).
    pub fn apply(&mut self, src: &[u8], width: usize, height: usize, dst: &mut [u8]) {
        let n = width * height;
        if self.identity || n == 0 {
            dst[..n].copy_from_slice(&src[..n]);
            return;
        }
        self.pad(src, width, height);
        #[cfg(target_arch = "x86_64")]
        if crate::kernels::cpu::has_avx2_fma() {
            #[allow(unsafe_code)]
            // SAFETY: the CPU has the features each function is compiled for.
            unsafe {
                if crate::nn::conv::Products::Avx512.supported() {
                    self.filter_avx512(width, height, dst)
                } else {
                    self.filter_avx2(width, height, dst)
                }
            };
            return;
        }
        self.filter_rows(width, height, dst);
    }

    /// Fills `padded` (BORDER_REFLECT_101) and, for a new row length, `offsets`.
    fn pad(&mut self, src: &[u8], width: usize, height: usize) {
        let r = self.radius;
        let pw = width + 2 * r;
        let ph = height + 2 * r;
        self.padded.resize(pw * ph, 0);
        for py in 0..ph {
            let sy = reflect101(py as isize - r as isize, height);
            let srow = &src[sy * width..(sy + 1) * width];
            let prow = &mut self.padded[py * pw..(py + 1) * pw];
            prow[r..r + width].copy_from_slice(srow);
            for px in (0..r).chain(r + width..pw) {
                prow[px] = srow[reflect101(px as isize - r as isize, width)];
            }
        }
        if self.offsets_width != pw {
            self.offsets.clear();
            self.offsets
                .extend(self.taps.iter().map(|&(dy, dx)| dy * pw as isize + dx));
            self.offsets_width = pw;
        }
    }

    /// The filter over `padded`, portable: tap by tap over each output row.
    fn filter_rows(&mut self, width: usize, height: usize, dst: &mut [u8]) {
        let r = self.radius;
        let pw = width + 2 * r;
        let cw = &self.color_weight;
        self.row_sum.resize(width, 0.0);
        self.row_wsum.resize(width, 0.0);
        for y in 0..height {
            // Tap by tap over the whole row: each pixel still sums its taps in OpenCV's order (so
            // the result is the same to the bit), but the pixels' sums are independent chains the
            // CPU overlaps, where one pixel's 25 dependent additions serialised before.
            self.row_sum.fill(0.0);
            self.row_wsum.fill(0.0);
            let c0 = (y + r) * pw + r;
            let centre = &self.padded[c0..c0 + width];
            for (&o, &sw) in self.offsets.iter().zip(&self.space_weight) {
                let start = (c0 as isize + o) as usize;
                let taps = &self.padded[start..start + width];
                for (((&v, &v0), sum), wsum) in taps
                    .iter()
                    .zip(centre)
                    .zip(self.row_sum.iter_mut())
                    .zip(self.row_wsum.iter_mut())
                {
                    let w = sw * cw[usize::from(v.abs_diff(v0))];
                    *wsum += w;
                    *sum += f32::from(v) * w;
                }
            }
            for ((d, &sum), &wsum) in dst[y * width..(y + 1) * width]
                .iter_mut()
                .zip(&self.row_sum)
                .zip(&self.row_wsum)
            {
                *d = quantize(sum, wsum);
            }
        }
    }

    /// [`Bilateral::filter_rows`] eight pixels at a time in AVX2 registers: the colour weights
    /// come from one hardware gather per tap, the sums stay in registers over the taps, each pixel
    /// adds its taps in the same order with the same operations (the same bytes; unit test). The
    /// portable loop's table lookups were scalar loads: `bilateral_64x32_d5` 14.3 / 13.9 → 7.4 /
    /// 7.1 µs, `m3_per_face` 656 / 639 → 623 / 635 µs (two alternating runs each, Intel Xeon).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn filter_avx2(&self, width: usize, height: usize, dst: &mut [u8]) {
        let r = self.radius;
        let pw = width + 2 * r;
        for y in 0..height {
            let c0 = (y + r) * pw + r;
            let out = &mut dst[y * width..(y + 1) * width];
            let mut x = 0;
            while x + 8 <= width {
                self.block8(c0 + x, &mut out[x..x + 8]);
                x += 8;
            }
            for (x, d) in out.iter_mut().enumerate().skip(x) {
                *d = self.pixel(c0 + x);
            }
        }
    }

    /// Eight output pixels centred at `padded[c..c + 8]` (see [`Bilateral::filter_avx2`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    fn block8(&self, c: usize, out: &mut [u8]) {
        use crate::kernels::cpu::avx2::{load_u8x8 as load8, store_u8x8};
        use std::arch::x86_64::{
            _mm256_abs_epi32, _mm256_add_ps, _mm256_cvtepi32_ps, _mm256_cvttps_epi32,
            _mm256_div_ps, _mm256_i32gather_ps, _mm256_max_ps, _mm256_min_ps, _mm256_mul_ps,
            _mm256_set1_ps, _mm256_setzero_ps, _mm256_sub_epi32,
        };
        let table = self.color_weight.as_ptr();
        let (zero, top) = (_mm256_setzero_ps(), _mm256_set1_ps(255.0));
        let v0 = load8(&self.padded[c..]);
        let (mut sum, mut wsum) = (zero, zero);
        for (&o, &sw) in self.offsets.iter().zip(&self.space_weight) {
            let v = load8(&self.padded[(c as isize + o) as usize..]);
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

    /// [`Bilateral::filter_avx2`] sixteen pixels at a time in 512-bit registers (one 16-lane
    /// gather per tap), then eight, then single pixels: each pixel's operations in the same order,
    /// so the same bytes (unit test).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,fma")]
    fn filter_avx512(&self, width: usize, height: usize, dst: &mut [u8]) {
        use std::arch::x86_64::{
            __m128i, _mm_loadu_si128, _mm_storeu_si128, _mm512_abs_epi32, _mm512_add_ps,
            _mm512_cvtepi32_epi8, _mm512_cvtepi32_ps, _mm512_cvtepu8_epi32, _mm512_cvttps_epi32,
            _mm512_div_ps, _mm512_i32gather_ps, _mm512_max_ps, _mm512_min_ps, _mm512_mul_ps,
            _mm512_set1_ps, _mm512_setzero_ps, _mm512_sub_epi32,
        };
        let r = self.radius;
        let pw = width + 2 * r;
        let table = self.color_weight.as_ptr();
        let (zero, top) = (_mm512_setzero_ps(), _mm512_set1_ps(255.0));
        let load16 = |at: usize| {
            let bytes: &[u8; 16] = self.padded[at..at + 16].try_into().expect("16 bytes");
            #[allow(unsafe_code)]
            // SAFETY: `bytes` holds the sixteen bytes read (unaligned loads are allowed).
            _mm512_cvtepu8_epi32(unsafe { _mm_loadu_si128(bytes.as_ptr().cast::<__m128i>()) })
        };
        for y in 0..height {
            let c0 = (y + r) * pw + r;
            let out = &mut dst[y * width..(y + 1) * width];
            let mut x = 0;
            while x + 16 <= width {
                let c = c0 + x;
                let v0 = load16(c);
                let (mut sum, mut wsum) = (zero, zero);
                for (&o, &sw) in self.offsets.iter().zip(&self.space_weight) {
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
                self.block8(c0 + x, &mut out[x..x + 8]);
                x += 8;
            }
            for (x, d) in out.iter_mut().enumerate().skip(x) {
                *d = self.pixel(c0 + x);
            }
        }
    }
}

impl Bilateral {
    /// One output pixel, centred at `c` in `padded`, in OpenCV's loop order: the definition the
    /// vectorised paths reproduce to the bit (unit test), and the AVX2 path's row tail.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    fn pixel(&self, c: usize) -> u8 {
        let v0 = self.padded[c];
        let (mut sum, mut wsum) = (0f32, 0f32);
        for (&o, &sw) in self.offsets.iter().zip(&self.space_weight) {
            let v = self.padded[(c as isize + o) as usize];
            let w = sw * self.color_weight[usize::from(v.abs_diff(v0))];
            wsum += w;
            sum += f32::from(v) * w;
        }
        quantize(sum, wsum)
    }
}

/// A pixel's weighted mean to u8. The OpenCV 5 build the training uses truncates here (measured
/// against it by tests/data/m3_preproc: rounding put 46 % of the pixels one level off,
/// truncation 3 %).
#[inline(always)]
fn quantize(sum: f32, wsum: f32) -> u8 {
    (sum / wsum).clamp(0.0, 255.0) as u8
}

/// OpenCV's BORDER_REFLECT_101 index (`gfedcb|abcdefgh|gfedcba`), for any offset.
fn reflect101(mut p: isize, len: usize) -> usize {
    let n = len as isize;
    if n == 1 {
        return 0;
    }
    while p < 0 || p >= n {
        p = if p < 0 { -p } else { 2 * n - 2 - p };
    }
    p as usize
}

/// `cv::equalizeHist` in place: the cumulative-histogram LUT scaled by 255 / (N − count of the
/// darkest level), computed in float32 and rounded half to even, as OpenCV does.
pub fn equalize_hist(buf: &mut [u8]) {
    let mut hist = [0u32; 256];
    for &v in buf.iter() {
        hist[usize::from(v)] += 1;
    }
    let total = buf.len() as u32;
    let Some(first) = hist.iter().position(|&c| c > 0) else {
        return;
    };
    if hist[first] == total {
        buf.fill(first as u8);
        return;
    }
    let scale = 255.0f32 / (total - hist[first]) as f32;
    let mut lut = [0u8; 256];
    let mut sum = 0u32;
    for i in first + 1..256 {
        sum += hist[i];
        lut[i] = (sum as f32 * scale).round_ties_even().clamp(0.0, 255.0) as u8;
    }
    for v in buf.iter_mut() {
        *v = lut[usize::from(*v)];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect101_matches_opencv() {
        // OpenCV: borderInterpolate(-1, 5, BORDER_REFLECT_101) == 1, (5, 5) == 3, (-2, 5) == 2.
        assert_eq!(reflect101(-1, 5), 1);
        assert_eq!(reflect101(-2, 5), 2);
        assert_eq!(reflect101(5, 5), 3);
        assert_eq!(reflect101(6, 5), 2);
        assert_eq!(reflect101(3, 1), 0);
    }

    #[test]
    fn bilateral_keeps_flat_images_and_disc_has_13_taps() {
        let mut f = Bilateral::new(5, 20.0, 3.0);
        assert_eq!(f.taps.len(), 13);
        let src = vec![77u8; 12 * 7];
        let mut dst = vec![0u8; 12 * 7];
        f.apply(&src, 12, 7, &mut dst);
        assert_eq!(src, dst);
    }

    #[test]
    fn bilateral_smooths_noise_but_keeps_a_strong_edge() {
        let (w, h) = (16, 8);
        let src: Vec<u8> = (0..w * h)
            .map(|i| {
                let base = if i % w < 8 { 40 } else { 200 };
                base + ((i * 7) % 5) as u8
            })
            .collect();
        let mut dst = vec![0u8; w * h];
        Bilateral::new(5, 20.0, 3.0).apply(&src, w, h, &mut dst);
        for (i, &v) in dst.iter().enumerate() {
            let base = if i % w < 8 { 40 } else { 200 };
            assert!((i32::from(v) - base - 2).abs() <= 2, "pixel {i}: {v}");
        }
    }

    /// The filter pixel by pixel ([`Bilateral::pixel`], OpenCV's loop order), for the exactness
    /// check below.
    fn bilateral_per_pixel(f: &mut Bilateral, src: &[u8], width: usize, height: usize) -> Vec<u8> {
        let mut scratch = vec![0u8; width * height];
        f.apply(src, width, height, &mut scratch); // fills f.padded / f.offsets for this size
        let (r, pw) = (f.radius, width + 2 * f.radius);
        let mut dst = vec![0u8; width * height];
        for y in 0..height {
            for x in 0..width {
                dst[y * width + x] = f.pixel((y + r) * pw + x + r);
            }
        }
        dst
    }

    /// On a CPU with AVX2 `apply` runs its gather path, so this holds that path to the per-pixel
    /// loop's bytes (widths with and without a tail of fewer than eight pixels); elsewhere it
    /// checks the portable row loop.
    #[test]
    fn row_order_bilateral_equals_the_per_pixel_loop_to_the_bit() {
        let mut f = Bilateral::new(5, 20.0, 3.0);
        let mut state = 12345u32;
        for (w, h) in [
            (64, 32),
            (48, 48),
            (40, 24),
            (7, 3),
            (1, 1),
            (13, 5),
            (21, 9),
            (40, 7),
            (17, 4),
        ] {
            let src: Vec<u8> = (0..w * h)
                .map(|i| {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    // Smooth ramps plus noise: many sums land near level boundaries.
                    ((i % w) * 3 + (i / w) * 2) as u8 ^ (state >> 29) as u8
                })
                .collect();
            let mut got = vec![0u8; w * h];
            f.apply(&src, w, h, &mut got);
            let want = bilateral_per_pixel(&mut f, &src, w, h);
            assert_eq!(got, want, "{w}x{h}");
            // The AVX2 path too, where `apply` took the 512-bit one.
            #[cfg(target_arch = "x86_64")]
            if crate::kernels::cpu::has_avx2_fma() {
                let mut avx2 = vec![0u8; w * h];
                #[allow(unsafe_code)]
                // SAFETY: the CPU has AVX2 and FMA; `apply` left `padded` filled for this image.
                unsafe {
                    f.filter_avx2(w, h, &mut avx2)
                };
                assert_eq!(avx2, want, "avx2 {w}x{h}");
            }
            // The portable loop too, where `apply` took a gather path.
            let mut rows = vec![0u8; w * h];
            f.filter_rows(w, h, &mut rows);
            assert_eq!(rows, want, "rows {w}x{h}");
        }
    }

    #[test]
    fn equalize_spreads_levels_like_opencv() {
        // Levels 10 (×2), 20 (×1), 30 (×1): OpenCV gives 0, 128 (127.5 → even), 255.
        let mut b = vec![10, 10, 20, 30];
        equalize_hist(&mut b);
        assert_eq!(b, vec![0, 0, 128, 255]);
        let mut flat = vec![9u8; 5];
        equalize_hist(&mut flat);
        assert_eq!(flat, vec![9; 5]);
        equalize_hist(&mut []);
    }
}
