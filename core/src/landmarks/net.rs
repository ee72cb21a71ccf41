//! The one place tract is used: an ONNX network loaded from bytes with fixed input shapes,
//! optimised once, and run through a reused plan state with reused input tensors.
//!
//! tract runs single-threaded unless its `multithread-mm` feature is enabled and an executor is
//! installed; the core enables neither, so each network runs on the calling thread.

use super::stem::Stem;
use crate::error::{Error, Result};
use std::sync::Arc;
use tract_onnx::pb::{AttributeProto, ModelProto, NodeProto};
use tract_onnx::prelude::*;

/// A loaded network with named outputs and reusable inputs.
#[derive(Debug)]
pub(crate) struct Net {
    state: TypedSimpleState,
    /// The first layer when computed outside tract ([`Stem`]); tract's input 0 is then its output.
    stem: Option<Stem>,
    inputs: Vec<Arc<Tensor>>,
    /// Output slot of each requested output name, in request order.
    output_slots: Vec<usize>,
    outputs: TVec<TValue>,
}

fn load_err(what: &str) -> impl Fn(TractError) -> Error + '_ {
    move |e| Error::ModelLoad(format!("{what}: {e:#}"))
}

impl Net {
    /// Loads `bytes` (ONNX) with inputs of the given names and shapes (in the graph's input
    /// order) and outputs looked up by name. `what` names the network in errors.
    ///
    /// A first layer of the form [`Stem`] computes (found by [`StemLayer::find`]) runs outside
    /// tract; the caller sees the same inputs either way.
    pub(crate) fn load(
        what: &str,
        bytes: &[u8],
        inputs: &[(&str, &[usize])],
        outputs: &[&str],
    ) -> Result<Self> {
        Self::load_with_stem(what, bytes, inputs, outputs, true)
    }

    /// [`Self::load`], with the first layer left to tract unless `use_stem`.
    fn load_with_stem(
        what: &str,
        bytes: &[u8],
        inputs: &[(&str, &[usize])],
        outputs: &[&str],
        use_stem: bool,
    ) -> Result<Self> {
        crate::cpu::select_tract_kernels();
        let onnx = tract_onnx::onnx();
        let mut proto = onnx
            .proto_model_for_read(&mut &*bytes)
            .map_err(load_err(what))?;
        let mut shapes: Vec<Vec<usize>> = inputs.iter().map(|(_, s)| s.to_vec()).collect();
        let layer = use_stem.then(|| StemLayer::find(&proto, &shapes)).flatten();
        let stem = match layer {
            Some(layer) => {
                let (kernel, bias) = layer
                    .weights(&onnx, &proto, &shapes)
                    .map_err(load_err(what))?;
                layer.cut(&mut proto);
                let [batch, _, h, w] = [shapes[0][0], 1, shapes[0][2], shapes[0][3]];
                let stem = Stem::new(batch, h, w, &kernel, &bias, layer.next_pad);
                shapes[0] = stem.output_shape().to_vec();
                Some(stem)
            }
            None => None,
        };
        let mut model = onnx.model_for_proto_model(&proto).map_err(load_err(what))?;
        let names: Vec<String> = model
            .input_outlets()
            .map_err(load_err(what))?
            .iter()
            .map(|o| model.node(o.node).name.clone())
            .collect();
        let want: Vec<&str> = inputs.iter().map(|(n, _)| *n).collect();
        if names != want {
            return Err(Error::ModelLoad(format!(
                "{what}: inputs {names:?}, expected {want:?} (models/M3_IO.md)"
            )));
        }
        for (i, shape) in shapes.iter().enumerate() {
            model
                .set_input_fact(i, f32::fact(shape).into())
                .map_err(load_err(what))?;
        }
        let model = model.into_optimized().map_err(load_err(what))?;
        let mut output_slots = Vec::with_capacity(outputs.len());
        let outlets = model.output_outlets().map_err(load_err(what))?;
        for name in outputs {
            let slot = outlets
                .iter()
                .position(|o| {
                    model.outlet_label(*o) == Some(*name) || model.node(o.node).name == *name
                })
                .ok_or_else(|| {
                    Error::ModelLoad(format!(
                        "{what}: no output named {name:?} (models/M3_IO.md)"
                    ))
                })?;
            output_slots.push(slot);
        }
        let plan = model.into_runnable().map_err(load_err(what))?;
        let state = plan.spawn().map_err(load_err(what))?;
        // Zeros: with a stem, input 0's border is the second layer's padding and stays zero.
        let inputs = shapes
            .iter()
            .map(|shape| Tensor::zero::<f32>(shape).map(Arc::new))
            .collect::<TractResult<Vec<_>>>()
            .map_err(load_err(what))?;
        Ok(Self {
            state,
            stem,
            inputs,
            output_slots,
            outputs: tvec![],
        })
    }

    /// Calls `fill` with input `i`'s values (row-major, its fixed shape) to overwrite them.
    pub(crate) fn fill_input(&mut self, i: usize, fill: impl FnOnce(&mut [f32])) -> Result<()> {
        if let (0, Some(stem)) = (i, &mut self.stem) {
            fill(stem.input_mut());
            return Ok(());
        }
        // The plan state drops its references to the inputs after each run, so the tensor is
        // unique again here and `make_mut` does not copy it.
        let t = Arc::make_mut(&mut self.inputs[i]);
        let mut view = t
            .try_as_plain_ram_mut()
            .map_err(|e| Error::Internal(format!("input tensor: {e:#}")))?;
        let s = view
            .as_slice_mut::<f32>()
            .map_err(|e| Error::Internal(format!("input tensor: {e:#}")))?;
        fill(s);
        Ok(())
    }

    /// Runs the network on the current inputs.
    pub(crate) fn run(&mut self) -> Result<()> {
        if let Some(stem) = &mut self.stem {
            let t = Arc::make_mut(&mut self.inputs[0]);
            let mut view = t
                .try_as_plain_ram_mut()
                .map_err(|e| Error::Internal(format!("input tensor: {e:#}")))?;
            let s = view
                .as_slice_mut::<f32>()
                .map_err(|e| Error::Internal(format!("input tensor: {e:#}")))?;
            stem.run(s);
        }
        let inputs: TVec<TValue> = self
            .inputs
            .iter()
            .map(|t| TValue::from_const(Arc::clone(t)))
            .collect();
        let outputs = self
            .state
            .run(inputs)
            .map_err(|e| Error::Internal(format!("network run: {e:#}")));
        crate::cpu::clear_upper_vector_state();
        self.outputs = outputs?;
        Ok(())
    }

    /// Output `k` (in the order the outputs were requested at load) of the last run.
    pub(crate) fn output(&self, k: usize) -> Result<&[f32]> {
        let t = self
            .outputs
            .get(self.output_slots[k])
            .ok_or_else(|| Error::Internal("network output missing".into()))?;
        t.try_as_plain_ram()
            .and_then(|v| v.as_slice::<f32>())
            .map_err(|e| Error::Internal(format!("network output: {e:#}")))
    }
}

/// A first layer [`Stem`] can compute, as found in an ONNX graph: the graph's first input
/// (`batch × 1 × h × w`) feeds only a 3×3, stride-2, padding-1 `Conv` with a bias, whose output
/// feeds only a ReLU (`Relu`, or `LeakyRelu` with α = 0), whose output feeds only a `Conv` with the
/// same padding `next_pad` on every side.
#[derive(Debug)]
struct StemLayer {
    conv: usize,
    relu: usize,
    next: usize,
    next_pad: usize,
}

fn attr<'a>(node: &'a NodeProto, name: &str) -> Option<&'a AttributeProto> {
    node.attribute.iter().find(|a| a.name == name)
}

fn ints_or<'a>(node: &'a NodeProto, name: &str, default: &'a [i64]) -> &'a [i64] {
    attr(node, name).map_or(default, |a| &a.ints)
}

/// Whether `node` is a `Conv` with explicit (not automatic) padding, group 1 and dilation 1.
fn plain_conv(node: &NodeProto) -> bool {
    node.op_type == "Conv"
        && attr(node, "auto_pad").is_none_or(|a| a.s.is_empty() || a.s == b"NOTSET")
        && attr(node, "group").is_none_or(|a| a.i == 1)
        && ints_or(node, "dilations", &[1, 1]) == [1, 1]
}

impl StemLayer {
    fn find(proto: &ModelProto, shapes: &[Vec<usize>]) -> Option<Self> {
        let graph = proto.graph.as_ref()?;
        if graph.input.len() != shapes.len() {
            return None;
        }
        let input = &graph.input.first()?.name;
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
        let (conv, c) = only_reader(input)?;
        if !(plain_conv(c)
            && c.input.len() == 3
            && c.input[0] == *input
            && ints_or(c, "kernel_shape", &[]) == [3, 3]
            && ints_or(c, "strides", &[1, 1]) == [2, 2]
            && ints_or(c, "pads", &[0; 4]) == [1, 1, 1, 1]
            && c.output.len() == 1)
        {
            return None;
        }
        let (relu, r) = only_reader(&c.output[0])?;
        let is_relu = r.op_type == "Relu"
            || (r.op_type == "LeakyRelu" && attr(r, "alpha").is_some_and(|a| a.f == 0.0));
        if !is_relu || r.output.len() != 1 {
            return None;
        }
        let (next, n) = only_reader(&r.output[0])?;
        let pads = ints_or(n, "pads", &[0; 4]);
        if !(plain_conv(n) && n.input[0] == r.output[0] && pads.len() == 4) {
            return None;
        }
        let next_pad = usize::try_from(pads[0]).ok()?;
        pads.iter().all(|&p| p == pads[0]).then_some(Self {
            conv,
            relu,
            next,
            next_pad,
        })
    }

    /// The layer's kernel (`channels × 9`) and bias, as tract computes them from the graph (so
    /// any storage of the weights tract reads — int8 with `DequantizeLinear`, float16 with `Cast`
    /// — works).
    fn weights(
        &self,
        onnx: &tract_onnx::Onnx,
        proto: &ModelProto,
        shapes: &[Vec<usize>],
    ) -> TractResult<(Vec<f32>, Vec<f32>)> {
        let Some(graph) = proto.graph.as_ref() else {
            tract_onnx::tract_core::internal::bail!("no graph");
        };
        let conv = &graph.node[self.conv];
        let mut model = onnx.model_for_proto_model(proto)?;
        for (i, shape) in shapes.iter().enumerate() {
            model.set_input_fact(i, f32::fact(shape).into())?;
        }
        model.select_outputs_by_name([&conv.input[1], &conv.input[2]])?;
        let plan = model.into_optimized()?.into_runnable()?;
        let zeros = shapes
            .iter()
            .map(|s| Tensor::zero::<f32>(s).map(TValue::from))
            .collect::<TractResult<TVec<_>>>()?;
        let out = plan.run(zeros)?;
        let (kernel, bias) = (&out[0], &out[1]);
        let channels = bias.len();
        if kernel.shape() != [channels, 1, 3, 3] || bias.rank() != 1 {
            tract_onnx::tract_core::internal::bail!(
                "first layer: kernel {:?} and bias {:?}",
                kernel.shape(),
                bias.shape()
            );
        }
        let values = |t: &TValue| -> TractResult<Vec<f32>> {
            Ok(t.try_as_plain_ram()?.as_slice::<f32>()?.to_vec())
        };
        Ok((values(kernel)?, values(bias)?))
    }

    /// Removes the layer from the graph: the next convolution reads the graph input, which will
    /// hold the stem's output with its padding, so the convolution pads nothing.
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
        let (hi, lo) = (self.conv.max(self.relu), self.conv.min(self.relu));
        graph.node.remove(hi);
        graph.node.remove(lo);
    }
}

/// Op types of the nodes of an ONNX graph, as stored (for the tests that check how the shipped
/// networks are written).
#[cfg(test)]
pub(crate) fn onnx_op_types(bytes: &[u8]) -> Vec<String> {
    let proto = tract_onnx::onnx()
        .proto_model_for_read(&mut &*bytes)
        .unwrap();
    proto
        .graph
        .unwrap()
        .node
        .into_iter()
        .map(|n| n.op_type)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::onnx_op_types as op_types;
    use super::*;
    use crate::landmarks::EMBEDDED_FILES;

    /// Input shapes of the shipped networks as `M3` runs them (the eye zone: both eyes at once).
    fn shipped_inputs(name: &str) -> Vec<(&'static str, Vec<usize>)> {
        let patch = |b, h, w| vec![("patch", vec![b, 1, h, w]), ("yaw", vec![b, 5])];
        match name {
            "level1.onnx" => vec![("image", vec![1, 1, 64, 64])],
            "face.onnx" | "mouth.onnx" => patch(1, 48, 48),
            "mouth_fine.onnx" => patch(1, 40, 48),
            "brows.onnx" => patch(1, 32, 64),
            "eye.onnx" => patch(2, 24, 40),
            "nose.onnx" => patch(1, 32, 32),
            _ => panic!("unknown network {name}"),
        }
    }

    /// Every shipped network's first layer runs as a [`Stem`] (a re-export that changed that
    /// layer would silently lose the speed, `stem.rs`), with the outputs tract gives for the
    /// whole graph to float rounding.
    #[test]
    fn shipped_networks_run_their_first_layer_as_a_stem_with_the_same_outputs() {
        for (name, bytes) in EMBEDDED_FILES.iter().filter(|(n, _)| n.ends_with(".onnx")) {
            let shapes = shipped_inputs(name);
            let inputs: Vec<(&str, &[usize])> =
                shapes.iter().map(|(n, s)| (*n, s.as_slice())).collect();
            let mut with = Net::load(name, bytes, &inputs, &[]).unwrap();
            let mut without = Net::load_with_stem(name, bytes, &inputs, &[], false).unwrap();
            assert!(
                with.stem.is_some(),
                "{name}: first layer not taken as a stem"
            );
            assert!(without.stem.is_none());
            for net in [&mut with, &mut without] {
                // A varied image in 0..1 and a yaw distribution (the networks' input ranges).
                net.fill_input(0, |x| {
                    x.iter_mut()
                        .enumerate()
                        .for_each(|(i, v)| *v = ((i * 7919) % 251) as f32 / 250.0)
                })
                .unwrap();
                if inputs.len() > 1 {
                    net.fill_input(1, |x| {
                        x.iter_mut()
                            .enumerate()
                            .for_each(|(i, v)| *v = [0.05, 0.1, 0.7, 0.1, 0.05][i % 5])
                    })
                    .unwrap();
                }
                net.run().unwrap();
            }
            assert_eq!(with.outputs.len(), without.outputs.len());
            for (a, b) in with.outputs.iter().zip(&without.outputs) {
                let (a, b) = (
                    a.try_as_plain_ram()
                        .unwrap()
                        .as_slice::<f32>()
                        .unwrap()
                        .to_vec(),
                    b.try_as_plain_ram()
                        .unwrap()
                        .as_slice::<f32>()
                        .unwrap()
                        .to_vec(),
                );
                assert_eq!(a.len(), b.len());
                let scale = b.iter().fold(1f32, |m, v| m.max(v.abs()));
                for (x, y) in a.iter().zip(&b) {
                    assert!((x - y).abs() <= 1e-4 * scale, "{name}: {x} vs {y}");
                }
            }
        }
    }

    /// Bytes that are no network, or a graph whose first layer is not a stem, still load (or
    /// fail with a typed error) without panicking.
    #[test]
    fn a_first_layer_of_another_form_is_left_to_tract() {
        let mut proto = tract_onnx::onnx()
            .proto_model_for_read(&mut crate::landmarks::embedded_file("nose.onnx").unwrap())
            .unwrap();
        let shapes = vec![vec![1, 1, 32, 32], vec![1, 5]];
        assert!(StemLayer::find(&proto, &shapes).is_some());
        // Wrong input count, a two-channel input, stride 1: no stem.
        assert!(StemLayer::find(&proto, &shapes[..1]).is_none());
        assert!(StemLayer::find(&proto, &[vec![1, 2, 32, 32], vec![1, 5]]).is_none());
        let graph = proto.graph.as_mut().unwrap();
        let conv = graph.node.iter_mut().find(|n| n.op_type == "Conv").unwrap();
        for a in conv.attribute.iter_mut().filter(|a| a.name == "strides") {
            a.ints = vec![1, 1];
        }
        assert!(StemLayer::find(&proto, &shapes).is_none());
    }

    /// The export's storage passes (`models/train/train_m3.py`) ran on every shipped network: a
    /// re-export without them still loads and gives the same points, so only this catches it —
    /// twice the bytes without `onnx_q8.py`, 6–7 % slower networks without `onnx_tract.py`.
    #[test]
    fn shipped_networks_have_int8_weights_and_fusable_relus() {
        let nets: Vec<_> = EMBEDDED_FILES
            .iter()
            .filter(|(name, _)| name.ends_with(".onnx"))
            .collect();
        assert_eq!(nets.len(), 7);
        for (name, bytes) in nets {
            let ops = op_types(bytes);
            assert!(
                !ops.iter().any(|o| o == "Relu"),
                "{name}: a Relu node (run models/train/onnx_tract.py)"
            );
            assert!(ops.iter().any(|o| o == "LeakyRelu"), "{name}: no LeakyRelu");
            assert!(
                ops.iter().any(|o| o == "DequantizeLinear"),
                "{name}: no int8 weights (run models/train/onnx_q8.py)"
            );
        }
    }
}
