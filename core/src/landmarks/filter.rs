//! Patch filters of `models/M3_IO.md`, with OpenCV's semantics on 8-bit gray images (the training
//! side calls OpenCV): [`Bilateral`] (`cv::bilateralFilter`, BORDER_REFLECT_101) and
//! [`equalize_hist`] (`cv::equalizeHist`).
//!
//! Bit-exactness: the equalisation is exact. The bilateral filter uses OpenCV's weight formulas,
//! float32 sums and truncation to u8 (what the installed OpenCV 5 does); OpenCV's vectorised
//! kernels sum in another order (with fused multiply-adds) and approximate `exp` for the colour
//! table, so a result within float rounding of an integer may land one level off: ±1 on a small
//! share of the pixels (the golden tests of `tests/data/m3_preproc/` measure and bound it).
//!
//! The filter's sums, which have a form per instruction set, are `crate::kernels::bilateral`'s;
//! [`Bilateral`] keeps the tables, the padding and the buffers.

use crate::kernels::bilateral::{Filter, RowSums};
use crate::math::Libm;

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
    /// The portable kernel's running sums of one output row.
    sums: RowSums,
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
            *w = ((i * i) as f32 * gc).mexp();
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
                space_weight.push((dist * dist * f64::from(gs)).mexp() as f32);
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
            sums: RowSums::default(),
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
        let filter = Filter {
            padded: &self.padded,
            width,
            height,
            radius: self.radius,
            offsets: &self.offsets,
            space_weight: &self.space_weight,
            color_weight: &self.color_weight,
        };
        filter.run(&mut self.sums, dst);
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

    /// `cv::bilateralFilter`'s definition pixel by pixel on the image itself, borders through
    /// [`reflect101`], taps in OpenCV's order.
    fn bilateral_definition(f: &Bilateral, src: &[u8], w: usize, h: usize) -> Vec<u8> {
        let mut dst = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let v0 = src[y * w + x];
                let (mut sum, mut wsum) = (0f32, 0f32);
                for (&(dy, dx), &sw) in f.taps.iter().zip(&f.space_weight) {
                    let (sy, sx) = (
                        reflect101(y as isize + dy, h),
                        reflect101(x as isize + dx, w),
                    );
                    let v = src[sy * w + sx];
                    let weight = sw * f.color_weight[usize::from(v.abs_diff(v0))];
                    wsum += weight;
                    sum += f32::from(v) * weight;
                }
                dst[y * w + x] = (sum / wsum).clamp(0.0, 255.0) as u8;
            }
        }
        dst
    }

    /// The padding, the offsets (recomputed as the width changes between calls) and the kernel
    /// this CPU runs, together, to the bit.
    #[test]
    fn bilateral_equals_the_definition_on_the_unpadded_image() {
        let mut f = Bilateral::new(5, 20.0, 3.0);
        let mut state = 777u32;
        for (w, h) in [(64, 32), (7, 3), (1, 1), (13, 5), (40, 7), (2, 9)] {
            let src: Vec<u8> = (0..w * h)
                .map(|i| {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    ((i % w) * 3 + (i / w) * 2) as u8 ^ (state >> 29) as u8
                })
                .collect();
            let mut got = vec![0u8; w * h];
            f.apply(&src, w, h, &mut got);
            assert_eq!(got, bilateral_definition(&f, &src, w, h), "{w}x{h}");
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
