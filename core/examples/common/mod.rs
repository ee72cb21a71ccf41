//! What the network-timing examples (`time_nets`, `profile_net`) share: a network loaded the way
//! `core::landmarks` loads it (with the library's kernel choice, `monotrack_core::nn::tract`) and inputs
//! that look like real patches.

use tract_onnx::prelude::*;

/// The ONNX network at `path` with fixed input `shapes` (in the graph's input order), optimised
/// and made runnable as `core::landmarks` does (one thread).
pub fn load_plan(
    path: &str,
    shapes: &[Vec<usize>],
) -> TractResult<std::sync::Arc<TypedRunnableModel>> {
    monotrack_core::nn::tract::select_tract_kernels();
    let mut model = tract_onnx::onnx().model_for_path(path)?;
    for (i, s) in shapes.iter().enumerate() {
        model = model.with_input_fact(i, f32::fact(s.as_slice()).into())?;
    }
    model.into_optimized()?.into_runnable()
}

/// One input per shape with values like a real patch (0..1, varied): zeros could take faster
/// paths than data.
pub fn patch_like_inputs(shapes: &[Vec<usize>]) -> TractResult<TVec<TValue>> {
    shapes
        .iter()
        .map(|s| {
            let n: usize = s.iter().product();
            let v: Vec<f32> = (0..n).map(|i| ((i * 7919) % 251) as f32 / 255.0).collect();
            tract_ndarray::ArrayD::from_shape_vec(s.clone(), v)
                .map(|a| TValue::from(Tensor::from(a)))
                .map_err(TractError::from)
        })
        .collect()
}
