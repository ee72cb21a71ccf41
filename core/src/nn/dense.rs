//! The fully connected heads of the M3 networks, computed here instead of by tract where the
//! trunk already runs outside it ([`crate::nn::stem`]).
//!
//! Why: once the trunks run in [`crate::nn::conv`], what tract would still run per face is the
//! heads, whose few multiply-adds cost less than tract's per-run bookkeeping (plan walk, tensor
//! allocation, copies). Here each layer is one pass over its weights, stored input-major so the
//! outputs are the vector lanes, in buffers allocated once ([`crate::kernels::dense`] computes the
//! products). Where the trunks multiply in int8 ([`crate::nn::conv::int8_products`]: AVX-512
//! VNNI), int8 layers do too: their input rounded per run to 16-bit steps (two u8 digits), the
//! same weights.
//!
//! What a graph may hold after its trunk was cut: `Flatten` of the trunk's output, `Gemm` (α = β =
//! 1, `transA` 0, either `transB`) with a bias, `Relu` or `LeakyRelu` with α = 0, `Concat` along
//! axis 1 of values and graph inputs, `Identity`, and the nodes that only make weights
//! (`DequantizeLinear`, `Cast` and `Constant` of weights, initializers); anything else leaves the
//! graph to tract.

use crate::nn::onnx::pb::{ModelProto, NodeProto};
use crate::nn::stem::{attr, is_relu, values_by_name};
use tract_core::internal::*;

use crate::kernels::dense::{CHUNK, Product, int8_product};

/// A layer's weights as stored here.
#[derive(Debug, Clone)]
enum Weights {
    F32(Vec<f32>),
    /// Per output column `o` the weights are `q[k][o] · scale[o]`: the form the shipped networks'
    /// int8 storage gives them (`models/train/onnx_q8.py`, one symmetric scale per output), a
    /// quarter of the bytes to stream — the f32 matrices (1.5 MB over the seven networks, 2.9 MB
    /// read per face in mirror average, counted from the graphs) did not stay in the cache, and
    /// their reading was the heads' time.
    I8 {
        q: Vec<i8>,
        scale: Vec<f32>,
        /// Where the heads multiply in int8 ([`crate::nn::conv::int8_products`]): the same weights
        /// for `vpdpbusd`, per four inputs (zero rows past `k`) the `n'` columns' words, byte `b`
        /// the weight of input `4r + b`.
        quads: Option<Vec<u32>>,
    },
}

impl Weights {
    /// `w` (`k × np`, input-major) as int8 times a scale per column where every value is one to
    /// within 1e-6 of its column's largest magnitude, else as it is.
    fn compact(w: Vec<f32>, np: usize) -> Self {
        let k = w.len() / np.max(1);
        if let Some((q, scale)) = crate::nn::conv::int8_per_output(&w, np, |t| t % np) {
            let quads = crate::nn::conv::int8_products().then(|| {
                (0..k.div_ceil(4) * np)
                    .map(|t| {
                        let (r, o) = (t / np, t % np);
                        crate::nn::conv::int8_word(|b| {
                            let row = 4 * r + b;
                            if row < k { q[row * np + o] } else { 0 }
                        })
                    })
                    .collect()
            });
            Weights::I8 { q, scale, quads }
        } else {
            Weights::F32(w)
        }
    }
}

/// One step over the value buffers (indices into [`Dense::values`]).
#[derive(Debug, Clone)]
enum Op {
    /// `values[dst] = weights · values[src] + bias`, optionally through a ReLU.
    Linear {
        src: usize,
        dst: usize,
        /// `k × n'` with `n'` the outputs rounded up to whole [`CHUNK`]s (zero columns past `n`):
        /// input-major, so one input's weights for a chunk of outputs are contiguous.
        weights: Weights,
        /// `n'` values, zero past `n`.
        bias: Vec<f32>,
        relu: bool,
    },
    /// `values[dst]` = the concatenation of `srcs`.
    Concat { srcs: Vec<usize>, dst: usize },
}

/// A network's heads as a list of steps over owned buffers.
#[derive(Debug, Clone)]
pub(crate) struct Dense {
    ops: Vec<Op>,
    /// Every value's buffer: the graph inputs first (in order; written through
    /// [`Dense::input_mut`]), then one per node output kept.
    values: Vec<Vec<f32>>,
    /// The value of each graph output, in the graph's output order.
    outputs: Vec<usize>,
    /// The graph outputs' names, in order.
    output_names: Vec<String>,
    /// A layer's input quantised for the int8 products: its high and then its low u8 digits, four
    /// to a word ([`int8_product`]).
    quantised: Vec<u32>,
}

/// The names of the values that are weights — initializers, and the outputs of `Constant`,
/// `DequantizeLinear` and `Cast` nodes fed by weights alone (evaluated by tract once, at load) —
/// and whether each node is such a weight maker.
fn weights_of(graph: &crate::nn::onnx::pb::GraphProto) -> (Vec<String>, Vec<bool>) {
    let mut names: Vec<String> = graph.initializer.iter().map(|t| t.name.clone()).collect();
    let mut makers = Vec::with_capacity(graph.node.len());
    for n in &graph.node {
        let maker = matches!(n.op_type.as_str(), "DequantizeLinear" | "Cast" | "Constant")
            && n.input.iter().all(|i| i.is_empty() || names.contains(i));
        if maker {
            names.extend(n.output.iter().cloned());
        }
        makers.push(maker);
    }
    (names, makers)
}

/// A `Gemm` of the form the heads use: `Y = A · B(ᵀ) + C` with a bias `C`.
fn plain_gemm(node: &NodeProto) -> bool {
    node.op_type == "Gemm"
        && node.input.len() == 3
        && attr(node, "alpha").is_none_or(|a| a.f == 1.0)
        && attr(node, "beta").is_none_or(|a| a.f == 1.0)
        && attr(node, "transA").is_none_or(|a| a.i == 0)
}

impl Dense {
    /// The heads of `proto` — a graph whose first input is the trunk's output, of shape
    /// `shapes[0]`, other inputs of `shapes[1..]` — when every node has a form listed in the module
    /// notes; `Ok(None)` otherwise (tract then runs the graph). Weights are read through tract
    /// (`onnx`), so any weight storage it reads works.
    pub(crate) fn from_proto(
        proto: &ModelProto,
        shapes: &[Vec<usize>],
    ) -> TractResult<Option<Self>> {
        let Some(graph) = proto.graph.as_ref() else {
            return Ok(None);
        };
        // Inputs as tract counts them (an input that is also an initializer is none) and batches
        // of one.
        let initializer = |name: &str| graph.initializer.iter().any(|t| t.name == name);
        if graph.input.len() != shapes.len()
            || graph.input.iter().any(|i| initializer(&i.name))
            || shapes.iter().any(|s| s.first() != Some(&1))
        {
            return Ok(None);
        }
        let (weight_names, makers) = weights_of(graph);
        let is_weight = |name: &str| weight_names.iter().any(|w| w == name);
        // Value names → (buffer index, length), the graph inputs first.
        let mut names: Vec<(String, usize)> = Vec::new();
        let mut lens: Vec<usize> = Vec::new();
        for (input, shape) in graph.input.iter().zip(shapes) {
            names.push((input.name.clone(), lens.len()));
            lens.push(shape.iter().product());
        }
        let find = |names: &[(String, usize)], n: &str| {
            names.iter().find(|(m, _)| m == n).map(|&(_, i)| i)
        };
        // First pass: the structure, with each Gemm's weight names and shape to read.
        enum Pending {
            Linear {
                src: usize,
                dst: usize,
                b: String,
                c: String,
                trans_b: bool,
                relu: bool,
            },
            Concat {
                srcs: Vec<usize>,
                dst: usize,
            },
        }
        let mut pending: Vec<Pending> = Vec::new();
        let nodes: Vec<&NodeProto> = graph
            .node
            .iter()
            .zip(&makers)
            .filter(|(_, m)| !**m)
            .map(|(n, _)| n)
            .collect();
        let mut i = 0;
        while i < nodes.len() {
            let n = nodes[i];
            if n.output.len() != 1 {
                return Ok(None);
            }
            match n.op_type.as_str() {
                "Flatten" | "Identity" if n.input.len() == 1 => {
                    // Flatten from axis 1 keeps a batch of one as it is laid out.
                    if n.op_type == "Flatten" && attr(n, "axis").is_some_and(|a| a.i != 1) {
                        return Ok(None);
                    }
                    let Some(src) = find(&names, &n.input[0]) else {
                        return Ok(None);
                    };
                    names.push((n.output[0].clone(), src));
                }
                "Concat" if attr(n, "axis").is_some_and(|a| a.i == 1 || a.i == -1) => {
                    let Some(srcs) = n
                        .input
                        .iter()
                        .map(|s| find(&names, s))
                        .collect::<Option<Vec<_>>>()
                    else {
                        return Ok(None);
                    };
                    // Axis −1 is axis 1 only for the flat (batch × features) values it joins.
                    let dst = lens.len();
                    lens.push(0); // summed once the Gemms' sizes are read
                    names.push((n.output[0].clone(), dst));
                    pending.push(Pending::Concat { srcs, dst });
                }
                _ if plain_gemm(n) && is_weight(&n.input[1]) && is_weight(&n.input[2]) => {
                    let Some(src) = find(&names, &n.input[0]) else {
                        return Ok(None);
                    };
                    // A ReLU that is the Gemm's only reader folds into it.
                    let next = nodes.get(i + 1).filter(|r| {
                        is_relu(r)
                            && r.input.len() == 1
                            && r.input[0] == n.output[0]
                            && r.output.len() == 1
                            && nodes
                                .iter()
                                .filter(|m| m.input.contains(&n.output[0]))
                                .count()
                                == 1
                            && !graph.output.iter().any(|o| o.name == n.output[0])
                    });
                    let dst = lens.len();
                    lens.push(0); // known once the weights are read
                    let out = next.map_or(&n.output[0], |r| &r.output[0]);
                    names.push((out.clone(), dst));
                    pending.push(Pending::Linear {
                        src,
                        dst,
                        b: n.input[1].clone(),
                        c: n.input[2].clone(),
                        trans_b: attr(n, "transB").is_some_and(|a| a.i != 0),
                        relu: next.is_some(),
                    });
                    if next.is_some() {
                        i += 1;
                    }
                }
                _ => return Ok(None),
            }
            i += 1;
        }
        let Some(outputs) = graph
            .output
            .iter()
            .map(|o| find(&names, &o.name))
            .collect::<Option<Vec<_>>>()
        else {
            return Ok(None);
        };
        // The weights as tract computes them (int8 or float16 storage dequantised).
        let wanted: Vec<&str> = pending
            .iter()
            .flat_map(|p| match p {
                Pending::Linear { b, c, .. } => vec![b.as_str(), c.as_str()],
                Pending::Concat { .. } => vec![],
            })
            .collect();
        // (The graph's inputs are `shapes`' alone, checked above, as `values_by_name` needs.)
        let tensors = values_by_name(proto, &wanted)?;
        let mut tensors = tensors.iter();
        let mut ops = Vec::with_capacity(pending.len());
        for p in pending {
            match p {
                Pending::Concat { srcs, dst } => {
                    lens[dst] = srcs.iter().map(|&s| lens[s]).sum();
                    ops.push(Op::Concat { srcs, dst });
                }
                Pending::Linear {
                    src,
                    dst,
                    trans_b,
                    relu,
                    ..
                } => {
                    let (Some(b), Some(c)) = (tensors.next(), tensors.next()) else {
                        tract_core::internal::bail!("weights missing");
                    };
                    let (bv, cv) = (
                        b.try_as_plain_ram()?.as_slice::<f32>()?,
                        c.try_as_plain_ram()?.as_slice::<f32>()?,
                    );
                    let &[r, s] = b.shape() else {
                        return Ok(None);
                    };
                    // ONNX: B is k × n, or n × k with transB.
                    let (k, n) = if trans_b { (s, r) } else { (r, s) };
                    if k != lens[src] || cv.len() != n {
                        return Ok(None);
                    }
                    let np = n.div_ceil(CHUNK) * CHUNK;
                    let mut weights = vec![0.0; k * np];
                    for (t, w) in weights.iter_mut().enumerate() {
                        let (row, col) = (t / np, t % np);
                        if col < n {
                            *w = if trans_b {
                                bv[col * k + row]
                            } else {
                                bv[row * n + col]
                            };
                        }
                    }
                    let mut bias = cv.to_vec();
                    bias.resize(np, 0.0);
                    lens[dst] = n;
                    ops.push(Op::Linear {
                        src,
                        dst,
                        weights: Weights::compact(weights, np),
                        bias,
                        relu,
                    });
                }
            }
        }
        let quantised = vec![0; 2 * lens.iter().max().copied().unwrap_or(0).div_ceil(4)];
        Ok(Some(Self {
            quantised,
            ops,
            values: lens.iter().map(|&l| vec![0.0; l]).collect(),
            outputs,
            output_names: graph.output.iter().map(|o| o.name.clone()).collect(),
        }))
    }

    /// The index of the graph output named `name`.
    pub(crate) fn output_index(&self, name: &str) -> Option<usize> {
        self.output_names.iter().position(|n| n == name)
    }

    /// Graph input `i`'s buffer (its shape's length, row-major), which [`Dense::run`] reads.
    pub(crate) fn input_mut(&mut self, i: usize) -> &mut [f32] {
        &mut self.values[i]
    }

    /// Runs the heads on the graph inputs as last written.
    pub(crate) fn run(&mut self) {
        for op in &self.ops {
            match op {
                Op::Concat { srcs, dst } => {
                    let mut out = std::mem::take(&mut self.values[*dst]);
                    let mut at = 0;
                    for &s in srcs {
                        let v = &self.values[s];
                        out[at..at + v.len()].copy_from_slice(v);
                        at += v.len();
                    }
                    self.values[*dst] = out;
                }
                Op::Linear {
                    src,
                    dst,
                    weights,
                    bias,
                    relu,
                } => {
                    let mut out = std::mem::take(&mut self.values[*dst]);
                    let x = &self.values[*src];
                    let (bias, relu) = (bias.as_slice(), *relu);
                    match weights {
                        Weights::F32(weights) => Product {
                            x,
                            weights,
                            scale: None,
                            bias,
                            relu,
                        }
                        .run(&mut out),
                        Weights::I8 { q, scale, quads } => {
                            let done = quads.as_ref().is_some_and(|quads| {
                                int8_product(
                                    x,
                                    quads,
                                    scale,
                                    bias,
                                    relu,
                                    &mut self.quantised,
                                    &mut out,
                                )
                            });
                            if !done {
                                Product {
                                    x,
                                    weights: q,
                                    scale: Some(scale),
                                    bias,
                                    relu,
                                }
                                .run(&mut out)
                            }
                        }
                    }
                    self.values[*dst] = out;
                }
            }
        }
    }

    /// How many of the layers multiply in int8 ([`Weights::I8`]'s `quads`).
    #[cfg(test)]
    pub(crate) fn int8_product_layers(&self) -> usize {
        self.ops
            .iter()
            .filter(|op| {
                matches!(
                    op,
                    Op::Linear {
                        weights: Weights::I8 { quads: Some(_), .. },
                        ..
                    }
                )
            })
            .count()
    }

    /// How many of the layers keep int8 weights, and how many layers there are.
    #[cfg(test)]
    pub(crate) fn int8_layers(&self) -> (usize, usize) {
        let layers = self.ops.iter().filter_map(|op| match op {
            Op::Linear { weights, .. } => Some(matches!(weights, Weights::I8 { .. })),
            Op::Concat { .. } => None,
        });
        layers.fold((0, 0), |(i, n), int8| (i + usize::from(int8), n + 1))
    }

    /// Graph output `k` after [`Dense::run`].
    pub(crate) fn output(&self, k: usize) -> &[f32] {
        &self.values[self.outputs[k]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Int8 times a scale per column is kept as int8 and gives the same products; other weights
    /// stay f32.
    #[test]
    fn weights_are_kept_as_int8_only_where_they_are_int8() {
        let np = CHUNK;
        let scale: Vec<f32> = (0..np).map(|o| 0.001 * (o + 1) as f32).collect();
        // As `onnx_q8.py` stores them: each column's largest magnitude is 127 steps.
        let quantised: Vec<f32> = (0..3 * np)
            .map(|t| {
                let q = if t < np {
                    127.0
                } else {
                    (t * 37 % 255) as f32 - 127.0
                };
                q * scale[t % np]
            })
            .collect();
        let Weights::I8 { q, scale: s, .. } = Weights::compact(quantised.clone(), np) else {
            panic!("int8 weights not kept as int8");
        };
        for (t, &w) in quantised.iter().enumerate() {
            assert!((f32::from(q[t]) * s[t % np] - w).abs() <= 1e-6 * w.abs().max(1e-3));
        }
        let other: Vec<f32> = (0..3 * np).map(|t| (t as f32 * 0.37).sin()).collect();
        assert!(matches!(Weights::compact(other, np), Weights::F32(_)));
        // The kernel on both forms: the same outputs, ReLU and bias included.
        let x = [0.5f32, -1.0, 2.0];
        let bias: Vec<f32> = (0..np).map(|o| o as f32 * 0.01 - 0.1).collect();
        let (mut a, mut b) = (vec![0.0; np - 3], vec![0.0; np - 3]);
        Product {
            x: &x,
            weights: &quantised,
            scale: None,
            bias: &bias,
            relu: true,
        }
        .run(&mut a);
        Product {
            x: &x,
            weights: &q,
            scale: Some(&s),
            bias: &bias,
            relu: true,
        }
        .run(&mut b);
        for (o, (a, b)) in a.iter().zip(&b).enumerate() {
            let want: f32 = bias[o] + (0..3).map(|k| x[k] * quantised[k * np + o]).sum::<f32>();
            assert!(
                (a - want.max(0.0)).abs() < 1e-5 && (b - a).abs() < 1e-5,
                "{o}: {a} {b}"
            );
        }
    }

    /// The int8 products (AVX-512 VNNI): within half a 16-bit step of the input per term of the
    /// f32 product (the weights are the same int8); inputs with a negative or non-finite value
    /// are left to the f32 kernel.
    #[test]
    #[cfg_attr(
        not(host_avx512_vnni),
        ignore = "this CPU runs no AVX-512 VNNI kernels"
    )]
    fn the_avx512_vnni_int8_products_match_the_f32_kernel_within_the_input_quantisation() {
        assert!(
            crate::nn::conv::Products::Vnni.supported(),
            "the AVX-512 VNNI kernels do not run here (no such CPU, or the portable path)"
        );
        // Column counts of one, two and five registers' worth past whole groups of four (96 =
        // 64 + 32, 160 = 2·64 + 32), inputs not a multiple of four or of sixteen, outputs fewer
        // than the columns.
        for (k, n) in [(37usize, 32usize), (64, 96), (5, 160), (130, 61)] {
            let np = n.div_ceil(CHUNK) * CHUNK;
            let weights: Vec<f32> = (0..k * np)
                .map(|t| {
                    let (row, o) = (t / np, t % np);
                    let q = crate::nn::conv::int8_test_code(t, row == o % k);
                    if o < n {
                        q as f32 * 0.002 * (1 + o % 7) as f32
                    } else {
                        0.0
                    }
                })
                .collect();
            let compact = crate::nn::conv::building(crate::nn::conv::Products::Vnni, || {
                Weights::compact(weights.clone(), np)
            });
            let Weights::I8 { q, scale, quads } = compact else {
                panic!("int8 weights not kept as int8");
            };
            let quads = quads.expect("int8 weights without their int8 products");
            let bias: Vec<f32> = (0..np).map(|o| o as f32 * 0.01 - 0.3).collect();
            let x: Vec<f32> = (0..k).map(|i| (i * 53 % 29) as f32 / 7.0).collect();
            let max = x.iter().fold(0f32, |m, &v| m.max(v));
            let mut quantised = vec![0; 2 * k.div_ceil(4)];
            for relu in [false, true] {
                let (mut want, mut got) = (vec![0.0; n], vec![0.0; n]);
                let product = Product {
                    x: &x,
                    weights: &q,
                    scale: Some(&scale),
                    bias: &bias,
                    relu,
                };
                product.run(&mut want);
                assert!(int8_product(
                    &x,
                    &quads,
                    &scale,
                    &bias,
                    relu,
                    &mut quantised,
                    &mut got
                ));
                for o in 0..n {
                    let column: f32 = (0..k).map(|r| weights[r * np + o].abs()).sum();
                    let bound = 1e-4 + column * max / 131_070.0;
                    assert!(
                        (got[o] - want[o]).abs() <= bound,
                        "{k}×{n} relu {relu}: column {o}: {} vs {} (bound {bound})",
                        got[o],
                        want[o]
                    );
                }
                for bad in [-0.5, f32::NAN, f32::INFINITY] {
                    let mut signed = x.clone();
                    signed[k - 1] = bad;
                    got.fill(9.0);
                    assert!(!int8_product(
                        &signed,
                        &quads,
                        &scale,
                        &bias,
                        relu,
                        &mut quantised,
                        &mut got
                    ));
                    assert!(got.iter().all(|&v| v == 9.0), "written before falling back");
                }
            }
        }
    }
}
