//! The one place tract is used: an ONNX network loaded from bytes with fixed input shapes,
//! optimised once, and run through a reused plan state with reused input tensors.
//!
//! tract runs single-threaded unless its `multithread-mm` feature is enabled and an executor is
//! installed; the core enables neither, so each network runs on the calling thread.

use crate::error::{Error, Result};
use std::sync::Arc;
use tract_onnx::prelude::*;

/// A loaded network with named outputs and reusable inputs.
#[derive(Debug)]
pub(crate) struct Net {
    state: TypedSimpleState,
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
    pub(crate) fn load(
        what: &str,
        bytes: &[u8],
        inputs: &[(&str, &[usize])],
        outputs: &[&str],
    ) -> Result<Self> {
        crate::cpu::select_tract_kernels();
        let mut model = tract_onnx::onnx()
            .model_for_read(&mut &*bytes)
            .map_err(load_err(what))?;
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
        for (i, (_, shape)) in inputs.iter().enumerate() {
            model
                .set_input_fact(i, f32::fact(*shape).into())
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
        let inputs = inputs
            .iter()
            .map(|(_, shape)| Tensor::zero::<f32>(shape).map(Arc::new))
            .collect::<TractResult<Vec<_>>>()
            .map_err(load_err(what))?;
        Ok(Self {
            state,
            inputs,
            output_slots,
            outputs: tvec![],
        })
    }

    /// Calls `fill` with input `i`'s values (row-major, its fixed shape) to overwrite them.
    pub(crate) fn fill_input(&mut self, i: usize, fill: impl FnOnce(&mut [f32])) -> Result<()> {
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
    use crate::landmarks::EMBEDDED_FILES;

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
