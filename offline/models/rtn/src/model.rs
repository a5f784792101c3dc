//! The Recurrent Transition Network (Harvey & Pal 2018, sec. 4).

use crate::config::{Config, InitState};
use candle_core::{DType, Device, Module, Result, Tensor};
use candle_nn::VarBuilder;
use zoo_nn::{Activation, Mlp};

/// The LSTM state `(h, c)`, each `(batch, units)`. Lives outside the model (one per character).
#[derive(Clone, Debug)]
pub struct RtnState {
    /// Output state `h`.
    pub h: Tensor,
    /// Cell state `c`.
    pub c: Tensor,
}

/// Per-sequence constants: the encoded target's contribution to the gates and the fused gate
/// weights. Built once per transition by [`Rtn::begin`] (the target is constant, RTN sec. 4.3).
#[derive(Clone, Debug)]
pub struct RtnSequence {
    /// `[W; U; C_O]^T`, `(E + H + O, 4H)`, so each step is one matmul for the four gates; `None`
    /// inside a data-parallel training step, where each gate weight is taped on its own
    /// (`zoo_nn::tape`: the workers share the variables' copies, not a fused matrix per worker).
    fused_t: Option<Tensor>,
    /// `C_F h_F + b`, `(batch, 4H)` (or `(1, 4H)` without conditioning).
    gate_bias: Tensor,
}

impl RtnSequence {
    /// `C_F h_F + b`, the per-sequence gate bias `(batch, 4H)` (`(1, 4H)` without future
    /// conditioning): the `gate_bias` state of the exported step graph.
    pub fn gate_bias(&self) -> &Tensor {
        &self.gate_bias
    }
}

/// Inputs of one step, normalised: the sequence constants from [`Rtn::begin`], `x` `(batch, D)`,
/// the global offset `o_t` `(batch, D)` (ignored without future conditioning), the terrain
/// patch `(batch, side^2)` when the model is terrain-aware and the interpolation frame
/// `(batch, D)` when it predicts a residual on the interpolation.
#[derive(Clone, Copy, Debug)]
pub struct RtnInputs<'a> {
    /// Per-sequence constants (encoded target, fused gate weights).
    pub sequence: &'a RtnSequence,
    /// Current frame features `x_t`.
    pub x: &'a Tensor,
    /// Normalised global offset `o_t` of the current frame from the target.
    pub offset: Option<&'a Tensor>,
    /// Normalised terrain patch `p_t`.
    pub terrain: Option<&'a Tensor>,
    /// Normalised interpolation frame `b_(t+1)` `(batch, D)`, required with
    /// [`Config::interp_residual`] (ignored without).
    pub base: Option<&'a Tensor>,
    /// The time-to-arrival embedding `(batch, dims)` of the frame this step predicts, required
    /// with [`Config::time_to_arrival`] (ignored without).
    pub tta: Option<&'a Tensor>,
}

/// The Recurrent Transition Network: encoders E, F, O, the conditioned LSTM R, decoder D and
/// state initialiser H (RTN sec. 4, Fig. 3).
///
/// Tensor names: `frame_encoder.{i}.*`, `target_encoder.{i}.*`, `offset_encoder.{i}.*`,
/// `lstm.{weight_ih,weight_hh,weight_target,weight_offset,bias}` (gate blocks in the order
/// i, f, g, o like candle's and PyTorch's LSTM), `decoder.{i}.*`, `state_init.{i}.*` (learned H)
/// or `state_init.{h,c}` (common state).
#[derive(Clone, Debug)]
pub struct Rtn {
    config: Config,
    device: Device,
    frame_encoder: Mlp,
    target_encoder: Option<Mlp>,
    offset_encoder: Option<Mlp>,
    weight_ih: Tensor,
    weight_hh: Tensor,
    weight_target: Option<Tensor>,
    weight_offset: Option<Tensor>,
    bias: Tensor,
    decoder: Mlp,
    init: Init,
}

#[derive(Clone, Debug)]
enum Init {
    Learned(Mlp),
    Zero,
    Common { h: Tensor, c: Tensor },
}

impl Rtn {
    /// Builds (or loads, depending on `vb`) the model.
    pub fn new(config: &Config, vb: VarBuilder) -> Result<Self> {
        let d = config.dim();
        // `phi` in the paper: every hidden layer is leaky-ReLU activated.
        let phi = Activation::LeakyRelu(config.leaky_slope);
        let hu = config.lstm;
        let frame_encoder =
            Mlp::new(config.frame_encoder_input(), &config.frame_encoder, phi, true, vb.pp("frame_encoder"))?;
        let (target_encoder, offset_encoder) = if config.future_conditioning {
            (
                Some(Mlp::new(2 * d, &config.target_encoder, phi, true, vb.pp("target_encoder"))?),
                Some(Mlp::new(d, &config.offset_encoder, phi, true, vb.pp("offset_encoder"))?),
            )
        } else {
            (None, None)
        };
        let e = frame_encoder.out_dim();
        // PyTorch's LSTM initialisation: U(-1/sqrt(H), 1/sqrt(H)) for every weight and bias.
        let k = 1.0 / (hu as f64).sqrt();
        let init = candle_nn::Init::Uniform { lo: -k, up: k };
        let lv = vb.pp("lstm");
        let weight_ih = lv.get_with_hints((4 * hu, e), "weight_ih", init)?;
        let weight_hh = lv.get_with_hints((4 * hu, hu), "weight_hh", init)?;
        let (weight_target, weight_offset) = match (&target_encoder, &offset_encoder) {
            (Some(f), Some(o)) => (
                Some(lv.get_with_hints((4 * hu, f.out_dim()), "weight_target", init)?),
                Some(lv.get_with_hints((4 * hu, o.out_dim()), "weight_offset", init)?),
            ),
            _ => (None, None),
        };
        let bias = lv.get_with_hints(4 * hu, "bias", init)?;
        let mut dec_sizes = config.decoder.clone();
        dec_sizes.push(d);
        let decoder = Mlp::new(hu, &dec_sizes, phi, false, vb.pp("decoder"))?;
        let sv = vb.pp("state_init");
        let init = match config.init_state {
            // RTN eq. 14: one hidden layer, linear output of (h, c)
            InitState::Learned => Init::Learned(Mlp::new(d, &[config.init_hidden, 2 * hu], phi, false, sv)?),
            InitState::Zero => Init::Zero,
            InitState::Common => Init::Common {
                h: sv.get_with_hints((1, hu), "h", candle_nn::Init::Const(0.0))?,
                c: sv.get_with_hints((1, hu), "c", candle_nn::Init::Const(0.0))?,
            },
        };
        Ok(Rtn {
            config: config.clone(),
            device: vb.device().clone(),
            frame_encoder,
            target_encoder,
            offset_encoder,
            weight_ih,
            weight_hh,
            weight_target,
            weight_offset,
            bias,
            decoder,
            init,
        })
    }

    /// The configuration the model was built with.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The device of the weights.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Zero LSTM state for `batch` sequences.
    pub fn zero_state(&self, batch: usize, device: &Device) -> Result<RtnState> {
        let z = Tensor::zeros((batch, self.config.lstm), DType::F32, device)?;
        Ok(RtnState { h: z.clone(), c: z })
    }

    /// Initial LSTM state from the first frame `x0` `(batch, D)` (RTN sec. 4.6, eq. 14), or the
    /// ablations' zero / common learned state.
    pub fn initial_state(&self, x0: &Tensor) -> Result<RtnState> {
        let b = x0.dim(0)?;
        let hu = self.config.lstm;
        match &self.init {
            Init::Learned(mlp) => {
                let hc = mlp.forward(x0)?;
                Ok(RtnState { h: hc.narrow(1, 0, hu)?, c: hc.narrow(1, hu, hu)? })
            }
            Init::Zero => self.zero_state(b, x0.device()),
            Init::Common { h, c } => Ok(RtnState { h: h.broadcast_as((b, hu))?, c: c.broadcast_as((b, hu))? }),
        }
    }

    /// Per-sequence constants from the normalised target vector `(batch, 2D)` (ignored without
    /// future conditioning): encodes the target once (eq. 3) and fuses the gate weights.
    pub fn begin(&self, target: &Tensor) -> Result<RtnSequence> {
        let fused_t = if zoo_nn::tape::active() {
            None
        } else {
            let mut w = vec![&self.weight_ih, &self.weight_hh];
            if let Some(wo) = &self.weight_offset {
                w.push(wo);
            }
            Some(Tensor::cat(&w, 1)?.t()?.contiguous()?)
        };
        let gate_bias = match (&self.target_encoder, &self.weight_target) {
            (Some(f), Some(wt)) => {
                let hf = f.forward(target)?; // RTN eq. 3
                hf.matmul(&wt.t()?)?.broadcast_add(&self.bias)?
            }
            _ => self.bias.unsqueeze(0)?,
        };
        Ok(RtnSequence { fused_t, gate_bias })
    }

    /// One step: from the current frame `x_t` (and offset, terrain) and the state, the next frame
    /// `x_(t+1)` `(batch, D)` and the new state.
    pub fn step(&self, inputs: &RtnInputs, state: &RtnState) -> Result<(Tensor, RtnState)> {
        let (x, seq) = (inputs.x, inputs.sequence);
        // RTN eq. 2: h_E = E([x_t, p_t]), with the interpolation frame appended: E([x_t, p_t, b_(t+1)])
        let mut e_in = vec![x];
        match (self.config.terrain, inputs.terrain) {
            (true, Some(p)) => e_in.push(p),
            (true, None) => candle_core::bail!("this RTN is terrain-aware: pass a terrain patch to every step"),
            (false, _) => {}
        }
        let base = match (self.config.interp_residual, inputs.base) {
            (true, Some(b)) => {
                e_in.push(b);
                Some(b)
            }
            (true, None) => candle_core::bail!(
                "this RTN predicts a residual on the interpolation: pass the interpolation frame to every step"
            ),
            (false, _) => None,
        };
        match (self.config.time_to_arrival.is_some(), inputs.tta) {
            (true, Some(z)) => e_in.push(z),
            (true, None) => candle_core::bail!(
                "this RTN reads the time to arrival: pass its embedding of the frames left to every step"
            ),
            (false, _) => {}
        }
        let he = if e_in.len() == 1 {
            self.frame_encoder.forward(x)?
        } else {
            self.frame_encoder.forward(&Tensor::cat(&e_in, 1)?)?
        };
        // RTN eq. 5-8 with one fused matmul: [h_E, h_(t-1), h_O] [W; U; C_O]^T + (C_F h_F + b)
        let ho = match &self.offset_encoder {
            Some(o) => {
                let Some(off) = inputs.offset else {
                    candle_core::bail!("this RTN is conditioned on the future: pass the global offset to every step")
                };
                Some(o.forward(off)?) // RTN eq. 4
            }
            None => None,
        };
        let z = match &seq.fused_t {
            Some(fused_t) => {
                let z_in = match &ho {
                    Some(ho) => Tensor::cat(&[&he, &state.h, ho], 1)?,
                    None => Tensor::cat(&[&he, &state.h], 1)?,
                };
                z_in.matmul(fused_t)?
            }
            None => {
                // Training: each weight's gradient taped (zoo_nn::tape), the same sum of products.
                let mut z = (zoo_nn::tape::matmul_weight(&he, &self.weight_ih, true)?
                    + zoo_nn::tape::matmul_weight(&state.h, &self.weight_hh, true)?)?;
                if let (Some(ho), Some(wo)) = (&ho, &self.weight_offset) {
                    z = (z + zoo_nn::tape::matmul_weight(ho, wo, true)?)?;
                }
                z
            }
        }
        .broadcast_add(&seq.gate_bias)?;
        // RTN eq. 5-11 after the gate sums: one fused cell step (zoo_nn::cells).
        let (h, c) = zoo_nn::cells::lstm_cell(&z, &state.c)?;
        // RTN eq. 12-13; with the interpolation residual x_(t+1) = b_(t+1) + D(h_t)
        let dx = self.decoder.forward(&h)?;
        let next = match base {
            Some(b) => (b + dx)?,
            None if self.config.residual => (x + dx)?,
            None => dx,
        };
        Ok((next, RtnState { h, c }))
    }

    /// Total number of parameters.
    pub fn parameter_count(&self) -> usize {
        let mut n = 0;
        let mut add = |t: &Tensor| n += t.elem_count();
        let mlps = [
            Some(&self.frame_encoder),
            self.target_encoder.as_ref(),
            self.offset_encoder.as_ref(),
            Some(&self.decoder),
        ];
        for m in mlps.into_iter().flatten() {
            for l in m.layers() {
                add(l.weight());
                if let Some(b) = l.bias() {
                    add(b);
                }
            }
        }
        for t in [
            Some(&self.weight_ih),
            Some(&self.weight_hh),
            self.weight_target.as_ref(),
            self.weight_offset.as_ref(),
            Some(&self.bias),
        ]
        .into_iter()
        .flatten()
        {
            add(t);
        }
        match &self.init {
            Init::Learned(m) => {
                for l in m.layers() {
                    add(l.weight());
                    if let Some(b) = l.bias() {
                        add(b);
                    }
                }
            }
            Init::Zero => {}
            Init::Common { h, c } => {
                add(h);
                add(c);
            }
        }
        n
    }
}

/// Normalisation constants as tensors, to recompute the global offset `o_t` from generated
/// frames inside the graph (RTN sec. 3.2: offsets follow the generated frames).
#[derive(Clone, Debug)]
pub struct OffsetTensors {
    /// `sigma_x * m * inv_sigma_o`, `(1, D)`, `m` masking the root-velocity slot.
    x_scale: Tensor,
    /// `mu_x * m * inv_sigma_o`, `(1, D)`.
    x_shift: Tensor,
    /// `(3, D)`: tiles a root position over every joint and divides by `sigma_o`.
    root_tile: Tensor,
    /// `mu_o * inv_sigma_o`, `(1, D)`.
    o_shift: Tensor,
    /// `inv_sigma_o`, `(1, D)`.
    o_inv: Tensor,
    /// `sigma_x` of the root velocity, `(1, 3)`.
    v_scale: Tensor,
    /// `mu_x` of the root velocity, `(1, 3)`.
    v_shift: Tensor,
}

impl OffsetTensors {
    /// From the statistics of features and offsets.
    pub fn new(stats: &crate::features::FeatureStats, device: &Device) -> Result<Self> {
        let d = stats.dim();
        let inv: Vec<f32> = stats.offset.std.iter().map(|s| 1.0 / s).collect();
        let mask = |i: usize| if i < 3 { 0.0 } else { 1.0 };
        let x_scale: Vec<f32> = (0..d).map(|i| stats.x.std[i] * mask(i) * inv[i]).collect();
        let x_shift: Vec<f32> = (0..d).map(|i| stats.x.mean[i] * mask(i) * inv[i]).collect();
        let mut tile = vec![0f32; 3 * d];
        for i in 0..d {
            tile[(i % 3) * d + i] = inv[i];
        }
        let o_shift: Vec<f32> = (0..d).map(|i| stats.offset.mean[i] * inv[i]).collect();
        let row = |v: Vec<f32>| Tensor::from_vec(v, (1, d), device);
        Ok(OffsetTensors {
            x_scale: row(x_scale)?,
            x_shift: row(x_shift)?,
            root_tile: Tensor::from_vec(tile, (3, d), device)?,
            o_shift: row(o_shift)?,
            o_inv: row(inv)?,
            v_scale: Tensor::from_slice(&stats.x.std[..3], (1, 3), device)?,
            v_shift: Tensor::from_slice(&stats.x.mean[..3], (1, 3), device)?,
        })
    }

    /// Per-sequence constant `(y_T - mu_o) / sigma_o + mu_x m / sigma_o` from the global target
    /// frame `(batch, D)`.
    pub fn target_term(&self, target_global: &Tensor) -> Result<Tensor> {
        target_global.broadcast_mul(&self.o_inv)?.broadcast_sub(&self.o_shift)?.broadcast_sub(&self.x_shift)
    }

    /// Global root of a generated frame: previous root plus the denormalised root velocity.
    pub fn next_root(&self, prev_root: &Tensor, x: &Tensor) -> Result<Tensor> {
        prev_root + x.narrow(1, 0, 3)?.broadcast_mul(&self.v_scale)?.broadcast_add(&self.v_shift)?
    }

    /// The normalised interpolation frames `b_0 .. b_n` `(batch, D)` of a transition of `n`
    /// frames before the target (`n + 1` of them, the last at the target), from the normalised
    /// features of the last context frame `x_last`, its global root `root_last` `(batch, 3)`,
    /// the normalised target vector `target` `(batch, 2D)` and the global target frame
    /// `target_global` `(batch, D)`: the features of the linear interpolation of positions
    /// between the last context frame and the target (see
    /// [`crate::features::interpolation_frame`]; normalisation is affine, so the root-relative
    /// values are interpolated normalised).
    pub fn interpolation_frames(
        &self,
        x_last: &Tensor,
        root_last: &Tensor,
        target: &Tensor,
        target_global: &Tensor,
        n: usize,
    ) -> Result<Vec<Tensor>> {
        let d = x_last.dim(1)?;
        let steps = (n + 1) as f64;
        let v = ((target_global.narrow(1, 0, 3)? - root_last)? / steps)?;
        let v = v.broadcast_sub(&self.v_shift)?.broadcast_div(&self.v_scale)?;
        let from = x_last.narrow(1, 3, d - 3)?;
        let to = target.narrow(1, 3, d - 3)?;
        let span = (&to - &from)?;
        (0..=n)
            .map(|i| {
                let w = (i + 1) as f64 / steps;
                Tensor::cat(&[&v, &(&from + (&span * w)?)?], 1)
            })
            .collect()
    }

    /// Normalised global offset `o_t = ((y_T - y_t) - mu_o) / sigma_o` of the frame with
    /// features `x` `(batch, D)` and global root `root` `(batch, 3)`; `target_term` from
    /// [`OffsetTensors::target_term`].
    pub fn offset(&self, target_term: &Tensor, x: &Tensor, root: &Tensor) -> Result<Tensor> {
        let xs = x.broadcast_mul(&self.x_scale)?;
        let rt = root.matmul(&self.root_tile)?;
        (target_term - xs)? - rt
    }
}
