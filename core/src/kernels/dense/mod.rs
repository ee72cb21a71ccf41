//! A fully connected layer's product, `out = scale ⊙ (weights · x) + bias` with an optional
//! ReLU, as M3's heads compute it (`crate::nn::dense` matches the heads in the graphs): the
//! portable form (f32 fused multiply-adds over columns in chunks of [`CHUNK`], with f32 or int8
//! weights), its copies compiled for AVX2 + FMA and for FMA alone (the same operations, so the
//! same bits), and on x86-64 CPUs with AVX-512 VNNI the int8 form in `x86_64.rs`.

#[cfg(target_arch = "x86_64")]
mod x86_64;

/// Outputs of a layer accumulated together: four 256-bit registers, which stay in registers over
/// the whole input (accumulating in the output buffer made every product a load and a store). The
/// weights' columns are padded to whole chunks.
pub(crate) const CHUNK: usize = 32;

/// `out = scale ⊙ (weights · x) + bias` (through a ReLU with `relu`) in int8 products: `x`
/// rounded to 16-bit steps of 1/65535 of its largest value, held as two u8 digits in `quantised`
/// (the high digits' words, then the low digits'), each digit's four u8 × i8 products summed in
/// an i32 lane by `vpdpbusd` (`quads` as [`Weights::I8`] holds them) and the two sums joined as
/// `256·high + low`. False, with nothing written, where the CPU lacks AVX-512 VNNI or `x` has a
/// negative or non-finite value.
///
/// Why: the f32 kernel widens each int8 weight to f32 before its multiply-add (four instructions
/// per eight weights before the FMA); here one instruction takes sixty-four. Why two digits: with
/// one (u8 inputs, as the 3×3 layers take) a brow gesture probability of the `m3_golden` cases
/// moved 0.027 from the Python reference, over the test's 0.02; the second digit costs a second
/// product per weight, still a fraction of the f32 kernel's work.
pub(crate) fn int8_product(
    x: &[f32],
    quads: &[u32],
    scale: &[f32],
    bias: &[f32],
    relu: bool,
    quantised: &mut [u32],
    out: &mut [f32],
) -> bool {
    #[cfg(target_arch = "x86_64")]
    if crate::kernels::cpu::has_avx512(crate::kernels::cpu::Avx512::Vnni) {
        #[allow(unsafe_code)]
        // SAFETY: the CPU has AVX-512F, BW and VNNI.
        return unsafe { x86_64::int8_product_avx512(x, quads, scale, bias, relu, quantised, out) };
    }
    let _ = (x, quads, scale, bias, relu, quantised, out);
    false
}

/// A weight as the kernel multiplies it.
pub(crate) trait Weight: Copy {
    fn value(self) -> f32;
}

impl Weight for f32 {
    #[inline(always)]
    fn value(self) -> f32 {
        self
    }
}

impl Weight for i8 {
    #[inline(always)]
    fn value(self) -> f32 {
        f32::from(self)
    }
}

/// One fully connected layer's product (`crate::nn::dense` runs them): `x`, `weights` input-major (`x.len()` rows of
/// `bias.len()`, a whole number of [`CHUNK`]s), `scale` per column (1 without), the bias, and
/// whether a ReLU follows.
pub(crate) struct Product<'a, W> {
    pub(crate) x: &'a [f32],
    pub(crate) weights: &'a [W],
    pub(crate) scale: Option<&'a [f32]>,
    pub(crate) bias: &'a [f32],
    pub(crate) relu: bool,
}

impl<W: Weight> Product<'_, W> {
    crate::kernels::cpu::with_avx2_copy! {
        /// `out = scale ⊙ (weights · x) + bias` (`out` the first of the columns' outputs).
        fn run_plain / run_avx2 (&self, out: &mut [f32]) => run_body
    }

    /// `out = scale ⊙ (weights · x) + bias` (`out` the first of the columns' outputs): on an
    /// x86-64 CPU with FMA that runs the portable path, through a copy compiled for FMA — the same
    /// fused multiply-adds as everywhere, so the same bits, where the portable build calls a
    /// library routine for each one.
    pub(crate) fn run(&self, out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if !crate::kernels::cpu::has_avx2_fma() && crate::kernels::cpu::has_fma() {
            #[allow(unsafe_code)]
            // SAFETY: the CPU has FMA (and so AVX), the features the copy is compiled for.
            return unsafe { self.run_fma(out) };
        }
        self.run_plain(out)
    }

    /// [`Self::run_body`] compiled for FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,fma")]
    fn run_fma(&self, out: &mut [f32]) {
        self.run_body(out)
    }

    #[inline(always)]
    fn run_body(&self, out: &mut [f32]) {
        let Self {
            x,
            weights,
            scale,
            bias,
            relu,
        } = *self;
        let np = bias.len();
        debug_assert!(np.is_multiple_of(CHUNK) && weights.len() == x.len() * np && out.len() <= np);
        let chunk = |row: &[W], c: usize| -> [W; CHUNK] {
            row[c * CHUNK..][..CHUNK]
                .try_into()
                .expect("a chunk of weights")
        };
        for (c, (b, dst)) in bias
            .chunks_exact(CHUNK)
            .zip(out.chunks_mut(CHUNK))
            .enumerate()
        {
            // Two sums over alternate inputs: each register's chain of fused multiply-adds then
            // waits on itself every other input, so the adds overlap (one sum was bound by the
            // add latency, 4 cycles per input).
            let mut even = [0f32; CHUNK];
            let mut odd = [0f32; CHUNK];
            let mut rows = x.iter().zip(weights.chunks_exact(np));
            while let (Some((&v0, r0)), Some((&v1, r1))) = (rows.next(), rows.next()) {
                let (w0, w1) = (chunk(r0, c), chunk(r1, c));
                for j in 0..CHUNK {
                    even[j] = v0.mul_add(w0[j].value(), even[j]);
                    odd[j] = v1.mul_add(w1[j].value(), odd[j]);
                }
            }
            if x.len() % 2 == 1 {
                let (v, w) = (x[x.len() - 1], chunk(&weights[(x.len() - 1) * np..], c));
                for j in 0..CHUNK {
                    even[j] = v.mul_add(w[j].value(), even[j]);
                }
            }
            let s = scale.map(|s| &s[c * CHUNK..][..CHUNK]);
            for (j, d) in dst.iter_mut().enumerate() {
                let sum = even[j] + odd[j];
                let a = s.map_or(sum, |s| sum * s[j]) + b[j];
                *d = if relu { a.max(0.0) } else { a };
            }
        }
    }
}
