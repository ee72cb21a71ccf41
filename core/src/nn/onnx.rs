//! The ONNX front end of the shipped networks: ONNX bytes to a tract `TypedModel`, for the
//! operators the networks use, without tract-onnx's operator registry.
//!
//! tract-onnx's front end registers every ONNX operator it knows (and, through them, tract's
//! inference layer, its NNEF layer and most of tract-core's operators); linked into the phone
//! library that was over half of its size. Here the protobuf messages the networks need are
//! declared in [`pb`] (prost skips every other field), and the graph is wired with tract-core
//! operators directly, the way tract-onnx's own expansions wire them
//! (`Conv`, `LeakyRelu`, `Gemm` as an `EinSum` plus a bias, `Flatten` as a reshape, `Concat`,
//! and `Add`/`Sub`/`Mul`/`Div` with rank broadcasting). Weights stored as `DequantizeLinear` of
//! int8, `Cast` of float16 or `Constant` nodes are evaluated here, once, at load. Anything else
//! is a typed error naming the operator. The tests hold every shipped network's outputs to what
//! tract-onnx computes for the same bytes.

use pb::{AttributeProto, GraphProto, ModelProto, NodeProto, TensorProto};
use std::collections::HashMap;
use tract_core::axes::AxesMapping;
use tract_core::internal::*;
use tract_core::internal::{bail, ensure, format_err};
use tract_core::ops::array::TypedConcat;
use tract_core::ops::change_axes::{AxisOp, wire_with_rank_broadcast};
use tract_core::ops::cnn::{Conv, KernelFormat, PaddingSpec, PoolSpec};
use tract_core::ops::einsum::EinSum;
use tract_core::ops::math;
use tract_core::ops::nn::{DataFormat, leaky_relu};

/// The ONNX protobuf messages (`onnx.proto`), with the fields the networks use; prost skips the
/// others when decoding.
pub(crate) mod pb {
    /// A whole model file.
    #[derive(Clone, PartialEq, prost::Message)]
    pub struct ModelProto {
        #[prost(message, optional, tag = "7")]
        pub graph: Option<GraphProto>,
    }

    /// The network.
    #[derive(Clone, PartialEq, prost::Message)]
    pub struct GraphProto {
        #[prost(message, repeated, tag = "1")]
        pub node: Vec<NodeProto>,
        #[prost(string, tag = "2")]
        pub name: String,
        #[prost(message, repeated, tag = "5")]
        pub initializer: Vec<TensorProto>,
        #[prost(message, repeated, tag = "11")]
        pub input: Vec<ValueInfoProto>,
        #[prost(message, repeated, tag = "12")]
        pub output: Vec<ValueInfoProto>,
    }

    /// A graph input or output (its name; the type is not read).
    #[derive(Clone, PartialEq, prost::Message)]
    pub struct ValueInfoProto {
        #[prost(string, tag = "1")]
        pub name: String,
    }

    /// One operator.
    #[derive(Clone, PartialEq, prost::Message)]
    pub struct NodeProto {
        #[prost(string, repeated, tag = "1")]
        pub input: Vec<String>,
        #[prost(string, repeated, tag = "2")]
        pub output: Vec<String>,
        #[prost(string, tag = "3")]
        pub name: String,
        #[prost(string, tag = "4")]
        pub op_type: String,
        #[prost(message, repeated, tag = "5")]
        pub attribute: Vec<AttributeProto>,
        #[prost(string, tag = "7")]
        pub domain: String,
    }

    /// An operator's attribute.
    #[derive(Clone, PartialEq, prost::Message)]
    pub struct AttributeProto {
        #[prost(string, tag = "1")]
        pub name: String,
        #[prost(float, tag = "2")]
        pub f: f32,
        #[prost(int64, tag = "3")]
        pub i: i64,
        #[prost(bytes = "vec", tag = "4")]
        pub s: Vec<u8>,
        #[prost(message, optional, tag = "5")]
        pub t: Option<TensorProto>,
        #[prost(float, repeated, tag = "7")]
        pub floats: Vec<f32>,
        #[prost(int64, repeated, tag = "8")]
        pub ints: Vec<i64>,
        #[prost(int32, tag = "20")]
        pub r#type: i32,
    }

    /// A constant tensor.
    #[derive(Clone, PartialEq, prost::Message)]
    pub struct TensorProto {
        #[prost(int64, repeated, tag = "1")]
        pub dims: Vec<i64>,
        #[prost(int32, tag = "2")]
        pub data_type: i32,
        #[prost(float, repeated, tag = "4")]
        pub float_data: Vec<f32>,
        #[prost(int32, repeated, tag = "5")]
        pub int32_data: Vec<i32>,
        #[prost(int64, repeated, tag = "7")]
        pub int64_data: Vec<i64>,
        #[prost(string, tag = "8")]
        pub name: String,
        #[prost(bytes = "vec", tag = "9")]
        pub raw_data: Vec<u8>,
    }
}

/// ONNX `TensorProto.DataType` codes read here.
const FLOAT: i32 = 1;
const UINT8: i32 = 2;
const INT8: i32 = 3;
const INT32: i32 = 6;
const INT64: i32 = 7;
const FLOAT16: i32 = 10;

/// Decodes ONNX bytes.
pub(crate) fn parse(bytes: &[u8]) -> TractResult<ModelProto> {
    use prost::Message;
    let proto = ModelProto::decode(bytes).map_err(|e| format_err!("not an ONNX model: {e}"))?;
    ensure!(proto.graph.is_some(), "ONNX model without a graph");
    Ok(proto)
}

/// The attribute `name` of `node`.
fn attr<'a>(node: &'a NodeProto, name: &str) -> Option<&'a AttributeProto> {
    node.attribute.iter().find(|a| a.name == name)
}

fn attr_i(node: &NodeProto, name: &str, default: i64) -> i64 {
    attr(node, name).map_or(default, |a| a.i)
}

fn attr_f(node: &NodeProto, name: &str, default: f32) -> f32 {
    attr(node, name).map_or(default, |a| a.f)
}

fn attr_usizes(node: &NodeProto, name: &str) -> TractResult<Option<TVec<usize>>> {
    let Some(a) = attr(node, name) else {
        return Ok(None);
    };
    a.ints
        .iter()
        .map(|&v| usize::try_from(v).map_err(|_| format_err!("{}: {name} {v}", node.name)))
        .collect::<TractResult<TVec<usize>>>()
        .map(Some)
}

/// The values of an ONNX tensor, for the element types the networks store.
fn tensor(t: &TensorProto) -> TractResult<Tensor> {
    let shape = t
        .dims
        .iter()
        .map(|&d| usize::try_from(d).map_err(|_| format_err!("tensor {}: dim {d}", t.name)))
        .collect::<TractResult<Vec<usize>>>()?;
    let len = shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| format_err!("tensor {}: too large", t.name))?;
    let raw = t.raw_data.as_slice();
    let width = match t.data_type {
        FLOAT | INT32 => 4,
        INT64 => 8,
        FLOAT16 => 2,
        UINT8 | INT8 => 1,
        other => bail!("tensor {}: element type {other} not supported", t.name),
    };
    let from_raw = !raw.is_empty();
    let stored = if from_raw {
        raw.len() / width
    } else {
        match t.data_type {
            FLOAT => t.float_data.len(),
            INT64 => t.int64_data.len(),
            _ => t.int32_data.len(),
        }
    };
    ensure!(
        stored == len && (!from_raw || raw.len() == len * width),
        "tensor {}: {} values stored for shape {shape:?}",
        t.name,
        stored
    );
    fn build<T: Datum + Copy>(shape: &[usize], v: Vec<T>) -> TractResult<Tensor> {
        Tensor::from_shape(shape, &v)
    }
    let le4 = |c: &[u8]| [c[0], c[1], c[2], c[3]];
    match t.data_type {
        FLOAT if from_raw => build(
            &shape,
            raw.chunks_exact(4)
                .map(|c| f32::from_le_bytes(le4(c)))
                .collect(),
        ),
        FLOAT => build(&shape, t.float_data.clone()),
        INT32 if from_raw => build(
            &shape,
            raw.chunks_exact(4)
                .map(|c| i32::from_le_bytes(le4(c)))
                .collect(),
        ),
        INT32 => build(&shape, t.int32_data.clone()),
        INT64 if from_raw => build(
            &shape,
            raw.chunks_exact(8)
                .map(|c| i64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
                .collect(),
        ),
        INT64 => build(&shape, t.int64_data.clone()),
        FLOAT16 if from_raw => build(
            &shape,
            raw.chunks_exact(2)
                .map(|c| f16::from_bits(u16::from_le_bytes([c[0], c[1]])))
                .collect(),
        ),
        FLOAT16 => build(
            &shape,
            t.int32_data
                .iter()
                .map(|&v| f16::from_bits(v as u16))
                .collect(),
        ),
        UINT8 if from_raw => build(&shape, raw.to_vec()),
        UINT8 => build(&shape, t.int32_data.iter().map(|&v| v as u8).collect()),
        INT8 if from_raw => build(&shape, raw.iter().map(|&v| v as i8).collect()),
        _ => build(&shape, t.int32_data.iter().map(|&v| v as i8).collect()),
    }
}

/// `t` as float32 values.
fn to_f32(t: &Tensor) -> TractResult<Tensor> {
    t.cast_to::<f32>().map(|c| c.into_owned())
}

/// `DequantizeLinear(x, scale, zero)` along `axis` (ONNX's default 1; a scalar scale applies to
/// the whole tensor).
fn dequantize(x: &Tensor, scale: &Tensor, zero: Option<&Tensor>, axis: i64) -> TractResult<Tensor> {
    let xv = to_f32(x)?;
    let scale = to_f32(scale)?;
    let zero = zero.map(to_f32).transpose()?;
    let (s, z) = (
        scale.try_as_plain_ram()?.as_slice::<f32>()?.to_vec(),
        match &zero {
            Some(z) => z.try_as_plain_ram()?.as_slice::<f32>()?.to_vec(),
            None => vec![0.0; scale.len()],
        },
    );
    ensure!(
        z.len() == s.len(),
        "DequantizeLinear: {} scales, {} zero points",
        s.len(),
        z.len()
    );
    let shape = x.shape().to_vec();
    let mut out = xv;
    let mut plain = out.try_as_plain_ram_mut()?;
    let values = plain.as_slice_mut::<f32>()?;
    if s.len() == 1 {
        values.iter_mut().for_each(|v| *v = (*v - z[0]) * s[0]);
        return Ok(out);
    }
    let rank = shape.len() as i64;
    let axis = if axis < 0 { axis + rank } else { axis };
    ensure!(
        (0..rank).contains(&axis) && shape[axis as usize] == s.len(),
        "DequantizeLinear: {} scales for axis {axis} of {shape:?}",
        s.len()
    );
    let inner: usize = shape[axis as usize + 1..].iter().product();
    for (i, v) in values.iter_mut().enumerate() {
        let c = (i / inner.max(1)) % s.len();
        *v = (*v - z[c]) * s[c];
    }
    Ok(out)
}

/// The graph's constant values by name: initializers, and the outputs of `Constant`, `Cast` and
/// `DequantizeLinear` nodes whose inputs are constants (how the networks store weights).
pub(crate) fn constants(graph: &GraphProto) -> TractResult<HashMap<String, Tensor>> {
    let mut values = HashMap::new();
    for t in &graph.initializer {
        values.insert(t.name.clone(), tensor(t)?);
    }
    for node in &graph.node {
        let known = |n: &String| n.is_empty() || values.contains_key(n);
        if !node.input.iter().all(known) || node.output.is_empty() {
            continue;
        }
        let input = |i: usize| {
            node.input
                .get(i)
                .filter(|n| !n.is_empty())
                .and_then(|n| values.get(n))
        };
        let value = match node.op_type.as_str() {
            "Constant" => match attr(node, "value").and_then(|a| a.t.as_ref()) {
                Some(t) => tensor(t)?,
                None => bail!("Constant {}: no tensor value", node.name),
            },
            "Cast" => {
                let x = input(0).ok_or_else(|| format_err!("Cast {}: no input", node.name))?;
                match attr_i(node, "to", 0) as i32 {
                    FLOAT => to_f32(x)?,
                    to => bail!("Cast {}: to type {to} not supported", node.name),
                }
            }
            "DequantizeLinear" => {
                let (Some(x), Some(scale)) = (input(0), input(1)) else {
                    bail!("DequantizeLinear {}: inputs missing", node.name);
                };
                dequantize(x, scale, input(2), attr_i(node, "axis", 1))?
            }
            _ => continue,
        };
        values.insert(node.output[0].clone(), value);
    }
    Ok(values)
}

/// The padding of a `Conv` node.
fn padding(node: &NodeProto, spatial: usize) -> TractResult<PaddingSpec> {
    let auto = attr(node, "auto_pad").map_or(&b""[..], |a| a.s.as_slice());
    Ok(match auto {
        b"" | b"NOTSET" => match attr_usizes(node, "pads")? {
            Some(p) => {
                ensure!(p.len() == 2 * spatial, "Conv {}: pads {p:?}", node.name);
                PaddingSpec::Explicit(p[..spatial].into(), p[spatial..].into())
            }
            None => PaddingSpec::Valid,
        },
        b"VALID" => PaddingSpec::Valid,
        b"SAME_UPPER" => PaddingSpec::SameUpper,
        b"SAME_LOWER" => PaddingSpec::SameLower,
        other => bail!(
            "Conv {}: auto_pad {}",
            node.name,
            String::from_utf8_lossy(other)
        ),
    })
}

/// The network as a tract `TypedModel` (not yet optimised) with float32 inputs of `shapes`, in
/// the order of the graph's inputs that are not initializers; its outputs are labelled with the
/// graph's output names and its sources named as the graph's inputs.
pub(crate) fn typed_model(proto: &ModelProto, shapes: &[Vec<usize>]) -> TractResult<TypedModel> {
    let graph = proto
        .graph
        .as_ref()
        .ok_or_else(|| format_err!("ONNX model without a graph"))?;
    let constants = constants(graph)?;
    let mut model = TypedModel::default();
    let mut wires: HashMap<String, OutletId> = HashMap::new();
    let inputs: Vec<&str> = graph
        .input
        .iter()
        .map(|i| i.name.as_str())
        .filter(|n| !constants.contains_key(*n))
        .collect();
    ensure!(
        inputs.len() == shapes.len(),
        "{} inputs, expected {}",
        inputs.len(),
        shapes.len()
    );
    for (name, shape) in inputs.iter().zip(shapes) {
        let source = model.add_source(*name, f32::fact(shape))?;
        wires.insert(name.to_string(), source);
    }
    for node in &graph.node {
        if node
            .output
            .first()
            .is_some_and(|o| constants.contains_key(o))
        {
            continue;
        }
        let name = if node.name.is_empty() {
            node.output.first().cloned().unwrap_or_default()
        } else {
            node.name.clone()
        };
        // An input: a wire, or a constant added to the graph on first use.
        let mut input = |model: &mut TypedModel, i: usize| -> TractResult<OutletId> {
            let n = node
                .input
                .get(i)
                .filter(|n| !n.is_empty())
                .ok_or_else(|| format_err!("{name}: input {i} missing"))?;
            if let Some(w) = wires.get(n) {
                return Ok(*w);
            }
            let c = constants
                .get(n)
                .ok_or_else(|| format_err!("{name}: unknown input {n}"))?;
            let w = model.add_const(n.clone(), to_f32(c)?)?;
            wires.insert(n.clone(), w);
            Ok(w)
        };
        let constant = |i: usize| -> TractResult<Tensor> {
            let n = node.input.get(i).map_or("", |n| n.as_str());
            constants
                .get(n)
                .ok_or_else(|| format_err!("{name}: input {i} is not a constant"))
                .and_then(to_f32)
        };
        let out = match node.op_type.as_str() {
            "Conv" => {
                let x = input(&mut model, 0)?;
                let kernel = constant(1)?;
                let ks = kernel.shape().to_vec();
                ensure!(ks.len() == 4, "{name}: kernel {ks:?}");
                let group = usize::try_from(attr_i(node, "group", 1))
                    .ok()
                    .filter(|&g| g > 0 && ks[0] % g == 0)
                    .ok_or_else(|| format_err!("{name}: group"))?;
                let bias = if node.input.get(2).is_some_and(|n| !n.is_empty()) {
                    let b = constant(2)?;
                    ensure!(b.shape() == [ks[0]], "{name}: bias {:?}", b.shape());
                    b
                } else {
                    Tensor::zero::<f32>(&[ks[0]])?
                };
                let spec = PoolSpec {
                    data_format: DataFormat::NCHW,
                    kernel_shape: ks[2..].into(),
                    padding: padding(node, 2)?,
                    dilations: attr_usizes(node, "dilations")?,
                    strides: attr_usizes(node, "strides")?,
                    input_channels: ks[1] * group,
                    output_channels: ks[0],
                };
                let k = model.add_const(format!("{name}.kernel"), kernel)?;
                let b = model.add_const(format!("{name}.bias"), bias)?;
                model.wire_node(
                    &name,
                    Conv::new(spec, KernelFormat::OIHW, group, None),
                    &[x, k, b],
                )?[0]
            }
            "Relu" => {
                let x = input(&mut model, 0)?;
                model.wire_node(&name, leaky_relu(0.0), &[x])?[0]
            }
            "LeakyRelu" => {
                let x = input(&mut model, 0)?;
                model.wire_node(&name, leaky_relu(attr_f(node, "alpha", 0.01)), &[x])?[0]
            }
            "Gemm" => {
                let (a, b) = (input(&mut model, 0)?, input(&mut model, 1)?);
                let axes = AxesMapping::for_numpy_matmul(
                    2,
                    attr_i(node, "transA", 0) != 0,
                    attr_i(node, "transB", 0) != 0,
                    false,
                )?;
                let mut wire = model.wire_node(
                    format!("{name}.ab"),
                    EinSum::new(axes, f32::datum_type()),
                    &[a, b],
                )?[0];
                let (alpha, beta) = (attr_f(node, "alpha", 1.0), attr_f(node, "beta", 1.0));
                if alpha != 1.0 {
                    let k = model.add_const(format!("{name}.alpha"), tensor2(&[[alpha]]))?;
                    wire = model.wire_node(format!("{name}.alpha_ab"), math::mul(), &[k, wire])?[0];
                }
                if beta != 0.0 && node.input.get(2).is_some_and(|n| !n.is_empty()) {
                    let mut c = constant(2)?;
                    if beta != 1.0 {
                        c.try_as_plain_ram_mut()?
                            .as_slice_mut::<f32>()?
                            .iter_mut()
                            .for_each(|v| *v *= beta);
                    }
                    let c = model.add_const(format!("{name}.c"), c)?;
                    wire = wire_with_rank_broadcast(&name, &mut model, math::add(), &[wire, c])?[0];
                }
                wire
            }
            "Flatten" => {
                let x = input(&mut model, 0)?;
                let shape = model.outlet_fact(x)?.shape.to_tvec();
                let rank = shape.len() as i64;
                let axis = attr_i(node, "axis", 1);
                let axis = if axis < 0 { axis + rank } else { axis };
                ensure!((0..=rank).contains(&axis), "{name}: axis {axis}");
                let (outer, inner) = shape.split_at(axis as usize);
                let prod = |d: &[TDim]| d.iter().fold(TDim::from(1), |p, x| p * x);
                model.wire_node(
                    &name,
                    AxisOp::Reshape(0, shape.clone(), tvec![prod(outer), prod(inner)]),
                    &[x],
                )?[0]
            }
            "Concat" => {
                let xs = (0..node.input.len())
                    .map(|i| input(&mut model, i))
                    .collect::<TractResult<TVec<_>>>()?;
                let rank = model.outlet_fact(xs[0])?.rank() as i64;
                let axis = attr_i(node, "axis", 0);
                let axis = if axis < 0 { axis + rank } else { axis };
                ensure!((0..rank).contains(&axis), "{name}: axis {axis}");
                model.wire_node(&name, TypedConcat::new(axis as usize), &xs)?[0]
            }
            op @ ("Add" | "Sub" | "Mul" | "Div") => {
                let (a, b) = (input(&mut model, 0)?, input(&mut model, 1)?);
                let op: Box<dyn TypedOp> = match op {
                    "Add" => Box::new(math::add()),
                    "Sub" => Box::new(math::sub()),
                    "Mul" => Box::new(math::mul()),
                    _ => Box::new(math::div()),
                };
                wire_with_rank_broadcast(&name, &mut model, op, &[a, b])?[0]
            }
            other => bail!("{name}: operator {other} is not one the shipped networks use"),
        };
        let output = node
            .output
            .first()
            .ok_or_else(|| format_err!("{name}: no output"))?;
        wires.insert(output.clone(), out);
    }
    let mut outputs = tvec![];
    for o in &graph.output {
        let w = *wires
            .get(&o.name)
            .ok_or_else(|| format_err!("output {} is not computed", o.name))?;
        model.set_outlet_label(w, o.name.clone())?;
        outputs.push(w);
    }
    model.select_output_outlets(&outputs)?;
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tract_onnx::prelude::InferenceModelExt;

    /// tract-onnx's whole front end on `bytes` with inputs of `shapes`, then our model, on the
    /// same deterministic inputs: outputs equal to float rounding.
    pub(crate) fn assert_same_as_tract_onnx(what: &str, bytes: &[u8], shapes: &[Vec<usize>]) {
        let mut theirs = tract_onnx::onnx().model_for_read(&mut &*bytes).unwrap();
        for (i, s) in shapes.iter().enumerate() {
            theirs.set_input_fact(i, f32::fact(s).into()).unwrap();
        }
        let theirs = theirs.into_optimized().unwrap().into_runnable().unwrap();
        let ours = typed_model(&parse(bytes).unwrap(), shapes)
            .unwrap()
            .into_optimized()
            .unwrap()
            .into_runnable()
            .unwrap();
        let inputs = || -> TVec<TValue> {
            shapes
                .iter()
                .enumerate()
                .map(|(k, s)| {
                    let n: usize = s.iter().product();
                    let v: Vec<f32> = (0..n)
                        .map(|i| (((i + 13 * k) * 7919) % 251) as f32 / 250.0)
                        .collect();
                    Tensor::from_shape(s, &v).unwrap().into_tvalue()
                })
                .collect()
        };
        let (a, b) = (ours.run(inputs()).unwrap(), theirs.run(inputs()).unwrap());
        assert_eq!(a.len(), b.len(), "{what}: outputs");
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.shape(), y.shape(), "{what}");
            let x = x.try_as_plain_ram().unwrap();
            let y = y.try_as_plain_ram().unwrap();
            let (x, y) = (x.as_slice::<f32>().unwrap(), y.as_slice::<f32>().unwrap());
            let scale = y.iter().fold(1f32, |m, v| m.max(v.abs()));
            let worst = x
                .iter()
                .zip(y)
                .fold(0f32, |m, (p, q)| m.max((p - q).abs() / scale));
            assert!(worst < 1e-5, "{what}: {worst} of the scale");
        }
    }

    #[test]
    fn every_shipped_network_computes_what_tract_onnx_computes() {
        let zone = |h: usize, w: usize| vec![vec![1, 1, h, w], vec![1, 5]];
        for (file, shapes) in [
            ("level1.onnx", vec![vec![1, 1, 64, 64]]),
            ("brows.onnx", zone(32, 64)),
            ("eye.onnx", zone(24, 40)),
            ("face.onnx", zone(48, 48)),
            ("mouth.onnx", zone(48, 48)),
            ("mouth_fine.onnx", zone(40, 48)),
            ("nose.onnx", zone(40, 24)),
        ] {
            let bytes = crate::landmarks::embedded_file(file).unwrap();
            assert_same_as_tract_onnx(file, bytes, &shapes);
        }
        for shape in [[1, 1, 96, 128], [1, 1, 75, 101]] {
            let det = crate::detect::MODEL_ONNX;
            assert_same_as_tract_onnx("detector.onnx", det, &[shape.to_vec()]);
        }
    }

    #[test]
    fn bytes_that_are_no_network_are_an_error() {
        assert!(parse(b"not a model").is_err());
        assert!(parse(&[]).is_err());
        let mut bytes = crate::landmarks::embedded_file("nose.onnx")
            .unwrap()
            .to_vec();
        bytes.truncate(bytes.len() / 2);
        assert!(parse(&bytes).is_err());
    }
}
