//! The path-following benchmark (`zoo bench follow`, protocol in docs/rnn-gmm-control.md): the
//! test paths (straight 10 m, circle of radius 2 m, S-curve, a hand-drawn polyline with a
//! 120-degree corner, a 20 m spiral) from each start clip (walking, running), with the root's
//! distance to the path, foot skate beside the real clips' own, and the time per generated
//! second.

use crate::FollowOptions;
use crate::error::RnnGmmResult;
use crate::path::GroundPath;
use crate::run::{follow_with_progress, plot_path, root_track};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::{Context, Progress};
use zoo_motion::Clip;

/// The benchmark's settings and inputs.
#[derive(Clone, Debug)]
pub struct FollowBenchOptions {
    /// Run folder of `zoo train rnn-gmm`.
    pub model: PathBuf,
    /// Start clips and frames, one per gait (empty: the run folder's start clip, frame 29).
    pub from: Vec<(PathBuf, usize)>,
    /// Test paths, by name ([`crate::path::TEST_PATHS`]).
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
}

/// One path from one start.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
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
    let (g, _) = crate::run::load_run(&o.model, true)?;
    let froms: Vec<Option<(&std::path::Path, usize)>> =
        if o.from.is_empty() { vec![None] } else { o.from.iter().map(|(p, f)| Some((p.as_path(), *f))).collect() };
    let starts = froms.iter().map(|f| crate::run::start_clip(&o.model, *f, &g)).collect::<RnnGmmResult<Vec<_>>>()?;
    let starts_clips: Vec<&Clip> = starts.iter().map(|s| &s.0).collect();
    let (skate, real) = super::skate_reference(&g, o.data.as_deref(), &o.glob, &starts_clips, p)?;
    let opts = &o.optimiser;
    let mut rows = Vec::new();
    let mut tracks: Vec<Vec<Vec<[f64; 2]>>> = Vec::new();
    for (clip, frame, label) in &starts {
        tracks.push(Vec::new());
        for (name, path) in &paths {
            let t = Instant::now();
            let f = follow_with_progress(&g, clip, *frame, path, opts, &format!("{name} from {label}"), p)
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
            let track = root_track(&f);
            if let Some(dir) = &o.plots {
                let stem = format!("{name}-start{}", rows.len() / paths.len());
                plot_path(&dir.join(format!("{stem}.png")), path, &track)?;
                let mut out = f.motion.clip.clone();
                out.skeleton = clip.skeleton.clone();
                zoo_data::bvh::write_file(&out, &dir.join(format!("{stem}.bvh")))
                    .with_context(|| format!("writing {stem}.bvh"))?;
            }
            rows.push(row);
            tracks.last_mut().expect("one list per start").push(track);
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
                "{:>8} from {}: {} frames, root to path mean {:.2} max {:.2}, skate {:.3}, {:.1} s per generated \
                 second{}\n",
                r.path,
                r.start,
                r.frames,
                r.mean_distance,
                r.max_distance,
                r.foot_skate,
                r.seconds_per_generated_second,
                if r.reached_end { "" } else { " (did not reach the end)" }
            );
        }
        s += "\n| start | path | frames | reached end | root to path, mean (cm) | max (cm) | foot skate (cm/frame) | s \
              per generated second |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n";
        for r in &self.rows {
            s += &format!(
                "| {} | {} | {} | {} | {:.2} | {:.2} | {:.3} | {:.1} |\n",
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
