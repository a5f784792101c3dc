//! Encoding windows of global positions into batches and generating transitions
//! autoregressively (RTN sec. 3.2, 4, 5).

use crate::config::Config;
use crate::error::{RtnError, RtnResult};
use crate::features::{self, FeatureStats, Heightmap, YawAbout};
use crate::model::{OffsetTensors, Rtn, RtnInputs, RtnState};
use candle_core::{Device, Tensor};

/// One sequence to encode: known frames (global positions, `frames * 3K`), the target frame
/// and the frame after it, optional terrain and the rotation already applied to the positions.
#[derive(Clone, Debug)]
pub(crate) struct SequenceInput<'a> {
    pub known: std::borrow::Cow<'a, [f32]>,
    pub target: std::borrow::Cow<'a, [f32]>,
    pub next: std::borrow::Cow<'a, [f32]>,
    pub terrain: Option<&'a Heightmap>,
    pub rotation: Option<YawAbout>,
}

/// A batch of encoded sequences: one `(batch, D)` tensor per known frame.
#[derive(Clone, Debug)]
pub(crate) struct EncodedBatch<'a> {
    pub batch: usize,
    /// Normalised features of the known frames.
    pub x: Vec<Tensor>,
    /// Global roots `(batch, 3)` of the known frames.
    pub roots: Vec<Tensor>,
    /// Normalised target vectors `(batch, 2D)`.
    pub target: Tensor,
    /// Global target frames `(batch, D)`.
    pub target_global: Tensor,
    /// Terrain of each sequence (when terrain-aware).
    pub terrain: Vec<(Option<&'a Heightmap>, Option<YawAbout>)>,
}

/// Checks that `len` values hold `frames` frames of `joints` joints (at least, when `at_least`).
pub(crate) fn check_frames(what: &str, len: usize, frames: usize, joints: usize, at_least: bool) -> RtnResult<()> {
    let d = 3 * joints;
    let ok = if at_least { len >= frames * d && len.is_multiple_of(d) } else { len == frames * d };
    if ok {
        Ok(())
    } else {
        Err(RtnError::Size {
            what: what.to_string(),
            expected: frames * d,
            detail: format!(
                "{}{frames} frames x {joints} joints x 3",
                if at_least { "a multiple of 3K and at least " } else { "" }
            ),
            found: len,
        })
    }
}

pub(crate) fn encode_batch<'a>(
    stats: &FeatureStats,
    items: &[SequenceInput<'a>],
    device: &Device,
) -> RtnResult<EncodedBatch<'a>> {
    let d = stats.dim();
    let b = items.len();
    if b == 0 {
        return Err(RtnError::Config("a batch needs at least one sequence".into()));
    }
    let frames = items[0].known.len() / d;
    let mut x = vec![0f32; frames * b * d];
    let mut roots = vec![0f32; frames * b * 3];
    let mut target = vec![0f32; b * 2 * d];
    let mut target_global = vec![0f32; b * d];
    let mut buf = vec![0f32; frames * d];
    for (k, it) in items.iter().enumerate() {
        debug_assert_eq!(it.known.len(), frames * d);
        features::encode_positions(&it.known, stats.joints, &mut buf);
        stats.x.normalize(&mut buf);
        for f in 0..frames {
            x[(f * b + k) * d..(f * b + k + 1) * d].copy_from_slice(&buf[f * d..(f + 1) * d]);
            roots[(f * b + k) * 3..(f * b + k + 1) * 3].copy_from_slice(&it.known[f * d..f * d + 3]);
        }
        let t = &mut target[k * 2 * d..(k + 1) * 2 * d];
        features::target_vector(&it.target, &it.next, t);
        stats.normalize_target(t);
        target_global[k * d..(k + 1) * d].copy_from_slice(&it.target);
    }
    let xs = (0..frames)
        .map(|f| Tensor::from_slice(&x[f * b * d..(f + 1) * b * d], (b, d), device))
        .collect::<candle_core::Result<Vec<_>>>()?;
    let rs = (0..frames)
        .map(|f| Tensor::from_slice(&roots[f * b * 3..(f + 1) * b * 3], (b, 3), device))
        .collect::<candle_core::Result<Vec<_>>>()?;
    Ok(EncodedBatch {
        batch: b,
        x: xs,
        roots: rs,
        target: Tensor::from_vec(target, (b, 2 * d), device)?,
        target_global: Tensor::from_vec(target_global, (b, d), device)?,
        terrain: items.iter().map(|i| (i.terrain, i.rotation)).collect(),
    })
}

/// Normalised terrain patches `(batch, side^2)` under the given roots `(batch, 3)`.
fn terrain_patches(config: &Config, stats: &FeatureStats, batch: &EncodedBatch, root: &Tensor) -> RtnResult<Tensor> {
    let Some(ts) = &stats.terrain else {
        return Err(RtnError::Config("a terrain-aware RTN needs terrain statistics in its FeatureStats".into()));
    };
    let roots = root.to_vec2::<f32>()?;
    let n = config.terrain_dim();
    let mut out = vec![0f32; batch.batch * n];
    for (k, r) in roots.iter().enumerate() {
        let (map, rot) = batch.terrain[k];
        let Some(map) = map else {
            return Err(RtnError::Config(format!("sequence {k} has no terrain but the RTN is terrain-aware")));
        };
        let p = &mut out[k * n..(k + 1) * n];
        features::terrain_patch(map, [r[0], r[1], r[2]], config.terrain_extent, config.terrain_side, rot, p);
        ts.normalize(p);
    }
    Ok(Tensor::from_vec(out, (batch.batch, n), root.device())?)
}

/// How many times [`generate`] calls `teacher()` for `past` context frames, `n_out` outputs and
/// `known` known frames: once for each input frame `nt` in `past..=min(past - 1 + n_out, known
/// - 1)`, in order (the calls do not depend on the data, so the draws can be made in advance).
pub(crate) fn teacher_calls(past: usize, n_out: usize, known: usize) -> usize {
    let last = (past + n_out).saturating_sub(1).min(known.saturating_sub(1));
    (last + 1).saturating_sub(past)
}

/// Runs the RTN over a batch: known frames `0..past` are fed as context, then `n_out` frames
/// are predicted (`x_past .. x_(past+n_out-1)`); after the context, input frame `t` is the
/// ground truth when `teacher()` says so and a ground truth exists (RTN sec. 6.2), else the
/// previous prediction, whose global root is integrated and whose offset to the target is
/// recomputed in the graph (sec. 3.2).
///
/// `grad`: keep the graph for backpropagation (training). Without it every step's outputs are
/// detached, so memory and the depth of candle's graph do not grow with `n_out` (a graph kept
/// over thousands of steps used gigabytes and overflowed the stack when it was dropped).
pub(crate) fn generate(
    model: &Rtn,
    stats: &FeatureStats,
    offsets: &OffsetTensors,
    batch: &EncodedBatch,
    past: usize,
    n_out: usize,
    grad: bool,
    teacher: &mut dyn FnMut() -> bool,
) -> RtnResult<Vec<Tensor>> {
    let config = model.config();
    if past == 0 || past > batch.x.len() {
        return Err(RtnError::Config(format!("need 1..={} past frames, got {past}", batch.x.len())));
    }
    let seq = model.begin(&batch.target)?;
    let mut state = model.initial_state(&batch.x[0])?;
    let target_term = if config.future_conditioning { Some(offsets.target_term(&batch.target_global)?) } else { None };
    // Interpolation-residual RTN: the interpolation frames of the transition (constants).
    let bases = if config.interp_residual {
        offsets.interpolation_frames(
            &batch.x[past - 1],
            &batch.roots[past - 1],
            &batch.target,
            &batch.target_global,
            n_out.saturating_sub(1),
        )?
    } else {
        Vec::new()
    };
    // Time to arrival of the frame step `t` predicts (`t + 1`): the target is frame
    // `past + n_out - 1`.
    let tta = |t: usize| -> RtnResult<Option<Tensor>> {
        let Some(z) = config.time_to_arrival else { return Ok(None) };
        let mut e = vec![0f32; z.dims];
        z.embed((past + n_out - 1).saturating_sub(t + 1), &mut e);
        let row = Tensor::from_vec(e, (1, z.dims), batch.x[0].device())?;
        Ok(Some(row.broadcast_as((batch.batch, z.dims))?.contiguous()?))
    };
    let mut x = batch.x[0].clone();
    let mut root = batch.roots[0].clone();
    let mut outs = Vec::with_capacity(n_out);
    for t in 0..past - 1 + n_out {
        // The frame predicted by this step is `t + 1`: within the context its interpolation
        // base is the known frame itself, after it the interpolation frame.
        let base = if !config.interp_residual {
            None
        } else if t + 1 < past {
            Some(&batch.x[t + 1])
        } else {
            Some(&bases[t + 1 - past])
        };
        let offset = match &target_term {
            Some(tt) => Some(offsets.offset(tt, &x, &root)?),
            None => None,
        };
        let terrain = if config.terrain { Some(terrain_patches(config, stats, batch, &root)?) } else { None };
        let tta = tta(t)?;
        let inputs = RtnInputs {
            sequence: &seq,
            x: &x,
            offset: offset.as_ref(),
            terrain: terrain.as_ref(),
            base,
            tta: tta.as_ref(),
        };
        let (mut next, mut st) = model.step(&inputs, &state)?;
        if !grad {
            next = next.detach();
            st = RtnState { h: st.h.detach(), c: st.c.detach() };
        }
        state = st;
        let nt = t + 1;
        if nt >= past {
            outs.push(next.clone());
        }
        if nt < past || (nt < batch.x.len() && teacher()) {
            x = batch.x[nt].clone();
            root = batch.roots[nt].clone();
        } else {
            root = offsets.next_root(&root, &next)?;
            if !grad {
                root = root.detach();
            }
            x = next;
        }
    }
    Ok(outs)
}

impl Rtn {
    /// Generates a transition autoregressively (RTN sec. 4) for one character.
    ///
    /// `past`: global positions of the context frames (`frames * 3K`, at least one frame; the
    /// paper uses 10); `target` and `next`: the target frame and the one after it (`3K` each,
    /// for the target velocity); `terrain`: required by a terrain-aware model. Returns
    /// `n_frames + 1` frames of global positions: the transition and the predicted target,
    /// without post-processing (see [`Rtn::transition`]).
    pub fn unroll(
        &self,
        stats: &FeatureStats,
        past: &[f32],
        target: &[f32],
        next: &[f32],
        n_frames: usize,
        terrain: Option<&Heightmap>,
    ) -> RtnResult<Vec<f32>> {
        let k = self.config().joints;
        let d = 3 * k;
        if stats.joints != k {
            return Err(RtnError::Config(format!("statistics are for {} joints, the model for {k}", stats.joints)));
        }
        check_frames("past frames", past.len(), 1, k, true)?;
        check_frames("target frame", target.len(), 1, k, false)?;
        check_frames("frame after the target", next.len(), 1, k, false)?;
        let device = self.device();
        let offsets = OffsetTensors::new(stats, device)?;
        let item =
            SequenceInput { known: past.into(), target: target.into(), next: next.into(), terrain, rotation: None };
        let batch = encode_batch(stats, std::slice::from_ref(&item), device)?;
        let n_past = past.len() / d;
        let outs = generate(self, stats, &offsets, &batch, n_past, n_frames + 1, false, &mut || false)?;
        let mut feats = Tensor::cat(&outs, 0)?.flatten_all()?.to_vec1::<f32>()?;
        stats.x.denormalize(&mut feats);
        let mut y = vec![0f32; feats.len()];
        let start = features::root_of(&past[(n_past - 1) * d..]);
        features::decode_features(start, &feats, k, &mut y);
        Ok(y)
    }

    /// [`Rtn::unroll`] followed by the target blend of RTN eq. 15-16 over the configured
    /// `target_blend` frames: the last of the `n_frames + 1` frames equals `target`.
    pub fn transition(
        &self,
        stats: &FeatureStats,
        past: &[f32],
        target: &[f32],
        next: &[f32],
        n_frames: usize,
        terrain: Option<&Heightmap>,
    ) -> RtnResult<Vec<f32>> {
        let mut y = self.unroll(stats, past, target, next, n_frames, terrain)?;
        features::target_blend(&mut y, target, self.config().target_blend);
        Ok(y)
    }
}
