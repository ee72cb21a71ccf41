//! The Lucas–Kanade tracker's window kernels (`track::flow`): per point and pyramid level, the
//! previous image's window sampled with a one-cell border, its patch, central-difference
//! gradients and gradient-matrix sums ([`Windows::gradients`]); per iteration, the next image's
//! window sampled where the motion has got to and its mismatch sums against the patch
//! ([`Windows::mismatch`]).
//!
//! Each iteration of a point waits on the last one's result, so the forms are written for
//! latency: each image row of the next window is interpolated along x once and serves the two
//! window rows it lies between, and the sums are taken in the same pass; each sum keeps separate
//! chains for even and odd rows and ends in a tree ([`reduce`]). The one-pass gradient forms hold
//! the bordered rows in registers and take their shifted cells by lane shifts: read back from
//! memory at offsets of one and two cells, each load straddled two recent stores and waited for
//! them to reach the cache.
//!
//! | form | lanes | where it runs |
//! |---|---|---|
//! | portable (this file) | arrays of sixteen | the reference; every CPU where no other form runs |
//! | NEON (`arm64.rs`) | four registers per lane group | aarch64, unless the portable path was asked for |
//! | AVX2 + FMA (`x86_64.rs`) | two registers per lane group | x86-64's native path |
//! | AVX-512 F, BW, VL (`x86_64.rs`) | one register, masked byte loads at the window's edge | x86-64's native path, where the CPU has them |
//!
//! The AVX-512 form's masked loads let windows up to the image's last column take its vector
//! path, where the others fall back.
//!
//! Every form gives the same bits: each sum keeps [`LANES`] lanes (cell c of a window row in lane
//! c mod [`LANES`]), adds them in one order at the end, and every lane does the portable form's
//! operations in its order (Rust never fuses `a·b + c`, and the vector forms keep multiplies and
//! adds apart). The tests hold every form this CPU runs to the portable one, bit for bit. A
//! form's one-pass kernels serve the windows they suit; the others (near the image's edge, whose
//! sampling clamps to the border, or too wide for one register) are sampled and differentiated in
//! separate steps, in AVX2 where an x86-64 form runs and in the portable code elsewhere.

/// The row walk of the one-pass gradient kernels (`x86_64::bordered_gradients_*`,
/// `arm64::bordered_gradients`): bordered rows 0 and 1, then window rows two at a time (even rows
/// into one chain of sums, odd rows into another), each from the bordered rows above, at and below
/// it; `row(r, [up, mid, down], acc)` adds window row r to `acc`. Evaluates to `(even, odd)`. A
/// macro, not a generic function, so each kernel's closures stay inlined in its own target
/// features (as `x86_64::mismatch_avx2`'s macros).
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
#[cfg(target_arch = "x86_64")]
mod x86_64;

use crate::image::GrayImage;

/// Lanes of the window sums: sixteen f32 sums kept apart (one AVX-512 register, two of AVX2,
/// four of NEON), added in a fixed order at the end ([`reduce`]).
pub(crate) const LANES: usize = 16;

/// Which form of the window kernels a [`Windows`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Form {
    /// Plain Rust (every CPU; the compiler vectorises what it can).
    Portable,
    /// AVX2 + FMA: 8 lanes a register, two registers per lane group.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// AVX-512 (F, BW, VL): one register per lane group, the window's edge by masked byte loads.
    #[cfg(target_arch = "x86_64")]
    Avx512,
    /// NEON (aarch64's baseline): four registers per lane group.
    #[cfg(target_arch = "aarch64")]
    Neon,
}

impl Form {
    /// The form the process's kernel choice names for the flow (`crate::kernels::choice().flow`:
    /// `portable`, `avx2` or `avx512`, so the forms can be timed against each other on one
    /// machine), else the widest this CPU runs; a named form the CPU lacks is ignored.
    pub(crate) fn chosen() -> Self {
        let widest = Self::widest();
        match crate::kernels::choice().flow.as_deref() {
            Some("portable") => Form::Portable,
            #[cfg(target_arch = "x86_64")]
            Some("avx2") if widest != Form::Portable => Form::Avx2,
            _ => widest,
        }
    }

    /// The widest form this CPU runs on the process's kernel path.
    pub(crate) fn widest() -> Self {
        #[cfg(target_arch = "aarch64")]
        if crate::kernels::cpu::neon() {
            return Form::Neon;
        }
        #[cfg(target_arch = "x86_64")]
        {
            use crate::kernels::cpu::{Avx512, has_avx2_fma, has_avx512};
            if has_avx512(Avx512::BwVl) {
                return Form::Avx512;
            }
            if has_avx2_fma() {
                return Form::Avx2;
            }
        }
        Form::Portable
    }

    /// Whether this CPU has the features the form is compiled for. NEON is part of every aarch64
    /// target's baseline; the x86-64 forms need the native path's feature checks.
    pub(crate) fn runs_here(self) -> bool {
        match self {
            Form::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Form::Avx2 => crate::kernels::cpu::has_avx2_fma(),
            #[cfg(target_arch = "x86_64")]
            Form::Avx512 => crate::kernels::cpu::has_avx512(crate::kernels::cpu::Avx512::BwVl),
            #[cfg(target_arch = "aarch64")]
            Form::Neon => true,
        }
    }

    /// Every form this CPU runs, the portable one first (for the tests). NEON is listed on the
    /// portable path too, where the tests still hold it to the portable form.
    #[cfg(test)]
    pub(crate) fn all() -> Vec<Self> {
        #[allow(unused_mut)]
        let mut forms = vec![Form::Portable];
        #[cfg(target_arch = "aarch64")]
        forms.push(Form::Neon);
        #[cfg(target_arch = "x86_64")]
        forms.extend(
            [Form::Avx2, Form::Avx512]
                .into_iter()
                .filter(|f| f.runs_here()),
        );
        forms
    }
}

/// One tracker's window buffers and the form that fills them: for each of a batch's `slots`
/// points its window's patch and gradients (kept from [`Windows::gradients`] for the
/// [`Windows::mismatch`] calls of the level), plus scratch rows.
#[derive(Debug, Clone)]
pub(crate) struct Windows {
    form: Form,
    /// The window's side, `2 · half window + 1`.
    n: usize,
    /// Cells between window rows: `n` rounded up to whole lane groups.
    stride: usize,
    /// Previous-image window with a 1-pixel border (for central-difference gradients), rows
    /// `bstride = stride + LANES` cells apart so whole lane groups of the gradients read inside it.
    bordered: Vec<f32>,
    bstride: usize,
    /// The window's rows, `stride` cells apart, one window per slot; the cells past the window's
    /// width stay zero in these three and in `moving`, so whole rows of lanes can be summed.
    patch: Vec<f32>,
    gx: Vec<f32>,
    gy: Vec<f32>,
    /// The next image's window, sampled here only where no vector form, which samples and sums in
    /// one pass, serves it.
    moving: Vec<f32>,
}

impl Windows {
    /// Buffers for `slots` windows of side `n`, filled by `form`.
    ///
    /// # Panics
    /// Where `form` does not run on this CPU ([`Form::runs_here`]): the kernels' soundness rests
    /// on it.
    pub(crate) fn new(n: usize, slots: usize, form: Form) -> Self {
        assert!(
            form.runs_here(),
            "the {form:?} window kernels do not run here"
        );
        let stride = n.next_multiple_of(LANES);
        Self {
            form,
            n,
            stride,
            bordered: vec![0.0; (n + 2) * (stride + LANES)],
            bstride: stride + LANES,
            patch: vec![0.0; slots * n * stride],
            gx: vec![0.0; slots * n * stride],
            gy: vec![0.0; slots * n * stride],
            moving: vec![0.0; n * stride],
        }
    }

    /// Cells between a window's rows in [`Windows::gradients_mut`]'s slices.
    pub(crate) fn stride(&self) -> usize {
        self.stride
    }

    /// Slot `slot`'s gradients along x and y, `n` rows [`Windows::stride`] cells apart, for the
    /// caller to adjust before the level's [`Windows::mismatch`] calls read them. The cells past
    /// the window's width must stay zero.
    pub(crate) fn gradients_mut(&mut self, slot: usize) -> [&mut [f32]; 2] {
        let len = self.n * self.stride;
        let at = slot * len;
        [&mut self.gx[at..at + len], &mut self.gy[at..at + len]]
    }

    /// The previous image's window (`n + 2` samples a side, its border's top-left sample at
    /// pixel-index position (x, y)): its patch and gradients into `slot`, and the gradient
    /// matrix's sums [Σ gx², Σ gx·gy, Σ gy²].
    #[inline(always)]
    pub(crate) fn gradients(&mut self, img: &GrayImage, x: f32, y: f32, slot: usize) -> [f32; 3] {
        let (form, n, st) = (self.form, self.n, self.stride);
        let at = slot * n * st;
        let outs = [
            &mut self.patch[at..at + n * st],
            &mut self.gx[at..at + n * st],
            &mut self.gy[at..at + n * st],
        ];
        if let Some(sums) = one_pass_gradients(form, img, x, y, n, st, outs) {
            return sums;
        }
        self.sample_bordered(img, x, y);
        let outs = [
            &mut self.patch[at..at + n * st],
            &mut self.gx[at..at + n * st],
            &mut self.gy[at..at + n * st],
        ];
        bordered_gradients(form, &self.bordered, self.bstride, n, outs)
    }

    /// The next image's window with its top-left sample at (x, y) against slot `slot`'s patch:
    /// the sums [Σ (patch − moving)·gx, Σ (patch − moving)·gy, Σ |patch − moving|].
    #[inline(always)]
    pub(crate) fn mismatch(&mut self, img: &GrayImage, x: f32, y: f32, slot: usize) -> [f32; 3] {
        let (n, st) = (self.n, self.stride);
        let at = slot * n * st;
        let window = [
            &self.patch[at..at + n * st],
            &self.gx[at..at + n * st],
            &self.gy[at..at + n * st],
        ];
        if let Some(sums) = one_pass_mismatch(self.form, img, x, y, n, st, window) {
            return sums;
        }
        sample_patch(img, x, y, n, st, &mut self.moving);
        mismatch_portable(&self.moving, n, st, window)
    }

    /// Samples the previous image's `(n + 2)²` window with its top-left sample at (x, y) into
    /// `bordered`.
    #[inline(always)]
    fn sample_bordered(&mut self, img: &GrayImage, x: f32, y: f32) {
        let size = self.n + 2;
        let (out, stride) = (&mut self.bordered, self.bstride);
        // The AVX-512 form's one-pass kernel leaves here only windows too wide for a register
        // (`n + 2 > 16`) or near the image's edge, which the AVX2 sampling serves.
        let done = match self.form {
            #[cfg(target_arch = "x86_64")]
            #[allow(unsafe_code)]
            // SAFETY: the form runs on this CPU (`Windows::new` checked it), and both x86-64
            // forms have AVX2 and FMA.
            Form::Avx512 | Form::Avx2 => unsafe {
                x86_64::sample_avx2(img, x, y, size, stride, out)
            },
            _ => false,
        };
        if !done {
            sample_patch(img, x, y, size, stride, out);
        }
    }
}

/// The forms' kernels that sample the previous image's bordered window and take its patch,
/// gradients and sums in one pass, for the windows they suit (`None` for the others, and from the
/// portable form).
#[inline(always)]
#[cfg_attr(
    not(any(target_arch = "x86_64", target_arch = "aarch64")),
    allow(unused_variables)
)]
fn one_pass_gradients(
    form: Form,
    img: &GrayImage,
    x: f32,
    y: f32,
    n: usize,
    st: usize,
    outs: [&mut [f32]; 3],
) -> Option<[f32; 3]> {
    // SAFETY (each arm): the form runs on this CPU (`Windows::new` checked it; NEON is part of
    // every aarch64 target's baseline).
    match form {
        #[cfg(target_arch = "x86_64")]
        #[allow(unsafe_code)]
        Form::Avx512 => unsafe { x86_64::bordered_gradients_avx512(img, x, y, n, st, outs) },
        #[cfg(target_arch = "x86_64")]
        #[allow(unsafe_code)]
        Form::Avx2 => unsafe { x86_64::bordered_gradients_avx2(img, x, y, n, st, outs) },
        #[cfg(target_arch = "aarch64")]
        #[allow(unsafe_code)]
        Form::Neon => unsafe { arm64::bordered_gradients(img, x, y, n, st, outs) },
        Form::Portable => None,
    }
}

/// The patch, gradients and sums from a sampled bordered window, in the form's lanes (the x86-64
/// forms' AVX2 kernel; the portable one elsewhere).
#[inline(always)]
fn bordered_gradients(
    form: Form,
    bordered: &[f32],
    bw: usize,
    n: usize,
    outs: [&mut [f32]; 3],
) -> [f32; 3] {
    match form {
        #[cfg(target_arch = "x86_64")]
        #[allow(unsafe_code)]
        // SAFETY: the form runs on this CPU (`Windows::new` checked it), and both x86-64 forms
        // have AVX2 and FMA.
        Form::Avx512 | Form::Avx2 => unsafe { x86_64::gradients_avx2(bordered, bw, n, outs) },
        _ => gradients_portable(bordered, bw, n, outs),
    }
}

/// The forms' kernels that sample the next image's window and take its mismatch sums in one pass,
/// for the windows they suit (`None` for the others, and from the portable form).
#[inline(always)]
#[cfg_attr(
    not(any(target_arch = "x86_64", target_arch = "aarch64")),
    allow(unused_variables)
)]
fn one_pass_mismatch(
    form: Form,
    img: &GrayImage,
    x: f32,
    y: f32,
    n: usize,
    st: usize,
    window: [&[f32]; 3],
) -> Option<[f32; 3]> {
    // SAFETY (each arm): the form runs on this CPU (`Windows::new` checked it; NEON is part of
    // every aarch64 target's baseline).
    match form {
        #[cfg(target_arch = "x86_64")]
        #[allow(unsafe_code)]
        Form::Avx512 => unsafe { x86_64::mismatch_avx512(img, x, y, n, st, window) },
        #[cfg(target_arch = "x86_64")]
        #[allow(unsafe_code)]
        Form::Avx2 => unsafe { x86_64::mismatch_avx2(img, x, y, n, st, window) },
        #[cfg(target_arch = "aarch64")]
        #[allow(unsafe_code)]
        Form::Neon => unsafe { arm64::mismatch(img, x, y, n, st, window) },
        Form::Portable => None,
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

/// The portable form of the gradients: the window's patch and gradients from `bordered` (rows
/// `bw` cells apart; zero past the window's width) and the gradient matrix's sums
/// [Σ gx², Σ gx·gy, Σ gy²], in [`LANES`] sums.
#[inline(always)]
fn gradients_portable(
    bordered: &[f32],
    bw: usize,
    n: usize,
    [patch, gx, gy]: [&mut [f32]; 3],
) -> [f32; 3] {
    let st = n.next_multiple_of(LANES);
    let mut sums = [[[0.0f32; LANES]; 2]; 3];
    for r in 0..n {
        let a = r % 2;
        let up = &bordered[r * bw..(r + 1) * bw];
        let mid = &bordered[(r + 1) * bw..(r + 2) * bw];
        let down = &bordered[(r + 2) * bw..(r + 3) * bw];
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

/// The portable form of the mismatch: the next image's window `moving` (rows `st` cells apart,
/// zero past the window's width) against the patch, in [`LANES`] sums, the lane groups of a row in
/// the outer loop and the rows in the inner one.
#[inline(always)]
fn mismatch_portable(
    moving: &[f32],
    n: usize,
    st: usize,
    [patch, gx, gy]: [&[f32]; 3],
) -> [f32; 3] {
    let mut sums = [[[0.0f32; LANES]; 2]; 3];
    for c0 in (0..st).step_by(LANES) {
        for r in 0..n {
            let a = r % 2;
            let k0 = r * st + c0;
            let p = &patch[k0..k0 + LANES];
            let m = &moving[k0..k0 + LANES];
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

/// One window sum from its two accumulators (even and odd window rows), in the order every
/// form adds them: the two accumulators lane by lane, then the lanes as a tree (lane k + lane
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w`×`h` image of fine, irregular texture (strong gradients everywhere, no two windows
    /// alike).
    fn texture(w: usize, h: usize) -> GrayImage {
        let mut img = GrayImage::new(w, h);
        for (i, v) in img.data_mut().iter_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            *v = ((x * 37 + y * 101 + (x * y) % 29 * 7) % 251) as u8;
        }
        img
    }

    /// Window sides the forms are held to the portable one on: one 8-lane group, one 16-lane
    /// group, a bordered row just too wide for the one-pass gradient kernels, two lane groups, the
    /// largest the tracker allows.
    const SIDES: [usize; 6] = [3, 5, 11, 15, 19, 31];

    /// Top-left sample positions of windows of side `n` in a `w`×`h` image: inside, off the top
    /// and left edges (clamped sampling), just inside the right and bottom edges (where the
    /// AVX-512 form's masked loads still reach and the others fall back), and past them.
    fn positions(n: usize, w: usize, h: usize) -> Vec<(f32, f32)> {
        let along = |len: usize| {
            let len = len as f32;
            let n = n as f32;
            [
                -3.3,
                -0.6,
                0.0,
                0.25,
                1.5,
                40.7,
                len - n - 17.4,
                len - n - 2.6,
                len - n - 1.2,
            ]
        };
        let (xs, ys) = (along(w), along(h));
        xs.iter()
            .flat_map(|&x| ys.iter().map(move |&y| (x, y)))
            .collect()
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// Slot `slot`'s patch and gradients.
    fn slot(win: &Windows, slot: usize) -> [&[f32]; 3] {
        let len = win.n * win.stride;
        let at = slot * len;
        [
            &win.patch[at..at + len],
            &win.gx[at..at + len],
            &win.gy[at..at + len],
        ]
    }

    /// Every form's gradients and mismatch sums, and the patch and gradients it keeps, are the
    /// portable form's bits, for every window side and position (each window compared with the
    /// next image's window at a fractional shift).
    #[test]
    fn every_form_gives_the_portable_windows_and_sums() {
        let (w, h) = (96, 72);
        let (prev, next) = (texture(w, h), texture(w + 3, h));
        for n in SIDES {
            let mut portable = Windows::new(n, 2, Form::Portable);
            let mut forms: Vec<Windows> = Form::all()
                .into_iter()
                .map(|f| Windows::new(n, 2, f))
                .collect();
            for (i, (x, y)) in positions(n, w, h).into_iter().enumerate() {
                let s = i % 2;
                let want = portable.gradients(&prev, x - 1.0, y - 1.0, s);
                let want_mismatch = portable.mismatch(&next, x + 0.37, y - 0.61, s);
                for win in &mut forms {
                    let form = win.form;
                    let got = win.gradients(&prev, x - 1.0, y - 1.0, s);
                    assert_eq!(bits(&got), bits(&want), "{form:?} n {n} at ({x}, {y})");
                    for (g, p) in slot(win, s).iter().zip(slot(&portable, s)) {
                        assert_eq!(bits(g), bits(p), "{form:?} n {n} at ({x}, {y})");
                    }
                    let got = win.mismatch(&next, x + 0.37, y - 0.61, s);
                    assert_eq!(
                        bits(&got),
                        bits(&want_mismatch),
                        "{form:?} n {n} mismatch at ({x}, {y})"
                    );
                }
            }
        }
    }

    /// The vector forms' one-pass kernels serve windows of the default side well inside the image
    /// (the comparison above is not of the portable fallback alone).
    #[test]
    fn the_vector_forms_serve_inner_windows() {
        let img = texture(96, 72);
        let n = 11;
        for form in Form::all().into_iter().filter(|&f| f != Form::Portable) {
            let mut win = Windows::new(n, 1, form);
            let st = win.stride;
            let len = n * st;
            let outs = [
                &mut win.patch[..len],
                &mut win.gx[..len],
                &mut win.gy[..len],
            ];
            assert!(one_pass_gradients(form, &img, 30.3, 20.7, n, st, outs).is_some());
            let window = [&win.patch[..len], &win.gx[..len], &win.gy[..len]];
            assert!(one_pass_mismatch(form, &img, 31.1, 19.4, n, st, window).is_some());
        }
    }

    /// On a ramp (grey x + 2y) every form's gradients are the ramp's slopes and its mismatch sums
    /// those of the shift between the windows, to rounding: the forms compute the definition, not
    /// merely each other.
    #[test]
    fn every_form_measures_a_ramp() {
        let (w, h) = (80, 60);
        let mut img = GrayImage::new(w, h);
        for (i, v) in img.data_mut().iter_mut().enumerate() {
            *v = (i % w + 2 * (i / w)) as u8;
        }
        let close = |a: f32, b: f32| (a - b).abs() <= 1e-3 * b.abs().max(1.0);
        for form in Form::all() {
            for n in [5, 11, 19] {
                let mut win = Windows::new(n, 1, form);
                let area = (n * n) as f32;
                let [gxx, gxy, gyy] = win.gradients(&img, 10.25, 8.5, 0);
                assert!(
                    close(gxx, area) && close(gxy, 2.0 * area) && close(gyy, 4.0 * area),
                    "{form:?} n {n}: {gxx} {gxy} {gyy}"
                );
                // The next window 0.5 px right and 0.25 px down: each cell brighter by 1.
                let [bx, by, sad] = win.mismatch(&img, 11.75, 9.75, 0);
                assert!(
                    close(bx, -area) && close(by, -2.0 * area) && close(sad, area),
                    "{form:?} n {n}: {bx} {by} {sad}"
                );
            }
        }
    }

    /// Sampling clamps to the border: a window wholly left of the image repeats its first column.
    #[test]
    fn sampling_clamps_to_the_border() {
        let img = texture(40, 30);
        let mut out = [0.0f32; 5 * 16];
        sample_patch(&img, -20.0, 3.0, 5, 16, &mut out);
        for r in 0..5 {
            for c in 0..5 {
                assert_eq!(out[r * 16 + c], f32::from(img.get(0, 3 + r)));
            }
            assert!(out[r * 16 + 5..(r + 1) * 16].iter().all(|&v| v == 0.0));
        }
    }

    #[test]
    fn the_reduction_adds_in_its_tree_order() {
        let mut acc = [[0.0f32; LANES]; 2];
        acc[0][0] = 1e8;
        acc[1][8] = -1e8;
        acc[0][1] = 1.0;
        // Lane 0 + lane 8 cancel before lane 1 is added: a plain left-to-right sum would lose it.
        assert_eq!(reduce(&acc), 1.0);
    }

    /// The tracker's form runs here and is the one the kernel choice names, else the widest.
    #[test]
    fn the_chosen_form_follows_the_kernel_choice() {
        let (chosen, widest) = (Form::chosen(), Form::widest());
        assert!(chosen.runs_here() && Form::all().contains(&chosen));
        match crate::kernels::choice().flow.as_deref() {
            Some("portable") => assert_eq!(chosen, Form::Portable),
            #[cfg(target_arch = "x86_64")]
            Some("avx2") if widest != Form::Portable => assert_eq!(chosen, Form::Avx2),
            _ => assert_eq!(chosen, widest),
        }
    }

    /// Where the CPU runs the AVX2 forms, the tests above include them.
    #[cfg(target_arch = "x86_64")]
    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn the_avx2_forms_are_among_those_tested() {
        crate::kernels::cpu::assert_avx2_fma_path();
        assert!(Form::all().contains(&Form::Avx2));
        assert_ne!(Form::widest(), Form::Portable);
    }
}
