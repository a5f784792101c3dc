//! The benchmarks of a trained RNN-GMM, each a function with a typed result that serialises to
//! the JSON of its command: random synthesis against held-out real motion ([`synthesis`], `zoo
//! bench synthesis`) and denoising ([`denoise`]); protocols in docs/rnn-gmm.md and
//! docs/rnn-gmm-control.md. Path following and online control, which also run the exported
//! generator through the runtime, are `zoo_bench::follow` and `zoo_bench::control` (no crate
//! under `models/` links the runtime's tract).

pub mod denoise;
pub mod synthesis;

use crate::checkpoint::LoadedGenerator;
use crate::error::RnnGmmResult;
use std::path::Path;
use zoo_data::metrics::{FootSkate, foot_joints};
use zoo_data::{Progress, bail};
use zoo_motion::Clip;

/// The foot-skate measure of a benchmark of generated motion: the model's foot joints with the
/// planted heights of the real clips of `data` (matching `glob`), or of `fallback` (the start
/// clips) without data; and, with data, what they are and their own skate.
pub fn skate_reference(
    g: &LoadedGenerator,
    data: Option<&Path>,
    glob: &str,
    fallback: &[&Clip],
    progress: &dyn Progress,
) -> RnnGmmResult<(FootSkate, Option<(String, f64)>)> {
    let feet = foot_joints(&g.spec.skeleton.names);
    if feet.is_empty() {
        bail!("the model's skeleton has no joint named like a foot or toe: the skate cannot be measured");
    }
    let Some(d) = data else { return Ok((FootSkate::fit(feet, fallback), None)) };
    let clips = zoo_data::dataset::load_reporting(d, Some(glob), false, progress)?;
    if clips.is_empty() {
        bail!("no clip of {} matches `{glob}`", d.display());
    }
    let reference: Vec<&Clip> = clips.iter().map(|c| &c.clip).collect();
    let skate = FootSkate::fit(feet, &reference);
    let real = skate.mean_over(&reference);
    Ok((skate, Some((format!("{} ({glob}: {} clips)", d.display(), clips.len()), real))))
}

/// The worker threads of a benchmark: `threads`, else the cores available to the process.
pub use zoo_nn::run_folder::default_threads as worker_threads;

/// A one-thread rayon pool for a worker (candle runs on the worker's thread alone).
fn one_thread_pool() -> RnnGmmResult<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| zoo_data::Message(format!("worker thread pool: {e}")).into())
}
