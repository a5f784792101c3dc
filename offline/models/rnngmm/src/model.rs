//! The generator G (sec. 4.1.2, Fig. 3): fully connected layers FC1-FC3 (ReLU), a 2-layer LSTM
//! and the mixture head, with the LSTM state outside the model (one per character).

use crate::config::Config;
use crate::error::{RnnGmmError, RnnGmmResult};
use crate::gmm::{self, Mixture, MixtureTensors};
use candle_core::{DType, Device, Module, Result, Tensor};
use candle_nn::{Linear, VarBuilder};
use zoo_motion::rng::SplitMix64;
use zoo_nn::{Activation, Lstm, LstmState, Mlp};

/// The generator: `x_t` (normalised, `(batch, D)`) and the LSTM state give the mixture over
/// `x_(t+1)` (eq. 5-7).
///
/// Tensor names: `fc.{i}.{weight,bias}`, `lstm.{weight_ih,weight_hh,bias_ih,bias_hh}_l{k}`
/// (PyTorch's LSTM names and gate order i, f, g, o), `head.{weight,bias}` (`M (1 + 2 D)` outputs:
/// logits, means, log stds; see [`crate::gmm`]).
#[derive(Clone, Debug)]
pub struct Generator {
    config: Config,
    device: Device,
    fc: Mlp,
    lstm: Lstm,
    head: Linear,
}

impl Generator {
    /// Builds (or loads, depending on `vb`) the generator of `config` (validated first).
    pub fn new(config: &Config, vb: VarBuilder) -> RnnGmmResult<Self> {
        config.validate()?;
        let fc = Mlp::new(config.dim, &config.fc, Activation::Relu, true, vb.pp("fc"))?;
        let lstm = Lstm::new(fc.out_dim(), config.lstm, config.lstm_layers, 0.0, vb.pp("lstm"))?;
        let head = candle_nn::linear(config.lstm, config.head_dim(), vb.pp("head"))?;
        Ok(Generator { config: config.clone(), device: vb.device().clone(), fc, lstm, head })
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The device of the weights.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Zero `h` and `c` of every layer for `batch` sequences (the paper's start; see
    /// [`crate::initial_state`] for eq. 26).
    pub fn zero_state(&self, batch: usize) -> Result<LstmState> {
        self.lstm.zero_state(batch)
    }

    /// One step: normalised `x` `(batch, D)` and the state give the head outputs `(batch,
    /// M (1 + 2 D))` and the next state.
    pub fn step(&self, x: &Tensor, state: &LstmState) -> Result<(Tensor, LstmState)> {
        let state = self.lstm.step(&self.fc.forward(x)?, state)?;
        Ok((self.head.forward(state.output())?, state))
    }

    /// A whole sequence `(batch, time, D)` from `state`: head outputs `(batch, time, M (1 + 2 D))`
    /// (output `t` is the mixture over frame `t + 1`) and the last state.
    pub fn forward_seq(&self, xs: &Tensor, state: &LstmState) -> Result<(Tensor, LstmState)> {
        let (out, state) = self.lstm.forward_seq(&self.fc.forward(xs)?, state, None)?;
        Ok((self.head.forward(&out)?, state))
    }

    /// The mixture parameters of head outputs (eq. 7).
    pub fn mixture(&self, raw: &Tensor) -> Result<MixtureTensors> {
        let c = &self.config;
        gmm::split_head(raw, c.components, c.dim, c.min_log_std, c.max_log_std)
    }

    /// The mixture of one frame's head outputs in plain numbers.
    pub fn mixture_of(&self, raw: &[f32]) -> RnnGmmResult<Mixture> {
        let c = &self.config;
        Mixture::from_head(raw, c.components, c.dim, c.min_log_std, c.max_log_std)
    }

    /// Mean NLL per frame of `xs[:, 1..]` given `xs[:, ..T-1]` (`inputs` may carry noise; the
    /// targets are `targets`), both `(batch, time, D)`, from zero states.
    pub fn sequence_nll(&self, inputs: &Tensor, targets: &Tensor) -> Result<Tensor> {
        let state = self.zero_state(inputs.dim(0)?)?;
        let (raw, _) = self.forward_seq(inputs, &state)?;
        gmm::nll(&self.mixture(&raw)?, targets)?.mean_all()
    }

    /// Number of parameters.
    pub fn parameter_count(&self) -> usize {
        let c = &self.config;
        let mut n = 0;
        let mut prev = c.dim;
        for &w in &c.fc {
            n += prev * w + w;
            prev = w;
        }
        for k in 0..c.lstm_layers {
            let input = if k == 0 { prev } else { c.lstm };
            n += 4 * c.lstm * (input + c.lstm + 2);
        }
        n + c.lstm * c.head_dim() + c.head_dim()
    }

    /// Random synthesis (sec. 4.1.4): from normalised seed frames `start` (`(n, D)` values, n >=
    /// 1, fed in order from `state`), samples `frames` further normalised frames, each fed back
    /// as the next input. Deterministic for a seed; `temperature` scales the standard deviations.
    /// Returns the sampled frames (`frames * D`) and the final state.
    pub fn sample(
        &self,
        start: &[f32],
        state: &LstmState,
        frames: usize,
        rng: &mut SplitMix64,
        temperature: f64,
    ) -> RnnGmmResult<(Vec<f32>, LstmState)> {
        let d = self.config.dim;
        if start.is_empty() || !start.len().is_multiple_of(d) {
            return Err(RnnGmmError::Size {
                what: "seed frames".into(),
                expected: d,
                detail: format!("a whole number of frames of D = {d} values, at least one"),
                found: start.len(),
            });
        }
        if !(temperature.is_finite() && temperature >= 0.0) {
            return Err(RnnGmmError::Config(format!(
                "temperature must be finite and not negative, found {temperature}"
            )));
        }
        let mut state = state.clone();
        let mut raw = None;
        for x in start.chunks_exact(d) {
            let (r, s) = self.step(&Tensor::from_slice(x, (1, d), &self.device)?, &state)?;
            (raw, state) = (Some(r), s);
        }
        let mut out = vec![0f32; frames * d];
        for f in 0..frames {
            let head = raw.take().expect("one step per frame").flatten_all()?.to_dtype(DType::F32)?.to_vec1::<f32>()?;
            let frame = &mut out[f * d..(f + 1) * d];
            self.mixture_of(&head)?.sample(rng, temperature, frame);
            let (r, s) = self.step(&Tensor::from_slice(frame, (1, d), &self.device)?, &state)?;
            (raw, state) = (Some(r), s);
        }
        Ok((out, state))
    }

    /// Batched random synthesis: `n` sequences, each seeded with its own `seed_len` normalised
    /// frames (`start`: `n * seed_len * D` values, sequence-major) fed from zero states, then
    /// `frames` sampled frames each. Returns `n * frames * D` values, sequence-major.
    /// Deterministic for a seed (draws go sequence by sequence within each frame).
    pub fn sample_batch(
        &self,
        start: &[f32],
        n: usize,
        seed_len: usize,
        frames: usize,
        rng: &mut SplitMix64,
        temperature: f64,
    ) -> RnnGmmResult<Vec<f32>> {
        let d = self.config.dim;
        if n == 0 || seed_len == 0 || start.len() != n * seed_len * d {
            return Err(RnnGmmError::Size {
                what: "seed frames".into(),
                expected: n * seed_len * d,
                detail: format!("{n} sequences of {seed_len} frames of D = {d}, both positive"),
                found: start.len(),
            });
        }
        if !(temperature.is_finite() && temperature >= 0.0) {
            return Err(RnnGmmError::Config(format!(
                "temperature must be finite and not negative, found {temperature}"
            )));
        }
        let seeds = Tensor::from_slice(start, (n, seed_len, d), &self.device)?;
        let (raw, mut state) = self.forward_seq(&seeds, &self.zero_state(n)?)?;
        let mut raw = raw.narrow(1, seed_len - 1, 1)?.squeeze(1)?;
        let mut out = vec![0f32; n * frames * d];
        let mut frame = vec![0f32; n * d];
        for f in 0..frames {
            let heads = raw.to_dtype(DType::F32)?.to_vec2::<f32>()?;
            for (i, head) in heads.iter().enumerate() {
                let x = &mut frame[i * d..(i + 1) * d];
                self.mixture_of(head)?.sample(rng, temperature, x);
                out[(i * frames + f) * d..(i * frames + f + 1) * d].copy_from_slice(x);
            }
            if f + 1 < frames {
                let (r, s) = self.step(&Tensor::from_slice(&frame, (n, d), &self.device)?, &state)?;
                (raw, state) = (r, s);
            }
        }
        Ok(out)
    }
}
