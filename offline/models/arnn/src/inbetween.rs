//! The key-to-key in-betweening network for humanoid keys (issue 46, beyond the ARNN paper): a
//! bidirectional GRU over a whole shot that predicts a correction of Blender's default F-curves
//! through the keys ([`zoo_protocol::fcurve::bezier_inbetween`]), scaled per value by an envelope
//! that is zero on the key frames fixing it, so that every key is met by construction. It is
//! the residual-on-interpolation idea of the RTN (Harvey et al. 2020, sec. 3.3, where it took
//! the RTN from worse than interpolation to a third of its error) applied to an animator's keys,
//! with the whole shot seen at once instead of autoregressively (the ARNN of the paper, sec. 6,
//! drifts 1-2 m away from humanoid keys before its key correction, docs/keys-only.md).
//!
//! Poses are the humanoid ARNN's ([`crate::humanoid`]): the root position, then one quaternion
//! `(w, x, y, z)` per joint, `d = 3 + 4 J` values, in network units `(x - mean) / std`. Key
//! groups: group 0 is the root position, group `1 + j` joint `j`'s rotation. Per frame `t` of a
//! shot (frames `0..=last key`) the network reads ([`zoo_protocol::inbetween`] builds them, for
//! training and for the runtime alike):
//! - `b_t`, the Bezier pose;
//! - `k-_t - b_t` and `k+_t - b_t`: per value, the previous key fixing its group (at or before
//!   `t`) and the next one (after `t`), minus the Bezier pose (a key's quaternion taken with the
//!   sign nearest the Bezier one);
//! - the phase `s_t = (t - t-) / (t+ - t-)` and the gap `(t+ - t-) / gap_unit` of the keys fixing
//!   the root;
//! - per group, 1 where a key fixes it at `t`, and its envelope `e_g(t) = 4 s (1 - s)` (`s` the
//!   phase between the keys fixing the group; 0 on them and outside them).
//!
//! Output: `x_t = b_t + r_t`, the residual `r` made from the correction `c_t =
//! D(BGRU(E(input_t)))` zero on every key ([`Residual`], the config's `residual`): `e(t) c_t`
//! with `e` per value its group's envelope, or `c_t` minus the straight line through `c` on the
//! keys around `t` fixing the value (new runs; smooth through the keys).
//!
//! The backbone between E and D is a bidirectional GRU, or a transformer encoder over the frames
//! ([`Backbone`], `zoo train arnn --design inbetween --backbone transformer`).

use crate::config::HumanoidSkeleton;
use crate::train::Normalization;
use crate::{ArnnError, ArnnResult};
use candle_core::{Device, Module, Tensor};
use candle_nn::VarBuilder;
use serde::{Deserialize, Serialize};
use std::path::Path;
use zoo_motion::EulerOrder;
use zoo_nn::{Activation, BiGru, Dropout, Mlp, RowRngs};
use zoo_protocol::inbetween::InbetweenFeatures;
pub use zoo_protocol::inbetween::Residual;

/// The `design` field of an in-betweening run's `config.json`.
pub const DESIGN: &str = "inbetween";

/// Sizes, loss weights and key sampling of the in-betweening network.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InbetweenConfig {
    /// Always `"arnn"`: the run folder is a `zoo train arnn` run.
    pub model: String,
    /// Always [`DESIGN`]: which design of `zoo train arnn` the folder holds.
    pub design: String,
    /// The skeleton and the clips' frame rate.
    pub skeleton: HumanoidSkeleton,
    /// Each joint's Euler channel order as axis indices (0 = X, 1 = Y, 2 = Z; bandai2: ZXY =
    /// `[2, 0, 1]`): the Bezier curves are drawn on these channels, as Blender draws them.
    pub euler_axes: Vec<[usize; 3]>,
    /// The network over the shot between the per-frame encoder and decoder (runs written
    /// before the field: the bidirectional GRU).
    #[serde(default)]
    pub backbone: Backbone,
    /// Width of the per-frame encoder E (one ReLU layer); the transformer's token width.
    pub encoder: usize,
    /// GRU units per direction; the transformer's feed-forward width.
    pub hidden: usize,
    /// Bidirectional GRU layers; the transformer's encoder blocks.
    pub layers: usize,
    /// The transformer's attention heads (`encoder` a multiple of it; unused by the GRU).
    #[serde(default = "heads")]
    pub heads: usize,
    /// Hidden width of the decoder D (one ReLU layer, then a linear layer to `d` values).
    pub decoder: usize,
    /// Dropout in training: between GRU layers; the transformer's on each block's attention and
    /// feed-forward outputs, before they are added to the block's input.
    pub dropout: f64,
    /// Frames the gap input is divided by.
    pub gap_unit: f64,
    /// Weight of the global position loss (forward kinematics) beside the pose L1 loss.
    pub lambda_fk: f64,
    /// Clip units (bandai2: cm) a global position error is divided by in the loss.
    pub fk_unit: f64,
    /// Weight of the global velocity loss: every joint's frame-to-frame displacement by forward
    /// kinematics against the truth's (0: off; runs written before the field have none).
    #[serde(default)]
    pub lambda_vel: f64,
    /// Clip units a velocity error (per frame) is divided by in the loss.
    #[serde(default = "one")]
    pub vel_unit: f64,
    /// Weight of the feet (joints named `foot` or `toe`) in the velocity loss, the others' 1:
    /// their displacement while the truth's stands still is the foot skate.
    #[serde(default = "one")]
    pub foot_weight: f64,
    /// Training keys: smallest base spacing in frames.
    pub min_gap: usize,
    /// Training keys: largest base spacing in frames.
    pub max_gap: usize,
    /// Training keys: fraction of shots keyed exactly every K frames (the rest jittered, each
    /// gap drawn in `[0.6 K, 1.4 K]`).
    pub regular_fraction: f64,
    /// Training keys: fraction of shots whose keys between the first and the last fix the root
    /// and the limbs' end joints only (the benchmark's partial layout).
    pub partial_fraction: f64,
    /// Training keys: fraction of batches in the in-betweening benchmark's transition layout:
    /// the first `N_PAST` frames all keys (the context), then the target `5..=45` frames after
    /// them, whole keys (runs written before the field: none).
    #[serde(default)]
    pub transition_fraction: f64,
    /// Shots per batch.
    pub batch_size: usize,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// The learning rate halves every this many steps (0: constant); `zoo train arnn
    /// --design inbetween` sets a quarter of the run's steps, so that the run ends at a
    /// sixteenth of it.
    #[serde(default)]
    pub lr_half_life: u64,
    /// Gradient norm clipped to this (0: no clipping).
    pub max_grad_norm: f64,
    /// Seed of the weights and of the key draws.
    pub seed: u64,
    /// How the correction is made zero on the keys (runs written before the field: the
    /// envelope).
    #[serde(default)]
    pub residual: Residual,
    /// The fallback towards the curves, calibrated at the end of training on the validation
    /// shots (`zoo_protocol::inbetween::Fallback`; absent: the network alone, as runs written
    /// before it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fallback: Option<zoo_protocol::inbetween::Fallback>,
}

impl InbetweenConfig {
    /// The humanoid sizes: encoder 256, one bidirectional GRU layer of 256 units per direction,
    /// decoder 256; keys every 5-30 frames, half of them regular, a fifth partial; pose L1 plus
    /// the global position loss in units of 10 cm (the velocity loss off: with weight 1, feet
    /// 4, it slowed the position terms without lowering the skate, docs/keys-only.md); Adam
    /// 1e-3, batches of 32.
    pub fn humanoid(skeleton: HumanoidSkeleton, euler_axes: Vec<[usize; 3]>) -> Self {
        InbetweenConfig {
            model: "arnn".into(),
            design: DESIGN.into(),
            skeleton,
            euler_axes,
            backbone: Backbone::Bgru,
            encoder: 256,
            hidden: 256,
            layers: 1,
            heads: heads(),
            decoder: 256,
            dropout: 0.0,
            gap_unit: 30.0,
            lambda_fk: 1.0,
            fk_unit: 10.0,
            lambda_vel: 0.0,
            vel_unit: 1.0,
            foot_weight: 4.0,
            min_gap: 5,
            max_gap: 30,
            regular_fraction: 0.5,
            partial_fraction: 0.2,
            transition_fraction: 0.0,
            batch_size: 32,
            learning_rate: 1e-3,
            lr_half_life: 0,
            max_grad_norm: 1.0,
            seed: 1,
            residual: Residual::KeyLerp,
            fallback: None,
        }
    }

    /// The humanoid configuration at test sizes (widths of 16).
    pub fn tiny(skeleton: HumanoidSkeleton, euler_axes: Vec<[usize; 3]>) -> Self {
        InbetweenConfig { encoder: 16, hidden: 16, decoder: 16, batch_size: 4, ..Self::humanoid(skeleton, euler_axes) }
    }

    /// The quick sizes (`zoo train arnn --design inbetween --preset quick`): the humanoid
    /// design at half width (encoder 128, one bidirectional GRU layer of 128 per direction,
    /// decoder 128), batch 32, Adam 2e-3; about 5 minutes of one thread on 20 minutes of
    /// synthetic locomotion (docs/keys-only.md, "Try it in minutes").
    pub fn quick(skeleton: HumanoidSkeleton, euler_axes: Vec<[usize; 3]>) -> Self {
        InbetweenConfig {
            encoder: 128,
            hidden: 128,
            decoder: 128,
            learning_rate: 2e-3,
            ..Self::humanoid(skeleton, euler_axes)
        }
    }

    /// This configuration with `backbone`: the GRU keeps the sizes; the transformer's tokens are
    /// `encoder` values wide, its feed-forward width twice that, 3 blocks of 8 heads (the
    /// humanoid sizes: 256, 512; test sizes under 128: 2 blocks of 2 heads); the decoder, keys
    /// and losses stay.
    pub fn with_backbone(self, backbone: Backbone) -> Self {
        match backbone {
            Backbone::Bgru => InbetweenConfig { backbone, ..self },
            Backbone::Transformer if self.encoder >= 128 => {
                InbetweenConfig { backbone, hidden: 2 * self.encoder, layers: 3, heads: 8, ..self }
            }
            Backbone::Transformer => {
                InbetweenConfig { backbone, hidden: 2 * self.encoder, layers: 2, heads: 2, ..self }
            }
        }
    }

    /// Joints.
    pub fn joints(&self) -> usize {
        self.skeleton.names.len()
    }

    /// Values per pose, `3 + 4 J`.
    pub fn dofs(&self) -> usize {
        3 + 4 * self.joints()
    }

    /// Key groups, `1 + J`.
    pub fn groups(&self) -> usize {
        1 + self.joints()
    }

    /// The group of each pose value.
    pub fn key_groups(&self) -> Vec<usize> {
        crate::humanoid::pose_layout(&self.skeleton.names).1
    }

    /// Values per frame the encoder reads: the input features, and with the transformer the
    /// Bezier pose's frame-to-frame change ([`velocity`]).
    pub fn encoder_input(&self) -> usize {
        match self.backbone {
            Backbone::Bgru => self.input_width(),
            Backbone::Transformer => self.input_width() + self.dofs(),
        }
    }

    /// Values per frame of the network's input, `3 d + 2 + 2 (1 + J)`.
    pub fn input_width(&self) -> usize {
        3 * self.dofs() + 2 + 2 * self.groups()
    }

    /// The Euler orders of the joints.
    pub fn orders(&self) -> ArnnResult<Vec<EulerOrder>> {
        self.euler_axes
            .iter()
            .enumerate()
            .map(|(j, a)| {
                EulerOrder::from_axes(*a).ok_or_else(|| {
                    ArnnError::Config(format!(
                        "euler_axes of joint {j} is {a:?}: three different axes 0-2 (0 = X) are needed"
                    ))
                })
            })
            .collect()
    }

    /// Checks the sizes and the skeleton.
    pub fn validate(&self) -> ArnnResult<()> {
        let bad = |m: String| Err(ArnnError::Config(m));
        if self.model != "arnn" || self.design != DESIGN {
            return bad(format!("model `{}` design `{}`: expected `arnn` and `{DESIGN}`", self.model, self.design));
        }
        let j = self.joints();
        let s = &self.skeleton;
        if j == 0 || s.parents.len() != j || s.offsets.len() != j || self.euler_axes.len() != j {
            return bad(format!(
                "the skeleton needs one parent, offset and Euler order per joint: {j} names, {} parents, {} offsets, {} \
                 orders",
                s.parents.len(),
                s.offsets.len(),
                self.euler_axes.len()
            ));
        }
        if s.parents[0] != -1 || s.parents.iter().enumerate().skip(1).any(|(i, &p)| p < 0 || p as usize >= i) {
            return bad("joint 0 must be the root and every other joint's parent must come before it".into());
        }
        self.orders()?;
        if let Some(f) = &self.fallback {
            f.check().map_err(|e| ArnnError::Config(format!("fallback: {e}")))?;
        }
        if [self.encoder, self.hidden, self.layers, self.decoder, self.batch_size, self.heads].contains(&0) {
            return bad("encoder, hidden, layers, heads, decoder and batch_size must be positive".into());
        }
        if self.backbone == Backbone::Transformer && self.encoder % self.heads != 0 {
            return bad(format!(
                "the transformer's token width (encoder {}) must be a multiple of its heads ({})",
                self.encoder, self.heads
            ));
        }
        if self.min_gap < 2 || self.max_gap < self.min_gap {
            return bad(format!("key gaps {}-{}: need 2 <= min_gap <= max_gap", self.min_gap, self.max_gap));
        }
        let fractions = [self.regular_fraction, self.partial_fraction, self.transition_fraction];
        if fractions.iter().any(|f| !(0.0..=1.0).contains(f)) {
            return bad("regular_fraction, partial_fraction and transition_fraction must be in [0, 1]".into());
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return bad(format!("dropout {}: must be in [0, 1)", self.dropout));
        }
        let positive = [self.gap_unit, self.fk_unit, self.vel_unit, self.learning_rate];
        let weights = [self.lambda_fk, self.lambda_vel, self.foot_weight];
        if positive.iter().any(|v| v.is_nan() || *v <= 0.0) || weights.iter().any(|w| w.is_nan() || *w < 0.0) {
            return bad(
                "gap_unit, fk_unit, vel_unit and learning_rate must be positive, lambda_fk, lambda_vel and foot_weight \
                 not negative"
                    .into(),
            );
        }
        Ok(())
    }
}

fn one() -> f64 {
    1.0
}

fn heads() -> usize {
    8
}

/// The network over the shot, between the per-frame encoder E and decoder D.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Backbone {
    /// Bidirectional GRU layers (`hidden` units per direction).
    #[default]
    Bgru,
    /// A transformer encoder over the shot's frames as tokens (not in any paper in this form;
    /// the scope of the whole-shot in-betweener asks for one after Qin et al. 2022 and SILK,
    /// Akhoundi et al. 2025): pre-norm blocks of multi-head self-attention and a ReLU
    /// feed-forward layer, each added to its input; positions by the attention's linear bias on
    /// the frame distance (ALiBi, Press et al. 2022: head `h` of `H` adds `-2^(-8 (h + 1) / H)
    /// |i - j|` to the scores), so that a shot of any length runs; the keys and the context are
    /// flagged in the features; the encoder also reads the Bezier pose's frame-to-frame change
    /// ([`velocity`]); a last layer normalisation before the decoder.
    Transformer,
}

/// Factor of the Bezier pose's frame-to-frame change (normalised units) in the transformer's
/// input: a change of 0.1 normalised units per frame reads as 1.
pub const VELOCITY_SCALE: f64 = 10.0;

/// The Bezier pose's frame-to-frame change of features `(batch, frames, width)` (the first `d`
/// values of a frame are its normalised Bezier pose): `VELOCITY_SCALE (b_t - b_(t-1))`, 0 on the
/// first frame; `(batch, frames, d)`.
pub fn velocity(features: &Tensor, d: usize) -> candle_core::Result<Tensor> {
    let b = features.narrow(2, 0, d)?;
    let t = b.dim(1)?;
    // b_(t-1), the first frame standing for its own predecessor.
    let prev = match t {
        1 => b.clone(),
        _ => Tensor::cat(&[&b.narrow(1, 0, 1)?, &b.narrow(1, 0, t - 1)?], 1)?,
    };
    (b - prev)? * VELOCITY_SCALE
}

/// The transformer's attention bias `(heads, frames, frames)`: head `h` adds `-m_h |i - j|`,
/// `m_h = 2^(-8 (h + 1) / heads)` ([`Backbone::Transformer`]).
pub fn alibi_slopes(heads: usize) -> Vec<f32> {
    (0..heads).map(|h| 2f32.powf(-8.0 * (h + 1) as f32 / heads as f32)).collect()
}

/// Epsilon of the transformer's layer normalisations.
pub const LAYER_NORM_EPS: f64 = 1e-5;

/// A layer normalisation over the last dimension, from candle's differentiable ops.
#[derive(Clone, Debug)]
struct LayerNorm {
    weight: Tensor,
    bias: Tensor,
}

impl LayerNorm {
    fn new(width: usize, vb: VarBuilder) -> candle_core::Result<Self> {
        let weight = vb.get_with_hints(width, "weight", candle_nn::Init::Const(1.0))?;
        let bias = vb.get_with_hints(width, "bias", candle_nn::Init::Const(0.0))?;
        Ok(LayerNorm { weight, bias })
    }

    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        use candle_core::D;
        let xc = x.broadcast_sub(&x.mean_keepdim(D::Minus1)?)?;
        let var = xc.sqr()?.mean_keepdim(D::Minus1)?;
        xc.broadcast_div(&(var + LAYER_NORM_EPS)?.sqrt()?)?.broadcast_mul(&self.weight)?.broadcast_add(&self.bias)
    }
}

/// One pre-norm transformer encoder block: `h + O(attention(LN1 h))`, then `h + F(LN2 h)`.
/// Weights `ln1`, `q.0`, `k.0`, `v.0`, `o.0`, `ln2`, `ffn.{0,1}`.
#[derive(Clone, Debug)]
struct Block {
    ln1: LayerNorm,
    q: Mlp,
    k: Mlp,
    v: Mlp,
    o: Mlp,
    ln2: LayerNorm,
    ffn: Mlp,
    heads: usize,
}

impl Block {
    fn new(width: usize, ffn: usize, heads: usize, vb: VarBuilder) -> candle_core::Result<Self> {
        let linear = |name: &str| Mlp::new(width, &[width], Activation::Relu, false, vb.pp(name));
        Ok(Block {
            ln1: LayerNorm::new(width, vb.pp("ln1"))?,
            q: linear("q")?,
            k: linear("k")?,
            v: linear("v")?,
            o: linear("o")?,
            ln2: LayerNorm::new(width, vb.pp("ln2"))?,
            ffn: Mlp::new(width, &[ffn, width], Activation::Relu, false, vb.pp("ffn"))?,
            heads,
        })
    }

    /// `h` `(batch, frames, width)`, `bias` `(heads, frames, frames)`; `drop` on the attention's
    /// and the feed-forward's outputs when `rng` is `Some` (training).
    fn forward(
        &self,
        h: &Tensor,
        bias: &Tensor,
        drop: &Dropout,
        mut rng: Option<&mut RowRngs>,
    ) -> candle_core::Result<Tensor> {
        let (b, t, e) = h.dims3()?;
        let dh = e / self.heads;
        let a = self.ln1.forward(h)?;
        let split = |m: &Mlp| m.forward(&a)?.reshape((b, t, self.heads, dh))?.transpose(1, 2)?.contiguous();
        let (q, k, v) = (split(&self.q)?, split(&self.k)?, split(&self.v)?);
        let scores = (q.matmul(&k.t()?.contiguous()?)? / (dh as f64).sqrt())?.broadcast_add(bias)?;
        let p = candle_nn::ops::softmax(&scores, candle_core::D::Minus1)?;
        let o = p.matmul(&v)?.transpose(1, 2)?.reshape((b, t, e))?;
        let h = (h + drop.forward(&self.o.forward(&o)?, rng.as_deref_mut())?)?;
        &h + drop.forward(&self.ffn.forward(&self.ln2.forward(&h)?)?, rng)?
    }
}

/// The network over the shot.
#[derive(Clone, Debug)]
enum Body {
    Bgru(BiGru),
    Transformer { blocks: Vec<Block>, ln: LayerNorm, heads: usize },
}

/// The in-betweening network. Weights: `encoder.0`, `bgru.weight_ih_l0` ... (PyTorch's GRU
/// names, `_reverse` for the backward direction) or the transformer's `blocks.{i}.*` and `ln`,
/// `decoder.{0,1}`.
#[derive(Clone, Debug)]
pub struct Inbetween {
    config: InbetweenConfig,
    encoder: Mlp,
    body: Body,
    decoder: Mlp,
    device: Device,
}

impl Inbetween {
    /// Builds (or loads, depending on `vb`) the network.
    pub fn new(config: &InbetweenConfig, vb: VarBuilder) -> ArnnResult<Self> {
        config.validate()?;
        let c = config;
        let encoder = Mlp::new(c.encoder_input(), &[c.encoder], Activation::Relu, true, vb.pp("encoder"))?;
        let (body, width) = match c.backbone {
            Backbone::Bgru => {
                (Body::Bgru(BiGru::new(c.encoder, c.hidden, c.layers, c.dropout, vb.pp("bgru"))?), 2 * c.hidden)
            }
            Backbone::Transformer => {
                let blocks = (0..c.layers)
                    .map(|i| Block::new(c.encoder, c.hidden, c.heads, vb.pp(format!("blocks.{i}"))))
                    .collect::<candle_core::Result<_>>()?;
                (Body::Transformer { blocks, ln: LayerNorm::new(c.encoder, vb.pp("ln"))?, heads: c.heads }, c.encoder)
            }
        };
        let decoder = Mlp::new(width, &[c.decoder, c.dofs()], Activation::Relu, false, vb.pp("decoder"))?;
        Ok(Inbetween { config: config.clone(), encoder, body, decoder, device: vb.device().clone() })
    }

    /// The configuration.
    pub fn config(&self) -> &InbetweenConfig {
        &self.config
    }

    /// The device of the weights.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The correction `D(BGRU(E(x)))` (the transformer: `D(LN(blocks(E([x, v]))))`, `v` the
    /// [`velocity`]) of input features `(batch, frames, input_width)`:
    /// `(batch, frames, d)`, normalised units, before the envelope. Dropout from `rng` when it
    /// is `Some` (training).
    pub fn correction(&self, features: &Tensor, mut rng: Option<&mut RowRngs>) -> ArnnResult<Tensor> {
        let w = self.config.input_width();
        let dims = features.dims();
        if dims.len() != 3 || dims[2] != w || dims[1] == 0 {
            return Err(ArnnError::Config(format!(
                "the in-betweening network takes (batch, frames >= 1, {w}) features, got shape {dims:?}"
            )));
        }
        let h = match &self.body {
            Body::Bgru(bgru) => bgru.forward(&self.encoder.forward(features)?, rng)?,
            Body::Transformer { blocks, ln, heads } => {
                let x = Tensor::cat(&[features, &velocity(features, self.config.dofs())?], 2)?;
                let mut h = self.encoder.forward(&x)?;
                let t = dims[1];
                let slopes = alibi_slopes(*heads);
                let bias: Vec<f32> = slopes
                    .iter()
                    .flat_map(|m| (0..t * t).map(move |ij| -m * (ij / t).abs_diff(ij % t) as f32))
                    .collect();
                let bias = Tensor::from_vec(bias, (*heads, t, t), &self.device)?;
                let drop = Dropout::new(self.config.dropout);
                for b in blocks {
                    h = b.forward(&h, &bias, &drop, rng.as_deref_mut())?;
                }
                ln.forward(&h)?
            }
        };
        Ok(self.decoder.forward(&h)?)
    }

    /// The completed poses in network units, `b + r` ([`Residual`]), from a batch of shot
    /// tensors ([`ShotBatch`]).
    pub fn forward(&self, batch: &ShotBatch, rng: Option<&mut RowRngs>) -> ArnnResult<Tensor> {
        let delta = self.correction(&batch.features, rng)?;
        let r = match self.config.residual {
            Residual::Envelope => delta.mul(&batch.envelope)?,
            Residual::KeyLerp => {
                let (a, c) = (delta.gather(&batch.lerp_a, 1)?, delta.gather(&batch.lerp_c, 1)?);
                let line = (&a + (c - &a)?.mul(&batch.lerp_s)?)?;
                (delta - line)?
            }
        };
        Ok((&batch.bezier + r)?)
    }
}

/// One shot's network inputs and its Bezier poses (built by [`zoo_protocol::inbetween`]).
pub use zoo_protocol::inbetween::ShotInputs;

/// Tensors of shots of one length: features `(b, T, in)`, Bezier poses (normalised) and
/// envelopes `(b, T, d)`.
#[derive(Clone, Debug)]
pub struct ShotBatch {
    /// Input features.
    pub features: Tensor,
    /// Bezier poses, normalised.
    pub bezier: Tensor,
    /// Envelopes.
    pub envelope: Tensor,
    /// [`ShotInputs::lerp`]: the frame of the key before (`u32`), `(b, T, d)`.
    pub lerp_a: Tensor,
    /// [`ShotInputs::lerp`]: the frame of the key after (`u32`), `(b, T, d)`.
    pub lerp_c: Tensor,
    /// [`ShotInputs::lerp`]: the phase between them, `(b, T, d)`.
    pub lerp_s: Tensor,
}

impl ShotBatch {
    /// Stacks shots of one length.
    pub fn new(shots: &[&ShotInputs], norm: &Normalization, device: &Device) -> ArnnResult<Self> {
        let (b, t) = (shots.len(), shots.first().map_or(0, |s| s.frames));
        if b == 0 || shots.iter().any(|s| s.frames != t) {
            return Err(ArnnError::Config("a batch needs at least one shot, all of one length".into()));
        }
        let (w, d) = (shots[0].features.len() / t, norm.mean.len());
        let features: Vec<f32> = shots.iter().flat_map(|s| s.features.iter().copied()).collect();
        let bez: Vec<f32> = shots.iter().flat_map(|s| s.bezier.chunks_exact(d).flat_map(|p| norm.apply(p))).collect();
        let env: Vec<f32> = shots.iter().flat_map(|s| s.envelope.iter().map(|&e| e as f32)).collect();
        let lerp_a: Vec<u32> = shots.iter().flat_map(|s| s.lerp.iter().map(|l| l.0)).collect();
        let lerp_c: Vec<u32> = shots.iter().flat_map(|s| s.lerp.iter().map(|l| l.1)).collect();
        let lerp_s: Vec<f32> = shots.iter().flat_map(|s| s.lerp.iter().map(|l| l.2 as f32)).collect();
        Ok(ShotBatch {
            features: Tensor::from_vec(features, (b, t, w), device)?,
            bezier: Tensor::from_vec(bez, (b, t, d), device)?,
            envelope: Tensor::from_vec(env, (b, t, d), device)?,
            lerp_a: Tensor::from_vec(lerp_a, (b, t, d), device)?,
            lerp_c: Tensor::from_vec(lerp_c, (b, t, d), device)?,
            lerp_s: Tensor::from_vec(lerp_s, (b, t, d), device)?,
        })
    }
}

/// The feature settings of `config` with the statistics `norm`, checked.
pub fn features(config: &InbetweenConfig, norm: &Normalization) -> ArnnResult<InbetweenFeatures> {
    let f = InbetweenFeatures {
        orders: config.orders()?,
        gap_unit: config.gap_unit,
        mean: norm.mean.clone(),
        std: norm.std.clone(),
        residual: config.residual,
    };
    f.check().map_err(|e| ArnnError::Config(e.to_string()))?;
    Ok(f)
}

/// Key poses and flags flattened key-major for [`zoo_protocol::inbetween`], each pose's `d`
/// values and each row's `g` flags counted first.
fn flatten(
    frames: &[usize],
    poses: &[Vec<f64>],
    fixed: &[Vec<bool>],
    (d, g): (usize, usize),
) -> ArnnResult<(Vec<f64>, Vec<bool>)> {
    if poses.len() != frames.len() || poses.iter().any(|p| p.len() != d) {
        return Err(ArnnError::Config(format!(
            "{} key frames need as many poses of {d} finite values, got {}",
            frames.len(),
            poses.len()
        )));
    }
    if !fixed.is_empty() && (fixed.len() != frames.len() || fixed.iter().any(|m| m.len() != g)) {
        return Err(ArnnError::Config(format!("partial keys need one row of {g} group flags per key")));
    }
    Ok((poses.concat(), fixed.concat()))
}

/// The network's inputs and the Bezier poses of a shot: keys at `frames` (from 0) with poses
/// `poses` (the humanoid pose layout, clip units) fixing the groups `fixed` (empty: whole keys),
/// built by [`InbetweenFeatures::shot`].
pub fn shot_inputs(
    config: &InbetweenConfig,
    norm: &Normalization,
    frames: &[usize],
    poses: &[Vec<f64>],
    fixed: &[Vec<bool>],
) -> ArnnResult<ShotInputs> {
    let (p, m) = flatten(frames, poses, fixed, (config.dofs(), config.groups()))?;
    features(config, norm)?.shot(frames, &p, &m).map_err(|e| ArnnError::Config(e.to_string()))
}

/// Completes shots: per shot its key frames (from 0), key poses and fixed groups (empty: whole
/// keys); returns each shot's poses of frames `0..=last key` in clip units, composed in f64
/// (`b + e * correction * std`), so that a value equals its Bezier value, and so its key, on
/// every key frame fixing it, with the run's fallback towards the curves
/// (`zoo_protocol::inbetween::Fallback`) when it has one. Shots of one length run as one batch
/// (at most 64 at a time).
pub fn complete_shots(
    model: &Inbetween,
    norm: &Normalization,
    shots: &[ShotKeyRefs<'_>],
) -> ArnnResult<Vec<Vec<Vec<f64>>>> {
    Ok(complete_shots_kept(model, norm, shots)?.into_iter().map(|(poses, _)| poses).collect())
}

/// [`complete_shots`], with each shot's share of the correction the fallback kept per frame
/// (`zoo_protocol::inbetween::Completed::kept`, all 1 without a fallback), which scales the foot
/// lock between the keys.
pub fn complete_shots_kept(
    model: &Inbetween,
    norm: &Normalization,
    shots: &[ShotKeyRefs<'_>],
) -> ArnnResult<Vec<(Vec<Vec<f64>>, Vec<f64>)>> {
    let c = model.config();
    let features = features(c, norm)?;
    let done = shot_corrections(model, norm, shots)?;
    Ok(done
        .iter()
        .map(|(s, dl)| {
            let done = features.complete(s, dl, c.fallback.as_ref());
            (done.poses.chunks_exact(c.dofs()).map(<[f64]>::to_vec).collect(), done.kept)
        })
        .collect())
}

/// Each shot's inputs and the network's correction (normalised units, frames x d), as
/// [`complete_shots`] makes them before composing.
pub fn shot_corrections(
    model: &Inbetween,
    norm: &Normalization,
    shots: &[ShotKeyRefs<'_>],
) -> ArnnResult<Vec<(ShotInputs, Vec<f32>)>> {
    let c = model.config();
    let d = c.dofs();
    if norm.mean.len() != d || norm.std.len() != d {
        return Err(ArnnError::Config(format!("normalization of {} values for a model of {d}", norm.mean.len())));
    }
    let features = features(c, norm)?;
    // Each shot makes `last key + 1` frames of `d` values: bounded before anything is allocated
    // (a last key of usize::MAX wrapped to 0 frames and divided by zero).
    if let Some(last) = shots.iter().filter_map(|(f, _, _)| f.last()).find(|&&l| l >= crate::completion::MAX_FRAMES) {
        return Err(ArnnError::Config(format!(
            "a shot's last key is at frame {last}: at most {} frames are completed at a time",
            crate::completion::MAX_FRAMES
        )));
    }
    let shot = |(f, p, m): &ShotKeyRefs<'_>| {
        let (p, m) = flatten(f, p, m, (d, c.groups()))?;
        features.shot(f, &p, &m).map_err(|e| ArnnError::Config(e.to_string()))
    };
    let inputs: Vec<ShotInputs> = shots.iter().map(shot).collect::<ArnnResult<_>>()?;
    let mut deltas: Vec<Vec<f32>> = vec![Vec::new(); shots.len()];
    let mut lengths: Vec<usize> = inputs.iter().map(|s| s.frames).collect();
    lengths.sort_unstable();
    lengths.dedup();
    for n in lengths {
        let idx: Vec<usize> = (0..inputs.len()).filter(|&i| inputs[i].frames == n).collect();
        for chunk in idx.chunks(64) {
            let group: Vec<&ShotInputs> = chunk.iter().map(|&i| &inputs[i]).collect();
            let batch = ShotBatch::new(&group, norm, model.device())?;
            let delta: Vec<f32> = model.correction(&batch.features, None)?.flatten_all()?.to_vec1()?;
            for (k, &i) in chunk.iter().enumerate() {
                deltas[i] = delta[k * n * d..(k + 1) * n * d].to_vec();
            }
        }
    }
    Ok(inputs.into_iter().zip(deltas).collect())
}

/// One shot's keys for [`complete_shots`]: key frames (from 0), key poses, fixed groups (empty:
/// whole keys).
pub type ShotKeyRefs<'a> = (&'a [usize], &'a [Vec<f64>], &'a [Vec<bool>]);

/// Whether the run folder `dir` holds the in-betweening design (its `config.json` says
/// `"design": "inbetween"`).
pub fn is_inbetween_run(dir: &Path) -> bool {
    let path = dir.join(zoo_nn::checkpoint::CONFIG_FILE);
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .is_some_and(|v| v.get("design").and_then(|d| d.as_str()) == Some(DESIGN))
}

/// Loads an in-betweening run folder (`config.json`, `model.safetensors`,
/// `normalization.json`) for inference.
pub fn load(dir: &Path, device: &Device) -> ArnnResult<(Inbetween, Normalization)> {
    let (config, norm) = read_meta(dir)?;
    let varmap = candle_nn::VarMap::new();
    let model = Inbetween::new(&config, VarBuilder::from_varmap(&varmap, candle_core::DType::F32, device))?;
    zoo_nn::checkpoint::read_varmap(&dir.join(zoo_nn::checkpoint::WEIGHTS_FILE), &varmap)?;
    zoo_nn::checkpoint::check_finite(&varmap)?;
    Ok((model, norm))
}

/// Reads and checks the configuration and the normalisation statistics of an in-betweening
/// run folder.
pub fn read_meta(dir: &Path) -> ArnnResult<(InbetweenConfig, Normalization)> {
    use zoo_nn::checkpoint as ck;
    let config: InbetweenConfig = ck::read_json(&dir.join(ck::CONFIG_FILE))?;
    config.validate().map_err(|e| ArnnError::Config(format!("{}: {e}", dir.join(ck::CONFIG_FILE).display())))?;
    let norm: Normalization = ck::read_json(&dir.join(ck::STATS_FILE))?;
    let d = config.dofs();
    if norm.mean.len() != d || norm.std.len() != d || norm.std.iter().any(|s| s.is_nan() || *s <= 0.0) {
        return Err(ArnnError::Config(format!(
            "{}: expected {d} means and {d} positive standard deviations",
            dir.join(ck::STATS_FILE).display()
        )));
    }
    Ok((config, norm))
}

/// The configuration for a skeleton (its Euler orders) and the clips' frame rate.
pub fn config_for(skeleton: &zoo_motion::Skeleton, fps: f64) -> InbetweenConfig {
    let axes = skeleton.channels.iter().map(|c| c.order.axes()).collect();
    InbetweenConfig::humanoid(crate::humanoid::skeleton_info(skeleton, fps), axes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::humanoid::poses;
    use glam::{DQuat, DVec3};

    pub(crate) fn skeleton() -> HumanoidSkeleton {
        HumanoidSkeleton {
            names: vec!["Hips".into(), "Spine".into(), "Hand".into()],
            parents: vec![-1, 0, 1],
            offsets: vec![[0.0; 3], [0.0, 10.0, 0.0], [0.0, 10.0, 0.0]],
            fps: 30.0,
        }
    }

    fn tiny() -> InbetweenConfig {
        InbetweenConfig::tiny(skeleton(), vec![[2, 0, 1]; 3])
    }

    fn keys() -> (Vec<usize>, Vec<Vec<f64>>) {
        let frames = vec![0, 7, 15, 20];
        let root: Vec<DVec3> = frames.iter().map(|&f| DVec3::new(f as f64, 90.0, 0.5 * f as f64)).collect();
        let rot: Vec<DQuat> = frames
            .iter()
            .flat_map(|&f| {
                let a = f as f64 * 0.1;
                [DQuat::from_rotation_y(a), DQuat::from_rotation_x(-a), DQuat::from_rotation_z(0.5 * a)]
            })
            .collect();
        (frames, poses(&root, &rot, 3))
    }

    fn unit_norm(d: usize) -> Normalization {
        Normalization { mean: vec![0.0; d], std: vec![0.5; d] }
    }

    #[test]
    fn keys_are_hit_by_construction() {
        let c = tiny();
        let varmap = candle_nn::VarMap::new();
        let vb = zoo_nn::SeededVarMap::builder(&varmap, 3, candle_core::DType::F32, &Device::Cpu);
        let model = Inbetween::new(&c, vb).unwrap();
        let (frames, kp) = keys();
        let norm = unit_norm(c.dofs());
        let partial: Vec<Vec<bool>> = (0..4).map(|k| vec![true, k != 1, true, k != 2]).collect();
        for fixed in [vec![], partial] {
            let out = complete_shots(&model, &norm, &[(&frames, &kp, &fixed)]).unwrap().remove(0);
            assert_eq!(out.len(), 21);
            let (root, (deg, _, _)) = crate::humanoid::key_misses(&out, &frames, &kp, &fixed, 3);
            assert!(root < 1e-9 && deg < 1e-5, "key misses {root} / {deg} degrees");
            // Between keys the network does move the pose away from the Bezier curve.
            let inputs = shot_inputs(&c, &norm, &frames, &kp, &fixed).unwrap();
            let moved =
                (0..out.len() * c.dofs()).any(|x| (out[x / c.dofs()][x % c.dofs()] - inputs.bezier[x]).abs() > 1e-6);
            assert!(moved);
        }
    }

    #[test]
    fn inputs_have_the_documented_width_and_envelope() {
        let c = tiny();
        let (frames, kp) = keys();
        let s = shot_inputs(&c, &unit_norm(c.dofs()), &frames, &kp, &[]).unwrap();
        assert_eq!(s.features.len(), 21 * c.input_width());
        assert_eq!(s.envelope.len(), 21 * c.dofs());
        for &f in &frames {
            assert!(s.envelope[f * c.dofs()..(f + 1) * c.dofs()].iter().all(|&e| e == 0.0));
        }
        // Midway between keys 7 and 15 (frame 11) the envelope peaks at 1.
        assert!((s.envelope[11 * c.dofs()] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn bad_keys_and_configs_are_refused() {
        let c = tiny();
        let norm = unit_norm(c.dofs());
        let (frames, kp) = keys();
        let err = |r: ArnnResult<ShotInputs>| r.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err(shot_inputs(&c, &norm, &[1, 7, 15, 20], &kp, &[])).contains("from frame 0"));
        assert!(err(shot_inputs(&c, &norm, &frames, &kp[..3], &[])).contains("poses"));
        let none_fix_spine: Vec<Vec<bool>> = (0..4).map(|_| vec![true, true, false, true]).collect();
        assert!(err(shot_inputs(&c, &norm, &frames, &kp, &none_fix_spine)).contains("group 2"));
        let bad = InbetweenConfig { euler_axes: vec![[0, 0, 1]; 3], ..c.clone() };
        assert!(bad.validate().unwrap_err().to_string().contains("three different axes"));
        let bad = InbetweenConfig { heads: 3, ..c.clone().with_backbone(Backbone::Transformer) };
        assert!(bad.validate().unwrap_err().to_string().contains("multiple of its heads (3)"));
        let bad = InbetweenConfig { min_gap: 1, ..c };
        assert!(bad.validate().is_err());
    }

    /// The transformer: keys met by construction; a frame's correction depends on the frames
    /// around it (not a per-frame network) and on their distance (the attention bias), and a
    /// shot's correction does not depend on the other shots of its batch.
    #[test]
    fn the_transformer_hits_the_keys_and_reads_the_whole_shot() {
        let c = tiny().with_backbone(Backbone::Transformer);
        let varmap = candle_nn::VarMap::new();
        let vb = zoo_nn::SeededVarMap::builder(&varmap, 3, candle_core::DType::F32, &Device::Cpu);
        let model = Inbetween::new(&c, vb).unwrap();
        let (frames, kp) = keys();
        let norm = unit_norm(c.dofs());
        let out = complete_shots(&model, &norm, &[(&frames, &kp, &[])]).unwrap().remove(0);
        let (root, (deg, _, _)) = crate::humanoid::key_misses(&out, &frames, &kp, &[], 3);
        assert!(root < 1e-9 && deg < 1e-5, "key misses {root} / {deg} degrees");
        let w = c.input_width();
        let x: Vec<f32> = (0..2 * 9 * w).map(|i| (i * 37 % 101) as f32 / 50.0 - 1.0).collect();
        let x = Tensor::from_vec(x, (2, 9, w), &Device::Cpu).unwrap();
        let both: Vec<f32> = model.correction(&x, None).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let first: Vec<f32> =
            model.correction(&x.narrow(0, 0, 1).unwrap(), None).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let diff = first.iter().zip(&both).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(diff < 1e-5, "shot 0 alone differs by {diff}");
        // Changing the last frame's features moves frame 0's correction.
        let mut y: Vec<f32> = x.narrow(0, 0, 1).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        y[8 * w..].iter_mut().for_each(|v| *v += 1.0);
        let y = Tensor::from_vec(y, (1, 9, w), &Device::Cpu).unwrap();
        let moved: Vec<f32> = model.correction(&y, None).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let d = c.dofs();
        assert!((0..d).any(|v| (moved[v] - first[v]).abs() > 1e-5), "frame 0 does not read frame 8");
        // The velocity input: 0 on the first frame, the scaled change of the Bezier pose after.
        let v: Vec<f32> = velocity(&x.narrow(0, 0, 1).unwrap(), d).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        let xs: Vec<f32> = x.narrow(0, 0, 1).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        assert!(v[..d].iter().all(|&a| a == 0.0));
        let want = (xs[w] - xs[0]) * VELOCITY_SCALE as f32;
        assert!((v[d] - want).abs() < 1e-5, "{} vs {want}", v[d]);
        assert_eq!(alibi_slopes(2), [0.0625, 0.00390625]);
    }

    /// The transformer's dropout: off without generators (evaluation, export), seeded in
    /// training (the same draws give the same correction, others another), and a dropout of 1 is
    /// refused.
    #[test]
    fn the_transformers_dropout_is_seeded_and_off_in_evaluation() {
        let plain = tiny().with_backbone(Backbone::Transformer);
        let c = InbetweenConfig { dropout: 0.3, ..plain.clone() };
        let build = |c: &InbetweenConfig| {
            let varmap = candle_nn::VarMap::new();
            let vb = zoo_nn::SeededVarMap::builder(&varmap, 3, candle_core::DType::F32, &Device::Cpu);
            Inbetween::new(c, vb).unwrap()
        };
        let (with, without) = (build(&c), build(&plain));
        let w = c.input_width();
        let x: Vec<f32> = (0..2 * 9 * w).map(|i| (i * 37 % 101) as f32 / 50.0 - 1.0).collect();
        let x = Tensor::from_vec(x, (2, 9, w), &Device::Cpu).unwrap();
        let run = |m: &Inbetween, rng: Option<&mut RowRngs>| -> Vec<f32> {
            m.correction(&x, rng).unwrap().flatten_all().unwrap().to_vec1().unwrap()
        };
        assert_eq!(run(&with, None), run(&without, None));
        let a = run(&with, Some(&mut RowRngs::new(5, 0..2)));
        assert_eq!(a, run(&with, Some(&mut RowRngs::new(5, 0..2))));
        assert_ne!(a, run(&with, Some(&mut RowRngs::new(6, 0..2))));
        assert_ne!(a, run(&with, None));
        // Without dropout the generators change nothing.
        assert_eq!(run(&without, Some(&mut RowRngs::new(5, 0..2))), run(&without, None));
        let bad = InbetweenConfig { dropout: 1.0, ..c };
        assert!(bad.validate().unwrap_err().to_string().contains("dropout 1: must be in [0, 1)"));
    }

    #[test]
    fn config_round_trips_through_json() {
        let c = tiny();
        let back: InbetweenConfig = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, c);
    }
}
