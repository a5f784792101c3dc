//! One module per subcommand.

pub mod bench;
pub mod bench_control;
pub mod bench_denoise;
pub mod bench_follow;
pub mod bench_speed;
pub mod bench_stitch;
pub mod bench_synthesis;
pub mod complete;
pub mod control;
pub mod data;
pub mod data_luxo;
pub mod decompress;
pub mod denoise;
pub mod eval_arnn;
pub mod export;
pub mod follow;
pub mod generate;
pub mod io_check;
pub mod render;
pub mod stitch;
pub mod train;
pub mod train_resume;
pub mod transition;

use anyhow::{Context, bail};
use std::path::Path;

/// Checks, before the long work, that `path` (an option's output file) can be written: its
/// folder exists and is writable, and `path` is not a folder. Leaves no file behind.
pub fn check_output_file(option: &str, path: &Path) -> anyhow::Result<()> {
    if path.is_dir() {
        bail!("{option} {}: is a folder; give a file name", path.display());
    }
    zoo_format::atomic::check_destination(path).map_err(|e| anyhow::anyhow!("{option} {e}"))?;
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !parent.is_dir() {
        bail!("{option} {}: the folder {} does not exist (create it first)", path.display(), parent.display());
    }
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path)
        .with_context(|| format!("{option} {}: cannot write there", path.display()))?;
    if !existed {
        std::fs::remove_file(path)
            .with_context(|| format!("{option} {}: cannot remove the test file", path.display()))?;
    }
    Ok(())
}

/// Creates `dir` (an option's output folder) if needed and checks, before the long work, that
/// files can be written in it.
pub fn check_output_dir(option: &str, dir: &Path) -> anyhow::Result<()> {
    Ok(zoo_nn::run_folder::writable_dir(option, dir)?)
}

/// Loads a dataset for a command ([`zoo_data::dataset::load_reporting`], its notices on
/// standard error).
pub fn load_dataset(
    path: &Path,
    name_glob: Option<&str>,
    skip_invalid: bool,
) -> anyhow::Result<Vec<zoo_data::dataset::NamedClip>> {
    Ok(zoo_data::dataset::load_reporting(path, name_glob, skip_invalid, &Stderr)?)
}

/// Notices on standard error, no progress shown.
pub use zoo_nn::progress::Stderr;

/// Leaves out the clips whose file name matches `exclude` (`--exclude-glob`: e.g. a content
/// type held out of training for the out-of-distribution protocol, docs/ood.md); says how many.
pub fn exclude_clips(
    clips: Vec<zoo_data::dataset::NamedClip>,
    exclude: Option<&str>,
) -> anyhow::Result<Vec<zoo_data::dataset::NamedClip>> {
    let Some(pattern) = exclude else { return Ok(clips) };
    let m = zoo_data::dataset::glob(pattern)?;
    let before = clips.len();
    let kept: Vec<_> = clips.into_iter().filter(|c| !m.is_match(&c.name)).collect();
    if kept.is_empty() {
        bail!("--exclude-glob {pattern}: every one of the {before} clips matches; nothing is left");
    }
    eprintln!("--exclude-glob {pattern}: left out {} of {before} clips", before - kept.len());
    Ok(kept)
}

/// How a benchmark's test clips are chosen: by a glob on `--data`, or from another dataset.
pub struct Split<'a> {
    /// `--valid-glob`: the test split of `--data`.
    pub valid_glob: Option<&'a str>,
    /// `--test-data`: a held-out dataset tested instead.
    pub test_data: Option<&'a Path>,
    /// `--exclude-glob`: clips left out of `--data` before the split.
    pub exclude_glob: Option<&'a str>,
}

/// The training and test clips of a benchmark: `data` split by `--valid-glob`, or `data` (its
/// training split when a glob is given) and every clip of `--test-data`.
pub fn load_split(
    data: &Path,
    split: &Split,
    skip_invalid: bool,
    progress: &dyn zoo_data::Progress,
) -> anyhow::Result<(Vec<zoo_data::dataset::NamedClip>, Vec<zoo_data::dataset::NamedClip>)> {
    use zoo_data::dataset;
    progress.stage(&format!("loading {}", data.display()));
    let clips = load_dataset(data, None, skip_invalid)?;
    let clips = exclude_clips(clips, split.exclude_glob)?;
    Ok(match (split.test_data, split.valid_glob) {
        (Some(test_path), glob) => {
            let train = match glob {
                Some(g) => dataset::split(clips, g)?.0,
                None => clips,
            };
            progress.stage(&format!("loading {}", test_path.display()));
            (train, load_dataset(test_path, None, skip_invalid)?)
        }
        (None, Some(g)) => dataset::split(clips, g)?,
        (None, None) => bail!("pass --valid-glob GLOB to choose the test split of --data, or --test-data PATH"),
    })
}

/// Writes `value` as pretty JSON to `path` (atomically), after checking that its numbers are
/// finite ([`zoo_motion::finite::check_serialize`]).
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> anyhow::Result<()> {
    zoo_motion::finite::check_serialize(&path.display().to_string(), value)?;
    let text = serde_json::to_string_pretty(value)?;
    zoo_format::atomic::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// A command-line error as a library message (for callbacks the libraries call).
pub fn message(e: anyhow::Error) -> zoo_data::Message {
    zoo_data::Message(format!("{e:#}"))
}

/// Writes a `--positions` file ([`zoo_data::positions`]).
pub fn write_positions(path: &Path, value: &serde_json::Value) -> anyhow::Result<()> {
    zoo_data::positions::write(path, value).with_context(|| format!("writing {}", path.display()))
}

/// Writes a benchmark's report as JSON to `path`, when given, and says so.
pub fn write_report(path: Option<&Path>, report: &impl serde::Serialize) -> anyhow::Result<()> {
    if let Some(p) = path {
        write_json(p, report)?;
        println!("wrote {}", p.display());
    }
    Ok(())
}

/// Says which files a command wrote: the clip and its contact labels, and a plot.
pub fn say_written(out: &Path, contacts: &Path, plot: Option<&Path>) {
    println!("wrote {} and {}", out.display(), contacts.display());
    if let Some(p) = plot {
        println!("wrote {}", p.display());
    }
}
