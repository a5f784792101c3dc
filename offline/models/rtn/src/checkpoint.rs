//! RTN checkpoint folders: `config.json`, `model.safetensors`, `normalization.json`, and for
//! training `optimizer.safetensors`, `ema.safetensors` and `rng.json` (file names and atomic
//! writes from [`zoo_nn::checkpoint`]).
//!
//! Every file is written to a temporary name in the same folder and renamed into place, so an
//! interrupted save never leaves a truncated checkpoint, and a model holding NaN/inf is never
//! saved over the last good one.

use crate::config::{Config, TeacherForcing};
use crate::error::{RtnError, RtnResult};
use crate::features::{FeatureStats, MeanStd};
use crate::model::Rtn;
use candle_core::{DType, Device};
use candle_nn::{VarBuilder, VarMap};
use std::path::Path;
use zoo_format::{MotionMeanStd, check_parents};
use zoo_nn::checkpoint as ck;

pub use zoo_nn::checkpoint::{CONFIG_FILE, EMA_FILE, OPTIMIZER_FILE, RNG_FILE, STATS_FILE, WEIGHTS_FILE, check_finite};

/// Writes a checkpoint folder atomically (created if missing): the weights (refused when one
/// holds NaN/inf), the statistics, then the configuration.
pub fn save(dir: &Path, config: &Config, varmap: &VarMap, stats: &FeatureStats) -> RtnResult<()> {
    let weights = ck::stage_varmap(&dir.join(WEIGHTS_FILE), varmap)?;
    let st = ck::stage_json(&dir.join(STATS_FILE), stats)?;
    let cfg = ck::stage_json(&dir.join(CONFIG_FILE), config)?;
    ck::commit([weights, st, cfg])?;
    Ok(())
}

/// Reads the configuration and statistics of a checkpoint folder and checks them with
/// [`check_meta`]: every loader of a run folder (inference, `zoo export`, resuming) goes
/// through here, so all of them accept and refuse the same folders as the runtime does.
pub fn read_meta(dir: &Path) -> RtnResult<(Config, FeatureStats)> {
    let (config, stats) = (ck::read_json(&dir.join(CONFIG_FILE))?, ck::read_json(&dir.join(STATS_FILE))?);
    check_meta(&config, &stats).map_err(|e| RtnError::Config(format!("{}: {e}", dir.display())))?;
    Ok((config, stats))
}

fn positive_sizes(what: &str, sizes: &[usize]) -> Result<(), String> {
    match sizes.iter().position(|&s| s == 0) {
        Some(i) => Err(format!("{CONFIG_FILE}: {what} has a layer of size 0 (layer {i}); every size must be >= 1")),
        None => Ok(()),
    }
}

/// The most parameters a configuration may describe (2 GB of f32), so that a corrupt
/// `config.json` is refused instead of aborting on an allocation.
pub const MAX_PARAMETERS: f64 = 5e8;

/// About how many parameters the configuration's layers hold (f64: a corrupt size cannot overflow).
fn parameter_estimate(c: &Config) -> f64 {
    let d = 3.0 * c.joints as f64;
    let chain = |input: f64, sizes: &[usize]| -> (f64, f64) {
        sizes.iter().fold((0.0, input), |(n, prev), &s| (n + prev * s as f64 + s as f64, s as f64))
    };
    let terrain = if c.terrain { (c.terrain_side as f64).powi(2) } else { 0.0 };
    let (fe, fe_out) = chain(d + terrain, &c.frame_encoder);
    let (te, te_out) = chain(2.0 * d, &c.target_encoder);
    let (oe, oe_out) = chain(d, &c.offset_encoder);
    let h = c.lstm as f64;
    let input = fe_out + if c.future_conditioning { te_out + oe_out } else { 0.0 };
    let (dec, dec_out) = chain(h, &c.decoder);
    let init = (d + 1.0) * c.init_hidden as f64 + (c.init_hidden as f64 + 1.0) * 2.0 * h;
    fe + te + oe + 4.0 * h * (input + h + 2.0) + dec + dec_out * d + init
}

/// Checks that a configuration and its statistics describe one usable model, with the checks
/// the runtime applies to an exported file (`zoo_format`): sizes >= 1, a valid
/// skeleton of `joints` joints, finite training settings, and statistics of the config's sizes
/// with finite means and positive, finite deviations.
pub fn check_meta(config: &Config, stats: &FeatureStats) -> Result<(), String> {
    let k = config.joints;
    if k == 0 {
        return Err(format!("{CONFIG_FILE}: joints is 0"));
    }
    if !config.parents.is_empty() {
        if config.parents.len() != k {
            return Err(format!(
                "{CONFIG_FILE}: {} parents for {k} joints (`parents` must list one parent per joint)",
                config.parents.len()
            ));
        }
        check_parents(&config.parents, |_| "in `parents`".to_string()).map_err(|e| format!("{CONFIG_FILE}: {e}"))?;
    }
    for (what, n) in [
        ("past_frames", config.past_frames),
        ("transition_frames", config.transition_frames),
        ("lstm", config.lstm),
        ("init_hidden", config.init_hidden),
    ] {
        if n == 0 {
            return Err(format!("{CONFIG_FILE}: {what} is 0; it must be >= 1"));
        }
    }
    if let Some([lo, hi]) = config.train.lengths
        && !(1 <= lo && lo <= hi && hi <= config.transition_frames)
    {
        return Err(format!(
            "{CONFIG_FILE}: train.lengths [{lo}, {hi}] must satisfy 1 <= shortest <= longest <= transition_frames ({})",
            config.transition_frames
        ));
    }
    if let Some(t) = &config.time_to_arrival {
        t.check().map_err(|e| format!("{CONFIG_FILE}: {e}"))?;
    }
    positive_sizes("frame_encoder", &config.frame_encoder)?;
    positive_sizes("target_encoder", &config.target_encoder)?;
    positive_sizes("offset_encoder", &config.offset_encoder)?;
    positive_sizes("decoder", &config.decoder)?;
    let params = parameter_estimate(config);
    if params > MAX_PARAMETERS {
        return Err(format!(
            "{CONFIG_FILE} describes a model of about {params:.3e} parameters, more than the {MAX_PARAMETERS:.0e} zoo \
             builds (check `joints` and the layer sizes)"
        ));
    }
    if !config.leaky_slope.is_finite() {
        return Err(format!("{CONFIG_FILE}: leaky_slope {} is not finite", config.leaky_slope));
    }
    if config.terrain
        && (!(1..=1024).contains(&config.terrain_side)
            || !(config.terrain_extent.is_finite() && config.terrain_extent > 0.0))
    {
        return Err(format!(
            "{CONFIG_FILE}: terrain patch of side {} (1..=1024) and extent {} (> 0) is not a patch",
            config.terrain_side, config.terrain_extent
        ));
    }
    let t = &config.train;
    if !(t.learning_rate.is_finite() && t.learning_rate > 0.0) || t.batch_size == 0 {
        return Err(format!(
            "{CONFIG_FILE}: train.learning_rate {} and train.batch_size {} must be positive",
            t.learning_rate, t.batch_size
        ));
    }
    if !((0.0..1.0).contains(&t.beta1) && (0.0..1.0).contains(&t.beta2) && t.eps.is_finite() && t.eps > 0.0) {
        return Err(format!(
            "{CONFIG_FILE}: train.beta1 {} and train.beta2 {} must be in [0, 1), train.eps {} > 0",
            t.beta1, t.beta2, t.eps
        ));
    }
    if let Some(d) = t.ema_decay
        && !(0.0..1.0).contains(&d)
    {
        return Err(format!("{CONFIG_FILE}: train.ema_decay {d} is not a decay in [0, 1)"));
    }
    if let TeacherForcing::Fixed(p) = t.teacher_forcing
        && !(0.0..=1.0).contains(&p)
    {
        return Err(format!("{CONFIG_FILE}: teacher forcing probability {p} is not in [0, 1]"));
    }
    if stats.joints != k {
        return Err(format!("{STATS_FILE} is for {} joints but {CONFIG_FILE} for {k}", stats.joints));
    }
    let d = config.dim();
    let group = |name: &str, g: &MeanStd, n: usize| {
        MotionMeanStd { mean: g.mean.clone(), std: g.std.clone() }
            .check(name, Some(n))
            .map_err(|e| format!("{STATS_FILE}: {e} (retrain, or refit the statistics)"))
    };
    group("x", &stats.x, d)?;
    group("velocity", &stats.velocity, d)?;
    group("offset", &stats.offset, d)?;
    match (&stats.terrain, config.terrain) {
        (Some(g), true) => group("terrain", g, config.terrain_dim())?,
        (None, true) => return Err(format!("{CONFIG_FILE} is terrain-aware but {STATS_FILE} has no terrain group")),
        _ => {}
    }
    Ok(())
}

/// Fills the variables of `varmap` from the folder's weights (every variable must be present).
pub fn load_weights(dir: &Path, varmap: &VarMap) -> RtnResult<()> {
    Ok(ck::read_varmap(&dir.join(WEIGHTS_FILE), varmap)?)
}

/// Loads a model for inference from a checkpoint folder: the model, its configuration is
/// [`Rtn::config`], and the normalisation statistics.
pub fn load(dir: &Path, device: &Device) -> RtnResult<(Rtn, FeatureStats)> {
    let (config, stats) = read_meta(dir)?;
    let varmap = VarMap::new();
    let model = Rtn::new(&config, VarBuilder::from_varmap(&varmap, DType::F32, device))?;
    load_weights(dir, &varmap)?;
    Ok((model, stats))
}

/// The RTN of run folder `dir` for `zoo COMMAND` (`transition`, `decompress`; the command
/// checks the folder's kind first, `zoo_models::require_task`).
pub fn load_run(dir: &Path, command: &str) -> RtnResult<(Rtn, FeatureStats)> {
    let kind = zoo_nn::checkpoint::model_kind(dir).map_err(|e| zoo_data::Message::new(e))?;
    if kind != crate::export::MODEL_KIND {
        return Err(zoo_data::Message(format!(
            "`zoo {command}`: {} holds a `{kind}` model, not an RTN",
            dir.display()
        ))
        .into());
    }
    load(dir, &Device::Cpu).map_err(|e| zoo_data::Message(format!("loading the RTN in {}: {e}", dir.display())).into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_nn::VarBuilder;

    #[test]
    fn the_parameter_estimate_is_close_and_bounds_corrupt_sizes() {
        let config = Config::paper();
        let varmap = VarMap::new();
        let model = Rtn::new(&config, VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu)).unwrap();
        let (estimate, actual) = (parameter_estimate(&config), model.parameter_count() as f64);
        assert!((estimate / actual - 1.0).abs() < 0.1, "estimate {estimate} vs {actual}");
        let stats = FeatureStats::identity(config.joints);
        assert!(check_meta(&config, &stats).is_ok());
        let huge = Config { lstm: 1 << 20, ..Config::paper() };
        let err = check_meta(&huge, &stats).unwrap_err();
        assert!(err.contains("more than the 5e8 zoo builds"), "{err}");
        let huge = Config { joints: usize::MAX / 2, ..Config::paper() };
        assert!(check_meta(&huge, &FeatureStats::identity(1)).unwrap_err().contains("parameters"));
    }
}
