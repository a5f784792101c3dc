//! The network of RMR sec. 5 (Figure 5): encoder E (fully connected, ReLU), recurrent refiner R
//! (two layers; the cell is the Table 1 switch), decoder D (fully connected, ReLU, last layer
//! linear). Sequences are batch-first `(batch, frames, dim)` in normalised units.

use crate::config::{Config, RefinerCell};
use crate::error::{RmrError, RmrResult};
use candle_core::{Device, Module, Tensor};
use candle_nn::VarBuilder;
use zoo_nn::RowRngs;
use zoo_nn::{Activation, BiGru, BiLstm, Gru, Lstm, Mlp};

/// The recurrent refiner R.
#[derive(Clone, Debug)]
pub enum Refiner {
    /// Unidirectional LSTM from a zero state.
    Lstm(Lstm),
    /// Unidirectional GRU from a zero state.
    Gru(Gru),
    /// Bidirectional LSTM.
    Blstm(BiLstm),
    /// Bidirectional GRU (the paper's).
    Bgru(BiGru),
}

impl Refiner {
    fn new(config: &Config, vb: VarBuilder) -> candle_core::Result<Refiner> {
        let (i, h, l, p) = (*config.encoder.last().unwrap_or(&0), config.hidden, config.layers, config.dropout);
        Ok(match config.cell {
            RefinerCell::Lstm => Refiner::Lstm(Lstm::new(i, h, l, p, vb)?),
            RefinerCell::Gru => Refiner::Gru(Gru::new(i, h, l, p, vb)?),
            RefinerCell::Blstm => Refiner::Blstm(BiLstm::new(i, h, l, p, vb)?),
            RefinerCell::Bgru => Refiner::Bgru(BiGru::new(i, h, l, p, vb)?),
        })
    }

    /// `(batch, frames, in)` -> `(batch, frames, H)` or `(batch, frames, 2H)` (bidirectional:
    /// forward then backward hidden state of the last layer, concatenated).
    pub fn forward(&self, xs: &Tensor, rng: Option<&mut RowRngs>) -> candle_core::Result<Tensor> {
        let batch = xs.dim(0)?;
        match self {
            Refiner::Lstm(r) => Ok(r.forward_seq(xs, &r.zero_state(batch)?, rng)?.0),
            Refiner::Gru(r) => Ok(r.forward_seq(xs, &r.zero_state(batch)?, rng)?.0),
            Refiner::Blstm(r) => r.forward(xs, rng),
            Refiner::Bgru(r) => r.forward(xs, rng),
        }
    }
}

/// The Recurrent Motion Refiner. Weights: `encoder.{0,1}`, `refiner.weight_ih_l0...`,
/// `decoder.{0,1}`. With [`Config::residual`] the output is `x + D(R(E(x)))` on the pose
/// values and `D(R(E(x)))` on the contacts.
#[derive(Clone, Debug)]
pub struct Rmr {
    config: Config,
    encoder: Mlp,
    refiner: Refiner,
    decoder: Mlp,
    /// `(1, 1, dim)`: 1 on the pose values, 0 on the contacts (residual decoder only).
    residual_mask: Option<Tensor>,
    device: Device,
    fallback_counts: std::sync::Arc<crate::fallback::FallbackCounts>,
}

impl Rmr {
    /// Builds (or loads, depending on `vb`) the model.
    pub fn new(config: &Config, vb: VarBuilder) -> RmrResult<Rmr> {
        config.validate()?;
        let d = config.dim();
        let encoder = Mlp::new(d, &config.encoder, Activation::Relu, true, vb.pp("encoder"))?;
        let refiner = Refiner::new(config, vb.pp("refiner"))?;
        let width = if config.cell.bidirectional() { 2 * config.hidden } else { config.hidden };
        let mut widths = config.decoder.clone();
        widths.push(d);
        let decoder = Mlp::new(width, &widths, Activation::Relu, false, vb.pp("decoder"))?;
        let residual_mask = config
            .residual
            .then(|| {
                let pose =
                    crate::features::FeatureLayout::new(config.joints, config.layout.lower_body.len()).contacts();
                let mask: Vec<f32> = (0..d).map(|i| if i < pose { 1.0 } else { 0.0 }).collect();
                Tensor::from_vec(mask, (1, 1, d), vb.device())
            })
            .transpose()?;
        Ok(Rmr {
            config: config.clone(),
            encoder,
            refiner,
            decoder,
            residual_mask,
            device: vb.device().clone(),
            fallback_counts: Default::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The device of the weights.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The refiner.
    pub fn refiner(&self) -> &Refiner {
        &self.refiner
    }

    /// Refines normalised sequences `(batch, frames, dim)` into `(batch, frames, dim)` (the
    /// contact values are logits; with [`Config::residual`] the pose values are the input's
    /// plus the decoder's correction). Dropout is drawn from `rng` when it is `Some` (training).
    pub fn forward(&self, xs: &Tensor, rng: Option<&mut RowRngs>) -> RmrResult<Tensor> {
        let d = self.config.dim();
        let dims = xs.dims();
        if dims.len() != 3 || dims[2] != d || dims[1] == 0 {
            return Err(RmrError::Config(format!(
                "the refiner takes (batch, frames >= 1, {d}) pose vectors, got shape {dims:?}"
            )));
        }
        let h = self.encoder.forward(xs)?;
        let h = self.refiner.forward(&h, rng)?;
        let y = self.decoder.forward(&h)?;
        match &self.residual_mask {
            Some(mask) => Ok((y + xs.broadcast_mul(mask)?)?),
            None => Ok(y),
        }
    }

    /// How many of the decoder's first hidden ReLU units are active (output > 0) on at least
    /// one frame of `xs` `(batch, frames, dim)`, evaluation mode, and how many there are. A
    /// unit that is inactive on every frame gets no gradient again: when all are, the model is
    /// stuck at its output layer's bias (docs/rmr.md, "Dead decoder units").
    pub fn active_decoder_units(&self, xs: &Tensor) -> RmrResult<(usize, usize)> {
        let first = self.decoder.layers().first().ok_or_else(|| RmrError::Config("the decoder has no layer".into()))?;
        let h = self.refiner.forward(&self.encoder.forward(xs)?, None)?;
        let pre = first.forward(&h)?;
        let units = pre.dim(2)?;
        let max = pre.flatten_to(1)?.max(0)?.to_vec1::<f32>()?;
        Ok((max.iter().filter(|&&m| m > 0.0).count(), units))
    }

    /// Sets the fallback [`Rmr::refine_window`] applies (`None`: the network alone, as
    /// `--no-fallback` asks); a loaded model has its configuration's.
    pub fn set_fallback(&mut self, fallback: Option<crate::fallback::Fallback>) {
        self.config.fallback = fallback;
    }

    /// [`Rmr::refine`] followed by the configuration's fallback ([`crate::fallback`]): the
    /// window refiner of `zoo stitch` and the benchmark.
    pub fn refine_window(&self, x: &[f32]) -> RmrResult<Vec<f32>> {
        let mut y = self.refine(x)?;
        if let Some(f) = &self.config.fallback {
            let fl = crate::features::FeatureLayout::new(self.config.joints, self.config.layout.lower_body.len());
            self.fallback_counts.count(f.apply(x, &mut y, fl.dim(), fl.contacts()));
        }
        Ok(y)
    }

    /// How often [`Rmr::refine_window`]'s fallback acted on this model and its clones
    /// ([`crate::fallback::FallbackCounts::summary`]); `None` without a fallback.
    pub fn fallback_summary(&self) -> Option<(u64, f64, f64)> {
        self.config.fallback.map(|_| self.fallback_counts.summary())
    }

    /// Refines one sequence of normalised pose vectors (`frames * dim`), evaluation mode.
    pub fn refine(&self, x: &[f32]) -> RmrResult<Vec<f32>> {
        let d = self.config.dim();
        if x.is_empty() || !x.len().is_multiple_of(d) {
            return Err(RmrError::Size {
                what: "window".into(),
                expected: d,
                detail: format!("a positive multiple of the pose vector size {d}"),
                found: x.len(),
            });
        }
        let xs = Tensor::from_slice(x, (1, x.len() / d, d), &self.device)?;
        Ok(self.forward(&xs, None)?.flatten_all()?.to_vec1()?)
    }
}

/// Number of scalar parameters in `varmap`.
pub fn parameter_count(varmap: &candle_nn::VarMap) -> usize {
    varmap.all_vars().iter().map(|v| v.elem_count()).sum()
}
