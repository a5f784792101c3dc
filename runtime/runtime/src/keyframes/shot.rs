//! The in-betweening design of the keyframes task (`zoo train arnn --design inbetween`, exported
//! by `zoo_arnn::inbetween_export`): one whole-shot graph call per character, instead of one
//! step per frame.
//!
//! Per character: the features of its keys ([`zoo_protocol::inbetween::InbetweenFeatures::shot`],
//! the code training uses, from the section's Euler orders, gap unit and f64 statistics); the
//! graph maps `features [batch, frames, width]` to `correction [batch, frames, dofs]`; the
//! completed pose is `b + e * correction * std` composed in f64 (the keys' Bezier pose `b`, the
//! envelope `e`, zero on every key frame fixing a value), as `zoo_arnn::inbetween::complete_shots`
//! composes it, with the residual scaled down towards the curves where the runner's fallback
//! says so ([`zoo_protocol::inbetween::Fallback`]). The graph is planned once for one shot of any number of frames, and once more
//! for any number of shots of one length where tract can ([`plan`]): the characters of a call
//! whose shots have the same number of frames then run in one graph call, so that the
//! recurrent layer's weights are read once per frame for all of them instead of once per
//! character. Unlike the step graph, a call allocates: the features, the Bezier poses and
//! tract's tensors of each shot.

use super::MotionKeys;
use crate::error::{MotionError, chain};
use crate::metadata::MotionModelMetadata;
use crate::model::Plan;
use tract_onnx::pb;
use tract_onnx::prelude::*;
use zoo_protocol::inbetween::{Fallback, InbetweenFeatures, ShotInputs};

/// The whole-shot graph of an in-betweening keyframe model, planned, with its feature settings.
#[derive(Debug)]
pub(super) struct ShotGraph {
    pub(super) metadata: MotionModelMetadata,
    /// The plan for one shot (`[1, frames, width]`).
    plan: Plan,
    /// The plan for shots of one length (`[batch, frames, width]`), when tract plans it.
    batched: Option<Plan>,
    features: InbetweenFeatures,
}

/// The dims of a graph input or output (each `None` where symbolic); `None` when it is not an
/// f32 tensor with a shape.
fn dims(v: &pb::ValueInfoProto) -> Option<Vec<Option<i64>>> {
    use pb::tensor_shape_proto::dimension::Value as D;
    let Some(pb::TypeProto { value: Some(pb::type_proto::Value::TensorType(t)), .. }) = &v.r#type else {
        return None;
    };
    if t.elem_type != pb::tensor_proto::DataType::Float as i32 {
        return None;
    }
    let shape = t.shape.as_ref()?;
    Some(
        shape
            .dim
            .iter()
            .map(|d| match &d.value {
                Some(D::DimValue(n)) => Some(*n),
                _ => None,
            })
            .collect(),
    )
}

/// Plans the graph for `batch` shots (`None`: any number) of any length (`[batch, frames,
/// width]`): tract 0.23.9 plans an ONNX `GRU` without `initial_h` only for a concrete batch size
/// (it panics on a symbolic one; the runtime's own GRU op, `crate::ops`, plans either), so a
/// planning panic is reported as an error.
fn plan(mut model: InferenceModel, batch: Option<usize>, width: usize) -> Result<Plan, MotionError> {
    let frames = model.symbols.sym("frames");
    let batch = match batch {
        Some(b) => TDim::from(b),
        None => model.symbols.sym("batch").into(),
    };
    let planned = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || -> TractResult<Plan> {
        model.set_input_fact(0, f32::fact(tvec![batch, frames.into(), TDim::from(width)]).into())?;
        crate::model::planned(model)
    }));
    match planned {
        Ok(plan) => plan.map_err(|e| MotionError::Unsupported { reason: chain(&e) }),
        Err(_) => Err(MotionError::Unsupported { reason: "tract panicked while planning the whole-shot graph".into() }),
    }
}

impl ShotGraph {
    /// Loads the graph of a `keyframes` file whose section has the in-betweening settings
    /// (the format crate checked them against the skeleton): input `features` `[batch, frames,
    /// input_width]`, output `correction` `[batch, frames, dofs]`, both f32.
    pub(super) fn load(bytes: &[u8], origin: &str, metadata: MotionModelMetadata) -> Result<Self, MotionError> {
        let section = metadata.task.as_keyframes().and_then(|t| t.inbetween.as_ref());
        let Some(section) = section else {
            return Err(MotionError::wrong_task(&metadata, "in-betweening keyframes", "KeyframeModel"));
        };
        let features = section
            .features()
            .map_err(|reason| MotionError::from(zoo_format::FormatError::bad(zoo_format::keys::KEYFRAMES, reason)))?;
        let (proto, model) = crate::model::read_graph(bytes, origin)?;
        let graph = proto.graph.as_ref().expect("read_graph checked the graph");
        let io = |vs: &[pb::ValueInfoProto]| vs.iter().map(|v| (v.name.clone(), dims(v))).collect::<Vec<_>>();
        let (inputs, outputs) = (io(&graph.input), io(&graph.output));
        let (w, d) = (features.input_width() as i64, features.dofs() as i64);
        let want_in = vec![("features".to_string(), Some(vec![None, None, Some(w)]))];
        let want_out = vec![("correction".to_string(), Some(vec![None, None, Some(d)]))];
        if inputs != want_in || outputs != want_out {
            return Err(MotionError::BadGraphIo {
                what: "input",
                name: inputs.first().map(|i| i.0.clone()).unwrap_or_default(),
                reason: format!(
                    "the in-betweening keyframes graph takes {inputs:?} and gives {outputs:?} (name, dims; None is \
                     symbolic); its section needs one f32 input `features` [batch, frames, {w}] and one f32 output \
                     `correction` [batch, frames, {d}]: re-export the model with `zoo export --onnx RUN_DIR`"
                ),
            });
        }
        // Shots of one length in one call where tract plans it (the runtime's GRU op; not tract's
        // own, kept with the runtime's ops off): one at a time otherwise.
        let tract_gru = model.nodes().iter().any(|n| n.op.name() == "GRU");
        let batched = (!tract_gru).then(|| plan(model.clone(), None, w as usize).ok()).flatten();
        let plan = plan(model, Some(1), w as usize)?;
        Ok(ShotGraph { metadata, plan, batched, features })
    }

    /// The features of each character's keys (checked by [`MotionKeys::check`] before), or the
    /// first character whose keys the in-betweening inputs (`zoo_protocol::inbetween`) refuse.
    fn shots(&self, keys: &[MotionKeys<'_>]) -> Result<Vec<ShotInputs>, MotionError> {
        let mut poses = Vec::new();
        let mut fixed = Vec::new();
        keys.iter()
            .enumerate()
            .map(|(c, k)| {
                poses.clear();
                poses.extend(k.poses.iter().map(|v| *v as f64));
                fixed.clear();
                fixed.extend(k.fixed.iter().map(|v| *v == 1.0));
                self.features
                    .shot(k.frames, &poses, &fixed)
                    .map_err(|e| MotionError::Keys { character: c, reason: e.to_string() })
            })
            .collect()
    }

    /// The graph's corrections of shots of one length (`frames x dofs` values each), in one
    /// graph call: the one-shot plan for one shot, the batched plan for more.
    fn corrections(&self, shots: &[&ShotInputs]) -> Result<Vec<Vec<f32>>, MotionError> {
        let run = |reason: String| MotionError::Run { reason };
        let (b, n, w, d) = (shots.len(), shots[0].frames, self.features.input_width(), self.features.dofs());
        let plan = match &self.batched {
            Some(batched) if b > 1 => batched,
            _ => &self.plan,
        };
        let mut x = Vec::with_capacity(b * n * w);
        shots.iter().for_each(|s| x.extend_from_slice(&s.features));
        let input = Tensor::from_shape::<f32>(&[b, n, w], &x).map_err(|e| run(chain(&e)))?;
        let result = plan.run(tvec![input.into()]).map_err(|e| run(chain(&e)))?;
        let y = result[0].try_as_plain_ram().and_then(|t| t.as_slice::<f32>()).map_err(|e| run(chain(&e)))?;
        if y.len() != b * n * d {
            return Err(run(format!("the graph returned {} values for {b} shots of {n} frames x {d}", y.len())));
        }
        if let Some(i) = y.iter().position(|v| !v.is_finite()) {
            return Err(run(format!(
                "the network's correction is {} at frame {}, value {}: check the model's weights",
                y[i],
                (i / d) % n,
                i % d
            )));
        }
        Ok(y.chunks_exact(n * d).map(|c| c.to_vec()).collect())
    }

    /// Completes checked keys into checked buffers (`out[c]`: `keys[c].len() * dofs` values):
    /// the graph runs once per shot length (once per character where tract plans no batch), and
    /// every character's features and correction are made before anything is written. With a
    /// `fallback`, each character's weight towards the curves is pushed to `weights` and its
    /// share of the correction kept per frame to `kept`.
    pub(super) fn complete(
        &self,
        keys: &[MotionKeys<'_>],
        out: &mut [&mut [f32]],
        fallback: Option<&Fallback>,
        weights: &mut Vec<f32>,
        kept: &mut Vec<Vec<f64>>,
    ) -> Result<(), MotionError> {
        let shots = self.shots(keys)?;
        let mut corrections: Vec<Vec<f32>> = vec![Vec::new(); shots.len()];
        let mut lengths: Vec<usize> = shots.iter().map(|s| s.frames).collect();
        lengths.sort_unstable();
        lengths.dedup();
        for n in lengths {
            let group: Vec<usize> = (0..shots.len()).filter(|&c| shots[c].frames == n).collect();
            let chunks: Vec<Vec<usize>> = match self.batched {
                Some(_) => vec![group],
                None => group.into_iter().map(|c| vec![c]).collect(),
            };
            for chunk in chunks {
                let refs: Vec<&ShotInputs> = chunk.iter().map(|&c| &shots[c]).collect();
                for (c, y) in chunk.into_iter().zip(self.corrections(&refs)?) {
                    corrections[c] = y;
                }
            }
        }
        for ((shot, correction), o) in shots.iter().zip(&corrections).zip(out.iter_mut()) {
            let done = self.features.complete(shot, correction, fallback);
            if fallback.is_some() {
                weights.push(done.weight);
                kept.push(done.kept);
            }
            for (v, p) in o.iter_mut().zip(done.poses) {
                *v = p as f32;
            }
        }
        Ok(())
    }
}
