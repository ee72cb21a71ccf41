//! Area (box-filter) resampling of a luma region into a network input, the Rust twin of OpenCV's
//! `INTER_AREA` shrink that the detector's training uses (`models/train/detector/train.py`).
//!
//! Output pixel `o` along an axis covers the source interval `[start + o·r, start + (o+1)·r)` (pixel
//! convention of `crate::camera`: source pixel `k` covers `[k, k+1)`); its value is the mean of the
//! source pixels over that interval, weighted by overlap. Source pixels outside the image are the
//! nearest border pixel (replicated). Taps are precomputed per geometry and reused.

use crate::image::GrayImage;

/// Precomputed taps of one axis: for output `o`, source indices `first[o] ..` with `weights`.
#[derive(Debug, Default, Clone)]
pub(crate) struct AxisTaps {
    /// Per output: (first index into `idx`/`weights`, count).
    spans: Vec<(u32, u32)>,
    idx: Vec<u32>,
    weights: Vec<f32>,
    key: (usize, u32, u32, usize),
}

impl AxisTaps {
    /// Builds (or keeps, when the geometry is unchanged) the taps for `n_out` outputs covering
    /// `[start, start + n_out·ratio)` of a source axis of `src_len` pixels. `ratio` ≥ 1 is the
    /// number of source pixels per output pixel; smaller ratios degrade to nearest-pixel weights.
    pub(crate) fn build(&mut self, src_len: usize, start: f32, ratio: f32, n_out: usize) {
        let key = (src_len, start.to_bits(), ratio.to_bits(), n_out);
        if key == self.key && !self.spans.is_empty() {
            return;
        }
        self.key = key;
        self.spans.clear();
        self.idx.clear();
        self.weights.clear();
        let last = src_len.saturating_sub(1) as i64;
        for o in 0..n_out {
            let a = start as f64 + o as f64 * ratio as f64;
            let b = a + ratio as f64;
            let first = self.idx.len() as u32;
            let mut k = a.floor() as i64;
            let mut total = 0.0f64;
            while (k as f64) < b {
                let lo = a.max(k as f64);
                let hi = b.min(k as f64 + 1.0);
                let w = hi - lo;
                if w > 1e-9 {
                    self.idx.push(k.clamp(0, last) as u32);
                    self.weights.push(w as f32);
                    total += w;
                }
                k += 1;
            }
            let n = self.idx.len() as u32 - first;
            let inv = if total > 0.0 {
                (1.0 / total) as f32
            } else {
                0.0
            };
            for w in &mut self.weights[first as usize..] {
                *w *= inv;
            }
            self.spans.push((first, n));
        }
    }

    #[inline]
    fn taps(&self, o: usize) -> (&[u32], &[f32]) {
        let (f, n) = self.spans[o];
        let r = f as usize..(f + n) as usize;
        (&self.idx[r.clone()], &self.weights[r])
    }
}

/// Separable area resampler with its reused row buffer.
#[derive(Debug, Default, Clone)]
pub(crate) struct AreaResampler {
    pub(crate) xs: AxisTaps,
    pub(crate) ys: AxisTaps,
    /// Vertically filtered rows: `out_h × source width`.
    tmp: Vec<f32>,
}

impl AreaResampler {
    /// Resamples into `out` (row-major, `out_w × out_h` region of a tensor with row length
    /// `out_stride`), writing `value / 255` (the network's input scaling). The taps must have been
    /// built with `n_out` = `out_w` (x) and `out_h` (y) for `img`.
    ///
    /// The vertical pass runs first: it reads whole source rows, so it vectorises, and it leaves
    /// the tap-by-tap horizontal pass (scalar: each output's taps are a short run of its own) only
    /// the `out_h` output rows instead of every source row used, which shortened
    /// `detect_640x480`. The sums are those of the horizontal-first order up to float rounding.
    pub(crate) fn run(
        &mut self,
        img: &GrayImage,
        out: &mut [f32],
        out_w: usize,
        out_h: usize,
        out_stride: usize,
    ) {
        let w = img.width();
        self.tmp.resize(out_h * w, 0.0);
        for (o, dst) in self.tmp.chunks_exact_mut(w).enumerate() {
            let (idx, wts) = self.ys.taps(o);
            dst.fill(0.0);
            for (&k, &wk) in idx.iter().zip(wts) {
                for (d, &s) in dst.iter_mut().zip(img.row(k as usize)) {
                    *d += f32::from(s) * wk;
                }
            }
        }
        const INV_255: f32 = 1.0 / 255.0;
        for (src, dst) in self.tmp.chunks_exact(w).zip(out.chunks_mut(out_stride)) {
            for (x, d) in dst[..out_w].iter_mut().enumerate() {
                let (idx, wts) = self.xs.taps(x);
                let mut acc = 0.0f32;
                for (&k, &wk) in idx.iter().zip(wts) {
                    acc += src[k as usize] * wk;
                }
                *d = acc * INV_255;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_ratio_is_block_mean() {
        let data: Vec<u8> = (0..16).map(|i| (i * 10) as u8).collect();
        let img = GrayImage::from_vec(4, 4, data).unwrap();
        let mut r = AreaResampler::default();
        r.xs.build(4, 0.0, 2.0, 2);
        r.ys.build(4, 0.0, 2.0, 2);
        let mut out = vec![0.0; 4];
        r.run(&img, &mut out, 2, 2, 2);
        // Top-left block: pixels 0, 10, 40, 50 → mean 25.
        assert!((out[0] * 255.0 - 25.0).abs() < 1e-3);
        assert!((out[3] * 255.0 - (100.0 + 110.0 + 140.0 + 150.0) / 4.0).abs() < 1e-3);
    }

    #[test]
    fn fractional_ratio_weights_sum_to_one_and_borders_replicate() {
        let img = GrayImage::from_vec(5, 1, vec![255; 5]).unwrap();
        let mut r = AreaResampler::default();
        // Starts left of the image and runs past its right edge: replicated borders keep 255.
        r.xs.build(5, -1.3, 2.5, 3);
        r.ys.build(1, 0.0, 1.0, 1);
        let mut out = vec![0.0; 3];
        r.run(&img, &mut out, 3, 1, 3);
        for v in out {
            assert!((v - 1.0).abs() < 1e-5, "{v}");
        }
    }
}
