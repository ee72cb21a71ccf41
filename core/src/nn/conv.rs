//! 3×3 convolutions with zero padding 1, stride 1 or 2, a bias and a ReLU: the layers of the M3
//! trunks and the detector's first ones ([`crate::nn::stem`] finds them in the graphs), computed here
//! instead of by tract ([`available`]): on aarch64 in NEON ([`Products::F32x4`], the kernel in
//! [`crate::kernels::conv3x3`]; x86-64's portable path runs its twin), on x86-64 in the forms
//! below.
//!
//! Why: tract lowers each such layer to an explicit `Pad` copy of its input, a lazily gathered
//! im2col matrix and a matrix product; `perf` on `m3_per_face` (AMD Zen 4, with tract running these layers) put the
//! gather alone at 14 % of M3 and the copies around it (ndarray `Zip` 3.6 %, memmove and memset
//! 3.9 %) at 5–8 %, for layers whose arithmetic its matrix kernels did in ≈ 30 %. Here each layer reads the previous
//! layer's output in place — written with a zero border that is this layer's padding — and
//! multiplies straight from it: sixteen output channels in two registers, six output positions at
//! a time, each input value broadcast from where it lies, so nothing is gathered or copied.
//!
//! Where the CPU also has AVX-512 BF16 (with VL: e.g. AMD Zen 4, Intel Cooper Lake and Sapphire Rapids), layers of
//! more than one input channel multiply in bf16: inputs and weights rounded to 8 significant bits,
//! products summed in f32 by `vdpbf16ps`, which does twice the multiply-adds of an f32 FMA per
//! instruction. The input channels go in pairs (each position's two values in one 32-bit word, so
//! one broadcast feeds two products), converted from the f32 buffer once per run. On the
//! development machine (AMD EPYC Zen 4) the trunk layers ran 1.45–1.65× faster (a timing of four
//! level-1-shaped layers alone), `m3_per_face` 362 → 299–315 µs and the validation NME moved
//! 3.979 → 3.980 % (`models/MODEL_CARD.md`). Phones multiply in f32 ([`Products::F32x4`]).
//!
//! Where the CPU has AVX-512F but is not AMD's, the layers multiply in f32 on 512-bit registers
//! instead: two blocks of sixteen output channels in one register each, eight output positions at
//! a time. On an Intel Xeon with AVX-512 BF16, FP16 and AMX a loop of independent FMAs ran 0.121 ns per 256-bit and 0.130 ns per
//! 512-bit FMA (two 512-bit FMA units: 66 against 123 GMAC/s), while `vdpbf16ps` took 0.483 ns on
//! 256 bits (33 GMAC/s, half the f32 rate): there bf16 made `m3_per_face` slower (551 / 573 µs
//! against 413 µs in f32 on 256 bits). Where such a CPU also has AVX-512 VNNI (with BW), the
//! layers of more than one input channel whose weights are int8 per output channel — the
//! shipped M3 networks' storage — multiply in int8 instead ([`Quads`]): each layer's input
//! rounded to u8 steps of 1/255 of its largest value, four u8 × i8 products summed in an i32
//! lane by `vpdpbusd`. On an Intel Xeon with AVX-512 VNNI a loop of independent 512-bit `vpdpbusd`
//! ran 0.135 ns each, the rate of the 512-bit FMA (0.133 ns) with four times its multiply-adds
//! (474 against 120 GMAC/s): `m3_per_face` 236–237 → 164 µs, `m3_per_face_mirror_average`
//! 356–375 → 244–251 µs in alternating runs, the validation NME 3.865 → 3.867 % in mirror
//! average and 3.979 → 3.980 % single-pass (the mean over eight box-jitter seeds 3.906 → 3.906 %;
//! `models/MODEL_CARD.md`). AMD keeps bf16 (int8 not measured there).
//!
//! With `MONOTRACK_CONV=maddubs` the same int8 layers run on 256-bit registers (AVX2,
//! [`Products::Maddubs`]): `vpmaddubsw` sums two u8 × i8 products into an i16
//! lane and `vpmaddwd` two of those into an i32 lane, three instructions for 32 multiply-adds
//! where f32 takes four FMAs (on an AMD EPYC Zen 3 a loop of them ran 0.41 against
//! 0.66 ns). The i16 sum saturates, so each layer's input keeps only as many steps as its widest
//! pair of neighbouring weights allows ([`maddubs_levels`]: 131–160 for the shipped layers,
//! against 255). On that Zen 3 (one binary, `MONOTRACK_CONV` alternating):
//! `m3_per_face` 484 / 483 → 395 / 377 µs, `m3_level1_face_confidence` 147 / 150 → 112 / 110 µs;
//! the validation NME 3.979 → 3.986 % single-pass, 3.865 → 3.865 % in mirror average
//! (`models/MODEL_CARD.md`). It is not the default anywhere: a gesture probability in one
//! `m3_golden` case moves 0.027 from the Python reference, over that test's 0.02. `MONOTRACK_CONV=avx2|avx512|bf16|vnni|maddubs`
//! in the environment overrides the choice (for measurements; a form the CPU lacks is ignored).
//!
//! Layout (the ONNX one, batch-major): input `batch × cin × (in_h + 2) × (in_w + 2)` with a zero
//! border of one, output `batch × cout × (out_h + 2·pad) × (out_w + 2·pad)`, only its interior
//! written. Between two layers of a chain whose second runs in int8 or in the 256-bit f32 kernel
//! the buffer is [`Layout::Interleaved`] instead: position after position, each position's
//! channels together. The first layer then stores each position's sixteen channels as they lie in
//! its registers, and the second quantises them into its own layout on the way, or (f32)
//! broadcasts each value from where it lies, so nothing is transposed or scattered value by value
//! (`store_wide`, which turns a group's positions × channels into channel planes, took 16 % of
//! `m3_per_face` in `perf` on an Intel Xeon with channel planes between all layers; the 256-bit kernel's value-by-value
//! stores about 30 % of its time on an AVX2-only AMD EPYC Zen 3, where `m3_per_face` went
//! 551.9 / 536.7 → 460.8 / 461.9 / 492.6 µs in alternating runs). The values, the sums and the quantised words are the same in both
//! layouts.

/// [`Products::whole_graph_tolerance`] of the int8 form. Each layer's input is rounded to 1/255
/// of its largest value, so a product is off by up to half of that step times its weight.
/// Measured on the shipped networks (the tests' inputs): up to 1.08e-2 for the mouth net's
/// gesture logits, 7.5e-3 for level 1's face logit, up to 2.0e-3 for every other output (the
/// detector's layers hold f16 weights and stay f32). What this costs in landmarks is measured end
/// to end (`models/MODEL_CARD.md`).
#[cfg(test)]
pub(crate) const INT8_TOLERANCE: f32 = 2e-2;

/// [`INT8_TOLERANCE`] of [`Products::Maddubs`], whose inputs keep 131–160 steps instead of 255
/// ([`maddubs_levels`]). Measured on the shipped networks (the tests' inputs): up to 2.6e-2 for
/// level 1's face logit, 1.0e-2 and 8.9e-3 for the brow and mouth nets' gesture logits, up to
/// 4.5e-3 for every other output. What this costs in landmarks is measured end to end
/// (`models/MODEL_CARD.md`).
#[cfg(test)]
pub(crate) const INT8_7BIT_TOLERANCE: f32 = 4e-2;

/// One layer's weights as read from the graph.
#[derive(Debug, Clone)]
pub(crate) struct ConvWeights {
    /// `cout × cin × 3 × 3`, as ONNX stores it.
    pub(crate) kernel: Vec<f32>,
    pub(crate) bias: Vec<f32>,
    pub(crate) stride: usize,
}

/// Output channels computed together: two AVX2 registers of f32, or one AVX-512 register.
pub(crate) const BLOCK: usize = 16;

/// How the buffer between two layers holds its values (both with the zero border around each
/// map that is the next layer's padding).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Layout {
    /// Channel after channel, each a padded plane: `batch × channels × rows × cols` (ONNX's).
    Planar,
    /// Position after position, each position's channels together, their count rounded up to a
    /// whole [`BLOCK`] (the extra channels zero): `batch × rows × cols × channels`.
    Interleaved,
}

/// Output positions per group of the AVX-512 kernel: two blocks of channels times eight positions
/// is sixteen accumulators of its thirty-two registers, and per tap two weight loads and eight
/// broadcasts feed sixteen FMAs.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
const POSITIONS_512: usize = 8;

/// How a layer's products are computed (see the module notes for which CPU runs which).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Products {
    /// f32 FMAs on 256-bit registers (AVX2 + FMA).
    Avx2,
    /// f32 FMAs on 512-bit registers (AVX-512F).
    Avx512,
    /// bf16 pairs summed in f32 (AVX-512 BF16 + VL), for layers of more than one input channel.
    Bf16,
    /// u8 inputs times int8 weights, four products summed in an i32 lane by `vpdpbusd` (AVX-512
    /// VNNI + BW), for layers of more than one input channel whose weights are int8 times a
    /// scale per output channel ([`Quads`]); 512-bit f32 for the other layers.
    Vnni,
    /// The layers [`Products::Vnni`] takes, on 256-bit registers (AVX2): `vpmaddubsw` sums two
    /// u8 × i8 products into an i16 lane, saturating, and `vpmaddwd` two of those into an i32
    /// lane; the inputs keep as many steps as no i16 sum can saturate with ([`maddubs_levels`]);
    /// 256-bit f32 for the other layers.
    Maddubs,
    /// f32 FMAs on 128-bit registers ([`crate::kernels::conv3x3`]): NEON on aarch64, what phones
    /// run; on x86-64 its twin of the same width and bits, which the portable path takes.
    F32x4,
}

/// Largest u8 step of the [`Products::Vnni`] form's inputs (`vpdpbusd` sums in i32).
const VNNI_LEVELS: i32 = 255;

/// Largest u8 step of a [`Products::Maddubs`] layer's inputs: `vpmaddubsw` sums the products of
/// two neighbouring channels (bytes 0–1 and 2–3 of a word) into an i16 lane, so an input of at
/// most `L` steps cannot saturate it where `L · (|w₀| + |w₁|) ≤ 32,767` for every such pair of
/// weights (`q`: `cout × cin × 9`, as ONNX orders them): 129 for pairs of ±127 (seven bits), up
/// to 255 where no pair's weights are both large.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn maddubs_levels(q: &[i8], cout: usize, cin: usize) -> i32 {
    let mut widest = 1;
    for co in 0..cout {
        for c in (0..cin).step_by(2) {
            for tap in 0..9 {
                let w = |c: usize| {
                    if c < cin {
                        i32::from(q[(co * cin + c) * 9 + tap]).abs()
                    } else {
                        0
                    }
                };
                widest = widest.max(w(c) + w(c + 1));
            }
        }
    }
    (i32::from(i16::MAX) / widest).min(VNNI_LEVELS)
}

impl Products {
    /// Whether this CPU can run the form.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(crate) fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            let avx512 = crate::kernels::cpu::has_avx2_fma() && has!("avx512f");
            match self {
                Products::Avx2 => crate::kernels::cpu::has_avx2_fma(),
                Products::Avx512 => avx512,
                Products::Bf16 => avx512 && has!("avx512vl") && has!("avx512bf16"),
                Products::Vnni => avx512 && has!("avx512bw") && has!("avx512vnni"),
                Products::Maddubs => crate::kernels::cpu::has_avx2_fma(),
                // The twin needs FMA (without it the portable form's fused multiply-add is a
                // library call per product).
                Products::F32x4 => std::arch::is_x86_feature_detected!("fma"),
            }
        }
        // Other 32-bit ARM builds (armeabi-v7a) have no fused multiply-add in their baseline
        // and keep tract.
        #[cfg(not(target_arch = "x86_64"))]
        {
            cfg!(target_arch = "aarch64") && self == Products::F32x4
        }
    }

    /// Whether the products are of bf16-rounded values.
    #[cfg(test)]
    pub(crate) fn is_bf16(self) -> bool {
        self == Products::Bf16
    }

    /// How far a network whose 3×3 layers ran in this form may be from tract's f32 run, as a
    /// share of its largest output (at least 1): float rounding for the f32 forms,
    /// [`crate::nn::stem::BF16_TOLERANCE`] and [`INT8_TOLERANCE`] for the others.
    #[cfg(test)]
    pub(crate) fn whole_graph_tolerance(self) -> f32 {
        match self {
            Products::Avx2 | Products::Avx512 | Products::F32x4 => 1e-4,
            Products::Bf16 => crate::nn::stem::BF16_TOLERANCE,
            Products::Vnni => INT8_TOLERANCE,
            Products::Maddubs => INT8_7BIT_TOLERANCE,
        }
    }
}

/// The form for this CPU, decided once: bf16 on AMD CPUs that have it (Zen 4: 1.45–1.65× on the
/// trunk layers), int8 on other CPUs with AVX-512 VNNI (on the Intel Xeon measured
/// on the whole M3: 1.44–1.50×), f32 on 512-bit registers on other CPUs with AVX-512F (on the Intel Xeon
/// measured, `vdpbf16ps` ran at half the FMA's rate and two 512-bit FMA units doubled the
/// 256-bit rate), else f32 on 256-bit registers; `MONOTRACK_CONV` overrides it where the CPU has
/// the named form (the 256-bit int8 form, [`Products::Maddubs`], only so: see the module notes).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn chosen_products() -> Products {
    static CHOSEN: std::sync::OnceLock<Products> = std::sync::OnceLock::new();
    *CHOSEN.get_or_init(|| {
        let named = std::env::var("MONOTRACK_CONV")
            .ok()
            .and_then(|v| match v.as_str() {
                "avx2" => Some(Products::Avx2),
                "avx512" => Some(Products::Avx512),
                "bf16" => Some(Products::Bf16),
                "vnni" => Some(Products::Vnni),
                "maddubs" => Some(Products::Maddubs),
                "f32x4" => Some(Products::F32x4),
                _ => None,
            });
        if let Some(p) = named.filter(|p| p.supported()) {
            return p;
        }
        // The phone's form: on aarch64, and on x86-64's portable path (its twin).
        if cfg!(target_arch = "aarch64")
            || crate::kernels::kernel_path() == crate::kernels::KernelPath::Portable
        {
            return Products::F32x4;
        }
        #[cfg(target_arch = "x86_64")]
        let amd = crate::kernels::cpu::is_amd().unwrap_or(false);
        #[cfg(not(target_arch = "x86_64"))]
        let amd = false;
        products_for(
            amd,
            Products::Bf16.supported(),
            Products::Avx512.supported(),
            Products::Vnni.supported(),
        )
    })
}

/// The policy of [`chosen_products`], from the vendor and the forms the CPU has.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn products_for(amd: bool, has_bf16: bool, has_avx512: bool, has_vnni: bool) -> Products {
    if amd && has_bf16 {
        Products::Bf16
    } else if !amd && has_vnni {
        Products::Vnni
    } else if !amd && has_avx512 {
        Products::Avx512
    } else {
        Products::Avx2
    }
}

/// Output positions computed together: with two accumulators each, twelve of the sixteen vector
/// registers (tract's x86-64 matrix kernel has the same 16 × 6 shape). In bf16 too: 8 and 10
/// measured the same, 12 slower (spills).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
const POSITIONS: usize = 6;

/// Output positions of [`Block::run_maddubs`]: two i32 accumulators each, with the two weight
/// registers, the broadcast word, the products and the ones of `vpmaddwd` in the rest of the
/// sixteen registers (5, which leaves none spare, measured the same within the noise).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
const POSITIONS_MADDUBS: usize = 4;

/// A layer for fixed input sizes, with its weights packed for the kernel.
// Off x86-64 nothing runs the kernel ([`available`] is false there), so the packed layout is unread.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
#[derive(Debug, Clone)]
pub(crate) struct Conv3x3 {
    batch: usize,
    cin: usize,
    cout: usize,
    stride: usize,
    in_plane: usize,
    /// Positions per padded input row.
    in_row: usize,
    out_plane: usize,
    out_h: usize,
    out_w: usize,
    out_pad: usize,
    /// Per block of [`BLOCK`] output channels: for each of the `9·cin` taps (channel, row,
    /// column) the block's weights, zero past `cout`.
    packed: Vec<f32>,
    /// The bias, zero past `cout` up to a whole block.
    bias: Vec<f32>,
    /// Offset of each tap in the padded input from the window's top-left value.
    taps: Vec<usize>,
    /// Per output position (row-major): its window's top-left offset in a padded input plane, and
    /// its offset in an output plane.
    at_in: Vec<usize>,
    at_out: Vec<usize>,
    /// The bf16 form of the layer, where it runs in bf16 products ([`Products::Bf16`]).
    pairs: Option<Pairs>,
    /// The int8 form of the layer, where it runs in int8 products ([`Products::Vnni`]).
    quads: Option<Quads>,
    /// The form of [`crate::kernels::conv3x3`] the layer runs, where its products are
    /// [`Products::F32x4`].
    x4: Option<crate::kernels::conv3x3::Form>,
    /// Whether the f32 products run on 512-bit registers ([`Products::Avx512`], and
    /// [`Products::Vnni`] for the runs the int8 form does not take).
    wide: bool,
    /// How the input and the output are held ([`Self::interleave_input`],
    /// [`Self::interleave_output`]).
    input_layout: Layout,
    output_layout: Layout,
    /// Where the input is interleaved: the planar copy the f32 kernels read in the runs the int8
    /// form does not take.
    planar: Vec<f32>,
    /// Where the output is interleaved: the largest value the last run wrote (≥ 0, ReLU; may be
    /// +∞), so the next layer quantises without a pass to find it.
    peak: Option<f32>,
}

/// A layer in int8 products (`vpdpbusd`: four u8 × i8 products summed into an i32 lane, four
/// times the multiply-adds per instruction of an f32 FMA, and at the same rate on the Intel Xeon
/// measured): the input channels taken in fours, each four's values at a position held as one
/// 32-bit word (byte `k` channel `4q + k`), so one broadcast feeds four products.
///
/// The weights are the int8 values the shipped networks store (`models/train/onnx_q8.py`: one
/// symmetric scale per output channel), so they lose nothing here. The input is quantised per
/// run: `u8 = round(v · 255 / max)` over the whole input, which holds ReLU outputs (nothing
/// negative); a run whose input has a negative or non-finite value goes through the f32 kernel.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
#[derive(Debug, Clone)]
struct Quads {
    /// Per block of [`BLOCK`] output channels: for each of the `9·⌈cin/4⌉` quad taps (channel
    /// four, row, column) the block's weight quads (byte `k` the weight of channel `4q + k`),
    /// zero past `cout` and past `cin`.
    packed: Vec<u32>,
    /// Offset of each quad tap in the quantised input from the window's top-left word.
    taps: Vec<usize>,
    /// Per output channel its weights' scale, zero past `cout` up to a whole block.
    scale: Vec<f32>,
    /// This run's factor per output channel from i32 sums to values: `scale` × the input's
    /// quantisation step.
    step: Vec<f32>,
    /// The input quantised: `batch × ⌈cin/4⌉` padded planes of words.
    input: Vec<u32>,
    /// Whether the products are `vpdpbusd`'s ([`Products::Vnni`]; else `vpmaddubsw`'s,
    /// [`Products::Maddubs`]).
    vnni: bool,
    /// The largest u8 step of the input: [`VNNI_LEVELS`], or [`maddubs_levels`].
    levels: i32,
}

/// `w` as int8 times a scale per output (`output_of(t)` the output of value `t`, below
/// `outputs`), where every value is one to within 1e-6 of its output's largest magnitude — the
/// form `models/train/onnx_q8.py` stores; `None` otherwise. The 3×3 layers here and the fully
/// connected heads (`landmarks::dense`) keep their weights so.
pub(crate) fn int8_per_output(
    w: &[f32],
    outputs: usize,
    output_of: impl Fn(usize) -> usize,
) -> Option<(Vec<i8>, Vec<f32>)> {
    let mut scale = vec![0f32; outputs];
    for (t, v) in w.iter().enumerate() {
        let s = &mut scale[output_of(t)];
        *s = s.max(v.abs());
    }
    for s in &mut scale {
        *s /= 127.0;
    }
    let q: Vec<i8> = w
        .iter()
        .enumerate()
        .map(|(t, &v)| {
            let s = scale[output_of(t)];
            if s > 0.0 {
                (v / s).round().clamp(-127.0, 127.0) as i8
            } else {
                0
            }
        })
        .collect();
    let exact = w.iter().zip(&q).enumerate().all(|(t, (&v, &q))| {
        let s = scale[output_of(t)];
        (f32::from(q) * s - v).abs() <= 1e-6 * 127.0 * s
    });
    exact.then_some((q, scale))
}

/// Four int8 values as the word `vpdpbusd` reads: byte `b` is `byte(b)`.
pub(crate) fn int8_word(byte: impl Fn(usize) -> i8) -> u32 {
    (0..4).fold(0, |word, b| word | (u32::from(byte(b) as u8) << (8 * b)))
}

/// A layer in bf16 (`vdpbf16ps`: two bf16 products summed into an f32 lane, twice the
/// multiply-adds per instruction of an f32 FMA): the input channels taken in pairs, each pair's
/// two values at a position held as one 32-bit word (low half the even channel), so one
/// broadcast feeds both products.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
#[derive(Debug, Clone)]
struct Pairs {
    /// Per block of [`BLOCK`] output channels: for each of the `9·⌈cin/2⌉` pair taps (channel
    /// pair, row, column) the block's weight pairs, zero past `cout` and past `cin`.
    packed: Vec<u32>,
    /// Offset of each pair tap in the paired input from the window's top-left word.
    taps: Vec<usize>,
    /// The input rounded to bf16 and paired: `batch × ⌈cin/2⌉` padded planes of words.
    input: Vec<u32>,
}

/// Runs the kernel `$block.$method::<P, S>` (`Block::run`, `Block::run_bf16` or
/// `Block::run_maddubs`) over a layer's output positions: groups of [`POSITIONS`] (or of the
/// count given), then the remainder. For the `unsafe` kernels of
/// [`Block`]: the caller has their CPU features and the layer's offsets.
#[cfg(target_arch = "x86_64")]
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
#[cfg(target_arch = "x86_64")]
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
#[cfg(target_arch = "x86_64")]
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
    /// A layer over `batch × cin × in_h × in_w` maps (held with a border of one) writing its
    /// output with a border of `out_pad`.
    ///
    /// # Panics
    /// When the weights do not hold `cout × cin × 9` values for `cout` biases or the stride is
    /// not 1 or 2 (the graph reader checks both first).
    pub(crate) fn new(
        batch: usize,
        cin: usize,
        in_h: usize,
        in_w: usize,
        weights: &ConvWeights,
        out_pad: usize,
    ) -> Self {
        let cout = weights.bias.len();
        let s = weights.stride;
        assert!(s == 1 || s == 2, "stride {s}");
        assert_eq!(weights.kernel.len(), cout * cin * 9, "kernel size");
        // ONNX output size of a 3×3 kernel with padding 1: ⌊(n + 2 − 3) / s⌋ + 1 (0 for n = 0).
        let side = |n: usize| if n == 0 { 0 } else { (n - 1) / s + 1 };
        let (out_h, out_w) = (side(in_h), side(in_w));
        let (pw, qw) = (in_w + 2, out_w + 2 * out_pad);
        let in_plane = (in_h + 2) * pw;
        let k = 9 * cin;
        let packed = pack(cout, k, 0.0, |co, t| weights.kernel[co * k + t]);
        let mut bias = weights.bias.clone();
        bias.resize(cout.div_ceil(BLOCK) * BLOCK, 0.0);
        let taps = tap_offsets(cin, in_plane, pw, 1);
        let (mut at_in, mut at_out) = (Vec::new(), Vec::new());
        for y in 0..out_h {
            for x in 0..out_w {
                at_in.push(s * y * pw + s * x);
                at_out.push((y + out_pad) * qw + x + out_pad);
            }
        }
        let form = products();
        // One input channel gains nothing from pairing (half of each pair would be zero).
        let pairs = (cin >= 2 && form == Products::Bf16).then(|| {
            let cp = cin.div_ceil(2);
            let packed = pack(cout, 9 * cp, 0, |co, t| {
                let (pair, tap) = (t / 9, t % 9);
                let half = |c: usize| {
                    (c < cin)
                        .then(|| weights.kernel[(co * cin + c) * 9 + tap])
                        .map_or(0, bf16_bits)
                };
                half(2 * pair) | (half(2 * pair + 1) << 16)
            });
            Pairs {
                packed,
                taps: tap_offsets(cp, in_plane, pw, 1),
                input: vec![0; batch * cp * in_plane],
            }
        });
        let quads = (cin >= 2 && matches!(form, Products::Vnni | Products::Maddubs))
            .then(|| int8_per_output(&weights.kernel, cout, |t| t / (9 * cin)))
            .flatten()
            .map(|(q, mut scale)| {
                let cq = cin.div_ceil(4);
                let packed = pack(cout, 9 * cq, 0, |co, t| {
                    let (four, tap) = (t / 9, t % 9);
                    int8_word(|b| {
                        let c = 4 * four + b;
                        if c < cin {
                            q[(co * cin + c) * 9 + tap]
                        } else {
                            0
                        }
                    })
                });
                scale.resize(bias.len(), 0.0);
                Quads {
                    packed,
                    taps: tap_offsets(cq, in_plane, pw, 1),
                    step: vec![0.0; scale.len()],
                    scale,
                    input: vec![0; batch * cq * in_plane],
                    vnni: form == Products::Vnni,
                    levels: if form == Products::Vnni {
                        VNNI_LEVELS
                    } else {
                        maddubs_levels(&q, cout, cin)
                    },
                }
            });
        Self {
            batch,
            cin,
            cout,
            stride: s,
            in_plane,
            in_row: pw,
            out_plane: (out_h + 2 * out_pad) * qw,
            out_h,
            out_w,
            out_pad,
            packed,
            bias,
            taps,
            at_in,
            at_out,
            pairs,
            quads,
            x4: (form == Products::F32x4).then(crate::kernels::conv3x3::Form::for_this_cpu),
            wide: matches!(form, Products::Avx512 | Products::Vnni),
            input_layout: Layout::Planar,
            output_layout: Layout::Planar,
            planar: Vec::new(),
            peak: None,
        }
    }

    /// Whether the layer would read an interleaved input: the layers that quantise their input
    /// ([`Quads`]) and those of the 256-bit and 128-bit f32 kernels, which broadcast each input
    /// value from wherever it lies.
    pub(crate) fn takes_interleaved_input(&self) -> bool {
        self.quads.is_some() || self.f32_256()
    }

    /// Offset in the input the f32 kernels read from one output position's window to the next
    /// one's along a row: the stride, times the channels per position where the layer reads its
    /// input interleaved in place (the int8 form reads planes of words, its fallback planes).
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    fn step(&self) -> usize {
        if self.input_layout == Layout::Interleaved && self.quads.is_none() {
            self.stride * Self::interleaved_width(self.cin)
        } else {
            self.stride
        }
    }

    /// Whether the layer's products are the 256-bit or the 128-bit f32 kernel's
    /// ([`Products::Avx2`], [`Products::F32x4`]).
    fn f32_256(&self) -> bool {
        !self.wide && self.pairs.is_none() && self.quads.is_none()
    }

    /// Reads the input as [`Layout::Interleaved`] from now on (see [`Self::input_len`]).
    ///
    /// # Panics
    /// When the layer reads planes only ([`Self::takes_interleaved_input`]).
    pub(crate) fn interleave_input(&mut self) {
        assert!(self.takes_interleaved_input(), "this layer reads planes");
        self.input_layout = Layout::Interleaved;
        if self.quads.is_some() {
            self.planar = vec![0.0; self.batch * self.cin * self.in_plane];
        } else {
            // The f32 kernel reads the interleaved values in place: the same taps in the same
            // order (so the same sums), each at its position's channel.
            let width = Self::interleaved_width(self.cin);
            self.taps = tap_offsets(self.cin, 1, self.in_row, width);
            for at in &mut self.at_in {
                *at *= width;
            }
        }
    }

    /// Writes the output as [`Layout::Interleaved`] from now on (see [`Self::output_len`]).
    pub(crate) fn interleave_output(&mut self) {
        self.output_layout = Layout::Interleaved;
    }

    /// Channels per position of an interleaved buffer of `channels`.
    fn interleaved_width(channels: usize) -> usize {
        channels.next_multiple_of(BLOCK)
    }

    /// Output shape of a planar output, border included: `batch × cout × (out_h + 2·pad) ×
    /// (out_w + 2·pad)`.
    pub(crate) fn output_shape(&self) -> [usize; 4] {
        let p = 2 * self.out_pad;
        [self.batch, self.cout, self.out_h + p, self.out_w + p]
    }

    /// Output length: [`Self::output_shape`]'s, with the channels rounded up to a whole
    /// [`BLOCK`] where the output is interleaved.
    pub(crate) fn output_len(&self) -> usize {
        let channels = match self.output_layout {
            Layout::Planar => self.cout,
            Layout::Interleaved => Self::interleaved_width(self.cout),
        };
        self.batch * channels * self.out_plane
    }

    /// Input length: `batch × cin × (in_h + 2) × (in_w + 2)`, the channels rounded up to a whole
    /// [`BLOCK`] where the input is interleaved.
    pub(crate) fn input_len(&self) -> usize {
        let channels = match self.input_layout {
            Layout::Planar => self.cin,
            Layout::Interleaved => Self::interleaved_width(self.cin),
        };
        self.batch * channels * self.in_plane
    }

    /// Computes the layer on `input` (its border zero) into the interior of `out` (of
    /// [`Self::output_len`]; the border is not written, nor, where the output is interleaved,
    /// anything but the channels of the interior's positions). Needs AVX2 and FMA
    /// ([`available`]); where the CPU has AVX-512 BF16 too, the products are of bf16-rounded
    /// inputs and weights (f32 sums).
    ///
    /// # Panics
    /// When the buffer lengths differ from the layer's, or off a CPU with AVX2 and FMA.
    pub(crate) fn run(&mut self, input: &[f32], out: &mut [f32]) {
        self.run_with(input, None, out);
    }

    /// [`Self::run`], where `input_peak` may be the largest value of an interleaved `input`: the
    /// [`Self::output_peak`] of the layer that wrote all of it (the rest of it being its zero
    /// border), which the int8 form then takes instead of finding it.
    #[cfg_attr(not(target_arch = "x86_64"), allow(unused_variables))]
    pub(crate) fn run_with(&mut self, input: &[f32], input_peak: Option<f32>, out: &mut [f32]) {
        assert_eq!(input.len(), self.input_len(), "conv input length");
        assert_eq!(out.len(), self.output_len(), "conv output length");
        self.peak = None;
        #[cfg(target_arch = "x86_64")]
        if let Some(mut quads) = self.quads.take() {
            let input_peak = input_peak.filter(|_| self.input_layout == Layout::Interleaved);
            #[allow(unsafe_code)]
            // SAFETY: `quads` exists only where the CPU has AVX-512F, BW and VNNI, AVX2 and FMA
            // (`Products::Vnni`), or (not `vnni`) AVX2 and FMA (`Products::Maddubs`); the
            // lengths were checked above.
            let done = unsafe { self.quantize(&mut quads, input, input_peak) };
            if done {
                // SAFETY: as above; `quads.input` now holds this run's input.
                #[allow(unsafe_code)]
                let peak = unsafe {
                    if quads.vnni {
                        self.run_vnni(&quads, out)
                    } else {
                        self.run_maddubs(&quads, out)
                    }
                };
                self.peak = peak;
            }
            self.quads = Some(quads);
            if done {
                return;
            }
        }
        if self.input_layout == Layout::Interleaved && self.quads.is_some() {
            // The f32 kernels of an int8 layer read planes: a run the int8 form did not take (an
            // input u8 cannot hold) goes through a planar copy.
            let mut planar = std::mem::take(&mut self.planar);
            self.deinterleave(input, &mut planar);
            self.run_float(&planar, out);
            self.planar = planar;
        } else {
            self.run_float(input, out);
        }
    }

    /// Where the output is interleaved, the largest value the last run wrote (+∞ included).
    pub(crate) fn output_peak(&self) -> Option<f32> {
        self.peak
    }

    /// `input` (interleaved) as planes into `planar`.
    fn deinterleave(&self, input: &[f32], planar: &mut [f32]) {
        let width = Self::interleaved_width(self.cin);
        for (slot, dst) in input
            .chunks_exact(width * self.in_plane)
            .zip(planar.chunks_exact_mut(self.cin * self.in_plane))
        {
            for (p, values) in slot.chunks_exact(width).enumerate() {
                for (c, &v) in values[..self.cin].iter().enumerate() {
                    dst[c * self.in_plane + p] = v;
                }
            }
        }
    }

    /// [`Self::run`] in f32 or bf16 products, on an input in the layout [`Self::taps`] address
    /// (planes, except for a 256-bit f32 layer that reads interleaved).
    fn run_float(&mut self, input: &[f32], out: &mut [f32]) {
        if let Some(form) = self.x4 {
            self.run_x4(form, input, out);
            self.peak = None;
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(mut pairs) = self.pairs.take() {
            // SAFETY: `pairs` exists only where the CPU has AVX2, FMA and AVX-512 BF16 + VL
            // (`Products::Bf16`); the lengths were checked above.
            #[allow(unsafe_code)]
            let peak = unsafe { self.run_bf16(&mut pairs, input, out) };
            self.peak = peak;
            self.pairs = Some(pairs);
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            #[allow(unsafe_code)]
            // SAFETY: `wide` is set only where the CPU has AVX-512F, AVX2 and FMA
            // (`Products::supported`); the lengths were checked above.
            unsafe {
                self.run_avx512(input, out)
            };
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if crate::kernels::cpu::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA; the lengths were checked above.
            #[allow(unsafe_code)]
            let peak = unsafe { self.run_avx2(input, out) };
            self.peak = peak;
            return;
        }
        panic!("Conv3x3::run needs AVX2 and FMA, or F32x4 products (conv::available)");
    }

    /// How the output is walked: the channels per position where it is interleaved (0 for
    /// planes), the values per batch slot, and the offset from one block of channels to the next.
    fn output_steps(&self) -> (usize, usize, usize) {
        match self.output_layout {
            Layout::Planar => (0, self.cout * self.out_plane, BLOCK * self.out_plane),
            Layout::Interleaved => {
                let width = Self::interleaved_width(self.cout);
                (width, width * self.out_plane, BLOCK)
            }
        }
    }

    /// [`Self::run`] through [`crate::kernels::conv3x3`] in `form`: per batch slot and block of
    /// sixteen output channels, the output positions in groups of six.
    fn run_x4(&self, form: crate::kernels::conv3x3::Form, input: &[f32], out: &mut [f32]) {
        let reach = self.taps.iter().copied().max().unwrap_or(0);
        let per_slot = input.len() / self.batch.max(1);
        let (width, out_slot, _) = self.output_steps();
        for b in 0..self.batch {
            crate::kernels::conv3x3::FullLayer {
                input: &input[b * per_slot..][..per_slot],
                packed: &self.packed,
                bias: &self.bias,
                taps: &self.taps,
                reach,
                cout: self.cout,
                plane: self.out_plane,
                width,
                relu: true,
                at_in: &self.at_in,
                at_out: &self.at_out,
            }
            .run(form, &mut out[b * out_slot..][..out_slot]);
        }
    }

    /// # Safety
    /// The CPU has AVX2 and FMA; `input` and `out` have the layer's lengths.
    #[cfg(target_arch = "x86_64")]
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
    #[cfg(target_arch = "x86_64")]
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
    #[cfg(target_arch = "x86_64")]
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
}

impl Conv3x3 {
    /// Whether the layer runs in int8 products where its input allows.
    #[cfg(test)]
    pub(crate) fn is_int8(&self) -> bool {
        self.quads.is_some()
    }

    /// The int8 kernel on the input [`Self::quantize`] left in `quads`; returns the largest value
    /// stored where the output is interleaved.
    ///
    /// # Safety
    /// The CPU has AVX-512F, BW and VNNI, AVX2 and FMA; `out` has the layer's length and `quads`
    /// is the layer's.
    #[cfg(target_arch = "x86_64")]
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

    /// [`Self::run_vnni`] in [`Products::Maddubs`]'s products, one block of [`BLOCK`] output
    /// channels at a time.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `out` has the layer's length and `quads` is the layer's.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(unsafe_code)]
    unsafe fn run_maddubs(&self, quads: &Quads, out: &mut [f32]) -> Option<f32> {
        self.for_each_block(
            &quads.input,
            &quads.packed,
            &quads.taps,
            &quads.step,
            out,
            |_| 1,
            |block, _, out| {
                each_group!(block.run_maddubs, self, out, POSITIONS_MADDUBS);
            },
        )
    }

    /// Quantises `input` into `quads.input` (`u8 = round(v · levels / max)`, `levels` the
    /// layer's [`Quads::levels`]) and sets `quads.step`; false (nothing written) where the input holds a
    /// negative or non-finite value, which u8 cannot carry. `input_peak`: as [`Self::run_with`].
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA, and where `quads.vnni`, AVX-512F and BW; `input` has the
    /// layer's length and `quads` is the layer's.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[allow(unsafe_code)]
    unsafe fn quantize(&self, quads: &mut Quads, input: &[f32], input_peak: Option<f32>) -> bool {
        let vnni = quads.vnni;
        let max = match input_peak {
            Some(peak) => peak.is_finite().then_some(peak),
            // SAFETY: AVX-512F where `vnni` (the contract).
            None if vnni => unsafe { nonnegative_max(input) },
            // The layers before a 256-bit int8 layer hand their peak over (`crate::nn::stem`), so
            // this runs in tests only.
            None => nonnegative_max_portable(input),
        };
        let Some(max) = max else {
            return false;
        };
        let levels = quads.levels as f32;
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
                    if vnni {
                        // SAFETY: AVX-512F and BW where `vnni` (the contract).
                        unsafe { quantize_interleaved(values, width, cq, per_step, words) };
                    } else {
                        quantize_interleaved_avx2(values, width, cq, per_step, quads.levels, words);
                    }
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
                        if vnni {
                            // SAFETY: AVX-512F and BW where `vnni` (the contract).
                            unsafe { quantize_four(planes, per_step, dst) };
                        } else {
                            quantize_four_avx2(planes, per_step, quads.levels, dst);
                        }
                    }
                }
            }
        }
        true
    }

    /// Whether the layer runs in bf16.
    #[cfg(test)]
    pub(crate) fn is_bf16(&self) -> bool {
        self.pairs.is_some()
    }

    /// # Safety
    /// The CPU has AVX2, FMA, AVX-512 BF16 and VL; `input` and `out` have the layer's lengths
    /// and `pairs` is the layer's.
    #[cfg(target_arch = "x86_64")]
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

/// Weights packed for the kernel: per block of [`BLOCK`] output channels, for each of the `k`
/// taps the block's values `weight(channel, tap)`, `zero` past `cout`.
pub(crate) fn pack<T: Copy>(
    cout: usize,
    k: usize,
    zero: T,
    weight: impl Fn(usize, usize) -> T,
) -> Vec<T> {
    let mut packed = vec![zero; cout.div_ceil(BLOCK) * k * BLOCK];
    for co in 0..cout {
        let (b, lane) = (co / BLOCK, co % BLOCK);
        for t in 0..k {
            packed[(b * k + t) * BLOCK + lane] = weight(co, t);
        }
    }
    packed
}

/// Offset of each tap (channel, row, column; `channels × 9` of them, in that order) from a
/// window's top-left value in an input of padded maps with rows of `row` positions, where one
/// channel lies `channel` values from the last and one position `position` values: planes of
/// `plane` values have `channel = plane, position = 1`, interleaved positions of `width`
/// channels `channel = 1, position = width`.
fn tap_offsets(channels: usize, channel: usize, row: usize, position: usize) -> Vec<usize> {
    (0..9 * channels)
        .map(|t| {
            let (c, dy, dx) = (t / 9, t % 9 / 3, t % 3);
            c * channel + (dy * row + dx) * position
        })
        .collect()
}

#[cfg(test)]
thread_local! {
    static FORCED_PRODUCTS: std::cell::Cell<Option<Products>> = const { std::cell::Cell::new(None) };
}

/// Every form this CPU can run, whichever it is given by default: a test holds each to its
/// reference.
#[cfg(test)]
pub(crate) fn product_forms() -> impl Iterator<Item = Products> + Clone {
    [
        Products::Avx2,
        Products::Avx512,
        Products::Bf16,
        Products::Vnni,
        Products::Maddubs,
        Products::F32x4,
    ]
    .into_iter()
    .filter(|p| p.supported())
}

/// Runs `f` with the layers it builds on this thread in the products `form`: for the tests that
/// hold a network to tract's f32 run in each form.
#[cfg(test)]
pub(crate) fn building<R>(form: Products, f: impl FnOnce() -> R) -> R {
    FORCED_PRODUCTS.set(Some(form));
    let r = f();
    FORCED_PRODUCTS.set(None);
    r
}

/// Whether layers built now multiply in f32 on 128-bit registers ([`Products::F32x4`]: aarch64,
/// x86-64's portable path): the detector's tail then runs in the same kernels
/// (`detect::tail`).
pub(crate) fn f32x4_products() -> bool {
    available() && products() == Products::F32x4
}

/// Whether layers built now multiply in int8 where their weights allow ([`Products::Vnni`]):
/// also the fully connected heads' choice (`landmarks::dense`).
pub(crate) fn int8_products() -> bool {
    products() == Products::Vnni
}

/// The form the layers built now take: [`chosen_products`], or in tests the one [`building`] set.
fn products() -> Products {
    #[cfg(test)]
    if let Some(p) = FORCED_PRODUCTS.get() {
        return p;
    }
    chosen_products()
}

/// `v` rounded to the nearest bf16 (ties to even), as its 16 bits: what `vcvtneps2bf16` gives
/// for the finite values the weights are.
fn bf16_bits(v: f32) -> u32 {
    let bits = v.to_bits();
    (bits + 0x7fff + ((bits >> 16) & 1)) >> 16
}

/// Rounds two planes to bf16 (to nearest, ties to even, as [`bf16_bits`]) and pairs them:
/// `dst[i]` = `even[i]` in the low half, `odd[i]` (0 without `odd`) in the high half. Integer
/// arithmetic on the bits: eight words in a handful of AVX2 operations.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
fn pair_bf16(even: &[f32], odd: Option<&[f32]>, dst: &mut [u32]) {
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
#[cfg(target_arch = "x86_64")]
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

/// [`nonnegative_max`] value by value.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn nonnegative_max_portable(v: &[f32]) -> Option<f32> {
    v.iter()
        .try_fold(0f32, |m, &x| (x.is_finite() && x >= 0.0).then(|| m.max(x)))
}

/// Quantises four planes to u8 (`round(v · per_step)`, ties to even, at most 255) into one word
/// per position, byte `k` from plane `k` (0 where it is `None`).
#[cfg(target_arch = "x86_64")]
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
#[cfg(target_arch = "x86_64")]
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
#[cfg(target_arch = "x86_64")]
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

/// The u8 steps of [`Products::Maddubs`]'s input: `round(v · per_step)` (ties to even), at
/// most `levels`, as i32 lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn steps_avx2(
    v: std::arch::x86_64::__m256,
    per_step: std::arch::x86_64::__m256,
    levels: std::arch::x86_64::__m256i,
) -> std::arch::x86_64::__m256i {
    use std::arch::x86_64::*;
    _mm256_min_epi32(_mm256_cvtps_epi32(_mm256_mul_ps(v, per_step)), levels)
}

/// [`steps_avx2`] of one value: the same rounding (`vcvtps2dq` rounds to nearest, ties to even).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn step_of(v: f32, per_step: f32, levels: i32) -> u32 {
    ((v * per_step).round_ties_even() as i32).clamp(0, levels) as u32
}

/// [`quantize_four`] for [`Products::Maddubs`] on AVX2: steps of at most `levels`, eight
/// positions at a time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
fn quantize_four_avx2(planes: [Option<&[f32]>; 4], per_step: f32, levels: i32, dst: &mut [u32]) {
    use std::arch::x86_64::*;
    let n = dst.len();
    assert!(planes.iter().flatten().all(|p| p.len() >= n));
    let (f, top) = (_mm256_set1_ps(per_step), _mm256_set1_epi32(levels));
    let mut i = 0;
    while i + 8 <= n {
        let level = |p: Option<&[f32]>| match p {
            // SAFETY: positions i..i + 8 lie below `n`, inside the plane (asserted above).
            Some(p) => steps_avx2(unsafe { _mm256_loadu_ps(p.as_ptr().add(i)) }, f, top),
            None => _mm256_setzero_si256(),
        };
        let [p0, p1, p2, p3] = planes;
        let word = _mm256_or_si256(
            _mm256_or_si256(level(p0), _mm256_slli_epi32::<8>(level(p1))),
            _mm256_or_si256(
                _mm256_slli_epi32::<16>(level(p2)),
                _mm256_slli_epi32::<24>(level(p3)),
            ),
        );
        // SAFETY: positions i..i + 8 lie inside `dst`.
        unsafe { _mm256_storeu_si256(dst.as_mut_ptr().add(i).cast(), word) };
        i += 8;
    }
    for (i, d) in dst.iter_mut().enumerate().skip(i) {
        *d = (0..4).fold(0, |word, k| {
            word | (planes[k].map_or(0, |p| step_of(p[i], per_step, levels)) << (8 * k))
        });
    }
}

/// [`quantize_interleaved`] for [`Products::Maddubs`] on AVX2: each position's sixteen channels
/// of a block rounded to bytes in registers (the same steps as [`quantize_four_avx2`]), their
/// four words stored to their planes one by one.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
fn quantize_interleaved_avx2(
    values: &[f32],
    width: usize,
    fours: usize,
    per_step: f32,
    levels: i32,
    dst: &mut [u32],
) {
    use std::arch::x86_64::*;
    let n = values.len() / width.max(1);
    assert!(
        width.is_multiple_of(BLOCK)
            && values.len() == n * width
            && 4 * fours <= width
            && dst.len() == fours * n,
        "quantize_interleaved_avx2: lengths"
    );
    let (f, top) = (_mm256_set1_ps(per_step), _mm256_set1_epi32(levels));
    let mut words = [0u32; 8];
    for (p, position) in values.chunks_exact(width).enumerate() {
        for j in 0..fours.div_ceil(4) {
            // SAFETY: block j's sixteen values lie within the position's `width`
            // (`16·(j + 1) ≤ 4·fours rounded up ≤ width`, asserted above).
            let (lo, hi) = unsafe {
                let at = position.as_ptr().add(j * BLOCK);
                (
                    steps_avx2(_mm256_loadu_ps(at), f, top),
                    steps_avx2(_mm256_loadu_ps(at.add(8)), f, top),
                )
            };
            // i16 lanes: channels 0–3, 8–11 | 4–7, 12–15; then their bytes, so the words of
            // the 128-bit halves are fours 0 and 2 | 1 and 3 (each in words 0, 1 and 4, 5).
            let shorts = _mm256_packs_epi32(lo, hi);
            let bytes = _mm256_packus_epi16(shorts, shorts);
            // SAFETY: `words` holds eight words.
            unsafe { _mm256_storeu_si256(words.as_mut_ptr().cast(), bytes) };
            let four = [words[0], words[4], words[1], words[5]];
            for (k, &word) in four.iter().enumerate().take(fours - 4 * j) {
                dst[(4 * j + k) * n + p] = word;
            }
        }
    }
}

/// Whether [`Conv3x3::run`] runs on this CPU, so tract leaves these layers to it: on aarch64
/// ([`Products::F32x4`]: NEON); on x86-64 with AVX2 and FMA on the native path, or with FMA on
/// the portable path (the NEON form's twin). Elsewhere (32-bit ARM, whose baseline has no fused
/// multiply-add, and x86-64 CPUs without FMA) tract keeps the layers.
pub(crate) fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    return crate::kernels::cpu::has_avx2_fma()
        || (crate::kernels::kernel_path() == crate::kernels::KernelPath::Portable
            && Products::F32x4.supported());
    #[cfg(not(target_arch = "x86_64"))]
    return Products::F32x4.supported();
}

/// One block of output channels of one batch slot. `T`: f32 values, or bf16 pairs as words
/// ([`Pairs`]).
#[cfg(target_arch = "x86_64")]
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
    /// without a pass over its input (a separate `nonnegative_max` pass took 2.5 % of `m3_per_face` on an Intel Xeon).
    peak: std::cell::Cell<[u32; BLOCK]>,
}

#[cfg(target_arch = "x86_64")]
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

#[cfg(target_arch = "x86_64")]
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

#[cfg(target_arch = "x86_64")]
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

#[cfg(target_arch = "x86_64")]
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

#[cfg(target_arch = "x86_64")]
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

#[cfg(target_arch = "x86_64")]
impl Block<'_, u32> {
    /// [`Block::run`] on int8 quads ([`Quads`]) in [`Products::Maddubs`]'s products: per quad
    /// tap two weight loads, and per position one broadcast word; each half of the block's
    /// sixteen channels takes `vpmaddubsw` (two u8 × i8 products per i16 lane), `vpmaddwd` by
    /// ones (two of those per i32 lane) and an add. The i32 sums times the channel's
    /// [`Block::scale`] plus the bias are the outputs.
    ///
    /// # Safety
    /// AVX2 + FMA; every `at_in[j] + taps[t]` lies inside `input`, whose bytes are at most the
    /// layer's [`maddubs_levels`] (so no i16 sum saturates), `weights` holds `taps.len() × BLOCK` words
    /// of bytes in −127..=127 and `bias` and `scale` `BLOCK` values.
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    #[allow(unsafe_code)]
    unsafe fn run_maddubs<const P: usize, const S: usize>(
        &self,
        at_in: &[usize],
        at_out: &[usize],
        out: &mut [f32],
    ) {
        use std::arch::x86_64::*;
        let at: [usize; P] =
            std::array::from_fn(|j| if S == 0 { at_in[j] } else { at_in[0] + S * j });
        assert!(self.scale.len() >= BLOCK && self.bias.len() >= BLOCK);
        debug_assert!(self.weights.len() >= self.taps.len() * BLOCK);
        let (x, w) = (self.input.as_ptr(), self.weights.as_ptr());
        let ones = _mm256_set1_epi16(1);
        let mut acc = [[_mm256_setzero_si256(); 2]; P];
        for (t, &tap) in self.taps.iter().enumerate() {
            // SAFETY: the caller's contract: tap offsets and weights within their buffers.
            unsafe {
                let w0 = _mm256_loadu_si256(w.add(t * BLOCK).cast());
                let w1 = _mm256_loadu_si256(w.add(t * BLOCK + 8).cast());
                for (acc, &at) in acc.iter_mut().zip(&at) {
                    debug_assert!(at + tap < self.input.len());
                    let v = _mm256_set1_epi32(*x.add(at + tap) as i32);
                    let p0 = _mm256_madd_epi16(_mm256_maddubs_epi16(v, w0), ones);
                    let p1 = _mm256_madd_epi16(_mm256_maddubs_epi16(v, w1), ones);
                    acc[0] = _mm256_add_epi32(acc[0], p0);
                    acc[1] = _mm256_add_epi32(acc[1], p1);
                }
            }
        }
        // SAFETY: `scale` and `bias` hold BLOCK values (asserted above).
        let (m, b) = unsafe {
            (
                [
                    _mm256_loadu_ps(self.scale.as_ptr()),
                    _mm256_loadu_ps(self.scale.as_ptr().add(8)),
                ],
                [
                    _mm256_loadu_ps(self.bias.as_ptr()),
                    _mm256_loadu_ps(self.bias.as_ptr().add(8)),
                ],
            )
        };
        let values: [[__m256; 2]; P] = std::array::from_fn(|j| {
            std::array::from_fn(|h| _mm256_fmadd_ps(_mm256_cvtepi32_ps(acc[j][h]), m[h], b[h]))
        });
        self.store(&values, at_out, out);
    }
}

#[cfg(target_arch = "x86_64")]
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

/// Test weights' int8 codes: 127 where `peak` (each output's largest, so its scale is exercised
/// to the full range), else a spread over −127..=127 from the weight's index `i`.
#[cfg(test)]
pub(crate) fn int8_test_code(i: usize, peak: bool) -> i32 {
    if peak {
        127
    } else {
        (i * 37 % 255) as i32 - 127
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The layer by its definition (zero padding 1, bias, ReLU), in f64, without a border; with
    /// each output the sum of the magnitudes of its terms (the scale of its rounding error).
    fn direct(
        input: &[f32],
        (cin, h, w): (usize, usize, usize),
        weights: &ConvWeights,
    ) -> Vec<(f32, f32)> {
        let s = weights.stride;
        let side = |n: usize| if n == 0 { 0 } else { (n - 1) / s + 1 };
        let (oh, ow) = (side(h), side(w));
        let cout = weights.bias.len();
        let mut out = vec![(0.0, 0.0); cout * oh * ow];
        for co in 0..cout {
            for y in 0..oh {
                for x in 0..ow {
                    let mut sum = f64::from(weights.bias[co]);
                    let mut mag = sum.abs();
                    for c in 0..cin {
                        for dy in 0..3 {
                            for dx in 0..3 {
                                let (iy, ix) =
                                    ((s * y + dy) as isize - 1, (s * x + dx) as isize - 1);
                                if iy < 0 || ix < 0 || iy >= h as isize || ix >= w as isize {
                                    continue;
                                }
                                let v = input[(c * h + iy as usize) * w + ix as usize];
                                let k = weights.kernel[((co * cin + c) * 3 + dy) * 3 + dx];
                                sum += f64::from(k) * f64::from(v);
                                mag += (f64::from(k) * f64::from(v)).abs();
                            }
                        }
                    }
                    out[(co * oh + y) * ow + x] = (sum.max(0.0) as f32, mag as f32);
                }
            }
        }
        out
    }

    /// bf16 where it was measured faster (AMD Zen 4), int8 on the other CPUs with AVX-512 VNNI
    /// (the Intel Xeon measured), 512-bit f32 on the other CPUs with AVX-512F (Intel, where bf16
    /// measured slower), 256-bit f32 elsewhere — also where the 256-bit int8 form
    /// ([`Products::Maddubs`]) would run, which is chosen by `MONOTRACK_CONV` only.
    #[test]
    fn the_policy_picks_bf16_on_amd_and_int8_or_512_bit_f32_on_other_avx512_cpus() {
        assert_eq!(products_for(true, true, true, true), Products::Bf16);
        assert_eq!(products_for(true, false, true, true), Products::Avx2);
        assert_eq!(products_for(true, false, false, false), Products::Avx2);
        assert_eq!(products_for(false, true, true, true), Products::Vnni);
        assert_eq!(products_for(false, true, true, false), Products::Avx512);
        assert_eq!(products_for(false, false, true, false), Products::Avx512);
        assert_eq!(products_for(false, false, false, false), Products::Avx2);
    }

    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn matches_the_definition_with_a_zero_border() {
        crate::kernels::cpu::assert_avx2_fma_path();
        // Strides 1 and 2, odd and even sides, a partial channel block (24 = 16 + 8), position
        // counts that leave every remainder of six (the 256-bit kernels) and of eight (the
        // 512-bit one), one, two and three blocks (40 = a pair and a partial single for the
        // 512-bit kernel), batches of one and two, borders 0, 1 and 2, and an empty map (no
        // output, no panic).
        let cases = [
            (1, 3, 8, 10, 16, 2, 1),
            (2, 5, 7, 5, 24, 2, 0),
            (1, 16, 4, 4, 32, 1, 1),
            (1, 2, 3, 11, 16, 1, 0),
            (2, 4, 6, 9, 8, 1, 2),
            (1, 2, 0, 4, 16, 2, 1),
            (1, 3, 9, 7, 48, 1, 1),
            (2, 4, 5, 5, 40, 2, 1),
            (1, 2, 13, 11, 40, 1, 0),
            (2, 3, 6, 18, 24, 2, 1),
        ];
        for (batch, cin, h, w, cout, stride, pad) in cases {
            let weights = ConvWeights {
                kernel: (0..cout * cin * 9)
                    .map(|i| ((i * 37 % 17) as f32 - 8.0) / 20.0)
                    .collect(),
                bias: (0..cout).map(|i| (i as f32 - 3.0) / 10.0).collect(),
                stride,
            };
            let maps: Vec<f32> = (0..batch * cin * h * w)
                .map(|i| (i * 53 % 29) as f32 / 29.0)
                .collect();
            // Every form the CPU has: f32 products to float rounding; bf16 ones within the
            // rounding of both factors to 8 significant bits: 2⁻⁸ of the terms' magnitude.
            for form in product_forms() {
                let mut layer = building(form, || Conv3x3::new(batch, cin, h, w, &weights, pad));
                assert_eq!(layer.is_bf16(), form.is_bf16() && cin >= 2);
                assert_eq!(
                    layer.wide,
                    matches!(form, Products::Avx512 | Products::Vnni)
                );
                let rel = if layer.is_bf16() { 2f32.powi(-8) } else { 0.0 };
                let got = run_unbordered(&mut layer, &maps, (h, w));
                let [_, _, ph, pw] = layer.output_shape();
                let plane = (ph - 2 * pad) * (pw - 2 * pad);
                for b in 0..batch {
                    let want = direct(
                        &maps[b * cin * h * w..][..cin * h * w],
                        (cin, h, w),
                        &weights,
                    );
                    for (i, &(v, mag)) in want.iter().enumerate() {
                        let g = got[b * cout * plane + i];
                        assert!(
                            (g - v).abs() <= 1e-5 + rel * mag,
                            "case {batch}x{cin}x{h}x{w}→{cout} s{stride} {form:?}: b{b} c{} p{} {g} vs {v}",
                            i / plane,
                            i % plane
                        );
                    }
                }
            }
        }
    }

    /// Runs `layer` on `maps` (`batch × cin × h × w`, no border) and returns its output's interior
    /// per batch slot, channel and position; a sentinel in the output's border shows stray
    /// writes (asserted untouched).
    fn run_unbordered(layer: &mut Conv3x3, maps: &[f32], (h, w): (usize, usize)) -> Vec<f32> {
        let mut input = vec![0.0; layer.input_len()];
        for (i, &v) in maps.iter().enumerate() {
            let (x, y, plane) = (i % w, i / w % h, i / (w * h));
            input[(plane * (h + 2) + y + 1) * (w + 2) + x + 1] = v;
        }
        let [nb, nc, ph, pw] = layer.output_shape();
        let pad = layer.out_pad;
        let mut out = vec![7.0; nb * nc * ph * pw];
        layer.run(&input, &mut out);
        let mut interior = Vec::new();
        for plane in 0..nb * nc {
            for y in 0..ph {
                for x in 0..pw {
                    let v = out[(plane * ph + y) * pw + x];
                    if (pad..ph - pad).contains(&y) && (pad..pw - pad).contains(&x) {
                        interior.push(v);
                    } else {
                        assert_eq!(v, 7.0, "border written at plane {plane} ({y},{x})");
                    }
                }
            }
        }
        interior
    }

    /// Layers whose weights are int8 times a scale per output channel run in int8 products
    /// where the CPU has AVX-512 VNNI: within half a quantisation step of the input per term of
    /// the definition (the weights are exact); the others, and inputs with a negative value,
    /// as in f32.
    #[test]
    fn int8_layers_match_the_definition_within_the_input_quantisation() {
        let forms: Vec<_> = [Products::Vnni, Products::Maddubs]
            .into_iter()
            .filter(|f| f.supported())
            .collect();
        if forms.is_empty() {
            eprintln!("skipped: this CPU has neither AVX-512 VNNI nor AVX2 + FMA");
            return;
        }
        for form in forms {
            int8_layers_match_the_definition_in(form);
        }
    }

    /// [`int8_layers_match_the_definition_within_the_input_quantisation`] in the products `form`.
    fn int8_layers_match_the_definition_in(form: Products) {
        // Partial fours of input channels (3, 5, 6), partial and double blocks, both strides,
        // remainders of eight positions, batches of one and two.
        let cases = [
            (1, 2, 8, 10, 16, 2, 1),
            (2, 5, 7, 5, 24, 2, 0),
            (1, 16, 4, 4, 32, 1, 1),
            (1, 3, 9, 7, 48, 1, 1),
            (2, 6, 5, 5, 40, 2, 1),
            (1, 8, 13, 11, 8, 1, 0),
        ];
        for (batch, cin, h, w, cout, stride, pad) in cases {
            let k = cin * 9;
            // Row co: q ∈ [−127, 127] with 127 in it, times a scale of its own.
            let kernel: Vec<f32> = (0..cout * k)
                .map(|i| {
                    let (co, t) = (i / k, i % k);
                    int8_test_code(i, t == co % k) as f32 * (0.001 + co as f32 * 1e-4)
                })
                .collect();
            let weights = ConvWeights {
                kernel,
                bias: (0..cout).map(|i| (i as f32 - 3.0) / 10.0).collect(),
                stride,
            };
            let maps: Vec<f32> = (0..batch * cin * h * w)
                .map(|i| (i * 53 % 29) as f32 / 7.0)
                .collect();
            let max = maps.iter().fold(0f32, |m, &v| m.max(v));
            let mut layer = building(form, || Conv3x3::new(batch, cin, h, w, &weights, pad));
            assert!(
                layer.is_int8(),
                "{form:?} {cin}→{cout}: int8 weights not taken as such"
            );
            let levels = layer.quads.as_ref().map_or(0, |q| q.levels) as f32;
            let got = run_unbordered(&mut layer, &maps, (h, w));
            let (oh, ow) = ((h - 1) / stride + 1, (w - 1) / stride + 1);
            for b in 0..batch {
                let want = direct(
                    &maps[b * cin * h * w..][..cin * h * w],
                    (cin, h, w),
                    &weights,
                );
                for c in 0..cout {
                    let row: f32 = weights.kernel[c * k..][..k].iter().map(|v| v.abs()).sum();
                    for p in 0..oh * ow {
                        let g = got[(b * cout + c) * oh * ow + p];
                        let (v, mag) = want[c * oh * ow + p];
                        let bound = 1e-5 + 1e-5 * mag + row * max / (2.0 * levels);
                        assert!(
                            (g - v).abs() <= bound,
                            "{form:?} {batch}x{cin}x{h}x{w}→{cout} s{stride}: b{b} c{c} p{p}: {g} vs {v} (bound {bound})"
                        );
                    }
                }
            }
            // A negative input value: u8 cannot hold it, the run goes through f32.
            let mut signed = maps.clone();
            signed[0] = -1.0;
            let got = run_unbordered(&mut layer, &signed, (h, w));
            for b in 0..batch {
                let want = direct(
                    &signed[b * cin * h * w..][..cin * h * w],
                    (cin, h, w),
                    &weights,
                );
                for (i, &(v, mag)) in want.iter().enumerate() {
                    let g = got[b * cout * oh * ow + i];
                    assert!(
                        (g - v).abs() <= 1e-5 + 1e-6 * mag,
                        "f32 fallback: {g} vs {v}"
                    );
                }
            }
        }
        // Weights that are not int8 per row stay f32.
        let weights = ConvWeights {
            kernel: (0..16 * 18).map(|i| (i as f32 * 0.37).sin()).collect(),
            bias: vec![0.0; 16],
            stride: 1,
        };
        let layer = building(form, || Conv3x3::new(1, 2, 4, 4, &weights, 1));
        assert!(!layer.is_int8());
    }

    /// A 256-bit int8 layer's inputs keep as many steps as its weights allow without an i16 sum
    /// of `vpmaddubsw` saturating: seven bits where two neighbouring channels' weights are both
    /// ±127, all eight where no pair exceeds 128; at the largest input everywhere (every pair's
    /// products at their largest) the outputs are still the definition's.
    #[test]
    fn maddubs_levels_keep_every_i16_sum_from_saturating() {
        // Channel c's weights: 127 steps, or 0 for odd channels in `sparse`.
        let kernel = |cin: usize, cout: usize, sparse: bool| -> Vec<f32> {
            (0..cout * cin * 9)
                .map(|i| {
                    let c = i / 9 % cin;
                    if sparse && c % 2 == 1 {
                        0.0
                    } else if i / 9 % 3 == 2 {
                        -0.01
                    } else {
                        0.01
                    }
                })
                .collect()
        };
        let q = |k: &[f32]| {
            k.iter()
                .map(|v| (v * 12700.0).round() as i8)
                .collect::<Vec<_>>()
        };
        assert_eq!(maddubs_levels(&q(&kernel(4, 16, false)), 16, 4), 129);
        assert_eq!(maddubs_levels(&q(&kernel(4, 16, true)), 16, 4), 255);
        // An odd channel count: the last channel pairs with nothing.
        assert_eq!(maddubs_levels(&q(&kernel(3, 16, true)), 16, 3), 255);
        if !Products::Maddubs.supported() {
            eprintln!("skipped: this CPU has no AVX2 + FMA");
            return;
        }
        let (h, w) = (6, 9);
        for (cin, sparse) in [(4, false), (8, false), (4, true), (5, false)] {
            let weights = ConvWeights {
                kernel: kernel(cin, 16, sparse),
                bias: vec![0.5; 16],
                stride: 1,
            };
            let maps = vec![1.0; cin * h * w];
            let mut layer = building(Products::Maddubs, || {
                Conv3x3::new(1, cin, h, w, &weights, 1)
            });
            assert!(layer.is_int8());
            let got = run_unbordered(&mut layer, &maps, (h, w));
            let want = direct(&maps, (cin, h, w), &weights);
            for (i, (&g, &(v, mag))) in got.iter().zip(&want).enumerate() {
                assert!(
                    (g - v).abs() <= 1e-5 + 1e-5 * mag,
                    "{cin} channels (sparse {sparse}), output {i}: {g} vs {v}"
                );
            }
        }
    }

    /// Interleaved buffers between layers change how the values are held, not the values: a
    /// chain (a one-channel f32 layer, then int8 layers) run through them gives the bits of the
    /// planar chain, and an input u8 cannot hold goes through the f32 kernel on a planar copy
    /// with the bits of the planar run.
    #[test]
    fn interleaved_buffers_give_the_bits_of_planar_ones() {
        let forms: Vec<_> = [Products::Vnni, Products::Maddubs, Products::Avx2]
            .into_iter()
            .filter(|f| f.supported())
            .collect();
        if forms.is_empty() {
            eprintln!("skipped: this CPU has neither AVX-512 VNNI nor AVX2 + FMA");
            return;
        }
        for form in forms {
            interleaved_chain_gives_the_bits_of_the_planar_one(form);
        }
    }

    /// [`interleaved_buffers_give_the_bits_of_planar_ones`] in the products `form`: int8 layers
    /// after a one-channel f32 one (which reads the image interleaved where it is a 256-bit one),
    /// or 256-bit f32 layers throughout.
    fn interleaved_chain_gives_the_bits_of_the_planar_one(form: Products) {
        // Channels 1 → 16 → 24 (a partial block) → 40 (a pair and a partial one) → 8; both
        // strides; maps whose position counts leave remainders of sixteen and eight; two slots.
        let (batch, h, w) = (2, 19, 13);
        let int8 = |cin: usize, cout: usize, stride: usize| {
            let k = 9 * cin;
            ConvWeights {
                kernel: (0..cout * k)
                    .map(|i| {
                        let (co, t) = (i / k, i % k);
                        int8_test_code(i, t == co % k) as f32 * (0.002 + co as f32 * 1e-4)
                    })
                    .collect(),
                bias: (0..cout).map(|i| (i as f32 - 5.0) / 20.0).collect(),
                stride,
            }
        };
        let first = ConvWeights {
            kernel: (0..16 * 9)
                .map(|i| ((i * 37 % 17) as f32 - 8.0) / 20.0)
                .collect(),
            bias: (0..16).map(|i| (i as f32 - 3.0) / 10.0).collect(),
            stride: 2,
        };
        let chain = [
            (1, first, 1),
            (16, int8(16, 24, 2), 1),
            (24, int8(24, 40, 1), 1),
            (40, int8(40, 8, 1), 0),
        ];
        let build = || {
            let (mut ih, mut iw) = (h, w);
            let mut layers = Vec::new();
            for (cin, weights, pad) in &chain {
                let layer = Conv3x3::new(batch, *cin, ih, iw, weights, *pad);
                (ih, iw) = (layer.out_h, layer.out_w);
                layers.push(layer);
            }
            layers
        };
        let mut planar = building(form, build);
        let mut interleaved = building(form, build);
        for i in 1..interleaved.len() {
            assert!(
                interleaved[i].takes_interleaved_input(),
                "{form:?}: layer {i} reads planes only"
            );
            interleaved[i - 1].interleave_output();
            interleaved[i].interleave_input();
        }
        // The one-channel layer takes the image's planes (int8 needs more channels).
        assert_eq!(
            interleaved[0].takes_interleaved_input(),
            matches!(form, Products::Avx2 | Products::Maddubs)
        );
        // The image, planar with its border.
        let mut image = vec![0.0; planar[0].input_len()];
        for (i, v) in image.iter_mut().enumerate() {
            let (x, y) = (i % (w + 2), i / (w + 2) % (h + 2));
            if (1..=w).contains(&x) && (1..=h).contains(&y) {
                *v = (i * 53 % 29) as f32 / 29.0;
            }
        }
        // Runs a chain from `image` as `Stem::run` does (each layer given the previous one's
        // peak), with `poison` (a layer, a position and a value) set in that layer's input first —
        // given as its peak too where it is +∞, as a layer that wrote it would report it; returns
        // each layer's output as planes.
        let run = |layers: &mut [Conv3x3], poison: Option<(usize, usize, f32)>| {
            let mut input = image.clone();
            let mut outs = Vec::new();
            let mut peak = None;
            for (i, layer) in layers.iter_mut().enumerate() {
                if let Some((_, at, v)) = poison.filter(|p| p.0 == i) {
                    input[at] = v;
                    peak = (v == f32::INFINITY).then_some(v);
                }
                let mut out = vec![0.0; layer.output_len()];
                layer.run_with(&input, peak, &mut out);
                peak = layer.output_peak();
                let planes = if layer.output_layout == Layout::Interleaved {
                    let largest = out.iter().fold(0f32, |m, &v| m.max(v));
                    assert_eq!(peak, Some(largest), "layer {i}: the peak reported");
                    let width = Conv3x3::interleaved_width(layer.cout);
                    let mut planes = vec![0.0; layer.batch * layer.cout * layer.out_plane];
                    for (slot, dst) in out
                        .chunks_exact(width * layer.out_plane)
                        .zip(planes.chunks_exact_mut(layer.cout * layer.out_plane))
                    {
                        for (p, values) in slot.chunks_exact(width).enumerate() {
                            // The channels the layout rounds up to stay zero.
                            assert!(values[layer.cout..].iter().all(|&v| v == 0.0));
                            for (c, &v) in values[..layer.cout].iter().enumerate() {
                                dst[c * layer.out_plane + p] = v;
                            }
                        }
                    }
                    planes
                } else {
                    assert_eq!(peak, None);
                    out.clone()
                };
                outs.push(planes);
                input = out;
            }
            outs
        };
        let want = run(&mut planar, None);
        let got = run(&mut interleaved, None);
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                g.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits()),
                "{form:?}, layer {i}: interleaved and planar outputs differ"
            );
        }
        // A negative or infinite value in the third layer's input (slot 1, channel 5, the
        // interior's first position): that layer runs in f32, from planes or from the interleaved
        // copy alike (an infinity then reaches the last layer's input too).
        let layer = &planar[2];
        // The input's rows are the second layer's output's, border included.
        let interior = planar[1].out_w + 2 + 1;
        let planar_at = (layer.cin + 5) * layer.in_plane + interior;
        let width = Conv3x3::interleaved_width(layer.cin);
        let interleaved_at = (layer.in_plane + interior) * width + 5;
        for v in [-1.0, f32::INFINITY] {
            let want = run(&mut planar, Some((2, planar_at, v)));
            let got = run(&mut interleaved, Some((2, interleaved_at, v)));
            assert_ne!(want[2], run(&mut planar, None)[2], "{v} changed nothing");
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    g.iter().zip(w).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "{form:?}, layer {i} after {v} in an input: interleaved and planar \
                     outputs differ"
                );
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn the_input_check_takes_only_finite_nonnegative_inputs() {
        if !Products::Vnni.supported() {
            eprintln!("skipped: this CPU has no AVX-512 VNNI");
            return;
        }
        #[allow(unsafe_code)]
        // SAFETY: the CPU has AVX-512F (VNNI implies it here: `Products::supported`).
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
