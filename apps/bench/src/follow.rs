//! The path-following benchmark (`zoo bench follow`, protocol in docs/rnn-gmm-control.md): the
//! test paths (straight 10 m, circle of radius 2 m, S-curve, a hand-drawn polyline with a
//! 120-degree corner, a 20 m spiral) from each start clip (walking, running), with the root's
//! distance to the path, foot skate beside the real clips' own, and the time per generated
//! second; for the offline follower (candle, [`zoo_rnngmm::follow`]) and, given the exported
//! generator, the runtime's real-time follower (tract, `zoo_runtime::follow`).

use glam::DVec3;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::{Context, Progress, bail};
use zoo_motion::Clip;
use zoo_rnngmm::FollowOptions;
use zoo_rnngmm::error::RnnGmmResult;
use zoo_rnngmm::path::GroundPath;
use zoo_rnngmm::run::{follow_with_progress, plot_path, root_track};
use zoo_runtime::control::{ControlRunner, ControlledCharacter};
use zoo_runtime::follow::{PathGoal, PathSettings};
use zoo_runtime::pose::EnginePose;
use zoo_runtime::synthesis::SynthesisModel;

/// The benchmark's settings and inputs.
#[derive(Clone, Debug)]
pub struct FollowBenchOptions {
    /// Run folder of `zoo train rnn-gmm`.
    pub model: PathBuf,
    /// Start clips and frames, one per gait (empty: the run folder's start clip, frame 29).
    pub from: Vec<(PathBuf, usize)>,
    /// Test paths, by name ([`zoo_rnngmm::path::TEST_PATHS`]).
    pub paths: Vec<String>,
    /// Real clips whose foot skate is the reference (a folder or file of BVH), with `glob`.
    pub data: Option<PathBuf>,
    /// Clip-name pattern within `data`.
    pub glob: String,
    /// Folder that receives a top-view PNG and the BVH of every run, and all the top views in
    /// one sheet (`all.png`: a row per start, a column per path).
    pub plots: Option<PathBuf>,
    /// The optimiser's settings.
    pub optimiser: FollowOptions,
    /// Run the offline follower (candle).
    pub offline: bool,
    /// The same generator exported and loaded by the runtime (without its refiner), and its
    /// file: the runtime's follower runs with it.
    pub onnx: Option<(SynthesisModel, PathBuf)>,
    /// Speed the runtime's follower walks at, clip units per second (`None`: the data's mean,
    /// the mean feature frame's step).
    pub speed: Option<f64>,
    /// Seed frames the runtime's follower warms its generator with, ending at the start frame.
    pub runtime_seed_frames: usize,
}

/// One path from one start by one follower.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// `offline` (candle, optimised windows) or `runtime` (tract, real time).
    pub follower: String,
    /// The start clip and frame.
    pub start: String,
    /// The test path.
    pub path: String,
    /// The path's length (cm).
    pub path_length_cm: f64,
    /// Frames generated.
    pub frames: usize,
    /// Whether the motion reached the path's end.
    pub reached_end: bool,
    /// Mean distance of the root to the path (cm).
    pub mean_distance: f64,
    /// Largest distance of the root to the path (cm).
    pub max_distance: f64,
    /// Foot skate (cm per frame).
    pub foot_skate: f64,
    /// Seconds of following.
    pub seconds: f64,
    /// Seconds per generated second of motion.
    pub seconds_per_generated_second: f64,
}

/// What the benchmark measured.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Run folder.
    pub model: String,
    /// The optimiser's settings.
    pub options: String,
    /// The real clips' foot skate, with `data`.
    pub real_foot_skate: Option<f64>,
    /// The real clips, with `data`.
    pub real: Option<String>,
    /// One row per start and path.
    pub rows: Vec<Row>,
}

/// Runs the benchmark.
pub fn run(o: &FollowBenchOptions, p: &dyn Progress) -> RnnGmmResult<Report> {
    if let Some(d) = &o.plots {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    let paths: Vec<(String, GroundPath)> = o
        .paths
        .iter()
        .map(|n| Ok((n.clone(), GroundPath::test_path(n).with_context(|| format!("--paths {n}"))?)))
        .collect::<RnnGmmResult<_>>()?;
    let (g, _) = zoo_rnngmm::run::load_run(&o.model, true)?;
    let froms: Vec<Option<(&std::path::Path, usize)>> =
        if o.from.is_empty() { vec![None] } else { o.from.iter().map(|(p, f)| Some((p.as_path(), *f))).collect() };
    let starts =
        froms.iter().map(|f| zoo_rnngmm::run::start_clip(&o.model, *f, &g)).collect::<RnnGmmResult<Vec<_>>>()?;
    let starts_clips: Vec<&Clip> = starts.iter().map(|s| &s.0).collect();
    let (skate, real) = zoo_rnngmm::bench::skate_reference(&g, o.data.as_deref(), &o.glob, &starts_clips, p)?;
    let opts = &o.optimiser;
    if !o.offline && o.onnx.is_none() {
        bail!("no follower to run: the runtime's follower needs the exported generator (--onnx FILE.onnx)");
    }
    if let Some((m, _)) = &o.onnx {
        crate::control::check_export(m, &g, &o.model)?;
    }
    let mut rows = Vec::new();
    let mut tracks: Vec<Vec<Vec<[f64; 2]>>> = Vec::new();
    for (clip, frame, label) in &starts {
        tracks.push(Vec::new());
        for (name, path) in &paths {
            if o.offline {
                let t = Instant::now();
                let f = follow_with_progress(&g, clip, *frame, path, opts, &format!("{name} from {label}"), p)
                    .with_context(|| format!("following {name} from {label}"))?;
                let seconds = t.elapsed().as_secs_f64();
                let frames = f.motion.clip.frames();
                let foot_skate = skate.mean_over(&[&f.motion.clip]);
                let row = row(
                    "offline",
                    label,
                    name,
                    path,
                    frames,
                    f.reached_end,
                    &f.distance,
                    foot_skate,
                    seconds,
                    g.spec.fps,
                );
                let track = root_track(&f);
                if let Some(dir) = &o.plots {
                    let stem = format!("{name}-start{}", tracks.len() - 1);
                    plot_path(&dir.join(format!("{stem}.png")), path, &track)?;
                    let mut out = f.motion.clip.clone();
                    out.skeleton = clip.skeleton.clone();
                    zoo_data::bvh::write_file(&out, &dir.join(format!("{stem}.bvh")))
                        .with_context(|| format!("writing {stem}.bvh"))?;
                }
                rows.push(row);
                tracks.last_mut().expect("one list per start").push(track);
            }
            if let Some((model, _)) = &o.onnx {
                let seed_frames = crate::control::seed_frames(&g, clip, *frame, o.runtime_seed_frames)?;
                let t = Instant::now();
                let r = runtime_follow(model, &seed_frames, path, o.speed, opts.seed)
                    .with_context(|| format!("the runtime's follower on {name} from {label}"))?;
                let seconds = t.elapsed().as_secs_f64();
                let frames = r.roots.len();
                let foot_skate = skate.skate(&r.global, frames, model.joints());
                let distance = distances(path, &r.roots);
                rows.push(row(
                    "runtime",
                    label,
                    name,
                    path,
                    frames,
                    r.reached_end,
                    &distance,
                    foot_skate,
                    seconds,
                    g.spec.fps,
                ));
                if let Some(dir) = &o.plots {
                    plot_path(&dir.join(format!("{name}-start{}-runtime.png", tracks.len() - 1)), path, &r.roots)?;
                }
            }
        }
    }
    if let Some(dir) = &o.plots {
        sheet(&dir.join("all.png"), &tracks, &paths)?;
    }
    Ok(Report {
        model: o.model.display().to_string(),
        options: format!("{opts:?}"),
        real_foot_skate: real.as_ref().map(|r| r.1),
        real: real.as_ref().map(|(w, _)| w.clone()),
        rows,
    })
}

/// A row of the report.
#[allow(clippy::too_many_arguments)]
fn row(
    follower: &str,
    start: &str,
    name: &str,
    path: &GroundPath,
    frames: usize,
    reached_end: bool,
    distance: &[f64],
    foot_skate: f64,
    seconds: f64,
    fps: f64,
) -> Row {
    let n = distance.len().max(1) as f64;
    let motion_s = frames as f64 / fps;
    Row {
        follower: follower.into(),
        start: start.into(),
        path: name.into(),
        path_length_cm: path.length(),
        frames,
        reached_end,
        mean_distance: distance.iter().sum::<f64>() / n,
        max_distance: distance.iter().copied().fold(0.0, f64::max),
        foot_skate,
        seconds,
        seconds_per_generated_second: seconds / motion_s.max(1e-9),
    }
}

/// What the runtime's follower made: each frame's ground root and global positions.
struct RuntimeFollowed {
    roots: Vec<[f64; 2]>,
    global: Vec<DVec3>,
    reached_end: bool,
}

/// The runtime's follower (`zoo_runtime::follow`, its default settings) along `path` from the
/// seed frames, at `speed` (default the data's mean), until the path's end or three times the
/// frames the path takes at that speed, plus a second.
fn runtime_follow(
    model: &SynthesisModel,
    seed_frames: &[f32],
    path: &GroundPath,
    speed: Option<f64>,
    seed: u64,
) -> RnnGmmResult<RuntimeFollowed> {
    let runtime = |e: zoo_runtime::MotionError| zoo_data::Message::new(e);
    let d = model.frame_dim();
    let mean = &model.model().metadata().group("x", d).map_err(|e| zoo_data::Message::new(e.to_string()))?.mean;
    let fps = model.model().metadata().fps as f64;
    let speed = speed.unwrap_or_else(|| (mean[0] as f64).hypot(mean[1] as f64) * fps);
    let mut goal = PathGoal::new(path.points(), speed, PathSettings::default()).map_err(runtime)?;
    let mut ch = ControlledCharacter::new(model, seed, PathSettings::control()).map_err(runtime)?;
    let [x, z, yaw] = goal.start_placement();
    ch.start(model, seed_frames, x as f32, z as f32, yaw as f32).map_err(runtime)?;
    let mut runner = ControlRunner::new(model).map_err(runtime)?;
    let mut pose = EnginePose::with_global_positions(model.joints());
    let most = (3.0 * path.length() / speed * fps).ceil() as usize + fps.round() as usize;
    let (mut roots, mut global) = (Vec::new(), Vec::new());
    while roots.len() < most && !goal.reached_end() {
        runner.step_along(&mut ch, &mut goal, &mut pose).map_err(runtime)?;
        roots.push([pose.root_position.x as f64, pose.root_position.z as f64]);
        global.extend(pose.global_positions.iter().map(|p| p.as_dvec3()));
    }
    Ok(RuntimeFollowed { roots, global, reached_end: goal.reached_end() })
}

/// Each root's distance to the path, the nearest point searched as the offline follower
/// searches it (a metre behind the progress so far to six metres ahead).
fn distances(path: &GroundPath, roots: &[[f64; 2]]) -> Vec<f64> {
    let mut s_now: f64 = 0.0;
    roots
        .iter()
        .map(|p| {
            let n = path.nearest(*p, s_now - 100.0, s_now + 600.0);
            s_now = s_now.max(n.s);
            n.distance
        })
        .collect()
}

/// Every run in one sheet: a row per start, a column per path.
fn sheet(png: &std::path::Path, tracks: &[Vec<Vec<[f64; 2]>>], paths: &[(String, GroundPath)]) -> RnnGmmResult<()> {
    let cells: Vec<Vec<Vec<zoo_nn::plot::TopSeries>>> = tracks
        .iter()
        .map(|row| {
            row.iter()
                .zip(paths)
                .map(|(t, (_, p))| vec![(p.points(), (150, 150, 150), 4.0), (t.as_slice(), (200, 30, 30), 1.2)])
                .collect()
        })
        .collect();
    zoo_nn::plot::top_view_grid(png, &cells, 100.0, 240).with_context(|| format!("writing {}", png.display()))?;
    Ok(())
}

impl Report {
    /// The report as the command prints it: a line per run, then the table.
    pub fn text(&self) -> String {
        let mut s = String::new();
        for r in &self.rows {
            s += &format!(
                "{:>8} from {} ({}): {} frames, root to path mean {:.2} max {:.2}, skate {:.3}, {:.2} s per \
                 generated second{}\n",
                r.path,
                r.start,
                r.follower,
                r.frames,
                r.mean_distance,
                r.max_distance,
                r.foot_skate,
                r.seconds_per_generated_second,
                if r.reached_end { "" } else { " (did not reach the end)" }
            );
        }
        s += "\n| follower | start | path | frames | reached end | root to path, mean (cm) | max (cm) | foot skate \
              (cm/frame) | s per generated second |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
        for r in &self.rows {
            s += &format!(
                "| {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.3} | {:.2} |\n",
                r.follower,
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
        if let (Some(what), Some(skate)) = (&self.real, self.real_foot_skate) {
            s += &format!("real foot skate: {skate:.3} cm/frame ({what})\n");
        }
        s.trim_end().to_string()
    }
}
