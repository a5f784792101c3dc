//! `zoo export --onnx`: writes a trained model as one ONNX file for the engine runtime
//! (`zoo-runtime`): the per-frame step graph with the transition-start graph and the
//! metadata (config, normalisation, skeleton, feature layout, fps) embedded.

use crate::cmd::transition::read_clip;
use anyhow::{Context, bail};
use clap::Args;
use std::path::PathBuf;
use zoo_export::rtn::{RtnExportOptions, export_rtn_dir};

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
    /// from it (the run folder records only the parents; without it names are `joint0`, ...
    /// and offsets zero).
    #[arg(long, value_name = "FILE.bvh")]
    pub skeleton: Option<PathBuf>,
    /// Frames per second of the training data (default: the skeleton clip's, else 30).
    #[arg(long)]
    pub fps: Option<f32>,
}

/// Runs `zoo export`.
pub fn run(a: ExportArgs) -> anyhow::Result<()> {
    let mut options = RtnExportOptions { fps: a.fps, ..RtnExportOptions::default() };
    if let Some(path) = &a.skeleton {
        let clip = read_clip(path).with_context(|| format!("reading the skeleton of {}", path.display()))?;
        let s = &clip.skeleton;
        options.names = Some(s.names.clone());
        options.offsets = Some(s.offsets.iter().map(|o| o.as_vec3().to_array()).collect());
        options.parents = Some(s.parents.iter().map(|p| p.map_or(-1, |p| p as i32)).collect());
        options.fps = options.fps.or(Some(clip.fps() as f32));
    }
    if !a.onnx.join(zoo_rtn::checkpoint::CONFIG_FILE).is_file() {
        bail!("{} is not a run folder of `zoo train rtn` (no config.json)", a.onnx.display());
    }
    let model = export_rtn_dir(&a.onnx, &options).with_context(|| format!("exporting {}", a.onnx.display()))?;
    model.write(&a.out)?;
    let summary = model.summary();
    println!(
        "wrote {}: RTN step graph ({} nodes, {} parameters) with its start graph and metadata",
        a.out.display(),
        summary.op_counts.values().sum::<usize>(),
        summary.parameters
    );
    Ok(())
}
