//! A fully convolutional network (the detector) planned per input shape: its first 3×3 layers in
//! [`Stem`], what follows in [`Tail`] where those layers multiply in the 128-bit form (aarch64,
//! x86-64's portable path), so a run there allocates nothing after warm-up; elsewhere in an
//! optimised tract plan, which allocates its intermediate tensors on each run.

use super::stem::{Stem, StemWeights, with_f32_slice};
use super::tail::{Tail, TailWeights};
use crate::{Error, Result};
use std::sync::Arc;
use tract_core::internal::*;

/// Plans cached per input shape. A video stream needs one; a batch of still images of a few sizes
/// needs a handful. The least recently used plan is dropped beyond this.
const MAX_PLANS: usize = 6;

type Plan = Arc<TypedSimplePlan>;
type State = TypedSimpleState;

/// The network for one input shape, with its reused buffers.
struct ShapePlan {
    h: usize,
    w: usize,
    /// The network's first layers ([`Stem`]); the body's input is then their output.
    stem: Option<Stem>,
    body: Body,
    last_used: u64,
}

/// What runs after the first layers.
enum Body {
    /// tract's optimised plan, its reused input tensor and the last run's outputs.
    Tract {
        state: Box<State>,
        input: Arc<Tensor>,
        outputs: TVec<TValue>,
    },
    /// The blocks and heads in the library's kernels ([`Tail`]).
    Tail(Box<Tail>),
}

impl ShapePlan {
    /// Runs the network on the `h × w` input `fill` writes.
    fn run(&mut self, fill: impl FnOnce(&mut [f32])) -> Result<()> {
        match (&mut self.stem, &mut self.body) {
            (Some(stem), Body::Tail(tail)) => {
                fill(stem.input_mut());
                stem.run(tail.input_mut());
                tail.run();
                Ok(())
            }
            (None, Body::Tail(_)) => Err(Error::Internal("network tail without a stem".into())),
            (
                stem,
                Body::Tract {
                    state,
                    input,
                    outputs,
                },
            ) => {
                match stem {
                    Some(stem) => {
                        fill(stem.input_mut());
                        with_f32_slice(input, |buf| stem.run(buf))
                    }
                    None => with_f32_slice(input, fill),
                }
                .map_err(internal)?;
                let run = state.run(tvec![input.clone().into_tvalue()]);
                super::tract::clear_upper_vector_state();
                *outputs = run.map_err(internal)?;
                Ok(())
            }
        }
    }

    /// Output `k` of the last run: its `channels` planes, rows and columns.
    fn output(&self, k: usize, channels: usize) -> Result<(&[f32], usize, usize)> {
        let missing = || Error::Internal(format!("network output {k} missing"));
        let (data, gh, gw) = match &self.body {
            Body::Tail(tail) => tail.output(k).ok_or_else(missing)?,
            Body::Tract { outputs, .. } => {
                let t = outputs.get(k).ok_or_else(missing)?;
                let shape = t.shape();
                if shape.len() != 4 || shape[1] != channels {
                    return Err(Error::Internal(format!("network output shape {shape:?}")));
                }
                let view = t.try_as_plain_ram().map_err(internal)?;
                (
                    view.as_slice::<f32>().map_err(internal)?,
                    shape[2],
                    shape[3],
                )
            }
        };
        if data.len() != channels * gh * gw {
            return Err(Error::Internal(format!(
                "network output of {} values for {channels} channels of {gh}x{gw} cells",
                data.len()
            )));
        }
        Ok((data, gh, gw))
    }
}

/// A fully convolutional one-channel-input network, planned per input shape on first use. Not
/// `Clone`: it owns tract plans; make one per thread.
pub(crate) struct FullyConvNet {
    what: &'static str,
    /// The network without its first layers when they run as a [`Stem`].
    model: super::onnx::pb::ModelProto,
    stem: Option<StemWeights>,
    /// What follows the first layers, where it has the form [`Tail`] computes: read from the
    /// graph by the first plan that runs it (`None` until then; `Some(None)` where the graph has
    /// another form), so CPUs whose plans keep these layers in tract never read it.
    tail: Option<Option<TailWeights>>,
    plans: Vec<ShapePlan>,
    /// The plan of the last run.
    last: Option<usize>,
    tick: u64,
}

fn internal(e: impl std::fmt::Display) -> Error {
    Error::Internal(format!("network: {e}"))
}

impl FullyConvNet {
    /// Loads `bytes` (ONNX, one input of `1 × 1 × h × w`), wiring it once for an input of
    /// `nominal` (rows, columns) so that a network that does not load fails here rather than on
    /// the first run. `what` names the network in errors.
    ///
    /// # Errors
    /// [`Error::ModelLoad`] when the bytes do not parse or the graph does not wire.
    pub(crate) fn load(what: &'static str, bytes: &[u8], nominal: [usize; 2]) -> Result<Self> {
        super::tract::select_tract_kernels();
        let load = |e: TractError| Error::ModelLoad(format!("{what}: {e:#}"));
        let mut proto = super::onnx::parse(bytes).map_err(load)?;
        // The first layer does not depend on the input size: any shape finds and computes it.
        let nominal = [vec![1, 1, nominal[0], nominal[1]]];
        let stem = StemWeights::split_from(&mut proto, &nominal).map_err(load)?;
        let shape = stem.as_ref().map_or(nominal[0].clone(), |w| {
            Stem::new(1, nominal[0][2], nominal[0][3], w)
                .output_shape()
                .to_vec()
        });
        super::onnx::typed_model(&proto, &[shape]).map_err(load)?;
        Ok(Self {
            what,
            model: proto,
            stem,
            tail: None,
            plans: Vec::with_capacity(MAX_PLANS),
            last: None,
            tick: 0,
        })
    }

    /// The number of input shapes planned (for `Debug` output).
    pub(crate) fn plans(&self) -> usize {
        self.plans.len()
    }

    /// Runs the network on an `h × w` input that `fill` writes (row-major, `h · w` values),
    /// planning that shape first when it is new.
    ///
    /// # Errors
    /// [`Error::ModelLoad`] if the shape cannot be planned, [`Error::Internal`] if the run fails.
    pub(crate) fn run(&mut self, h: usize, w: usize, fill: impl FnOnce(&mut [f32])) -> Result<()> {
        let idx = self.plan_for(h, w)?;
        self.last = None;
        self.plans[idx].run(fill)?;
        self.last = Some(idx);
        Ok(())
    }

    /// Output `k` of the last run, of `channels` planes: its values, rows and columns.
    ///
    /// # Errors
    /// [`Error::Internal`] before a run, for a missing output or one of another shape.
    pub(crate) fn output(&self, k: usize, channels: usize) -> Result<(&[f32], usize, usize)> {
        let idx = self
            .last
            .ok_or_else(|| Error::Internal(format!("{}: no run to read", self.what)))?;
        self.plans[idx].output(k, channels)
    }

    /// Index of the plan for a `h × w` network input, building and caching it when new.
    fn plan_for(&mut self, h: usize, w: usize) -> Result<usize> {
        self.tick += 1;
        if let Some(i) = self.plans.iter().position(|p| p.h == h && p.w == w) {
            self.plans[i].last_used = self.tick;
            return Ok(i);
        }
        let mut stem = self
            .stem
            .as_ref()
            .map(|weights| Stem::new(1, h, w, weights));
        let shape = stem.as_ref().map_or([1, 1, h, w], Stem::output_shape);
        // The tail in the library's kernels where the first layers run in the same form.
        let in_kernels = super::conv::f32x4_products();
        if in_kernels && self.tail.is_none() {
            self.tail = Some(match &self.stem {
                Some(weights) => TailWeights::from_proto(&self.model, shape[1], weights.next_pad)
                    .map_err(|e| Error::ModelLoad(format!("{}: {e:#}", self.what)))?,
                None => None,
            });
        }
        let tail = match (&mut stem, self.tail.as_ref().and_then(Option::as_ref)) {
            (Some(stem), Some(weights)) if in_kernels => {
                if !stem.interleave_output() {
                    return Err(Error::Internal(
                        "network tail after a first layer that writes planes only".into(),
                    ));
                }
                let tail = Tail::new(weights, shape[2] - 2, shape[3] - 2);
                if tail.input_len() != stem.output_len() {
                    return Err(Error::Internal(format!(
                        "network tail input {} for a stem output of {}",
                        tail.input_len(),
                        stem.output_len()
                    )));
                }
                Some(tail)
            }
            _ => None,
        };
        let body = match tail {
            Some(tail) => Body::Tail(Box::new(tail)),
            None => {
                let typed = super::onnx::typed_model(&self.model, &[shape.to_vec()])
                    .and_then(|m| m.into_optimized())
                    .map_err(|e| Error::ModelLoad(format!("{} plan {w}x{h}: {e}", self.what)))?;
                let plan: Plan = typed
                    .into_runnable()
                    .map_err(|e| Error::ModelLoad(format!("{} plan {w}x{h}: {e}", self.what)))?;
                Body::Tract {
                    state: Box::new(plan.spawn().map_err(internal)?),
                    // Zeros: with a stem, the border is the second layer's padding and stays
                    // zero.
                    input: Arc::new(Tensor::zero::<f32>(&shape).map_err(internal)?),
                    outputs: tvec![],
                }
            }
        };
        let entry = ShapePlan {
            h,
            w,
            stem,
            body,
            last_used: self.tick,
        };
        if self.plans.len() >= MAX_PLANS {
            let (oldest, _) = self
                .plans
                .iter()
                .enumerate()
                .min_by_key(|(_, p)| p.last_used)
                .ok_or_else(|| Error::Internal("empty plan cache at capacity".into()))?;
            self.plans[oldest] = entry;
            Ok(oldest)
        } else {
            self.plans.push(entry);
            Ok(self.plans.len() - 1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::MODEL_ONNX;
    use tract_onnx::prelude::InferenceModelExt;

    /// The shipped network's first layer runs as a [`Stem`], with the heads tract gives for the
    /// whole graph to float rounding (odd and even sizes).
    #[test]
    fn first_layer_runs_as_a_stem_with_the_whole_graphs_outputs() {
        let whole = tract_onnx::onnx()
            .model_for_read(&mut std::io::Cursor::new(MODEL_ONNX))
            .unwrap();
        // Every form of the layers' products this CPU has (`conv`).
        for ((h, w), form) in [(96, 128), (75, 101)]
            .into_iter()
            .flat_map(|s| super::super::conv::product_forms().map(move |f| (s, f)))
        {
            let mut det = FullyConvNet::load("detector", MODEL_ONNX, [64, 64]).unwrap();
            assert!(det.stem.is_some(), "first layer not taken as a stem");
            let input: Vec<f32> = (0..h * w)
                .map(|i| ((i * 7919) % 251) as f32 / 250.0)
                .collect();
            let idx = super::super::conv::building(form, || det.plan_for(h, w).unwrap());
            // Where `conv` runs, the three full 3×3 layers after the first (the fourth is
            // depthwise and stays in tract).
            let after_first = det.plans[idx].stem.as_ref().unwrap().layers_after_first();
            assert_eq!(
                after_first,
                if super::super::conv::available() {
                    3
                } else {
                    0
                }
            );
            // In the 128-bit form the blocks and heads run outside tract too.
            assert_eq!(
                matches!(det.plans[idx].body, Body::Tail(_)),
                form == super::super::conv::Products::F32x4,
                "{form:?}"
            );
            det.plans[idx]
                .run(|buf| buf.copy_from_slice(&input))
                .unwrap();
            let plan = whole
                .clone()
                .with_input_fact(0, f32::fact([1, 1, h, w]).into())
                .and_then(|m| m.into_optimized())
                .and_then(|m| m.into_runnable())
                .unwrap();
            let t = Tensor::from_shape(&[1, 1, h, w], &input).unwrap();
            let theirs = plan.run(tvec![t.into_tvalue()]).unwrap();
            assert!(
                det.plans[idx].output(theirs.len(), 5).is_err(),
                "an extra head"
            );
            for (k, b) in theirs.iter().enumerate() {
                let (a, gh, gw) = det.plans[idx].output(k, 5).unwrap();
                assert_eq!([1, 5, gh, gw], b.shape(), "head {k}");
                let b = b.try_as_plain_ram().unwrap();
                let b = b.as_slice::<f32>().unwrap();
                super::super::stem::assert_close_to_whole_graph(
                    &format!("{h}x{w} {form:?}"),
                    a,
                    b,
                    form,
                );
            }
        }
    }
}
