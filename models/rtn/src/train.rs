//! The training core (RTN sec. 3.3 and 6): random rotations, probabilistic teacher forcing,
//! MSE over the P + 1 predicted frames, AMSGrad.

use crate::amsgrad::{AmsGrad, ParamsAmsGrad};
use crate::config::Config;
use crate::error::{RtnError, RtnResult};
use crate::model::{OffsetTensors, Rtn};
use crate::transition::{SequenceInput, check_frames, encode_batch, generate};
use candle_core::{DType, Device, Tensor};
use candle_nn::{Optimizer, VarBuilder, VarMap};
use crate::features::{self, FeatureStats, Heightmap, MeanStd, Moments, YawAbout};

/// A training window: global joint positions (`frames * joints * 3`, frame-major, at least
/// [`Config::window_frames`] frames: past context, transition, target and the frame after it;
/// later frames are ignored) and, for the terrain-aware model, its heightmap.
#[derive(Clone, Copy, Debug)]
pub struct MotionWindow<'a> {
    /// Global positions.
    pub positions: &'a [f32],
    /// Terrain under the motion.
    pub terrain: Option<&'a Heightmap>,
}

impl<'a> MotionWindow<'a> {
    /// A window without terrain.
    pub fn new(positions: &'a [f32]) -> Self {
        MotionWindow { positions, terrain: None }
    }
}

/// SplitMix64: the trainer's small, seedable random source.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Fits the normalisation statistics of a training set (RTN sec. 3.2): features, target
/// velocities and offsets (yaw-invariant when the training rotates windows), and for the
/// terrain-aware model one mean/std shared by every terrain cell.
pub fn fit_stats(config: &Config, windows: &[MotionWindow]) -> RtnResult<FeatureStats> {
    let k = config.joints;
    for (i, w) in windows.iter().enumerate() {
        check_frames(&format!("training window {i}"), w.positions.len(), config.window_frames(), k, true)?;
    }
    let mut stats =
        FeatureStats::fit(windows.iter().map(|w| w.positions), k, config.target_frame(), config.train.random_rotation);
    if config.terrain {
        let mut m = Moments::new(1);
        let n = config.terrain_dim();
        let mut patch = vec![0f32; n];
        let d = config.dim();
        for (i, w) in windows.iter().enumerate() {
            let Some(map) = w.terrain else {
                return Err(RtnError::Config(format!(
                    "training window {i} has no terrain but the RTN is terrain-aware"
                )));
            };
            for f in 0..=config.target_frame() {
                let r = features::root_of(&w.positions[f * d..]);
                features::terrain_patch(map, r, config.terrain_extent, config.terrain_side, None, &mut patch);
                m.add(&patch);
            }
        }
        let s = m.finish(false);
        stats.terrain = Some(MeanStd { mean: vec![s.mean[0]; n], std: vec![s.std[0]; n] });
    }
    Ok(stats)
}

/// One variable of a trainer and its moving average.
struct Averaged {
    name: String,
    var: candle_core::Var,
    avg: Tensor,
}

/// Trains an RTN: owns the variables, the optimiser state, the statistics and the random source.
pub struct RtnTrainer {
    config: Config,
    stats: FeatureStats,
    varmap: VarMap,
    model: Rtn,
    opt: AmsGrad,
    offsets: OffsetTensors,
    rng: SplitMix64,
    step: u64,
    /// Moving average of every variable, in the optimiser's (sorted) order, when
    /// `config.train.ema_decay` is set.
    ema: Option<Vec<Averaged>>,
}

impl RtnTrainer {
    /// A freshly initialised model.
    pub fn new(config: &Config, stats: FeatureStats, device: &Device) -> RtnResult<Self> {
        Self::with_varmap(config, stats, VarMap::new(), device)
    }

    /// A trainer around `varmap`: variables it already holds are reused (e.g. loaded weights).
    pub(crate) fn with_varmap(
        config: &Config,
        stats: FeatureStats,
        varmap: VarMap,
        device: &Device,
    ) -> RtnResult<Self> {
        if stats.joints != config.joints {
            return Err(RtnError::Config(format!(
                "statistics are for {} joints, the configuration for {}",
                stats.joints, config.joints
            )));
        }
        if config.terrain && stats.terrain.is_none() {
            return Err(RtnError::Config("terrain-aware configuration but no terrain statistics".into()));
        }
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, device);
        let model = Rtn::new(config, vb)?;
        let t = &config.train;
        let params = ParamsAmsGrad { lr: t.learning_rate, beta1: t.beta1, beta2: t.beta2, eps: t.eps };
        let mut named: Vec<(String, candle_core::Var)> =
            varmap.data().lock().expect("varmap lock").iter().map(|(n, v)| (n.clone(), v.clone())).collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        let ema = match t.ema_decay {
            Some(d) if !(d > 0.0 && d < 1.0) => {
                return Err(RtnError::Config(format!("EMA decay {d} is outside (0, 1)")));
            }
            Some(_) => Some(
                named
                    .iter()
                    .map(|(name, var)| {
                        Ok(Averaged { name: name.clone(), var: var.clone(), avg: var.as_tensor().detach().copy()? })
                    })
                    .collect::<RtnResult<Vec<_>>>()?,
            ),
            None => None,
        };
        let opt = AmsGrad::new_named(named, params)?;
        let offsets = OffsetTensors::new(&stats, device)?;
        Ok(RtnTrainer {
            config: config.clone(),
            stats,
            varmap,
            model,
            opt,
            offsets,
            rng: SplitMix64::new(t.seed),
            step: 0,
            ema,
        })
    }

    /// The model being trained.
    pub fn model(&self) -> &Rtn {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The normalisation statistics.
    pub fn stats(&self) -> &FeatureStats {
        &self.stats
    }

    /// The variables (for saving).
    pub fn varmap(&self) -> &VarMap {
        &self.varmap
    }

    /// Training steps taken.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// Encodes windows, rotating each one about the vertical axis in [-pi, pi] when `rotate`
    /// (RTN sec. 3.3: on global positions before any processing; the terrain follows).
    fn encode<'a>(
        &mut self,
        windows: &[MotionWindow<'a>],
        rotate: bool,
    ) -> RtnResult<crate::transition::EncodedBatch<'a>> {
        let c = &self.config;
        let d = c.dim();
        let tf = c.target_frame();
        let mut items = Vec::with_capacity(windows.len());
        for (i, w) in windows.iter().enumerate() {
            check_frames(&format!("training window {i}"), w.positions.len(), c.window_frames(), c.joints, true)?;
            if !w.positions[..(tf + 2) * d].iter().all(|v| v.is_finite()) {
                return Err(RtnError::Config(format!("training window {i} holds NaN or inf positions")));
            }
            let mut p = w.positions[..(tf + 2) * d].to_vec();
            let rotation = if rotate {
                let angle = ((self.rng.next_f64() * 2.0 - 1.0) * std::f64::consts::PI) as f32;
                let r = features::root_of(&p[(c.past_frames - 1) * d..]);
                let rot = YawAbout { angle, center: [r[0], r[2]] };
                features::rotate_about_y(&mut p, rot.angle, rot.center);
                Some(rot)
            } else {
                None
            };
            items.push(SequenceInput {
                target: p[tf * d..(tf + 1) * d].to_vec().into(),
                next: p[(tf + 1) * d..(tf + 2) * d].to_vec().into(),
                known: {
                    p.truncate((tf + 1) * d);
                    p.into()
                },
                terrain: w.terrain,
                rotation,
            });
        }
        encode_batch(&self.stats, &items, self.model.device())
    }

    /// Generated and ground-truth frames `(batch, P + 1, D)` of a batch.
    fn predict(&mut self, windows: &[MotionWindow], rotate: bool, p_teacher: f64) -> RtnResult<(Tensor, Tensor)> {
        let batch = self.encode(windows, rotate)?;
        let (past, n_out) = (self.config.past_frames, self.config.transition_frames + 1);
        let rng = &mut self.rng;
        let mut teacher = || p_teacher > 0.0 && (p_teacher >= 1.0 || rng.next_f64() < p_teacher);
        let outs = generate(&self.model, &self.stats, &self.offsets, &batch, past, n_out, &mut teacher)?;
        let pred = Tensor::stack(&outs, 1)?;
        let truth = Tensor::stack(&batch.x[past..past + n_out], 1)?;
        Ok((pred, truth))
    }

    /// One AMSGrad step on a mini-batch; returns the loss before the step: the MSE over the
    /// P + 1 predicted frames including the target (RTN eq. 17, averaged over values).
    ///
    /// A NaN or infinite loss returns [`RtnError::NonFiniteLoss`] and leaves the parameters as
    /// they were.
    pub fn train_step(&mut self, windows: &[MotionWindow]) -> RtnResult<f32> {
        let p = self.config.train.teacher_forcing.probability(self.step);
        let rotate = self.config.train.random_rotation;
        let (pred, truth) = self.predict(windows, rotate, p)?;
        let loss = (pred - truth)?.sqr()?.mean_all()?;
        let value = loss.to_scalar::<f32>()?;
        if !value.is_finite() {
            return Err(RtnError::NonFiniteLoss { step: self.step, loss: value });
        }
        self.opt.backward_step(&loss)?;
        self.step += 1;
        self.update_ema()?;
        Ok(value)
    }

    /// Folds the current weights into the moving average. The decay warms up as
    /// `min(decay, (1 + t) / (10 + t))` so that the initial weights fade quickly.
    fn update_ema(&mut self) -> RtnResult<()> {
        let (Some(ema), Some(decay)) = (self.ema.as_mut(), self.config.train.ema_decay) else {
            return Ok(());
        };
        let t = self.step as f64;
        let d = decay.min((1.0 + t) / (10.0 + t));
        for Averaged { var, avg, .. } in ema.iter_mut() {
            // Detached: the average must not keep a graph back to every earlier step.
            *avg = (avg.affine(d, 0.0)? + var.as_tensor().detach().affine(1.0 - d, 0.0)?)?.detach();
        }
        Ok(())
    }

    /// Whether the trainer keeps a moving average of the weights.
    pub fn has_ema(&self) -> bool {
        self.ema.is_some()
    }

    /// Runs `f` with the moving-average weights in place of the trained ones, then puts the
    /// trained weights back (also when `f` fails). Without a moving average, `f` sees the trained
    /// weights.
    pub fn with_ema_weights<R>(&mut self, f: impl FnOnce(&mut Self) -> RtnResult<R>) -> RtnResult<R> {
        let Some(ema) = self.ema.as_ref() else {
            return f(self);
        };
        let mut saved = Vec::with_capacity(ema.len());
        for Averaged { var, avg, .. } in ema {
            saved.push(var.as_tensor().detach().copy()?);
            var.set(avg)?;
        }
        let out = f(self);
        if let Some(ema) = self.ema.as_ref() {
            for (a, w) in ema.iter().zip(&saved) {
                a.var.set(w)?;
            }
        }
        out
    }

    /// The moving-average tensors by variable name (for `--resume`), or `None`.
    pub fn ema_state(&self) -> Option<std::collections::HashMap<String, Tensor>> {
        let ema = self.ema.as_ref()?;
        Some(ema.iter().map(|a| (format!("ema.{}", a.name), a.avg.clone())).collect())
    }

    fn set_ema_state(&mut self, state: &std::collections::HashMap<String, Tensor>) -> RtnResult<()> {
        let Some(ema) = self.ema.as_mut() else { return Ok(()) };
        for a in ema.iter_mut() {
            let Some(saved) = state.get(&format!("ema.{}", a.name)) else {
                return Err(RtnError::Config(format!("the moving average has no tensor for {}", a.name)));
            };
            if saved.dims() != a.var.as_tensor().dims() {
                return Err(RtnError::Config(format!("the moving average of {} has the wrong shape", a.name)));
            }
            a.avg = saved.clone();
        }
        Ok(())
    }

    /// Validation loss: the same MSE without teacher forcing and without rotation.
    pub fn eval_loss(&mut self, windows: &[MotionWindow]) -> RtnResult<f32> {
        let (pred, truth) = self.predict(windows, false, 0.0)?;
        Ok((pred.detach() - truth)?.sqr()?.mean_all()?.to_scalar::<f32>()?)
    }

    /// Saves `config.json`, `model.safetensors` and `normalization.json` into `dir` (see
    /// [`crate::checkpoint::save`]).
    pub fn save(&self, dir: &std::path::Path) -> RtnResult<()> {
        crate::checkpoint::save(dir, &self.config, &self.varmap, &self.stats)
    }

    /// The optimiser (its state: [`AmsGrad::state`]).
    pub fn optimizer(&self) -> &AmsGrad {
        &self.opt
    }

    /// [`RtnTrainer::save`] plus the optimiser state (`optimizer.safetensors`, written
    /// atomically), so that [`RtnTrainer::load`] continues the run exactly.
    pub fn save_with_optimizer(&self, dir: &std::path::Path) -> RtnResult<()> {
        self.save(dir)?;
        crate::checkpoint::save_tensors(dir, crate::checkpoint::OPTIMIZER_FILE, &self.opt.state()?)?;
        if let Some(ema) = self.ema_state() {
            crate::checkpoint::save_tensors(dir, crate::checkpoint::EMA_FILE, &ema)?;
        }
        Ok(())
    }

    /// Resumes from a checkpoint folder: weights, statistics and, when the folder has one, the
    /// optimiser state (else a fresh one; returned `false`).
    pub fn load(dir: &std::path::Path, device: &Device) -> RtnResult<Self> {
        Ok(Self::load_with_optimizer(dir, device)?.0)
    }

    /// [`RtnTrainer::load`], also telling whether the optimiser state was restored.
    pub fn load_with_optimizer(dir: &std::path::Path, device: &Device) -> RtnResult<(Self, bool)> {
        let (config, stats) = crate::checkpoint::read_meta(dir)?;
        let varmap = VarMap::new();
        let mut t = Self::with_varmap(&config, stats, varmap, device)?;
        crate::checkpoint::load_weights(dir, &t.varmap)?;
        let path = dir.join(crate::checkpoint::OPTIMIZER_FILE);
        if !path.is_file() {
            return Ok((t, false));
        }
        let state = candle_core::safetensors::load(&path, device)
            .map_err(|e| RtnError::Config(format!("{}: {e}", path.display())))?;
        t.opt.set_state(&state).map_err(|e| RtnError::Config(format!("{}: {e}", path.display())))?;
        t.step = t.opt.steps();
        let ema_path = dir.join(crate::checkpoint::EMA_FILE);
        if t.ema.is_some() && ema_path.is_file() {
            let ema = candle_core::safetensors::load(&ema_path, device)
                .map_err(|e| RtnError::Config(format!("{}: {e}", ema_path.display())))?;
            t.set_ema_state(&ema).map_err(|e| RtnError::Config(format!("{}: {e}", ema_path.display())))?;
        }
        Ok((t, true))
    }
}

/// Generated frames for a batch with the given teacher-forcing decisions; exposed for tests.
#[doc(hidden)]
pub fn predict_with_teacher(
    model: &Rtn,
    stats: &FeatureStats,
    windows: &[MotionWindow],
    teacher: &mut dyn FnMut() -> bool,
) -> RtnResult<Tensor> {
    let c = model.config();
    let d = c.dim();
    let tf = c.target_frame();
    let items: Vec<SequenceInput> = windows
        .iter()
        .map(|w| SequenceInput {
            known: w.positions[..(tf + 1) * d].into(),
            target: w.positions[tf * d..(tf + 1) * d].into(),
            next: w.positions[(tf + 1) * d..(tf + 2) * d].into(),
            terrain: w.terrain,
            rotation: None,
        })
        .collect();
    let batch = encode_batch(stats, &items, model.device())?;
    let offsets = OffsetTensors::new(stats, model.device())?;
    let outs = generate(model, stats, &offsets, &batch, c.past_frames, c.transition_frames + 1, teacher)?;
    Ok(Tensor::stack(&outs, 1)?)
}
