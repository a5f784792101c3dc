//! The in-betweening benchmark (`zoo bench`, LaFAN1 protocol, `BENCHMARK.md`) over the
//! baselines, run folders of every kind that generates transitions and exported files
//! ([`crate::registry`]): the protocol itself is [`zoo_data::benchmark`].

use crate::Result;
use crate::registry::MethodSpec;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use zoo_data::benchmark::{BenchResult, Benchmark, TransitionMethod};
use zoo_data::dataset;
use zoo_data::{Context, Message, Progress, bail};

/// The hierarchy a benchmarked model was trained on, checked against the dataset's.
pub struct TrainedOn {
    /// Parent of each joint, -1 for the root.
    pub parents: Vec<i32>,
    /// Joint names, when the model records real ones (an exported file made with `--skeleton`).
    pub names: Option<Vec<String>>,
}

/// A `--methods` entry, loaded, with the hierarchy its model was trained on (`None` for the
/// baselines and for models that record none).
pub fn method(spec: &str) -> Result<(Box<dyn TransitionMethod>, Option<TrainedOn>)> {
    let parsed = crate::registry::parse_method(spec)?;
    match &parsed {
        MethodSpec::Model { name, kind, path, foot_lock, .. } if kind == crate::registry::ONNX_KIND => {
            let (m, s) = crate::onnx::load_onnx_with_skeleton(path, name.clone(), *foot_lock)?;
            // `zoo export` without `--skeleton` names the joints `joint0`, `joint1`, ...
            let placeholder = s.names.iter().enumerate().all(|(j, n)| *n == format!("joint{j}"));
            Ok((Box::new(m), Some(TrainedOn { parents: s.parents, names: (!placeholder).then_some(s.names) })))
        }
        MethodSpec::Model { kind, path, .. } if kind == "rtn" => {
            // The run folder's hierarchy (the exported file's is the same).
            let m = crate::registry::load_method(&parsed)?;
            let (config, _) = zoo_rtn::checkpoint::read_meta(path)
                .with_context(|| format!("method `{spec}`: loading the RTN in {}", path.display()))?;
            Ok((m, (!config.parents.is_empty()).then_some(TrainedOn { parents: config.parents, names: None })))
        }
        _ => Ok((crate::registry::load_method(&parsed)?, None)),
    }
}

/// The benchmark's settings.
#[derive(Clone, Debug)]
pub struct InbetweenOptions {
    /// Transition lengths in frames.
    pub lengths: Vec<usize>,
    /// Write BVH files of `save_count` test windows into this folder: the ground truth and every
    /// method's transition, per length (`w0003_n30_interp.bvh`, ...).
    pub save_bvh: Option<PathBuf>,
    /// How many test windows `save_bvh` writes (evenly spread over the test set).
    pub save_count: usize,
}

/// Loads the `--methods` entries, with the hierarchy each model was trained on.
pub fn load_methods(specs: &[String]) -> Result<(Vec<Box<dyn TransitionMethod>>, Vec<Option<TrainedOn>>)> {
    Ok(specs.iter().map(|m| method(m.trim())).collect::<Result<Vec<_>>>()?.into_iter().unzip())
}

/// The name of a method in a saved file's name: `rtn:runs/rtn-bandai2` -> `rtn-rtn-bandai2`.
fn file_tag(method: &str) -> String {
    match method.split_once(':') {
        Some((kind, path)) => {
            let last = Path::new(path).file_name().map(|f| f.to_string_lossy().into_owned());
            format!("{kind}-{}", last.unwrap_or_default())
        }
        None => method.to_string(),
    }
}

/// Runs the benchmark on the training and test clips with `methods` (the training split gives
/// the statistics, bone offsets and planted foot heights).
pub fn run(
    train: &[dataset::NamedClip],
    test: &[dataset::NamedClip],
    methods: &[Box<dyn TransitionMethod>],
    o: &InbetweenOptions,
    p: &dyn Progress,
) -> Result<BenchResult> {
    p.stage("preparing windows and statistics");
    let bench = Benchmark::new(train, test).map_err(Message)?;
    p.stage(&format!("evaluating {} test windows", bench.windows()));
    let refs: Vec<&dyn TransitionMethod> = methods.iter().map(|m| m.as_ref()).collect();
    let picks: Vec<usize> = match &o.save_bvh {
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            let k = o.save_count.min(bench.windows()).max(1);
            (0..k).map(|i| i * bench.windows() / k).collect()
        }
        None => Vec::new(),
    };
    let mut write_err: Option<Message> = None;
    let mut save = |method: &str, n: usize, transitions: &[zoo_data::benchmark::Transition]| {
        let Some(dir) = &o.save_bvh else { return };
        for &w in &picks {
            for (name, t) in [("gt".to_string(), None), (file_tag(method), Some(&transitions[w]))] {
                let path = dir.join(format!("w{w:04}_n{n}_{name}.bvh"));
                if let Err(e) = zoo_data::bvh::write_file(&bench.window_clip(w, n, t), &path) {
                    write_err.get_or_insert(Message(format!("writing {}: {e}", path.display())));
                }
            }
        }
    };
    let result = bench.run_with(&refs, &o.lengths, &mut save).map_err(Message)?;
    if let Some(e) = write_err {
        return Err(e.into());
    }
    p.finish();
    Ok(result)
}

/// The comparison of a result with reference values.
#[derive(Clone, Debug)]
pub struct ReferenceCheck {
    /// One line per value: ours, the reference's and the relative error.
    pub lines: Vec<String>,
    /// The values that differ by more than the tolerance, or cannot be compared.
    pub failures: Vec<String>,
    /// Values compared.
    pub count: usize,
    /// The largest relative error.
    pub worst: f64,
}

/// Refuses a model (an RTN run folder or an exported file) trained on another hierarchy than
/// the dataset's: the same joint count is not enough, the joints would be paired with the wrong
/// bones.
pub fn check_skeletons(specs: &[String], trained_on: &[Option<TrainedOn>], train: &[dataset::NamedClip]) -> Result<()> {
    let Some(first) = train.first() else { return Ok(()) };
    let parents = first.clip.skeleton.parents_i32();
    let names = &first.clip.skeleton.names;
    for (spec, trained) in specs.iter().zip(trained_on) {
        let Some(t) = trained else { continue };
        if t.parents != parents {
            bail!(
                "method `{spec}`: the model was trained on another skeleton ({} joints, parents {:?}) than the \
                 dataset's ({} joints, parents {:?}, from {})",
                t.parents.len(),
                t.parents,
                parents.len(),
                parents,
                first.path.display()
            );
        }
        if let Some(model_names) = &t.names
            && let Some(j) = (0..names.len()).find(|&j| model_names[j] != names[j])
        {
            bail!(
                "method `{spec}`: the model was trained on another skeleton: its joint {j} is `{}`, the dataset's \
                 is `{}` (from {})",
                model_names[j],
                names[j],
                first.path.display()
            );
        }
    }
    Ok(())
}

/// Maps a LaFAN1 benchmark key (`zerov_quat_loss@30`) to ours (`zerovel`, `l2q@30`).
pub fn map_reference_key(key: &str) -> Option<(String, String)> {
    let (name, n) = key.split_once('@')?;
    let (method, metric) = name.split_once('_')?;
    let method = match method {
        "zerov" => "zerovel",
        "interp" => "interp",
        other => other,
    };
    let metric = match metric {
        "quat_loss" => "l2q",
        "pos_loss" => "l2p",
        "npss_loss" => "npss",
        other => other,
    };
    Some((method.to_string(), format!("{metric}@{n}")))
}

/// Compares `result` with the reference values of the JSON file `path` (LaFAN1 benchmark key
/// names, e.g. `interp_pos_loss@30`) within the relative tolerance `tol`.
pub fn check_reference(result: &BenchResult, path: &Path, tol: f64) -> Result<ReferenceCheck> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let reference: BTreeMap<String, f64> = serde_json::from_str(&text)
        .with_context(|| format!("{}: expected a JSON object of numbers", path.display()))?;
    let mut lines = Vec::new();
    let mut worst: f64 = 0.0;
    let mut failures = Vec::new();
    for (key, want) in &reference {
        let Some((m, k)) = map_reference_key(key) else {
            failures.push(format!("{key}: not a `method_metric@n` key"));
            continue;
        };
        let Some(got) = result.methods.get(&m).and_then(|row| row.get(&k)) else {
            failures.push(format!("{key}: not computed (run with the method and length it names)"));
            continue;
        };
        let rel = (got - want).abs() / want.abs().max(1e-300);
        worst = worst.max(rel);
        lines.push(format!("{key:<24} reference {want:<22.15} ours {got:<22.15} rel {rel:.2e}"));
        if !(rel <= tol) {
            failures.push(format!("{key}: ours {got} vs reference {want} (relative error {rel:.2e} > {tol:e})"));
        }
    }
    Ok(ReferenceCheck { lines, failures, count: reference.len(), worst })
}

impl ReferenceCheck {
    /// The verdict: the summary line, or the failures as an error.
    pub fn verdict(&self, tol: f64) -> Result<String> {
        if !self.failures.is_empty() {
            bail!("reference check failed:\n  {}", self.failures.join("\n  "));
        }
        Ok(format!(
            "reference check: {} values match within {tol:e} (worst relative error {:.2e})",
            self.count, self.worst
        ))
    }
}
