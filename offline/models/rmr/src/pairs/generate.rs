//! Training pairs for stitching (RMR sec. 4): ground-truth windows `Y`, and inputs `X` made of
//! the window's first segment A and two retrieved segments B and C.
//!
//! For each window of `T` frames (windows slide by `window_step`):
//! 1. draw lengths `T_A + T_B + T_C = T`, multiples of `unit`, `T_A, T_C > 0`, `T_B >= 0`
//!    (uniformly over the valid triples);
//! 2. A is the window's first `T_A` frames;
//! 3. for B and C: the k-th nearest segment (`k` uniform in `k_min..=k_max`) to the window's
//!    corresponding frames in the database of that length ([`super::segments`]), skipping
//!    the window's own clip when the ground truth and the database share their clips;
//! 4. the ground truth's root trajectory is copied into B and C: the root of frame `t` of B is
//!    `anchor ∘ root_gt(b_0)^-1 ∘ root_gt(t)`, where the anchor is A's last root (C: B's last),
//!    so B starts exactly on A's last root (the alignment of RMR sec. 3) and follows the
//!    ground truth's path from there; the retrieved segment keeps its hips height and its hips
//!    orientation relative to its own root;
//! 5. joint rotations come from the retrieved segment, except the upper body (every joint not
//!    in [`StitchLayout::lower_body`]) which is interpolated towards the ground truth's with
//!    weight [`PairConfig::upper_body_ground_truth`] (1: copied, the default);
//! 6. both clips are re-expressed in the ground root of the window's first frame (that root
//!    becomes the identity) and quaternion sign flips along time are removed from `X`.

use super::StitchError;
use super::layout::{GroundRoot, StitchLayout};
use super::segments::{MotionSet, StitchDatabases};
use rayon::prelude::*;
use zoo_motion::Clip;
use zoo_motion::quat::slerp;
use zoo_motion::rng::SplitMix64;

/// How pairs are made. The defaults are the paper's numbers read at bandai2's 30 fps: the
/// paper's window is `T = 60` frames at 60 fps; we keep 60 frames (2 s at 30 fps) and segment
/// lengths in multiples of 10 frames (docs/rmr.md explains why).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairConfig {
    /// Frames per window, `T`.
    pub window: usize,
    /// Step between window starts (`T / 2` in the paper).
    pub window_step: usize,
    /// Segment lengths are multiples of this many frames.
    pub unit: usize,
    /// Smallest `k` of the k-th nearest neighbour.
    pub k_min: usize,
    /// Largest `k`.
    pub k_max: usize,
    /// Weight of the ground truth's upper-body rotations in B and C (0: the retrieved
    /// segment's, 1: the ground truth's).
    pub upper_body_ground_truth: f64,
    /// Skip segments of the window's own clip (set when the databases are built from the
    /// ground-truth clips themselves, so that B and C never come from the same take).
    pub exclude_same_clip: bool,
    /// Database segments start every this many frames.
    pub database_stride: usize,
    /// Seed of the draws (lengths and k); window `i` uses stream `i`.
    pub seed: u64,
}

impl Default for PairConfig {
    fn default() -> Self {
        PairConfig {
            window: 60,
            window_step: 30,
            unit: 10,
            k_min: 5,
            k_max: 10,
            upper_body_ground_truth: 1.0,
            exclude_same_clip: true,
            database_stride: 1,
            seed: 0,
        }
    }
}

impl PairConfig {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), StitchError> {
        let bad = |m: String| Err(StitchError::Config(m));
        if self.unit == 0 || self.window_step == 0 || self.database_stride == 0 {
            return bad("unit, window_step and database_stride must be at least 1".into());
        }
        if !self.window.is_multiple_of(self.unit) || self.window < 2 * self.unit {
            return bad(format!(
                "window {} must be a multiple of unit {} and hold at least two units (A and C)",
                self.window, self.unit
            ));
        }
        if self.k_min == 0 || self.k_min > self.k_max {
            return bad(format!("need 1 <= k_min <= k_max, got {}..={}", self.k_min, self.k_max));
        }
        if !(0.0..=1.0).contains(&self.upper_body_ground_truth) {
            return bad(format!("upper_body_ground_truth must be in [0, 1], got {}", self.upper_body_ground_truth));
        }
        Ok(())
    }

    /// Lengths that B or C can have: `unit, 2 unit, .., window - unit` (the databases to build).
    pub fn segment_lengths(&self) -> Vec<usize> {
        (1..self.window / self.unit).map(|n| n * self.unit).collect()
    }

    /// Every valid `(T_A, T_B, T_C)`.
    pub fn length_triples(&self) -> Vec<[usize; 3]> {
        let n = self.window / self.unit;
        let mut out = Vec::new();
        for a in 1..n {
            for c in 1..=(n - a) {
                out.push([a * self.unit, (n - a - c) * self.unit, c * self.unit]);
            }
        }
        out
    }

    /// Window starts of a clip of `frames` frames.
    pub fn window_starts(&self, frames: usize) -> impl Iterator<Item = usize> + '_ {
        (0..(frames + 1).saturating_sub(self.window)).step_by(self.window_step)
    }
}

/// A retrieved segment.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Retrieved {
    /// Clip index in the database's set.
    pub clip: usize,
    /// First frame.
    pub start: usize,
    /// Rank of the neighbour (k).
    pub k: usize,
    /// Squared feature distance to the ground truth's segment.
    pub distance: f32,
}

/// What one pair is made of: enough to rebuild it with [`build_pair`] (and small enough to
/// cache thousands of them as JSON).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairSpec {
    /// Ground-truth clip index.
    pub clip: usize,
    /// First frame of the window in that clip.
    pub start: usize,
    /// `[T_A, T_B, T_C]`.
    pub lengths: [usize; 3],
    /// Segment B (`None` when `T_B = 0`).
    pub b: Option<Retrieved>,
    /// Segment C.
    pub c: Retrieved,
}

/// A generated pair, both clips on the ground truth's skeleton, `T` frames, expressed in the
/// ground root of the window's first frame.
#[derive(Clone, Debug)]
pub struct StitchPair {
    /// The aligned input `X`.
    pub input: Clip,
    /// The ground truth `Y`.
    pub target: Clip,
    /// `[T_A, T_B, T_C]`.
    pub lengths: [usize; 3],
    /// First frame of each retrieved segment in the window (the seams).
    pub seams: Vec<usize>,
}

/// Plans one pair per ground-truth window: draws the lengths and `k`, searches the databases.
/// `gt` and `db_set` may be the same set (training pairs) or not (test cases from the
/// validation split searched in the training databases). Runs in parallel; the result does
/// not depend on the number of threads.
pub fn plan_pairs(
    gt: &MotionSet,
    db_set: &MotionSet,
    databases: &StitchDatabases,
    cfg: &PairConfig,
) -> Result<Vec<PairSpec>, StitchError> {
    cfg.validate()?;
    gt.check_compatible(db_set)?;
    for l in cfg.segment_lengths() {
        databases.get(l)?;
    }
    let windows: Vec<(usize, usize)> =
        (0..gt.clips.len()).flat_map(|c| cfg.window_starts(gt.frames(c)).map(move |s| (c, s))).collect();
    if windows.is_empty() {
        return Err(StitchError::TooShort { needed: cfg.window, longest: gt.longest() });
    }
    let triples = cfg.length_triples();
    windows
        .par_iter()
        .enumerate()
        .map(|(i, &(clip, start))| {
            let mut rng = SplitMix64::with_stream(cfg.seed, i as u64);
            let lengths = triples[rng.below(triples.len() as u64) as usize];
            let k_b = cfg.k_min + rng.below((cfg.k_max - cfg.k_min + 1) as u64) as usize;
            let k_c = cfg.k_min + rng.below((cfg.k_max - cfg.k_min + 1) as u64) as usize;
            let exclude = cfg.exclude_same_clip.then_some(clip);
            let b = if lengths[1] > 0 {
                Some(retrieve(gt, databases, clip, start + lengths[0], lengths[1], k_b, exclude)?)
            } else {
                None
            };
            let c = retrieve(gt, databases, clip, start + lengths[0] + lengths[1], lengths[2], k_c, exclude)?;
            Ok(PairSpec { clip, start, lengths, b, c })
        })
        .collect()
}

/// The k-th nearest database segment to frames `start..start + length` of ground-truth clip
/// `clip` (the farthest one found when fewer than `k` remain).
fn retrieve(
    gt: &MotionSet,
    databases: &StitchDatabases,
    clip: usize,
    start: usize,
    length: usize,
    k: usize,
    exclude: Option<usize>,
) -> Result<Retrieved, StitchError> {
    let db = databases.get(length)?;
    let mut query = vec![0.0f32; db.dim];
    gt.segment_feature(clip, start, length, &mut query);
    let found = db.nearest(&query, k, exclude);
    let n = found.last().ok_or_else(|| {
        StitchError::Config(format!(
            "the database of {length}-frame segments has no segment outside clip {} ({}); add clips to the training data",
            clip, gt.names[clip]
        ))
    })?;
    let s = db.segments[n.index];
    Ok(Retrieved { clip: s.clip as usize, start: s.start as usize, k: found.len(), distance: n.distance })
}

/// Builds the clips of a planned pair.
pub fn build_pair(
    spec: &PairSpec,
    gt: &MotionSet,
    db_set: &MotionSet,
    cfg: &PairConfig,
) -> Result<StitchPair, StitchError> {
    let t = cfg.window;
    let [ta, tb, tc] = spec.lengths;
    let spec_err = |m: String| StitchError::Spec(m);
    if ta + tb + tc != t || ta == 0 || tc == 0 || (tb > 0) != spec.b.is_some() {
        return Err(spec_err(format!(
            "lengths {:?} do not make a {t}-frame window with segments B {:?}",
            spec.lengths, spec.b
        )));
    }
    if spec.clip >= gt.clips.len() || spec.start + t > gt.frames(spec.clip) {
        return Err(spec_err(format!("window {}..{} of ground-truth clip {}", spec.start, spec.start + t, spec.clip)));
    }
    for (r, len) in spec.b.iter().map(|b| (b, tb)).chain([(&spec.c, tc)]) {
        if r.clip >= db_set.clips.len() || r.start + len > db_set.frames(r.clip) {
            return Err(spec_err(format!("segment {}..{} of database clip {}", r.start, r.start + len, r.clip)));
        }
    }
    let layout: &StitchLayout = &gt.layout;
    let j = gt.joints();
    let gt_clip = &gt.clips[spec.clip];
    let gt_roots = &gt.roots[spec.clip];
    let target = gt_clip.slice(spec.start, spec.start + t);
    let mut input = target.clone();
    let mut roots: Vec<GroundRoot> = gt_roots[spec.start..spec.start + t].to_vec();
    let w = cfg.upper_body_ground_truth;
    let segments = spec.b.iter().map(|b| (b, ta, tb)).chain([(&spec.c, ta + tb, tc)]);
    for (r, offset, len) in segments {
        let anchor = roots[offset - 1];
        let gt0 = gt_roots[spec.start + offset].inverse();
        let src = &db_set.clips[r.clip];
        for i in 0..len {
            let (f, g, s) = (offset + i, spec.start + offset + i, r.start + i);
            let root = anchor.compose(&gt0.compose(&gt_roots[g]));
            let src_root = db_set.roots[r.clip][s];
            let rel_rot = src_root.rotation().inverse() * src.local_rotations[s * j];
            let rel_pos = src_root.to_local(src.local_positions[s * j]);
            let (hr, hp) = root.apply(rel_rot, rel_pos);
            input.local_rotations[f * j] = hr;
            input.local_positions[f * j] = hp;
            for k in 1..j {
                let q = src.local_rotations[s * j + k];
                input.local_rotations[f * j + k] = if layout.is_lower(k) || w <= 0.0 {
                    q
                } else if w >= 1.0 {
                    target.local_rotations[f * j + k]
                } else {
                    slerp(q, target.local_rotations[f * j + k], w)
                };
                input.local_positions[f * j + k] = src.local_positions[s * j + k];
            }
            roots[f] = root;
        }
    }
    let origin = gt_roots[spec.start].inverse();
    let mut target = target;
    for clip in [&mut input, &mut target] {
        for f in 0..t {
            let (r, p) = origin.apply(clip.local_rotations[f * j], clip.local_positions[f * j]);
            clip.local_rotations[f * j] = r;
            clip.local_positions[f * j] = p;
        }
    }
    input.remove_sign_flips();
    let seams = if tb > 0 { vec![ta, ta + tb] } else { vec![ta] };
    Ok(StitchPair { input, target, lengths: spec.lengths, seams })
}

/// Plans and builds every pair (see [`plan_pairs`] and [`build_pair`]).
pub fn make_pairs(
    gt: &MotionSet,
    db_set: &MotionSet,
    databases: &StitchDatabases,
    cfg: &PairConfig,
) -> Result<Vec<StitchPair>, StitchError> {
    let specs = plan_pairs(gt, db_set, databases, cfg)?;
    specs.par_iter().map(|s| build_pair(s, gt, db_set, cfg)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_data::synth::{SynthConfig, generate};

    fn synth_set(minutes: f64, seed: u64) -> MotionSet {
        let cfg = SynthConfig { minutes, seed, clip_seconds: 6.0, ..SynthConfig::default() };
        let clips: Vec<Clip> = generate(&cfg).into_iter().map(|c| c.clip).collect();
        let layout = StitchLayout::bandai2(&clips[0].skeleton).unwrap();
        MotionSet::new(clips, vec![], layout).unwrap()
    }

    fn small_cfg() -> PairConfig {
        PairConfig { database_stride: 2, seed: 11, ..PairConfig::default() }
    }

    #[test]
    fn length_triples_are_all_valid_ones() {
        let cfg = PairConfig::default();
        let triples = cfg.length_triples();
        assert_eq!(triples.len(), 15); // a in 1..=5, c in 1..=6-a
        for [a, b, c] in &triples {
            assert_eq!(a + b + c, 60);
            assert!(*a > 0 && *c > 0 && a % 10 == 0 && b % 10 == 0 && c % 10 == 0);
        }
        assert!(triples.contains(&[10, 0, 50]) && triples.contains(&[50, 0, 10]) && triples.contains(&[10, 40, 10]));
        assert_eq!(cfg.segment_lengths(), vec![10, 20, 30, 40, 50]);
        assert_eq!(cfg.window_starts(150).collect::<Vec<_>>(), vec![0, 30, 60, 90]);
        let bad = PairConfig { window: 55, ..PairConfig::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("multiple of unit"));
        let bad = PairConfig { k_min: 6, k_max: 5, ..PairConfig::default() };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn pairs_follow_the_recipe() {
        let set = synth_set(1.0, 3);
        let cfg = small_cfg();
        let dbs = StitchDatabases::build(&set, &cfg.segment_lengths(), cfg.database_stride).unwrap();
        let specs = plan_pairs(&set, &set, &dbs, &cfg).unwrap();
        assert_eq!(specs.len(), 10 * 5); // 10 clips of 180 frames: starts 0, 30, .., 120
        assert_eq!(specs, plan_pairs(&set, &set, &dbs, &cfg).unwrap(), "seeded");
        let mut triples = std::collections::HashSet::new();
        let j = set.joints();
        let layout = &set.layout;
        for spec in &specs {
            triples.insert(spec.lengths);
            for r in spec.b.iter().chain([&spec.c]) {
                assert_ne!(r.clip, spec.clip, "the window's own clip is excluded");
                assert!((cfg.k_min..=cfg.k_max).contains(&r.k));
            }
            let pair = build_pair(spec, &set, &set, &cfg).unwrap();
            let [ta, tb, _] = spec.lengths;
            assert_eq!(pair.input.frames(), 60);
            let xr = super::super::layout::ground_roots(&pair.input, layout);
            let yr = super::super::layout::ground_roots(&pair.target, layout);
            // The window's first root is the identity; A is the ground truth.
            assert!(yr[0].pos.length() < 1e-9 && yr[0].yaw.abs() < 1e-9);
            for f in 0..ta * j {
                assert!(pair.input.local_rotations[f].dot(pair.target.local_rotations[f]).abs() > 1.0 - 1e-12);
                assert!((pair.input.local_positions[f] - pair.target.local_positions[f]).length() < 1e-9);
            }
            // Each retrieved segment starts on the previous segment's last root and follows
            // the ground truth's trajectory, relative to its own first frame.
            for &seam in &pair.seams {
                let d = xr[seam - 1].inverse().compose(&xr[seam]);
                assert!(d.pos.length() < 1e-6 && angle(d.yaw) < 1e-9, "seam {seam}: {d:?}");
                let end = pair.seams.iter().copied().find(|&s| s > seam).unwrap_or(60);
                for f in seam..end {
                    let dx = xr[seam].inverse().compose(&xr[f]);
                    let dy = yr[seam].inverse().compose(&yr[f]);
                    assert!((dx.pos - dy.pos).length() < 1e-6 && angle(dx.yaw - dy.yaw) < 1e-9);
                }
            }
            // Lower body from the retrieved segment, upper body from the ground truth.
            let r = spec.b.unwrap_or(spec.c);
            let src = &set.clips[r.clip];
            let f = ta;
            for k in 1..j {
                let x = pair.input.local_rotations[f * j + k];
                let want = if layout.is_lower(k) {
                    src.local_rotations[r.start * j + k]
                } else {
                    pair.target.local_rotations[f * j + k]
                };
                assert!(x.dot(want).abs() > 1.0 - 1e-12, "joint {k}");
            }
            // The hips keep their height of the retrieved segment.
            let hy = pair.input.local_positions[ta * j].y;
            assert!((hy - src.local_positions[r.start * j].y).abs() < 1e-9);
            let _ = tb;
        }
        assert!(triples.len() >= 12, "lengths drawn over the valid triples: {triples:?}");
    }

    fn angle(a: f64) -> f64 {
        let a = a.rem_euclid(std::f64::consts::TAU);
        a.min(std::f64::consts::TAU - a)
    }

    #[test]
    fn retrieval_is_the_kth_of_an_exhaustive_search() {
        let set = synth_set(0.6, 5);
        let cfg = small_cfg();
        let dbs = StitchDatabases::build(&set, &cfg.segment_lengths(), cfg.database_stride).unwrap();
        for spec in plan_pairs(&set, &set, &dbs, &cfg).unwrap().iter().take(8) {
            let length = spec.lengths[2];
            let db = dbs.get(length).unwrap();
            let mut q = vec![0.0f32; db.dim];
            set.segment_feature(spec.clip, spec.start + 60 - length, length, &mut q);
            let q = db.permute(&q);
            let all = super::super::knn::k_nearest_brute_force(&db.features, db.dim, &q, usize::MAX, |i| {
                db.segments[i].clip as usize == spec.clip
            });
            let want = db.segments[all[spec.c.k - 1].index];
            assert_eq!((want.clip as usize, want.start as usize), (spec.c.clip, spec.c.start));
            assert_eq!(all[spec.c.k - 1].distance, spec.c.distance);
        }
    }

    #[test]
    fn bad_input_is_refused_with_a_reason() {
        let set = synth_set(0.3, 1);
        let cfg = small_cfg();
        let dbs = StitchDatabases::build(&set, &[10, 20], 2).unwrap();
        let err = plan_pairs(&set, &set, &dbs, &cfg).unwrap_err().to_string();
        assert!(err.contains("length 30"), "{err}");
        let dbs = StitchDatabases::build(&set, &cfg.segment_lengths(), 2).unwrap();
        let long = PairConfig { window: 400, window_step: 200, ..cfg.clone() };
        let dbs_long = StitchDatabases::build(&set, &[10], 2);
        assert!(dbs_long.is_ok());
        let err = plan_pairs(&set, &set, &dbs, &long).unwrap_err().to_string();
        assert!(err.contains("no segment database") || err.contains("400"), "{err}");
        let mut spec = plan_pairs(&set, &set, &dbs, &cfg).unwrap()[0].clone();
        spec.c.clip = 99;
        assert!(build_pair(&spec, &set, &set, &cfg).unwrap_err().to_string().contains("database clip 99"));
        let mut other = set.clips.clone();
        for c in &mut other {
            c.frame_time = 1.0 / 60.0;
        }
        let other = MotionSet::new(other, vec![], set.layout.clone()).unwrap();
        assert!(plan_pairs(&other, &set, &dbs, &cfg).unwrap_err().to_string().contains("fps"));
    }
}
