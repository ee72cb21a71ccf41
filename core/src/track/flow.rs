//! Pyramidal Lucas–Kanade optical flow (Bouguet's formulation) and the optical-flow landmark filter
//! of the thesis' Algorithm 8.
//!
//! - [`Pyramid`]: 2×2 box-filtered image pyramid built into reused buffers.
//! - [`PyramidalLk`]: per point, iterative LK in a square window from the coarsest level down, with
//!   a status (lost: singular gradient matrix or left the image) and an error (mean absolute grey
//!   difference over the window) per point.
//!
//!   Cost: each iteration of a point waits on the last one's result, so the window kernels are
//!   written for latency. Each image row of the next window is interpolated along x once and
//!   serves the two window rows it lies between, and the sums are taken in the same pass. Each
//!   sum keeps separate chains for even and odd rows and ends in a tree. Four points go through
//!   the levels together and take their iterations in turn, so one point's sums overlap the
//!   next one's. The previous window's gradients come from bordered rows held in registers,
//!   their shifted cells by lane shifts: read back from memory at offsets of one and two cells,
//!   each load straddled two recent stores and waited for them to reach the cache.
//!   AVX-512 (masked byte loads at the window's edge), AVX2, NEON (`flow/arm64.rs`) and portable
//!   kernels give the same bits: every sum has sixteen lanes and one order. `MONOTRACK_FLOW=portable|avx2` picks a
//!   narrower set.
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
use serde::{Deserialize, Serialize};

/// Smallest side a pyramid level may have; coarser levels carry too few pixels for a window.
pub const MIN_LEVEL_SIDE: usize = 16;

/// Lucas–Kanade settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LkConfig {
    /// Window half-size: the window is (2·h + 1)² pixels. 5 (11×11) balances cost and robustness
    /// for landmark-sized features; OpenCV's default 21×21 costs 3.6× more per iteration.
    pub half_window: usize,
    /// Pyramid levels including full resolution: L levels follow motions (or, guided, a guess's
    /// errors) up to about 2^(L−1) × the half window. 2: the flow filter starts each point at its
    /// detection ([`PyramidalLk::track_guided`]) and keeps flow only within a few pixels of it, so
    /// the levels need to cover the detection's error, not the face's motion (3 levels, unguided,
    /// gave the same correct frames, NME and still jitter on `track_eval`'s sequences and cost
    /// half as much again).
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
    /// Lucas–Kanade. On by default: under ±30 % changing light it cuts the still-face jitter
    /// behind the default flow filter by about a third at the same accuracy (BENCHMARKS.md, "The
    /// flow filter under changing light").
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
    /// match. Why: the flow reads only windows around the face, and copying and halving a 1280×720
    /// frame cost more than the face's part of it (`pyramid_*` benches).
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

/// Samples a `size × size` patch whose top-left sample sits at pixel-index position (x, y) into
/// rows `stride ≥ size` apart; the cells past `size` in each row are left as they are.
///
/// Bilinear in the separable form the vector kernels compute, so all give the same bits: along x
/// in each of the two image rows, `a + fx·(b − a)`, then along y between them. Positions outside
/// the image clamp to the border.
#[inline(always)]
fn sample_patch(img: &GrayImage, x: f32, y: f32, size: usize, stride: usize, out: &mut [f32]) {
    let (w, h) = (img.width(), img.height());
    let d = img.data();
    if let Some(([ix, iy], [fx, fy])) = window_inside(img, x, y, size, size) {
        // Fast path: no bounds checks per sample.
        for r in 0..size {
            let a = &d[(iy + r) * w + ix..][..size + 1];
            let b = &d[(iy + r + 1) * w + ix..][..size + 1];
            let o = &mut out[r * stride..][..size];
            for c in 0..size {
                let top = lerp(f32::from(a[c]), f32::from(a[c + 1]), fx);
                let bottom = lerp(f32::from(b[c]), f32::from(b[c + 1]), fx);
                o[c] = lerp(top, bottom, fy);
            }
        }
        return;
    }
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (ix, iy) = (x0 as i64, y0 as i64);
    let at = |px: i64, py: i64| -> f32 {
        let px = px.clamp(0, w as i64 - 1) as usize;
        let py = py.clamp(0, h as i64 - 1) as usize;
        f32::from(d[py * w + px])
    };
    for r in 0..size {
        let py = iy + r as i64;
        for c in 0..size {
            let px = ix + c as i64;
            let top = lerp(at(px, py), at(px + 1, py), fx);
            let bottom = lerp(at(px, py + 1), at(px + 1, py + 1), fx);
            out[r * stride + c] = lerp(top, bottom, fy);
        }
    }
}

/// `a + t·(b − a)`: the bilinear step every sampling kernel takes, in this order.
#[inline(always)]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + t * (b - a)
}

/// The window kernels a [`PyramidalLk`] runs. All give the same bits: each sum keeps [`LANES`]
/// lanes (cell c of a window row in lane c mod [`LANES`]) and adds them in lane order at the end,
/// and every lane does the portable code's operations in its order (Rust never fuses `a·b + c`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kernels {
    /// Plain Rust (every CPU; the compiler vectorises what it can).
    Portable,
    /// AVX2 + FMA: 8 lanes a register, two registers per lane group.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// AVX-512 (F, BW, VL): one register per lane group, the window's edge by masked byte loads,
    /// so windows up to the image's last column take the vector path.
    #[cfg(target_arch = "x86_64")]
    Avx512,
    /// NEON (aarch64's baseline): four registers per lane group (`flow/arm64.rs`).
    #[cfg(target_arch = "aarch64")]
    Neon,
}

impl Kernels {
    /// The widest this CPU runs, decided once; `MONOTRACK_FLOW=portable|avx2` picks a narrower
    /// one (to measure them on one machine).
    fn detect() -> Self {
        static CHOSEN: std::sync::OnceLock<Kernels> = std::sync::OnceLock::new();
        *CHOSEN.get_or_init(|| {
            let widest = Self::widest();
            match std::env::var("MONOTRACK_FLOW").as_deref() {
                Ok("portable") => Kernels::Portable,
                #[cfg(target_arch = "x86_64")]
                Ok("avx2") if widest != Kernels::Portable => Kernels::Avx2,
                _ => widest,
            }
        })
    }

    /// The widest this CPU has.
    fn widest() -> Self {
        #[cfg(target_arch = "aarch64")]
        if crate::kernels::cpu::neon() {
            return Kernels::Neon;
        }
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if crate::kernels::cpu::has_avx2_fma() {
                return if has!("avx512f") && has!("avx512bw") && has!("avx512vl") {
                    Kernels::Avx512
                } else {
                    Kernels::Avx2
                };
            }
        }
        Kernels::Portable
    }
}

/// Pyramidal Lucas–Kanade point tracker; holds its window buffers.
#[derive(Debug, Clone)]
pub struct PyramidalLk {
    config: LkConfig,
    /// Previous-image patch with a 1-pixel border (for central-difference gradients), rows
    /// `bstride = stride + LANES` cells apart so whole lane groups of the gradients read inside it.
    bordered: Vec<f32>,
    bstride: usize,
    /// The window's rows, `stride` cells apart (a multiple of [`LANES`]), one window per point of a
    /// batch ([`BATCH`]; `moving` one); the cells past the window's width stay zero in all four,
    /// so whole rows of lanes can be summed.
    patch: Vec<f32>,
    gx: Vec<f32>,
    gy: Vec<f32>,
    /// The next image's window, sampled here only where the vector kernels, which sample and sum
    /// in one pass, do not run (near the image's edge, or on the portable path).
    moving: Vec<f32>,
    stride: usize,
    #[cfg_attr(
        not(any(target_arch = "x86_64", target_arch = "aarch64")),
        allow(dead_code)
    )]
    kernels: Kernels,
}

/// Points tracked together ([`PyramidalLk::track_batch`]); each has its own patch and gradients.
const BATCH: usize = 4;

/// Lanes of the window sums: sixteen f32 sums kept apart (one AVX-512 register, two of AVX2),
/// added in a fixed order at the end ([`reduce`]).
const LANES: usize = 16;

impl PyramidalLk {
    /// A tracker with `config`.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] when the config is out of range ([`LkConfig::validate`]).
    pub fn new(config: LkConfig) -> Result<Self> {
        config.validate()?;
        let n = 2 * config.half_window + 1;
        let stride = n.next_multiple_of(LANES);
        Ok(Self {
            config,
            bordered: vec![0.0; (n + 2) * (stride + LANES)],
            bstride: stride + LANES,
            patch: vec![0.0; BATCH * n * stride],
            gx: vec![0.0; BATCH * n * stride],
            gy: vec![0.0; BATCH * n * stride],
            moving: vec![0.0; n * stride],
            stride,
            kernels: Kernels::detect(),
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
    /// returned ones), each exactly as
    /// alone: the points go through the levels together and take their iterations in turn, so the
    /// CPU overlaps one point's window sums with the next one's where a single point would wait on
    /// each iteration's result before the next can start. With `guess` (level-0 positions, one
    /// per point) each point's motion starts at its guess's, scaled to the coarsest level.
    #[inline(always)]
    fn track_batch(
        &mut self,
        prev: &Pyramid,
        next: &Pyramid,
        points: &[[f32; 2]],
        guess: Option<&[[f32; 2]]>,
    ) -> [([f32; 2], bool, f32); BATCH] {
        let cfg = self.config;
        let hw = cfg.half_window;
        let n = 2 * hw + 1;
        let area = (n * n) as f32;
        let k = points.len();
        debug_assert!(k <= BATCH);
        #[derive(Clone, Copy, Default)]
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
        let mut pts = [Point::default(); BATCH];
        let top = 1.0 / (1u32 << (prev.len() - 1)) as f32;
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
        let (po, no) = (prev.origin(), next.origin());
        for l in (0..prev.len()).rev() {
            let scale = 1.0 / (1u32 << l) as f32;
            let (pi, ni) = (&prev.levels()[l], &next.levels()[l]);
            // The next pyramid's region starts elsewhere: its window moves by the difference.
            let (ox, oy) = (
                (po[0] >> l) as f32 - (no[0] >> l) as f32,
                (po[1] >> l) as f32 - (no[1] >> l) as f32,
            );
            for (slot, s) in pts[..k].iter_mut().enumerate() {
                if !s.alive {
                    continue;
                }
                // Window centre in the frame's pixel-index coordinates at this level (corner
                // convention → subtract 0.5), then in each stored region's.
                let fx = s.p[0] * scale - 0.5;
                let fy = s.p[1] * scale - 0.5;
                let (cx, cy) = (fx - (po[0] >> l) as f32, fy - (po[1] >> l) as f32);
                let mut sums =
                    self.window_gradients(pi, cx - hw as f32 - 1.0, cy - hw as f32 - 1.0, slot);
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
            for _ in 0..cfg.max_iterations {
                let mut any = false;
                for (slot, s) in pts[..k].iter_mut().enumerate() {
                    if !s.alive || s.done {
                        continue;
                    }
                    any = true;
                    let (g, d) = (s.g, s.d);
                    let [bx, by, sad] = self.mismatch(
                        ni,
                        s.at[0] + g[0] + d[0] - hw as f32,
                        s.at[1] + g[1] + d[1] - hw as f32,
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
            if l > 0 {
                for s in &mut pts[..k] {
                    s.g = [2.0 * (s.g[0] + s.d[0]), 2.0 * (s.g[1] + s.d[1])];
                }
            }
        }
        let (w, h) = next.size();
        pts.map(|s| {
            let out = [s.p[0] + s.g[0] + s.d[0], s.p[1] + s.g[1] + s.d[1]];
            let inside = out[0].is_finite()
                && out[1].is_finite()
                && out[0] >= 0.0
                && out[1] >= 0.0
                && out[0] <= w as f32
                && out[1] <= h as f32;
            if s.alive && inside {
                (out, true, s.sad / area)
            } else {
                (s.p, false, f32::INFINITY)
            }
        })
    }
}

impl PyramidalLk {
    /// The previous image's window with its border's top-left sample at (x, y): its patch and
    /// gradients in `slot` and the gradient matrix's sums ([`PyramidalLk::gradients`]).
    #[inline(always)]
    fn window_gradients(&mut self, img: &GrayImage, x: f32, y: f32, slot: usize) -> [f32; 3] {
        let n = 2 * self.config.half_window + 1;
        #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
        {
            let (st, at) = (self.stride, slot * n * self.stride);
            let outs = [
                &mut self.patch[at..at + n * st],
                &mut self.gx[at..at + n * st],
                &mut self.gy[at..at + n * st],
            ];
            #[allow(unsafe_code)]
            // SAFETY: `kernels` names features `Kernels::detect` found on this CPU (NEON is part
            // of every aarch64 target's baseline).
            let sums = match self.kernels {
                #[cfg(target_arch = "x86_64")]
                Kernels::Avx512 => unsafe { bordered_gradients_avx512(img, x, y, n, st, outs) },
                #[cfg(target_arch = "x86_64")]
                Kernels::Avx2 => unsafe { bordered_gradients_avx2(img, x, y, n, st, outs) },
                #[cfg(target_arch = "aarch64")]
                Kernels::Neon => unsafe { arm64::bordered_gradients(img, x, y, n, st, outs) },
                Kernels::Portable => None,
            };
            if let Some(sums) = sums {
                return sums;
            }
        }
        self.sample_bordered(img, x, y);
        self.gradients(n, slot)
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
        let st = self.stride;
        let at = slot * n * st;
        let (gx, gy) = (&mut self.gx[at..at + n * st], &mut self.gy[at..at + n * st]);
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

    /// Samples the previous image's `(n + 2)²` window with its top-left sample at (x, y) into
    /// `bordered`.
    #[inline(always)]
    fn sample_bordered(&mut self, img: &GrayImage, x: f32, y: f32) {
        let size = 2 * self.config.half_window + 3;
        let (out, stride) = (&mut self.bordered, self.bstride);
        #[cfg(target_arch = "x86_64")]
        #[allow(unsafe_code)]
        {
            // SAFETY: `kernels` names features `Kernels::detect` found on this CPU.
            // The 512-bit kernels sample in `window_gradients`; here, only windows too wide for
            // it (`n + 2 > 16`) or near the image's edge come, which the AVX2 kernel serves.
            let done = match self.kernels {
                Kernels::Avx512 | Kernels::Avx2 => unsafe {
                    sample_avx2(img, x, y, size, stride, out)
                },
                Kernels::Portable => false,
            };
            if done {
                return;
            }
        }
        sample_patch(img, x, y, size, stride, out);
    }

    /// The window's patch and gradients from `bordered` (zero past the window's width) and the
    /// gradient matrix's sums [Σ gx², Σ gx·gy, Σ gy²], in [`LANES`] sums.
    #[inline(always)]
    fn gradients(&mut self, n: usize, slot: usize) -> [f32; 3] {
        let (bw, st) = (self.bstride, self.stride);
        let at = slot * n * st;
        let (patch, gx, gy) = (
            &mut self.patch[at..at + n * st],
            &mut self.gx[at..at + n * st],
            &mut self.gy[at..at + n * st],
        );
        #[cfg(target_arch = "x86_64")]
        #[allow(unsafe_code)]
        {
            let outs = [&mut *patch, &mut *gx, &mut *gy];
            match self.kernels {
                // SAFETY: `kernels` names features `Kernels::detect` found on this CPU.
                // (AVX-512 CPUs come here only as `sample_bordered` says.)
                Kernels::Avx512 | Kernels::Avx2 => {
                    return unsafe { gradients_avx2(&self.bordered, bw, n, outs) };
                }
                Kernels::Portable => {}
            }
        }
        let mut sums = [[[0.0f32; LANES]; 2]; 3];
        for r in 0..n {
            let a = r % 2;
            let up = &self.bordered[r * bw..(r + 1) * bw];
            let mid = &self.bordered[(r + 1) * bw..(r + 2) * bw];
            let down = &self.bordered[(r + 2) * bw..(r + 3) * bw];
            for c0 in (0..st).step_by(LANES) {
                let k0 = r * st + c0;
                let patch: &mut [f32; LANES] = (&mut patch[k0..k0 + LANES]).try_into().unwrap();
                let gxs: &mut [f32; LANES] = (&mut gx[k0..k0 + LANES]).try_into().unwrap();
                let gys: &mut [f32; LANES] = (&mut gy[k0..k0 + LANES]).try_into().unwrap();
                let m: &[f32; LANES + 2] = mid[c0..c0 + LANES + 2].try_into().unwrap();
                let u: &[f32; LANES] = up[c0 + 1..c0 + 1 + LANES].try_into().unwrap();
                let dn: &[f32; LANES] = down[c0 + 1..c0 + 1 + LANES].try_into().unwrap();
                for k in 0..LANES {
                    let inside = c0 + k < n;
                    let gx = if inside { 0.5 * (m[k + 2] - m[k]) } else { 0.0 };
                    let gy = if inside { 0.5 * (dn[k] - u[k]) } else { 0.0 };
                    patch[k] = if inside { m[k + 1] } else { 0.0 };
                    gxs[k] = gx;
                    gys[k] = gy;
                    sums[0][a][k] += gx * gx;
                    sums[1][a][k] += gx * gy;
                    sums[2][a][k] += gy * gy;
                }
            }
        }
        sums.map(|s| reduce(&s))
    }

    /// The next image's window with its top-left sample at (x, y) against the patch: the sums
    /// [Σ (patch − moving)·gx, Σ (patch − moving)·gy, Σ |patch − moving|], in [`LANES`] sums, the
    /// lane groups of a row in the outer loop and the rows in the inner one.
    #[inline(always)]
    fn mismatch(&mut self, img: &GrayImage, x: f32, y: f32, slot: usize) -> [f32; 3] {
        let n = 2 * self.config.half_window + 1;
        let st = self.stride;
        let at = slot * n * st;
        let (patch, gx, gy) = (
            &self.patch[at..at + n * st],
            &self.gx[at..at + n * st],
            &self.gy[at..at + n * st],
        );
        #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
        #[allow(unsafe_code)]
        {
            let window = [patch, gx, gy];
            // SAFETY: `kernels` names features `Kernels::detect` found on this CPU (NEON is part
            // of every aarch64 target's baseline).
            let sums = match self.kernels {
                #[cfg(target_arch = "x86_64")]
                Kernels::Avx512 => unsafe { mismatch_avx512(img, x, y, n, st, window) },
                #[cfg(target_arch = "x86_64")]
                Kernels::Avx2 => unsafe { mismatch_avx2(img, x, y, n, st, window) },
                #[cfg(target_arch = "aarch64")]
                Kernels::Neon => unsafe { arm64::mismatch(img, x, y, n, st, window) },
                Kernels::Portable => None,
            };
            if let Some(sums) = sums {
                return sums;
            }
        }
        sample_patch(img, x, y, n, st, &mut self.moving);
        let mut sums = [[[0.0f32; LANES]; 2]; 3];
        for c0 in (0..st).step_by(LANES) {
            for r in 0..n {
                let a = r % 2;
                let k0 = r * st + c0;
                let p = &patch[k0..k0 + LANES];
                let m = &self.moving[k0..k0 + LANES];
                let (gx, gy) = (&gx[k0..k0 + LANES], &gy[k0..k0 + LANES]);
                for k in 0..LANES {
                    let diff = p[k] - m[k];
                    sums[0][a][k] += diff * gx[k];
                    sums[1][a][k] += diff * gy[k];
                    sums[2][a][k] += diff.abs();
                }
            }
        }
        sums.map(|s| reduce(&s))
    }
}

/// One window sum from its two accumulators (even and odd window rows), in the order every
/// kernel adds them: the two accumulators lane by lane, then the lanes as a tree (lane k + lane
/// k + 8, then + 4, + 2, + 1). Two chains of row sums and a tree instead of one chain and lane
/// order shorten the dependency chain each Lucas–Kanade iteration waits on.
#[inline(always)]
fn reduce(acc: &[[f32; LANES]; 2]) -> f32 {
    let mut t: [f32; LANES] = std::array::from_fn(|k| acc[0][k] + acc[1][k]);
    let mut width = LANES;
    while width > 1 {
        width /= 2;
        for k in 0..width {
            t[k] += t[k + width];
        }
    }
    t[0]
}

/// The integer top-left pixel of a window whose first sample sits at (x, y) and its fractions,
/// when the `rows + 1` image rows from it and the bytes `ix ..= ix + cols` of each lie inside the
/// image; `None` otherwise.
#[inline(always)]
fn window_inside(
    img: &GrayImage,
    x: f32,
    y: f32,
    cols: usize,
    rows: usize,
) -> Option<([usize; 2], [f32; 2])> {
    let (x0, y0) = (x.floor(), y.floor());
    let (ix, iy) = (x0 as i64, y0 as i64);
    let inside = ix >= 0
        && iy >= 0
        && ix + (cols as i64) < img.width() as i64
        && iy + (rows as i64) < img.height() as i64;
    inside.then_some(([ix as usize, iy as usize], [x - x0, y - y0]))
}

/// [`sample_patch`] for windows whose rows of whole 8-lane groups lie inside the image (`false`
/// otherwise, nothing written: the portable path clamps at the border): the portable path's
/// operations in its order, so the same bits, and the lanes past `size` set to zero, which the
/// portable path leaves as they are (zero: never written there).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn sample_avx2(
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
#[cfg(target_arch = "x86_64")]
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
#[cfg(target_arch = "x86_64")]
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

/// [`reduce`] of the accumulators `acc[row parity][half]` (lanes 0–7 of a lane group in half
/// 0, 8–15 in half 1).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn reduce_avx2(acc: [[std::arch::x86_64::__m256; 2]; 2]) -> f32 {
    use std::arch::x86_64::{_mm256_add_ps, _mm256_castps256_ps128, _mm256_extractf128_ps};
    let lo = _mm256_add_ps(acc[0][0], acc[1][0]);
    let hi = _mm256_add_ps(acc[0][1], acc[1][1]);
    let t8 = _mm256_add_ps(lo, hi);
    reduce_eight(_mm256_castps256_ps128(t8), _mm256_extractf128_ps::<1>(t8))
}

/// The last steps of [`reduce`]: lanes k + (k + 4) of the eight in `lo` (0–3) and `hi` (4–7),
/// then + 2, + 1.
#[cfg(target_arch = "x86_64")]
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
#[cfg(target_arch = "x86_64")]
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

/// [`PyramidalLk::gradients`] on eight lanes per step, lanes 0–7 and 8–15 of each lane group in
/// two registers of sums: the same operations in the same order (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn gradients_avx2(
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

/// The row walk of [`bordered_gradients_avx2`] and [`bordered_gradients_avx512`]: bordered rows
/// 0 and 1, then window rows two at a time (even rows into one chain of sums, odd rows into
/// another), each from the bordered rows above, at and below it; `row(r, [up, mid, down], acc)`
/// adds window row r to `acc`. Evaluates to `(even, odd)`. A macro, not a generic function, so
/// each kernel's closures stay inlined in its own target features (as `mismatch_avx2`'s macros).
#[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
macro_rules! walk_bordered_rows {
    ($n:expr, $along_x:ident, $bordered:ident, $row:ident, $zero:expr) => {{
        let (up, top) = $bordered(0, $along_x(0));
        let (mut mid, mut top) = $bordered(1, top);
        let mut up = up;
        let (mut even, mut odd) = ($zero, $zero);
        let mut r = 0;
        while r + 1 < $n {
            let (down, t) = $bordered(r + 2, top);
            even = $row(r, [up, mid, down], even);
            let (down2, t) = $bordered(r + 3, t);
            odd = $row(r + 1, [mid, down, down2], odd);
            (up, mid, top) = (down, down2, t);
            r += 2;
        }
        if r < $n {
            let (down, _) = $bordered(r + 2, top);
            even = $row(r, [up, mid, down], even);
        }
        (even, odd)
    }};
}

#[cfg(target_arch = "aarch64")]
mod arm64;

/// [`bordered_gradients_avx512`] on AVX2: each bordered row in two registers (lanes 0–7, 8–15),
/// its cells one and two to the right by shifts across the pair; the window's rows of sixteen
/// image bytes (and one) must lie inside the image (`None` otherwise, as for `n + 2 > 16`). The
/// same bits as the portable path; lanes past the bordered row hold image values here, which only
/// lanes the mask clears read.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn bordered_gradients_avx2(
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

/// [`PyramidalLk::mismatch`] where its window's rows of whole 8-lane groups lie inside the image
/// (`None` otherwise): each row of the next image's window is interpolated along x once and used
/// by the two window rows it lies between, and the sums are taken in the same pass, the portable
/// path's operations in its order (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn mismatch_avx2(
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
#[cfg(target_arch = "x86_64")]
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
#[cfg(target_arch = "x86_64")]
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
#[cfg(target_arch = "x86_64")]
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

/// [`reduce`] of the accumulators of even and odd rows.
#[cfg(target_arch = "x86_64")]
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

/// [`PyramidalLk::sample_bordered`] and [`PyramidalLk::gradients`] in one pass, for windows whose
/// bordered rows fit one register (`n + 2 ≤ 16`) and lie inside the image (`None` otherwise):
/// each bordered row is interpolated in a register and its cells one and two to the right come
/// from lane shifts, the same values as the portable path reads from `bordered` (the same bits).
/// Reading the stored rows back at those offsets instead made every load straddle two recent
/// stores, which the CPU cannot forward: a third of the flow's time went to that wait.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
fn bordered_gradients_avx512(
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

/// [`PyramidalLk::mismatch`] for windows inside the image (`None` otherwise), sixteen lanes per
/// step with the window's edge by masked loads; like [`mismatch_avx2`] it interpolates each image
/// row along x once and sums in the same pass (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx2,fma")]
fn mismatch_avx512(
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

    #[cfg(target_arch = "x86_64")]
    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn the_avx2_copies_and_kernels_give_the_same_pyramid_and_points() {
        crate::kernels::cpu::assert_avx2_fma_path();
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let (img0, img1) = (
            warped(id, [0.0, 0.0]),
            warped([[1.02, 0.03], [-0.02, 0.99]], [3.3, -2.1]),
        );
        let mut pyramids = Vec::new();
        for img in [&img0, &img1] {
            let (mut base, mut avx2) = (Pyramid::new(), Pyramid::new());
            base.build(img, 3);
            base.halve_body(img, 3, [0, 0, 640, 480]);
            avx2.build(img, 3);
            #[allow(unsafe_code)]
            // SAFETY: the CPU has AVX2 and FMA (checked above).
            unsafe {
                avx2.halve_avx2(img, 3, [0, 0, 640, 480])
            };
            assert_eq!(base.len(), avx2.len());
            for (a, b) in base.levels().iter().zip(avx2.levels()) {
                assert_eq!(a.data(), b.data());
            }
            pyramids.push(base);
        }
        let from = kernel_points();
        let n = from.len();
        let (prev, next) = (&pyramids[0], &pyramids[1]);
        // Points, status and errors of one run: the body as compiled for baseline x86-64, or its
        // AVX2 copy.
        let run = |lk: &mut PyramidalLk, avx2_copy: bool| {
            let (mut to, mut st, mut err) = (vec![[9.0; 2]; n], vec![true; n], vec![9.0; n]);
            if avx2_copy {
                #[allow(unsafe_code)]
                // SAFETY: the CPU has AVX2 and FMA (checked above).
                unsafe {
                    lk.track_with_avx2(prev, next, &from, &mut to, &mut st, &mut err, false)
                }
            } else {
                lk.track_body(prev, next, &from, &mut to, &mut st, &mut err, false)
            }
            .unwrap();
            (to, st, err)
        };
        let wide = Kernels::widest() == Kernels::Avx512;
        if !wide {
            eprintln!("SKIPPED (512-bit kernels): this CPU has no AVX-512 F, BW and VL");
        }
        // Windows of one 8-lane group, of one 16-lane group, of two, and the largest allowed.
        for half_window in [2, 5, 9, 15] {
            let cfg = LkConfig {
                half_window,
                ..LkConfig::default()
            };
            let with = |kernels| {
                let mut lk = PyramidalLk::new(cfg).unwrap();
                lk.kernels = kernels;
                lk
            };
            // The window kernels against the portable ones, bit for bit, in both copies.
            let body = run(&mut with(Kernels::Portable), false);
            assert_eq!(body, run(&mut with(Kernels::Portable), true));
            assert_eq!(body, run(&mut with(Kernels::Avx2), false));
            assert_eq!(body, run(&mut with(Kernels::Avx2), true));
            if wide {
                assert_eq!(body, run(&mut with(Kernels::Avx512), true));
            }
            // Enough tracked points that the comparison means something (the 5×5 window loses
            // more points as textureless).
            let tracked = body.1.iter().filter(|&&s| s).count();
            assert!(tracked > n / 3, "{half_window}: {:?}", body.1);
        }
    }

    /// The NEON window kernels against the portable ones, bit for bit: windows of one lane group
    /// and of two (whose bordered rows are too wide for the one-pass gradient kernel), points in
    /// the middle, near the border (clamped sampling) and near the right and bottom edges.
    #[cfg(target_arch = "aarch64")]
    #[test]
    fn the_neon_kernels_give_the_portable_points() {
        let id = [[1.0, 0.0], [0.0, 1.0]];
        let mut pyramids = Vec::new();
        for img in [
            warped(id, [0.0, 0.0]),
            warped([[1.02, 0.03], [-0.02, 0.99]], [3.3, -2.1]),
        ] {
            let mut p = Pyramid::new();
            p.build(&img, 3);
            pyramids.push(p);
        }
        let from = kernel_points();
        let n = from.len();
        let run = |kernels, half_window| {
            let cfg = LkConfig {
                half_window,
                ..LkConfig::default()
            };
            let mut lk = PyramidalLk::new(cfg).unwrap();
            lk.kernels = kernels;
            let (mut to, mut st, mut err) = (vec![[9.0; 2]; n], vec![true; n], vec![9.0; n]);
            lk.track(
                &pyramids[0],
                &pyramids[1],
                &from,
                &mut to,
                &mut st,
                &mut err,
            )
            .unwrap();
            (to, st, err)
        };
        // The NEON kernels serve inner windows of the default size (not only the fallback).
        let mut lk = PyramidalLk::new(LkConfig::default()).unwrap();
        let (n, st, img) = (11, lk.stride, &pyramids[0].levels()[0]);
        let outs = [
            &mut lk.patch[..n * st],
            &mut lk.gx[..n * st],
            &mut lk.gy[..n * st],
        ];
        #[allow(unsafe_code)]
        // SAFETY: NEON is part of every aarch64 target's baseline.
        let sums = unsafe { arm64::bordered_gradients(img, 100.3, 200.7, n, st, outs) };
        let window = [&lk.patch[..n * st], &lk.gx[..n * st], &lk.gy[..n * st]];
        #[allow(unsafe_code)]
        // SAFETY: as above.
        let mismatch = unsafe { arm64::mismatch(img, 101.1, 199.4, n, st, window) };
        assert!(sums.is_some() && mismatch.is_some());
        for half_window in [2, 5, 7, 9, 15] {
            let portable = run(Kernels::Portable, half_window);
            assert_eq!(portable, run(Kernels::Neon, half_window), "{half_window}");
            let tracked = portable.1.iter().filter(|&&s| s).count();
            assert!(tracked > n / 3, "{half_window}: {:?}", portable.1);
        }
    }

    /// Points the vector kernels are held to the portable ones on: the grid plus some near the
    /// border (the clamped sampling path) and near the right and bottom edges (the 512-bit
    /// kernels' masked loads reach them; the AVX2 and NEON ones fall back).
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
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
