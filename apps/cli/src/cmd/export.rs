//! `zoo export --onnx`: writes a trained model as one ONNX file for the engine runtime
//! (`zoo-runtime`): the per-frame step graph with the transition-start graph and the
//! metadata (model kind, task section, normalization, skeleton, feature layout, fps) embedded.
//!
//! `--portable` writes the portable profile instead (`zoo_export::portable`, docs/portable-export.md):
//! only operators Unity Inference Engine 2.3 documents, opset 15, recurrent ops unrolled into
//! their cell equations, and the graphs the regular file embeds in its metadata (start graph,
//! refiner) as `.onnx` files of their own beside the main file.
//!
//! The run folder's `config.json` names its model (`"model"`; folders written before the field
//! existed are RTN folders), and the table of models (`zoo_models`) exports it.

use anyhow::{Context, bail};
use clap::Args;
use std::path::PathBuf;
use zoo_export::OnnxModel;
use zoo_models::{ExportOptions, Portable};

/// Arguments of `zoo export`.
#[derive(Args)]
pub struct ExportArgs {
    /// Run folder of `zoo train rtn` (config.json, model.safetensors, normalization.json).
    #[arg(long, value_name = "MODEL_DIR")]
    pub onnx: PathBuf,
    /// Output `.onnx` file.
    #[arg(long)]
    pub out: PathBuf,
    /// A BVH clip of the training skeleton: joint names, parents, rest offsets and fps are taken
    /// from it (default: the run folder's skeleton.json, which `zoo train` writes; a folder
    /// without one needs this option).
    #[arg(long, value_name = "FILE.bvh")]
    pub skeleton: Option<PathBuf>,
    /// Frames per second of the training data (default: the run folder's skeleton.json, else
    /// the skeleton clip's).
    #[arg(long, allow_hyphen_values = true, value_parser = crate::args::fps_f32)]
    pub fps: Option<f32>,
    /// Length unit of the training data: cm, m, mm or in (default: the run folder's
    /// skeleton.json, else cm, zoo's convention for BVH, which does not say its unit).
    #[arg(long, value_parser = ["cm", "m", "mm", "in"])]
    pub units: Option<String>,
    /// Write the portable profile: only operators of Unity Inference Engine 2.3's supported
    /// list (opset 15), recurrent layers unrolled into MatMul/Gemm/Sigmoid/Tanh cells, and the
    /// start (or refiner) graph as a second file `NAME.start.onnx` (`NAME.refiner.onnx`) beside
    /// `--out` instead of base64 metadata. See docs/portable-export.md.
    #[arg(long)]
    pub portable: bool,
    /// With --portable: the fixed number of frames of a window graph (RMR), whose recurrent
    /// layers are unrolled over it (default: the model's runtime window).
    #[arg(long, requires = "portable", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub frames: Option<u32>,
    /// Also write reference vectors of the exported model to this JSON file: deterministic
    /// inputs and the runtime's outputs step by step (raw network outputs and engine poses),
    /// for checking an implementation of docs/runtime-protocol.md on another engine.
    #[arg(long, value_name = "FILE.json")]
    pub reference: Option<PathBuf>,
    /// The width the weights are stored in: f32 (default), f16 (half the bytes; the runtimes
    /// widen them when they load the file) or int8 (a quarter; per-channel scales, the
    /// fully-connected products run in 8-bit integers with activations quantized per call).
    /// The file records it (`zoo.weights`); docs/runtime.md measures each width's speed and
    /// quality cost.
    #[arg(long, default_value = "f32", value_parser = ["f32", "f16", "int8"])]
    pub weights: String,
}

/// Writes the reference vectors of `model` (`zoo_runtime::reference`) to `--reference`, if
/// given: the file as the runtime loads it.
fn write_reference(a: &ExportArgs, model: &OnnxModel) -> anyhow::Result<()> {
    use zoo_runtime::reference::{REFERENCE_SEED, reference_vectors};
    let Some(path) = &a.reference else { return Ok(()) };
    let loaded = zoo_runtime::LoadedModel::from_bytes(&model.to_bytes())
        .context("--reference: the runtime cannot load the exported model")?;
    let vectors = reference_vectors(&loaded, REFERENCE_SEED)
        .with_context(|| format!("--reference {}: computing the reference vectors", path.display()))?;
    let cases = vectors.transition.len() + vectors.keyframes.len() + vectors.stitch.len() + vectors.synthesis.len();
    zoo_motion::finite::check_serialize(&path.display().to_string(), &vectors)?;
    zoo_format::atomic::write(path, serde_json::to_string(&vectors)?)
        .with_context(|| format!("writing {}", path.display()))?;
    let check = if a.portable {
        String::new()
    } else {
        format!(
            "; check an implementation with `python3 scripts/runtime_protocol.py {} {}`",
            a.out.display(),
            path.display()
        )
    };
    println!(
        "wrote {}: reference vectors of the `{}` model, {cases} {} case(s) (seed {REFERENCE_SEED}, \
         docs/runtime-protocol.md){check}",
        path.display(),
        vectors.model_kind,
        vectors.task,
    );
    Ok(())
}

/// Lowers `model` to the portable profile and writes it to `a.out` with its companion files;
/// `frames`: the fixed size of a `frames` dimension (window graphs).
fn write_portable(a: &ExportArgs, model: &OnnxModel, what: &str, frames: Option<usize>) -> anyhow::Result<()> {
    use zoo_export::portable::{EmbeddedGraph, PortableOptions, to_portable};
    use zoo_export::unity::{UNITY_OPERATORS_URL, UNITY_PACKAGE, UNITY_VERSION};
    use zoo_runtime::portable::{PORTABLE_GRAPHS, PORTABLE_KEY};
    let mut options = PortableOptions { memory_bound: Some(zoo_data::limits::memory_bound()), ..Default::default() };
    if let Some(n) = frames {
        options.fixed_dims.insert("frames".into(), n);
    }
    let embedded: Vec<EmbeddedGraph> =
        PORTABLE_GRAPHS.iter().map(|g| EmbeddedGraph { key: g.key, file_key: g.file_key, suffix: g.suffix }).collect();
    let mut portable = to_portable(model, &options, &embedded)
        .with_context(|| format!("writing {} with the portable profile", a.out.display()))?;
    for c in &portable.companions {
        crate::cmd::check_output_file(
            "--out (its portable companion)",
            &zoo_export::PortableModel::companion_path(&a.out, &c.suffix),
        )?;
    }
    let profile = serde_json::json!({
        "operators": format!("{UNITY_PACKAGE} {UNITY_VERSION}"),
        "operators_url": UNITY_OPERATORS_URL,
        "opset": zoo_export::portable::PORTABLE_OPSET,
        "fixed_dims": options.fixed_dims,
    });
    portable.main.set_metadata(PORTABLE_KEY, &profile.to_string());
    let written = portable.write(&a.out)?;
    let nodes = |m: &OnnxModel| m.summary().op_counts.values().sum::<usize>();
    let ops = portable
        .graphs()
        .iter()
        .flat_map(|(_, m)| zoo_export::portable::op_types(m))
        .collect::<std::collections::BTreeSet<_>>();
    println!(
        "wrote {}: {what} ({} nodes), portable (Unity Inference Engine {UNITY_VERSION} operators, opset {}){}; operators: {}",
        a.out.display(),
        nodes(&portable.main),
        zoo_export::portable::PORTABLE_OPSET,
        written[1..]
            .iter()
            .zip(&portable.companions)
            .map(|(p, c)| format!(", {} graph in {} ({} nodes)", c.suffix, p.display(), nodes(&c.model)))
            .collect::<String>(),
        ops.into_iter().collect::<Vec<_>>().join(", ")
    );
    Ok(())
}

/// Runs `zoo export`.
pub fn run(a: ExportArgs) -> anyhow::Result<()> {
    crate::cmd::check_output_file("--out", &a.out)?;
    if let Some(r) = &a.reference {
        crate::cmd::check_output_file("--reference", r)?;
    }
    let model = zoo_models::of_run(&a.onnx).map_err(anyhow::Error::msg)?;
    let width = zoo_export::WeightWidth::parse(&a.weights).map_err(anyhow::Error::msg)?;
    if a.portable && width != zoo_export::WeightWidth::F32 {
        bail!(
            "--portable writes f32 weights only (Unity Inference Engine runs no integer matrix products); \
             drop --weights {width} or --portable"
        );
    }
    let frames = match (a.portable, model.portable(&a.onnx, a.frames)?) {
        (false, _) | (true, Portable::Step) => None,
        (true, Portable::Window(frames, source)) => {
            println!("fixing the window graph's `frames` dimension to {frames} ({source})");
            Some(frames)
        }
        (true, Portable::Refused(why)) => bail!("{why}"),
    };
    let options = ExportOptions { skeleton: a.skeleton.as_deref(), fps: a.fps, units: a.units.as_deref() };
    let exported = model.export(&a.onnx, &options).with_context(|| format!("exporting {}", a.onnx.display()))?;
    let m =
        zoo_export::with_weights(&exported.model, width).with_context(|| format!("storing the weights as {width}"))?;
    if a.portable {
        write_portable(&a, &m, exported.what, frames)?;
    } else {
        m.write(&a.out)?;
        let summary = m.summary();
        let (nodes, parameters) = (summary.op_counts.values().sum::<usize>(), summary.parameters);
        let (what, with, bytes) = (exported.what, exported.with, m.to_bytes().len());
        println!(
            "wrote {}: {what} ({nodes} nodes, {parameters} parameters) {with}, {width} weights ({bytes} bytes)",
            a.out.display()
        );
    }
    write_reference(&a, &m)
}
