//! The bilinear sampling of a patch under an affine map (`landmarks::warp`, the contract of
//! `models/M3_IO.md`, "Sampling convention"): [`ClampedMap`] for rotated maps, in f32 over chunks
//! of sixteen pixels, and [`sample_axis_aligned`] for maps without rotation (the level-1 crop), in
//! f64 with its taps computed once per column and per row. `landmarks::warp` validates the map and
//! the image and chooses between them and its own per-pixel f64 loop.
//!
//! | form | rotated maps | axis-aligned maps |
//! |---|---|---|
//! | portable (the reference; aarch64, where the compiler vectorises it) | lanes in arrays | pixel by pixel |
//! | AVX2 + FMA (`x86_64.rs`) | eight-lane hardware gathers of the tap pairs | the portable form |
//! | AVX-512F (`x86_64.rs`) | sixteen-lane gathers | sixteen pixels per gather of each tap |
//!
//! Every form does each pixel's arithmetic in the portable form's order (Rust never contracts it
//! into fused multiply-adds), so all write the same bytes: the tests hold each form to the
//! portable one byte for byte.

#[cfg(target_arch = "x86_64")]
mod x86_64;

use crate::kernels::cpu::PixelForm as Form;

/// A rotated map sampled in f32 over chunks of [`ClampedMap::CHUNK`] pixels, so the coordinate
/// and blend passes vectorise, for any placement of the patch: each coordinate is clamped to the
/// rectangle of the image's pixel centres, which is exact (beyond the last centre the replicated
/// border makes the bilinear sample the edge pixel's value), and the top-left tap to one pixel
/// inside the last column and row, with the weight then 1 on the far tap. Now and then one level
/// off the f64 formula (`landmarks::warp`'s unit test bounds how often), far inside the training
/// side's own ±1 agreement (`landmarks::warp`'s docs).
///
/// Why every placement: patches that reach past the image edge (large faces, faces at the
/// border) would otherwise take the per-pixel f64 loop, and were the slow end of M3's time per
/// face.
pub(crate) struct ClampedMap<'a> {
    m: &'a [f64; 6],
}

impl<'a> ClampedMap<'a> {
    /// Pixels per vectorised chunk: two AVX-512 or four NEON f32 registers.
    const CHUNK: usize = 16;
    /// Largest image side: f32 coordinates below 2^14 round by under 0.001 px.
    pub(crate) const MAX_SIDE: usize = 1 << 14;

    /// The sampler of map `m` (`x = m[0]·u + m[1]·v + m[2]`, `y = m[3]·u + m[4]·v + m[5]`) for an
    /// `iw`×`ih` image; `None` where a side is below two pixels or above [`Self::MAX_SIDE`].
    pub(crate) fn new(m: &'a [f64; 6], iw: usize, ih: usize) -> Option<Self> {
        (iw >= 2 && ih >= 2 && iw.max(ih) <= Self::MAX_SIDE).then_some(Self { m })
    }

    /// Samples the patch, rows of `width` pixels, into `out` from `data`, the row-major
    /// `iw`×`ih` image this sampler was made for.
    pub(crate) fn sample(&self, data: &[u8], iw: usize, ih: usize, width: usize, out: &mut [u8]) {
        self.sample_with(Form::for_this_cpu(), data, iw, ih, width, out);
    }

    fn sample_with(
        &self,
        form: Form,
        data: &[u8],
        iw: usize,
        ih: usize,
        width: usize,
        out: &mut [u8],
    ) {
        // The gathers' bounds rest on `data` being the whole iw × ih image: checked here, not
        // assumed, since a violation would be a read out of bounds rather than a panic.
        let form = if data.len() == iw * ih {
            form
        } else {
            Form::Portable
        };
        match form {
            Form::Portable => self.sample_body(data, iw, ih, width, out),
            #[cfg(target_arch = "x86_64")]
            Form::Avx2 => {
                #[allow(unsafe_code)]
                // SAFETY: the CPU has AVX2 and FMA, which this form is only chosen with
                // (`Form::for_this_cpu`, `Form::all`).
                unsafe {
                    x86_64::sample_avx2(self, data, iw, ih, width, out)
                }
            }
            #[cfg(target_arch = "x86_64")]
            Form::Avx512 => {
                #[allow(unsafe_code)]
                // SAFETY: the CPU has AVX-512F, AVX2 and FMA, which this form is only chosen with
                // (`Form::for_this_cpu`, `Form::all`).
                unsafe {
                    x86_64::sample_avx512(self, data, iw, ih, width, out)
                }
            }
        }
    }

    /// The portable form: the reference the gathers reproduce.
    fn sample_body(&self, data: &[u8], iw: usize, ih: usize, width: usize, out: &mut [u8]) {
        const N: usize = ClampedMap::CHUNK;
        let m = self.m;
        let (dx, dy) = (m[0] as f32, m[3] as f32);
        let ramp: [f32; N] = std::array::from_fn(|k| k as f32);
        let (x_cap, y_cap) = ((iw - 1) as f32, (ih - 1) as f32);
        let (x0_cap, y0_cap) = (iw as u32 - 2, ih as u32 - 2);
        // Each tap pair's lower row, and the largest index of a top-left tap.
        let below = &data[iw..];
        let last = below.len() - 2;
        let (mut idx, mut fx, mut fy) = ([0usize; N], [0f32; N], [0f32; N]);
        let (mut p00, mut p01, mut p10, mut p11) = ([0f32; N], [0f32; N], [0f32; N], [0f32; N]);
        for (v, row) in out.chunks_exact_mut(width).enumerate() {
            let vc = v as f64 + 0.5;
            for (c, chunk) in row.chunks_mut(N).enumerate() {
                // Chunk origins in f64, offsets within a chunk in f32: the f32 part stays small
                // against a pixel ([`ClampedMap::MAX_SIDE`]).
                let uc = (c * N) as f64 + 0.5;
                let x_org = (m[0] * uc + m[1] * vc + m[2] - 0.5) as f32;
                let y_org = (m[3] * uc + m[4] * vc + m[5] - 0.5) as f32;
                let n = chunk.len();
                for k in 0..N {
                    // `as u32` saturates (NaN → 0), so every lane's taps stay in the image.
                    let x = (x_org + dx * ramp[k]).clamp(0.0, x_cap);
                    let y = (y_org + dy * ramp[k]).clamp(0.0, y_cap);
                    let (x0, y0) = ((x as u32).min(x0_cap), (y as u32).min(y0_cap));
                    fx[k] = x - x0 as f32;
                    fy[k] = y - y0 as f32;
                    idx[k] = y0 as usize * iw + x0 as usize;
                }
                for k in 0..n {
                    // An identity (the clamps above bound idx by `last`) that lets the compiler
                    // drop the four bounds checks.
                    let i = idx[k].min(last);
                    p00[k] = f32::from(data[i]);
                    p01[k] = f32::from(data[i + 1]);
                    p10[k] = f32::from(below[i]);
                    p11[k] = f32::from(below[i + 1]);
                }
                for k in 0..N {
                    let top = p00[k] + fx[k] * (p01[k] - p00[k]);
                    let bottom = p10[k] + fx[k] * (p11[k] - p10[k]);
                    fx[k] = top + fy[k] * (bottom - top) + 0.5;
                }
                for (o, &val) in chunk.iter_mut().zip(&fx) {
                    // The saturating cast floors val ≥ 0 and keeps f32 overshoot at 255.
                    *o = val as u8;
                }
            }
        }
    }
}

/// Largest side [`sample_axis_aligned`] handles (its tap tables live on the stack).
pub(crate) const AXIS_MAX_SIDE: usize = 256;

/// One source tap pair and the weight of the second.
type Tap = (usize, usize, f64);

/// The patch of a map without rotation (`m[1] = m[3] = 0`: x depends on u only and y on v only)
/// from `data`, the row-major `iw`×`ih` image, into `out` (rows of `width` pixels): taps and
/// weights are computed once per column and once per row instead of per pixel, with the
/// per-pixel formula's f64 operations, so the same bytes.
///
/// # Panics
/// Where the patch has a side above [`AXIS_MAX_SIDE`] or `data` is shorter than the image.
pub(crate) fn sample_axis_aligned(
    data: &[u8],
    iw: usize,
    ih: usize,
    m: &[f64; 6],
    width: usize,
    out: &mut [u8],
) {
    sample_axis_aligned_with(Form::for_this_cpu(), data, iw, ih, m, width, out);
}

#[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
fn sample_axis_aligned_with(
    form: Form,
    data: &[u8],
    iw: usize,
    ih: usize,
    m: &[f64; 6],
    width: usize,
    out: &mut [u8],
) {
    let height = out.len() / width;
    assert!(
        width <= AXIS_MAX_SIDE && height <= AXIS_MAX_SIDE,
        "a {width}x{height} patch on the axis-aligned path"
    );
    let mut cols = [(0, 0, 0.0); AXIS_MAX_SIDE];
    let mut rows = [(0, 0, 0.0); AXIS_MAX_SIDE];
    axis_taps(m[0], m[2], iw, 1, &mut cols[..width]);
    axis_taps(m[4], m[5], ih, iw, &mut rows[..height]);
    let (cols, rows) = (&cols[..width], &rows[..height]);
    #[cfg(target_arch = "x86_64")]
    if form == Form::Avx512
        && width >= x86_64::AXIS_LANES
        && data.len() == iw * ih
        && i32::try_from(data.len()).is_ok()
    {
        #[allow(unsafe_code)]
        // SAFETY: the CPU has AVX-512F, AVX2 and FMA, which this form is only chosen with
        // (`Form::for_this_cpu`, `Form::all`); `data` is the whole image and its length fits
        // i32; `axis_taps` clamps every column tap below iw and every row tap to a row of the
        // image; there are at least `AXIS_LANES` columns.
        unsafe {
            x86_64::axis_rows_avx512(data, iw, cols, rows, out)
        };
        return;
    }
    for (row, &(ra, rb, fy)) in out.chunks_exact_mut(width).zip(rows) {
        axis_row(data, iw, ra, rb, fy, cols, row);
    }
}

/// One axis of an axis-aligned map: for each of the first `n` output indices the two source taps
/// (multiplied by `stride`) and the weight of the second, clamped as the per-pixel formula is.
fn axis_taps(scale: f64, offset: f64, len: usize, stride: usize, taps: &mut [Tap]) {
    let max = (len - 1) as isize;
    for (i, t) in taps.iter_mut().enumerate() {
        // The general formula's value: its cross term is an exact zero.
        let c = i as f64 + 0.5;
        let x = (scale * c + offset - 0.5).clamp(-1.0, len as f64);
        let x0 = (x + 1.0) as isize - 1;
        let a = x0.clamp(0, max) as usize * stride;
        let b = (x0 + 1).clamp(0, max) as usize * stride;
        *t = (a, b, x - x0 as f64);
    }
}

/// One output row of [`sample_axis_aligned`] pixel by pixel, the portable form: source rows
/// starting at `ra` and `rb`, their weights `1 − fy` and `fy`.
fn axis_row(data: &[u8], iw: usize, ra: usize, rb: usize, fy: f64, cols: &[Tap], row: &mut [u8]) {
    let (top, bottom) = (&data[ra..ra + iw], &data[rb..rb + iw]);
    for (o, &(xa, xb, fx)) in row.iter_mut().zip(cols) {
        let (p00, p01) = (f64::from(top[xa]), f64::from(top[xb]));
        let (p10, p11) = (f64::from(bottom[xa]), f64::from(bottom[xb]));
        let val = (1.0 - fy) * ((1.0 - fx) * p00 + fx * p01) + fy * ((1.0 - fx) * p10 + fx * p11);
        *o = (val + 0.5) as u8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform numbers in [0, 1) from a 64-bit LCG seeded with `seed`.
    #[cfg(target_arch = "x86_64")]
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A rotated map of scale `scale` and angle `angle` putting the `w`×`h` patch's centre at
    /// (cx, cy).
    #[cfg(target_arch = "x86_64")]
    fn rotated(angle: f64, scale: f64, w: usize, h: usize, cx: f64, cy: f64) -> [f64; 6] {
        let (c, s) = (scale * angle.cos(), scale * angle.sin());
        let (hw, hh) = (0.5 * w as f64, 0.5 * h as f64);
        [c, -s, cx - c * hw + s * hh, s, c, cy - s * hw - c * hh]
    }

    /// Hashed noise of `iw`×`ih` pixels.
    #[cfg(target_arch = "x86_64")]
    fn noise(iw: usize, ih: usize) -> Vec<u8> {
        (0..iw * ih)
            .map(|i: usize| (i.wrapping_mul(2_654_435_761) >> 12) as u8)
            .collect()
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn the_avx2_and_avx512_copies_of_the_clamped_path_give_the_same_bytes() {
        crate::kernels::cpu::assert_avx2_fma_path();
        let forms = Form::all();
        assert!(forms.contains(&Form::Avx2), "{forms:?}");
        let mut rnd = uniform(4242);
        // The smallest images too: every read of a gather must stay inside 4 or 15 bytes.
        for (iw, ih) in [(97, 61), (2, 2), (3, 5)] {
            let data = noise(iw, ih);
            for case in 0..300 {
                let (w, h) = (1 + (70.0 * rnd()) as usize, 1 + (50.0 * rnd()) as usize);
                // Patches inside, across the edges (the last row and column included) and around
                // the image.
                let (fw, fh) = (iw as f64, ih as f64);
                let m = rotated(
                    6.3 * rnd(),
                    0.05 + 1.2 * rnd(),
                    w,
                    h,
                    fw * (1.6 * rnd() - 0.3),
                    fh * (1.6 * rnd() - 0.3),
                );
                let map = ClampedMap::new(&m, iw, ih).unwrap();
                let mut base = vec![0u8; w * h];
                map.sample_with(Form::Portable, &data, iw, ih, w, &mut base);
                for (k, &form) in forms.iter().enumerate() {
                    let mut got = vec![k as u8 + 1; w * h];
                    map.sample_with(form, &data, iw, ih, w, &mut got);
                    assert_eq!(base, got, "{form:?}, case {case}: {m:?} {w}x{h}");
                }
                // The dispatched form is one of them.
                let mut got = vec![0xEE; w * h];
                map.sample(&data, iw, ih, w, &mut got);
                assert_eq!(base, got, "dispatched, case {case}: {m:?} {w}x{h}");
            }
        }
    }

    /// Every form this CPU runs, bit for bit with the portable one, over crops of the whole image
    /// and past it: first and last rows and columns, the last row through the word ending at its
    /// tap, widths with a partial last group of 16, and small images (three columns is the
    /// narrowest the gathers take).
    #[test]
    fn every_form_of_the_axis_aligned_path_gives_the_portable_bytes() {
        for (iw, ih) in [(97, 61), (3, 2), (5, 1), (2, 7), (40, 3)] {
            let data: Vec<u8> = (0..iw * ih).map(|i: usize| (i * 37 % 251) as u8).collect();
            for (w, h) in [(16, 16), (17, 5), (31, 40), (64, 64), (200, 3), (256, 2)] {
                for (sx, ox) in [(iw as f64 / w as f64, 0.0), (1.7, -20.0), (0.3, 1.1)] {
                    let sy = ih as f64 / h as f64;
                    for oy in [0.0, -3.0, 2.5] {
                        let m = [sx, 0.0, ox, 0.0, sy, oy];
                        let mut base = vec![0u8; w * h];
                        sample_axis_aligned_with(Form::Portable, &data, iw, ih, &m, w, &mut base);
                        for form in Form::all() {
                            let mut got = vec![0xEE; w * h];
                            sample_axis_aligned_with(form, &data, iw, ih, &m, w, &mut got);
                            assert_eq!(got, base, "{form:?}: {iw}x{ih} image, {w}x{h}, {m:?}");
                        }
                    }
                }
            }
        }
    }
}
