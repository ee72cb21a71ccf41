//! What follows the detector's first layers — its depthwise and pointwise blocks and its 3×3
//! heads — computed in the 128-bit f32 kernels ([`crate::kernels::conv3x3`]) where the 3×3
//! layers run in them ([`crate::nn::conv::f32x4_products`]: aarch64, and x86-64's portable path), so
//! a phone runs the whole detector outside tract.
//!
//! Why: on the phone's path tract ran these layers through its generic depthwise loop and gave
//! every operator output a new tensor on each run; and with M3 already outside tract, they were
//! the only frame work left in tract-core, whose speed depends on building it for speed (the
//! `release-small` profile builds it for size).
//!
//! What the graph may hold after the first layers were cut (`crate::nn::stem`): `Conv` nodes with a
//! bias, group 1 with a 3×3 kernel (stride 1 or 2, padding 1) or a 1×1 kernel (stride 1, padding
//! 0), or depthwise (group = channels, 3×3, stride 1 or 2, padding 1); each followed by a ReLU
//! (`Relu`, `LeakyRelu` with α = 0) that is its only reader, except the graph's outputs, which are
//! 3×3 convolutions read by nothing; and the nodes that make weights. Anything else leaves the
//! graph to tract.
//!
//! Layout: every value between layers is held interleaved — position after position, each
//! position's channels together, rounded up to a whole block of sixteen (the extra channels zero)
//! — with a zero border of one position, the padding of the 3×3 layers that read it; the outputs
//! are planes without a border, as tract gives them (`1 × channels × rows × columns`).

use crate::kernels::conv3x3::{Depthwise, Form, FullLayer, POSITIONS};
use crate::nn::conv::{BLOCK, pack};
use crate::nn::onnx::pb::{ModelProto, NodeProto};
use crate::nn::stem::{attr, is_relu, values_by_name};
use tract_core::internal::*;

/// The kinds of layer the tail computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// One 3×3 kernel per channel.
    Depthwise,
    /// A 1×1 kernel, group 1.
    Pointwise,
    /// A 3×3 kernel, group 1.
    Full,
}

/// One layer as read from the graph.
#[derive(Debug, Clone)]
struct LayerWeights {
    kind: Kind,
    /// Value read and value written (0 is the tail's input).
    src: usize,
    dst: usize,
    cin: usize,
    cout: usize,
    stride: usize,
    /// As ONNX stores it: `cout × (cin, or 1 for depthwise) × k × k`.
    kernel: Vec<f32>,
    bias: Vec<f32>,
    relu: bool,
}

/// The tail of the detector as read from its graph, for any input size.
#[derive(Debug, Clone)]
pub(crate) struct TailWeights {
    layers: Vec<LayerWeights>,
    /// Channels of each value.
    channels: Vec<usize>,
    /// The value of each graph output, in the graph's order.
    outputs: Vec<usize>,
}

/// The ints attribute `name` of `node`.
fn ints(node: &NodeProto, name: &str) -> Option<Vec<i64>> {
    attr(node, name).map(|a| a.ints.clone())
}

impl TailWeights {
    /// The tail of `proto`, the detector's graph after [`crate::nn::stem`] cut its first layers: its
    /// one input holds their output, `channels` deep, with a border of `input_pad` (the padding
    /// of the node that reads it, which the cut set to zero). `Ok(None)` where a node has a form
    /// the module notes do not list.
    pub(crate) fn from_proto(
        proto: &ModelProto,
        channels: usize,
        input_pad: usize,
    ) -> TractResult<Option<Self>> {
        let Some(graph) = proto.graph.as_ref() else {
            return Ok(None);
        };
        if graph.input.len() != 1 || input_pad != 1 {
            return Ok(None);
        }
        // Nodes that only make weights (as `nn::dense` reads them) and the others.
        let mut made: Vec<String> = graph.initializer.iter().map(|t| t.name.clone()).collect();
        let mut work: Vec<&NodeProto> = Vec::new();
        for n in &graph.node {
            let maker = matches!(n.op_type.as_str(), "DequantizeLinear" | "Cast" | "Constant")
                && n.input.iter().all(|i| i.is_empty() || made.contains(i));
            if maker {
                made.extend(n.output.iter().cloned());
            } else {
                work.push(n);
            }
        }
        if work.iter().any(|n| {
            n.op_type == "Conv"
                && (n.input.len() != 3
                    || !made.contains(&n.input[1])
                    || !made.contains(&n.input[2]))
        }) {
            return Ok(None);
        }
        // Every convolution's weights and bias, read at once (their storage evaluated once).
        let names: Vec<&str> = work
            .iter()
            .filter(|n| n.op_type == "Conv")
            .flat_map(|n| [n.input[1].as_str(), n.input[2].as_str()])
            .collect();
        let tensors = values_by_name(proto, &names)?;
        let mut tensors = tensors.iter();
        let is_output = |name: &str| graph.output.iter().any(|o| o.name == name);
        let readers = |name: &str| {
            work.iter()
                .filter(|n| n.input.iter().any(|i| i == name))
                .count()
        };
        let mut values: Vec<(String, usize)> = vec![(graph.input[0].name.clone(), 0)];
        let mut chans = vec![channels];
        let mut layers: Vec<LayerWeights> = Vec::new();
        let mut i = 0;
        while i < work.len() {
            let n = work[i];
            if n.op_type != "Conv" || n.output.len() != 1 {
                return Ok(None);
            }
            let (Some(k), Some(b)) = (tensors.next(), tensors.next()) else {
                return Ok(None);
            };
            let Some(&(_, src)) = values.iter().find(|(m, _)| *m == n.input[0]) else {
                return Ok(None);
            };
            let kernel = ints(n, "kernel_shape").unwrap_or_default();
            let strides = ints(n, "strides").unwrap_or_else(|| vec![1, 1]);
            let pads = ints(n, "pads").unwrap_or_else(|| vec![0; 4]);
            let dilations = ints(n, "dilations").unwrap_or_else(|| vec![1, 1]);
            let group = attr(n, "group").map_or(1, |a| a.i);
            let auto = attr(n, "auto_pad").is_some_and(|a| !a.s.is_empty() && a.s != b"NOTSET");
            if auto || dilations != [1, 1] || pads.len() != 4 || pads.iter().any(|&p| p != pads[0])
            {
                return Ok(None);
            }
            // The node that reads the tail's input had its padding cut to zero: the input holds it.
            let pad = if src == 0 {
                input_pad as i64 + pads[0]
            } else {
                pads[0]
            };
            let stride = match strides.as_slice() {
                [1, 1] => 1,
                [2, 2] => 2,
                _ => return Ok(None),
            };
            let cin = chans[src];
            let kind = match (kernel.as_slice(), group, pad, stride) {
                ([3, 3], 1, 1, _) => Kind::Full,
                ([1, 1], 1, 0, 1) if src != 0 => Kind::Pointwise,
                ([3, 3], g, 1, _) if g == cin as i64 && g > 1 => Kind::Depthwise,
                _ => return Ok(None),
            };
            let cout = b.len();
            let side = if kind == Kind::Pointwise { 1 } else { 3 };
            let per = if kind == Kind::Depthwise { 1 } else { cin };
            if k.shape() != [cout, per, side, side]
                || b.rank() != 1
                || (kind == Kind::Depthwise && cout != cin)
            {
                return Ok(None);
            }
            let out = n.output[0].clone();
            // A ReLU that is the convolution's only reader folds into it; an output has none.
            let relu_node = work.get(i + 1).filter(|r| {
                is_relu(r)
                    && r.input.len() == 1
                    && r.input[0] == out
                    && r.output.len() == 1
                    && readers(&out) == 1
                    && !is_output(&out)
            });
            let (name, relu) = match relu_node {
                Some(r) => (r.output[0].clone(), true),
                None if is_output(&out) && readers(&out) == 0 && kind == Kind::Full => (out, false),
                None => return Ok(None),
            };
            let dst = chans.len();
            chans.push(cout);
            values.push((name, dst));
            layers.push(LayerWeights {
                kind,
                src,
                dst,
                cin,
                cout,
                stride,
                kernel: k.try_as_plain_ram()?.as_slice::<f32>()?.to_vec(),
                bias: b.try_as_plain_ram()?.as_slice::<f32>()?.to_vec(),
                relu,
            });
            i += if relu { 2 } else { 1 };
        }
        let Some(outputs) = graph
            .output
            .iter()
            .map(|o| values.iter().find(|(m, _)| *m == o.name).map(|&(_, v)| v))
            .collect::<Option<Vec<_>>>()
        else {
            return Ok(None);
        };
        // Each output is a layer's and read by nothing (so it may be held as planes).
        if outputs.contains(&0) || layers.iter().any(|l| outputs.contains(&l.src)) {
            return Ok(None);
        }
        Ok(Some(Self {
            layers,
            channels: chans,
            outputs,
        }))
    }
}

/// Channels per position of an interleaved value of `channels`.
fn width(channels: usize) -> usize {
    channels.next_multiple_of(BLOCK)
}

/// A layer for fixed input sizes, its weights packed for the kernel.
#[derive(Debug, Clone)]
struct Layer {
    kind: Kind,
    src: usize,
    dst: usize,
    cout: usize,
    /// Full and pointwise: per block of sixteen output channels, per tap the block's weights;
    /// depthwise: per tap the `width` channels' weights.
    packed: Vec<f32>,
    /// Biases, zero past `cout` up to a whole block.
    bias: Vec<f32>,
    /// Full and pointwise: each tap's offset in the input from a window's first value.
    taps: Vec<usize>,
    reach: usize,
    /// Depthwise: each tap's offset in positions.
    dw_taps: [usize; 9],
    /// Per output position its window's first value (full, pointwise) or position
    /// (depthwise) in the input, and its place in the output (a position where interleaved, an
    /// offset in a plane otherwise).
    at_in: Vec<usize>,
    at_out: Vec<usize>,
    /// Channels per output position where interleaved, 0 for planes.
    out_width: usize,
    /// Values per output plane (planes).
    plane: usize,
    relu: bool,
}

/// The tail for one input size, with its buffers.
#[derive(Debug, Clone)]
pub(crate) struct Tail {
    layers: Vec<Layer>,
    values: Vec<Vec<f32>>,
    /// The graph outputs: value, rows, columns.
    outputs: Vec<(usize, usize, usize)>,
    form: Form,
}

impl Tail {
    /// The tail of `weights` for an input of `h × w` positions (the interior of the first layers'
    /// output).
    pub(crate) fn new(weights: &TailWeights, h: usize, w: usize) -> Self {
        let n = weights.channels.len();
        let mut dims = vec![(0usize, 0usize); n];
        dims[0] = (h, w);
        let mut is_output = vec![false; n];
        for &o in &weights.outputs {
            is_output[o] = true;
        }
        let mut layers = Vec::with_capacity(weights.layers.len());
        for l in &weights.layers {
            let (ih, iw) = dims[l.src];
            let s = l.stride;
            let side = |v: usize| if v == 0 { 0 } else { (v - 1) / s + 1 };
            let (oh, ow) = (side(ih), side(iw));
            dims[l.dst] = (oh, ow);
            let (pw, win) = (iw + 2, width(l.cin));
            let planar = is_output[l.dst];
            let (out_width, plane) = if planar {
                (0, oh * ow)
            } else {
                (width(l.cout), 0)
            };
            let mut at_in = Vec::with_capacity(oh * ow);
            let mut at_out = Vec::with_capacity(oh * ow);
            for y in 0..oh {
                for x in 0..ow {
                    // The window's top-left position in the padded input (a 1×1 kernel reads the
                    // position itself, one in from the border).
                    let p = match l.kind {
                        Kind::Pointwise => (y + 1) * pw + x + 1,
                        _ => s * y * pw + s * x,
                    };
                    at_in.push(if l.kind == Kind::Depthwise {
                        p
                    } else {
                        p * win
                    });
                    at_out.push(if planar {
                        y * ow + x
                    } else {
                        (y + 1) * (ow + 2) + x + 1
                    });
                }
            }
            let (packed, taps, dw_taps) = match l.kind {
                Kind::Depthwise => {
                    let mut packed = vec![0.0; 9 * win];
                    for c in 0..l.cin {
                        for t in 0..9 {
                            packed[t * win + c] = l.kernel[c * 9 + t];
                        }
                    }
                    let dw_taps = std::array::from_fn(|t| (t / 3) * pw + t % 3);
                    (packed, Vec::new(), dw_taps)
                }
                Kind::Pointwise => {
                    let packed = pack(l.cout, l.cin, 0.0, |co, c| l.kernel[co * l.cin + c]);
                    (packed, (0..l.cin).collect(), [0; 9])
                }
                Kind::Full => {
                    let k = 9 * l.cin;
                    let packed = pack(l.cout, k, 0.0, |co, t| l.kernel[co * k + t]);
                    let taps = (0..k)
                        .map(|t| {
                            let (c, dy, dx) = (t / 9, t % 9 / 3, t % 3);
                            c + (dy * pw + dx) * win
                        })
                        .collect();
                    (packed, taps, [0; 9])
                }
            };
            let mut bias = l.bias.clone();
            bias.resize(width(l.cout), 0.0);
            layers.push(Layer {
                kind: l.kind,
                src: l.src,
                dst: l.dst,
                cout: l.cout,
                packed,
                bias,
                reach: taps.iter().copied().max().unwrap_or(0),
                taps,
                dw_taps,
                at_in,
                at_out,
                out_width,
                plane,
                relu: l.relu,
            });
        }
        let values = (0..n)
            .map(|v| {
                let (vh, vw) = dims[v];
                if is_output[v] {
                    weights.channels[v] * vh * vw
                } else {
                    (vh + 2) * (vw + 2) * width(weights.channels[v])
                }
            })
            .map(|len| vec![0.0; len])
            .collect();
        Self {
            layers,
            values,
            outputs: weights
                .outputs
                .iter()
                .map(|&v| (v, dims[v].0, dims[v].1))
                .collect(),
            form: Form::for_this_cpu(),
        }
    }

    /// The input buffer: `(h + 2) × (w + 2)` positions of the input's channels rounded up to a
    /// whole block, interleaved, whose border (and extra channels) the writer leaves zero.
    pub(crate) fn input_mut(&mut self) -> &mut [f32] {
        &mut self.values[0]
    }

    /// The length of [`Self::input_mut`].
    pub(crate) fn input_len(&self) -> usize {
        self.values[0].len()
    }

    /// Runs every layer on the input as last written.
    pub(crate) fn run(&mut self) {
        for l in &self.layers {
            let mut out = std::mem::take(&mut self.values[l.dst]);
            let input = &self.values[l.src];
            match l.kind {
                Kind::Depthwise => {
                    let dw = Depthwise {
                        input,
                        weights: &l.packed,
                        bias: &l.bias,
                        taps: &l.dw_taps,
                        width: l.bias.len(),
                    };
                    for (ai, ao) in l.at_in.chunks(POSITIONS).zip(l.at_out.chunks(POSITIONS)) {
                        dw.run(self.form, ai, ao, &mut out);
                    }
                }
                Kind::Pointwise | Kind::Full => FullLayer {
                    input,
                    packed: &l.packed,
                    bias: &l.bias,
                    taps: &l.taps,
                    reach: l.reach,
                    cout: l.cout,
                    plane: l.plane,
                    width: l.out_width,
                    relu: l.relu,
                    at_in: &l.at_in,
                    at_out: &l.at_out,
                }
                .run(self.form, &mut out),
            }
            self.values[l.dst] = out;
        }
    }

    /// Graph output `k` after [`Tail::run`]: its planes (`channels × rows × columns`), rows and
    /// columns.
    pub(crate) fn output(&self, k: usize) -> Option<(&[f32], usize, usize)> {
        let &(v, h, w) = self.outputs.get(k)?;
        Some((&self.values[v], h, w))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::stem::{Stem, StemWeights};

    /// The shipped detector's graph with its first layers cut, and their output's channels and
    /// border.
    fn cut_detector() -> (ModelProto, usize, usize) {
        let mut proto = crate::nn::onnx::parse(crate::detect::MODEL_ONNX).unwrap();
        let weights = StemWeights::split_from(&mut proto, &[vec![1, 1, 64, 64]])
            .unwrap()
            .expect("a stem");
        let channels = Stem::new(1, 64, 64, &weights).output_shape()[1];
        (proto, channels, weights.next_pad)
    }

    #[test]
    #[cfg_attr(
        any(
            all(target_arch = "x86_64", not(host_avx2_fma)),
            not(any(target_arch = "x86_64", target_arch = "aarch64"))
        ),
        ignore = "this CPU leaves the detector's first layers to tract"
    )]
    fn the_shipped_detectors_blocks_and_heads_are_read_whole() {
        assert!(
            crate::nn::conv::available(),
            "this CPU leaves the detector's first layers to tract"
        );
        let (proto, channels, pad) = cut_detector();
        let tail = TailWeights::from_proto(&proto, channels, pad)
            .unwrap()
            .expect("the tail's form");
        let count = |k: Kind| tail.layers.iter().filter(|l| l.kind == k).count();
        // c3.2, c4.0–c6.1: a depthwise and a pointwise layer each; one head per stride.
        assert_eq!(
            (
                count(Kind::Depthwise),
                count(Kind::Pointwise),
                count(Kind::Full)
            ),
            (7, 7, 4)
        );
        assert_eq!(tail.outputs.len(), 4);
        assert!(tail.layers.iter().all(|l| l.relu == (l.kind != Kind::Full)));
        // Each head reads the block output of its stride.
        let heads: Vec<usize> = tail
            .layers
            .iter()
            .filter(|l| l.kind == Kind::Full)
            .map(|l| l.cin)
            .collect();
        assert_eq!(heads, [48, 64, 96, 96]);
    }

    #[test]
    #[cfg_attr(
        any(
            all(target_arch = "x86_64", not(host_avx2_fma)),
            not(any(target_arch = "x86_64", target_arch = "aarch64"))
        ),
        ignore = "this CPU leaves the detector's first layers to tract"
    )]
    fn a_node_of_another_form_leaves_the_graph_to_tract() {
        assert!(
            crate::nn::conv::available(),
            "this CPU leaves the detector's first layers to tract"
        );
        let (proto, channels, pad) = cut_detector();
        // What is changed, in the first node of which type, and how.
        type Edit = (&'static str, &'static str, fn(&mut NodeProto));
        let edits: [Edit; 3] = [
            ("a leaky ReLU", "LeakyRelu", |n| n.attribute[0].f = 0.1),
            ("a dilated convolution", "Conv", |n| {
                for a in n.attribute.iter_mut().filter(|a| a.name == "dilations") {
                    a.ints = vec![2, 2];
                }
            }),
            ("a sigmoid", "LeakyRelu", |n| n.op_type = "Sigmoid".into()),
        ];
        for (what, op, edit) in edits {
            let mut p = proto.clone();
            let graph = p.graph.as_mut().unwrap();
            edit(graph.node.iter_mut().find(|n| n.op_type == op).unwrap());
            assert!(
                TailWeights::from_proto(&p, channels, pad)
                    .unwrap()
                    .is_none(),
                "{what}"
            );
        }
        // A border the input does not have.
        assert!(
            TailWeights::from_proto(&proto, channels, 0)
                .unwrap()
                .is_none()
        );
    }
}
