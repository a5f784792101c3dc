//! The ARNN of section 6 (Figure 6): pose feature nets, two GRU layers with SELU between, a
//! two-layer decoder and a residual added to the previous pose; and the two architectures of
//! section 9 it is compared with (Table 2), [`Architecture::NoMemory`] and
//! [`Architecture::Segregated`].

use crate::config::{Architecture, ArnnConfig, NoMemoryOutput};
use candle_core::{D, Module, Result, Tensor};
use candle_nn::VarBuilder;
use zoo_nn::RowRngs;
use zoo_nn::{Activation, Dropout, Gru, GruState, Mlp};

/// The recurrent state: one [`GruState`] per GRU layer, each `(batch, hidden)`; empty for the
/// no-memory net.
#[derive(Clone, Debug)]
pub struct ArnnState {
    /// First and second GRU layers.
    pub gru: Vec<GruState>,
}

/// The two recurrent layers (ARNN and the segregated net's motion pattern network).
#[derive(Clone, Debug)]
struct Recurrent {
    gru1: Gru,
    gru2: Gru,
}

/// The network's layers per architecture.
#[derive(Clone, Debug)]
enum Body {
    Arnn { prev_features: Mlp, key_a_features: Mlp, key_b_features: Mlp, rnn: Recurrent },
    NoMemory { key_a_features: Mlp, key_b_features: Mlp, hidden: Mlp },
    Segregated { prev_features: Mlp, rnn: Recurrent, key_a_features: Mlp, key_b_features: Mlp, correction: Mlp },
}

/// The network. Poses are normalised degrees of freedom `(batch, dofs)`.
#[derive(Clone, Debug)]
pub struct Arnn {
    config: ArnnConfig,
    body: Body,
    decoder: Mlp,
}

impl Arnn {
    /// Builds (or loads) the weights. ARNN: `prev_features`, `key_a_features`,
    /// `key_b_features`, `gru1`, `gru2`, `decoder`; no-memory net: `key_a_features`,
    /// `key_b_features`, `hidden`, `decoder`; segregated net: `prev_features`, `gru1`, `gru2`,
    /// `decoder` (motion pattern network), `key_a_features`, `key_b_features`, `correction`
    /// (interpolation network).
    pub fn new(config: &ArnnConfig, vb: VarBuilder) -> Result<Self> {
        config.validate().map_err(candle_core::Error::Msg)?;
        let (d, f, h, w, c) = (config.dofs, config.feature, config.hidden, config.decoder, config.correction);
        let features = |name: &str| Mlp::new(d, &[f, f], Activation::Selu, true, vb.pp(name));
        // Keys carry one flag per group after the pose when partial keys are on.
        let key_features = |name: &str| Mlp::new(config.key_width(), &[f, f], Activation::Selu, true, vb.pp(name));
        let rnn = |input: usize| -> Result<Recurrent> {
            Ok(Recurrent {
                gru1: Gru::new(input, h, 1, 0.0, vb.pp("gru1"))?,
                gru2: Gru::new(h, h, 1, 0.0, vb.pp("gru2"))?,
            })
        };
        let body = match config.architecture {
            Architecture::Arnn => Body::Arnn {
                prev_features: features("prev_features")?,
                key_a_features: key_features("key_a_features")?,
                key_b_features: key_features("key_b_features")?,
                rnn: rnn(3 * f + 1)?,
            },
            Architecture::NoMemory => Body::NoMemory {
                key_a_features: key_features("key_a_features")?,
                key_b_features: key_features("key_b_features")?,
                hidden: Mlp::new(2 * f + 1, &[h, h], Activation::Selu, true, vb.pp("hidden"))?,
            },
            Architecture::Segregated => Body::Segregated {
                prev_features: features("prev_features")?,
                rnn: rnn(f)?,
                key_a_features: key_features("key_a_features")?,
                key_b_features: key_features("key_b_features")?,
                correction: Mlp::new(2 * f + 1, &[c, c, d], Activation::Selu, false, vb.pp("correction"))?,
            },
        };
        Ok(Arnn {
            config: config.clone(),
            body,
            decoder: Mlp::new(h, &[w, w, d], Activation::Selu, false, vb.pp("decoder"))?,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &ArnnConfig {
        &self.config
    }

    /// The device of the weights.
    pub fn device(&self) -> &candle_core::Device {
        self.decoder.layers()[0].weight().device()
    }

    /// The zero state for `batch` sequences.
    pub fn zero_state(&self, batch: usize) -> Result<ArnnState> {
        let gru = match &self.body {
            Body::Arnn { rnn, .. } | Body::Segregated { rnn, .. } => {
                vec![rnn.gru1.zero_state(batch)?, rnn.gru2.zero_state(batch)?]
            }
            Body::NoMemory { .. } => vec![],
        };
        Ok(ArnnState { gru })
    }

    /// One frame (section 6): from the previous pose `Y'_{t-1}` `(batch, dofs)`, the keys `X_K`
    /// and `X_{K+1}` (each `(batch, key_width)`: the pose, then with partial keys one flag per
    /// group, [`crate::train::Normalization::key_input`]) and `t_rel` `(batch, 1)`, the pose
    /// `Y'_t` and the next state.
    /// `rng` `Some` applies dropout (training).
    pub fn step(
        &self,
        prev: &Tensor,
        key_a: &Tensor,
        key_b: &Tensor,
        t_rel: &Tensor,
        state: &ArnnState,
        rng: Option<&mut RowRngs>,
    ) -> Result<(Tensor, ArnnState)> {
        let (fa, fb) = self.key_features(key_a, key_b)?;
        self.step_with_key_features(prev, (key_a, key_b), &fa, &fb, t_rel, state, rng)
    }

    /// The feature nets of the keys, `(X_K, X_{K+1})` -> their features; any leading shape
    /// (`(batch, dofs)`, or `(frames, batch, dofs)` to compute a whole sequence's at once: the
    /// keys do not depend on the recurrence).
    pub fn key_features(&self, key_a: &Tensor, key_b: &Tensor) -> Result<(Tensor, Tensor)> {
        let (a, b) = match &self.body {
            Body::Arnn { key_a_features, key_b_features, .. }
            | Body::NoMemory { key_a_features, key_b_features, .. }
            | Body::Segregated { key_a_features, key_b_features, .. } => (key_a_features, key_b_features),
        };
        let apply = |net: &Mlp, x: &Tensor| -> Result<Tensor> {
            let dims = x.dims().to_vec();
            let d = *dims.last().unwrap_or(&0);
            let rows = x.elem_count() / d.max(1);
            // As one 2-D batch of rows (one matmul per layer, taped in training).
            let y = net.forward(&x.reshape((rows, d))?)?;
            let mut out = dims;
            if let Some(last) = out.last_mut() {
                *last = y.dim(1)?;
            }
            y.reshape(out)
        };
        Ok((apply(a, key_a)?, apply(b, key_b)?))
    }

    /// [`Arnn::step`] with the key features already computed ([`Arnn::key_features`]); `key_poses`
    /// are `X_K` and `X_{K+1}` as given to them.
    #[allow(clippy::too_many_arguments)]
    pub fn step_with_key_features(
        &self,
        prev: &Tensor,
        key_poses: (&Tensor, &Tensor),
        fa: &Tensor,
        fb: &Tensor,
        t_rel: &Tensor,
        state: &ArnnState,
        rng: Option<&mut RowRngs>,
    ) -> Result<(Tensor, ArnnState)> {
        let keys = Tensor::cat(&[fa, fb, t_rel], D::Minus1)?;
        self.step_with_keys(prev, key_poses, &keys, state, rng)
    }

    /// [`Arnn::step`] from the keys' part of the input, `[features(X_K), features(X_{K+1}),
    /// t_rel]` concatenated `(batch, 2 * feature + 1)` (training computes it for every frame at
    /// once), and `X_K`, `X_{K+1}` (each `(batch, key_width)`; only the no-memory net reads them:
    /// its residual is on their interpolation).
    pub fn step_with_keys(
        &self,
        prev: &Tensor,
        key_poses: (&Tensor, &Tensor),
        keys: &Tensor,
        state: &ArnnState,
        mut rng: Option<&mut RowRngs>,
    ) -> Result<(Tensor, ArnnState)> {
        match &self.body {
            Body::Arnn { prev_features, rnn, .. } => {
                let x = Tensor::cat(&[&prev_features.forward(prev)?, keys], D::Minus1)?;
                let (h, state) = self.recurrent(rnn, &x, state, rng.as_deref_mut())?;
                Ok(((prev + self.decode(&h, rng)?)?, state))
            }
            Body::NoMemory { hidden, .. } => {
                let x = keys.clone();
                let drops = self.config.gru_dropout.map(Dropout::new);
                let mut h = x;
                for (l, drop) in hidden.layers().iter().zip(drops) {
                    h = zoo_nn::layers::linear_act(l, &h, Activation::Selu, &drop, rng.as_deref_mut())?;
                }
                let y = self.decode(&h, rng)?;
                let d = self.config.dofs;
                let a = || key_poses.0.narrow(D::Minus1, 0, d);
                let y = match self.config.no_memory_output {
                    NoMemoryOutput::Pose => y,
                    NoMemoryOutput::KeyResidual => (a()? + y)?,
                    // Small wherever the keys pin the motion down, so the dropout on the
                    // decoder perturbs the keys little.
                    NoMemoryOutput::Interpolation => {
                        let t_rel = keys.narrow(D::Minus1, keys.dim(D::Minus1)? - 1, 1)?;
                        let (a, b) = (a()?, key_poses.1.narrow(D::Minus1, 0, d)?);
                        ((&a + (b - &a)?.broadcast_mul(&t_rel)?)? + y)?
                    }
                };
                Ok((y, ArnnState { gru: vec![] }))
            }
            Body::Segregated { prev_features, rnn, correction, .. } => {
                // The motion pattern network sees only the previous pose; the interpolation
                // network only the keys and t_rel (Figure 14).
                let (h, state) = self.recurrent(rnn, &prev_features.forward(prev)?, state, rng.as_deref_mut())?;
                let motion = (prev + self.decode(&h, rng.as_deref_mut())?)?;
                let x = keys.clone();
                let drop = Dropout::new(self.config.linear_dropout[0]);
                let fix = correction.forward_dropout(&x, &drop, rng)?;
                Ok(((motion + fix)?, state))
            }
        }
    }

    /// Two GRU layers with SELU and dropout after each; the second layer's output.
    fn recurrent(
        &self,
        rnn: &Recurrent,
        x: &Tensor,
        state: &ArnnState,
        mut rng: Option<&mut RowRngs>,
    ) -> Result<(Tensor, ArnnState)> {
        if state.gru.len() != 2 {
            candle_core::bail!("the state has {} GRU layers, the network 2", state.gru.len())
        }
        // SELU and dropout after each layer, one fused op each.
        let selu_dropout = |h: &Tensor, p: f64, rng: Option<&mut RowRngs>| -> Result<Tensor> {
            zoo_nn::act::bias_act(h, None, Activation::Selu, Dropout::new(p).mask(h, rng)?)
        };
        let s1 = rnn.gru1.step(x, &state.gru[0])?;
        let h1 = selu_dropout(s1.output(), self.config.gru_dropout[0], rng.as_deref_mut())?;
        let s2 = rnn.gru2.step(&h1, &state.gru[1])?;
        let h2 = selu_dropout(s2.output(), self.config.gru_dropout[1], rng)?;
        Ok((h2, ArnnState { gru: vec![s1, s2] }))
    }

    /// The decoder: two SELU layers with dropout, a linear layer to the pose.
    fn decode(&self, h: &Tensor, mut rng: Option<&mut RowRngs>) -> Result<Tensor> {
        let layers = self.decoder.layers();
        let mut y = h.clone();
        for (i, l) in layers.iter().enumerate() {
            y = if i + 1 < layers.len() {
                let drop = Dropout::new(self.config.linear_dropout[i.min(1)]);
                zoo_nn::layers::linear_act(l, &y, Activation::Selu, &drop, rng.as_deref_mut())?
            } else {
                zoo_nn::layers::linear_forward(l, &y)?
            };
        }
        Ok(y)
    }
}
