//! A network's first layer — an optional scalar affine of the one-channel input (`Sub`, `Mul`,
//! `Add`, `Div` by constants), a 3×3, stride-2, zero-padded convolution and a ReLU — computed here
//! instead of by tract: [`StemLayer`] finds the layer in the ONNX graph, takes its weights from it
//! and cuts it out, and [`Stem`] computes it before the rest runs (`nn::net`, `nn::fcn`). Where [`crate::nn::conv`] runs ([`crate::nn::conv::available`]: aarch64, x86-64 with AVX2 +
//! FMA), the layer goes through its kernel, and so do the plain 3×3 layers that follow it, cut
//! from the graph the same way: what comes after them then runs in `nn::dense` (M3's fully
//! connected heads) and, for the detector, in `nn::tail` where the layers multiply in the
//! 128-bit form (aarch64, x86-64's portable path), else in tract. The ONNX files stay whole: training, the Python references and `M3_IO.md` see the
//! same networks, and the tests hold the outputs to tract's run of the whole graph.
//!
//! Why: tract lowers every convolution to a matrix product over an im2col matrix; with one input
//! channel that matrix has nine rows and gathering it, not the arithmetic, is the cost
//! (`core/examples/profile_net.rs` shows it per layer), and its explicit `Pad` passes (of the
//! input, and of the first layer's output for the second layer) cost more. In the portable path the input rows are split into
//! even and odd columns so every tap is a contiguous run, each output block keeps its nine taps in
//! registers for all channels, and the output is written straight into the second layer's padded
//! input (its border stays zero), so tract's second convolution pads nothing.

use crate::nn::conv::{Conv3x3, ConvWeights};
use crate::nn::onnx::pb::{AttributeProto, ModelProto, NodeProto, TensorProto};
use tract_core::internal::*;

/// The first layer of one network and its buffers. Shapes: input `batch × in_h × in_w` (what the
/// network's image input held), output `batch × channels × (out_h + 2·pad) × (out_w + 2·pad)`.
#[derive(Debug, Clone)]
pub(crate) struct Stem {
    batch: usize,
    channels: usize,
    in_h: usize,
    in_w: usize,
    out_h: usize,
    out_w: usize,
    /// Border of zeros around each plane the first layer writes: the second layer's padding.
    pad: usize,
    /// The 3×3 layers after the first one computed here too ([`crate::nn::conv`]; empty where tract
    /// computes them), each with the buffer of its input: the previous layer's output.
    layers: Vec<(Conv3x3, Vec<f32>)>,
    /// How the layer itself is computed, with that path's weights and buffers.
    first: First,
    /// The input affine `v · scale + shift`, applied before the zero padding.
    scale: f32,
    shift: f32,
    /// The network input as the caller filled it.
    input: Vec<f32>,
}

/// The two ways of computing the first layer.
#[derive(Debug, Clone)]
enum First {
    /// Where [`crate::nn::conv::available`]: a [`Conv3x3`] of one input channel, with its
    /// zero-bordered input.
    Direct(Box<Conv3x3>, Vec<f32>),
    /// The portable path ([`first_lanes`]).
    Lanes {
        /// Per channel: the 3×3 kernel row by row, then the bias.
        weights: Vec<[f32; 10]>,
        /// The zero-padded input's `in_h + 2` rows split into even and odd columns, each row
        /// `out_w` rounded up to [`LANES`], plus one, long.
        even: Vec<f32>,
        odd: Vec<f32>,
    },
}

impl Stem {
    /// A stem for a `batch × 1 × in_h × in_w` input with `layer`'s weights, writing planes with
    /// its zero border.
    pub(crate) fn new(batch: usize, in_h: usize, in_w: usize, layer: &StemWeights) -> Self {
        Self::with_path(batch, in_h, in_w, layer, crate::nn::conv::available())
    }

    /// [`Self::new`], the first layer through [`Conv3x3`] if `direct`, else the lane loop.
    fn with_path(
        batch: usize,
        in_h: usize,
        in_w: usize,
        layer: &StemWeights,
        direct: bool,
    ) -> Self {
        let (kernel, bias) = (&layer.kernel, &layer.bias);
        // With layers after it, the first writes their padding (1); the last writes the next's.
        let pad = if layer.chain.is_empty() {
            layer.next_pad
        } else {
            1
        };
        let channels = bias.len();
        debug_assert_eq!(kernel.len(), 9 * channels);
        // ONNX output size of a 3×3 kernel, stride 2, padding 1: ⌊(n + 2 − 3) / 2⌋ + 1.
        let (out_h, out_w) = (in_h.div_ceil(2), in_w.div_ceil(2));
        let mut layers: Vec<(Conv3x3, Vec<f32>)> = Vec::new();
        let (mut cin, mut h, mut w) = (channels, out_h, out_w);
        for (i, weights) in layer.chain.iter().enumerate() {
            let last = i + 1 == layer.chain.len();
            let out_pad = if last { layer.next_pad } else { 1 };
            let conv = Conv3x3::new(batch, cin, h, w, weights, out_pad);
            let [_, c, ph, pw] = conv.output_shape();
            (cin, h, w) = (c, ph - 2 * out_pad, pw - 2 * out_pad);
            // The input buffer once its layout is known (below).
            layers.push((conv, Vec::new()));
        }
        let mut first = if direct {
            let weights = ConvWeights {
                kernel: kernel.clone(),
                bias: bias.clone(),
                stride: 2,
            };
            let conv = Conv3x3::new(batch, 1, in_h, in_w, &weights, pad);
            let input = vec![0.0; conv.input_len()];
            First::Direct(Box::new(conv), input)
        } else {
            let row = out_w.next_multiple_of(LANES) + 1;
            First::Lanes {
                weights: kernel
                    .chunks_exact(9)
                    .zip(bias)
                    .map(|(k, &b)| std::array::from_fn(|i| if i < 9 { k[i] } else { b }))
                    .collect(),
                even: vec![0.0; (in_h + 2) * row],
                odd: vec![0.0; (in_h + 2) * row],
            }
        };
        // A layer that quantises its input reads it interleaved, so the layer before it stores
        // each position's channels as they lie in its registers (`crate::nn::conv::Layout`).
        for i in 0..layers.len() {
            if !layers[i].0.takes_interleaved_input() {
                continue;
            }
            match (i, &mut first) {
                (0, First::Direct(conv, _)) => conv.interleave_output(),
                (0, First::Lanes { .. }) => continue,
                _ => layers[i - 1].0.interleave_output(),
            }
            layers[i].0.interleave_input();
        }
        for (conv, input) in &mut layers {
            *input = vec![0.0; conv.input_len()];
        }
        Self {
            batch,
            channels,
            in_h,
            in_w,
            out_h,
            out_w,
            pad,
            layers,
            first,
            scale: layer.scale,
            shift: layer.shift,
            input: vec![0.0; batch * in_h * in_w],
        }
    }

    /// The shape of the output: the input of the first layer tract computes.
    pub(crate) fn output_shape(&self) -> [usize; 4] {
        if let Some((last, _)) = self.layers.last() {
            return last.output_shape();
        }
        let p = 2 * self.pad;
        [self.batch, self.channels, self.out_h + p, self.out_w + p]
    }

    /// Computes the first layer and the layers after it held here on the current input into the
    /// interior of `out` (of [`Self::output_shape`]; its border is left as it is, zero).
    pub(crate) fn run(&mut self, out: &mut [f32]) {
        let mut layers = std::mem::take(&mut self.layers);
        // Each layer writes all of the next one's input (its interior; the border stays zero),
        // so the largest value it wrote is that input's.
        let mut peak = match layers.first_mut() {
            Some((_, input)) => self.first(input),
            None => self.first(out),
        };
        for i in 0..layers.len() {
            let (done, rest) = layers.split_at_mut(i + 1);
            let (conv, input) = &mut done[i];
            match rest.first_mut() {
                Some((_, next)) => conv.run_with(input, peak, next),
                None => conv.run_with(input, peak, out),
            }
            peak = conv.output_peak();
        }
        self.layers = layers;
    }

    /// Computes the first layer on the current input into the interior of `out` (the planes
    /// with their border `pad`, which is left as it is, zero); where it wrote `out` interleaved,
    /// returns the largest value it wrote ([`Conv3x3::output_peak`]).
    fn first(&mut self, out: &mut [f32]) -> Option<f32> {
        let (conv, padded) = match &mut self.first {
            First::Direct(conv, padded) => (conv, padded),
            First::Lanes { weights, even, odd } => {
                let dims = [self.in_h, self.in_w, self.out_h, self.out_w, self.pad];
                let affine = (self.scale, self.shift);
                first_lanes(dims, affine, &self.input, weights, [even, odd], out);
                return None;
            }
        };
        let (h, w, a, c) = (self.in_h, self.in_w, self.scale, self.shift);
        for (image, plane) in self
            .input
            .chunks_exact(h * w)
            .zip(padded.chunks_exact_mut((h + 2) * (w + 2)))
        {
            // The affine applies to the pixels; the border stays zero (the padding).
            for (src, dst) in image
                .chunks_exact(w)
                .zip(plane.chunks_exact_mut(w + 2).skip(1))
            {
                for (d, &v) in dst[1..=w].iter_mut().zip(src) {
                    *d = v * a + c;
                }
            }
        }
        conv.run(padded, out);
        conv.output_peak()
    }

    /// Makes the last layer write its output interleaved ([`crate::nn::conv::Layout::Interleaved`]:
    /// position after position, the channels rounded up to a whole block), for a reader that
    /// takes it so (`nn::tail`); false, changing nothing, where the last layer is the lane
    /// loop, which writes planes only.
    pub(crate) fn interleave_output(&mut self) -> bool {
        match (self.layers.last_mut(), &mut self.first) {
            (Some((conv, _)), _) => conv.interleave_output(),
            (None, First::Direct(conv, _)) => conv.interleave_output(),
            (None, First::Lanes { .. }) => return false,
        }
        true
    }

    /// The length of the output [`Self::run`] writes: [`Self::output_shape`]'s, with the
    /// channels rounded up to a whole block where [`Self::interleave_output`] was called.
    pub(crate) fn output_len(&self) -> usize {
        match (self.layers.last(), &self.first) {
            (Some((conv, _)), _) => conv.output_len(),
            (None, First::Direct(conv, _)) => conv.output_len(),
            (None, First::Lanes { .. }) => self.output_shape().iter().product(),
        }
    }

    /// How many layers after the first one run here.
    #[cfg(test)]
    pub(crate) fn layers_after_first(&self) -> usize {
        self.layers.len()
    }

    /// The network input, `batch × in_h × in_w`, for the caller to fill.
    pub(crate) fn input_mut(&mut self) -> &mut [f32] {
        &mut self.input
    }
}

/// [`Stem::first`] in lanes of output positions ([`First::Lanes`]): the input rows split into
/// even and odd columns, so each tap is a contiguous run. `dims`: the stem's `in_h`, `in_w`,
/// `out_h`, `out_w` and `pad`; `affine`: its `scale` and `shift`.
fn first_lanes(
    [h, w, oh, ow, p]: [usize; 5],
    (a, c): (f32, f32),
    input: &[f32],
    weights: &[[f32; 10]],
    [even, odd]: [&mut [f32]; 2],
    out: &mut [f32],
) {
    let channels = weights.len();
    let (pw, plane) = (ow + 2 * p, (oh + 2 * p) * (ow + 2 * p));
    let ew = ow.next_multiple_of(LANES) + 1;
    for (b, image) in input.chunks_exact(h * w).enumerate() {
        // Padded row r (image row r − 1) into its even and odd columns: padded column 2j is
        // image column 2j − 1, padded column 2j + 1 is image column 2j. Zeros elsewhere: the
        // padding, and the lanes past the row's end.
        even.fill(0.0);
        odd.fill(0.0);
        for (r, src) in image.chunks_exact(w).enumerate() {
            let (e, o) = (
                &mut even[(r + 1) * ew..][..ew],
                &mut odd[(r + 1) * ew..][..ew],
            );
            for (d, &v) in e[1..].iter_mut().zip(src.iter().skip(1).step_by(2)) {
                *d = v * a + c;
            }
            for (d, &v) in o.iter_mut().zip(src.iter().step_by(2)) {
                *d = v * a + c;
            }
        }
        let out_b = &mut out[b * channels * plane..][..channels * plane];
        for y in 0..oh {
            for x0 in (0..ow).step_by(LANES) {
                // The nine taps of LANES outputs, loaded once for every channel.
                let taps: [[f32; LANES]; 9] = std::array::from_fn(|k| {
                    let (dy, dx) = (k / 3, k % 3);
                    let row = (2 * y + dy) * ew;
                    let (src, at) = match dx {
                        0 => (&*even, row + x0),
                        1 => (&*odd, row + x0),
                        _ => (&*even, row + x0 + 1),
                    };
                    std::array::from_fn(|l| src[at + l])
                });
                let at = (y + p) * pw + p + x0;
                let n = LANES.min(ow - x0);
                let groups = weights.chunks_exact(GROUP);
                let rest = groups.remainder();
                let mut planes = out_b.chunks_exact_mut(GROUP * plane);
                for (wg, dst) in groups.zip(&mut planes) {
                    block::<GROUP>(wg, &taps, dst, plane, at, n);
                }
                let rest_out = planes.into_remainder();
                for (wt, dst) in rest.chunks_exact(1).zip(rest_out.chunks_exact_mut(plane)) {
                    block::<1>(wt, &taps, dst, plane, at, n);
                }
            }
        }
    }
}

/// Outputs computed together: one AVX2 register of f32.
const LANES: usize = 8;

/// Channels computed together: independent sums the CPU overlaps, where one channel's nine
/// dependent additions serialise.
const GROUP: usize = 4;

/// `G` channels of one output block: each channel's bias plus its nine taps in kernel order (so
/// every output is the same sum in the same order whatever `G`), ReLU, written at `at` of each
/// channel's plane in `dst` (`n` ≤ [`LANES`] outputs).
#[inline(always)]
fn block<const G: usize>(
    weights: &[[f32; 10]],
    taps: &[[f32; LANES]; 9],
    dst: &mut [f32],
    plane: usize,
    at: usize,
    n: usize,
) {
    let mut acc: [[f32; LANES]; G] = std::array::from_fn(|c| [weights[c][9]; LANES]);
    for (k, tap) in taps.iter().enumerate() {
        for (acc, wt) in acc.iter_mut().zip(weights) {
            for (a, &t) in acc.iter_mut().zip(tap) {
                *a += wt[k] * t;
            }
        }
    }
    for (acc, dst) in acc.iter().zip(dst.chunks_exact_mut(plane)) {
        for (d, &a) in dst[at..at + n].iter_mut().zip(acc) {
            *d = a.max(0.0);
        }
    }
}

/// The weights of a first layer as [`Stem`] runs them.
#[derive(Debug, Clone)]
pub(crate) struct StemWeights {
    /// `channels × 9`, each kernel row by row.
    pub(crate) kernel: Vec<f32>,
    pub(crate) bias: Vec<f32>,
    /// The input affine before the convolution: `v · scale + shift`.
    pub(crate) scale: f32,
    pub(crate) shift: f32,
    /// The 3×3 layers after the first one that run here too ([`crate::nn::conv`]), in order.
    pub(crate) chain: Vec<ConvWeights>,
    /// The padding of the convolution after the layers taken (0 for another node), now the
    /// border of the last one's output.
    pub(crate) next_pad: usize,
}

impl StemWeights {
    /// Finds the first layer of `proto` ([`StemLayer::find`], inputs of `shapes`) — and, where
    /// [`crate::nn::conv::available`], the 3×3 layers after it — takes their weights and cuts them
    /// from the graph; `None` (and `proto` untouched) when the first layer has another form.
    pub(crate) fn split_from(
        proto: &mut ModelProto,
        shapes: &[Vec<usize>],
    ) -> TractResult<Option<Self>> {
        let Some(layer) = StemLayer::find(proto, shapes, crate::nn::conv::available()) else {
            return Ok(None);
        };
        let weights = layer.weights(proto)?;
        layer.cut(proto);
        Ok(Some(weights))
    }
}

/// Calls `f` with the values of the f32 tensor `t`, which the caller holds alone between runs (a
/// plan state drops its references to its inputs after each run), so `make_mut` copies nothing.
pub(crate) fn with_f32_slice(
    t: &mut std::sync::Arc<Tensor>,
    f: impl FnOnce(&mut [f32]),
) -> TractResult<()> {
    let t = std::sync::Arc::make_mut(t);
    f(t.try_as_plain_ram_mut()?.as_slice_mut::<f32>()?);
    Ok(())
}

/// A first layer [`Stem`] can compute, as found in an ONNX graph: the graph's first input
/// (`batch × 1 × h × w`) feeds only a chain of `Sub` / `Mul` / `Add` / `Div` by scalar constants
/// (possibly empty), which feeds only a 3×3, stride-2, padding-1 `Conv` with a bias, whose output
/// feeds only a ReLU (`Relu`, or `LeakyRelu` with α = 0), whose output feeds only a `Conv` with the
/// same padding on every side. When asked, also the chain of layers after it that
/// [`crate::nn::conv`] computes: a 3×3, stride 1 or 2, padding-1 `Conv` (group 1) with a bias on the
/// previous ReLU's output alone, feeding only a ReLU; the node after the chain is then a `Conv`
/// with the same padding on every side or a node without padding.
#[derive(Debug)]
pub(crate) struct StemLayer {
    /// Indices of the affine nodes, the convolutions and the ReLUs (the nodes cut).
    cut: Vec<usize>,
    conv: usize,
    /// The chain's convolutions and their strides.
    chain: Vec<(usize, usize)>,
    next: usize,
    next_pad: usize,
    scale: f32,
    shift: f32,
}

/// The attribute `name` of `node`.
pub(crate) fn attr<'a>(node: &'a NodeProto, name: &str) -> Option<&'a AttributeProto> {
    node.attribute.iter().find(|a| a.name == name)
}

fn ints_or<'a>(node: &'a NodeProto, name: &str, default: &'a [i64]) -> &'a [i64] {
    attr(node, name).map_or(default, |a| &a.ints)
}

/// Whether `node` is a ReLU: `Relu`, or `LeakyRelu` with α = 0 (the form
/// `models/train/onnx_tract.py` writes).
pub(crate) fn is_relu(node: &NodeProto) -> bool {
    node.op_type == "Relu"
        || (node.op_type == "LeakyRelu" && attr(node, "alpha").is_some_and(|a| a.f == 0.0))
}

/// The weights `names` of `proto` as float32 tensors: the layers run outside tract read them
/// whatever storage the graph gives them (int8 with `DequantizeLinear`, float16 with `Cast`).
pub(crate) fn values_by_name(proto: &ModelProto, names: &[&str]) -> TractResult<TVec<TValue>> {
    let Some(graph) = proto.graph.as_ref() else {
        tract_core::internal::bail!("no graph");
    };
    let constants = crate::nn::onnx::constants(graph)?;
    names
        .iter()
        .map(|n| {
            let t = constants
                .get(*n)
                .ok_or_else(|| tract_core::internal::format_err!("{n} is not a weight"))?;
            Ok(t.cast_to::<f32>()?.into_owned().into_tvalue())
        })
        .collect()
}

/// Whether `node` is a `Conv` with explicit (not automatic) padding, group 1 and dilation 1.
fn plain_conv(node: &NodeProto) -> bool {
    node.op_type == "Conv"
        && attr(node, "auto_pad").is_none_or(|a| a.s.is_empty() || a.s == b"NOTSET")
        && attr(node, "group").is_none_or(|a| a.i == 1)
        && ints_or(node, "dilations", &[1, 1]) == [1, 1]
}

/// The value of a one-element float32 tensor.
fn scalar(t: &TensorProto) -> Option<f32> {
    const FLOAT: i32 = 1;
    if t.data_type != FLOAT || t.dims.iter().product::<i64>() != 1 {
        return None;
    }
    match (t.float_data.as_slice(), t.raw_data.as_slice()) {
        ([v], _) => Some(*v),
        ([], raw) => Some(f32::from_le_bytes(raw.try_into().ok()?)),
        _ => None,
    }
}

impl StemLayer {
    /// The first layer of `proto` if it has the stem's form, for inputs of `shapes` (the graph's
    /// inputs, in order; the first `batch × 1 × h × w`), with the chain after it if `chain`.
    pub(crate) fn find(proto: &ModelProto, shapes: &[Vec<usize>], chain: bool) -> Option<Self> {
        let graph = proto.graph.as_ref()?;
        if graph.input.len() != shapes.len() {
            return None;
        }
        if !matches!(shapes.first()?.as_slice(), [_, 1, h, w] if *h > 0 && *w > 0) {
            return None;
        }
        let is_output = |name: &str| graph.output.iter().any(|o| o.name == name);
        // The one node reading `name` (and `name` no graph output).
        let only_reader = |name: &str| {
            let mut readers = graph
                .node
                .iter()
                .enumerate()
                .filter(|(_, n)| n.input.iter().any(|i| i == name));
            let first = readers.next();
            if readers.next().is_some() || is_output(name) {
                None
            } else {
                first
            }
        };
        // A scalar constant by name: an initializer or a `Constant` node's value.
        let constant = |name: &str| {
            if let Some(t) = graph.initializer.iter().find(|t| t.name == name) {
                return scalar(t);
            }
            let node = graph
                .node
                .iter()
                .find(|n| n.op_type == "Constant" && n.output.iter().any(|o| o == name))?;
            match (attr(node, "value"), attr(node, "value_float")) {
                (Some(a), _) => scalar(a.t.as_ref()?),
                (None, Some(a)) => Some(a.f),
                _ => None,
            }
        };
        let (mut scale, mut shift) = (1f32, 0f32);
        let mut cut = Vec::new();
        let mut value = graph.input.first()?.name.as_str();
        let (conv, c) = loop {
            let (i, n) = only_reader(value)?;
            if n.op_type == "Conv" {
                break (i, n);
            }
            if n.input.len() != 2 || n.input[0] != value || n.output.len() != 1 {
                return None;
            }
            let k = constant(&n.input[1])?;
            match n.op_type.as_str() {
                "Sub" => shift -= k,
                "Add" => shift += k,
                "Mul" => (scale, shift) = (scale * k, shift * k),
                "Div" => (scale, shift) = (scale / k, shift / k),
                _ => return None,
            }
            cut.push(i);
            value = &n.output[0];
        };
        if !(plain_conv(c)
            && c.input.len() == 3
            && c.input[0] == value
            && ints_or(c, "kernel_shape", &[]) == [3, 3]
            && ints_or(c, "strides", &[1, 1]) == [2, 2]
            && ints_or(c, "pads", &[0; 4]) == [1, 1, 1, 1]
            && c.output.len() == 1)
        {
            return None;
        }
        // The ReLU reading a convolution's output alone, and its output.
        let relu_of = |conv: &NodeProto| {
            let (i, r) = only_reader(conv.output.first()?)?;
            (is_relu(r) && r.output.len() == 1).then_some((i, r.output[0].as_str()))
        };
        // A 3×3, padding-1 convolution with a bias on `value` alone: its stride.
        let conv_3x3 = |n: &NodeProto, value: &str, strides: &[&[i64]]| {
            (plain_conv(n)
                && n.input.len() == 3
                && n.input[0] == value
                && ints_or(n, "kernel_shape", &[]) == [3, 3]
                && ints_or(n, "pads", &[0; 4]) == [1, 1, 1, 1]
                && n.output.len() == 1)
                .then(|| {
                    strides
                        .iter()
                        .position(|s| ints_or(n, "strides", &[1, 1]) == *s)
                })
                .flatten()
        };
        conv_3x3(c, value, &[&[2, 2]])?;
        let (relu, mut value) = relu_of(c)?;
        cut.extend([conv, relu]);
        let mut layers = Vec::new();
        let (mut next, mut n) = only_reader(value)?;
        while let (true, Some(stride), Some((relu, out))) =
            (chain, conv_3x3(n, value, &[&[1, 1], &[2, 2]]), relu_of(n))
        {
            layers.push((next, stride + 1));
            cut.extend([next, relu]);
            value = out;
            (next, n) = only_reader(value)?;
        }
        // After the first layer alone, a convolution (whose zero padding the stem writes as its
        // border); after a chain, also a node that pads nothing (a pooling's padding is no zero
        // border).
        let pads = ints_or(n, "pads", &[0; 4]);
        let is_conv = n.op_type == "Conv"
            && attr(n, "auto_pad").is_none_or(|a| a.s.is_empty() || a.s == b"NOTSET")
            && pads.len() == 4
            && pads.iter().all(|&p| p == pads[0]);
        let pads_nothing = attr(n, "pads").is_none() && attr(n, "auto_pad").is_none();
        if n.input.first().map(String::as_str) != Some(value)
            || !(is_conv || (pads_nothing && !layers.is_empty()))
        {
            return None;
        }
        let next_pad = if is_conv {
            usize::try_from(pads[0]).ok()?
        } else {
            0
        };
        (scale.is_finite() && shift.is_finite()).then_some(Self {
            cut,
            conv,
            chain: layers,
            next,
            next_pad,
            scale,
            shift,
        })
    }

    /// The layer's weights, the kernel and bias as tract computes them from the graph (so any
    /// storage of them tract reads — int8 with `DequantizeLinear`, float16 with `Cast` — works).
    fn weights(&self, proto: &ModelProto) -> TractResult<StemWeights> {
        let Some(graph) = proto.graph.as_ref() else {
            tract_core::internal::bail!("no graph");
        };
        let convs: Vec<&NodeProto> = std::iter::once(self.conv)
            .chain(self.chain.iter().map(|&(i, _)| i))
            .map(|i| &graph.node[i])
            .collect();
        let names: Vec<&str> = convs
            .iter()
            .flat_map(|c| [c.input[1].as_str(), c.input[2].as_str()])
            .collect();
        let out = values_by_name(proto, &names)?;
        let values = |t: &TValue| -> TractResult<Vec<f32>> {
            Ok(t.try_as_plain_ram()?.as_slice::<f32>()?.to_vec())
        };
        // Each layer's kernel `cout × cin × 3 × 3` (cin 1, then the previous cout) and bias.
        let mut cin = 1;
        let mut layers = Vec::with_capacity(convs.len());
        for (kernel, bias) in out.chunks_exact(2).map(|kb| (&kb[0], &kb[1])) {
            let cout = bias.len();
            if kernel.shape() != [cout, cin, 3, 3] || bias.rank() != 1 {
                tract_core::internal::bail!(
                    "layer {}: kernel {:?} and bias {:?}",
                    layers.len() + 1,
                    kernel.shape(),
                    bias.shape()
                );
            }
            layers.push((values(kernel)?, values(bias)?));
            cin = cout;
        }
        let mut layers = layers.into_iter();
        let Some((kernel, bias)) = layers.next() else {
            tract_core::internal::bail!("no first layer");
        };
        Ok(StemWeights {
            kernel,
            bias,
            chain: layers
                .zip(&self.chain)
                .map(|((kernel, bias), &(_, stride))| ConvWeights {
                    kernel,
                    bias,
                    stride,
                })
                .collect(),
            scale: self.scale,
            shift: self.shift,
            next_pad: self.next_pad,
        })
    }

    /// Removes the layers from the graph: the node after them reads the graph input, which will
    /// hold their output with its padding, so a convolution there pads nothing.
    fn cut(&self, proto: &mut ModelProto) {
        let Some(graph) = proto.graph.as_mut() else {
            return;
        };
        let input = graph.input[0].name.clone();
        let next = &mut graph.node[self.next];
        next.input[0] = input;
        for a in next.attribute.iter_mut().filter(|a| a.name == "pads") {
            a.ints.iter_mut().for_each(|p| *p = 0);
        }
        let mut cut = self.cut.clone();
        cut.sort_unstable();
        for &i in cut.iter().rev() {
            graph.node.remove(i);
        }
    }
}

/// Asserts that `got` equals `want` (a network's output as tract computes it for the whole graph)
/// to float rounding: within 1e-4 of the largest |value| of `want` (at least 1) — or, with
/// `bf16` (the layers here ran in bf16 products, `conv`), within [`BF16_TOLERANCE`] of it. For
/// the tests that hold networks run with a [`Stem`] to their whole-graph outputs.
#[cfg(test)]
pub(crate) fn assert_close_to_whole_graph(
    what: &str,
    got: &[f32],
    want: &[f32],
    form: crate::nn::conv::Products,
) {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    let scale = want.iter().fold(1f32, |m, v| m.max(v.abs()));
    let tol = form.whole_graph_tolerance();
    let worst = got
        .iter()
        .zip(want)
        .fold(0f32, |m, (x, y)| m.max((x - y).abs() / scale));
    assert!(worst <= tol, "{what} ({form:?}): {worst} of the scale");
}

/// How far a network whose 3×3 layers ran in bf16 products may be from tract's f32 run, as a
/// share of its largest output (at least 1). bf16 keeps 8 significant bits, so each product is
/// off by up to 2⁻⁸ ≈ 4e-3 of itself, and the errors mostly cancel in the sums: measured on the
/// shipped networks (the tests' inputs) up to 3.4e-3 for every output. What this costs in
/// landmarks is measured end to end (`models/MODEL_CARD.md`); the golden tests hold the pipeline
/// to the Python reference.
#[cfg(test)]
pub(crate) const BF16_TOLERANCE: f32 = 2e-2;

#[cfg(test)]
mod tests {
    use super::*;

    /// The layer by its definition: zero padding 1, stride 2, bias, ReLU.
    fn direct(
        input: &[f32],
        h: usize,
        w: usize,
        kernel: &[f32],
        bias: &[f32],
    ) -> Vec<Vec<Vec<f32>>> {
        let (oh, ow) = (h.div_ceil(2), w.div_ceil(2));
        let at = |y: isize, x: isize| {
            if y < 0 || x < 0 || y >= h as isize || x >= w as isize {
                0.0
            } else {
                f64::from(input[y as usize * w + x as usize])
            }
        };
        (0..bias.len())
            .map(|c| {
                (0..oh)
                    .map(|y| {
                        (0..ow)
                            .map(|x| {
                                let mut s = f64::from(bias[c]);
                                for dy in 0..3 {
                                    for dx in 0..3 {
                                        s += f64::from(kernel[9 * c + 3 * dy + dx])
                                            * at(
                                                2 * y as isize + dy as isize - 1,
                                                2 * x as isize + dx as isize - 1,
                                            );
                                    }
                                }
                                s.max(0.0) as f32
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn matches_the_definition_with_a_zero_border() {
        // Even and odd sides, one and two batch slots, border 0 and 1.
        for &(batch, h, w, pad) in &[(1, 8, 10, 1), (2, 7, 5, 1), (1, 6, 6, 0), (2, 3, 4, 2)] {
            // Six channels: one block of GROUP = 4 and two single ones.
            let channels = 6;
            let kernel: Vec<f32> = (0..9 * channels)
                .map(|i| ((i * 37 % 17) as f32 - 8.0) / 10.0)
                .collect();
            let bias = [0.1, -0.3, 0.0, 0.2, -0.1, 0.05];
            let weights = StemWeights {
                kernel: kernel.clone(),
                bias: bias.to_vec(),
                chain: Vec::new(),
                scale: 2.0,
                shift: -0.5,
                next_pad: pad,
            };
            for mut stem in [
                Stem::new(batch, h, w, &weights),
                Stem::with_path(batch, h, w, &weights, false),
            ] {
                let images: Vec<f32> = (0..batch * h * w)
                    .map(|i| (i * 53 % 29) as f32 / 29.0)
                    .collect();
                stem.input_mut().copy_from_slice(&images);
                let [nb, nc, ph, pw] = stem.output_shape();
                assert_eq!([nb, nc], [batch, channels]);
                // A sentinel border shows any write outside the interior.
                let mut out = vec![7.0; nb * nc * ph * pw];
                stem.run(&mut out);
                let (oh, ow) = (ph - 2 * pad, pw - 2 * pad);
                for b in 0..batch {
                    // The affine applies to the pixels, before the zero padding.
                    let affine: Vec<f32> = images[b * h * w..][..h * w]
                        .iter()
                        .map(|v| v * 2.0 - 0.5)
                        .collect();
                    let want = direct(&affine, h, w, &kernel, &bias);
                    for c in 0..channels {
                        let plane = &out[(b * nc + c) * ph * pw..][..ph * pw];
                        for y in 0..ph {
                            for x in 0..pw {
                                let got = plane[y * pw + x];
                                let inside =
                                    (pad..pad + oh).contains(&y) && (pad..pad + ow).contains(&x);
                                if inside {
                                    let v = want[c][y - pad][x - pad];
                                    assert!(
                                        (got - v).abs() < 1e-5,
                                        "b{b} c{c} ({y},{x}): {got} vs {v}"
                                    );
                                } else {
                                    assert_eq!(got, 7.0, "border written at b{b} c{c} ({y},{x})");
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}
