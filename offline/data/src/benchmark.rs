//! The in-betweening benchmark (LaFAN1 protocol, `BENCHMARK.md`): setup from a training and
//! a test split, transition methods (zero-velocity and interpolation baselines built in),
//! and the metric table.

use crate::dataset::{self, NamedClip, PositionStats, WindowOptions, Windows};
use crate::metrics::{self, FootSkate};
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::time::Instant;
use zoo_motion::Skeleton;
use zoo_motion::fk::forward_kinematics_frame;
use zoo_motion::quat::slerp;

/// Past context frames of every transition.
pub const N_PAST: usize = 10;
/// Frames kept after the target.
pub const N_FUTURE: usize = 10;

/// One transition to generate: the context a method may look at.
#[derive(Clone, Copy, Debug)]
pub struct TransitionTask<'a> {
    /// Skeleton (joint 0 is the root).
    pub skeleton: &'a Skeleton,
    /// Bone offsets of joints `1..` (the benchmark's evaluation offsets).
    pub offsets: &'a [DVec3],
    /// Local rotations of the past frames, `N_PAST x joints`.
    pub past_rot: &'a [DQuat],
    /// Root positions of the past frames.
    pub past_root: &'a [DVec3],
    /// Local rotations of the target frame and the frame after it, `2 x joints`.
    pub target_rot: &'a [DQuat],
    /// Root positions of the target frame and the frame after it.
    pub target_root: &'a [DVec3],
    /// Transition length in frames.
    pub frames: usize,
}

/// A generated transition: `frames` frames of root positions and local rotations.
#[derive(Clone, Debug, Default)]
pub struct Transition {
    /// Root position per frame.
    pub root: Vec<DVec3>,
    /// Local rotations, frames x joints.
    pub rot: Vec<DQuat>,
    /// For methods that generate joint positions first: their raw global positions
    /// (frames x joints), reported as `l2p_raw` beside L2P after the skeleton fit.
    pub raw_positions: Option<Vec<DVec3>>,
}

/// A transition generator evaluated by the benchmark.
pub trait TransitionMethod: Sync {
    /// Row name in the table and key in the JSON.
    fn name(&self) -> String;
    /// Generates one transition per task.
    fn generate(&self, tasks: &[TransitionTask<'_>]) -> Result<Vec<Transition>, String>;
}

/// Zero-velocity baseline: every transition frame repeats the last past frame.
pub struct ZeroVelocity;

impl TransitionMethod for ZeroVelocity {
    fn name(&self) -> String {
        "zerovel".into()
    }
    fn generate(&self, tasks: &[TransitionTask<'_>]) -> Result<Vec<Transition>, String> {
        Ok(tasks
            .iter()
            .map(|t| {
                let j = t.skeleton.len();
                let last = &t.past_rot[(N_PAST - 1) * j..N_PAST * j];
                Transition {
                    root: vec![t.past_root[N_PAST - 1]; t.frames],
                    rot: (0..t.frames).flat_map(|_| last.iter().copied()).collect(),
                    raw_positions: None,
                }
            })
            .collect())
    }
}

/// Interpolation baseline: root LERP and local-rotation SLERP between the last past frame and
/// the target, with weights `k / (n + 1)`, `k = 1..n`.
pub struct Interpolation;

/// Interpolates one transition (the baseline's own code, reused by other methods).
pub fn interpolate(t: &TransitionTask<'_>) -> Transition {
    let j = t.skeleton.len();
    let (r0, r1) = (t.past_root[N_PAST - 1], t.target_root[0]);
    let q0 = &t.past_rot[(N_PAST - 1) * j..N_PAST * j];
    let q1 = &t.target_rot[..j];
    let mut root = Vec::with_capacity(t.frames);
    let mut rot = Vec::with_capacity(t.frames * j);
    for k in 1..=t.frames {
        // float32 weights, as np.linspace(..., dtype=float32) in the reference
        let w = (k as f32 / (t.frames + 1) as f32) as f64;
        root.push(r0 + (r1 - r0) * w);
        rot.extend((0..j).map(|i| slerp(q0[i], q1[i], w)));
    }
    Transition { root, rot, raw_positions: None }
}

impl TransitionMethod for Interpolation {
    fn name(&self) -> String {
        "interp".into()
    }
    fn generate(&self, tasks: &[TransitionTask<'_>]) -> Result<Vec<Transition>, String> {
        Ok(tasks.iter().map(interpolate).collect())
    }
}

/// Everything the benchmark derives from the training split, plus the test windows.
pub struct Benchmark {
    /// Test windows (65 frames, offset 40, centred, facing unified).
    pub test: Windows,
    /// Global-position statistics of the training windows.
    pub stats: PositionStats,
    /// Evaluation bone offsets (joints `1..` of the first training window's first frame).
    pub offsets: Vec<DVec3>,
    /// Foot-skate parameters (planted heights from the training windows).
    pub skate: FootSkate,
    /// Root positions of the test windows (windows x frames).
    roots: Vec<DVec3>,
}

impl Benchmark {
    /// Builds the benchmark from training clips (statistics, offsets, planted foot heights)
    /// and test clips (windows).
    pub fn new(train: &[NamedClip], test: &[NamedClip]) -> Result<Benchmark, String> {
        let tw = dataset::windows(train, &WindowOptions::TRAIN);
        if tw.count == 0 {
            return Err("the training split has no 50-frame window: its clips are all too short".into());
        }
        let test = dataset::windows(test, &WindowOptions::TEST);
        if test.count == 0 {
            return Err("the test split has no 65-frame window: its clips are all too short".into());
        }
        if let Some(why) = tw.skeleton.topology_difference(&test.skeleton) {
            return Err(format!(
                "the test data's skeleton differs from the training data's ({why}): use a held-out set on the same rig"
            ));
        }
        let j = tw.joints();
        let (_, gp) = tw.global();
        let stats = dataset::position_stats(&gp, j);
        let offsets = tw.local_pos[1..j].to_vec();
        let feet = metrics::foot_joints(&tw.skeleton.names);
        let planted = feet
            .iter()
            .map(|&f| {
                let mut h: Vec<f64> = gp.iter().skip(f).step_by(j).map(|p| p.y).collect();
                dataset::percentile(&mut h, 5.0)
            })
            .collect();
        let roots = test.local_pos.iter().step_by(j).copied().collect();
        Ok(Benchmark { test, stats, offsets, skate: FootSkate { joints: feet, planted, scale: 2.5 }, roots })
    }

    /// Number of test windows.
    pub fn windows(&self) -> usize {
        self.test.count
    }

    fn tasks(&self, n: usize) -> Vec<TransitionTask<'_>> {
        let j = self.test.joints();
        (0..self.test.count)
            .map(|w| {
                let rot = self.test.rot(w);
                let roots = &self.roots[w * self.test.window..(w + 1) * self.test.window];
                let tgt = N_PAST + n;
                TransitionTask {
                    skeleton: &self.test.skeleton,
                    offsets: &self.offsets,
                    past_rot: &rot[..N_PAST * j],
                    past_root: &roots[..N_PAST],
                    target_rot: &rot[tgt * j..(tgt + 2) * j],
                    target_root: &roots[tgt..tgt + 2],
                    frames: n,
                }
            })
            .collect()
    }

    /// Global rotations and positions (frames `N_PAST - 1 .. N_PAST + n`: the last context
    /// frame then the transition) of the ground truth or of generated transitions, with the
    /// evaluation offsets for joints `1..`.
    fn globals(&self, n: usize, generated: Option<&[Transition]>) -> (Vec<DQuat>, Vec<DVec3>) {
        let j = self.test.joints();
        let frames = n + 1;
        let mut gr = vec![DQuat::IDENTITY; self.test.count * frames * j];
        let mut gp = vec![DVec3::ZERO; self.test.count * frames * j];
        gr.par_chunks_mut(frames * j).zip(gp.par_chunks_mut(frames * j)).enumerate().for_each(|(w, (gr, gp))| {
            let (rot, pos) = (self.test.rot(w), self.test.pos(w));
            let mut lp = vec![DVec3::ZERO; j];
            lp[1..].copy_from_slice(&self.offsets);
            for k in 0..frames {
                let f = N_PAST - 1 + k;
                let lr = match generated {
                    Some(g) if k > 0 => {
                        lp[0] = g[w].root[k - 1];
                        &g[w].rot[(k - 1) * j..k * j]
                    }
                    _ => {
                        lp[0] = pos[f * j];
                        &rot[f * j..(f + 1) * j]
                    }
                };
                forward_kinematics_frame(
                    &self.test.skeleton.parents,
                    lr,
                    &lp,
                    &mut gr[k * j..(k + 1) * j],
                    &mut gp[k * j..(k + 1) * j],
                );
            }
        });
        (gr, gp)
    }

    /// Runs `methods` at every transition length in `lengths`.
    pub fn run(&self, methods: &[&dyn TransitionMethod], lengths: &[usize]) -> Result<BenchResult, String> {
        self.run_with(methods, lengths, &mut |_, _, _| {})
    }

    /// Test window `w` cut to `N_PAST + n + N_FUTURE` frames, with the evaluation offsets, and
    /// with `transition` in place of its frames `N_PAST..N_PAST + n` when given (the ground
    /// truth otherwise): a clip to write as BVH or render.
    pub fn window_clip(&self, w: usize, n: usize, transition: Option<&Transition>) -> zoo_motion::Clip {
        let j = self.test.joints();
        let frames = N_PAST + n + N_FUTURE;
        let mut clip = zoo_motion::Clip {
            skeleton: self.test.skeleton.clone(),
            frame_time: 1.0 / 30.0,
            local_rotations: self.test.rot(w)[..frames * j].to_vec(),
            local_positions: Vec::with_capacity(frames * j),
        };
        for f in 0..frames {
            clip.local_positions.push(self.roots[w * self.test.window + f]);
            clip.local_positions.extend_from_slice(&self.offsets);
        }
        if let Some(t) = transition {
            for k in 0..n {
                let f = N_PAST + k;
                clip.local_rotations[f * j..(f + 1) * j].copy_from_slice(&t.rot[k * j..(k + 1) * j]);
                clip.local_positions[f * j] = t.root[k];
            }
        }
        clip
    }

    /// [`Self::run`], handing every method's transitions at every length to `generated`
    /// (method name, length, one transition per test window).
    pub fn run_with(
        &self,
        methods: &[&dyn TransitionMethod],
        lengths: &[usize],
        generated_out: &mut dyn FnMut(&str, usize, &[Transition]),
    ) -> Result<BenchResult, String> {
        let j = self.test.joints();
        let mut result = BenchResult { windows: self.test.count, gt: BTreeMap::new(), methods: BTreeMap::new() };
        for &n in lengths {
            if N_PAST + n + N_FUTURE > self.test.window {
                return Err(format!(
                    "transition length {n} needs {} frames per test window, windows have {}",
                    N_PAST + n + N_FUTURE,
                    self.test.window
                ));
            }
            let tasks = self.tasks(n);
            let (gt_r, gt_p) = self.globals(n, None);
            // Without foot joints there is no skate to measure: no figure rather than a 0.
            let feet = !self.skate.joints.is_empty();
            if feet {
                result.gt.insert(format!("skate@{n}"), self.skate.skate(&gt_p, n + 1, j));
            }
            let (gt_rt, gt_pt) = (transition_part(&gt_r, n, j), transition_part(&gt_p, n, j));
            for m in methods {
                let start = Instant::now();
                let generated = m.generate(&tasks)?;
                let ms = start.elapsed().as_secs_f64() * 1e3 / tasks.len() as f64;
                if generated.len() != tasks.len() || generated.iter().any(|g| g.root.len() != n || g.rot.len() != n * j)
                {
                    return Err(format!("method {} returned transitions of the wrong shape", m.name()));
                }
                generated_out(&m.name(), n, &generated);
                let (pr, pp) = self.globals(n, Some(&generated));
                let (prt, ppt) = (transition_part(&pr, n, j), transition_part(&pp, n, j));
                let row = result.methods.entry(m.name()).or_default();
                row.insert(format!("l2q@{n}"), metrics::l2q(&prt, &gt_rt, j));
                row.insert(format!("l2p@{n}"), metrics::l2p(&ppt, &gt_pt, j, &self.stats.std));
                row.insert(format!("npss@{n}"), metrics::npss(&prt, &gt_rt, self.test.count, n, j));
                row.insert(format!("aco@{n}"), metrics::aco(&ppt, &gt_pt));
                if feet {
                    row.insert(format!("skate@{n}"), self.skate.skate(&pp, n + 1, j));
                }
                row.insert(format!("ms_per_transition@{n}"), ms);
                if generated.iter().all(|g| g.raw_positions.is_some()) {
                    let raw: Vec<DVec3> = generated.iter().flat_map(|g| g.raw_positions.clone().unwrap()).collect();
                    row.insert(format!("l2p_raw@{n}"), metrics::l2p(&raw, &gt_pt, j, &self.stats.std));
                }
            }
        }
        Ok(result)
    }
}

/// Drops the leading context frame of each window's `(n + 1)`-frame block.
fn transition_part<T: Copy>(all: &[T], n: usize, joints: usize) -> Vec<T> {
    all.chunks_exact((n + 1) * joints).flat_map(|c| c[joints..].iter().copied()).collect()
}

/// What the table says instead of foot-skate figures when the skeleton has no foot joints.
pub const NO_FEET: &str =
    "not measured: no joint name contains `foot` or `toe`, so the benchmark found no feet (rename the foot joints)";

/// Benchmark results, shaped as the JSON output.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BenchResult {
    /// Number of test windows.
    pub windows: usize,
    /// Ground truth's own figures (`skate@n`).
    pub gt: BTreeMap<String, f64>,
    /// Per method: `metric@n` -> value.
    pub methods: BTreeMap<String, BTreeMap<String, f64>>,
}

impl BenchResult {
    /// The LaFAN1-style table: one block per metric, one row per method, one column per length.
    pub fn table(&self, lengths: &[usize]) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(s, "test windows: {}", self.windows);
        let blocks = [
            ("L2Q", "l2q", 3),
            ("L2P", "l2p", 3),
            ("L2P (raw positions)", "l2p_raw", 3),
            ("NPSS", "npss", 4),
            ("ACO (cm)", "aco", 2),
            ("Foot skate (cm/frame)", "skate", 3),
            ("ms per transition", "ms_per_transition", 3),
        ];
        for (title, key, prec) in blocks {
            let rows: Vec<(&String, &BTreeMap<String, f64>)> =
                self.methods.iter().filter(|(_, m)| m.keys().any(|k| k.starts_with(&format!("{key}@")))).collect();
            if rows.is_empty() {
                if key == "skate" && !self.methods.is_empty() {
                    let _ = writeln!(s, "\n{title}: {NO_FEET}");
                }
                continue;
            }
            let _ = write!(s, "\n{title:<22}");
            for n in lengths {
                let _ = write!(s, "{:>10}", n);
            }
            s.push('\n');
            if key == "skate" {
                let _ = write!(s, "{:<22}", "  ground truth");
                for n in lengths {
                    let _ = write!(s, "{:>10.prec$}", self.gt.get(&format!("skate@{n}")).copied().unwrap_or(f64::NAN));
                }
                s.push('\n');
            }
            for (name, m) in rows {
                let _ = write!(s, "{:<22}", format!("  {name}"));
                for n in lengths {
                    let v = m.get(&format!("{key}@{n}")).copied().unwrap_or(f64::NAN);
                    let _ = write!(s, "{:>10.prec$}", v);
                }
                s.push('\n');
            }
        }
        s
    }
}
