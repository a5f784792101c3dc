//! The ARNN of section 6 (Figure 6): pose feature nets, two GRU layers with SELU between, a
//! two-layer decoder and a residual added to the previous pose.

use crate::config::ArnnConfig;
use candle_core::{D, Module, Result, Tensor};
use candle_nn::VarBuilder;
use zoo_nn::rng::SplitMix64;
use zoo_nn::{Activation, Dropout, Gru, GruState, Mlp};

/// The recurrent state: one [`GruState`] per GRU layer, each `(batch, hidden)`.
#[derive(Clone, Debug)]
pub struct ArnnState {
    /// First and second GRU layers.
    pub gru: [GruState; 2],
}

/// The network. Poses are normalised degrees of freedom `(batch, dofs)`.
#[derive(Clone, Debug)]
pub struct Arnn {
    config: ArnnConfig,
    prev_features: Mlp,
    key_a_features: Mlp,
    key_b_features: Mlp,
    gru1: Gru,
    gru2: Gru,
    decoder: Mlp,
}

impl Arnn {
    /// Builds (or loads) the weights: `prev_features`, `key_a_features`, `key_b_features`,
    /// `gru1`, `gru2`, `decoder`.
    pub fn new(config: &ArnnConfig, vb: VarBuilder) -> Result<Self> {
        config.validate().map_err(candle_core::Error::Msg)?;
        let (d, f, h, w) = (config.dofs, config.feature, config.hidden, config.decoder);
        let features = |name: &str| Mlp::new(d, &[f, f], Activation::Selu, true, vb.pp(name));
        Ok(Arnn {
            config: config.clone(),
            prev_features: features("prev_features")?,
            key_a_features: features("key_a_features")?,
            key_b_features: features("key_b_features")?,
            gru1: Gru::new(3 * f + 1, h, 1, 0.0, vb.pp("gru1"))?,
            gru2: Gru::new(h, h, 1, 0.0, vb.pp("gru2"))?,
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
        Ok(ArnnState { gru: [self.gru1.zero_state(batch)?, self.gru2.zero_state(batch)?] })
    }

    /// One frame (section 6): from the previous pose `Y'_{t-1}`, the keys `X_K` and `X_{K+1}`
    /// (each `(batch, dofs)`) and `t_rel` `(batch, 1)`, the pose `Y'_t` and the next state.
    /// `rng` `Some` applies dropout (training).
    pub fn step(
        &self,
        prev: &Tensor,
        key_a: &Tensor,
        key_b: &Tensor,
        t_rel: &Tensor,
        state: &ArnnState,
        mut rng: Option<&mut SplitMix64>,
    ) -> Result<(Tensor, ArnnState)> {
        let x = Tensor::cat(
            &[
                self.prev_features.forward(prev)?,
                self.key_a_features.forward(key_a)?,
                self.key_b_features.forward(key_b)?,
                t_rel.clone(),
            ],
            D::Minus1,
        )?;
        let s1 = self.gru1.step(&x, &state.gru[0])?;
        let h1 = Activation::Selu.apply(s1.output())?;
        let h1 = Dropout::new(self.config.gru_dropout[0]).forward(&h1, rng.as_deref_mut())?;
        let s2 = self.gru2.step(&h1, &state.gru[1])?;
        let h2 = Activation::Selu.apply(s2.output())?;
        let h2 = Dropout::new(self.config.gru_dropout[1]).forward(&h2, rng.as_deref_mut())?;
        let layers = self.decoder.layers();
        let mut y = h2;
        for (i, l) in layers.iter().enumerate() {
            y = l.forward(&y)?;
            if i + 1 < layers.len() {
                y = Activation::Selu.apply(&y)?;
                y = Dropout::new(self.config.linear_dropout[i.min(1)]).forward(&y, rng.as_deref_mut())?;
            }
        }
        Ok(((prev + y)?, ArnnState { gru: [s1, s2] }))
    }
}
