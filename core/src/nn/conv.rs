//! 3×3 convolutions with zero padding 1, stride 1 or 2, a bias and a ReLU: the layers of the M3
//! trunks and the detector's first ones ([`crate::nn::stem`] finds them in the graphs), planned
//! here and computed in the library's kernels instead of by tract ([`available`]).
//!
//! Why not tract: tract lowers each such layer to an explicit `Pad` copy of its input, a lazily
//! gathered im2col matrix and a matrix product, and the gather and copies cost more than the
//! arithmetic for layers this small. Here each layer reads the previous layer's output in place —
//! written with a zero border that is this layer's padding — and multiplies straight from it, so
//! nothing is gathered or copied.
//!
//! Which products ([`Products`]) a CPU runs, chosen once per process ([`chosen_products`]):
//!
//! | CPU | products | kernel |
//! |---|---|---|
//! | aarch64 (phones), and any x86-64 CPU on the portable path | f32 on 128-bit registers ([`Products::F32x4`]) | [`crate::kernels::conv3x3`] (NEON; its 128-bit twin on x86-64) |
//! | x86-64, AMD with AVX-512 BF16 (Zen 4) | bf16 pairs summed in f32 (`vdpbf16ps`) for layers of more than one input channel | `kernels/conv3x3/avx.rs` |
//! | x86-64, other CPUs with AVX-512 VNNI | int8 quads summed in i32 (`vpdpbusd`) for layers with int8 weights ([`Quads`]), f32 on 512-bit registers for the others | `kernels/conv3x3/avx.rs` |
//! | x86-64 with AVX2 + FMA | f32 on 256-bit registers | `kernels/conv3x3/avx.rs` |
//!
//! bf16 rounds inputs and weights to 8 significant bits and int8 rounds each layer's input to
//! u8 steps of 1/255 of its largest value (the weights are the int8 the shipped networks store);
//! what either costs in landmarks is measured end to end (`models/MODEL_CARD.md`), and what each
//! form gains is in `BENCHMARKS.md`. The x86-64 choice serves the desktop CLI and the tests; a
//! phone runs the 128-bit f32 form.
//!
//! Layout (the ONNX one, batch-major): input `batch × cin × (in_h + 2) × (in_w + 2)` with a zero
//! border of one, output `batch × cout × (out_h + 2·pad) × (out_w + 2·pad)`, only its interior
//! written. Between two layers of a chain whose second runs in int8 or in the 256-bit f32 kernel
//! the buffer is [`Layout::Interleaved`] instead: position after position, each position's
//! channels together. The first layer then stores each position's sixteen channels as they lie in
//! its registers, and the second quantises them into its own layout on the way, or (f32)
//! broadcasts each value from where it lies, so nothing is transposed or scattered value by value.
//! The values, the sums and the quantised words are the same in both layouts.

/// [`Products::whole_graph_tolerance`] of the int8 form. Each layer's input is rounded to 1/255
/// of its largest value, so a product is off by up to half of that step times its weight.
/// The shipped networks' outputs stay inside it on the tests' inputs (the detector's layers hold
/// f16 weights and stay f32). What this costs in landmarks is measured end to end
/// (`models/MODEL_CARD.md`).
#[cfg(test)]
pub(crate) const INT8_TOLERANCE: f32 = 2e-2;

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
pub(crate) const POSITIONS_512: usize = 8;

/// How a layer's products are computed (see the module notes for which CPU runs which).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Products {
    /// f32 FMAs on 256-bit registers (AVX2 + FMA).
    Avx2,
    /// bf16 pairs summed in f32 (AVX-512 BF16 + VL), for layers of more than one input channel.
    Bf16,
    /// u8 inputs times int8 weights, four products summed in an i32 lane by `vpdpbusd` (AVX-512
    /// VNNI + BW), for layers of more than one input channel whose weights are int8 times a
    /// scale per output channel ([`Quads`]); 512-bit f32 for the other layers.
    Vnni,
    /// f32 FMAs on 128-bit registers ([`crate::kernels::conv3x3`]): NEON on aarch64, what phones
    /// run; on x86-64 its twin of the same width and bits, which the portable path takes.
    F32x4,
}

/// Largest u8 step of the [`Products::Vnni`] form's inputs (`vpdpbusd` sums in i32).
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) const VNNI_LEVELS: i32 = 255;

impl Products {
    /// Whether this CPU can run the form.
    #[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
    pub(crate) fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            use crate::kernels::cpu::{Avx512, has_avx2_fma, has_avx512, has_fma};
            match self {
                Products::Avx2 => has_avx2_fma(),
                Products::Bf16 => has_avx512(Avx512::Bf16),
                Products::Vnni => has_avx512(Avx512::Vnni),
                // The twin needs FMA (without it the portable form's fused multiply-add is a
                // library call per product).
                Products::F32x4 => has_fma(),
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
            Products::Avx2 | Products::F32x4 => 1e-4,
            Products::Bf16 => crate::nn::stem::BF16_TOLERANCE,
            Products::Vnni => INT8_TOLERANCE,
        }
    }
}

/// The form for this CPU, decided once (the table in the module notes); the kernel choice's
/// `conv=FORM` ([`crate::kernels::KernelChoice`]) overrides it where the CPU has the named form.
/// bf16 on AMD only: on Intel's AVX-512 parts `vdpbf16ps` runs at half the FMA's rate. f32 on
/// 512-bit registers is no default of its own: it lost to the 256-bit form where it was measured
/// (`BENCHMARKS.md`, "What each x86-64 form earns"); the int8 form keeps it for the layers it does
/// not take.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn chosen_products() -> Products {
    static CHOSEN: std::sync::OnceLock<Products> = std::sync::OnceLock::new();
    *CHOSEN.get_or_init(|| {
        let named = crate::kernels::choice()
            .conv
            .as_deref()
            .and_then(|v| match v {
                "avx2" => Some(Products::Avx2),
                "bf16" => Some(Products::Bf16),
                "vnni" => Some(Products::Vnni),
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
        products_for(amd, Products::Bf16.supported(), Products::Vnni.supported())
    })
}

/// The policy of [`chosen_products`], from the vendor and the forms the CPU has.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
fn products_for(amd: bool, has_bf16: bool, has_vnni: bool) -> Products {
    if amd && has_bf16 {
        Products::Bf16
    } else if !amd && has_vnni {
        Products::Vnni
    } else {
        Products::Avx2
    }
}

/// Output positions computed together: with two accumulators each, twelve of the sixteen vector
/// registers (tract's x86-64 matrix kernel has the same 16 × 6 shape); in bf16 too.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) const POSITIONS: usize = 6;

/// A layer for fixed input sizes, with its weights packed for the kernel.
// Off x86-64 nothing runs the kernel ([`available`] is false there), so the packed layout is unread.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
#[derive(Debug, Clone)]
pub(crate) struct Conv3x3 {
    pub(crate) batch: usize,
    pub(crate) cin: usize,
    pub(crate) cout: usize,
    pub(crate) stride: usize,
    pub(crate) in_plane: usize,
    /// Positions per padded input row.
    pub(crate) in_row: usize,
    pub(crate) out_plane: usize,
    pub(crate) out_h: usize,
    pub(crate) out_w: usize,
    pub(crate) out_pad: usize,
    /// Per block of [`BLOCK`] output channels: for each of the `9·cin` taps (channel, row,
    /// column) the block's weights, zero past `cout`.
    pub(crate) packed: Vec<f32>,
    /// The bias, zero past `cout` up to a whole block.
    pub(crate) bias: Vec<f32>,
    /// Offset of each tap in the padded input from the window's top-left value.
    pub(crate) taps: Vec<usize>,
    /// Per output position (row-major): its window's top-left offset in a padded input plane, and
    /// its offset in an output plane.
    pub(crate) at_in: Vec<usize>,
    pub(crate) at_out: Vec<usize>,
    /// The bf16 form of the layer, where it runs in bf16 products ([`Products::Bf16`]).
    pub(crate) pairs: Option<Pairs>,
    /// The int8 form of the layer, where it runs in int8 products ([`Products::Vnni`]).
    pub(crate) quads: Option<Quads>,
    /// The form of [`crate::kernels::conv3x3`] the layer runs, where its products are
    /// [`Products::F32x4`].
    pub(crate) x4: Option<crate::kernels::conv3x3::Form>,
    /// Whether the f32 products run on 512-bit registers: [`Products::Vnni`]'s layers and runs
    /// that the int8 form does not take.
    pub(crate) wide: bool,
    /// How the input and the output are held ([`Self::interleave_input`],
    /// [`Self::interleave_output`]).
    pub(crate) input_layout: Layout,
    pub(crate) output_layout: Layout,
    /// Where the input is interleaved: the planar copy the f32 kernels read in the runs the int8
    /// form does not take.
    pub(crate) planar: Vec<f32>,
    /// Where the output is interleaved: the largest value the last run wrote (≥ 0, ReLU; may be
    /// +∞), so the next layer quantises without a pass to find it.
    pub(crate) peak: Option<f32>,
}

/// A layer in int8 products (`vpdpbusd`: four u8 × i8 products summed into an i32 lane, four
/// times the multiply-adds per instruction of an f32 FMA): the input channels taken in fours, each four's values at a position held as one
/// 32-bit word (byte `k` channel `4q + k`), so one broadcast feeds four products.
///
/// The weights are the int8 values the shipped networks store (`models/train/onnx_q8.py`: one
/// symmetric scale per output channel), so they lose nothing here. The input is quantised per
/// run: `u8 = round(v · 255 / max)` over the whole input, which holds ReLU outputs (nothing
/// negative); a run whose input has a negative or non-finite value goes through the f32 kernel.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
#[derive(Debug, Clone)]
pub(crate) struct Quads {
    /// Per block of [`BLOCK`] output channels: for each of the `9·⌈cin/4⌉` quad taps (channel
    /// four, row, column) the block's weight quads (byte `k` the weight of channel `4q + k`),
    /// zero past `cout` and past `cin`.
    pub(crate) packed: Vec<u32>,
    /// Offset of each quad tap in the quantised input from the window's top-left word.
    pub(crate) taps: Vec<usize>,
    /// Per output channel its weights' scale, zero past `cout` up to a whole block.
    pub(crate) scale: Vec<f32>,
    /// This run's factor per output channel from i32 sums to values: `scale` × the input's
    /// quantisation step.
    pub(crate) step: Vec<f32>,
    /// The input quantised: `batch × ⌈cin/4⌉` padded planes of words.
    pub(crate) input: Vec<u32>,
}

/// `w` as int8 times a scale per output (`output_of(t)` the output of value `t`, below
/// `outputs`), where every value is one to within 1e-6 of its output's largest magnitude — the
/// form `models/train/onnx_q8.py` stores; `None` otherwise. The 3×3 layers here and the fully
/// connected heads (`nn::dense`) keep their weights so.
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
pub(crate) struct Pairs {
    /// Per block of [`BLOCK`] output channels: for each of the `9·⌈cin/2⌉` pair taps (channel
    /// pair, row, column) the block's weight pairs, zero past `cout` and past `cin`.
    pub(crate) packed: Vec<u32>,
    /// Offset of each pair tap in the paired input from the window's top-left word.
    pub(crate) taps: Vec<usize>,
    /// The input rounded to bf16 and paired: `batch × ⌈cin/2⌉` padded planes of words.
    pub(crate) input: Vec<u32>,
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
        let quads = (cin >= 2 && form == Products::Vnni)
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
            wide: form == Products::Vnni,
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
    pub(crate) fn step(&self) -> usize {
        if self.input_layout == Layout::Interleaved && self.quads.is_none() {
            self.stride * Self::interleaved_width(self.cin)
        } else {
            self.stride
        }
    }

    /// Whether the layer's products are the 256-bit or the 128-bit f32 kernel's
    /// ([`Products::Avx2`], [`Products::F32x4`]).
    pub(crate) fn f32_256(&self) -> bool {
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
    pub(crate) fn interleaved_width(channels: usize) -> usize {
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
        if self.run_int8_native(input, input_peak, out) {
            return;
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
        if self.run_float_native(input, out) {
            return;
        }
        panic!("Conv3x3::run needs AVX2 and FMA, or F32x4 products (conv::available)");
    }

    /// How the output is walked: the channels per position where it is interleaved (0 for
    /// planes), the values per batch slot, and the offset from one block of channels to the next.
    pub(crate) fn output_steps(&self) -> (usize, usize, usize) {
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
}

impl Conv3x3 {
    /// Whether the layer runs in int8 products where its input allows.
    #[cfg(test)]
    pub(crate) fn is_int8(&self) -> bool {
        self.quads.is_some()
    }

    /// Whether the layer runs in bf16.
    #[cfg(test)]
    pub(crate) fn is_bf16(&self) -> bool {
        self.pairs.is_some()
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
        Products::Bf16,
        Products::Vnni,
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
/// (`nn::tail`).
pub(crate) fn f32x4_products() -> bool {
    available() && products() == Products::F32x4
}

/// Whether layers built now multiply in int8 where their weights allow ([`Products::Vnni`]):
/// also the fully connected heads' choice (`nn::dense`).
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
pub(crate) fn bf16_bits(v: f32) -> u32 {
    let bits = v.to_bits();
    (bits + 0x7fff + ((bits >> 16) & 1)) >> 16
}

/// [`nonnegative_max`] value by value.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) fn nonnegative_max_portable(v: &[f32]) -> Option<f32> {
    v.iter()
        .try_fold(0f32, |m, &x| (x.is_finite() && x >= 0.0).then(|| m.max(x)))
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

    /// bf16 on AMD CPUs with it, int8 on the other CPUs with AVX-512 VNNI, 256-bit f32 elsewhere.
    #[test]
    fn the_policy_picks_bf16_on_amd_and_int8_on_other_avx512_vnni_cpus() {
        assert_eq!(products_for(true, true, true), Products::Bf16);
        assert_eq!(products_for(true, false, true), Products::Avx2);
        assert_eq!(products_for(true, false, false), Products::Avx2);
        assert_eq!(products_for(false, true, true), Products::Vnni);
        assert_eq!(products_for(false, true, false), Products::Avx2);
        assert_eq!(products_for(false, false, false), Products::Avx2);
    }

    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn the_avx2_forms_match_the_definition_with_a_zero_border() {
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
                assert_eq!(layer.wide, form == Products::Vnni);
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
    #[cfg_attr(
        not(host_avx512_vnni),
        ignore = "this CPU runs no AVX-512 VNNI kernels"
    )]
    fn the_avx512_vnni_int8_layers_match_the_definition_within_the_input_quantisation() {
        assert!(
            Products::Vnni.supported(),
            "the AVX-512 VNNI kernels do not run here (no such CPU, or the portable path)"
        );
        int8_layers_match_the_definition_in(Products::Vnni);
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
            let levels = VNNI_LEVELS as f32;
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

    /// Interleaved buffers between layers change how the values are held, not the values: a
    /// chain (a one-channel f32 layer, then int8 layers) run through them gives the bits of the
    /// planar chain, and an input u8 cannot hold goes through the f32 kernel on a planar copy
    /// with the bits of the planar run.
    #[test]
    #[cfg_attr(not(host_avx2_fma), ignore = "this CPU runs no AVX2 + FMA kernels")]
    fn the_avx2_and_int8_interleaved_buffers_give_the_bits_of_planar_ones() {
        crate::kernels::cpu::assert_avx2_fma_path();
        let forms: Vec<_> = [Products::Vnni, Products::Avx2]
            .into_iter()
            .filter(|f| f.supported())
            .collect();
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
            form == Products::Avx2
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
}
