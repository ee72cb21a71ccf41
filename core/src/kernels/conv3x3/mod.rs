//! A convolution's block of sixteen output channels for up to six output positions — bias, the
//! products of every tap and a ReLU — in f32 fused multiply-adds on four-lane (128-bit) vectors,
//! as an aarch64 phone computes the networks: [`Block`] for a full convolution (any list of taps:
//! the 3×3 layers of the M3 trunks and of the detector, the detector's 1×1 layers; its heads
//! without the ReLU), [`Depthwise`] for one 3×3 kernel per channel (the detector's blocks).
//! [`crate::nn::conv`] and `nn::tail` lay the layers out and call these per block.
//!
//! Why here and not in tract: tract lowers each such layer to an explicit `Pad` copy, a lazily
//! gathered im2col matrix and a matrix product, gives each run's every output a new tensor (583
//! heap allocations per tracked frame) and keeps its convolution glue at full speed only where
//! tract-core is built for speed. Here each layer reads the previous one's output in place
//! (written with the zero border that is its padding) and multiplies straight from it, as the
//! x86-64 forms in `conv` do.
//!
//! Shape: sixteen output channels are four vectors, six positions twenty-four accumulators; with
//! the tap's four weight vectors and a broadcast input value that is 29 of NEON's 32 registers.
//! Per tap: four weight loads, six broadcasts, twenty-four FMAs. [`Depthwise`] loads each tap's
//! sixteen input values as they lie (positions interleaved) instead of broadcasting one.
//!
//! | form | where it runs |
//! |---|---|
//! | portable (`[f32; 4]`, `f32::mul_add`) | the reference; aarch64 with `MONOTRACK_KERNELS=portable` |
//! | NEON (`arm64.rs`: `fmla`, `ld1r`) | aarch64 |
//! | x86-64 twin (`x86_64.rs`: 128-bit `vfmadd`, `vbroadcastss`) | x86-64's portable path (`MONOTRACK_KERNELS=portable`), so the phone's path is timed on a development machine with the phone's vector width |
//!
//! Every form computes each lane as the same chain of fused multiply-adds in the same tap order
//! and the same ReLU (`v > 0 ? v : +0`, which sends NaN and −0 to +0), so all give the same bits:
//! the tests hold each to the portable form byte for byte, and a phone computes what the
//! development machine's portable path computed.

#[cfg(target_arch = "aarch64")]
mod arm64;
#[cfg(target_arch = "x86_64")]
mod avx;
#[cfg(target_arch = "x86_64")]
mod x86_64;
#[cfg(target_arch = "x86_64")]
pub(crate) use avx::nonnegative_max;

/// Output channels of a block: four vectors of four lanes.
pub(crate) const BLOCK: usize = 16;

/// Output positions computed together (see the module notes).
pub(crate) const POSITIONS: usize = 6;

/// Four f32 lanes as one form holds them; every operation is lane by lane.
#[allow(unsafe_code)]
pub(crate) trait Lanes: Copy {
    /// The four values at `p`.
    ///
    /// # Safety
    /// `p` is valid for reading four values.
    unsafe fn load(p: *const f32) -> Self;
    /// The value at `p` in every lane.
    ///
    /// # Safety
    /// `p` is valid for reading one value.
    unsafe fn splat(p: *const f32) -> Self;
    /// `self + w · x`, rounded once.
    fn mul_add(self, w: Self, x: Self) -> Self;
    /// `v` where `v > 0`, else +0 (NaN and −0 included).
    fn relu(self) -> Self;
    /// The four lanes as an array.
    fn to_array(self) -> [f32; 4];
}

impl Lanes for [f32; 4] {
    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn load(p: *const f32) -> Self {
        // SAFETY: the caller's contract.
        unsafe { p.cast::<[f32; 4]>().read_unaligned() }
    }

    #[inline(always)]
    #[allow(unsafe_code)]
    unsafe fn splat(p: *const f32) -> Self {
        // SAFETY: the caller's contract.
        [unsafe { p.read() }; 4]
    }

    #[inline(always)]
    fn mul_add(self, w: Self, x: Self) -> Self {
        std::array::from_fn(|i| w[i].mul_add(x[i], self[i]))
    }

    #[inline(always)]
    fn relu(self) -> Self {
        self.map(|v| if v > 0.0 { v } else { 0.0 })
    }

    #[inline(always)]
    fn to_array(self) -> [f32; 4] {
        self
    }
}

/// Which form [`Block::run`] takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Form {
    /// Plain Rust ([`Lanes`] for `[f32; 4]`).
    Portable,
    /// NEON (baseline on aarch64).
    #[cfg(target_arch = "aarch64")]
    Neon,
    /// The 128-bit x86-64 twin; `wide_file`: with AVX-512VL's 32 vector registers, as NEON has
    /// (with 16 the accumulators spill).
    #[cfg(target_arch = "x86_64")]
    Fma128 { wide_file: bool },
}

impl Form {
    /// The fastest form this CPU runs: NEON on aarch64 unless the portable path was asked for;
    /// the x86-64 twin where the CPU has FMA; else the portable form.
    pub(crate) fn for_this_cpu() -> Self {
        #[cfg(target_arch = "aarch64")]
        if crate::kernels::cpu::neon() {
            return Form::Neon;
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("fma") {
            use std::arch::is_x86_feature_detected as has;
            return Form::Fma128 {
                wide_file: has!("avx512f") && has!("avx512vl"),
            };
        }
        Form::Portable
    }

    /// Every form this CPU can run (for the tests).
    #[cfg(test)]
    #[cfg_attr(
        not(any(target_arch = "x86_64", target_arch = "aarch64")),
        allow(unused_mut)
    )]
    pub(crate) fn all() -> Vec<Self> {
        let mut forms = vec![Form::Portable];
        #[cfg(target_arch = "aarch64")]
        forms.push(Form::Neon);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("fma") {
            forms.push(Form::Fma128 { wide_file: false });
            if std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl")
            {
                forms.push(Form::Fma128 { wide_file: true });
            }
        }
        forms
    }
}

/// `$s.$m::<P>(args)` with `P` the number of positions `$n` (1 to [`POSITIONS`]; 0 does
/// nothing): the kernels are compiled per group size so the accumulators stay in registers.
macro_rules! by_positions {
    ($n:expr, $s:ident . $m:ident ($($arg:expr),*)) => {
        match $n {
            0 => {}
            1 => $s.$m::<1>($($arg),*),
            2 => $s.$m::<2>($($arg),*),
            3 => $s.$m::<3>($($arg),*),
            4 => $s.$m::<4>($($arg),*),
            5 => $s.$m::<5>($($arg),*),
            6 => $s.$m::<6>($($arg),*),
            n => panic!("{n} positions in one group"),
        }
    };
}

/// One block of output channels of one layer (one batch slot).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Block<'a> {
    /// The layer's input (padded planes, or interleaved positions), as `taps` address it.
    pub(crate) input: &'a [f32],
    /// `taps.len() × BLOCK` weights: per tap the block's sixteen channels (zero past the layer's
    /// output channels).
    pub(crate) weights: &'a [f32],
    /// The block's sixteen biases (zero past the layer's output channels).
    pub(crate) bias: &'a [f32; BLOCK],
    /// Offset of each tap from a window's top-left value.
    pub(crate) taps: &'a [usize],
    /// The largest of `taps`.
    pub(crate) reach: usize,
    /// Channels of the block that exist: the planes stored (an interleaved output stores all
    /// sixteen, the extra ones zero).
    pub(crate) channels: usize,
    /// Values per output plane (planar output).
    pub(crate) plane: usize,
    /// Channels per position of an interleaved output; 0 for planes.
    pub(crate) width: usize,
    /// Whether a ReLU follows (the detector's heads have none).
    pub(crate) relu: bool,
}

impl Block<'_> {
    /// Computes the block at the output positions whose windows start at `at_in` (offsets in
    /// `input`) and which lie at `at_out` (offsets in an output plane; where the output is
    /// interleaved, positions), at most [`POSITIONS`] of them, into `out` (whose first plane, or
    /// first channel where interleaved, is the block's first channel).
    ///
    /// # Panics
    /// Where an offset, the weights or the output do not fit their buffers, or more than
    /// [`POSITIONS`] positions are given.
    pub(crate) fn run(&self, form: Form, at_in: &[usize], at_out: &[usize], out: &mut [f32]) {
        assert_eq!(at_in.len(), at_out.len(), "positions");
        assert!(self.weights.len() >= self.taps.len() * BLOCK, "weights");
        for &at in at_in {
            assert!(
                at + self.reach < self.input.len(),
                "window outside the input"
            );
        }
        for &o in at_out {
            let end = if self.width > 0 {
                o * self.width + BLOCK
            } else {
                (self.channels.max(1) - 1) * self.plane + o + 1
            };
            assert!(end <= out.len(), "store outside the output");
        }
        by_positions!(at_in.len(), self.run_n(form, at_in, at_out, out))
    }

    fn run_n<const P: usize>(
        &self,
        form: Form,
        at_in: &[usize],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        let at_in: &[usize; P] = at_in.try_into().expect("P offsets");
        let at_out: &[usize; P] = at_out.try_into().expect("P offsets");
        #[allow(unsafe_code)]
        // SAFETY: `run` checked every offset against its buffer; each form's CPU features are
        // those `Form` was chosen for (`for_this_cpu`, `all`).
        unsafe {
            match form {
                Form::Portable => self.body::<[f32; 4], P>(at_in, at_out, out),
                #[cfg(target_arch = "aarch64")]
                Form::Neon => arm64::run(self, at_in, at_out, out),
                #[cfg(target_arch = "x86_64")]
                Form::Fma128 { wide_file: false } => x86_64::run(self, at_in, at_out, out),
                #[cfg(target_arch = "x86_64")]
                Form::Fma128 { wide_file: true } => x86_64::run_wide_file(self, at_in, at_out, out),
            }
        }
    }

    /// The kernel in lanes `V`.
    ///
    /// # Safety
    /// Every `at_in[j] + taps[t]` lies inside `input`, `weights` holds `taps.len() × BLOCK`
    /// values, and the stores at `at_out` lie inside `out` (what [`Block::run`] checks); `V`'s
    /// operations run on this CPU.
    #[inline(always)]
    #[allow(unsafe_code)]
    pub(crate) unsafe fn body<V: Lanes, const P: usize>(
        &self,
        at_in: &[usize; P],
        at_out: &[usize; P],
        out: &mut [f32],
    ) {
        let (x, w, b) = (
            self.input.as_ptr(),
            self.weights.as_ptr(),
            self.bias.as_ptr(),
        );
        // SAFETY: the bias holds BLOCK values; the loads below as the contract says.
        unsafe {
            let bias: [V; 4] = std::array::from_fn(|h| V::load(b.add(4 * h)));
            let mut acc = [bias; P];
            for (t, &tap) in self.taps.iter().enumerate() {
                let wt: [V; 4] = std::array::from_fn(|h| V::load(w.add(t * BLOCK + 4 * h)));
                for (acc, &at) in acc.iter_mut().zip(at_in) {
                    let v = V::splat(x.add(at + tap));
                    for (a, &wt) in acc.iter_mut().zip(&wt) {
                        *a = a.mul_add(wt, v);
                    }
                }
            }
            let relu = self.relu;
            let act = move |a: V| if relu { a.relu() } else { a }.to_array();
            for (acc, &o) in acc.iter().zip(at_out) {
                if self.width > 0 {
                    let dst = &mut out[o * self.width..][..BLOCK];
                    for (d, &a) in dst.chunks_exact_mut(4).zip(acc) {
                        d.copy_from_slice(&act(a));
                    }
                } else {
                    let lanes: [f32; BLOCK] = std::array::from_fn(|c| act(acc[c / 4])[c % 4]);
                    for (c, &v) in lanes[..self.channels].iter().enumerate() {
                        out[c * self.plane + o] = v;
                    }
                }
            }
        }
    }
}

/// A full convolution's every block of sixteen output channels over all its output positions, in
/// groups of [`POSITIONS`]: the walk `conv` and `nn::tail` share.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FullLayer<'a> {
    /// As [`Block::input`].
    pub(crate) input: &'a [f32],
    /// Per block of output channels, `taps.len() × BLOCK` weights (as [`Block::weights`]).
    pub(crate) packed: &'a [f32],
    /// The biases, a whole number of blocks (zero past `cout`).
    pub(crate) bias: &'a [f32],
    /// As [`Block::taps`] and [`Block::reach`].
    pub(crate) taps: &'a [usize],
    pub(crate) reach: usize,
    /// Output channels.
    pub(crate) cout: usize,
    /// As [`Block::plane`], [`Block::width`] and [`Block::relu`].
    pub(crate) plane: usize,
    pub(crate) width: usize,
    pub(crate) relu: bool,
    /// Each output position's window in the input and place in the output (as [`Block::run`]).
    pub(crate) at_in: &'a [usize],
    pub(crate) at_out: &'a [usize],
}

impl FullLayer<'_> {
    /// Computes the layer into `out` (channel planes, or interleaved positions of `width`).
    ///
    /// # Panics
    /// As [`Block::run`]; where `packed` or `bias` hold fewer blocks than `cout` needs.
    pub(crate) fn run(&self, form: Form, out: &mut [f32]) {
        let k = self.taps.len();
        for blk in 0..self.cout.div_ceil(BLOCK) {
            let block = Block {
                input: self.input,
                weights: &self.packed[blk * k * BLOCK..][..k * BLOCK],
                bias: self.bias[blk * BLOCK..][..BLOCK]
                    .try_into()
                    .expect("a block of biases"),
                taps: self.taps,
                reach: self.reach,
                channels: BLOCK.min(self.cout - blk * BLOCK),
                plane: self.plane,
                width: self.width,
                relu: self.relu,
            };
            // From one block of channels to the next: sixteen channels of each position, or
            // sixteen planes.
            let at = if self.width > 0 {
                blk * BLOCK
            } else {
                blk * BLOCK * self.plane
            };
            let out = &mut out[at..];
            for (ai, ao) in self
                .at_in
                .chunks(POSITIONS)
                .zip(self.at_out.chunks(POSITIONS))
            {
                block.run(form, ai, ao, out);
            }
        }
    }
}

/// A depthwise 3×3 convolution (one kernel per channel) with a bias and a ReLU, over interleaved
/// positions of `width` channels in and out (the detector's blocks after its first layers):
/// sixteen channels at a time, each tap's input loaded as it lies, so every lane runs the same
/// chain of fused multiply-adds as [`Block`]'s.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Depthwise<'a> {
    /// Interleaved input: positions of `width` channels.
    pub(crate) input: &'a [f32],
    /// Per tap (row, column) `width` weights, channel by channel (zero past the channels).
    pub(crate) weights: &'a [f32],
    /// `width` biases (zero past the channels).
    pub(crate) bias: &'a [f32],
    /// Offset of each of the nine taps from a window's top-left position, in positions.
    pub(crate) taps: &'a [usize; 9],
    /// Channels per position of the input and the output: a whole number of [`BLOCK`]s.
    pub(crate) width: usize,
}

impl Depthwise<'_> {
    /// Computes the output positions `at_out` (in positions of `out`) whose windows start at the
    /// input positions `at_in`, at most [`POSITIONS`] of them, every channel.
    ///
    /// # Panics
    /// Where a window, a store, the weights or the biases do not fit their buffers, the width is
    /// not a whole number of blocks or more than [`POSITIONS`] positions are given.
    pub(crate) fn run(&self, form: Form, at_in: &[usize], at_out: &[usize], out: &mut [f32]) {
        let width = self.width;
        assert!(width.is_multiple_of(BLOCK), "width {width}");
        assert_eq!(at_in.len(), at_out.len(), "positions");
        assert!(
            self.weights.len() >= 9 * width && self.bias.len() >= width,
            "weights"
        );
        let reach = self.taps.iter().copied().max().unwrap_or(0);
        for &at in at_in {
            assert!(
                (at + reach + 1) * width <= self.input.len(),
                "window outside the input"
            );
        }
        for &o in at_out {
            assert!((o + 1) * width <= out.len(), "store outside the output");
        }
        by_positions!(at_in.len(), self.run_n(form, at_in, at_out, out))
    }

    fn run_n<const P: usize>(
        &self,
        form: Form,
        at_in: &[usize],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        let at_in: &[usize; P] = at_in.try_into().expect("P offsets");
        let at_out: &[usize; P] = at_out.try_into().expect("P offsets");
        #[allow(unsafe_code)]
        // SAFETY: `run` checked every offset against its buffer; each form's CPU features are
        // those `Form` was chosen for (`for_this_cpu`, `all`).
        unsafe {
            match form {
                Form::Portable => self.body::<[f32; 4], P>(at_in, at_out, out),
                #[cfg(target_arch = "aarch64")]
                Form::Neon => arm64::run_depthwise(self, at_in, at_out, out),
                #[cfg(target_arch = "x86_64")]
                Form::Fma128 { wide_file: false } => {
                    x86_64::run_depthwise(self, at_in, at_out, out)
                }
                #[cfg(target_arch = "x86_64")]
                Form::Fma128 { wide_file: true } => {
                    x86_64::run_depthwise_wide_file(self, at_in, at_out, out)
                }
            }
        }
    }

    /// The kernel in lanes `V`.
    ///
    /// # Safety
    /// What [`Depthwise::run`] checks holds; `V`'s operations run on this CPU.
    #[inline(always)]
    #[allow(unsafe_code)]
    pub(crate) unsafe fn body<V: Lanes, const P: usize>(
        &self,
        at_in: &[usize; P],
        at_out: &[usize; P],
        out: &mut [f32],
    ) {
        let width = self.width;
        let (x, w, b) = (
            self.input.as_ptr(),
            self.weights.as_ptr(),
            self.bias.as_ptr(),
        );
        for blk in (0..width).step_by(BLOCK) {
            // SAFETY: the checks of `run`: every tap's block of values, the weights' and the
            // biases' lie inside their buffers.
            unsafe {
                let bias: [V; 4] = std::array::from_fn(|h| V::load(b.add(blk + 4 * h)));
                let mut acc = [bias; P];
                for (t, &tap) in self.taps.iter().enumerate() {
                    let wt: [V; 4] =
                        std::array::from_fn(|h| V::load(w.add(t * width + blk + 4 * h)));
                    for (acc, &at) in acc.iter_mut().zip(at_in) {
                        let src = x.add((at + tap) * width + blk);
                        for (h, (a, &wt)) in acc.iter_mut().zip(&wt).enumerate() {
                            *a = a.mul_add(wt, V::load(src.add(4 * h)));
                        }
                    }
                }
                for (acc, &o) in acc.iter().zip(at_out) {
                    let dst = &mut out[o * width + blk..][..BLOCK];
                    for (d, &a) in dst.chunks_exact_mut(4).zip(acc) {
                        d.copy_from_slice(&a.relu().to_array());
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The definition: bias plus the sum over taps, in tap order, each product rounded into the
    /// sum once, then the ReLU.
    fn reference(block: &Block<'_>, at: usize, c: usize) -> f32 {
        let mut s = block.bias[c];
        for (t, &tap) in block.taps.iter().enumerate() {
            s = block.weights[t * BLOCK + c].mul_add(block.input[at + tap], s);
        }
        if s > 0.0 { s } else { 0.0 }
    }

    /// A deterministic spread of values in −1..1 with some exact zeros and negative zeros.
    fn values(n: usize, seed: usize) -> Vec<f32> {
        (0..n)
            .map(|i| match (i * 31 + seed) % 17 {
                0 => 0.0,
                1 => -0.0,
                _ => (((i * 7919 + seed * 104_729) % 2001) as f32 - 1000.0) / 1000.0,
            })
            .collect()
    }

    #[test]
    fn every_form_gives_the_definitions_bits_planar_and_interleaved() {
        // Planes of a 5×7 map with its border, 3 channels: taps (channel, row, column).
        let (cin, rows, cols) = (3, 7, 9);
        let plane = rows * cols;
        let taps: Vec<usize> = (0..9 * cin)
            .map(|t| (t / 9) * plane + (t % 9 / 3) * cols + t % 3)
            .collect();
        let input = values(cin * plane, 1);
        let weights = values(taps.len() * BLOCK, 2);
        let bias: [f32; BLOCK] = values(BLOCK, 3).try_into().unwrap();
        for channels in [BLOCK, 5] {
            for width in [0, 32] {
                let block = Block {
                    input: &input,
                    weights: &weights,
                    bias: &bias,
                    taps: &taps,
                    reach: *taps.iter().max().unwrap(),
                    channels,
                    plane: 40,
                    width,
                    relu: true,
                };
                for n in 1..=POSITIONS {
                    let at_in: Vec<usize> = (0..n).map(|j| (j % 3) * 2 + (j / 3) * cols).collect();
                    let at_out: Vec<usize> = (0..n).map(|j| 3 * j + 1).collect();
                    let len = if width > 0 { 40 * width } else { BLOCK * 40 };
                    let mut want = vec![7.0f32; len];
                    for (&a, &o) in at_in.iter().zip(&at_out) {
                        for c in 0..BLOCK {
                            let v = reference(&block, a, c);
                            if width > 0 {
                                want[o * width + c] = v;
                            } else if c < channels {
                                want[c * 40 + o] = v;
                            }
                        }
                    }
                    for form in Form::all() {
                        let mut got = vec![7.0f32; len];
                        block.run(form, &at_in, &at_out, &mut got);
                        let (g, w): (Vec<u32>, Vec<u32>) = (
                            got.iter().map(|v| v.to_bits()).collect(),
                            want.iter().map(|v| v.to_bits()).collect(),
                        );
                        assert_eq!(
                            g, w,
                            "{form:?}, {n} positions, {channels} channels, width {width}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn nan_and_negative_zero_become_positive_zero_in_every_form() {
        let input = [f32::NAN, -0.0, 1.0, -1.0];
        let taps = [0];
        let mut weights = [0.0f32; BLOCK];
        weights[0] = 1.0; // NaN · 1 → NaN
        weights[1] = 1.0; // −0 + (−0 · 1)... with a −0 bias stays −0
        let mut bias = [0.0f32; BLOCK];
        bias[1] = -0.0;
        for form in Form::all() {
            let block = Block {
                input: &input,
                weights: &weights,
                bias: &bias,
                taps: &taps,
                reach: 0,
                channels: BLOCK,
                plane: 0,
                width: BLOCK,
                relu: true,
            };
            let mut out = [9.0f32; 2 * BLOCK];
            block.run(form, &[0, 1], &[0, 1], &mut out);
            assert!(out.iter().all(|v| v.to_bits() == 0), "{form:?}: {out:?}");
        }
    }

    #[test]
    #[should_panic(expected = "window outside the input")]
    fn a_window_past_the_input_is_refused() {
        let (input, weights, bias) = ([0.0f32; 4], [0.0f32; BLOCK], [0.0f32; BLOCK]);
        let block = Block {
            input: &input,
            weights: &weights,
            bias: &bias,
            taps: &[0],
            reach: 0,
            channels: BLOCK,
            plane: 1,
            width: 0,
            relu: true,
        };
        block.run(Form::Portable, &[4], &[0], &mut [0.0; BLOCK]);
    }

    #[test]
    fn every_depthwise_form_gives_the_definitions_bits() {
        // A 5×6 grid of positions, 32 channels, taps of a 3×3 window on it.
        let (cols, width) = (6, 32);
        let taps: [usize; 9] = std::array::from_fn(|t| (t / 3) * cols + t % 3);
        let input = values(5 * cols * width, 4);
        let weights = values(9 * width, 5);
        let bias = values(width, 6);
        let dw = Depthwise {
            input: &input,
            weights: &weights,
            bias: &bias,
            taps: &taps,
            width,
        };
        for n in 1..=POSITIONS {
            let at_in: Vec<usize> = (0..n).map(|j| (j % 4) + (j / 4) * 2 * cols).collect();
            let at_out: Vec<usize> = (0..n).map(|j| 2 * j + 1).collect();
            let mut want = vec![7.0f32; 16 * width];
            for (&a, &o) in at_in.iter().zip(&at_out) {
                for c in 0..width {
                    let mut s = bias[c];
                    for (t, &tap) in taps.iter().enumerate() {
                        s = weights[t * width + c].mul_add(input[(a + tap) * width + c], s);
                    }
                    want[o * width + c] = if s > 0.0 { s } else { 0.0 };
                }
            }
            for form in Form::all() {
                let mut got = vec![7.0f32; 16 * width];
                dw.run(form, &at_in, &at_out, &mut got);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&want), "{form:?}, {n} positions");
            }
        }
    }

    #[test]
    fn a_block_without_relu_keeps_negative_sums() {
        let (input, taps) = ([2.0f32], [0]);
        let mut weights = [0.0f32; BLOCK];
        weights[0] = -1.5;
        let bias = [0.25f32; BLOCK];
        for form in Form::all() {
            let block = Block {
                input: &input,
                weights: &weights,
                bias: &bias,
                taps: &taps,
                reach: 0,
                channels: 2,
                plane: 1,
                width: 0,
                relu: false,
            };
            let mut out = [9.0f32; 2];
            block.run(form, &[0], &[0], &mut out);
            assert_eq!(out, [-2.75, 0.25], "{form:?}");
        }
    }
}
