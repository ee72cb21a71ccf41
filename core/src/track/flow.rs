//! Pyramidal Lucas–Kanade optical flow (Bouguet's formulation) and the optical-flow landmark filter
//! of the thesis' Algorithm 8.
//!
//! - [`Pyramid`]: 2×2 box-filtered image pyramid built into reused buffers.
//! - [`PyramidalLk`]: per point, iterative LK in a square window from the coarsest level down, with
//!   a status (lost: singular gradient matrix or left the image) and an error (mean absolute grey
//!   difference over the window) per point.
//!
//!   Cost: each iteration of a point waits on the last one's result, so the window kernels
//!   (`kernels::lk`: sampling, gradients and sums, in a portable form and NEON, AVX2 and AVX-512
//!   forms that give its bits) are written for latency, and four points go through the levels
//!   together and take their iterations in turn, so one point's sums overlap the next one's. The
//!   process's kernel choice picks the form (`MONOTRACK_KERNELS=native,flow=portable|avx2|avx512`,
//!   `kernels::choice`; the widest the CPU runs otherwise).
//!   [`PyramidalLk::track_guided`] starts each point at a guess (OpenCV's initial flow), so the
//!   levels need only cover the guess's error.
//! - [`FlowFilter`]: per landmark, takes the flow estimate from the previous frame's (filtered)
//!   landmarks when it lies within a threshold of the new detection, moved a little towards the
//!   detection (more the farther it is), else takes the detection. The flow follows real motion,
//!   so this removes detection jitter without adding lag; a landmark that moved farther than the
//!   threshold snaps to the detection at once, and an error the flow carries fades within frames.
//!   The flow starts at the detection: only a match near it is kept, so two levels serve whatever
//!   the face's motion.
//!
//! Coordinates follow [`crate::camera`]: pixel (i, j) covers [i, i+1)×[j, j+1). With 2×2 box
//! decimation that corner convention scales exactly: level l's coordinates are level 0's / 2^l.

use crate::error::{Error, Result};
use crate::image::{GrayImage, Rect};
use crate::kernels::lk::{Form, Windows};
use serde::{Deserialize, Serialize};

/// Smallest side a pyramid level may have; coarser levels carry too few pixels for a window.
pub const MIN_LEVEL_SIDE: usize = 16;

/// Lucas–Kanade settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LkConfig {
    /// Window half-size: the window is (2·h + 1)² pixels. 5 (11×11) balances cost and robustness
    /// for landmark-sized features; OpenCV's default 21×21 sums (21 / 11)² times the cells per
    /// iteration.
    pub half_window: usize,
    /// Pyramid levels including full resolution: L levels follow motions (or, guided, a guess's
    /// errors) up to about 2^(L−1) × the half window. 2: the flow filter starts each point at its
    /// detection ([`PyramidalLk::track_guided`]) and keeps flow only within a few pixels of it, so
    /// the levels need to cover the detection's error, not the face's motion (3 levels, unguided,
    /// tracked `track_eval`'s sequences no better, at a higher cost).
    pub levels: usize,
    /// Iterations per level at most.
    pub max_iterations: u32,
    /// Stop iterating when the update is below this many pixels.
    pub epsilon: f32,
    /// Smallest eigenvalue of the window's gradient matrix divided by the window area (grey levels²
    /// per pixel) under which a point is textureless and lost (OpenCV's `minEigThreshold` idea; its
    /// 1e-4 is on gradients scaled to 0..1, i.e. 6.5 in our 0..255 units — we take 1.0, since faces
    /// have gentle texture and the filter falls back to the detection anyway).
    pub min_eigenvalue: f32,
    /// Solve each window's motion together with a brightness offset between the two frames (the
    /// window's gradients taken about their mean), so a change of exposure does not read as
    /// motion. A window whose gradients about their mean fail `min_eigenvalue` (a single edge or
    /// a smooth ramp, where the offset and the motion cannot be told apart) is tracked as plain
    /// Lucas–Kanade. On by default: under changing light it cuts the still-face jitter behind the
    /// default flow filter at the same accuracy (BENCHMARKS.md, "The flow filter under changing
    /// light").
    pub offset_invariant: bool,
}

impl Default for LkConfig {
    fn default() -> Self {
        Self {
            half_window: 5,
            levels: 2,
            max_iterations: 10,
            epsilon: 0.01,
            min_eigenvalue: 1.0,
            offset_invariant: true,
        }
    }
}

impl LkConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for a window half-size outside 1..=15, levels outside 1..=6, zero
    /// iterations, or a non-finite or negative epsilon / eigenvalue threshold.
    pub fn validate(&self) -> Result<()> {
        if !(1..=15).contains(&self.half_window) {
            return Err(Error::InvalidConfig(format!(
                "lk.half_window must be 1..=15, got {}",
                self.half_window
            )));
        }
        if !(1..=6).contains(&self.levels) {
            return Err(Error::InvalidConfig(format!(
                "lk.levels must be 1..=6, got {}",
                self.levels
            )));
        }
        if self.max_iterations == 0 {
            return Err(Error::InvalidConfig("lk.max_iterations must be > 0".into()));
        }
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return Err(Error::InvalidConfig(format!(
                "lk.epsilon must be finite and > 0, got {}",
                self.epsilon
            )));
        }
        if !(self.min_eigenvalue.is_finite() && self.min_eigenvalue >= 0.0) {
            return Err(Error::InvalidConfig(format!(
                "lk.min_eigenvalue must be finite and >= 0, got {}",
                self.min_eigenvalue
            )));
        }
        Ok(())
    }
}

/// The smaller eigenvalue of the symmetric 2×2 matrix [[a, b], [b, c]] given as [a, b, c].
#[inline(always)]
fn smallest_eigenvalue([a, b, c]: [f32; 3]) -> f32 {
    0.5 * (a + c - ((a - c).powi(2) + 4.0 * b * b).sqrt())
}

/// An image pyramid: level 0 is a copy of the image, or of a region of it, each next level the 2×2
/// mean of the one before.
///
/// A region pyramid holds exactly the full pyramid's pixels inside the region: its origin is a
/// multiple of 2^(levels − 1) so every 2×2 block is the full pyramid's block. Points stay in the
/// frame's level-0 pixels; [`Pyramid::origin`] maps them into the stored levels.
#[derive(Debug, Clone, Default)]
pub struct Pyramid {
    levels: Vec<GrayImage>,
    n: usize,
    /// Level 0's top-left pixel in the frame.
    origin: [usize; 2],
    /// The frame's size.
    frame: (usize, usize),
}

impl Pyramid {
    /// An empty pyramid.
    pub fn new() -> Self {
        Self::default()
    }

    /// Rebuilds from the whole of `image` with up to `levels` levels (fewer when a level would get
    /// smaller than [`MIN_LEVEL_SIDE`]), reusing the buffers.
    pub fn build(&mut self, image: &GrayImage, levels: usize) {
        let (w, h) = (image.width(), image.height());
        self.build_region(image, levels, &Rect::new(0.0, 0.0, w as f32, h as f32));
    }

    /// Rebuilds like [`Pyramid::build`] but stores only the pixels around `region` (frame pixels;
    /// widened to the level grid and to [`MIN_LEVEL_SIDE`] at the coarsest level, clipped to the
    /// frame). The number of levels is the whole frame's, so pyramids of one frame size always
    /// match. Why: the flow reads only windows around the face, so copying and halving the rest of
    /// the frame would be wasted work (`pyramid_*` benches).
    pub fn build_region(&mut self, image: &GrayImage, levels: usize, region: &Rect) {
        let (w, h) = (image.width(), image.height());
        let levels = levels.max(1);
        let mut n = 1;
        while n < levels && (w >> n) >= MIN_LEVEL_SIDE && (h >> n) >= MIN_LEVEL_SIDE {
            n += 1;
        }
        let a = 1usize << (n - 1);
        let span = |lo: f32, len: f32, full: usize| -> (usize, usize) {
            let need = (MIN_LEVEL_SIDE * a).min(full);
            // The end from the region's own start: ceil(x + w), not floor(x) + w, which could
            // stop a pixel short of a fractional region.
            let hi = if (lo + len).is_finite() {
                (lo + len).ceil().max(0.0)
            } else {
                full as f32
            };
            let lo = if lo.is_finite() {
                lo.floor().max(0.0)
            } else {
                0.0
            };
            let (mut lo, mut hi) = ((lo as usize).min(full), (hi as usize).min(full));
            if hi < lo + need {
                // Centre the minimum span on the region, inside the frame.
                let mid = (lo + hi) / 2;
                lo = mid.saturating_sub(need / 2).min(full - need);
                hi = lo + need;
            }
            let lo = lo / a * a;
            let hi = hi.next_multiple_of(a).min(full);
            (lo, hi)
        };
        let (x0, x1) = span(region.x, region.w, w);
        let (y0, y1) = span(region.y, region.h, h);
        self.origin = [x0, y0];
        self.frame = (w, h);
        self.halve(image, n, [x0, y0, x1, y1]);
    }

    crate::kernels::cpu::with_avx2_copy! {
        /// Copies the frame's `[x0, y0, x1, y1)` into level 0 and halves it `n − 1` times.
        fn halve / halve_avx2 (&mut self, image: &GrayImage, n: usize, roi: [usize; 4]) => halve_body
    }

    #[inline(always)]
    fn halve_body(&mut self, image: &GrayImage, n: usize, [x0, y0, x1, y1]: [usize; 4]) {
        while self.levels.len() < n {
            self.levels.push(GrayImage::default());
        }
        let (rw, rh) = (x1 - x0, y1 - y0);
        let l0 = &mut self.levels[0];
        l0.resize(rw, rh);
        let iw = image.width();
        for (y, row) in l0.data_mut().chunks_exact_mut(rw.max(1)).enumerate() {
            let at = (y0 + y) * iw + x0;
            row.copy_from_slice(&image.data()[at..at + rw]);
        }
        self.n = 1;
        for l in 1..n {
            let (w, h) = (
                self.levels[l - 1].width() / 2,
                self.levels[l - 1].height() / 2,
            );
            let (lo, hi) = self.levels.split_at_mut(l);
            let src = &lo[l - 1];
            let dst = &mut hi[0];
            dst.resize(w, h);
            let sw = src.width();
            for y in 0..h {
                let r0 = &src.data()[2 * y * sw..2 * y * sw + 2 * w];
                let r1 = &src.data()[(2 * y + 1) * sw..(2 * y + 1) * sw + 2 * w];
                let d = &mut dst.data_mut()[y * w..(y + 1) * w];
                for (x, o) in d.iter_mut().enumerate() {
                    let s = u16::from(r0[2 * x])
                        + u16::from(r0[2 * x + 1])
                        + u16::from(r1[2 * x])
                        + u16::from(r1[2 * x + 1]);
                    *o = ((s + 2) >> 2) as u8;
                }
            }
            self.n = l + 1;
        }
    }

    /// Level 0's top-left pixel in the frame (level l's is this / 2^l, exactly).
    pub fn origin(&self) -> [usize; 2] {
        self.origin
    }

    /// Number of built levels.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether nothing was built yet.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The built levels, finest first.
    pub fn levels(&self) -> &[GrayImage] {
        &self.levels[..self.n]
    }

    /// The frame's full-resolution size (0, 0 when empty).
    pub fn size(&self) -> (usize, usize) {
        if self.n == 0 { (0, 0) } else { self.frame }
    }
}

/// Pyramidal Lucas–Kanade point tracker; holds its window buffers.
#[derive(Debug, Clone)]
pub struct PyramidalLk {
    config: LkConfig,
    /// One window per point of a batch ([`BATCH`]), filled by the kernels' chosen form.
    windows: Windows,
}

/// Points tracked together ([`PyramidalLk::track_batch`]); each has its own patch and gradients.
const BATCH: usize = 4;

/// One point of a batch on its way through the levels.
#[derive(Debug, Clone, Copy, Default)]
struct Point {
    p: [f32; 2],
    /// Tracking this point (not yet lost).
    alive: bool,
    /// Done iterating at this level.
    done: bool,
    g: [f32; 2],
    d: [f32; 2],
    /// Σ |patch − moving| of the last window compared; at the end, level 0's.
    sad: f32,
    /// This level's window origin in the next image (before g + d) and gradient matrix.
    at: [f32; 2],
    gm: [f32; 3],
    inv_det: f32,
}

impl Point {
    /// A batch's points at the coarsest of `levels` levels, each moving by its guess's motion
    /// scaled to that level (no motion without a guess, or where the guess is not finite); the
    /// slots past `points` stay lost.
    #[inline(always)]
    fn start(points: &[[f32; 2]], guess: Option<&[[f32; 2]]>, levels: usize) -> [Point; BATCH] {
        let mut pts = [Point::default(); BATCH];
        let top = 1.0 / (1u32 << (levels - 1)) as f32;
        for (i, (s, &p)) in pts.iter_mut().zip(points).enumerate() {
            let g = guess.map_or([0.0; 2], |q| {
                let g = [(q[i][0] - p[0]) * top, (q[i][1] - p[1]) * top];
                if g[0].is_finite() && g[1].is_finite() {
                    g
                } else {
                    [0.0; 2]
                }
            });
            *s = Point {
                p,
                g,
                alive: p[0].is_finite() && p[1].is_finite(),
                ..Point::default()
            };
        }
        pts
    }

    /// The point's result after level 0 (position, tracked, error): lost where it was lost or
    /// ended outside the `size` frame.
    #[inline(always)]
    fn result(&self, (w, h): (usize, usize), area: f32) -> ([f32; 2], bool, f32) {
        let out = [
            self.p[0] + self.g[0] + self.d[0],
            self.p[1] + self.g[1] + self.d[1],
        ];
        let inside = out[0].is_finite()
            && out[1].is_finite()
            && out[0] >= 0.0
            && out[1] >= 0.0
            && out[0] <= w as f32
            && out[1] <= h as f32;
        if self.alive && inside {
            (out, true, self.sad / area)
        } else {
            (self.p, false, f32::INFINITY)
        }
    }
}

impl PyramidalLk {
    /// A tracker with `config`.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] when the config is out of range ([`LkConfig::validate`]).
    pub fn new(config: LkConfig) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config,
            windows: Windows::new(2 * config.half_window + 1, BATCH, Form::chosen()),
        })
    }

    /// Settings.
    pub fn config(&self) -> &LkConfig {
        &self.config
    }

    /// Tracks `from` (points in `prev`'s level-0 pixels) into `next`, writing the new positions
    /// to `to`, whether each point was tracked to `status` and its mean absolute grey
    /// difference over the window to `error`. Lost points keep their old position in `to`.
    /// Each point starts at no motion, so the pyramid's levels bound the motion it follows.
    ///
    /// # Errors
    /// [`Error::InvalidInput`] when the slices differ in length, the pyramids are empty or
    /// differ in size or depth.
    pub fn track(
        &mut self,
        prev: &Pyramid,
        next: &Pyramid,
        from: &[[f32; 2]],
        to: &mut [[f32; 2]],
        status: &mut [bool],
        error: &mut [f32],
    ) -> Result<()> {
        self.track_with(prev, next, from, to, status, error, false)
    }

    /// [`PyramidalLk::track`] starting each point at its guess, which `to` holds on entry (as
    /// OpenCV's `OPTFLOW_USE_INITIAL_FLOW`): the levels then bound the guess's error, not the
    /// motion. A guess that is not finite counts as no motion.
    ///
    /// # Errors
    /// As [`PyramidalLk::track`].
    pub fn track_guided(
        &mut self,
        prev: &Pyramid,
        next: &Pyramid,
        from: &[[f32; 2]],
        to: &mut [[f32; 2]],
        status: &mut [bool],
        error: &mut [f32],
    ) -> Result<()> {
        self.track_with(prev, next, from, to, status, error, true)
    }

    crate::kernels::cpu::with_avx2_copy! {
        /// [`PyramidalLk::track`], or [`PyramidalLk::track_guided`] if `guided`.
        #[allow(clippy::too_many_arguments)]
        fn track_with / track_with_avx2 (&mut self, prev: &Pyramid, next: &Pyramid,
            from: &[[f32; 2]], to: &mut [[f32; 2]], status: &mut [bool], error: &mut [f32],
            guided: bool) -> Result<()>
            => track_body
    }

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn track_body(
        &mut self,
        prev: &Pyramid,
        next: &Pyramid,
        from: &[[f32; 2]],
        to: &mut [[f32; 2]],
        status: &mut [bool],
        error: &mut [f32],
        guided: bool,
    ) -> Result<()> {
        if to.len() != from.len() || status.len() != from.len() || error.len() != from.len() {
            return Err(Error::InvalidInput(format!(
                "optical flow: {} points but {} outputs, {} status, {} errors",
                from.len(),
                to.len(),
                status.len(),
                error.len()
            )));
        }
        if prev.is_empty() || prev.size() != next.size() || prev.len() != next.len() {
            return Err(Error::InvalidInput(format!(
                "optical flow: pyramids differ ({:?}, {} levels vs {:?}, {} levels)",
                prev.size(),
                prev.len(),
                next.size(),
                next.len()
            )));
        }
        for start in (0..from.len()).step_by(BATCH) {
            let end = (start + BATCH).min(from.len());
            let guess = guided.then(|| &to[start..end]);
            let results = self.track_batch(prev, next, &from[start..end], guess);
            for (i, &(p, ok, e)) in (start..end).zip(&results) {
                to[i] = if ok { p } else { from[i] };
                status[i] = ok;
                error[i] = e;
            }
        }
        Ok(())
    }

    /// Tracks up to [`BATCH`] points (position, tracked, error; the first `points.len()` of the
    /// returned ones), each exactly as alone: the points go through the levels together and take
    /// their iterations in turn, so the CPU overlaps one point's window sums with the next one's
    /// where a single point would wait on each iteration's result before the next can start. With
    /// `guess` (level-0 positions, one per point) each point's motion starts at its guess's,
    /// scaled to the coarsest level.
    #[inline(always)]
    fn track_batch(
        &mut self,
        prev: &Pyramid,
        next: &Pyramid,
        points: &[[f32; 2]],
        guess: Option<&[[f32; 2]]>,
    ) -> [([f32; 2], bool, f32); BATCH] {
        debug_assert!(points.len() <= BATCH);
        let mut pts = Point::start(points, guess, prev.len());
        let batch = &mut pts[..points.len()];
        for l in (0..prev.len()).rev() {
            self.start_level(prev, next, l, batch);
            self.iterate(&next.levels()[l], batch);
            if l > 0 {
                for s in batch.iter_mut() {
                    s.g = [2.0 * (s.g[0] + s.d[0]), 2.0 * (s.g[1] + s.d[1])];
                }
            }
        }
        let n = 2 * self.config.half_window + 1;
        let area = (n * n) as f32;
        pts.map(|s| s.result(next.size(), area))
    }

    /// Level `l`'s start for each point still tracked: its window's patch, gradients and gradient
    /// matrix from the previous image, where the window lies in the next one, and no motion yet
    /// at this level; a point whose window is textureless (or singular) is lost.
    #[inline(always)]
    fn start_level(&mut self, prev: &Pyramid, next: &Pyramid, l: usize, pts: &mut [Point]) {
        let cfg = self.config;
        let hw = cfg.half_window;
        let n = 2 * hw + 1;
        let area = (n * n) as f32;
        let scale = 1.0 / (1u32 << l) as f32;
        let pi = &prev.levels()[l];
        let (po, no) = (prev.origin(), next.origin());
        // The next pyramid's region starts elsewhere: its window moves by the difference.
        let (ox, oy) = (
            (po[0] >> l) as f32 - (no[0] >> l) as f32,
            (po[1] >> l) as f32 - (no[1] >> l) as f32,
        );
        for (slot, s) in pts.iter_mut().enumerate() {
            if !s.alive {
                continue;
            }
            // Window centre in the frame's pixel-index coordinates at this level (corner
            // convention → subtract 0.5), then in each stored region's.
            let fx = s.p[0] * scale - 0.5;
            let fy = s.p[1] * scale - 0.5;
            let (cx, cy) = (fx - (po[0] >> l) as f32, fy - (po[1] >> l) as f32);
            let mut sums =
                self.windows
                    .gradients(pi, cx - hw as f32 - 1.0, cy - hw as f32 - 1.0, slot);
            if cfg.offset_invariant {
                sums = self.centre_gradients(n, slot, sums);
            }
            let [gxx, gxy, gyy] = sums;
            let det = gxx * gyy - gxy * gxy;
            let min_eig = smallest_eigenvalue(sums);
            if min_eig / area < cfg.min_eigenvalue || det.abs() < f32::EPSILON {
                s.alive = false;
                continue;
            }
            s.inv_det = 1.0 / det;
            s.gm = [gxx, gxy, gyy];
            s.at = [cx + ox, cy + oy];
            s.d = [0.0, 0.0];
            s.done = false;
        }
    }

    /// The level's iterations in `next_level` (the next pyramid's level): each point still
    /// tracked and not yet settled takes one step per round, in turn, until every point has
    /// settled or the rounds run out.
    #[inline(always)]
    fn iterate(&mut self, next_level: &GrayImage, pts: &mut [Point]) {
        let cfg = self.config;
        let hw = cfg.half_window as f32;
        for _ in 0..cfg.max_iterations {
            let mut any = false;
            for (slot, s) in pts.iter_mut().enumerate() {
                if !s.alive || s.done {
                    continue;
                }
                any = true;
                let (g, d) = (s.g, s.d);
                let [bx, by, sad] = self.windows.mismatch(
                    next_level,
                    s.at[0] + g[0] + d[0] - hw,
                    s.at[1] + g[1] + d[1] - hw,
                    slot,
                );
                s.sad = sad;
                let [gxx, gxy, gyy] = s.gm;
                let ux = (gyy * bx - gxy * by) * s.inv_det;
                let uy = (gxx * by - gxy * bx) * s.inv_det;
                s.d[0] += ux;
                s.d[1] += uy;
                s.done = ux * ux + uy * uy < cfg.epsilon * cfg.epsilon;
            }
            if !any {
                break;
            }
        }
    }

    /// The window's gradients in `slot` taken about their mean, and their matrix
    /// Σ g·gᵀ − N·ḡ·ḡᵀ, when that matrix keeps a smallest eigenvalue of `min_eigenvalue` per pixel;
    /// else `sums` with the gradients left as they are.
    ///
    /// Why this solves for a brightness offset β with the motion: the least-squares system of
    /// Σ (I − J − g·d − β)² eliminates β as Σ (g − ḡ)(g − ḡ)ᵀ · d = Σ (g − ḡ) · (I − J), so the
    /// mismatch kernels, summing the stored gradients times the difference, need no change.
    /// Plain code: n² subtractions per window and level, beside the kernels' n² per iteration.
    #[inline(always)]
    fn centre_gradients(&mut self, n: usize, slot: usize, sums: [f32; 3]) -> [f32; 3] {
        let st = self.windows.stride();
        let [gx, gy] = self.windows.gradients_mut(slot);
        let (mut sx, mut sy) = (0.0f32, 0.0f32);
        for r in 0..n {
            sx += gx[r * st..r * st + n].iter().sum::<f32>();
            sy += gy[r * st..r * st + n].iter().sum::<f32>();
        }
        let area = (n * n) as f32;
        let (mx, my) = (sx / area, sy / area);
        let c = [sums[0] - sx * mx, sums[1] - sx * my, sums[2] - sy * my];
        let min_eig = smallest_eigenvalue(c);
        // NaN (a non-finite window) falls back too.
        if min_eig.is_nan() || min_eig / area < self.config.min_eigenvalue {
            return sums;
        }
        // Only the window's n columns: the padding past them stays zero, which is what keeps it
        // out of the mismatch sums.
        for r in 0..n {
            gx[r * st..r * st + n].iter_mut().for_each(|v| *v -= mx);
            gy[r * st..r * st + n].iter_mut().for_each(|v| *v -= my);
        }
        c
    }
}

/// The optical-flow landmark filter (thesis Alg. 8), one per tracked face.
#[derive(Debug, Clone)]
pub struct FlowFilter {
    lk: PyramidalLk,
    prev: Vec<[f32; 2]>,
    flow: Vec<[f32; 2]>,
    status: Vec<bool>,
    error: Vec<f32>,
    has_prev: bool,
}

impl FlowFilter {
    /// A filter whose flow uses `config`.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for an out-of-range [`LkConfig`].
    pub fn new(config: LkConfig) -> Result<Self> {
        Ok(Self {
            lk: PyramidalLk::new(config)?,
            prev: Vec::new(),
            flow: Vec::new(),
            status: Vec::new(),
            error: Vec::new(),
            has_prev: false,
        })
    }

    /// Forgets the previous landmarks (a new track starts).
    pub fn reset(&mut self) {
        self.has_prev = false;
    }

    /// Whether previous landmarks are held.
    pub fn has_previous(&self) -> bool {
        self.has_prev
    }

    /// Filters `points` (the new detection, in `next`'s pixels) in place. Where the flow of the
    /// previous output from `prev` to `next` was tracked and lies within `threshold_px` of the
    /// detection, the point becomes that flow moved towards the detection by the fraction
    /// max(`pull`, (distance / threshold)²), or stays the flow when `pull` is 0; elsewhere it
    /// stays the detection. The result is remembered for the next frame. Returns how many points
    /// came from the flow (0 on the first frame of a track or when the number of points changed,
    /// which restarts the filter).
    ///
    /// `pull = 0` is the thesis' rule (Alg. 8: the flow kept whole). Why a pull: a point held
    /// wholly on the flow keeps any error it once had for as long as it stays within the threshold
    /// (a blurred frame's reading, or the drift of the flow itself when the light changes), so on
    /// sharp still frames after motion, or under a phone's changing exposure, that filter was less
    /// accurate and less steady than no filter at all (`TrackerConfig::flow_pull`).
    ///
    /// # Errors
    /// [`Error::InvalidInput`] when the pyramids differ in size or depth (the caller must reset on
    /// a change of frame size), a threshold that is not finite and ≥ 0, or a pull outside 0..=1.
    pub fn apply(
        &mut self,
        prev: &Pyramid,
        next: &Pyramid,
        points: &mut [[f32; 2]],
        threshold_px: f32,
        pull: f32,
    ) -> Result<usize> {
        if !(threshold_px.is_finite() && threshold_px >= 0.0) {
            return Err(Error::InvalidInput(format!(
                "flow filter threshold must be finite and >= 0, got {threshold_px}"
            )));
        }
        if !(0.0..=1.0).contains(&pull) {
            return Err(Error::InvalidInput(format!(
                "flow filter pull must be in 0..=1, got {pull}"
            )));
        }
        let mut used = 0;
        if self.has_prev && self.prev.len() == points.len() {
            let n = points.len();
            // Each point starts at its detection: the flow is kept only near it.
            self.flow.clear();
            self.flow.extend_from_slice(points);
            self.status.resize(n, false);
            self.error.resize(n, 0.0);
            self.lk.track_guided(
                prev,
                next,
                &self.prev,
                &mut self.flow,
                &mut self.status,
                &mut self.error,
            )?;
            let t2 = threshold_px * threshold_px;
            for ((p, f), &ok) in points.iter_mut().zip(&self.flow).zip(&self.status) {
                let d2 = (f[0] - p[0]).powi(2) + (f[1] - p[1]).powi(2);
                if ok && d2 <= t2 {
                    // pull 0 is the thesis' rule: the flow whole.
                    let a = if pull > 0.0 { pull.max(d2 / t2) } else { 0.0 };
                    *p = [f[0] + a * (p[0] - f[0]), f[1] + a * (p[1] - f[1])];
                    used += 1;
                }
            }
        }
        self.prev.clear();
        self.prev.extend_from_slice(points);
        self.has_prev = true;
        Ok(used)
    }
}

#[cfg(test)]
mod tests {
    use super::super::ncc::tests::texture;
    use super::*;

    /// 640×480 image of the texture under the affine map p ↦ A·p + b (image(A·q + b) = texture(q)).
    fn warped(a: [[f32; 2]; 2], b: [f32; 2]) -> GrayImage {
        let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        let inv = [
            [a[1][1] / det, -a[0][1] / det],
            [-a[1][0] / det, a[0][0] / det],
        ];
        let (w, h) = (640, 480);
        let mut img = GrayImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (px, py) = (x as f32 + 0.5 - b[0], y as f32 + 0.5 - b[1]);
                let qx = inv[0][0] * px + inv[0][1] * py;
                let qy = inv[1][0] * px + inv[1][1] * py;
                img.data_mut()[y * w + x] = texture(qx, qy).round() as u8;
            }
        }
        img
    }

    /// A tracker whose windows run `form`.
    fn tracker(config: LkConfig, form: Form) -> PyramidalLk {
        let mut lk = PyramidalLk::new(config).unwrap();
        lk.windows = Windows::new(2 * config.half_window + 1, BATCH, form);
        lk
    }

    /// The two frames the window forms are compared on, as pyramids of three levels.
    fn kernel_pyramids() -> [Pyramid; 2] {
        let id = [[1.0, 0.0], [0.0, 1.0]];
        [
            warped(id, [0.0, 0.0]),
            warped([[1.02, 0.03], [-0.02, 0.99]], [3.3, -2.1]),
        ]
        .map(|img| {
            let mut p = Pyramid::new();
            p.build(&img, 3);
            p
        })
    }

    /// Points, status and errors of one tracking run.
    type Tracked = (Vec<[f32; 2]>, Vec<bool>, Vec<f32>);

    /// `lk` tracking [`kernel_points`] between `pyramids`.
    fn track_kernel_points(lk: &mut PyramidalLk, pyramids: &[Pyramid; 2]) -> Tracked {
        let from = kernel_points();
        let n = from.len();
        let (mut to, mut st, mut err) = (vec![[9.0; 2]; n], vec![true; n], vec![9.0; n]);
        let [prev, next] = pyramids;
        lk.track(prev, next, &from, &mut to, &mut st, &mut err)
            .unwrap();
        (to, st, err)
    }

    /// Every window form this CPU runs tracks the portable form's points, bit for bit: windows
    /// of one 8-lane group, of one 16-lane group, of one whose bordered rows are too wide for the
    /// one-pass gradient kernels, of two, and the largest allowed. (`kernels::lk`'s tests hold
    /// each kernel to the portable one; this holds the tracker's use of them.)
    #[test]
    fn every_window_form_tracks_the_portable_points() {
        let pyramids = kernel_pyramids();
        for half_window in [2, 5, 7, 9, 15] {
            let cfg = LkConfig {
                half_window,
                ..LkConfig::default()
            };
            let portable = track_kernel_points(&mut tracker(cfg, Form::Portable), &pyramids);
            // Enough tracked points that the comparison means something (the 5×5 window loses
            // more points as textureless).
            let tracked = portable.1.iter().filter(|&&s| s).count();
            assert!(
                tracked > portable.1.len() / 3,
                "{half_window}: {:?}",
                portable.1
            );
            for form in Form::all() {
                let got = track_kernel_points(&mut tracker(cfg, form), &pyramids);
                assert_eq!(got, portable, "{form:?}, half window {half_window}");
            }
        }
    }

    /// The AVX2 copies of the pyramid's halving and of the tracker (`with_avx2_copy!`) give the
    /// baseline bodies' bits, with every window form.
    #[cfg(target_arch = "x86_64")]
    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn the_avx2_copies_give_the_baseline_pyramid_and_points() {
        crate::kernels::cpu::assert_avx2_fma_path();
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let (img0, img1) = (
            warped(id, [0.0, 0.0]),
            warped([[1.02, 0.03], [-0.02, 0.99]], [3.3, -2.1]),
        );
        let mut pyramids = Vec::new();
        for img in [&img0, &img1] {
            // `build` halves through the AVX2 copy on this CPU (asserted above).
            let (mut base, mut avx2) = (Pyramid::new(), Pyramid::new());
            base.build(img, 3);
            base.halve_body(img, 3, [0, 0, 640, 480]);
            avx2.build(img, 3);
            assert_eq!(base.len(), avx2.len());
            for (a, b) in base.levels().iter().zip(avx2.levels()) {
                assert_eq!(a.data(), b.data());
            }
            pyramids.push(base);
        }
        let from = kernel_points();
        let n = from.len();
        let (prev, next) = (&pyramids[0], &pyramids[1]);
        // Points, status and errors of one run: the body as compiled for baseline x86-64, or
        // (through the dispatching method, on this CPU) its AVX2 copy.
        let run = |lk: &mut PyramidalLk, avx2_copy: bool| {
            let (mut to, mut st, mut err) = (vec![[9.0; 2]; n], vec![true; n], vec![9.0; n]);
            if avx2_copy {
                lk.track_with(prev, next, &from, &mut to, &mut st, &mut err, false)
            } else {
                lk.track_body(prev, next, &from, &mut to, &mut st, &mut err, false)
            }
            .unwrap();
            (to, st, err)
        };
        for half_window in [2, 5, 9, 15] {
            let cfg = LkConfig {
                half_window,
                ..LkConfig::default()
            };
            for form in Form::all() {
                let body = run(&mut tracker(cfg, form), false);
                assert_eq!(body, run(&mut tracker(cfg, form), true), "{form:?}");
            }
        }
    }

    /// Points the window forms are held to the portable one on: the grid plus some near the
    /// border (the clamped sampling path) and near the right and bottom edges (the 512-bit
    /// kernels' masked loads reach them; the AVX2 and NEON ones fall back).
    fn kernel_points() -> Vec<[f32; 2]> {
        let mut from = grid();
        from.extend([
            [1.5, 2.5],
            [637.2, 477.9],
            [-3.0, 240.0],
            [631.3, 200.6],
            [633.8, 121.1],
            [300.4, 472.2],
        ]);
        from
    }

    fn grid() -> Vec<[f32; 2]> {
        let mut pts = Vec::new();
        for j in 0..6 {
            for i in 0..8 {
                pts.push([120.0 + 55.0 * i as f32 + 0.3, 90.0 + 55.0 * j as f32 + 0.7]);
            }
        }
        pts
    }

    fn run(a: [[f32; 2]; 2], b: [f32; 2]) -> (Vec<[f32; 2]>, Vec<[f32; 2]>, Vec<bool>) {
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let (mut p0, mut p1) = (Pyramid::new(), Pyramid::new());
        p0.build(&warped(id, [0.0, 0.0]), 3);
        p1.build(&warped(a, b), 3);
        let from = grid();
        let mut to = vec![[0.0; 2]; from.len()];
        let mut st = vec![false; from.len()];
        let mut err = vec![0.0; from.len()];
        let mut lk = PyramidalLk::new(LkConfig::default()).unwrap();
        lk.track(&p0, &p1, &from, &mut to, &mut st, &mut err)
            .unwrap();
        let expect = from
            .iter()
            .map(|p| {
                [
                    a[0][0] * p[0] + a[0][1] * p[1] + b[0],
                    a[1][0] * p[0] + a[1][1] * p[1] + b[1],
                ]
            })
            .collect();
        (to, expect, st)
    }

    fn check(a: [[f32; 2]; 2], b: [f32; 2], tol: f32, min_tracked: f32) {
        let (to, expect, st) = run(a, b);
        let n = st.len() as f32;
        let tracked = st.iter().filter(|&&s| s).count() as f32;
        assert!(tracked / n >= min_tracked, "tracked {tracked}/{n}");
        let mut errs: Vec<f32> = to
            .iter()
            .zip(&expect)
            .zip(&st)
            .filter(|(_, s)| **s)
            .map(|((t, e), _)| ((t[0] - e[0]).powi(2) + (t[1] - e[1]).powi(2)).sqrt())
            .collect();
        errs.sort_by(f32::total_cmp);
        let median = errs[errs.len() / 2];
        assert!(median < tol, "median error {median} px (all {errs:?})");
    }

    #[test]
    fn pyramid_levels_halve_and_average() {
        let mut img = GrayImage::new(64, 40);
        for (i, v) in img.data_mut().iter_mut().enumerate() {
            *v = (i % 7 * 30) as u8;
        }
        let mut p = Pyramid::new();
        p.build(&img, 4);
        // 64×40 → 32×20 → 16×10 stops (10 < MIN_LEVEL_SIDE).
        assert_eq!(p.len(), 2);
        assert_eq!((p.levels()[1].width(), p.levels()[1].height()), (32, 20));
        let s: u32 = [(0, 0), (1, 0), (0, 1), (1, 1)]
            .iter()
            .map(|&(x, y)| u32::from(img.get(x, y)))
            .sum();
        assert_eq!(u32::from(p.levels()[1].get(0, 0)), (s + 2) / 4);
        // Rebuilding reuses buffers.
        let cap = p.levels()[0].data().as_ptr();
        p.build(&img, 4);
        assert_eq!(cap, p.levels()[0].data().as_ptr());
    }

    /// Level `l` of `p` as frame-level pixels: the value at (x, y) of level l's frame grid.
    fn at(p: &Pyramid, l: usize, x: usize, y: usize) -> u8 {
        let o = p.origin();
        p.levels()[l].get(x - (o[0] >> l), y - (o[1] >> l))
    }

    #[test]
    fn region_pyramids_hold_the_full_pyramids_pixels() {
        let img = warped([[1.02, 0.03], [-0.02, 0.99]], [3.3, -2.1]);
        let mut full = Pyramid::new();
        full.build(&img, 3);
        let regions = [
            Rect::new(101.3, 57.8, 180.0, 203.5),
            // Ends just past a multiple of the level grid: the region's last pixel column and row
            // (280 and 240) must be stored.
            Rect::new(100.5, 40.5, 180.0, 200.0),
            // At the frame's corners (clipped) and tiny (widened to the coarsest level's minimum).
            Rect::new(-40.0, 300.0, 120.0, 400.0),
            Rect::new(630.0, 2.0, 3.0, 3.0),
            Rect::new(f32::NAN, 10.0, 20.0, 20.0),
        ];
        for r in regions {
            let mut p = Pyramid::new();
            p.build_region(&img, 3, &r);
            assert_eq!(p.len(), full.len());
            assert_eq!(p.size(), (640, 480));
            let o = p.origin();
            assert_eq!((o[0] % 4, o[1] % 4), (0, 0), "{r:?}: origin {o:?}");
            for l in 0..p.len() {
                let lv = &p.levels()[l];
                assert!(lv.width() >= MIN_LEVEL_SIDE && lv.height() >= MIN_LEVEL_SIDE);
                assert!((o[0] >> l) + lv.width() <= full.levels()[l].width());
                assert!((o[1] >> l) + lv.height() <= full.levels()[l].height());
                for y in 0..lv.height() {
                    for x in 0..lv.width() {
                        let (fx, fy) = (x + (o[0] >> l), y + (o[1] >> l));
                        assert_eq!(
                            lv.get(x, y),
                            full.levels()[l].get(fx, fy),
                            "{r:?} level {l}"
                        );
                    }
                }
            }
            // The region asked for is inside (where the frame has it).
            if r.x.is_finite() {
                let x0 = r.x.max(0.0) as usize;
                let y0 = r.y.max(0.0) as usize;
                let x1 = ((r.x + r.w).ceil() as usize).min(640);
                let y1 = ((r.y + r.h).ceil() as usize).min(480);
                assert!(o[0] <= x0 && o[1] <= y0, "{r:?}");
                assert!(o[0] + p.levels()[0].width() >= x1, "{r:?}");
                assert!(o[1] + p.levels()[0].height() >= y1, "{r:?}");
                assert_eq!(at(&p, 0, x0, y0), img.get(x0, y0));
            }
        }
    }

    #[test]
    fn flow_between_region_pyramids_equals_the_full_frames() {
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let (img0, img1) = (warped(id, [0.0, 0.0]), warped(id, [6.6, -3.9]));
        let (mut f0, mut f1) = (Pyramid::new(), Pyramid::new());
        f0.build(&img0, 3);
        f1.build(&img1, 3);
        // Each frame's region around its own face position, as the tracker builds them.
        let (mut r0, mut r1) = (Pyramid::new(), Pyramid::new());
        r0.build_region(&img0, 3, &Rect::new(150.0, 110.0, 300.0, 250.0));
        r1.build_region(&img1, 3, &Rect::new(157.0, 105.0, 300.0, 250.0));
        assert_ne!(r0.origin(), r1.origin());
        let from: Vec<[f32; 2]> = (0..40)
            .map(|i| [200.0 + 5.3 * i as f32, 160.0 + 3.7 * (i % 13) as f32])
            .collect();
        let run = |a: &Pyramid, b: &Pyramid| {
            let n = from.len();
            let (mut to, mut st, mut err) = (vec![[0.0; 2]; n], vec![false; n], vec![0.0; n]);
            let mut lk = PyramidalLk::new(LkConfig::default()).unwrap();
            lk.track(a, b, &from, &mut to, &mut st, &mut err).unwrap();
            (to, st, err)
        };
        let (full, region) = (run(&f0, &f1), run(&r0, &r1));
        assert!(full.1.iter().filter(|&&s| s).count() > 35);
        assert_eq!(full.1, region.1);
        for (a, b) in full.0.iter().zip(&region.0) {
            assert!(
                (a[0] - b[0]).abs() < 1e-3 && (a[1] - b[1]).abs() < 1e-3,
                "{a:?} {b:?}"
            );
        }
    }

    /// A change of exposure between the frames (grey × 1.05 + 3) on fine texture: plain
    /// Lucas–Kanade reads part of it as motion, the offset-invariant window does not.
    #[test]
    fn a_brightness_change_does_not_read_as_motion() {
        let fine = [[1.0 / 3.0, 0.0], [0.0, 1.0 / 3.0]];
        let shift = [1.3, -0.7];
        let img0 = warped(fine, [0.0, 0.0]);
        let mut img1 = warped(fine, shift);
        for v in img1.data_mut() {
            *v = (f32::from(*v) * 1.05 + 3.0).round().min(255.0) as u8;
        }
        let (mut p0, mut p1) = (Pyramid::new(), Pyramid::new());
        p0.build(&img0, 2);
        p1.build(&img1, 2);
        let from: Vec<[f32; 2]> = (0..60)
            .map(|i| [100.0 + 7.3 * i as f32, 120.0 + 4.1 * (i % 37) as f32])
            .collect();
        let median_error = |offset_invariant: bool| {
            let n = from.len();
            let (mut to, mut st, mut err) = (vec![[0.0; 2]; n], vec![false; n], vec![0.0; n]);
            let mut lk = PyramidalLk::new(LkConfig {
                offset_invariant,
                ..LkConfig::default()
            })
            .unwrap();
            lk.track(&p0, &p1, &from, &mut to, &mut st, &mut err)
                .unwrap();
            let mut e: Vec<f32> = from
                .iter()
                .zip(&to)
                .zip(&st)
                .filter(|&(_, &ok)| ok)
                .map(|((a, b), _)| {
                    ((b[0] - a[0] - shift[0]).powi(2) + (b[1] - a[1] - shift[1]).powi(2)).sqrt()
                })
                .collect();
            assert!(e.len() > n / 2, "{offset_invariant}: {} tracked", e.len());
            e.sort_by(f32::total_cmp);
            e[e.len() / 2]
        };
        let (plain, invariant) = (median_error(false), median_error(true));
        assert!(
            invariant < 0.1,
            "offset-invariant median error {invariant} px"
        );
        assert!(
            plain > 3.0 * invariant,
            "plain {plain} px, offset-invariant {invariant} px"
        );
    }

    #[test]
    fn translation_is_recovered() {
        let id = [[1.0, 0.0], [0.0, 1.0]];
        check(id, [2.6, -1.3], 0.1, 0.9);
        // Larger than the window: needs the pyramid.
        check(id, [11.4, 7.8], 0.15, 0.9);
    }

    #[test]
    fn a_guess_replaces_the_levels_a_motion_needs() {
        // A 40 px shift on one level: beyond a 5 px half window unguided, found from guesses
        // 2–3 px off.
        let b = [31.7f32, -25.1];
        let (mut p0, mut p1) = (Pyramid::new(), Pyramid::new());
        p0.build(&warped([[1.0, 0.0], [0.0, 1.0]], [0.0, 0.0]), 1);
        p1.build(&warped([[1.0, 0.0], [0.0, 1.0]], b), 1);
        let from = grid();
        let n = from.len();
        let mut lk = PyramidalLk::new(LkConfig::default()).unwrap();
        let (mut st, mut err) = (vec![false; n], vec![0.0; n]);
        let near = |to: &[[f32; 2]], st: &[bool]| {
            from.iter()
                .zip(to)
                .zip(st)
                .filter(|((f, t), s)| {
                    **s && (t[0] - f[0] - b[0]).abs() < 0.15 && (t[1] - f[1] - b[1]).abs() < 0.15
                })
                .count()
        };
        let mut to = vec![[0.0; 2]; n];
        lk.track(&p0, &p1, &from, &mut to, &mut st, &mut err)
            .unwrap();
        let unguided = near(&to, &st);
        let mut to: Vec<[f32; 2]> = from
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let e = if i % 2 == 0 { [2.1, -1.4] } else { [-1.7, 2.3] };
                [f[0] + b[0] + e[0], f[1] + b[1] + e[1]]
            })
            .collect();
        // A guess that is not finite is no motion (the point is lost here, not a panic).
        to[0] = [f32::NAN, 0.0];
        lk.track_guided(&p0, &p1, &from, &mut to, &mut st, &mut err)
            .unwrap();
        let guided = near(&to, &st);
        assert!(unguided * 4 < n, "unguided: {unguided} of {n} found");
        assert!(guided * 10 >= 9 * n, "guided: {guided} of {n} found");
    }

    #[test]
    fn affine_motion_is_recovered() {
        // 3° rotation and 4 % zoom about the image centre plus a shift (points move 5–20 px): the
        // window sees (nearly) a translation locally.
        let (s, c) = (3f32.to_radians().sin(), 3f32.to_radians().cos());
        let k = 1.04;
        let a = [[k * c, -k * s], [k * s, k * c]];
        let centre = [320.0f32, 240.0];
        let b = [
            centre[0] - (a[0][0] * centre[0] + a[0][1] * centre[1]) - 4.0,
            centre[1] - (a[1][0] * centre[0] + a[1][1] * centre[1]) + 3.0,
        ];
        check(a, b, 0.3, 0.9);
    }

    #[test]
    fn mismatched_inputs_are_errors() {
        let mut lk = PyramidalLk::new(LkConfig::default()).unwrap();
        let (mut p0, mut p1) = (Pyramid::new(), Pyramid::new());
        p0.build(&GrayImage::new(64, 64), 3);
        p1.build(&GrayImage::new(80, 64), 3);
        let from = [[10.0f32, 10.0]];
        let (mut to, mut st, mut e) = ([[0.0f32; 2]; 1], [false; 1], [0.0f32; 1]);
        assert!(matches!(
            lk.track(&p0, &p1, &from, &mut to, &mut st, &mut e),
            Err(Error::InvalidInput(_))
        ));
        assert!(matches!(
            lk.track(&p0, &p0, &from, &mut [[0.0; 2]; 2], &mut st, &mut e),
            Err(Error::InvalidInput(_))
        ));
        // A flat image: every point is textureless and lost, and keeps its position.
        lk.track(&p0, &p0, &from, &mut to, &mut st, &mut e).unwrap();
        assert!(!st[0]);
        assert_eq!(to[0], from[0]);
        assert!(matches!(
            PyramidalLk::new(LkConfig {
                levels: 0,
                ..Default::default()
            }),
            Err(Error::InvalidConfig(_))
        ));
    }

    #[test]
    fn filter_keeps_flow_near_detections_and_snaps_to_far_ones() {
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let shift = [3.0f32, -2.0];
        let (mut p0, mut p1) = (Pyramid::new(), Pyramid::new());
        p0.build(&warped(id, [0.0, 0.0]), 3);
        p1.build(&warped(id, shift), 3);
        let truth0 = grid();
        let mut f = FlowFilter::new(LkConfig::default()).unwrap();
        // First frame of a track: the detection passes through.
        let mut pts = truth0.clone();
        assert_eq!(f.apply(&p0, &p0, &mut pts, 5.0, 0.0).unwrap(), 0);
        assert_eq!(pts, truth0);
        // Next frame: detections = truth + jitter (±1.5 px) on all but point 0, which the detector
        // puts 20 px off (a jump the filter must follow: beyond the threshold).
        let mut det: Vec<[f32; 2]> = truth0
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let j = if i % 2 == 0 { 1.5 } else { -1.5 };
                [p[0] + shift[0] + j, p[1] + shift[1] - j]
            })
            .collect();
        det[0][0] += 20.0;
        let mut out = det.clone();
        let used = f.apply(&p0, &p1, &mut out, 5.0, 0.0).unwrap();
        assert!(used >= det.len() - 3, "used {used}");
        assert_eq!(out[0], det[0], "far detection must win");
        let mut err_det = 0.0;
        let mut err_out = 0.0;
        for i in 1..det.len() {
            let t = [truth0[i][0] + shift[0], truth0[i][1] + shift[1]];
            err_det += ((det[i][0] - t[0]).powi(2) + (det[i][1] - t[1]).powi(2)).sqrt();
            err_out += ((out[i][0] - t[0]).powi(2) + (out[i][1] - t[1]).powi(2)).sqrt();
        }
        // The flow removes the jitter: the filtered points sit on the true motion.
        assert!(err_out < 0.2 * err_det, "{err_out} vs {err_det}");
        // Threshold 0 takes the detections; reset restarts.
        let mut out2 = det.clone();
        f.apply(&p1, &p1, &mut out2, 0.0, 0.1).unwrap();
        f.reset();
        assert!(!f.has_previous());
        let mut out3 = det.clone();
        assert_eq!(f.apply(&p1, &p1, &mut out3, 5.0, 0.1).unwrap(), 0);
        assert!(f.apply(&p1, &p1, &mut out3, f32::NAN, 0.1).is_err());
        assert!(f.apply(&p1, &p1, &mut out3, 5.0, f32::NAN).is_err());
        assert!(f.apply(&p1, &p1, &mut out3, 5.0, -0.1).is_err());
    }

    /// The pull's rule, against the flow computed apart: each point kept from the flow moves
    /// towards its detection by max(pull, (distance / threshold)²); pull 0 keeps the flow whole
    /// (the thesis' filter) and pull 1 gives the detections.
    #[test]
    fn the_pull_moves_flow_points_towards_the_detections() {
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let shift = [2.0f32, 1.0];
        let (mut p0, mut p1) = (Pyramid::new(), Pyramid::new());
        p0.build(&warped(id, [0.0, 0.0]), 3);
        p1.build(&warped(id, shift), 3);
        let prev = grid();
        let det: Vec<[f32; 2]> = prev
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let j = 0.5 * (i % 7) as f32;
                [p[0] + shift[0] + j, p[1] + shift[1] - 0.5 * j]
            })
            .collect();
        let mut lk = PyramidalLk::new(LkConfig::default()).unwrap();
        let mut flow = det.clone();
        let (mut st, mut e) = (vec![false; det.len()], vec![0.0f32; det.len()]);
        lk.track_guided(&p0, &p1, &prev, &mut flow, &mut st, &mut e)
            .unwrap();
        let threshold = 5.0f32;
        for pull in [0.0f32, crate::track::DEFAULT_FLOW_PULL, 1.0] {
            let mut f = FlowFilter::new(LkConfig::default()).unwrap();
            let mut first = prev.clone();
            f.apply(&p0, &p0, &mut first, threshold, pull).unwrap();
            let mut out = det.clone();
            let used = f.apply(&p0, &p1, &mut out, threshold, pull).unwrap();
            assert!(used >= det.len() - 2, "used {used}");
            for i in 0..det.len() {
                let (fl, d) = (flow[i], det[i]);
                let d2 = (fl[0] - d[0]).powi(2) + (fl[1] - d[1]).powi(2);
                if !st[i] || d2 > threshold * threshold {
                    assert_eq!(out[i], d);
                    continue;
                }
                let a = if pull > 0.0 {
                    pull.max(d2 / (threshold * threshold))
                } else {
                    0.0
                };
                let want = [fl[0] + a * (d[0] - fl[0]), fl[1] + a * (d[1] - fl[1])];
                assert_eq!(out[i], want, "point {i}, pull {pull}");
                if pull == 1.0 {
                    assert!((out[i][0] - d[0]).abs() < 1e-4 && (out[i][1] - d[1]).abs() < 1e-4);
                }
            }
        }
    }
}
