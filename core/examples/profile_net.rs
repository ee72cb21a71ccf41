//! Time per node of one ONNX network as tract runs it (fixed input shapes, `into_optimized`, one
//! thread): where a network's time goes after tract's lowering and fusing — e.g. the separate ReLU
//! passes that `core/models/train/onnx_tract.py` removes.
//!
//! ```text
//! cargo run --release -p monotrack-core --example profile_net -- core/models/m3/level1.onnx 1x1x64x64
//! cargo run --release -p monotrack-core --example profile_net -- core/models/m3/brows.onnx 1x1x32x64 1x5
//! ```
//!
//! Prints the mean µs per run of every node taking at least 0.5 µs (500 runs after 20 warm-up
//! runs) and the total over all nodes.

use std::time::Instant;
use tract_onnx::prelude::*;
use tract_onnx::tract_core::plan::eval;

const RUNS: usize = 500;
const WARM_UP: usize = 20;

fn main() -> TractResult<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((path, dims)) = args.split_first() else {
        eprintln!("usage: profile_net MODEL.onnx SHAPE... (e.g. 1x1x64x64 1x5, one per input)");
        std::process::exit(2);
    };
    let shapes: Vec<Vec<usize>> = dims
        .iter()
        .map(|s| s.split('x').map(|v| v.parse::<usize>()).collect())
        .collect::<Result<_, _>>()?;
    let mut model = tract_onnx::onnx().model_for_path(path)?;
    for (i, s) in shapes.iter().enumerate() {
        model = model.with_input_fact(i, f32::fact(s.as_slice()).into())?;
    }
    let plan = model.into_optimized()?.into_runnable()?;
    // Values like a real patch (0..1, varied), as time_nets uses.
    let inputs: TVec<TValue> = shapes
        .iter()
        .map(|s| {
            let n: usize = s.iter().product();
            let v: Vec<f32> = (0..n).map(|i| ((i * 7919) % 251) as f32 / 255.0).collect();
            tract_ndarray::ArrayD::from_shape_vec(s.clone(), v)
                .map(|a| TValue::from(Tensor::from(a)))
                .map_err(TractError::from)
        })
        .collect::<TractResult<_>>()?;
    let mut state = plan.spawn()?;
    let mut seconds = vec![0f64; plan.model().nodes().len()];
    for run in 0..WARM_UP + RUNS {
        state.run_plan_with_eval(inputs.clone(), |session, op_state, node, input| {
            let t = Instant::now();
            let out = eval(session, op_state, node, input);
            if run >= WARM_UP {
                seconds[node.id] += t.elapsed().as_secs_f64();
            }
            out
        })?;
    }
    let mut total = 0.0;
    for node in plan.model().nodes() {
        let us = seconds[node.id] / RUNS as f64 * 1e6;
        total += us;
        if us >= 0.5 {
            println!(
                "{us:8.1} us  {:>4} {} ({})",
                node.id,
                node.name,
                node.op().name()
            );
        }
    }
    println!("total {total:.1} us per run");
    Ok(())
}
