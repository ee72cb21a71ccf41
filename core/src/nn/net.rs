//! A network of fixed input shapes loaded from ONNX bytes: its leading 3×3 layers and, after
//! them, its fully connected heads in the library's kernels where they have those forms, the rest
//! optimised once by tract and run through a reused plan state with reused input tensors.

use super::dense::Dense;
use crate::error::{Error, Result};
use crate::nn::stem::{Stem, StemWeights, with_f32_slice};
use std::sync::Arc;
use tract_core::internal::*;

/// A loaded network with named outputs and reusable inputs.
#[derive(Debug)]
pub(crate) struct Net {
    /// What runs after the first layer (the whole network when there is no stem).
    body: Body,
    /// The first layer when computed outside tract ([`Stem`]); the body's input 0 is then its
    /// output.
    stem: Option<Stem>,
    /// Output slot of each requested output name, in request order.
    output_slots: Vec<usize>,
}

/// The part of a network after its first layer.
#[derive(Debug)]
enum Body {
    /// tract's plan, its reused input tensors and the last run's outputs.
    Tract {
        state: TypedSimpleState,
        inputs: Vec<Arc<Tensor>>,
        outputs: TVec<TValue>,
    },
    /// The fully connected heads computed here, after a trunk the stem took ([`Dense`]); they
    /// hold their inputs.
    Dense(Dense),
}

fn load_err(what: &str) -> impl Fn(TractError) -> Error + '_ {
    move |e| Error::ModelLoad(format!("{what}: {e:#}"))
}

impl Net {
    /// Loads `bytes` (ONNX) with inputs of the given names and shapes (in the graph's input
    /// order) and outputs looked up by name. `what` names the network in errors.
    ///
    /// A first layer of the form [`Stem`] computes (`StemWeights::split_from`) runs outside
    /// tract, and after a trunk taken that way the fully connected heads too ([`Dense`]); the
    /// caller sees the same inputs and outputs either way.
    pub(crate) fn load(
        what: &str,
        bytes: &[u8],
        inputs: &[(&str, &[usize])],
        outputs: &[&str],
    ) -> Result<Self> {
        Self::load_with(what, bytes, inputs, outputs, true, true)
    }

    /// [`Self::load`], with the first layer left to tract unless `use_stem` and the heads unless
    /// `use_dense`.
    fn load_with(
        what: &str,
        bytes: &[u8],
        inputs: &[(&str, &[usize])],
        outputs: &[&str],
        use_stem: bool,
        use_dense: bool,
    ) -> Result<Self> {
        crate::nn::tract::select_tract_kernels();
        let mut proto = crate::nn::onnx::parse(bytes).map_err(load_err(what))?;
        let mut shapes: Vec<Vec<usize>> = inputs.iter().map(|(_, s)| s.to_vec()).collect();
        let weights = if use_stem {
            StemWeights::split_from(&mut proto, &shapes).map_err(load_err(what))?
        } else {
            None
        };
        let stem = weights.map(|weights| {
            let stem = Stem::new(shapes[0][0], shapes[0][2], shapes[0][3], &weights);
            shapes[0] = stem.output_shape().to_vec();
            stem
        });
        let want: Vec<&str> = inputs.iter().map(|(n, _)| *n).collect();
        let input_names: Vec<&str> = proto
            .graph
            .as_ref()
            .map(|g| g.input.iter().map(|i| i.name.as_str()).collect())
            .unwrap_or_default();
        // Only after a stem took the trunk is what is left the heads alone.
        let dense = if stem.is_some() && use_dense && input_names == want {
            Dense::from_proto(&proto, &shapes).map_err(load_err(what))?
        } else {
            None
        };
        if let Some(dense) = dense {
            let output_slots = outputs
                .iter()
                .map(|name| {
                    dense.output_index(name).ok_or_else(|| {
                        Error::ModelLoad(format!(
                            "{what}: no output named {name:?} (models/M3_IO.md)"
                        ))
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            return Ok(Self {
                body: Body::Dense(dense),
                stem,
                output_slots,
            });
        }
        let model = crate::nn::onnx::typed_model(&proto, &shapes).map_err(load_err(what))?;
        let names: Vec<String> = model
            .input_outlets()
            .map_err(load_err(what))?
            .iter()
            .map(|o| model.node(o.node).name.clone())
            .collect();
        if names != want {
            return Err(Error::ModelLoad(format!(
                "{what}: inputs {names:?}, expected {want:?} (models/M3_IO.md)"
            )));
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
            body: Body::Tract {
                state,
                inputs,
                outputs: tvec![],
            },
            stem,
            output_slots,
        })
    }

    /// Calls `fill` with input `i`'s values (row-major, its fixed shape) to overwrite them.
    pub(crate) fn fill_input(&mut self, i: usize, fill: impl FnOnce(&mut [f32])) -> Result<()> {
        if let (0, Some(stem)) = (i, &mut self.stem) {
            fill(stem.input_mut());
            return Ok(());
        }
        match &mut self.body {
            Body::Tract { inputs, .. } => with_input_slice(&mut inputs[i], fill),
            Body::Dense(dense) => {
                fill(dense.input_mut(i));
                Ok(())
            }
        }
    }

    /// Runs the network on the current inputs.
    pub(crate) fn run(&mut self) -> Result<()> {
        let (state, inputs, outputs) = match &mut self.body {
            Body::Dense(dense) => {
                if let Some(stem) = &mut self.stem {
                    stem.run(dense.input_mut(0));
                }
                dense.run();
                return Ok(());
            }
            Body::Tract {
                state,
                inputs,
                outputs,
            } => (state, inputs, outputs),
        };
        if let Some(stem) = &mut self.stem {
            with_input_slice(&mut inputs[0], |s| stem.run(s))?;
        }
        let values: TVec<TValue> = inputs
            .iter()
            .map(|t| TValue::from_const(Arc::clone(t)))
            .collect();
        let run = state
            .run(values)
            .map_err(|e| Error::Internal(format!("network run: {e:#}")));
        crate::nn::tract::clear_upper_vector_state();
        *outputs = run?;
        Ok(())
    }

    /// Output `k` (in the order the outputs were requested at load) of the last run.
    pub(crate) fn output(&self, k: usize) -> Result<&[f32]> {
        let outputs = match &self.body {
            Body::Dense(dense) => return Ok(dense.output(self.output_slots[k])),
            Body::Tract { outputs, .. } => outputs,
        };
        let t = outputs
            .get(self.output_slots[k])
            .ok_or_else(|| Error::Internal("network output missing".into()))?;
        t.try_as_plain_ram()
            .and_then(|v| v.as_slice::<f32>())
            .map_err(|e| Error::Internal(format!("network output: {e:#}")))
    }

    /// The heads when they run outside tract.
    #[cfg(test)]
    fn dense(&self) -> Option<&Dense> {
        match &self.body {
            Body::Dense(dense) => Some(dense),
            Body::Tract { .. } => None,
        }
    }
}

/// [`with_f32_slice`] on an input tensor.
fn with_input_slice(t: &mut Arc<Tensor>, f: impl FnOnce(&mut [f32])) -> Result<()> {
    with_f32_slice(t, f).map_err(|e| Error::Internal(format!("input tensor: {e:#}")))
}

/// The graph of an ONNX file (for the tests that check how the shipped networks are written).
#[cfg(test)]
fn onnx_graph(bytes: &[u8]) -> crate::nn::onnx::pb::GraphProto {
    crate::nn::onnx::parse(bytes).unwrap().graph.unwrap()
}

/// The graph output names of an ONNX file, in order.
#[cfg(test)]
fn onnx_output_names(bytes: &[u8]) -> Vec<String> {
    onnx_graph(bytes)
        .output
        .into_iter()
        .map(|o| o.name)
        .collect()
}

/// Op types of the nodes of an ONNX graph, as stored.
#[cfg(test)]
pub(crate) fn onnx_op_types(bytes: &[u8]) -> Vec<String> {
    onnx_graph(bytes)
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
    use crate::nn::stem::{StemLayer, assert_close_to_whole_graph};

    /// Input shapes of the shipped networks as `M3` runs them (one patch per run, the eyes too).
    fn shipped_inputs(name: &str) -> Vec<(&'static str, Vec<usize>)> {
        let patch = |b, h, w| vec![("patch", vec![b, 1, h, w]), ("yaw", vec![b, 5])];
        match name {
            "level1.onnx" => vec![("image", vec![1, 1, 64, 64])],
            "face.onnx" | "mouth.onnx" => patch(1, 48, 48),
            "mouth_fine.onnx" => patch(1, 40, 48),
            "brows.onnx" => patch(1, 32, 64),
            "eye.onnx" => patch(1, 24, 40),
            "nose.onnx" => patch(1, 40, 24),
            _ => panic!("unknown network {name}"),
        }
    }

    /// Every shipped network's first layer runs as a [`Stem`] (a re-export that changed that
    /// layer would silently lose the speed, `stem.rs`), with the outputs tract gives for the
    /// whole graph to float rounding.
    #[test]
    fn shipped_networks_run_their_first_layer_as_a_stem_with_the_same_outputs() {
        // Every form of the layers' products this CPU has (`conv`).
        for form in crate::nn::conv::product_forms() {
            for (name, bytes) in EMBEDDED_FILES.iter().filter(|(n, _)| n.ends_with(".onnx")) {
                let shapes = shipped_inputs(name);
                let inputs: Vec<(&str, &[usize])> =
                    shapes.iter().map(|(n, s)| (*n, s.as_slice())).collect();
                let names = onnx_output_names(bytes);
                let outputs: Vec<&str> = names.iter().map(String::as_str).collect();
                let mut with = crate::nn::conv::building(form, || {
                    Net::load(name, bytes, &inputs, &outputs).unwrap()
                });
                // The stem, with the heads left to tract.
                let mut tract_heads = crate::nn::conv::building(form, || {
                    Net::load_with(name, bytes, &inputs, &outputs, true, false).unwrap()
                });
                let mut without =
                    Net::load_with(name, bytes, &inputs, &outputs, false, false).unwrap();
                assert!(
                    with.stem.is_some(),
                    "{name}: first layer not taken as a stem"
                );
                assert!(without.stem.is_none());
                // Where the trunk runs outside tract, the heads do too (all the shipped heads'
                // nodes are of `Dense`'s forms).
                assert_eq!(
                    with.dense().is_some(),
                    crate::nn::conv::available(),
                    "{name}: heads outside tract"
                );
                assert!(tract_heads.dense().is_none() && without.dense().is_none());
                // Their weights are int8 times a scale per output (`onnx_q8.py`), kept that way.
                if let Some(dense) = with.dense() {
                    let (int8, layers) = dense.int8_layers();
                    assert!(
                        layers >= 2 && int8 == layers,
                        "{name}: {int8} of {layers} int8"
                    );
                    // And multiplied in int8 where the trunks are.
                    let products = if form == crate::nn::conv::Products::Vnni {
                        layers
                    } else {
                        0
                    };
                    assert_eq!(dense.int8_product_layers(), products, "{name} {form:?}");
                }
                // Where `conv` runs, every 3×3 layer after the first (all the shipped trunks' layers).
                let convs = op_types(bytes).iter().filter(|o| *o == "Conv").count();
                let after_first = with.stem.as_ref().map_or(0, Stem::layers_after_first);
                let want = if crate::nn::conv::available() {
                    convs - 1
                } else {
                    0
                };
                assert_eq!(
                    after_first, want,
                    "{name}: layers after the first run outside tract"
                );
                for net in [&mut with, &mut tract_heads, &mut without] {
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
                for (k, output) in outputs.iter().enumerate() {
                    let want = without.output(k).unwrap();
                    for net in [&with, &tract_heads] {
                        let what = format!("{name} {output} (dense {})", net.dense().is_some());
                        assert_close_to_whole_graph(&what, net.output(k).unwrap(), want, form);
                    }
                }
            }
        }
    }

    /// Bytes that are no network, or a graph whose first layer is not a stem, still load (or
    /// fail with a typed error) without panicking.
    #[test]
    fn a_first_layer_of_another_form_is_left_to_tract() {
        let mut proto =
            crate::nn::onnx::parse(crate::landmarks::embedded_file("nose.onnx").unwrap()).unwrap();
        let shapes = vec![vec![1, 1, 40, 24], vec![1, 5]];
        assert!(StemLayer::find(&proto, &shapes, false).is_some());
        assert!(StemLayer::find(&proto, &shapes, true).is_some());
        // A chain that ends at a node padding by rules of its own (a pooling's padding is no zero
        // border): nothing is taken.
        let mut padded_end = proto.clone();
        let graph = padded_end.graph.as_mut().unwrap();
        let flatten = graph
            .node
            .iter_mut()
            .find(|n| n.op_type == "Flatten")
            .unwrap();
        flatten.attribute.push(crate::nn::onnx::pb::AttributeProto {
            name: "pads".into(),
            ints: vec![1, 1, 1, 1],
            ..Default::default()
        });
        assert!(StemLayer::find(&padded_end, &shapes, true).is_none());
        // Wrong input count, a two-channel input, stride 1: no stem.
        assert!(StemLayer::find(&proto, &shapes[..1], false).is_none());
        assert!(StemLayer::find(&proto, &[vec![1, 2, 40, 24], vec![1, 5]], false).is_none());
        let graph = proto.graph.as_mut().unwrap();
        let conv = graph.node.iter_mut().find(|n| n.op_type == "Conv").unwrap();
        for a in conv.attribute.iter_mut().filter(|a| a.name == "strides") {
            a.ints = vec![1, 1];
        }
        assert!(StemLayer::find(&proto, &shapes, false).is_none());
        // A malformed graph (the second conv without inputs): no stem, no panic.
        let graph = proto.graph.as_mut().unwrap();
        for a in graph.node.iter_mut().flat_map(|n| n.attribute.iter_mut()) {
            if a.name == "strides" && a.ints == [1, 1] {
                a.ints = vec![2, 2];
            }
        }
        assert!(StemLayer::find(&proto, &shapes, false).is_some());
        let graph = proto.graph.as_mut().unwrap();
        let second = graph
            .node
            .iter()
            .filter(|n| n.op_type == "Conv")
            .nth(1)
            .unwrap()
            .name
            .clone();
        for n in graph.node.iter_mut().filter(|n| n.name == second) {
            n.input.clear();
        }
        assert!(StemLayer::find(&proto, &shapes, false).is_none());
    }

    /// The export's storage passes (`models/train/train_m3.py`) ran on every shipped network: a
    /// re-export without them still loads and gives the same points, so only this catches it
    /// (without `onnx_q8.py` the files double; without `onnx_tract.py` the networks run slower).
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
