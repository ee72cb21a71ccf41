//! Times ONNX networks the way `core::landmarks` runs them (tract, fixed input shapes,
//! `into_optimized`, one thread): the harness behind MODEL_CARD.md's "Architecture for tract" table.
//!
//! ```text
//! python3 core/models/train/export_trunks.py /tmp/trunks level1=16s-32s-48s-48c-64s face=...
//! cargo run --release -p monotrack-core --example time_nets -- /tmp/trunks
//! ```
//!
//! Every `NAME.onnx` in the folder whose name is an M3 net (level1, face, brows, mouth, eye) runs
//! with that net's input shapes on a fixed varied input; prints the median and 10th percentile of
//! 300 runs after 20 warm-up runs.

use std::time::Instant;
use tract_onnx::prelude::*;

const NETS: [(&str, &[&[usize]]); 5] = [
    ("level1", &[&[1, 1, 64, 64]]),
    ("face", &[&[1, 1, 64, 64], &[1, 5]]),
    ("brows", &[&[1, 1, 32, 64], &[1, 5]]),
    ("mouth", &[&[1, 1, 48, 48], &[1, 5]]),
    ("eye", &[&[1, 1, 24, 40], &[1, 5]]),
];

fn main() -> TractResult<()> {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: time_nets DIR (with level1.onnx, face.onnx, ... inside)");
        std::process::exit(2);
    };
    for (name, shapes) in NETS {
        let path = format!("{dir}/{name}.onnx");
        if !std::path::Path::new(&path).exists() {
            continue;
        }
        let mut model = tract_onnx::onnx().model_for_path(&path)?;
        for (i, s) in shapes.iter().enumerate() {
            model = model.with_input_fact(i, f32::fact(*s).into())?;
        }
        let plan = model.into_optimized()?.into_runnable()?;
        // Values like a real patch (0..1, varied): zeros could take faster paths than data.
        let inputs: TVec<TValue> = shapes
            .iter()
            .map(|s| {
                let n: usize = s.iter().product();
                let v: Vec<f32> = (0..n).map(|i| ((i * 7919) % 251) as f32 / 255.0).collect();
                tract_ndarray::ArrayD::from_shape_vec(s.to_vec(), v)
                    .map(|a| TValue::from(Tensor::from(a)))
                    .map_err(TractError::from)
            })
            .collect::<TractResult<_>>()?;
        for _ in 0..20 {
            plan.run(inputs.clone())?;
        }
        let mut us: Vec<u128> = (0..300)
            .map(|_| {
                let t = Instant::now();
                plan.run(inputs.clone()).map(|_| t.elapsed().as_micros())
            })
            .collect::<TractResult<_>>()?;
        us.sort_unstable();
        println!("{name}: median {} us, p10 {} us", us[150], us[30]);
    }
    Ok(())
}
