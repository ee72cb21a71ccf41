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

mod common;

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
    let plan = common::load_plan(path, &shapes)?;
    let inputs = common::patch_like_inputs(&shapes)?;
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
