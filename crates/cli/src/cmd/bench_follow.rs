//! `zoo bench follow`: the path-following benchmark (RNN-GMM control, issue 15): the five test
//! paths (straight 10 m, circle of radius 2 m, S-curve, a hand-drawn polyline with a 120-degree
//! corner, a 20 m spiral) from each start clip (walking, running), with the root's distance to
//! the path, foot skate beside the real clips' own, and the time per generated second.

use crate::cmd::follow::{OptimiserArgs, follow_with_progress, plot, root_track};
use crate::cmd::generate::{load_model, start_clip};
use anyhow::{Context, bail};
use clap::Args;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::metrics::{FootSkate, foot_joints};
use zoo_motion::Clip;
use zoo_rnngmm::path::{GroundPath, TEST_PATHS};

/// Arguments of `zoo bench follow`.
#[derive(Args)]
pub struct BenchFollowArgs {
    /// Run folder of `zoo train rnn-gmm`.
    #[arg(long)]
    pub model: PathBuf,
    /// Start clips and frames, `CLIP.bvh:FRAME`, one per gait (repeat the option) [default: the
    /// run folder's start.bvh, frame 29].
    #[arg(long)]
    pub from: Vec<String>,
    /// Test paths, comma-separated, of straight, circle, s-curve, corner, spiral.
    #[arg(long, value_delimiter = ',', default_values_t = TEST_PATHS.map(String::from))]
    pub paths: Vec<String>,
    /// Real clips whose foot skate is the reference (a folder or file of BVH); with --glob.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Clip-name pattern within --data.
    #[arg(long, default_value = "*")]
    pub glob: String,
    /// Folder that receives a top-view PNG and the BVH of every run, and all the top views in one
    /// sheet (`all.png`: a row per start, a column per path).
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// The optimiser's settings.
    #[command(flatten)]
    pub optimiser: OptimiserArgs,
    /// Write the results as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One path from one start.
#[derive(Serialize)]
struct Row {
    start: String,
    path: String,
    path_length_cm: f64,
    frames: usize,
    reached_end: bool,
    mean_distance: f64,
    max_distance: f64,
    foot_skate: f64,
    seconds: f64,
    seconds_per_generated_second: f64,
}

#[derive(Serialize)]
struct Report {
    model: String,
    options: String,
    real_foot_skate: Option<f64>,
    real: Option<String>,
    rows: Vec<Row>,
}

/// Runs the benchmark.
pub fn run(a: BenchFollowArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.json {
        crate::cmd::check_output_file("--json", p)?;
    }
    if let Some(d) = &a.plots {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    let paths: Vec<(String, GroundPath)> = a
        .paths
        .iter()
        .map(|n| Ok((n.clone(), GroundPath::test_path(n).with_context(|| format!("--paths {n}"))?)))
        .collect::<anyhow::Result<_>>()?;
    let (g, _) = load_model(&a.model, true)?;
    let froms: Vec<Option<&str>> =
        if a.from.is_empty() { vec![None] } else { a.from.iter().map(|s| Some(s.as_str())).collect() };
    let starts = froms.iter().map(|f| start_clip(&a.model, *f, &g)).collect::<anyhow::Result<Vec<_>>>()?;
    let starts_clips: Vec<&Clip> = starts.iter().map(|s| &s.0).collect();
    let (skate, real) = skate_reference(&g, a.data.as_deref(), &a.glob, &starts_clips)?;
    let real_skate = real.as_ref().map(|r| r.1);
    let opts = a.optimiser.options();
    let mut rows = Vec::new();
    let mut tracks: Vec<Vec<Vec<[f64; 2]>>> = Vec::new();
    for (clip, frame, label) in &starts {
        tracks.push(Vec::new());
        for (name, path) in &paths {
            let t = Instant::now();
            let f = follow_with_progress(&g, clip, *frame, path, &opts, &format!("{name} from {label}"))
                .with_context(|| format!("following {name} from {label}"))?;
            let seconds = t.elapsed().as_secs_f64();
            let n = f.distance.len().max(1) as f64;
            let frames = f.motion.clip.frames();
            let motion_s = frames as f64 / g.spec.fps;
            let row = Row {
                start: label.clone(),
                path: name.clone(),
                path_length_cm: path.length(),
                frames,
                reached_end: f.reached_end,
                mean_distance: f.distance.iter().sum::<f64>() / n,
                max_distance: f.distance.iter().copied().fold(0.0, f64::max),
                foot_skate: skate.mean_over(&[&f.motion.clip]),
                seconds,
                seconds_per_generated_second: seconds / motion_s.max(1e-9),
            };
            println!(
                "{name:>8} from {label}: {frames} frames, root to path mean {:.2} max {:.2}, skate {:.3}, {:.1} s per \
                 generated second{}",
                row.mean_distance,
                row.max_distance,
                row.foot_skate,
                row.seconds_per_generated_second,
                if f.reached_end { "" } else { " (did not reach the end)" }
            );
            let track = root_track(&f);
            if let Some(dir) = &a.plots {
                let k = rows.len() / paths.len();
                let stem = format!("{name}-start{k}");
                plot(&dir.join(format!("{stem}.png")), path, &track)?;
                let mut out = f.motion.clip.clone();
                out.skeleton = clip.skeleton.clone();
                zoo_data::bvh::write_file(&out, &dir.join(format!("{stem}.bvh")))
                    .with_context(|| format!("writing {stem}.bvh"))?;
            }
            rows.push(row);
            tracks.last_mut().expect("one list per start").push(track);
        }
    }
    if let Some(dir) = &a.plots {
        // Every run in one sheet: a row per start, a column per path.
        let cells: Vec<Vec<Vec<zoo_nn::plot::TopSeries>>> = tracks
            .iter()
            .map(|row| {
                row.iter()
                    .zip(&paths)
                    .map(|(t, (_, p))| vec![(p.points(), (150, 150, 150), 4.0), (t.as_slice(), (200, 30, 30), 1.2)])
                    .collect()
            })
            .collect();
        let sheet = dir.join("all.png");
        zoo_nn::plot::top_view_grid(&sheet, &cells, 100.0, 240)
            .with_context(|| format!("writing {}", sheet.display()))?;
    }
    println!();
    println!(
        "| start | path | frames | reached end | root to path, mean (cm) | max (cm) | foot skate (cm/frame) | s per generated \
         second |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for r in &rows {
        println!(
            "| {} | {} | {} | {} | {:.2} | {:.2} | {:.3} | {:.1} |",
            r.start,
            r.path,
            r.frames,
            if r.reached_end { "yes" } else { "no" },
            r.mean_distance,
            r.max_distance,
            r.foot_skate,
            r.seconds_per_generated_second
        );
    }
    if let Some((what, s)) = &real {
        println!("real foot skate: {s:.3} cm/frame ({what})");
    }
    if let Some(p) = &a.json {
        let report = Report {
            model: a.model.display().to_string(),
            options: format!("{opts:?}"),
            real_foot_skate: real_skate,
            real: real.as_ref().map(|(w, _)| w.clone()),
            rows,
        };
        let tmp = p.with_extension("json.tmp");
        std::fs::write(&tmp, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", tmp.display()))?;
        std::fs::rename(&tmp, p).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

/// The foot-skate measure of a benchmark of generated motion: the model's foot joints with the
/// planted heights of the real clips of `data` (matching `glob`), or of `fallback` (the start
/// clips) without data; and, with data, what they are and their own skate.
pub fn skate_reference(
    g: &zoo_rnngmm::checkpoint::LoadedGenerator,
    data: Option<&std::path::Path>,
    glob: &str,
    fallback: &[&Clip],
) -> anyhow::Result<(FootSkate, Option<(String, f64)>)> {
    let feet = foot_joints(&g.spec.skeleton.names);
    if feet.is_empty() {
        bail!("the model's skeleton has no joint named like a foot or toe: the skate cannot be measured");
    }
    let Some(d) = data else { return Ok((FootSkate::fit(feet, fallback), None)) };
    let clips = crate::cmd::load_dataset(d, Some(glob), false)?;
    if clips.is_empty() {
        bail!("no clip of {} matches `{glob}`", d.display());
    }
    let reference: Vec<&Clip> = clips.iter().map(|c| &c.clip).collect();
    let skate = FootSkate::fit(feet, &reference);
    let real = skate.mean_over(&reference);
    Ok((skate, Some((format!("{} ({glob}: {} clips)", d.display(), clips.len()), real))))
}
