//! The native x86-64 forms of the networks' 3×3 layers, which [`crate::nn::conv`] plans and
//! chooses between (its notes say which CPU runs which): f32 on 256-bit registers (AVX2 + FMA) and
//! on 512-bit ones (AVX-512F), bf16 pairs summed in f32 (`vdpbf16ps`, AVX-512 BF16) and int8 quads
//! summed in i32 (`vpdpbusd`, AVX-512 VNNI). None runs on a phone: aarch64 and x86-64's portable
//! path run the 128-bit form of this folder's `mod.rs`. `crate::nn::conv`'s tests hold every form
//! to the layer's definition and to each other.

use crate::nn::conv::{
    BLOCK, Conv3x3, Layout, POSITIONS, POSITIONS_512, Pairs, Quads, VNNI_LEVELS, bf16_bits,
    nonnegative_max_portable,
};

/// Runs the kernel `$block.$method::<P, S>` (`Block::run`, `Block::run_bf16` or
/// `Block::run_vnni`) over a layer's output positions: groups of [`POSITIONS`] (or of the
/// count given), then the remainder. For the `unsafe` kernels of
/// [`Block`]: the caller has their CPU features and the layer's offsets.
macro_rules! each_group {
    ($block:ident . $method:ident, $layer:expr, $out:expr) => {
        each_group!($block.$method, $layer, $out, POSITIONS)
    };
    // Groups of `$positions` (at most six) positions.
    ($block:ident . $method:ident, $layer:expr, $out:expr, $positions:expr) => {{
        let n = $layer.at_in.len();
        let mut p = 0;
        #[allow(unsafe_code)]
        // SAFETY: the caller's features; offsets from the layer, as `Block` needs.
        unsafe {
            while p + $positions <= n {
                group!($block.$method, $layer, p, $out, $positions);
                p += $positions;
            }
            match n - p {
                0 => {}
                1 => group!($block.$method, $layer, p, $out, 1),
                2 => group!($block.$method, $layer, p, $out, 2),
                3 => group!($block.$method, $layer, p, $out, 3),
                4 => group!($block.$method, $layer, p, $out, 4),
                _ => group!($block.$method, $layer, p, $out, 5),
            }
        }
    }};
}

/// The kernel on the `$n` positions from `$p`: as one run along a row where they lie in one (their
/// windows then `stride` apart, so one address serves all their loads — the general form keeps
/// `$n` offsets in registers and spills), else each at its own offset. Inside [`each_group`]'s
/// `unsafe` block.
macro_rules! group {
    ($block:ident . $method:ident, $layer:expr, $p:expr, $out:expr, $n:expr) => {{
        let (ai, ao) = (&$layer.at_in[$p..$p + $n], &$layer.at_out[$p..$p + $n]);
        let step = $layer.step();
        let in_row = ai[$n - 1] - ai[0] == step * ($n - 1);
        // The steps of planes (the stride) and of interleaved inputs (the stride times the
        // channels of 16, 32, 48 or 64, the widths of the shipped networks) as constants.
        match (in_row, step) {
            (true, 1) => $block.$method::<{ $n }, 1>(ai, ao, $out),
            (true, 2) => $block.$method::<{ $n }, 2>(ai, ao, $out),
            (true, 16) => $block.$method::<{ $n }, 16>(ai, ao, $out),
            (true, 32) => $block.$method::<{ $n }, 32>(ai, ao, $out),
            (true, 48) => $block.$method::<{ $n }, 48>(ai, ao, $out),
            (true, 64) => $block.$method::<{ $n }, 64>(ai, ao, $out),
            (true, 96) => $block.$method::<{ $n }, 96>(ai, ao, $out),
            (true, 128) => $block.$method::<{ $n }, 128>(ai, ao, $out),
            _ => $block.$method::<{ $n }, 0>(ai, ao, $out),
        }
    }};
    ($block:ident . $method:ident, $layer:expr, $p:expr, $out:expr, $n:expr, $nb:literal) => {{
        let (ai, ao) = (&$layer.at_in[$p..$p + $n], &$layer.at_out[$p..$p + $n]);
        let in_row = ai[$n - 1] - ai[0] == $layer.stride * ($n - 1);
        match (in_row, $layer.stride) {
            (true, 1) => $block.$method::<$nb, { $n }, 1>(ai, ao, $out),
            (true, 2) => $block.$method::<$nb, { $n }, 2>(ai, ao, $out),
            _ => $block.$method::<$nb, { $n }, 0>(ai, ao, $out),
        }
    }};
}

/// [`each_group`] for the AVX-512 kernel [`Block::run_wide`] over `$nb` blocks: groups of
/// [`POSITIONS_512`], then the remainder.
macro_rules! each_group_wide {
    ($wide:ident . $method:ident, $nb:literal, $layer:expr, $out:expr) => {{
        let n = $layer.at_in.len();
        let mut p = 0;
        #[allow(unsafe_code)]
        // SAFETY: the caller's features; offsets from the layer, as `Block::run_wide` needs.
        unsafe {
            while p + POSITIONS_512 <= n {
                group!($wide.$method, $layer, p, $out, POSITIONS_512, $nb);
                p += POSITIONS_512;
            }
            match n - p {
                0 => {}
                1 => group!($wide.$method, $layer, p, $out, 1, $nb),
                2 => group!($wide.$method, $layer, p, $out, 2, $nb),
                3 => group!($wide.$method, $layer, p, $out, 3, $nb),
                4 => group!($wide.$method, $layer, p, $out, 4, $nb),
                5 => group!($wide.$method, $layer, p, $out, 5, $nb),
                6 => group!($wide.$method, $layer, p, $out, 6, $nb),
                _ => group!($wide.$method, $layer, p, $out, 7, $nb),
            }
        }
    }};
}

impl Conv3x3 {
    /// The run in int8 products, where the layer has them ([`Quads`]) and its input fits u8;
    /// false (nothing written) otherwise. `input_peak`: as [`Conv3x3::run_with`].
    pub(crate) fn run_int8_native(
        &mut self,
        input: &[f32],
        input_peak: Option<f32>,
        out: &mut [f32],
    ) -> bool {
        if let Some(mut quads) = self.quads.take() {
            let input_peak = input_peak.filter(|_| self.input_layout == Layout::Interleaved);
            #[allow(unsafe_code)]
            // SAFETY: `quads` exists only where the CPU has AVX-512F, BW and VNNI, AVX2 and FMA
            // (`Products::Vnni`); the lengths were checked above.
            let done = unsafe { self.quantize(&mut quads, input, input_peak) };
            if done {
                // SAFETY: as above; `quads.input` now holds this run's input.
                #[allow(unsafe_code)]
                let peak = unsafe { self.run_vnni(&quads, out) };
                self.peak = peak;
            }
            self.quads = Some(quads);
            if done {
                return true;
            }
        }
        false
    }

    /// The run in f32 or bf16 products on an input in the layout the layer's taps address; false
    /// (nothing written) where the CPU lacks AVX2 and FMA.
    pub(crate) fn run_float_native(&mut self, input: &[f32], out: &mut [f32]) -> bool {
        if let Some(mut pairs) = self.pairs.take() {
            // SAFETY: `pairs` exists only where the CPU has AVX2, FMA and AVX-512 BF16 + VL
            // (`Products::Bf16`); the lengths were checked above.
            #[allow(unsafe_code)]
            let peak = unsafe { self.run_bf16(&mut pairs, input, out) };
            self.peak = peak;
            self.pairs = Some(pairs);
            return true;
        }
        if self.wide {
            #[allow(unsafe_code)]
            // SAFETY: `wide` is set only where the CPU has AVX-512F, AVX2 and FMA
            // (`Products::supported`); the lengths were checked above.
            unsafe {
                self.run_avx512(input, out)
            };
            return true;
        }
        if crate::kernels::cpu::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA; the lengths were checked above.
            #[allow(unsafe_code)]
            let peak = unsafe { self.run_avx2(input, out) };
            self.peak = peak;
            return true;
        }
        false
    }

    /// # Safety
    /// The CPU has AVX2 and FMA; `input` and `out` have the layer's lengths.
    #[target_feature(enable = "avx2,fma")]
    #[allow(unsafe_code)]
    unsafe fn run_avx2(&self, input: &[f32], out: &mut [f32]) -> Option<f32> {
        self.for_each_block(
            input,
            &self.packed,
            &self.taps,
            &[],
            out,
            |_| 1,
            |block, _, out| {
                each_group!(block.run, self, out);
            },
        )
    }

    /// # Safety
    /// The CPU has AVX-512F, AVX2 and FMA; `input` and `out` have the layer's lengths.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[allow(unsafe_code)]
    unsafe fn run_avx512(&mut self, input: &[f32], out: &mut [f32]) {
        self.peak = self.for_each_block(
            input,
            &self.packed,
            &self.taps,
            &[],
            out,
            |rest| rest.min(2),
            |block, n, out| {
                if n == 2 {
                    each_group_wide!(block.run_wide, 2, self, out);
                } else {
                    each_group_wide!(block.run_wide, 1, self, out);
                }
            },
        );
    }

    /// Calls `each` with every group of consecutive blocks of [`BLOCK`] output channels of every
    /// batch slot — `group(rest)` blocks at a time, `rest` the blocks left (1 for the 256-bit
    /// kernels, up to 2 for the 512-bit one) — with their count and their part of `out`
    /// (`input` holding the batch slots' values one slot after the other, `packed` the weights
    /// per block as the kernel reads them, `scale` empty or a factor per output channel). Where
    /// the output is interleaved, returns the largest value stored ([`Block::peak`]).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn for_each_block<T>(
        &self,
        input: &[T],
        packed: &[T],
        taps: &[usize],
        scale: &[f32],
        out: &mut [f32],
        group: impl Fn(usize) -> usize,
        mut each: impl FnMut(&Block<'_, T>, usize, &mut [f32]),
    ) -> Option<f32> {
        let (k, blocks) = (taps.len(), self.cout.div_ceil(BLOCK));
        let per_slot = input.len() / self.batch.max(1);
        let (width, out_slot, block_step) = self.output_steps();
        let mut peak = 0u32;
        for b in 0..self.batch {
            let input = &input[b * per_slot..][..per_slot];
            let out = &mut out[b * out_slot..][..out_slot];
            let mut blk = 0;
            while blk < blocks {
                let n = group(blocks - blk);
                let block = Block {
                    input,
                    weights: &packed[blk * k * BLOCK..][..n * k * BLOCK],
                    bias: &self.bias[blk * BLOCK..][..n * BLOCK],
                    scale: if scale.is_empty() {
                        &[]
                    } else {
                        &scale[blk * BLOCK..][..n * BLOCK]
                    },
                    taps,
                    channels: (n * BLOCK).min(self.cout - blk * BLOCK),
                    plane: self.out_plane,
                    width,
                    peak: std::cell::Cell::new([0; BLOCK]),
                };
                each(&block, n, &mut out[blk * block_step..]);
                peak = block.peak.get().into_iter().fold(peak, u32::max);
                blk += n;
            }
        }
        // The stored values are ≥ +0 (the ReLU's maximum with +0 turns NaN into +0 too), so the
        // largest bits as unsigned integers are the largest value's.
        (self.output_layout == Layout::Interleaved).then(|| f32::from_bits(peak))
    }

    /// The int8 kernel on the input [`Self::quantize`] left in `quads`; returns the largest value
    /// stored where the output is interleaved.
    ///
    /// # Safety
    /// The CPU has AVX-512F, BW and VNNI, AVX2 and FMA; `out` has the layer's length and `quads`
    /// is the layer's.
    #[target_feature(enable = "avx512f,avx512bw,avx512vnni,avx2,fma")]
    #[allow(unsafe_code)]
    unsafe fn run_vnni(&self, quads: &Quads, out: &mut [f32]) -> Option<f32> {
        self.for_each_block(
            &quads.input,
            &quads.packed,
            &quads.taps,
            &quads.step,
            out,
            |rest| rest.min(2),
            |block, n, out| {
                if n == 2 {
                    each_group_wide!(block.run_vnni, 2, self, out);
                } else {
                    each_group_wide!(block.run_vnni, 1, self, out);
                }
            },
        )
    }

    /// Quantises `input` into `quads.input` (`u8 = round(v · 255 / max)`) and sets `quads.step`; false (nothing written) where the input holds a
    /// negative or non-finite value, which u8 cannot carry. `input_peak`: as [`Self::run_with`].
    ///
    /// # Safety
    /// The CPU has AVX-512F and BW, AVX2 and FMA; `input` has the layer's length and `quads` is
    /// the layer's.
    #[target_feature(enable = "avx512f,avx512bw,avx2,fma")]
    #[allow(unsafe_code)]
    unsafe fn quantize(&self, quads: &mut Quads, input: &[f32], input_peak: Option<f32>) -> bool {
        let max = match input_peak {
            Some(peak) => peak.is_finite().then_some(peak),
            None => nonnegative_max(input),
        };
        let Some(max) = max else {
            return false;
        };
        let levels = VNNI_LEVELS as f32;
        // One step of the u8 scale is max / levels (no step for an all-zero input).
        let per_step = if max > 0.0 { levels / max } else { 0.0 };
        for (d, &s) in quads.step.iter_mut().zip(&quads.scale) {
            *d = s * (max / levels);
        }
        let cq = self.cin.div_ceil(4);
        let slots = quads.input.chunks_exact_mut(cq * self.in_plane);
        match self.input_layout {
            Layout::Interleaved => {
                let width = Self::interleaved_width(self.cin);
                for (values, words) in input.chunks_exact(width * self.in_plane).zip(slots) {
                    quantize_interleaved(values, width, cq, per_step, words);
                }
            }
            Layout::Planar => {
                for (planes, words) in input.chunks_exact(self.cin * self.in_plane).zip(slots) {
                    for (four, dst) in words.chunks_exact_mut(self.in_plane).enumerate() {
                        let plane = |k: usize| {
                            let c = 4 * four + k;
                            (c < self.cin).then(|| &planes[c * self.in_plane..][..self.in_plane])
                        };
                        let planes = [plane(0), plane(1), plane(2), plane(3)];
                        quantize_four(planes, per_step, dst);
                    }
                }
            }
        }
        true
    }

    /// # Safety
    /// The CPU has AVX2, FMA, AVX-512 BF16 and VL; `input` and `out` have the layer's lengths
    /// and `pairs` is the layer's.
    #[target_feature(enable = "avx2,fma,avx512f,avx512vl,avx512bf16")]
    #[allow(unsafe_code)]
    unsafe fn run_bf16(&self, pairs: &mut Pairs, input: &[f32], out: &mut [f32]) -> Option<f32> {
        let cp = self.cin.div_ceil(2);
        for b in 0..self.batch {
            let planes = &input[b * self.cin * self.in_plane..][..self.cin * self.in_plane];
            let paired = &mut pairs.input[b * cp * self.in_plane..][..cp * self.in_plane];
            for (pair, dst) in paired.chunks_exact_mut(self.in_plane).enumerate() {
                let even = &planes[2 * pair * self.in_plane..][..self.in_plane];
                let odd = (2 * pair + 1 < self.cin)
                    .then(|| &planes[(2 * pair + 1) * self.in_plane..][..self.in_plane]);
                pair_bf16(even, odd, dst);
            }
        }
        self.for_each_block(
            &pairs.input,
            &pairs.packed,
            &pairs.taps,
            &[],
            out,
            |_| 1,
            |block, _, out| {
                each_group!(block.run_bf16, self, out);
            },
        )
    }
}

/// Rounds two planes to bf16 (to nearest, ties to even, as [`bf16_bits`]) and pairs them:
/// `dst[i]` = `even[i]` in the low half, `odd[i]` (0 without `odd`) in the high half. Integer
/// arithmetic on the bits: eight words in a handful of AVX2 operations.
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
pub(crate) fn pair_bf16(even: &[f32], odd: Option<&[f32]>, dst: &mut [u32]) {
    use std::arch::x86_64::*;
    let n = dst.len();
    assert!(even.len() >= n && odd.is_none_or(|o| o.len() >= n));
    let (bias, one, high) = (
        _mm256_set1_epi32(0x7fff),
        _mm256_set1_epi32(1),
        _mm256_set1_epi32(0xffff_0000_u32 as i32),
    );
    // bits + 0x7fff + (bit 16), whose upper half is the rounded bf16.
    let round = |v: __m256i| {
        _mm256_add_epi32(
            _mm256_add_epi32(v, bias),
            _mm256_and_si256(_mm256_srli_epi32::<16>(v), one),
        )
    };
    let mut i = 0;
    while i + 8 <= n {
        // SAFETY: `i + 8 <= n` and both planes hold at least `n` values (asserted above).
        unsafe {
            let e = round(_mm256_loadu_si256(even.as_ptr().add(i).cast()));
            let mut w = _mm256_srli_epi32::<16>(e);
            if let Some(o) = odd {
                let o = round(_mm256_loadu_si256(o.as_ptr().add(i).cast()));
                w = _mm256_or_si256(w, _mm256_and_si256(o, high));
            }
            _mm256_storeu_si256(dst.as_mut_ptr().add(i).cast(), w);
        }
        i += 8;
    }
    for j in i..n {
        dst[j] = bf16_bits(even[j]) | odd.map_or(0, |o| bf16_bits(o[j]) << 16);
    }
}

/// The largest value of `v`, or `None` where a value is negative or not finite (0 for an empty
/// `v`; −0 counts as 0).
///
/// Why through the bits: for finite values ≥ +0 the order of their bits as unsigned integers is
/// their order, and every negative, infinite or NaN value has larger bits than any of them, so one
/// unsigned maximum over four independent registers answers both questions (a float maximum and
/// minimum waited on their own latency every sixteen values).
#[target_feature(enable = "avx512f")]
#[allow(unsafe_code)]
pub(crate) fn nonnegative_max(v: &[f32]) -> Option<f32> {
    use std::arch::x86_64::*;
    const INF_BITS: u32 = 0x7f80_0000;
    let mut acc = [_mm512_setzero_si512(); 4];
    let blocks = v.chunks_exact(64);
    let rest = blocks.remainder();
    for b in blocks {
        for (k, a) in acc.iter_mut().enumerate() {
            // SAFETY: the block holds 64 values.
            let x = unsafe { _mm512_loadu_si512(b.as_ptr().add(16 * k).cast()) };
            *a = _mm512_max_epu32(*a, x);
        }
    }
    for (k, c) in rest.chunks(16).enumerate() {
        let mask = (1u32 << c.len()).wrapping_sub(1) as u16;
        // SAFETY: the mask reads the chunk's values only.
        let x = unsafe { _mm512_maskz_loadu_epi32(mask, c.as_ptr().cast()) };
        acc[k] = _mm512_max_epu32(acc[k], x);
    }
    let m = _mm512_max_epu32(
        _mm512_max_epu32(acc[0], acc[1]),
        _mm512_max_epu32(acc[2], acc[3]),
    );
    let bits = _mm512_reduce_max_epu32(m);
    if bits < INF_BITS {
        return Some(f32::from_bits(bits));
    }
    // A negative, infinite or NaN value, or a −0 (whose sign bit makes its bits large).
    nonnegative_max_portable(v)
}

/// Quantises four planes to u8 (`round(v · per_step)`, ties to even, at most 255) into one word
/// per position, byte `k` from plane `k` (0 where it is `None`).
#[target_feature(enable = "avx512f,avx512bw")]
#[allow(unsafe_code)]
fn quantize_four(planes: [Option<&[f32]>; 4], per_step: f32, dst: &mut [u32]) {
    use std::arch::x86_64::*;
    let n = dst.len();
    assert!(planes.iter().flatten().all(|p| p.len() >= n));
    let f = _mm512_set1_ps(per_step);
    // A plane's u8 values at `i..` (the lanes of `mask`), as i32 lanes; 0 without the plane.
    let level = |p: Option<&[f32]>, i: usize, mask: u16| match p {
        // SAFETY: the mask's lanes are positions below `n`, inside the plane (asserted above).
        Some(p) => u8_steps(unsafe { _mm512_maskz_loadu_ps(mask, p.as_ptr().add(i)) }, f),
        None => _mm512_setzero_si512(),
    };
    let [p0, p1, p2, p3] = planes;
    let mut i = 0;
    while i < n {
        let mask = (1u32 << (n - i).min(16)).wrapping_sub(1) as u16;
        let word = _mm512_or_si512(
            _mm512_or_si512(
                level(p0, i, mask),
                _mm512_slli_epi32::<8>(level(p1, i, mask)),
            ),
            _mm512_or_si512(
                _mm512_slli_epi32::<16>(level(p2, i, mask)),
                _mm512_slli_epi32::<24>(level(p3, i, mask)),
            ),
        );
        // SAFETY: the mask's lanes are positions below `n`, inside `dst`.
        unsafe { _mm512_mask_storeu_epi32(dst.as_mut_ptr().add(i).cast(), mask, word) };
        i += 16;
    }
}

/// The u8 steps of the int8 form's input: `round(v · per_step)` (ties to even), at most 255, as
/// i32 lanes. Both quantisations take it, so both layouts give the same words.
#[target_feature(enable = "avx512f")]
#[inline]
fn u8_steps(
    v: std::arch::x86_64::__m512,
    per_step: std::arch::x86_64::__m512,
) -> std::arch::x86_64::__m512i {
    use std::arch::x86_64::*;
    _mm512_min_epi32(
        _mm512_cvtps_epi32(_mm512_mul_ps(v, per_step)),
        _mm512_set1_epi32(255),
    )
}

/// [`quantize_four`] from an interleaved input: `values` holds `positions × width` values
/// (channels past the layer's zero), `dst` the `fours` planes of `positions` words. Sixteen
/// positions at a time: each position's sixteen channels of a block rounded to bytes as
/// `quantize_four` rounds them (four words, one per four of channels), then the words of sixteen
/// positions regrouped by four in registers, so each plane takes one store.
#[target_feature(enable = "avx512f,avx512bw")]
#[allow(unsafe_code)]
fn quantize_interleaved(
    values: &[f32],
    width: usize,
    fours: usize,
    per_step: f32,
    dst: &mut [u32],
) {
    use std::arch::x86_64::*;
    let n = values.len() / width.max(1);
    assert!(
        width.is_multiple_of(BLOCK)
            && values.len() == n * width
            && 4 * fours <= width
            && dst.len() == fours * n,
        "quantize_interleaved: lengths"
    );
    let f = _mm512_set1_ps(per_step);
    // Lanes 0–7: word k0 of the eight positions of two registers of four positions × four words;
    // lanes 8–15: word k1 of the same positions.
    let pick = |k0: i32, k1: i32| {
        _mm512_setr_epi32(
            k0,
            4 + k0,
            8 + k0,
            12 + k0,
            16 + k0,
            20 + k0,
            24 + k0,
            28 + k0,
            k1,
            4 + k1,
            8 + k1,
            12 + k1,
            16 + k1,
            20 + k1,
            24 + k1,
            28 + k1,
        )
    };
    let (words01, words23) = (pick(0, 1), pick(2, 3));
    for j in 0..fours.div_ceil(4) {
        let planes = (fours - 4 * j).min(4);
        let mut p0 = 0;
        while p0 < n {
            let m = (n - p0).min(16);
            // Position p0 + p's channels 16j.. as bytes; zero past the positions.
            let bytes = |p: usize| {
                if p < m {
                    // SAFETY: position p0 + p < n, and its block j lies within its `width`
                    // values (`16·(j + 1) ≤ 4·fours rounded up ≤ width`).
                    let v = unsafe {
                        _mm512_loadu_ps(values.as_ptr().add((p0 + p) * width + j * BLOCK))
                    };
                    _mm512_cvtepi32_epi8(u8_steps(v, f))
                } else {
                    _mm_setzero_si128()
                }
            };
            // Four positions from p: position p + i in 128-bit lane i.
            let four = |p: usize| {
                let z = _mm512_castsi128_si512(bytes(p));
                let z = _mm512_inserti32x4::<1>(z, bytes(p + 1));
                let z = _mm512_inserti32x4::<2>(z, bytes(p + 2));
                _mm512_inserti32x4::<3>(z, bytes(p + 3))
            };
            let (z0, z1, z2, z3) = (four(0), four(4), four(8), four(12));
            let (a01, b01) = (
                _mm512_permutex2var_epi32(z0, words01, z1),
                _mm512_permutex2var_epi32(z2, words01, z3),
            );
            let (a23, b23) = (
                _mm512_permutex2var_epi32(z0, words23, z1),
                _mm512_permutex2var_epi32(z2, words23, z3),
            );
            // Word k of positions 0–7 (from a) then 8–15 (from b).
            let word = [
                _mm512_shuffle_i64x2::<0b01_00_01_00>(a01, b01),
                _mm512_shuffle_i64x2::<0b11_10_11_10>(a01, b01),
                _mm512_shuffle_i64x2::<0b01_00_01_00>(a23, b23),
                _mm512_shuffle_i64x2::<0b11_10_11_10>(a23, b23),
            ];
            let mask = ((1u32 << m) - 1) as u16;
            for (k, w) in word.iter().enumerate().take(planes) {
                // SAFETY: plane 4j + k < fours, and the mask's lanes are positions below n.
                unsafe {
                    _mm512_mask_storeu_epi32(
                        dst.as_mut_ptr().add((4 * j + k) * n + p0).cast(),
                        mask,
                        *w,
                    )
                };
            }
            p0 += 16;
        }
    }
}

/// One block of output channels of one batch slot. `T`: f32 values, or bf16 pairs as words
/// ([`Pairs`]).
struct Block<'a, T> {
    input: &'a [T],
    /// `taps.len() × BLOCK` weights per block: one block, or `NB` for [`Block::run_wide`].
    weights: &'a [T],
    bias: &'a [f32],
    /// Per channel the factor from the int8 kernel's i32 sums to values ([`Quads::step`]);
    /// empty for the other kernels.
    scale: &'a [f32],
    taps: &'a [usize],
    /// Channels of the block that exist (the rest of the lanes are not stored in planes).
    channels: usize,
    plane: usize,
    /// Channels per position of an interleaved output ([`Layout::Interleaved`]); 0 for planes.
    width: usize,
    /// Per lane the largest bits stored interleaved so far: the next layer's quantisation scale
    /// without a separate `nonnegative_max` pass over its input.
    peak: std::cell::Cell<[u32; BLOCK]>,
}

impl<T> Block<'_, T> {
    /// The window offsets of `P` positions (`at_in[..P]`, or with `S` > 0 `at_in[0] + S·j`) and
    /// their accumulators, started at the bias.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    #[allow(clippy::type_complexity)]
    fn start<const P: usize, const S: usize>(
        &self,
        at_in: &[usize],
    ) -> ([usize; P], [[std::arch::x86_64::__m256; 2]; P]) {
        use std::arch::x86_64::*;
        let at = std::array::from_fn(|j| if S == 0 { at_in[j] } else { at_in[0] + S * j });
        let bias: &[f32; BLOCK] = self.bias[..BLOCK].try_into().expect("a block of biases");
        #[allow(unsafe_code)]
        // SAFETY: `bias` holds BLOCK values.
        let (b0, b1) = unsafe {
            (
                _mm256_loadu_ps(bias.as_ptr()),
                _mm256_loadu_ps(bias.as_ptr().add(8)),
            )
        };
        (at, [[b0, b1]; P])
    }

    /// The accumulators of `P` positions, with the ReLU, into their offsets `at_out` of the
    /// block's channel planes in `out`, or where the output is interleaved, as each position's
    /// sixteen channels at `at_out[q]·width` (two stores; lanes past `cout` hold zeros, from zero
    /// weights and bias), keeping [`Block::peak`].
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    #[allow(unsafe_code)]
    fn store<const P: usize>(
        &self,
        acc: &[[std::arch::x86_64::__m256; 2]; P],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        use std::arch::x86_64::*;
        let zero = _mm256_setzero_ps();
        if self.width > 0 {
            let at_out = &at_out[..P];
            let last = at_out.iter().max().copied().unwrap_or(0);
            assert!(
                out.len() >= last * self.width + BLOCK,
                "store outside the output"
            );
            let lanes = self.peak.as_ptr().cast::<__m256i>();
            // SAFETY: the cell holds BLOCK words, and nothing else refers to them during the
            // call.
            let mut peak = unsafe { [_mm256_loadu_si256(lanes), _mm256_loadu_si256(lanes.add(1))] };
            for (a, &o) in acc.iter().zip(at_out) {
                for (h, (&v, peak)) in a.iter().zip(&mut peak).enumerate() {
                    let v = _mm256_max_ps(v, zero);
                    *peak = _mm256_max_epu32(*peak, _mm256_castps_si256(v));
                    // SAFETY: `o·width + 16 ≤ last·width + 16 ≤ out.len()` (asserted).
                    unsafe { _mm256_storeu_ps(out.as_mut_ptr().add(o * self.width + 8 * h), v) };
                }
            }
            // SAFETY: as the load above.
            unsafe {
                _mm256_storeu_si256(lanes, peak[0]);
                _mm256_storeu_si256(lanes.add(1), peak[1]);
            }
            return;
        }
        let mut lanes = [0f32; BLOCK];
        for (acc, &o) in acc.iter().zip(at_out) {
            // SAFETY: `lanes` holds BLOCK values.
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_ps(lanes.as_mut_ptr(), _mm256_max_ps(acc[0], zero));
                _mm256_storeu_ps(lanes.as_mut_ptr().add(8), _mm256_max_ps(acc[1], zero));
            }
            for (c, &v) in lanes[..self.channels].iter().enumerate() {
                out[c * self.plane + o] = v;
            }
        }
    }
}

impl Block<'_, u32> {
    /// [`Block::run`] on bf16 pairs: per pair tap one broadcast word, two `vdpbf16ps`.
    ///
    /// # Safety
    /// AVX2, FMA, AVX-512 BF16 + VL; every `at_in[j] + taps[t]` lies inside `input` and
    /// `weights` holds `taps.len() × BLOCK` words.
    #[target_feature(enable = "avx2,fma,avx512f,avx512vl,avx512bf16")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn run_bf16<const P: usize, const S: usize>(
        &self,
        at_in: &[usize],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        use std::arch::x86_64::*;
        let (at, mut acc) = self.start::<P, S>(at_in);
        let (x, w) = (self.input.as_ptr(), self.weights.as_ptr());
        debug_assert!(self.weights.len() >= self.taps.len() * BLOCK);
        for (t, &tap) in self.taps.iter().enumerate() {
            // SAFETY: the caller's contract: tap offsets and weights within their buffers; the
            // words are bf16 pairs, so reading them as `__m256bh` is what they hold.
            unsafe {
                let w0: __m256bh = std::mem::transmute(_mm256_loadu_si256(w.add(t * BLOCK).cast()));
                let w1: __m256bh =
                    std::mem::transmute(_mm256_loadu_si256(w.add(t * BLOCK + 8).cast()));
                for (acc, &at) in acc.iter_mut().zip(&at) {
                    debug_assert!(at + tap < self.input.len());
                    let v: __m256bh =
                        std::mem::transmute(_mm256_set1_epi32(*x.add(at + tap) as i32));
                    acc[0] = _mm256_dpbf16_ps(acc[0], w0, v);
                    acc[1] = _mm256_dpbf16_ps(acc[1], w1, v);
                }
            }
        }
        self.store(&acc, at_out, out);
    }
}

impl Block<'_, f32> {
    /// `P` output positions: window offsets `at_in[..P]` (with `S` > 0, `at_in[0] + S·j`),
    /// output offsets `at_out[..P]` (within a plane of `out`, whose plane `c` is the block's
    /// channel `c`).
    ///
    /// # Safety
    /// AVX2 + FMA; every `at_in[j] + taps[t]` lies inside `input` (the layer's construction) and
    /// `weights` holds `taps.len() × BLOCK` values.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn run<const P: usize, const S: usize>(
        &self,
        at_in: &[usize],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        use std::arch::x86_64::*;
        let (at, mut acc) = self.start::<P, S>(at_in);
        let (x, w) = (self.input.as_ptr(), self.weights.as_ptr());
        debug_assert!(self.weights.len() >= self.taps.len() * BLOCK);
        for (t, &tap) in self.taps.iter().enumerate() {
            // SAFETY: the caller's contract: tap offsets and weights within their buffers.
            unsafe {
                let w0 = _mm256_loadu_ps(w.add(t * BLOCK));
                let w1 = _mm256_loadu_ps(w.add(t * BLOCK + 8));
                for (acc, &at) in acc.iter_mut().zip(&at) {
                    debug_assert!(at + tap < self.input.len());
                    let v = _mm256_broadcast_ss(&*x.add(at + tap));
                    acc[0] = _mm256_fmadd_ps(w0, v, acc[0]);
                    acc[1] = _mm256_fmadd_ps(w1, v, acc[1]);
                }
            }
        }
        self.store(&acc, at_out, out);
    }
}

impl Block<'_, f32> {
    /// [`Block::run`] on 512-bit registers over `NB` consecutive blocks (`weights` and `bias`
    /// holding all of theirs, `channels` counting them): `P` output positions, window offsets
    /// `at_in[..P]` (with `S` > 0, `at_in[0] + S·j`), output offsets `at_out[..P]` within a plane
    /// of `out`, whose plane `c` is channel `c` of the first block.
    ///
    /// # Safety
    /// AVX-512F + AVX2 + FMA; every `at_in[j] + taps[t]` lies inside `input` (the layer's
    /// construction), `weights` holds `NB × taps.len() × BLOCK` values and `bias` `NB × BLOCK`.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn run_wide<const NB: usize, const P: usize, const S: usize>(
        &self,
        at_in: &[usize],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        use std::arch::x86_64::*;
        let at: [usize; P] =
            std::array::from_fn(|j| if S == 0 { at_in[j] } else { at_in[0] + S * j });
        let k = self.taps.len();
        debug_assert!(self.weights.len() >= NB * k * BLOCK && self.bias.len() >= NB * BLOCK);
        let (x, w) = (self.input.as_ptr(), self.weights.as_ptr());
        let mut acc = [[_mm512_setzero_ps(); NB]; P];
        for j in 0..NB {
            // SAFETY: `bias` holds NB × BLOCK values.
            let b = unsafe { _mm512_loadu_ps(self.bias.as_ptr().add(j * BLOCK)) };
            for a in acc.iter_mut() {
                a[j] = b;
            }
        }
        for (t, &tap) in self.taps.iter().enumerate() {
            let mut wt = [_mm512_setzero_ps(); NB];
            for (j, wt) in wt.iter_mut().enumerate() {
                // SAFETY: block j's weights for tap t lie within `weights` (the contract).
                *wt = unsafe { _mm512_loadu_ps(w.add((j * k + t) * BLOCK)) };
            }
            for (acc, &at) in acc.iter_mut().zip(&at) {
                debug_assert!(at + tap < self.input.len());
                // SAFETY: the tap lies inside `input` (the contract).
                let v = unsafe { _mm512_set1_ps(*x.add(at + tap)) };
                for (a, &wt) in acc.iter_mut().zip(&wt) {
                    *a = _mm512_fmadd_ps(wt, v, *a);
                }
            }
        }
        self.store_512(&acc, at_out, out);
    }
}

impl Block<'_, u32> {
    /// [`Block::run_wide`] on int8 quads ([`Quads`]): per quad tap `NB` weight loads, and per
    /// position one broadcast word feeding `NB` `vpdpbusd`; the i32 sums times the channel's
    /// [`Block::scale`] plus the bias are the outputs.
    ///
    /// # Safety
    /// AVX-512F, BW and VNNI, AVX2 + FMA; every `at_in[j] + taps[t]` lies inside `input`,
    /// `weights` holds `NB × taps.len() × BLOCK` words and `bias` and `scale` `NB × BLOCK`
    /// values.
    #[target_feature(enable = "avx512f,avx512bw,avx512vnni,avx2,fma")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn run_vnni<const NB: usize, const P: usize, const S: usize>(
        &self,
        at_in: &[usize],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        use std::arch::x86_64::*;
        let at: [usize; P] =
            std::array::from_fn(|j| if S == 0 { at_in[j] } else { at_in[0] + S * j });
        let k = self.taps.len();
        assert!(self.scale.len() >= NB * BLOCK && self.bias.len() >= NB * BLOCK);
        debug_assert!(self.weights.len() >= NB * k * BLOCK);
        let (x, w) = (self.input.as_ptr(), self.weights.as_ptr());
        let mut acc = [[_mm512_setzero_si512(); NB]; P];
        for (t, &tap) in self.taps.iter().enumerate() {
            let mut wt = [_mm512_setzero_si512(); NB];
            for (j, wt) in wt.iter_mut().enumerate() {
                // SAFETY: block j's weights for tap t lie within `weights` (the contract).
                *wt = unsafe { _mm512_loadu_si512(w.add((j * k + t) * BLOCK).cast()) };
            }
            for (acc, &at) in acc.iter_mut().zip(&at) {
                debug_assert!(at + tap < self.input.len());
                // SAFETY: the tap lies inside `input` (the contract).
                let v = unsafe { _mm512_set1_epi32(*x.add(at + tap) as i32) };
                for (a, &wt) in acc.iter_mut().zip(&wt) {
                    *a = _mm512_dpbusd_epi32(*a, v, wt);
                }
            }
        }
        let mut values = [[_mm512_setzero_ps(); NB]; P];
        for j in 0..NB {
            // SAFETY: `scale` and `bias` hold NB × BLOCK values (asserted above).
            let (m, b) = unsafe {
                (
                    _mm512_loadu_ps(self.scale.as_ptr().add(j * BLOCK)),
                    _mm512_loadu_ps(self.bias.as_ptr().add(j * BLOCK)),
                )
            };
            for (v, a) in values.iter_mut().zip(&acc) {
                v[j] = _mm512_fmadd_ps(_mm512_cvtepi32_ps(a[j]), m, b);
            }
        }
        self.store_512(&values, at_out, out);
    }
}

impl<T> Block<'_, T> {
    /// The accumulators of [`Block::run_wide`] into `out`, in the output's layout.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    fn store_512<const NB: usize, const P: usize>(
        &self,
        acc: &[[std::arch::x86_64::__m512; NB]; P],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        if self.width == 0 {
            self.store_wide(acc, at_out, out);
        } else {
            self.store_interleaved(acc, at_out, out);
        }
    }

    /// The accumulators of [`Block::run_wide`], with the ReLU, into an interleaved `out` (its
    /// first value this block's first channel at position 0): position `q`'s channels of block
    /// `j` as one store at `at_out[q]·width + 16·j`. Lanes past `cout` hold zeros (zero weights
    /// and bias), the channels the layout rounds up to.
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    #[allow(unsafe_code)]
    fn store_interleaved<const NB: usize, const P: usize>(
        &self,
        acc: &[[std::arch::x86_64::__m512; NB]; P],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        use std::arch::x86_64::*;
        let at_out = &at_out[..P];
        let blocks = self.channels.div_ceil(BLOCK);
        let last = at_out.iter().max().copied().unwrap_or(0);
        assert!(
            blocks <= NB && (blocks == 0 || out.len() >= last * self.width + blocks * BLOCK),
            "store outside the output"
        );
        let zero = _mm512_setzero_ps();
        // SAFETY: the cell holds BLOCK words, and nothing else refers to them during the call.
        let mut peak = unsafe { _mm512_loadu_si512(self.peak.as_ptr().cast()) };
        for (a, &o) in acc.iter().zip(at_out) {
            for (j, &v) in a.iter().enumerate().take(blocks) {
                let v = _mm512_max_ps(v, zero);
                peak = _mm512_max_epu32(peak, _mm512_castps_si512(v));
                // SAFETY: `o·width + 16·j + 16 ≤ last·width + blocks·16 ≤ out.len()` (asserted).
                unsafe { _mm512_storeu_ps(out.as_mut_ptr().add(o * self.width + j * BLOCK), v) };
            }
        }
        // SAFETY: as the load above.
        unsafe { _mm512_storeu_si512(self.peak.as_ptr().cast(), peak) };
    }

    /// The accumulators of [`Block::run_wide`], with the ReLU, into their offsets `at_out` of the
    /// block's channel planes in `out`: the positions × channels of each block transposed in
    /// registers, then per channel one masked store per run of positions that are consecutive in
    /// their output row (one run for a group along a row, two where it wraps to the next).
    ///
    /// Why: storing value by value (a store per channel and position, as the 256-bit kernels
    /// do) takes about a fifth of the 512-bit kernel's time in `perf` on an Intel Xeon with AVX-512).
    #[target_feature(enable = "avx512f,avx2,fma")]
    #[inline]
    #[allow(unsafe_code)]
    fn store_wide<const NB: usize, const P: usize>(
        &self,
        acc: &[[std::arch::x86_64::__m512; NB]; P],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        use std::arch::x86_64::*;
        const { assert!(P <= 8) };
        let at_out = &at_out[..P];
        let last = at_out.iter().max().map_or(0, |&o| o + 1);
        assert!(
            self.channels <= NB * BLOCK
                && (self.channels == 0 || out.len() >= (self.channels - 1) * self.plane + last)
                && at_out.windows(2).all(|w| w[0] < w[1]),
            "store outside the output"
        );
        // Runs of consecutive offsets: (first position, its offset, mask of the run's lanes).
        let mut runs = [(0usize, 0usize, 0u16); 8];
        let mut n_runs = 0;
        for (q, &o) in at_out.iter().enumerate() {
            if q == 0 || o != at_out[q - 1] + 1 {
                runs[n_runs] = (q, o, 0);
                n_runs += 1;
            }
            runs[n_runs - 1].2 |= 1 << q;
        }
        let runs = &runs[..n_runs];
        let zero = _mm512_setzero_ps();
        // Lanes 0–7 of `v` below are channel c's positions 0–7, lanes 8–15 channel c + 4's.
        let lo = _mm512_setr_epi32(0, 1, 2, 3, 16, 17, 18, 19, 4, 5, 6, 7, 20, 21, 22, 23);
        let hi = _mm512_setr_epi32(8, 9, 10, 11, 24, 25, 26, 27, 12, 13, 14, 15, 28, 29, 30, 31);
        // j picks block j out of every position's accumulators.
        #[allow(clippy::needless_range_loop)]
        for j in 0..NB {
            let p: [__m512; 8] = std::array::from_fn(|q| {
                if q < P {
                    _mm512_max_ps(acc[q][j], zero)
                } else {
                    zero
                }
            });
            let t: [__m512; 8] = std::array::from_fn(|q| {
                let (a, b) = (p[q & !1], p[q | 1]);
                if q % 2 == 0 {
                    _mm512_unpacklo_ps(a, b)
                } else {
                    _mm512_unpackhi_ps(a, b)
                }
            });
            // In 128-bit lane L, u[k] holds channel 4L + k at positions 0–3 and u[4 + k] the
            // same channel at positions 4–7.
            let u: [__m512; 8] = std::array::from_fn(|q| {
                let (h, k) = (q / 4, q % 4);
                let a = _mm512_castps_pd(t[4 * h + k / 2]);
                let b = _mm512_castps_pd(t[4 * h + 2 + k / 2]);
                _mm512_castpd_ps(if k % 2 == 0 {
                    _mm512_unpacklo_pd(a, b)
                } else {
                    _mm512_unpackhi_pd(a, b)
                })
            });
            for k in 0..4 {
                for (index, c0) in [(lo, k), (hi, 8 + k)] {
                    let v = _mm512_permutex2var_ps(u[k], index, u[4 + k]);
                    for (half, shift) in [(0, 0), (4, 8)] {
                        let c = j * BLOCK + c0 + half;
                        if c >= self.channels {
                            continue;
                        }
                        for &(q, o, mask) in runs {
                            // Lane shift + q holds position q: the store starts shift + q
                            // values before position q's offset, and writes only its run.
                            let at = (c * self.plane + o).wrapping_sub(shift + q);
                            // SAFETY: the stored lanes are the run's positions of channel c,
                            // inside `out` (asserted above); masked-off lanes are neither
                            // read nor written, and `wrapping_add` makes no in-bounds claim.
                            unsafe {
                                _mm512_mask_storeu_ps(
                                    out.as_mut_ptr().wrapping_add(at),
                                    mask << shift,
                                    v,
                                )
                            };
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg_attr(not(host_avx512), ignore = "this CPU runs no AVX-512 kernels")]
    fn the_avx512_input_check_takes_only_finite_nonnegative_inputs() {
        assert!(
            crate::kernels::cpu::has_avx512(crate::kernels::cpu::Avx512::F),
            "the AVX-512 kernels do not run here (no such CPU, or the portable path)"
        );
        #[allow(unsafe_code)]
        // SAFETY: the CPU has AVX-512F (asserted above).
        let max = |v: &[f32]| unsafe { nonnegative_max(v) };
        // Two whole blocks of 64 and a remainder of 22 (a whole 16 and 6).
        let mut v: Vec<f32> = (0..150).map(|i| (i * 37 % 150) as f32 * 0.5).collect();
        assert_eq!(max(&v), Some(74.5));
        assert_eq!(max(&v[..37]), v[..37].iter().copied().reduce(f32::max));
        assert_eq!(max(&[]), Some(0.0));
        // −0 counts as 0 (through the slower check).
        v[5] = -0.0;
        assert_eq!(max(&v), Some(74.5));
        for bad in [-0.5, f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            // In a block, in the whole remainder vector and in the partial one.
            for at in [3, 100, 130, 147] {
                let keep = v[at];
                v[at] = bad;
                assert_eq!(max(&v), None, "{bad} at {at}");
                v[at] = keep;
            }
        }
    }
}
