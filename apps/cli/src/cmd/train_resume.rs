//! `zoo train ... --resume DIR` continues a run with the options it was started with: a fresh
//! run records the options its command line gave (as it spelled them) in the run folder
//! (`zoo_nn::run_folder::COMMAND_FILE`), the others being their defaults; a resume takes them
//! from there, so `zoo train rtn --resume runs/rtn --epochs 80` needs no data options repeated,
//! and refuses an option given on its command line with another value than the run's (the
//! recorded one, else the default): it could not be honoured (the run's configuration, data and
//! statistics are kept), and the message names both values.
//! The run's length and threads (`--epochs`, `--time-limit`, `--threads`, and RNN-GMM's stage
//! options) are the resumed command's own.

use clap::parser::ValueSource;
use clap::{ArgAction, ArgMatches};
use std::collections::BTreeMap;
use std::ffi::OsString;
use std::path::PathBuf;
use zoo_nn::run_folder::COMMAND_FILE;

/// Options a resumed command sets itself (never taken from the record, never compared).
const OWN_OPTIONS: [&str; 9] =
    ["resume", "out", "overwrite", "epochs", "time-limit", "threads", "stage", "refiner-epochs", "refiner-time-limit"];

/// What `zoo train MODEL ...` runs with.
pub enum Resolved {
    /// A fresh run: its options, to record in the run folder.
    Fresh(Vec<(String, Vec<String>)>),
    /// A resume of a run that recorded its options: the command line to run instead
    /// (`zoo train MODEL` and the options).
    Resume(Vec<OsString>),
    /// A resume of a run that never finished an epoch (`zoo_nn::run_folder::unfinished`): the
    /// command line that trains it again from the start with its recorded options (`--out DIR`
    /// instead of `--resume DIR`), and the options to record.
    Restart(Vec<OsString>, Vec<(String, Vec<String>)>),
    /// A resume of a run that recorded nothing (started by an older zoo): as given.
    AsGiven,
}

/// One option of the subcommand: its long name, values, whether the command line gave it, and
/// its default.
struct Given {
    name: String,
    values: Vec<String>,
    from_command_line: bool,
    default: Vec<String>,
}

fn options(sub: &ArgMatches, def: &clap::Command) -> Vec<Given> {
    let mut out = Vec::new();
    for arg in def.get_arguments() {
        let (Some(long), id) = (arg.get_long(), arg.get_id().as_str()) else { continue };
        if matches!(arg.get_action(), ArgAction::Help | ArgAction::Version) || !sub.contains_id(id) {
            continue;
        }
        let Ok(Some(raw)) = sub.try_get_raw(id) else { continue };
        let values: Vec<String> = raw.map(|v| v.to_string_lossy().into_owned()).collect();
        let default = arg.get_default_values().iter().map(|v| v.to_string_lossy().into_owned()).collect();
        out.push(Given {
            name: long.to_string(),
            values,
            from_command_line: sub.value_source(id) == Some(ValueSource::CommandLine),
            default,
        });
    }
    out
}

/// The same values: equal text, or equal numbers (`0.001` and `1e-3`).
fn same(a: &[String], b: &[String]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x == y || matches!((x.parse::<f64>(), y.parse::<f64>()), (Ok(p), Ok(q)) if p == q))
}

/// Resolves `zoo train MODEL ...` (`train`: the `train` subcommand's matches, `def`: its
/// definition).
pub fn resolve(train: &ArgMatches, def: &clap::Command) -> anyhow::Result<Resolved> {
    let Some((model, sub)) = train.subcommand() else { return Ok(Resolved::AsGiven) };
    let Some(model_def) = def.find_subcommand(model) else { return Ok(Resolved::AsGiven) };
    let given = options(sub, model_def);
    let Some(dir) = sub.try_get_one::<PathBuf>("resume").ok().flatten() else {
        let own = |n: &str| matches!(n, "resume" | "out" | "overwrite");
        let recorded = given.into_iter().filter(|g| g.from_command_line && !own(&g.name));
        return Ok(Resolved::Fresh(recorded.map(|g| (g.name, g.values)).collect()));
    };
    // An old run that an interrupted `--overwrite` kept aside is put back (under the folder's
    // lock) before the run's recorded options are read: they are the old run's.
    if dir.join(zoo_nn::run_folder::ASIDE_DIR).is_dir() {
        let _ = zoo_nn::run_folder::lock(dir);
    }
    let Some(recorded) = zoo_nn::run_folder::read_command(dir)? else { return Ok(Resolved::AsGiven) };
    let restart = zoo_nn::run_folder::unfinished(dir);
    let mut merged: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (name, values) in &recorded {
        if !OWN_OPTIONS.contains(&name.as_str()) {
            merged.insert(name.clone(), values.clone());
        }
    }
    for g in given {
        let own = OWN_OPTIONS.contains(&g.name.as_str());
        if own && g.name != "out" && g.name != "overwrite" && (g.from_command_line || g.name == "resume") {
            merged.insert(g.name, g.values);
            continue;
        }
        if own || !g.from_command_line {
            continue;
        }
        let was = match recorded.get(&g.name) {
            Some(was) => format!("--{} {}", g.name, was.join(",")),
            None if g.default.is_empty() => format!("no --{}", g.name),
            None => format!("--{} {} (the default)", g.name, g.default.join(",")),
        };
        if !same(recorded.get(&g.name).unwrap_or(&g.default), &g.values) {
            anyhow::bail!(
                "--{0} {1}: the run in {2} was started with {was}, and a resumed run keeps the options it was started \
                 with (recorded in {2}/{COMMAND_FILE}); drop --{0}, or start a new run with --out (or --overwrite to \
                 replace this one)",
                g.name,
                g.values.join(","),
                dir.display(),
            );
        }
        merged.insert(g.name, g.values);
    }
    let flags: Vec<String> = model_def
        .get_arguments()
        .filter(|a| matches!(a.get_action(), ArgAction::SetTrue))
        .filter_map(|a| a.get_long().map(str::to_string))
        .collect();
    if restart {
        // Trained again from the start: the run's own length too, unless this command gives it.
        for (name, values) in &recorded {
            if OWN_OPTIONS.contains(&name.as_str()) && !matches!(name.as_str(), "resume" | "out" | "overwrite") {
                merged.entry(name.clone()).or_insert_with(|| values.clone());
            }
        }
        if let Some(v) = merged.remove("resume") {
            merged.insert("out".into(), v);
        }
        // What the folder holds never finished an epoch: kept aside until the new start has.
        merged.insert("overwrite".into(), vec!["true".into()]);
        eprintln!(
            "--resume {}: the run never finished an epoch (stopped before its first checkpoint), so there is nothing to \
             continue; it is trained from the start with the options it was started with ({COMMAND_FILE})",
            dir.display()
        );
    }
    let mut argv: Vec<OsString> = vec!["zoo".into(), "train".into(), model.into()];
    for (name, values) in merged {
        if flags.contains(&name) {
            if values.iter().any(|v| v == "true") {
                argv.push(format!("--{name}").into());
            }
        } else if !values.is_empty() {
            argv.push(format!("--{name}={}", values.join(",")).into());
        }
    }
    if restart {
        return Ok(Resolved::Restart(argv, recorded.into_iter().collect()));
    }
    Ok(Resolved::Resume(argv))
}
