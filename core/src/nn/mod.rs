//! The inference engine: the networks of [`crate::landmarks`] (M3) and [`crate::detect`] loaded
//! from ONNX bytes and run on caller-filled inputs into buffers they own, allocating nothing per
//! run after the first.
//!
//! The pipeline sees two types: [`Net`], a network of fixed input shapes (the M3 level-1 and
//! zone networks), and [`FullyConvNet`], a fully convolutional network planned per input shape
//! (the detector). Everything else is the engine's inside:
//!
//! | module | what it does |
//! |---|---|
//! | `onnx` | the ONNX front end: protobuf decoding and the graph wired into a tract model |
//! | `stem` | finds a network's leading 3×3 layers in the graph and cuts them out |
//! | `conv` | plans and runs those 3×3 layers in the library's kernels ([`crate::kernels::conv3x3`]) |
//! | `dense` | matches M3's fully connected heads and runs them in the library's kernels |
//! | `tail` | matches the detector's depthwise / 1×1 blocks and heads and runs them likewise |
//! | `net`, `fcn` | the two network types: what the library's kernels computes, the rest in tract |
//! | `tract` | tract's kernel choice per CPU and the vector state after its runs |
//!
//! tract is the engine's graph library (every network is read and checked by it at load) and the
//! tests' oracle (each layer the library computes is compared with tract's run of the whole
//! graph). Which layers run in tract on which CPU is in `ARCHITECTURE.md`.

pub(crate) mod conv;
pub(crate) mod dense;
mod fcn;
mod net;
pub(crate) mod onnx;
pub(crate) mod stem;
pub(crate) mod tail;
pub mod tract;

pub(crate) use fcn::FullyConvNet;
pub(crate) use net::Net;
#[cfg(test)]
pub(crate) use net::onnx_op_types;
