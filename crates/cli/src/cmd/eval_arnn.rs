//! `zoo eval-arnn`: the completion test of a `zoo train arnn` run folder on its held-out lamp
//! sequences (the split recorded in `train_state.json`), against linear and spline
//! interpolation of the same keys: one row of the paper's Tables 1-2 per run.

use crate::cmd::train_arnn::{self, ArnnVariant, DataSettings};
use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use zoo_arnn::eval::{CompletionError, CompletionReport};
use zoo_nn::checkpoint::LAST_DIR;
use zoo_nn::train_loop;

/// Which weights of a run folder to evaluate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Checkpoint {
    /// The run folder's checkpoint: the best validation loss (frame + key).
    Best,
    /// The last epoch's weights (`last/`).
    Last,
}

/// Arguments of `zoo eval-arnn`.
#[derive(Args)]
pub struct EvalArnnArgs {
    /// Run folder of `zoo train arnn`.
    #[arg(long)]
    pub model: PathBuf,
    /// Which weights to evaluate.
    #[arg(long, value_enum, default_value_t = Checkpoint::Best)]
    pub checkpoint: Checkpoint,
    /// The `zoo data luxo` folder the run trained on, when it has moved since (its split is
    /// rebuilt from the run's seed and test fraction).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

fn line(name: &str, e: &CompletionError) {
    let miss = &e.max_key_miss;
    println!(
        "  {name:<14} key {:.5}  frame {:.5}  total {:.5}  RMSE base x {:.1} cm, y {:.1} cm, angles \
         {:.1}/{:.1}/{:.1}/{:.1} deg; largest key miss x {:.1} cm, y {:.1} cm, angle {:.1} deg; lowest base point {}",
        e.key,
        e.frame,
        e.key + e.frame,
        e.rmse[0] * 100.0,
        e.rmse[1] * 100.0,
        e.rmse[2].to_degrees(),
        e.rmse[3].to_degrees(),
        e.rmse[4].to_degrees(),
        e.rmse[5].to_degrees(),
        miss[0] * 100.0,
        miss[1] * 100.0,
        miss[2..].iter().fold(0.0f64, |a, b| a.max(*b)).to_degrees(),
        e.lowest_base.map_or("-".into(), |l| format!("{:.2} cm", l * 100.0)),
    );
}

/// Prints a completion report (frame / key error: normalised MSE; total = key + frame as in
/// the paper's Tables 1-2) and returns it as JSON.
pub fn print_report(r: &CompletionReport) -> serde_json::Value {
    println!(
        "test set, {} sequences completed from all their keys (normalised MSE per degree of freedom, every frame \
         after the first; key: the key frames after the first):",
        r.sequences
    );
    line("network", &r.arnn);
    if let Some(g) = &r.arnn_grounded {
        line("network+ground", g);
    }
    line("linear", &r.linear);
    line("cubic spline", &r.spline);
    println!(
        "  network frame error / spline frame error = {:.3} (linear: {:.3})",
        r.arnn.frame / r.spline.frame.max(1e-30),
        r.arnn.frame / r.linear.frame.max(1e-30)
    );
    serde_json::to_value(r).unwrap_or_default()
}

/// Runs `zoo eval-arnn`.
pub fn run(a: EvalArnnArgs) -> anyhow::Result<()> {
    let kind = zoo_nn::checkpoint::model_kind(&a.model)?;
    if kind != "arnn" {
        bail!("--model {}: the folder holds a `{kind}` run, not an ARNN (`zoo train arnn`)", a.model.display());
    }
    if let Some(j) = &a.json {
        crate::cmd::check_output_file("--json", j)?;
    }
    let state = train_loop::read_state(&a.model)?;
    let stored = state.extra.get("data_settings").cloned().with_context(|| {
        format!("{}: train_state.json has no data_settings (not written by `zoo train arnn`)", a.model.display())
    })?;
    let mut settings: DataSettings = serde_json::from_value(stored)?;
    if let Some(d) = &a.data {
        if settings.dir.is_none() {
            bail!("--data {}: the run trained on sequences generated in memory, not on a folder", d.display());
        }
        settings.dir = Some(d.clone());
    }
    let variant: Option<ArnnVariant> = state.extra.get("variant").and_then(|v| serde_json::from_value(v.clone()).ok());
    let (weights, epoch) = match a.checkpoint {
        Checkpoint::Best => (a.model.clone(), state.best_epoch),
        Checkpoint::Last => (a.model.join(LAST_DIR), state.epoch),
    };
    let device = candle_core::Device::Cpu;
    let (model, norm) = zoo_arnn::checkpoint::load(&weights, &device)
        .with_context(|| format!("loading the ARNN in {}", weights.display()))?;
    let data = train_arnn::lamp_data(&settings).with_context(|| {
        format!("rebuilding the test set of {} (give the data folder with --data if it moved)", a.model.display())
    })?;
    if let Some(names) = state.extra.get("test_sequences").and_then(|v| v.as_array()) {
        let now: Vec<&str> = data.test.iter().map(|s| s.name.as_str()).collect();
        let then: Vec<&str> = names.iter().filter_map(|v| v.as_str()).collect();
        if now != then {
            bail!(
                "the test set rebuilt from {} is not the run's ({} sequences recorded, {} found, first {:?} vs {:?}): \
                 the data folder changed",
                data.source,
                then.len(),
                now.len(),
                then.first(),
                now.first()
            );
        }
    }
    let config = model.config();
    let architecture = match config.architecture {
        zoo_arnn::Architecture::NoMemory => {
            format!("{:?} architecture ({:?} output)", config.architecture, config.no_memory_output)
        }
        other => format!("{other:?} architecture"),
    };
    println!(
        "{}: {} ({architecture}, {} parameters, ground weight {}), {:?} checkpoint (epoch {epoch} of {}), data {}",
        a.model.display(),
        variant.map_or("arnn".into(), |v| format!("{v:?}")),
        config.parameter_count(),
        config.ground_weight,
        a.checkpoint,
        state.epoch,
        data.source
    );
    let r = zoo_arnn::eval::evaluate(&model, &norm, &data.test)?;
    let mut v = print_report(&r);
    if let Some(j) = &a.json {
        if let Some(m) = v.as_object_mut() {
            m.insert("run".into(), serde_json::json!(a.model));
            m.insert("checkpoint".into(), format!("{:?}", a.checkpoint).to_lowercase().into());
            m.insert("epoch".into(), epoch.into());
            m.insert("variant".into(), serde_json::to_value(variant)?);
            m.insert("parameters".into(), config.parameter_count().into());
        }
        std::fs::write(j, serde_json::to_string_pretty(&v)?).with_context(|| format!("writing {}", j.display()))?;
    }
    Ok(())
}
