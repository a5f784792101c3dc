//! What every training command shares (`zoo train rtn|rmr|rnn-gmm|arnn`): the run folder
//! checked before any data is loaded, the thread count, and the closing line.

use crate::checkpoint;
use crate::error::TrainError;
use crate::train_loop::{self, TrainState};
use std::path::{Path, PathBuf};
use std::time::Duration;

mod guard;
pub use guard::{
    ASIDE_DIR, LOCK_FILE, checkpoint_writing, end_of_command, epoch_done, lock, set_aside, stop_on_signal,
};

/// The options every training command takes.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    /// Run folder of a fresh run.
    pub out: PathBuf,
    /// Continue the run in this folder instead (its config is kept; `epochs` is the new total).
    pub resume: Option<PathBuf>,
    /// Replace the run already in `out` (its files are set aside, deleted after the new run's
    /// first epoch).
    pub overwrite: bool,
    /// Epochs to train (the total of a resumed run).
    pub epochs: usize,
    /// Stop after this many minutes (the epoch in progress finishes first).
    pub time_limit_minutes: Option<f64>,
    /// Seed of the data made in memory and of the trainer.
    pub seed: u64,
    /// Data-parallel training threads (`None`: the cores available).
    pub threads: Option<usize>,
    /// The options of the command that starts a fresh run, as the command line spells them
    /// (`(name, values)`, defaults included), recorded in the run folder's [`COMMAND_FILE`] so
    /// that `--resume DIR` continues with exactly them (empty: nothing to record).
    pub command: Vec<(String, Vec<String>)>,
}

impl RunSpec {
    /// The time limit as a duration (a limit too large for a `Duration` is no limit).
    pub fn time_limit(&self) -> Option<Duration> {
        self.time_limit_minutes.and_then(|m| Duration::try_from_secs_f64(m * 60.0).ok())
    }

    /// The thread count of the run: `threads`, else the cores available to the process.
    pub fn thread_count(&self) -> usize {
        default_threads(self.threads)
    }
}

/// `threads`, else the cores available to the process.
pub fn default_threads(threads: Option<usize>) -> usize {
    threads.unwrap_or_else(|| std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1))
}

/// The files and folders every run writes (what `--overwrite` deletes), before a model's own.
pub const COMMON_RUN_FILES: [&str; 9] = [
    checkpoint::CONFIG_FILE,
    checkpoint::WEIGHTS_FILE,
    checkpoint::STATS_FILE,
    checkpoint::OPTIMIZER_FILE,
    checkpoint::RNG_FILE,
    checkpoint::TRAIN_STATE_FILE,
    checkpoint::SUMMARY_FILE,
    checkpoint::LOSS_CURVE_FILE,
    checkpoint::LAST_DIR,
];

/// The options a run was started with ([`RunSpec::command`]), in its folder.
pub const COMMAND_FILE: &str = "command.json";

/// The `format` of [`COMMAND_FILE`].
const COMMAND_FORMAT: &str = "zoo.train-command";

/// Records `spec`'s command in `out` (atomically): a fresh run's options, merged over those
/// already recorded there (a later stage of the same run adds its own). Nothing when the
/// command is empty.
pub fn record_command(out: &Path, spec: &RunSpec) -> Result<(), TrainError> {
    if spec.command.is_empty() {
        return Ok(());
    }
    let mut options = read_command(out)?.unwrap_or_default();
    for (name, values) in &spec.command {
        options.insert(name.clone(), values.clone());
    }
    let v = serde_json::json!({"format": COMMAND_FORMAT, "version": 1, "options": options});
    let path = out.join(COMMAND_FILE);
    let text = serde_json::to_string_pretty(&v).map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
    zoo_format::atomic::write(&path, text.as_bytes())
        .map_err(|e| TrainError::Config(format!("cannot write {}: {e}", path.display())))
}

/// The options recorded in `dir` by [`record_command`] (`None`: a run started before they were
/// recorded, or by a library call).
pub fn read_command(dir: &Path) -> Result<Option<std::collections::BTreeMap<String, Vec<String>>>, TrainError> {
    let path = dir.join(COMMAND_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    let bad = |why: String| {
        TrainError::Config(format!(
            "{}: {why}; delete it to resume with the options given on the command line",
            path.display()
        ))
    };
    let text = std::fs::read_to_string(&path).map_err(|e| bad(e.to_string()))?;
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(format!("does not parse: {e}")))?;
    if v.get("format").and_then(|f| f.as_str()) != Some(COMMAND_FORMAT) {
        return Err(bad(format!("not a {COMMAND_FORMAT} file")));
    }
    let options = v.get("options").cloned().unwrap_or_default();
    serde_json::from_value(options).map(Some).map_err(|e| bad(format!("its `options` are not name: [values]: {e}")))
}

/// Whether `dir` holds (part of) a run: a model, a state or a `last/` checkpoint.
fn holds_run(dir: &Path) -> bool {
    [checkpoint::CONFIG_FILE, checkpoint::WEIGHTS_FILE, checkpoint::TRAIN_STATE_FILE, checkpoint::LAST_DIR]
        .iter()
        .any(|f| dir.join(f).exists())
}

/// Whether `dir` holds a run that never finished an epoch: a fresh run recorded its command
/// there ([`COMMAND_FILE`]) and may have begun its files, but no epoch's training state was
/// written (the process was killed, or the disk filled, before the first checkpoint). Such a
/// folder is trained again from the start by the command that started it (`--out DIR`) and by
/// `--resume DIR` alike: there is nothing to continue, and nothing trained to lose.
pub fn unfinished(dir: &Path) -> bool {
    if !dir.join(COMMAND_FILE).is_file() || train_loop::read_state(dir).is_ok() {
        return false;
    }
    // A model's stage folders (`zoo train rnn-gmm`'s generator/ and refiner/) hold their own state.
    let stages = std::fs::read_dir(dir).into_iter().flatten().flatten().map(|e| e.path());
    !stages.filter(|p| p.is_dir()).any(|p| train_loop::read_state(&p).is_ok())
}

/// Creates `dir` (an option's output folder) if needed and checks, before the long work, that
/// files can be written in it.
pub fn writable_dir(option: &str, dir: &Path) -> Result<(), TrainError> {
    let fail = |what: &str, e: std::io::Error| TrainError::Config(format!("{option} {}: {what}: {e}", dir.display()));
    if dir.exists() && !dir.is_dir() {
        return Err(TrainError::Config(format!("{option} {}: is a file, not a folder", dir.display())));
    }
    std::fs::create_dir_all(dir).map_err(|e| fail("cannot create the folder", e))?;
    let probe = dir.join(format!(".zoo-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"").map_err(|e| fail("cannot write in this folder", e))?;
    std::fs::remove_file(&probe).map_err(|e| fail(&format!("cannot remove {}", probe.display()), e))
}

/// The run folder, checked before any data is loaded: a fresh run never replaces a trained one
/// unless `overwrite` says so (then the files and folders `run_files` are set aside in
/// [`ASIDE_DIR`], deleted only when the new run has finished its first epoch, put back if it
/// fails before: [`set_aside`]), a resumed run must be a run folder that `check_resume`
/// accepts, and the folder must be writable. The folder is locked for this process
/// ([`lock`]): a second training into it is refused while this one runs.
pub fn prepare(
    spec: &RunSpec,
    run_files: &[&str],
    check_resume: impl FnOnce(&Path) -> Result<(), TrainError>,
) -> Result<PathBuf, TrainError> {
    if let Some(dir) = &spec.resume {
        if !dir.is_dir() {
            return Err(TrainError::Config(format!(
                "--resume {}: no such folder (start a new run with --out instead)",
                dir.display()
            )));
        }
        guard::lock(dir)?;
        train_loop::read_state(dir)?;
        check_resume(dir)?;
        writable_dir("--resume", dir)?;
        return Ok(dir.clone());
    }
    let out = &spec.out;
    if out.is_dir() {
        guard::lock(out)?;
    }
    if holds_run(out) {
        let unfinished = unfinished(out);
        if unfinished && !spec.overwrite {
            println!(
                "--out {}: the run there never finished an epoch (stopped before its first checkpoint); it is \
                 trained again from the start",
                out.display()
            );
        }
        if !spec.overwrite && !unfinished {
            let what = match train_loop::read_state(out).ok() {
                Some(s) if s.epoch > 0 => format!(
                    "a run trained for {} epochs (best validation loss {:.5} at epoch {})",
                    s.epoch,
                    s.best_valid.unwrap_or(f64::NAN),
                    s.best_epoch
                ),
                _ => "a run".to_string(),
            };
            return Err(TrainError::Config(format!(
                "--out {} already holds {what}: continue it with `--resume {0}`, replace it with --overwrite, or \
                 choose another --out",
                out.display()
            )));
        }
        guard::lock(out)?;
        guard::set_aside(out, &[run_files, &[COMMAND_FILE]].concat())?;
    }
    writable_dir("--out", out)?;
    guard::lock(out)?;
    record_command(out, spec)?;
    Ok(out.clone())
}

/// The closing line of a training stage: epochs, time, the best validation loss, the folder.
pub fn done_line(state: &TrainState, out: &Path) -> String {
    format!(
        "done: {} epochs in {:.1} min, best valid loss {:.5} at epoch {}; model in {}",
        state.epoch,
        state.seconds / 60.0,
        state.best_valid.unwrap_or(f64::NAN),
        state.best_epoch,
        out.display()
    )
}
