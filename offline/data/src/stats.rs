//! Statistics of a dataset (`zoo data stats`): clips, frames, frame rates, the skeleton, root
//! speed, the feet's planted heights and skate (above each clip's terrain when it has one),
//! and how rigid the bones are.

use crate::dataset::{self, NamedClip};
use crate::{Message, metrics};
use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::time::Instant;
use zoo_motion::Skeleton;

/// Statistics printed by `zoo data stats` (and written with `--json`).
#[derive(Serialize)]
pub struct DataStats {
    /// Number of clips.
    pub clips: usize,
    /// Total frames.
    pub frames: usize,
    /// Total duration in seconds.
    pub duration_s: f64,
    /// Distinct frame rates found.
    pub fps: Vec<f64>,
    /// Joints per frame (after dropping a dummy root).
    pub joints: usize,
    /// Joint names.
    pub joint_names: Vec<String>,
    /// Parent index per joint (-1 for the root).
    pub parents: Vec<i32>,
    /// Horizontal root speed percentiles over all frames (units/s): p5, p25, p50, p75, p95;
    /// `null` when no clip has two frames.
    pub root_speed: Option<RootSpeed>,
    /// Foot joints used for the skate measure (empty: none found, no foot figures).
    pub foot_joints: Vec<String>,
    /// Planted height of each foot joint (5th percentile of its height); `null` where it cannot
    /// be computed (listed in `not_computed`).
    pub planted_heights: Vec<Option<f64>>,
    /// The data's own foot skate (units per frame, `BENCHMARK.md` definition, all frames; heights
    /// above the clip's terrain when a `NAME.terrain.json` lies beside it); `null` without feet
    /// or without two consecutive frames.
    pub foot_skate: Option<f64>,
    /// Lowest foot-joint height over all frames (above the terrain when there is one): how far
    /// feet sink below the ground if negative; `null` without feet or frames.
    pub min_foot_height: Option<f64>,
    /// Largest change of a bone's length within a clip (0 for rigid skeletons); `null` when it
    /// cannot be computed.
    pub max_bone_length_change: Option<f64>,
    /// The figures that cannot be computed for these clips (their values would be NaN or
    /// infinite: coordinates beyond the range of numbers, a frame time too small), each with
    /// the reason in words. Such a figure is `null` in the JSON, never NaN.
    pub not_computed: Vec<String>,
    /// Seconds taken.
    pub seconds: f64,
}

/// Percentiles of the horizontal root speed.
#[derive(Serialize)]
pub struct RootSpeed {
    /// 5th percentile.
    pub p5: f64,
    /// 25th percentile.
    pub p25: f64,
    /// Median.
    pub p50: f64,
    /// 75th percentile.
    pub p75: f64,
    /// 95th percentile.
    pub p95: f64,
}

/// Per clip: global positions of the feet, the root's horizontal speed, the bones' drift.
struct PerClip {
    feet: Vec<DVec3>,
    speed: Vec<f64>,
    bone_drift: f64,
}

/// The feet's positions (their heights above the clip's terrain, when a heightmap lies beside
/// it), the root's horizontal speed and the largest change of a bone's length of one clip.
fn per_clip(c: &NamedClip, feet: &[usize]) -> Result<PerClip, Message> {
    let (_, gp) = c.clip.global();
    let (frames, j) = (c.clip.frames(), c.clip.joints());
    let ground = match crate::terrain::sibling_of(&c.path) {
        Some(t) => Some(crate::terrain::read(&t).map_err(Message::new)?),
        None => None,
    };
    let mut fp = Vec::with_capacity(frames * feet.len());
    for f in 0..frames {
        fp.extend(feet.iter().map(|&k| {
            let p = gp[f * j + k];
            DVec3::new(p.x, p.y - ground.as_ref().map_or(0.0, |g| g.height(p.x, p.z)), p.z)
        }));
    }
    let speed = (1..frames)
        .map(|f| {
            let d = gp[f * j] - gp[(f - 1) * j];
            (d.x * d.x + d.z * d.z).sqrt() / c.clip.frame_time
        })
        .collect();
    // Largest change of any bone's length (global joint distance) from frame 0.
    let mut bone_drift: f64 = 0.0;
    for k in (1..j).filter(|_| frames > 0) {
        let p = c.clip.skeleton.parents[k].unwrap_or(0);
        let len0 = (gp[k] - gp[p]).length();
        for f in 1..frames {
            bone_drift = bone_drift.max(((gp[f * j + k] - gp[f * j + p]).length() - len0).abs());
        }
    }
    Ok(PerClip { feet: fp, speed, bone_drift })
}

/// Why a figure is not finite.
const OVERFLOW: &str = "the clips' positions or frame times are beyond the range this figure can be computed in; \
check the file's OFFSET and channel values and its Frame Time";

/// The statistics of `clips` (at least one).
pub fn stats(clips: &[NamedClip]) -> Result<DataStats, Message> {
    let start = Instant::now();
    let skeleton = clips.first().ok_or_else(|| Message::new("no clips"))?.clip.skeleton.clone();
    let j = skeleton.len();
    let feet = metrics::foot_joints(&skeleton.names);
    let per: Vec<PerClip> = clips.par_iter().map(|c| per_clip(c, &feet)).collect::<Result<_, _>>()?;
    let planted: Vec<f64> = (0..feet.len())
        .map(|k| {
            let mut h: Vec<f64> =
                per.iter().flat_map(|p| p.feet.iter().skip(k).step_by(feet.len()).map(|v| v.y)).collect();
            dataset::percentile(&mut h, 5.0)
        })
        .collect();
    let fs = metrics::FootSkate { joints: (0..feet.len()).collect(), planted: planted.clone(), scale: 2.5 };
    let (mut skate_sum, mut skate_n) = (0.0, 0usize);
    for (p, c) in per.iter().zip(clips) {
        let frames = c.clip.frames();
        if frames > 1 && !feet.is_empty() {
            skate_sum += fs.skate(&p.feet, frames, feet.len()) * ((frames - 1) * feet.len()) as f64;
            skate_n += (frames - 1) * feet.len();
        }
    }
    let mut speeds: Vec<f64> = per.iter().flat_map(|p| p.speed.iter().copied()).collect();
    let root_speed = (!speeds.is_empty()).then(|| {
        let mut pct = |q| dataset::percentile(&mut speeds, q);
        RootSpeed { p5: pct(5.0), p25: pct(25.0), p50: pct(50.0), p75: pct(75.0), p95: pct(95.0) }
    });
    let mut not_computed = Vec::new();
    let mut figure = |name: &str, v: Option<f64>| match v {
        Some(x) if !x.is_finite() => {
            not_computed.push(format!("{name}: cannot be computed ({OVERFLOW})"));
            None
        }
        v => v,
    };
    let root_speed = root_speed.filter(|r| {
        let ok = [r.p5, r.p25, r.p50, r.p75, r.p95].iter().all(|v| v.is_finite());
        ok || figure("root speed", Some(f64::INFINITY)).is_some()
    });
    let planted_heights: Vec<Option<f64>> = planted
        .iter()
        .zip(&feet)
        .map(|(&h, &k)| figure(&format!("planted height of {}", skeleton.names[k]), Some(h)))
        .collect();
    let foot_skate = figure("foot skate", (skate_n > 0).then(|| skate_sum / skate_n as f64));
    let min_foot_height =
        figure("lowest foot height", per.iter().flat_map(|p| p.feet.iter().map(|v| v.y)).reduce(f64::min));
    let max_bone_length_change =
        figure("largest bone length change", Some(per.iter().map(|p| p.bone_drift).fold(0.0, f64::max)));
    let mut fps: Vec<f64> = clips.iter().map(|c| (c.clip.fps() * 1000.0).round() / 1000.0).collect();
    fps.sort_by(f64::total_cmp);
    fps.dedup();
    let frames: usize = clips.iter().map(|c| c.clip.frames()).sum();
    Ok(DataStats {
        clips: clips.len(),
        frames,
        duration_s: clips.iter().map(|c| c.clip.duration()).sum(),
        fps,
        joints: j,
        joint_names: skeleton.names.clone(),
        parents: skeleton.parents_i32(),
        root_speed,
        foot_joints: feet.iter().map(|&k| skeleton.names[k].clone()).collect(),
        planted_heights,
        foot_skate,
        min_foot_height,
        max_bone_length_change,
        not_computed,
        seconds: start.elapsed().as_secs_f64(),
    })
}

impl DataStats {
    /// The statistics as `zoo data stats` prints them (`skeleton`: the clips' hierarchy).
    pub fn text(&self, skeleton: &Skeleton) -> String {
        let s = self;
        let mut t = String::new();
        let _ = writeln!(t, "clips      {}", s.clips);
        let _ = writeln!(t, "frames     {}", s.frames);
        let _ = writeln!(t, "duration   {:.1} s ({:.1} min)", s.duration_s, s.duration_s / 60.0);
        let _ = writeln!(t, "fps        {}", s.fps.iter().map(|f| format!("{f}")).collect::<Vec<_>>().join(", "));
        let _ = writeln!(t, "joints     {}", s.joints);
        tree(skeleton, 0, 1, &mut t);
        let _ = match &s.root_speed {
            Some(r) => writeln!(
                t,
                "root speed (units/s)  p5 {:.1}  p25 {:.1}  median {:.1}  p75 {:.1}  p95 {:.1}",
                r.p5, r.p25, r.p50, r.p75, r.p95
            ),
            None if s.frames > s.clips => writeln!(t, "root speed            not computed (below)"),
            None => writeln!(t, "root speed            not measured: no clip has two frames"),
        };
        for (n, h) in s.foot_joints.iter().zip(&s.planted_heights) {
            if let Some(h) = h {
                let _ = writeln!(t, "planted height  {n:<10} {h:.2}");
            }
        }
        if s.foot_joints.is_empty() {
            let _ = writeln!(t, "foot skate            not measured: no joint name contains `foot` or `toe`");
        } else {
            let _ = match s.foot_skate {
                Some(v) => writeln!(t, "foot skate (units/frame, all frames)  {v:.4}"),
                None if s.frames > s.clips => writeln!(t, "foot skate            not computed (below)"),
                None => writeln!(t, "foot skate            not measured: no clip has two frames"),
            };
            if let Some(h) = s.min_foot_height {
                let _ = writeln!(t, "lowest foot joint height              {h:.2}");
            }
        }
        if let Some(v) = s.max_bone_length_change {
            let _ = writeln!(t, "largest bone length change            {v:.2e}");
        }
        for n in &s.not_computed {
            let _ = writeln!(t, "{n}");
        }
        let _ = writeln!(t, "done in {:.2} s", s.seconds);
        t
    }
}

/// Indentation levels printed before the depth is written as a number instead.
const TREE_INDENT_LEVELS: usize = 32;

/// The joint tree below `root`, one joint a line indented by its depth (a stack, not
/// recursion: a file can nest joints as deep as it likes; past [`TREE_INDENT_LEVELS`] levels the
/// depth is written as a number, so the text grows with the joint count only).
fn tree(s: &Skeleton, root: usize, depth: usize, t: &mut String) {
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); s.len()];
    for (c, p) in s.parents.iter().enumerate() {
        if let Some(p) = *p {
            children[p].push(c);
        }
    }
    let mut stack = vec![(root, depth)];
    while let Some((j, d)) = stack.pop() {
        let _ = match d {
            d if d <= TREE_INDENT_LEVELS => writeln!(t, "{}{}", "  ".repeat(d), s.names[j]),
            d => writeln!(t, "{}[depth {d}] {}", "  ".repeat(TREE_INDENT_LEVELS), s.names[j]),
        };
        stack.extend(children[j].iter().rev().map(|&c| (c, d + 1)));
    }
}
