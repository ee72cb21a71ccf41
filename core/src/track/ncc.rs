//! Normalised cross-correlation (NCC) template matching at a reduced scale — the fast tracker's
//! region step (thesis 4.3.2): the face region of the previous frame is cut as a template and found
//! again in a search window around its old place in the new frame.
//!
//! Both the template and the window are box-decimated by one integer factor `f` chosen so the
//! template's larger side is about [`NccMatcher::template_px`] pixels; the cost is then independent of
//! the face size. Window sums and sums of squares come from integral images, so each candidate offset
//! costs one dot product with the zero-mean template; those of all offsets are computed together,
//! blocks of offsets at a time in vector registers (f32 sums). The peak is refined to sub-pixel by
//! a parabola through its neighbours along x and y, and the shift is returned in full-resolution
//! pixels.
//!
//! Pixel convention: see [`crate::camera`]; a region's (x, y) is the top-left corner.

use crate::image::{GrayImage, Rect};

/// Smallest decimated template side that still carries a usable correlation peak (below 4×4 cells
/// a face template is a few blobs and matches anywhere).
pub const MIN_TEMPLATE_CELLS: usize = 4;

/// Window standard deviation (grey levels, decimated) under which a candidate patch is treated as
/// flat: its NCC is undefined and scored 0 (a uniform wall must never "match" a face).
const FLAT_STD: f64 = 0.5;

/// The best match of a search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NccMatch {
    /// The template's region moved by the found shift (full-resolution pixels).
    pub rect: Rect,
    /// Shift from the template's region to the match, pixels (sub-pixel).
    pub shift: [f32; 2],
    /// Normalised cross-correlation at the peak, −1..1.
    pub score: f32,
}

/// Template matcher. Holds one template and every buffer, reused across frames.
#[derive(Debug, Clone)]
pub struct NccMatcher {
    template_px: usize,
    /// The region the template was cut for (may extend past the image).
    region: Rect,
    /// Full-resolution integer top-left corner of the part of the region inside the image.
    origin: [i64; 2],
    factor: usize,
    tw: usize,
    th: usize,
    /// Zero-mean decimated template, row-major `tw × th`.
    template: Vec<f32>,
    template_norm: f64,
    has_template: bool,
    /// Decimated search window, rows `WINDOW_PAD` cells longer than the window and zero rows
    /// below it, so the correlation's blocks of outputs read past the window's end without checks.
    window: Vec<f32>,
    integral: Vec<f64>,
    integral_sq: Vec<f64>,
    /// Correlation of the template with every offset, rows of `BLOCK`-multiple length.
    num: Vec<f32>,
    /// Decimated size of the last search's window.
    searched: [usize; 2],
    bands: Bands,
}

/// Output offsets per vector of the correlation (eight f32 lanes: one AVX2 register, two of SSE or
/// NEON).
const BLOCK: usize = 8;
/// Output rows correlated together: independent sums the CPU overlaps (one row alone waits on its
/// add latency for every template cell).
const ROWS: usize = 4;
/// Extra cells at the end of each window row: the last block of outputs reads up to `BLOCK − 1`
/// cells past the last offset's template row.
const WINDOW_PAD: usize = BLOCK;

impl NccMatcher {
    /// A matcher whose decimated template has its larger side near `template_px` (clamped to ≥ 8).
    pub fn new(template_px: usize) -> Self {
        Self {
            template_px: template_px.max(8),
            region: Rect::default(),
            origin: [0, 0],
            factor: 1,
            tw: 0,
            th: 0,
            template: Vec::new(),
            template_norm: 0.0,
            has_template: false,
            window: Vec::new(),
            integral: Vec::new(),
            integral_sq: Vec::new(),
            num: Vec::new(),
            searched: [0, 0],
            bands: Bands::default(),
        }
    }

    /// Target larger side of the decimated template, pixels.
    pub fn template_px(&self) -> usize {
        self.template_px
    }

    /// The decimation factor of the current template (1 = full resolution).
    pub fn factor(&self) -> usize {
        self.factor
    }

    /// Whether a usable template is held.
    pub fn has_template(&self) -> bool {
        self.has_template
    }

    /// Forgets the template.
    pub fn clear(&mut self) {
        self.has_template = false;
    }

    /// Cuts the template for `region` from `image` (the part inside the image). Returns whether a
    /// usable template resulted: `false` for a region (nearly) outside the image, too small, or flat.
    pub fn set_template(&mut self, image: &GrayImage, region: &Rect) -> bool {
        self.has_template = false;
        if !region.is_valid() || image.width() == 0 || image.height() == 0 {
            return false;
        }
        let size = region.w.max(region.h);
        let factor = ((size / self.template_px as f32).round() as usize).max(1);
        let x0 = (region.x.round() as i64).max(0);
        let y0 = (region.y.round() as i64).max(0);
        let x1 = ((region.x + region.w).round() as i64).min(image.width() as i64);
        let y1 = ((region.y + region.h).round() as i64).min(image.height() as i64);
        if x1 <= x0 || y1 <= y0 {
            return false;
        }
        let tw = (x1 - x0) as usize / factor;
        let th = (y1 - y0) as usize / factor;
        if tw < MIN_TEMPLATE_CELLS || th < MIN_TEMPLATE_CELLS {
            return false;
        }
        let cells = Cells {
            x0: x0 as usize,
            y0: y0 as usize,
            cols: tw,
            rows: th,
            f: factor,
        };
        decimate(
            image,
            cells,
            Padded {
                stride: tw,
                rows: th,
            },
            &mut self.bands,
            &mut self.template,
        );
        let n = (tw * th) as f64;
        let mean = self.template.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let mut ss = 0.0;
        for v in &mut self.template {
            *v -= mean as f32;
            ss += f64::from(*v) * f64::from(*v);
        }
        if ss / n < FLAT_STD * FLAT_STD {
            return false;
        }
        self.region = *region;
        self.origin = [x0, y0];
        self.factor = factor;
        self.tw = tw;
        self.th = th;
        self.template_norm = ss.sqrt();
        self.has_template = true;
        true
    }

    /// Finds the template in `image` within `margin` × (the region's larger side) of its old place
    /// in every direction. `None` without a template, or when the window left inside the image is
    /// smaller than the template.
    pub fn search(&mut self, image: &GrayImage, margin: f32) -> Option<NccMatch> {
        if !self.has_template || !margin.is_finite() || margin < 0.0 {
            return None;
        }
        let f = self.factor;
        let m = (margin * self.region.w.max(self.region.h)).ceil() as i64;
        let (iw, ih) = (image.width() as i64, image.height() as i64);
        let wx0 = (self.origin[0] - m).max(0);
        let wy0 = (self.origin[1] - m).max(0);
        let wx1 = (self.origin[0] + (self.tw * f) as i64 + m).min(iw);
        let wy1 = (self.origin[1] + (self.th * f) as i64 + m).min(ih);
        if wx1 <= wx0 || wy1 <= wy0 {
            return None;
        }
        let ww = (wx1 - wx0) as usize / f;
        let wh = (wy1 - wy0) as usize / f;
        let (tw, th) = (self.tw, self.th);
        if ww < tw || wh < th {
            return None;
        }
        self.searched = [ww, wh];
        let (nx, ny) = (ww - tw + 1, wh - th + 1);
        let blocks = nx.div_ceil(BLOCK);
        let ny_pad = ny.next_multiple_of(ROWS);
        let ws = ww + WINDOW_PAD;
        let cells = Cells {
            x0: wx0 as usize,
            y0: wy0 as usize,
            cols: ww,
            rows: wh,
            f,
        };
        decimate(
            image,
            cells,
            Padded {
                stride: ws,
                rows: ny_pad + th - 1,
            },
            &mut self.bands,
            &mut self.window,
        );
        integrals(
            &self.window,
            ww,
            wh,
            ws,
            &mut self.integral,
            &mut self.integral_sq,
        );
        self.correlate(ws, blocks, ny_pad);

        let n = (tw * th) as f64;
        let stride = ww + 1;
        let nxp = blocks * BLOCK;
        let score_at = |i: usize, j: usize| -> f64 {
            let box_sum = |t: &[f64]| {
                t[(j + th) * stride + i + tw] - t[j * stride + i + tw] - t[(j + th) * stride + i]
                    + t[j * stride + i]
            };
            let s = box_sum(&self.integral);
            let ss = box_sum(&self.integral_sq);
            let var = ss - s * s / n;
            if var < FLAT_STD * FLAT_STD * n {
                return 0.0;
            }
            // Σ t'·I equals Σ t'·(I − mean) because the template is zero-mean.
            f64::from(self.num[j * nxp + i]) / (self.template_norm * var.sqrt())
        };

        let mut best = (f64::NEG_INFINITY, 0usize, 0usize);
        for j in 0..ny {
            for i in 0..nx {
                let s = score_at(i, j);
                if s > best.0 {
                    best = (s, i, j);
                }
            }
        }
        let (peak, bi, bj) = best;
        if !peak.is_finite() {
            return None;
        }
        let sub = |lo: Option<f64>, hi: Option<f64>| -> f64 {
            match (lo, hi) {
                (Some(a), Some(b)) => {
                    let d = a - 2.0 * peak + b;
                    if d < -1e-12 {
                        (0.5 * (a - b) / d).clamp(-0.5, 0.5)
                    } else {
                        0.0
                    }
                }
                _ => 0.0,
            }
        };
        let dx = sub(
            (bi > 0).then(|| score_at(bi - 1, bj)),
            (bi + 1 < nx).then(|| score_at(bi + 1, bj)),
        );
        let dy = sub(
            (bj > 0).then(|| score_at(bi, bj - 1)),
            (bj + 1 < ny).then(|| score_at(bi, bj + 1)),
        );
        // Cell (i, j) of the window starts at (wx0 + i·f, wy0 + j·f); the template's first cell at
        // `origin`. Both are block means, so the shift between block grids is exact in full pixels.
        let sx = (wx0 - self.origin[0]) as f64 + (bi as f64 + dx) * f as f64;
        let sy = (wy0 - self.origin[1]) as f64 + (bj as f64 + dy) * f as f64;
        let shift = [sx as f32, sy as f32];
        Some(NccMatch {
            rect: Rect::new(
                self.region.x + shift[0],
                self.region.y + shift[1],
                self.region.w,
                self.region.h,
            ),
            shift,
            score: peak as f32,
        })
    }

    crate::cpu::with_avx2_copy! {
        /// Correlates the template with the window (row stride `ws`) at `blocks × BLOCK` offsets
        /// along x and `rows` (a multiple of `ROWS`) along y, into `num` (row stride
        /// `blocks × BLOCK`). Offsets past the window's last one read its zero padding; their sums
        /// are computed and never read.
        fn correlate / correlate_avx2 (&mut self, ws: usize, blocks: usize, rows: usize)
            => correlate_body
    }

    /// Written as output vectors rather than one dot product per offset: each template cell is
    /// multiplied into `ROWS × BLOCK` sums held in registers, one broadcast and `ROWS` unaligned
    /// loads per cell, where a dot product per offset spends its time on short rows (the decimated
    /// template is ≈ 30 cells wide) and reductions.
    #[inline(always)]
    fn correlate_body(&mut self, ws: usize, blocks: usize, rows: usize) {
        let (tw, th) = (self.tw, self.th);
        let nxp = blocks * BLOCK;
        self.num.clear();
        self.num.resize(nxp * rows, 0.0);
        // The window holds `rows + th − 1` rows of `ws ≥ nxp + tw − 1` cells (see `search`).
        assert!(ws >= nxp + tw - 1 && self.window.len() >= (rows + th - 1) * ws);
        assert!(rows.is_multiple_of(ROWS) && self.template.len() == tw * th);
        for j in (0..rows).step_by(ROWS) {
            for b in 0..blocks {
                let i0 = b * BLOCK;
                let mut acc = [[0.0f32; BLOCK]; ROWS];
                for v in 0..th {
                    let trow = &self.template[v * tw..(v + 1) * tw];
                    let srcs: [&[f32]; ROWS] = std::array::from_fn(|r| {
                        let start = (j + r + v) * ws + i0;
                        &self.window[start..start + tw + BLOCK - 1]
                    });
                    for (u, &t) in trow.iter().enumerate() {
                        for (a, src) in acc.iter_mut().zip(&srcs) {
                            let s = &src[u..u + BLOCK];
                            for k in 0..BLOCK {
                                a[k] += t * s[k];
                            }
                        }
                    }
                }
                for (r, a) in acc.iter().enumerate() {
                    let o = (j + r) * nxp + i0;
                    self.num[o..o + BLOCK].copy_from_slice(a);
                }
            }
        }
    }
}

/// Column sums of a band of rows, kept across frames ([`decimate`]).
#[derive(Debug, Clone, Default)]
struct Bands {
    narrow: Vec<u16>,
    wide: Vec<u32>,
}

/// Layout of a decimated buffer: rows of `stride ≥ cols` cells and `rows ≥` the decimated rows in
/// all, the cells past the decimated ones zero.
#[derive(Debug, Clone, Copy)]
struct Padded {
    stride: usize,
    rows: usize,
}

/// The cells of a decimation: `cols × rows` means of `f × f` blocks starting at full-resolution
/// pixel (x0, y0), which the caller keeps inside the image.
#[derive(Debug, Clone, Copy)]
struct Cells {
    x0: usize,
    y0: usize,
    cols: usize,
    rows: usize,
    f: usize,
}

/// The block means of `cells`, laid out as `pad` says.
fn decimate(image: &GrayImage, cells: Cells, pad: Padded, bands: &mut Bands, out: &mut Vec<f32>) {
    let (cols, f, stride) = (cells.cols, cells.f, pad.stride);
    assert!(stride >= cols && pad.rows >= cells.rows);
    out.clear();
    out.resize(stride * pad.rows, 0.0);
    if f == 1 {
        for r in 0..cells.rows {
            let src = &image.row(cells.y0 + r)[cells.x0..cells.x0 + cols];
            for (o, &s) in out[r * stride..r * stride + cols].iter_mut().zip(src) {
                *o = f32::from(s);
            }
        }
        return;
    }
    // Column sums of each band of `f` rows first (wide integer adds the compiler vectorises), then
    // the `f`-wide groups of each band: summing `f`-pixel chunks row by row instead measured 2×
    // slower for the whole search. u16 holds a band's column sum while `f · 255` fits.
    if f * 255 <= usize::from(u16::MAX) {
        decimate_bands(image, cells, stride, &mut bands.narrow, out);
    } else {
        decimate_bands(image, cells, stride, &mut bands.wide, out);
    }
}

/// [`decimate`] for `f > 1` (rows `stride` apart), column sums of each band of rows in `T` (see
/// there).
fn decimate_bands<T>(
    image: &GrayImage,
    cells: Cells,
    stride: usize,
    band: &mut Vec<T>,
    out: &mut [f32],
) where
    T: Copy + Default + From<u8> + std::ops::AddAssign + Into<u32>,
{
    let Cells {
        x0,
        y0,
        cols,
        rows,
        f,
    } = cells;
    let inv = 1.0 / (f * f) as f32;
    band.clear();
    band.resize(cols * f, T::default());
    for r in 0..rows {
        band.fill(T::default());
        for dy in 0..f {
            let src = &image.row(y0 + r * f + dy)[x0..x0 + cols * f];
            for (b, &v) in band.iter_mut().zip(src) {
                *b += T::from(v);
            }
        }
        let dst = &mut out[r * stride..r * stride + cols];
        for (o, group) in dst.iter_mut().zip(band.chunks_exact(f)) {
            *o = group.iter().map(|&v| v.into()).sum::<u32>() as f32 * inv;
        }
    }
}

/// Integral images of values and squares of the `w × h` cells of `src` (row stride `stride`),
/// `(w + 1) × (h + 1)`, first row and column zero.
fn integrals(
    src: &[f32],
    w: usize,
    h: usize,
    stride_src: usize,
    sum: &mut Vec<f64>,
    sq: &mut Vec<f64>,
) {
    let stride = w + 1;
    sum.clear();
    sum.resize(stride * (h + 1), 0.0);
    sq.clear();
    sq.resize(stride * (h + 1), 0.0);
    for y in 0..h {
        let (mut rs, mut rq) = (0.0f64, 0.0f64);
        for x in 0..w {
            let v = f64::from(src[y * stride_src + x]);
            rs += v;
            rq += v * v;
            sum[(y + 1) * stride + x + 1] = sum[y * stride + x + 1] + rs;
            sq[(y + 1) * stride + x + 1] = sq[y * stride + x + 1] + rq;
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A smooth, non-periodic texture (sum of incommensurate sines and Gaussian blobs), sampled at
    /// continuous positions so sub-pixel shifts are exact.
    pub(crate) fn texture(x: f32, y: f32) -> f32 {
        let blobs = [
            (120.0, 90.0, 25.0, 60.0),
            (300.0, 200.0, 40.0, -50.0),
            (200.0, 330.0, 30.0, 45.0),
            (450.0, 120.0, 35.0, -40.0),
        ];
        let mut v = 128.0
            + 30.0 * (0.113 * x + 0.071 * y).sin()
            + 25.0 * (0.047 * x - 0.131 * y + 1.0).sin()
            + 15.0 * (0.29 * x + 0.23 * y + 2.0).sin();
        for (cx, cy, s, a) in blobs {
            v += a * (-((x - cx).powi(2) + (y - cy).powi(2)) / (2.0 * s * s)).exp();
        }
        v.clamp(0.0, 255.0)
    }

    /// A 640×480 image of the texture moved by `shift` (image(p) = texture(p − shift)).
    pub(crate) fn shifted(shift: [f32; 2]) -> GrayImage {
        let (w, h) = (640, 480);
        let mut img = GrayImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let v = texture(x as f32 + 0.5 - shift[0], y as f32 + 0.5 - shift[1]);
                img.data_mut()[y * w + x] = v.round() as u8;
            }
        }
        img
    }

    #[test]
    fn integer_shift_is_found_exactly_at_full_resolution() {
        let a = shifted([0.0, 0.0]);
        let b = shifted([7.0, -4.0]);
        let mut m = NccMatcher::new(64);
        let region = Rect::new(200.0, 150.0, 60.0, 60.0);
        assert!(m.set_template(&a, &region));
        assert_eq!(m.factor(), 1);
        let hit = m.search(&b, 0.5).unwrap();
        assert!((hit.shift[0] - 7.0).abs() < 0.05, "{hit:?}");
        assert!((hit.shift[1] + 4.0).abs() < 0.05, "{hit:?}");
        assert!(hit.score > 0.99, "{hit:?}");
        assert!((hit.rect.x - 207.0).abs() < 0.05 && (hit.rect.y - 146.0).abs() < 0.05);
    }

    #[test]
    fn subpixel_shift_within_half_a_pixel() {
        let a = shifted([0.0, 0.0]);
        for s in [[3.5f32, 2.25], [-6.3, 4.7], [0.4, -0.4]] {
            let b = shifted(s);
            let mut m = NccMatcher::new(64);
            assert!(m.set_template(&a, &Rect::new(250.0, 180.0, 64.0, 64.0)));
            let hit = m.search(&b, 0.3).unwrap();
            assert!(
                (hit.shift[0] - s[0]).abs() < 0.5 && (hit.shift[1] - s[1]).abs() < 0.5,
                "{s:?} → {hit:?}"
            );
        }
    }

    #[test]
    fn reduced_scale_finds_large_shifts() {
        let a = shifted([0.0, 0.0]);
        let region = Rect::new(180.0, 120.0, 180.0, 200.0);
        for s in [[31.0f32, -22.0], [-45.5, 17.25], [2.0, 3.0]] {
            let b = shifted(s);
            let mut m = NccMatcher::new(32);
            assert!(m.set_template(&a, &region));
            assert!(m.factor() > 4, "factor {}", m.factor());
            let hit = m.search(&b, 0.4).unwrap();
            // One decimated cell is `factor` pixels; the parabola gets within a fraction of it.
            let tol = 0.5 * m.factor() as f32;
            assert!(
                (hit.shift[0] - s[0]).abs() < tol && (hit.shift[1] - s[1]).abs() < tol,
                "{s:?} → {hit:?} (factor {})",
                m.factor()
            );
            assert!(hit.score > 0.9);
        }
    }

    /// The correlation of every offset the search reads against direct f64 sums over the template
    /// and the window, for template sizes that leave blocks and row groups partly filled.
    #[test]
    fn correlation_equals_direct_sums_at_every_offset() {
        let a = shifted([0.0, 0.0]);
        let b = shifted([4.5, -3.25]);
        let cases = [
            (Rect::new(200.0, 150.0, 60.0, 60.0), 64, 0.3),
            (Rect::new(180.0, 120.0, 180.0, 200.0), 32, 0.5),
            (Rect::new(100.0, 90.0, 37.0, 53.0), 32, 0.45),
            (Rect::new(-20.0, 400.0, 90.0, 70.0), 20, 0.6),
        ];
        for (region, px, margin) in cases {
            let mut m = NccMatcher::new(px);
            assert!(m.set_template(&a, &region));
            let hit = m.search(&b, margin).unwrap();
            let (tw, th) = (m.tw, m.th);
            let [ww, wh] = m.searched;
            let (stride_w, nxp) = layout(&m);
            let (nx, ny) = (ww - tw + 1, wh - th + 1);
            assert!(m.num.len() >= ny * nxp && nxp >= nx);
            let mut checked = 0;
            for j in 0..ny {
                for i in 0..nx {
                    let (mut direct, mut scale) = (0.0f64, 0.0f64);
                    for v in 0..th {
                        for u in 0..tw {
                            let t = f64::from(m.template[v * tw + u]);
                            let w = f64::from(m.window[(j + v) * stride_w + i + u]);
                            direct += t * w;
                            scale += (t * w).abs();
                        }
                    }
                    let got = f64::from(m.num[j * nxp + i]);
                    assert!(
                        (got - direct).abs() <= 1e-5 * scale,
                        "{region:?} ({i}, {j}): {got} vs {direct}"
                    );
                    checked += 1;
                }
            }
            assert!(
                checked > 100 && hit.score > 0.9,
                "{region:?}: {checked} {hit:?}"
            );
        }
    }

    /// Block means through band column sums, in u16 and in u32 (the path for factors past 257),
    /// against per-block sums, with and without padding of the rows.
    #[test]
    fn decimation_equals_block_means_in_both_sum_widths() {
        let img = shifted([1.5, -2.0]);
        for (f, pad) in [(2, 0), (3, 5), (5, 8), (7, 1)] {
            let (x0, y0, cols, rows) = (13, 7, 40, 30);
            let layout = Padded {
                stride: cols + pad,
                rows: rows + pad,
            };
            let (mut narrow, mut wide) = (Vec::new(), Vec::new());
            let mut bands = Bands::default();
            let cells = Cells {
                x0,
                y0,
                cols,
                rows,
                f,
            };
            decimate(&img, cells, layout, &mut bands, &mut narrow);
            wide.resize(narrow.len(), 0.0);
            decimate_bands::<u32>(&img, cells, cols + pad, &mut bands.wide, &mut wide);
            assert_eq!(narrow, wide, "f {f}");
            assert_eq!(narrow.len(), (cols + pad) * (rows + pad));
            for r in 0..rows + pad {
                for c in 0..cols + pad {
                    let want = if r < rows && c < cols {
                        let mut sum = 0u32;
                        for dy in 0..f {
                            for dx in 0..f {
                                sum += u32::from(img.row(y0 + r * f + dy)[x0 + c * f + dx]);
                            }
                        }
                        sum as f32 * (1.0 / (f * f) as f32)
                    } else {
                        0.0
                    };
                    assert_eq!(narrow[r * (cols + pad) + c], want, "f {f} ({c}, {r})");
                }
            }
        }
    }

    /// The window's row stride and the correlation's row length of the last search.
    fn layout(m: &NccMatcher) -> (usize, usize) {
        let [ww, _] = m.searched;
        (ww + WINDOW_PAD, (ww - m.tw + 1).next_multiple_of(BLOCK))
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_avx2_copy_gives_the_same_correlation() {
        if !crate::cpu::avx2_fma_or_skip() {
            return;
        }
        let (a, b) = (shifted([0.0, 0.0]), shifted([-6.0, 2.5]));
        let mut m = NccMatcher::new(32);
        assert!(m.set_template(&a, &Rect::new(150.0, 100.0, 150.0, 170.0)));
        m.search(&b, 0.5).unwrap();
        let (ws, nxp) = layout(&m);
        let rows = m.num.len() / nxp;
        m.correlate_body(ws, nxp / BLOCK, rows);
        let portable = m.num.clone();
        #[allow(unsafe_code)]
        // SAFETY: the CPU has AVX2 and FMA (checked above).
        unsafe {
            m.correlate_avx2(ws, nxp / BLOCK, rows)
        };
        assert_eq!(portable, m.num);
    }

    #[test]
    fn degenerate_inputs_give_no_template_or_no_match() {
        let a = shifted([0.0, 0.0]);
        let mut m = NccMatcher::new(32);
        assert!(!m.set_template(&a, &Rect::new(700.0, 10.0, 50.0, 50.0)));
        assert!(!m.set_template(&a, &Rect::new(10.0, 10.0, 3.0, 3.0)));
        assert!(!m.set_template(&a, &Rect::new(f32::NAN, 10.0, 50.0, 50.0)));
        assert!(m.search(&a, 0.5).is_none());
        let flat = GrayImage::new(640, 480);
        assert!(!m.set_template(&flat, &Rect::new(100.0, 100.0, 80.0, 80.0)));
        // A flat search window scores 0, never a match.
        assert!(m.set_template(&a, &Rect::new(100.0, 100.0, 80.0, 80.0)));
        let hit = m.search(&flat, 0.5).unwrap();
        assert_eq!(hit.score, 0.0);
        // A region hanging over the border still tracks by its inside part.
        let b = shifted([5.0, 3.0]);
        assert!(m.set_template(&a, &Rect::new(-30.0, -20.0, 120.0, 120.0)));
        let hit = m.search(&b, 0.3).unwrap();
        let tol = 0.5 * m.factor() as f32;
        assert!((hit.shift[0] - 5.0).abs() < tol && (hit.shift[1] - 3.0).abs() < tol);
    }
}
