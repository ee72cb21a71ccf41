//! Normalised cross-correlation (NCC) template matching at a reduced scale — the fast tracker's
//! region step (thesis 4.3.2): the face region of the previous frame is cut as a template and found
//! again in a search window around its old place in the new frame.
//!
//! Both the template and the window are box-decimated by one integer factor `f` chosen so the
//! template's larger side is about [`NccMatcher::template_px`] pixels; the cost is then independent of
//! the face size. Window sums and sums of squares come from integral images, so each candidate offset
//! costs one dot product with the zero-mean template; those of many offsets are computed together,
//! blocks of offsets at a time in vector registers (f32 sums).
//!
//! Coarse to fine: where the template is at least 16 cells a side, every offset is scored at half
//! that scale (2×2 means of the cells: a quarter of the offsets, each a quarter of the work) and
//! only 4×4 fine offsets around each of the three best coarse peaks at the fine one (the same
//! peaks as the exhaustive search in the tests; `ncc_search_640x480` in `BENCHMARKS.md` times
//! it). The
//! peak is refined to sub-pixel by a parabola through its neighbours along x and y, and the shift is
//! returned in full-resolution pixels.
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

/// Smallest coarse template side (cells) for the coarse-to-fine search; smaller templates are
/// searched exhaustively at the one scale.
const MIN_COARSE_CELLS: usize = 8;

/// Fine offsets tried around a coarse peak, each way (the peak's two fine offsets plus this many
/// on either side; the four fit one row group of the correlation kernel).
const FINE_REACH: usize = 1;

/// Coarse peaks refined at the fine scale: at half scale a template's fine texture blurs, and the
/// best coarse peak need not be the best fine one (a two-face test sequence on a sine texture
/// lost its track with one).
const COARSE_PEAKS: usize = 3;

/// Template matcher. Holds one template and every buffer, reused across frames.
#[derive(Debug, Clone)]
pub struct NccMatcher {
    template_px: usize,
    /// The region the template was cut for (may extend past the image).
    region: Rect,
    /// Full-resolution integer top-left corner of the part of the region inside the image.
    origin: [i64; 2],
    factor: usize,
    /// The search at the decimated scale.
    fine: Level,
    /// The same at half that scale (2×2 means of `fine`'s cells), where the template is large
    /// enough: every offset is scored here, then only those near its peak at the fine scale.
    coarse: Level,
    coarse_to_fine: bool,
    has_template: bool,
    bands: Bands,
    /// The coarse scores and peaks of the last coarse-to-fine search.
    scores: Vec<f64>,
    peaks: Vec<(usize, usize)>,
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

/// One scale of the search: a zero-mean template, the window it is looked for in, the window's
/// integral images and, after an exhaustive search, the correlation at every offset.
#[derive(Debug, Clone, Default)]
struct Level {
    /// Zero-mean template, row-major `tw × th`.
    template: Vec<f32>,
    tw: usize,
    th: usize,
    /// √Σ template².
    norm: f64,
    /// Window cells `ww × wh`, rows `ws` apart, zero past them (layout: [`Level::set_window`]), so the
    /// correlation's blocks of outputs read past the window's end without checks.
    window: Vec<f32>,
    ww: usize,
    wh: usize,
    ws: usize,
    integral: Vec<f64>,
    integral_sq: Vec<f64>,
    /// Correlation of the template with every offset, rows `nxp` (a `BLOCK` multiple) long.
    num: Vec<f32>,
    nxp: usize,
}

impl Level {
    /// Sets the window size (cells) and returns the buffer layout the correlation needs: rows
    /// `WINDOW_PAD` cells longer and the rows of offsets rounded up to `ROWS`.
    fn set_window(&mut self, ww: usize, wh: usize) -> Padded {
        self.ww = ww;
        self.wh = wh;
        self.ws = ww + WINDOW_PAD;
        let ny = wh + 1 - self.th;
        Padded {
            stride: self.ws,
            rows: ny.next_multiple_of(ROWS) + self.th - 1,
        }
    }

    /// Offsets along x and y (the window holds at least the template).
    fn offsets(&self) -> (usize, usize) {
        (self.ww + 1 - self.tw, self.wh + 1 - self.th)
    }

    /// Subtracts the template's mean and keeps its norm; `false` for a flat template.
    fn centre_template(&mut self) -> bool {
        let n = self.template.len() as f64;
        let mean = self.template.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let mut ss = 0.0;
        for v in &mut self.template {
            *v -= mean as f32;
            ss += f64::from(*v) * f64::from(*v);
        }
        self.norm = ss.sqrt();
        ss / n >= FLAT_STD * FLAT_STD
    }

    fn integrals(&mut self) {
        integrals(
            &self.window,
            self.ww,
            self.wh,
            self.ws,
            &mut self.integral,
            &mut self.integral_sq,
        );
    }

    /// NCC at offset (i, j) from the template·window sum there; 0 on a flat window part.
    fn ncc(&self, i: usize, j: usize, num: f64) -> f64 {
        let (tw, th) = (self.tw, self.th);
        let stride = self.ww + 1;
        let box_sum = |t: &[f64]| {
            t[(j + th) * stride + i + tw] - t[j * stride + i + tw] - t[(j + th) * stride + i]
                + t[j * stride + i]
        };
        let n = (tw * th) as f64;
        let s = box_sum(&self.integral);
        let ss = box_sum(&self.integral_sq);
        let var = ss - s * s / n;
        if var < FLAT_STD * FLAT_STD * n {
            return 0.0;
        }
        // Σ t'·I equals Σ t'·(I − mean) because the template is zero-mean.
        num / (self.norm * var.sqrt())
    }

    /// NCC at (i, j) from the exhaustive correlation.
    fn ncc_correlated(&self, i: usize, j: usize) -> f64 {
        self.ncc(i, j, f64::from(self.num[j * self.nxp + i]))
    }

    /// NCC at (i, j) from one direct dot product (f32 lanes, then f64 per row).
    fn ncc_direct(&self, i: usize, j: usize) -> f64 {
        let tw = self.tw;
        let mut num = 0.0f64;
        for v in 0..self.th {
            let t = &self.template[v * tw..(v + 1) * tw];
            let at = (j + v) * self.ws + i;
            let w = &self.window[at..at + tw];
            let mut lanes = [0.0f32; BLOCK];
            let (tc, wc) = (t.chunks_exact(BLOCK), w.chunks_exact(BLOCK));
            let (tr, wr) = (tc.remainder(), wc.remainder());
            for (a, b) in tc.zip(wc) {
                for k in 0..BLOCK {
                    lanes[k] += a[k] * b[k];
                }
            }
            let row: f32 =
                lanes.iter().sum::<f32>() + tr.iter().zip(wr).map(|(a, b)| a * b).sum::<f32>();
            num += f64::from(row);
        }
        self.ncc(i, j, num)
    }

    /// After [`Level::correlate_all`]: the offsets of the `k` best local peaks into `out`, best
    /// first — each the best of what the ones before leave, apart by at least two offsets
    /// along x or y (its 3×3 neighbours are not peaks of their own).
    fn peaks(&self, k: usize, scores: &mut Vec<f64>, out: &mut Vec<(usize, usize)>) {
        let (nx, ny) = self.offsets();
        scores.clear();
        for j in 0..ny {
            for i in 0..nx {
                scores.push(self.ncc_correlated(i, j));
            }
        }
        out.clear();
        for _ in 0..k {
            let Some((at, &s)) = scores.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else {
                break;
            };
            if !s.is_finite() {
                break;
            }
            let (i, j) = (at % nx, at / nx);
            out.push((i, j));
            for y in j.saturating_sub(1)..(j + 2).min(ny) {
                for x in i.saturating_sub(1)..(i + 2).min(nx) {
                    scores[y * nx + x] = f64::NEG_INFINITY;
                }
            }
        }
    }

    /// Correlates the template with the window at every offset.
    fn correlate_all(&mut self) {
        let (nx, ny) = self.offsets();
        self.correlate([0, 0], nx.div_ceil(BLOCK), ny.next_multiple_of(ROWS));
    }

    /// The best (NCC, i, j) over offsets `xs × ys` (each range at most `BLOCK` × `ROWS` long):
    /// one block of the correlation kernel.
    fn best_in(
        &mut self,
        xs: std::ops::Range<usize>,
        ys: std::ops::Range<usize>,
    ) -> (f64, usize, usize) {
        let (_, ny) = self.offsets();
        debug_assert!(xs.len() <= BLOCK && ys.len() <= ROWS && xs.end <= self.offsets().0);
        // The kernel's rows of offsets must stay within the window's padded rows (`set_window`):
        // start higher where the range ends near them.
        let y0 = ys.start.min(ny.next_multiple_of(ROWS) - ROWS);
        self.correlate([xs.start, y0], 1, ROWS);
        let mut best = (f64::NEG_INFINITY, 0usize, 0usize);
        for j in ys {
            for i in xs.clone() {
                let num = f64::from(self.num[(j - y0) * self.nxp + i - xs.start]);
                let s = self.ncc(i, j, num);
                if s > best.0 {
                    best = (s, i, j);
                }
            }
        }
        best
    }

    /// Correlates every offset and returns the best (NCC, i, j).
    fn exhaustive(&mut self) -> (f64, usize, usize) {
        self.correlate_all();
        let (nx, ny) = self.offsets();
        let mut best = (f64::NEG_INFINITY, 0usize, 0usize);
        for j in 0..ny {
            for i in 0..nx {
                let s = self.ncc_correlated(i, j);
                if s > best.0 {
                    best = (s, i, j);
                }
            }
        }
        best
    }

    crate::kernels::cpu::with_avx2_copy! {
        /// Correlates the template with the window at `blocks × BLOCK` offsets along x and `rows`
        /// (a multiple of `ROWS`) along y from offset `at`, into `num` (offset `at + (i, j)` at
        /// `j · nxp + i`). Offsets past the window's last one read its zero padding; their sums
        /// are computed and never read.
        fn correlate / correlate_avx2 (&mut self, at: [usize; 2], blocks: usize, rows: usize)
            => correlate_body
    }

    /// Written as output vectors rather than one dot product per offset: each template cell is
    /// multiplied into `ROWS × BLOCK` sums held in registers, one broadcast and `ROWS` unaligned
    /// loads per cell, where a dot product per offset spends its time on short rows (the decimated
    /// template is ≈ 30 cells wide) and reductions.
    #[inline(always)]
    fn correlate_body(&mut self, [x0, y0]: [usize; 2], blocks: usize, rows: usize) {
        let (tw, th, ws) = (self.tw, self.th, self.ws);
        let nxp = blocks * BLOCK;
        self.nxp = nxp;
        self.num.clear();
        self.num.resize(nxp * rows, 0.0);
        // The reads stay inside the window's rows of `ws` cells (`set_window`).
        assert!(ws >= x0 + nxp + tw - 1 && self.window.len() >= (y0 + rows + th - 1) * ws);
        assert!(rows.is_multiple_of(ROWS) && self.template.len() == tw * th);
        for j in (0..rows).step_by(ROWS) {
            for b in 0..blocks {
                let i0 = b * BLOCK;
                let mut acc = [[0.0f32; BLOCK]; ROWS];
                for v in 0..th {
                    let trow = &self.template[v * tw..(v + 1) * tw];
                    let srcs: [&[f32]; ROWS] = std::array::from_fn(|r| {
                        let start = (y0 + j + r + v) * ws + x0 + i0;
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

/// Writes the 2×2 means of `src`'s cells (`w × h`, rows `stride` apart) into `out` (`w/2 × h/2`
/// cells, laid out as `pad` says, zero elsewhere).
fn halve(src: &[f32], w: usize, h: usize, stride: usize, pad: Padded, out: &mut Vec<f32>) {
    let (cw, ch) = (w / 2, h / 2);
    assert!(pad.stride >= cw && pad.rows >= ch && src.len() >= h * stride);
    out.clear();
    out.resize(pad.stride * pad.rows, 0.0);
    for r in 0..ch {
        let (a, b) = (&src[2 * r * stride..], &src[(2 * r + 1) * stride..]);
        for (c, o) in out[r * pad.stride..r * pad.stride + cw]
            .iter_mut()
            .enumerate()
        {
            *o = 0.25 * ((a[2 * c] + a[2 * c + 1]) + (b[2 * c] + b[2 * c + 1]));
        }
    }
}

impl NccMatcher {
    /// A matcher whose decimated template has its larger side near `template_px` (clamped to ≥ 8).
    pub fn new(template_px: usize) -> Self {
        Self {
            template_px: template_px.max(8),
            region: Rect::default(),
            origin: [0, 0],
            factor: 1,
            fine: Level::default(),
            coarse: Level::default(),
            coarse_to_fine: false,
            has_template: false,
            bands: Bands::default(),
            scores: Vec::new(),
            peaks: Vec::new(),
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
        let fine = &mut self.fine;
        self.bands.decimate(
            image,
            cells,
            Padded {
                stride: tw,
                rows: th,
            },
            &mut fine.template,
        );
        (fine.tw, fine.th) = (tw, th);
        if !fine.centre_template() {
            return false;
        }
        let coarse = &mut self.coarse;
        (coarse.tw, coarse.th) = (tw / 2, th / 2);
        self.coarse_to_fine = coarse.tw >= MIN_COARSE_CELLS && coarse.th >= MIN_COARSE_CELLS;
        if self.coarse_to_fine {
            let pad = Padded {
                stride: coarse.tw,
                rows: coarse.th,
            };
            halve(&fine.template, tw, th, tw, pad, &mut coarse.template);
            // A template flat at half scale (fine stripes) is searched at the fine scale alone.
            self.coarse_to_fine = coarse.centre_template();
        }
        self.region = *region;
        self.origin = [x0, y0];
        self.factor = factor;
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
        let (tw, th) = (self.fine.tw, self.fine.th);
        let m = (margin * self.region.w.max(self.region.h)).ceil() as i64;
        let (iw, ih) = (image.width() as i64, image.height() as i64);
        let wx0 = (self.origin[0] - m).max(0);
        let wy0 = (self.origin[1] - m).max(0);
        let wx1 = (self.origin[0] + (tw * f) as i64 + m).min(iw);
        let wy1 = (self.origin[1] + (th * f) as i64 + m).min(ih);
        if wx1 <= wx0 || wy1 <= wy0 {
            return None;
        }
        let ww = (wx1 - wx0) as usize / f;
        let wh = (wy1 - wy0) as usize / f;
        if ww < tw || wh < th {
            return None;
        }
        let cells = Cells {
            x0: wx0 as usize,
            y0: wy0 as usize,
            cols: ww,
            rows: wh,
            f,
        };
        let pad = self.fine.set_window(ww, wh);
        self.bands
            .decimate(image, cells, pad, &mut self.fine.window);
        self.fine.integrals();
        let (nx, ny) = self.fine.offsets();

        let coarse = self.coarse_to_fine && ww / 2 >= self.coarse.tw && wh / 2 >= self.coarse.th;
        let (peak, bi, bj) = if coarse {
            let c = &mut self.coarse;
            let pad = c.set_window(ww / 2, wh / 2);
            halve(&self.fine.window, ww, wh, self.fine.ws, pad, &mut c.window);
            c.integrals();
            c.correlate_all();
            c.peaks(COARSE_PEAKS, &mut self.scores, &mut self.peaks);
            // Coarse offset k covers fine offsets 2k and 2k + 1.
            let span = |k: usize, n: usize| {
                (2 * k).saturating_sub(FINE_REACH)..(2 * k + 2 + FINE_REACH).min(n)
            };
            let mut best = (f64::NEG_INFINITY, 0usize, 0usize);
            for &(ci, cj) in &self.peaks {
                let b = self.fine.best_in(span(ci, nx), span(cj, ny));
                if b.0 > best.0 {
                    best = b;
                }
            }
            best
        } else {
            self.fine.exhaustive()
        };
        if !peak.is_finite() {
            return None;
        }
        let fine = &self.fine;
        let score_at = |i: usize, j: usize| {
            if coarse {
                fine.ncc_direct(i, j)
            } else {
                fine.ncc_correlated(i, j)
            }
        };
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
}

/// Column sums of a band of rows, kept across frames ([`Bands::decimate`]).
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

impl Bands {
    crate::kernels::cpu::with_avx2_copy! {
        /// The block means of `cells`, laid out as `pad` says.
        fn decimate / decimate_avx2 (&mut self, image: &GrayImage, cells: Cells, pad: Padded,
            out: &mut Vec<f32>) => decimate_body
    }

    #[inline(always)]
    fn decimate_body(&mut self, image: &GrayImage, cells: Cells, pad: Padded, out: &mut Vec<f32>) {
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
        // Column sums of each band of `f` rows first (wide integer adds the compiler vectorises),
        // then the `f`-wide groups of each band: summing `f`-pixel chunks row by row instead
        // measured 2× slower for the whole search. u16 holds a band's column sum while `f · 255`
        // fits.
        if f * 255 <= usize::from(u16::MAX) {
            decimate_bands(image, cells, stride, &mut self.narrow, out);
        } else {
            decimate_bands(image, cells, stride, &mut self.wide, out);
        }
    }
}

/// [`Bands::decimate`] for `f > 1` (rows `stride` apart), column sums of each band of rows in `T` (see
/// there).
#[inline(always)]
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
    // Columns a chunk at a time, the chunk's sums kept in registers over the band's rows: summing
    // whole rows into the band instead loaded and stored it once per row, and that store
    // dominated a large search.
    const CHUNK: usize = 32;
    for r in 0..rows {
        let srcs = (0..f).map(|dy| &image.row(y0 + r * f + dy)[x0..x0 + cols * f]);
        let mut chunks = band.chunks_exact_mut(CHUNK);
        let mut at = 0;
        for b in &mut chunks {
            let mut acc = [T::default(); CHUNK];
            for src in srcs.clone() {
                let src: &[u8; CHUNK] = src[at..at + CHUNK].try_into().expect("chunk");
                for (a, &v) in acc.iter_mut().zip(src) {
                    *a += T::from(v);
                }
            }
            b.copy_from_slice(&acc);
            at += CHUNK;
        }
        let rest = chunks.into_remainder();
        rest.fill(T::default());
        for src in srcs {
            for (b, &v) in rest.iter_mut().zip(&src[at..]) {
                *b += T::from(v);
            }
        }
        let dst = &mut out[r * stride..r * stride + cols];
        // The common factors with the group width known to the compiler: a loop of unknown trip
        // count per cell took half of the decimation's time.
        // (Factor 12 is a 384 px face at the default 32-cell template.)
        match f {
            2 => group_means::<T, 2>(band, inv, dst),
            3 => group_means::<T, 3>(band, inv, dst),
            4 => group_means::<T, 4>(band, inv, dst),
            5 => group_means::<T, 5>(band, inv, dst),
            6 => group_means::<T, 6>(band, inv, dst),
            7 => group_means::<T, 7>(band, inv, dst),
            8 => group_means::<T, 8>(band, inv, dst),
            9 => group_means::<T, 9>(band, inv, dst),
            10 => group_means::<T, 10>(band, inv, dst),
            11 => group_means::<T, 11>(band, inv, dst),
            12 => group_means::<T, 12>(band, inv, dst),
            _ => {
                for (o, group) in dst.iter_mut().zip(band.chunks_exact(f)) {
                    *o = group.iter().map(|&v| v.into()).sum::<u32>() as f32 * inv;
                }
            }
        }
    }
}

/// `dst[c]` = the sum of `band[c·F .. (c + 1)·F]` times `inv`, the sum in `u32` in index order
/// (as the general loop of [`decimate_bands`]).
#[inline(always)]
fn group_means<T, const F: usize>(band: &[T], inv: f32, dst: &mut [f32])
where
    T: Copy + Into<u32>,
{
    for (o, group) in dst.iter_mut().zip(band.chunks_exact(F)) {
        let group: &[T; F] = group.try_into().expect("group");
        let sum = group.iter().fold(0u32, |a, &v| a + v.into());
        *o = sum as f32 * inv;
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
    // Only the first row and column need zeros: every other entry is written below (clearing
    // the whole of both images first was a memset as large as the images, each search).
    for t in [&mut *sum, &mut *sq] {
        t.resize(stride * (h + 1), 0.0);
        t[..stride].fill(0.0);
        for row in t.chunks_exact_mut(stride) {
            row[0] = 0.0;
        }
    }
    // Each row's running sums are one chain of dependent adds; four rows at a time keep four
    // chains in flight (the same operations per value, so the same bits as row by row).
    let mut y0 = 0;
    while y0 + 4 <= h {
        integrate_rows::<4>(src, w, stride_src, y0, sum, sq);
        y0 += 4;
    }
    for y in y0..h {
        integrate_rows::<1>(src, w, stride_src, y, sum, sq);
    }
}

/// Rows `y0 + 1 ..= y0 + R` of [`integrals`]' two images (rows `w + 1` apart) from the rows
/// above them and source rows `y0 .. y0 + R`.
#[inline(always)]
fn integrate_rows<const R: usize>(
    src: &[f32],
    w: usize,
    stride_src: usize,
    y0: usize,
    sum: &mut [f64],
    sq: &mut [f64],
) {
    let stride = w + 1;
    let (mut rs, mut rq) = ([0.0f64; R], [0.0f64; R]);
    for x in 0..w {
        for k in 0..R {
            let y = y0 + k;
            let v = f64::from(src[y * stride_src + x]);
            rs[k] += v;
            rq[k] += v * v;
            sum[(y + 1) * stride + x + 1] = sum[y * stride + x + 1] + rs[k];
            sq[(y + 1) * stride + x + 1] = sq[y * stride + x + 1] + rq[k];
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

    /// The level the last search correlated at every offset: the coarse one where the template
    /// allows the coarse-to-fine search.
    fn correlated(m: &NccMatcher) -> &Level {
        if m.coarse_to_fine { &m.coarse } else { &m.fine }
    }

    /// The correlation of every offset the search reads against direct f64 sums over the template
    /// and the window, for template sizes that leave blocks and row groups partly filled, at both
    /// scales.
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
        let mut scales = [0; 2];
        for (region, px, margin) in cases {
            let mut m = NccMatcher::new(px);
            assert!(m.set_template(&a, &region));
            let hit = m.search(&b, margin).unwrap();
            scales[usize::from(m.coarse_to_fine)] += 1;
            let l = correlated(&m);
            let (tw, th, nxp) = (l.tw, l.th, l.nxp);
            let (nx, ny) = l.offsets();
            assert!(l.num.len() >= ny * nxp && nxp >= nx);
            let mut checked = 0;
            for j in 0..ny {
                for i in 0..nx {
                    let (mut direct, mut scale) = (0.0f64, 0.0f64);
                    for v in 0..th {
                        for u in 0..tw {
                            let t = f64::from(l.template[v * tw + u]);
                            let w = f64::from(l.window[(j + v) * l.ws + i + u]);
                            direct += t * w;
                            scale += (t * w).abs();
                        }
                    }
                    let got = f64::from(l.num[j * nxp + i]);
                    assert!(
                        (got - direct).abs() <= 1e-5 * scale,
                        "{region:?} ({i}, {j}): {got} vs {direct}"
                    );
                    // The direct dot product of the fine stage gives the same score.
                    let (s0, s1) = (l.ncc_correlated(i, j), l.ncc_direct(i, j));
                    assert!(
                        (s0 - s1).abs() < 1e-5,
                        "{region:?} ({i}, {j}): {s0} vs {s1}"
                    );
                    checked += 1;
                }
            }
            assert!(
                checked > 40 && hit.score > 0.9,
                "{region:?}: {checked} {hit:?}"
            );
        }
        assert!(scales[0] > 0 && scales[1] > 0, "{scales:?}");
    }

    /// The fine stage's kernel blocks (any origin, rows started higher near the window's end)
    /// against one dot product per offset.
    #[test]
    fn blocks_of_offsets_equal_direct_scores() {
        let (a, b) = (shifted([0.0, 0.0]), shifted([3.0, 5.5]));
        let mut m = NccMatcher::new(32);
        assert!(m.set_template(&a, &Rect::new(180.0, 120.0, 180.0, 200.0)));
        m.search(&b, 0.5).unwrap();
        let l = &mut m.fine;
        let (nx, ny) = l.offsets();
        let mut tried = 0;
        for (x0, y0) in [
            (0, 0),
            (5, 7),
            (nx - 4, ny - 4),
            (nx - 1, ny - 1),
            (nx - 3, 0),
        ] {
            let (xs, ys) = (x0..(x0 + 4).min(nx), y0..(y0 + 4).min(ny));
            let mut want = (f64::NEG_INFINITY, 0, 0);
            for j in ys.clone() {
                for i in xs.clone() {
                    let s = l.ncc_direct(i, j);
                    if s > want.0 {
                        want = (s, i, j);
                    }
                }
            }
            let got = l.best_in(xs, ys);
            assert!(
                (got.0 - want.0).abs() < 1e-5 && (got.1, got.2) == (want.1, want.2),
                "({x0}, {y0}): {got:?} vs {want:?}"
            );
            tried += 1;
        }
        assert_eq!(tried, 5);
    }

    /// The coarse-to-fine search against the exhaustive one at the fine scale: the same peak and
    /// shift on textured frames, for face-sized regions, shifts up to the margin and a region over
    /// the border.
    #[test]
    fn coarse_to_fine_finds_the_exhaustive_peak() {
        let a = shifted([0.0, 0.0]);
        let regions = [
            Rect::new(180.0, 120.0, 180.0, 200.0),
            Rect::new(250.0, 180.0, 64.0, 64.0),
            Rect::new(-30.0, 300.0, 150.0, 160.0),
        ];
        let shifts = [
            [0.0f32, 0.0],
            [31.0, -22.0],
            [-45.5, 17.25],
            [6.5, -4.25],
            [-2.2, 9.9],
        ];
        let mut compared = 0;
        for region in regions {
            for s in shifts {
                let b = shifted(s);
                let mut m = NccMatcher::new(32);
                assert!(m.set_template(&a, &region));
                assert!(m.coarse_to_fine, "{region:?}");
                let fast = m.search(&b, 0.4).unwrap();
                m.coarse_to_fine = false;
                let full = m.search(&b, 0.4).unwrap();
                assert!(
                    (fast.shift[0] - full.shift[0]).abs() < 1e-3
                        && (fast.shift[1] - full.shift[1]).abs() < 1e-3
                        && (fast.score - full.score).abs() < 1e-5,
                    "{region:?} {s:?}: {fast:?} vs {full:?}"
                );
                compared += 1;
            }
        }
        assert_eq!(compared, 15);
    }

    /// Block means through band column sums, in u16 and in u32 (the path for factors past 257),
    /// against per-block sums, with and without padding of the rows.
    #[test]
    fn decimation_equals_block_means_in_both_sum_widths() {
        let img = shifted([1.5, -2.0]);
        // Every specialised group width, and 13 (the general loop).
        for (f, pad) in [
            (2, 0),
            (3, 5),
            (4, 2),
            (5, 8),
            (6, 0),
            (7, 1),
            (8, 3),
            (9, 0),
            (10, 1),
            (11, 4),
            (12, 2),
            (13, 0),
        ] {
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
            bands.decimate(&img, cells, layout, &mut narrow);
            // The portable body gives the same cells as the dispatched (AVX2) copy.
            let mut portable = Vec::new();
            bands.decimate_body(&img, cells, layout, &mut portable);
            assert_eq!(narrow, portable, "f {f}");
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

    #[cfg(target_arch = "x86_64")]
    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn the_avx2_copy_gives_the_same_correlation() {
        crate::kernels::cpu::assert_avx2_fma_path();
        let (a, b) = (shifted([0.0, 0.0]), shifted([-6.0, 2.5]));
        for px in [32, 12] {
            let mut m = NccMatcher::new(px);
            assert!(m.set_template(&a, &Rect::new(150.0, 100.0, 150.0, 170.0)));
            m.search(&b, 0.5).unwrap();
            let l = if m.coarse_to_fine {
                &mut m.coarse
            } else {
                &mut m.fine
            };
            let (blocks, rows) = (l.nxp / BLOCK, l.num.len() / l.nxp);
            l.correlate_body([0, 0], blocks, rows);
            let portable = l.num.clone();
            // The dispatched method runs the AVX2 copy here (the path is asserted above).
            l.correlate([0, 0], blocks, rows);
            assert_eq!(portable, l.num);
        }
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
