//! The stitching benchmark (`zoo bench stitch`, protocol in docs/rmr.md).
//!
//! - Cases with a ground truth: the section-4 generator ([`crate::pairs::plan_pairs`]) on the
//!   windows of the test split, B and C retrieved from the training split's databases, fixed
//!   seed: every method stitches the same aligned inputs and is compared with the same ground
//!   truth.
//! - Free cases: two and three different test clips cut at random points, aligned end to start
//!   (no ground truth).
//! - Measures ([`crate::pairs::eval`]): L2P, L2Q, NPSS against the ground truth; RMR's foot
//!   sliding; the benchmark's foot skate (the ground truth's beside it); root trajectory
//!   deviation from the input; pops (largest joint speed within 5 frames of a seam over the
//!   training data's 99th percentile); wall time per stitched second.

use crate::error::RmrResult;
use crate::pairs::baselines::{inertialize_seams, interpolate_seams};
use crate::pairs::eval::{StitchMeasures, hemisphere};
use crate::pairs::{
    MIN_CLIP_FRAMES, MotionSet, PairConfig, StitchDatabases, StitchLayout, align_clips, build_pair, plan_pairs,
};
use crate::stitch::{PostProcess, RefineOptions, refine_seams};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::benchmark::{N_PAST, TransitionMethod, TransitionTask};
use zoo_data::dataset::NamedClip;
use zoo_data::metrics::npss;
use zoo_data::{Context, Message, Progress, bail};
use zoo_motion::Clip;
use zoo_motion::glam::{DQuat, DVec3};
use zoo_motion::rng::SplitMix64;

/// A trained RMR with its post-processing (ankle IK, seam guard, foot lock, pre-blend), as a
/// method of the benchmark: [`CandleRmr`] here, the engine runtime's refiner in the commands'
/// crate (`zoo-tasks`), which the benchmark runs by default.
pub trait SeamRefiner {
    /// Stitches an aligned sequence with seams at `seams`; `blend` frames of blend after each
    /// window, of the pre-blend and of the guard's inertialized reference. A sequence shorter
    /// than the model's window is refined as one window.
    fn stitch(&self, aligned: &Clip, seams: &[usize], blend: usize) -> Result<Clip, Message>;
    /// Refuses clips on another skeleton than the model's, naming the first joint that differs.
    fn check_skeleton(&self, skeleton: &zoo_motion::Skeleton) -> Result<(), Message>;
    /// Drops the model's fallback towards the refiner's input (`--no-fallback`).
    fn drop_fallback(&mut self);
    /// Windows refined, the fraction of them the fallback acted on and its mean weight, so far;
    /// `None` without a fallback.
    fn fallback_summary(&self) -> Option<(u64, f64, f64)>;
}

/// The candle RMR of a run folder with its post-processing (`candle-rmr...:RUN_DIR`).
pub struct CandleRmr {
    model: crate::Rmr,
    stats: crate::features::FeatureStats,
    post: PostProcess,
}

impl CandleRmr {
    /// The RMR of the run folder `dir`, followed (and preceded) by `post`.
    pub fn load(dir: &std::path::Path, post: PostProcess) -> Result<CandleRmr, Message> {
        let kind = zoo_nn::checkpoint::model_kind(dir).map_err(|e| Message(e.to_string()))?;
        if kind != "rmr" {
            bail!("{} holds a `{kind}` model, not an RMR (`zoo train rmr`)", dir.display());
        }
        let (model, stats) = crate::checkpoint::load(dir, &candle_core::Device::Cpu)
            .with_context(|| format!("loading the RMR in {}", dir.display()))?;
        Ok(CandleRmr { model, stats, post })
    }
}

impl SeamRefiner for CandleRmr {
    fn stitch(&self, aligned: &Clip, seams: &[usize], blend: usize) -> Result<Clip, Message> {
        let c = self.model.config();
        let frames = aligned.frames();
        let (window, stride) = if c.window <= frames { (c.window, c.stride) } else { (frames, frames) };
        let opts = RefineOptions { window, stride, blend_frames: blend };
        Ok(refine_seams(&self.model, &self.stats, aligned, seams, opts, self.post)
            .map_err(|e| Message(e.to_string()))?
            .clip)
    }

    fn check_skeleton(&self, skeleton: &zoo_motion::Skeleton) -> Result<(), Message> {
        self.model.config().check_skeleton(skeleton).map_err(|e| Message(e.to_string()))
    }

    fn drop_fallback(&mut self) {
        self.model.set_fallback(None);
    }

    fn fallback_summary(&self) -> Option<(u64, f64, f64)> {
        self.model.fallback_summary()
    }
}

/// A method of the benchmark (`--methods`).
pub enum StitchMethod {
    /// `concat`: the aligned concatenation.
    Concat,
    /// `inertialize`: inertialization at each seam.
    Inertialize,
    /// `interp`: interpolation across each seam.
    Interp,
    /// `rmr...:RUN_DIR` (the exported model through the engine runtime, what `zoo stitch` and
    /// engines run) or `candle-rmr...:RUN_DIR` (the training model in candle, for parity
    /// checks): a trained RMR and its post-processing.
    Rmr {
        /// The spec, the method's name.
        name: String,
        /// The refiner with its post-processing.
        refiner: Box<dyn SeamRefiner>,
    },
    /// A transition model of the in-betweening benchmark (`rtn:DIR`, `rtn+lock:DIR`) across
    /// each seam.
    Transition {
        /// The spec, the method's name.
        name: String,
        /// The loaded method.
        method: Box<dyn TransitionMethod>,
    },
}

impl StitchMethod {
    /// Parses and loads a `--methods` entry; `transition` loads the in-betweening methods
    /// (`rtn:DIR`, `rtn+lock:DIR`) from their spec, `runtime` the engine runtime's refiner of
    /// `rmr...:PATH` (a run folder or its exported file) with its post-processing.
    pub fn parse(
        spec: &str,
        transition: impl FnOnce(&str) -> Result<Box<dyn TransitionMethod>, Message>,
        runtime: impl FnOnce(&std::path::Path, PostProcess) -> Result<Box<dyn SeamRefiner>, Message>,
    ) -> RmrResult<StitchMethod> {
        match spec {
            "concat" => return Ok(StitchMethod::Concat),
            "inertialize" => return Ok(StitchMethod::Inertialize),
            "interp" => return Ok(StitchMethod::Interp),
            _ => {}
        }
        let forms = "concat, inertialize, interp, rmr:RUN, rmr+ik:RUN, rmr+lock:RUN, \
                     rmr+ik+lock:RUN (each also as inert+rmr..., with +guard after rmr or rmr+ik, as in \
                     rmr+ik+guard+lock:RUN, with +reach at the end, and as candle-rmr... for the training model in candle), \
                     rtn:RUN_DIR, \
                     rtn+lock:RUN_DIR";
        let Some((head, path)) = spec.split_once(':') else { bail!("unknown method `{spec}`: expected {forms}") };
        // `candle-...`: the training model in candle instead of the exported one in the runtime.
        let (candle, head) = match head.strip_prefix("candle-") {
            Some(rest) => (true, rest),
            None => (false, head),
        };
        // `inert+rmr...`: the seams inertialized before the RMR refines (`zoo stitch --pre-blend`).
        let (pre_blend, head) = match head.strip_prefix("inert+") {
            Some(rest) if rest.starts_with("rmr") => (true, rest),
            _ => (false, head),
        };
        // `rmr+guard...`, `rmr+ik+guard+lock`: the seam guard after the ankle IK, before the lock.
        let seam_guard = head.starts_with("rmr") && head.contains("+guard");
        let head = if seam_guard { head.replacen("+guard", "", 1) } else { head.to_string() };
        // `...+reach`: the clips kept as they are a window away from every seam (`zoo stitch`'s default).
        // `...+reachN`: that reach in frames.
        let (keep_untouched, reach, head) = match head.rsplit_once("+reach") {
            Some((rest, n)) if rest.starts_with("rmr") && (n.is_empty() || n.parse::<usize>().is_ok_and(|n| n > 0)) => {
                (true, n.parse::<usize>().ok(), rest.to_string())
            }
            _ => (false, None, head),
        };
        let head = head.as_str();
        let (lock, ik) = match head {
            "rmr" => (false, false),
            "rmr+ik" => (false, true),
            "rmr+lock" => (true, false),
            // What `zoo stitch` writes by default: ankles by IK, then the foot lock.
            "rmr+ik+lock" => (true, true),
            "rtn" | "rtn+lock" if !candle => {
                return Ok(StitchMethod::Transition { name: spec.to_string(), method: transition(spec)? });
            }
            _ => bail!("unknown method `{spec}`: expected {forms} (other kinds do not stitch)"),
        };
        let dir = PathBuf::from(path);
        let post = PostProcess { ankle_ik: ik, foot_lock: lock, pre_blend, seam_guard, keep_untouched, reach };
        let refiner: Box<dyn SeamRefiner> = if candle {
            Box::new(CandleRmr::load(&dir, post).with_context(|| format!("method `{spec}`"))?)
        } else {
            runtime(&dir, post).with_context(|| format!("method `{spec}`"))?
        };
        Ok(StitchMethod::Rmr { name: spec.to_string(), refiner })
    }

    /// The method's name in the tables: its spec.
    pub fn name(&self) -> String {
        match self {
            StitchMethod::Concat => "concat".into(),
            StitchMethod::Inertialize => "inertialize".into(),
            StitchMethod::Interp => "interp".into(),
            StitchMethod::Rmr { name, .. } | StitchMethod::Transition { name, .. } => name.clone(),
        }
    }

    /// Stitches an aligned sequence with seams at `seams`.
    pub fn apply(&self, aligned: &Clip, seams: &[usize], blend: usize) -> RmrResult<Clip> {
        Ok(match self {
            StitchMethod::Concat => aligned.clone(),
            StitchMethod::Inertialize => inertialize_seams(aligned, seams, blend),
            StitchMethod::Interp => interpolate_seams(aligned, seams, blend),
            StitchMethod::Rmr { refiner, .. } => refiner.stitch(aligned, seams, blend)?,
            StitchMethod::Transition { method, .. } => transition_seams(method.as_ref(), aligned, seams, blend)?,
        })
    }
}

/// In-betweening across each seam `s`: the `2h` frames `s - h .. s + h` (`h = max(blend / 2,
/// 1)`) are generated by `method` from the 10 frames before them (the first frame repeated
/// where the sequence starts too early) to the frame `s + h` and the one after it.
fn transition_seams(method: &dyn TransitionMethod, aligned: &Clip, seams: &[usize], blend: usize) -> RmrResult<Clip> {
    let mut out = aligned.clone();
    let (frames, j) = (out.frames(), out.joints());
    let h = (blend / 2).max(1);
    let offsets: Vec<DVec3> = aligned.local_positions[1..j].to_vec();
    for &s in seams {
        let (first, target) = (s.saturating_sub(h), s + h);
        if first == 0 || target + 1 >= frames {
            continue;
        }
        let past: Vec<usize> = (0..N_PAST).map(|k| (first + k).saturating_sub(N_PAST)).collect();
        let rot = |f: usize| out.local_rotations[f * j..(f + 1) * j].to_vec();
        let past_rot: Vec<DQuat> = past.iter().flat_map(|&f| rot(f)).collect();
        let past_root: Vec<DVec3> = past.iter().map(|&f| out.local_positions[f * j]).collect();
        let target_rot: Vec<DQuat> = [target, target + 1].iter().flat_map(|&f| rot(f)).collect();
        let target_root = [out.local_positions[target * j], out.local_positions[(target + 1) * j]];
        let task = TransitionTask {
            skeleton: &aligned.skeleton,
            offsets: &offsets,
            past_rot: &past_rot,
            past_root: &past_root,
            target_rot: &target_rot,
            target_root: &target_root,
            frames: target - first,
        };
        let t = method.generate(&[task]).map_err(Message)?.remove(0);
        for k in 0..target - first {
            let f = first + k;
            out.local_positions[f * j] = t.root[k];
            out.local_rotations[f * j..(f + 1) * j].copy_from_slice(&t.rot[k * j..(k + 1) * j]);
        }
    }
    out.remove_sign_flips();
    Ok(out)
}

/// Sums of one method's measures over a set of cases.
#[derive(Default)]
struct Acc {
    cases: usize,
    l2p: f64,
    l2q: f64,
    slide: f64,
    slide_n: usize,
    skate: f64,
    root: f64,
    pops: Vec<f64>,
    seconds: f64,
    stitched_seconds: f64,
    rot: Vec<DQuat>,
    gt_rot: Vec<DQuat>,
}

/// One row of the table.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StitchRow {
    /// Cases measured.
    pub cases: usize,
    /// L2P against the ground truth (normalised global positions).
    pub l2p: Option<f64>,
    /// L2Q against the ground truth (global quaternions).
    pub l2q: Option<f64>,
    /// NPSS against the ground truth (global quaternions).
    pub npss: Option<f64>,
    /// RMR's foot sliding: mean horizontal displacement of a heel or toe per frame while it is
    /// within 2 cm of its planted height (clip units per frame).
    pub foot_sliding: f64,
    /// The benchmark's foot skate (clip units per frame).
    pub skate: f64,
    /// Mean horizontal distance of the ground root from the input's (clip units).
    pub root_deviation: f64,
    /// Mean over seams of the largest joint speed within 5 frames of the seam / the training
    /// data's 99th percentile of joint speeds.
    pub pops_mean: f64,
    /// Fraction of seams whose largest joint speed exceeds the 99th percentile.
    pub pops_over_p99: f64,
    /// Milliseconds of the method per stitched second of motion.
    pub ms_per_second: f64,
}

impl Acc {
    fn row(&self, with_gt: bool) -> StitchRow {
        let n = self.cases.max(1) as f64;
        StitchRow {
            cases: self.cases,
            l2p: with_gt.then_some(self.l2p / n),
            l2q: with_gt.then_some(self.l2q / n),
            npss: None,
            foot_sliding: self.slide / self.slide_n.max(1) as f64,
            skate: self.skate / n,
            root_deviation: self.root / n,
            pops_mean: self.pops.iter().sum::<f64>() / self.pops.len().max(1) as f64,
            pops_over_p99: self.pops.iter().filter(|&&p| p > 1.0).count() as f64 / self.pops.len().max(1) as f64,
            ms_per_second: 1000.0 * self.seconds / self.stitched_seconds.max(1e-12),
        }
    }
}

/// What the benchmark reports.
#[derive(Clone, Debug, Serialize)]
pub struct StitchBenchResult {
    /// Cases with a ground truth (section-4 pairs of the test split).
    pub cases: usize,
    /// Seams in those cases.
    pub seams: usize,
    /// Free cases (two- and three-clip).
    pub free_cases: usize,
    /// Frames per case with a ground truth.
    pub frames: usize,
    /// 99th percentile of joint speeds in the training data (clip units per frame).
    pub speed_p99: f64,
    /// Planted heights of heel L, toe L, heel R, toe R (clip units).
    pub planted: [f64; 4],
    /// The ground truth's own measures (the floor of foot sliding and skate).
    pub ground_truth: StitchRow,
    /// Per method, on the cases with a ground truth.
    pub methods: BTreeMap<String, StitchRow>,
    /// Per method, on the free cases.
    pub free: BTreeMap<String, StitchRow>,
    /// Test clips, training clips.
    pub clips: (usize, usize),
    /// Seconds for the whole benchmark.
    pub seconds: f64,
}

/// Free cases: `count` sequences of `n` different clips of `set`, each cut to a random range of
/// 30 to 90 frames (or the whole clip when shorter), aligned end to start.
fn free_cases(set: &MotionSet, n: usize, count: usize, seed: u64) -> RmrResult<Vec<(Clip, Vec<usize>)>> {
    let mut rng = SplitMix64::with_stream(seed, n as u64);
    let usable: Vec<usize> = (0..set.clips.len()).filter(|&c| set.frames(c) >= MIN_CLIP_FRAMES).collect();
    if usable.len() < n {
        return Ok(Vec::new());
    }
    (0..count)
        .map(|_| {
            let mut picked: Vec<usize> = Vec::new();
            while picked.len() < n {
                let c = usable[rng.below(usable.len() as u64) as usize];
                if !picked.contains(&c) {
                    picked.push(c);
                }
            }
            let parts: Vec<Clip> = picked
                .iter()
                .map(|&c| {
                    let frames = set.frames(c);
                    let len = (30 + rng.below(61) as usize).min(frames);
                    let start = rng.below((frames - len + 1) as u64) as usize;
                    set.clips[c].slice(start, start + len)
                })
                .collect();
            let a = align_clips(&parts, &set.layout, MIN_CLIP_FRAMES)?;
            Ok((a.clip, a.starts[1..].to_vec()))
        })
        .collect()
}

/// Measures one stitched case into `acc`.
fn measure(
    acc: &mut Acc,
    m: &StitchMeasures,
    out: &Clip,
    input: &Clip,
    seams: &[usize],
    gt: Option<&(Vec<DQuat>, Vec<DVec3>)>,
    seconds: f64,
) {
    let j = out.joints();
    let (gr, gp) = out.global();
    let (s, n) = m.foot_sliding(&gp, j);
    acc.slide += s;
    acc.slide_n += n;
    acc.skate += m.skate(&gp, j);
    acc.root += m.root_deviation(out, input);
    acc.pops.extend(m.pops(&gp, j, seams));
    acc.seconds += seconds;
    acc.stitched_seconds += out.frames() as f64 * out.frame_time;
    if let Some((gt_r, gt_p)) = gt {
        let (l2p, l2q) = m.pose_errors((&gr, &gp), (gt_r, gt_p), j);
        acc.l2p += l2p;
        acc.l2q += l2q;
        acc.rot.extend(hemisphere(&gr, gt_r));
        acc.gt_rot.extend_from_slice(gt_r);
    }
    acc.cases += 1;
}

/// The benchmark's settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StitchBenchOptions {
    /// Frames of the blend at each seam (inertialize, interp) and after each RMR window.
    pub blend_frames: usize,
    /// Free cases of each kind (two clips, three clips).
    pub free_cases: usize,
    /// Seed of the test cases (segment lengths, neighbour ranks, free cuts).
    pub seed: u64,
    /// Database segments start every this many frames (1: every segment, exact search).
    pub database_stride: usize,
}

/// The test cases every method stitches.
struct Cases {
    measures: StitchMeasures,
    /// Cases with a ground truth, and the ground truth's global rotations and positions.
    pairs: Vec<crate::pairs::StitchPair>,
    gts: Vec<(Vec<DQuat>, Vec<DVec3>)>,
    /// Free cases: the aligned clips and their seams.
    free: Vec<(Clip, Vec<usize>)>,
    /// Frames per case with a ground truth.
    frames: usize,
}

/// The training split's statistics and databases, and the test cases planned on them.
fn cases(train: Vec<NamedClip>, test: Vec<NamedClip>, o: &StitchBenchOptions, p: &dyn Progress) -> RmrResult<Cases> {
    let (n_train, n_test) = (train.len(), test.len());
    p.stage("forward kinematics, planted heights, statistics");
    let skeleton = &train[0].clip.skeleton;
    let layout = StitchLayout::bandai2(skeleton).context("the dataset's skeleton lacks a joint stitching reads")?;
    let train_set = MotionSet::from_named(train, layout)?;
    let layout = train_set
        .layout
        .clone()
        .with_planted_heights(train_set.global_positions.iter().map(Vec::as_slice), train_set.joints());
    let train_set = MotionSet { layout: layout.clone(), ..train_set };
    let test_set = MotionSet::from_named(test, layout)?;
    train_set.check_compatible(&test_set)?;
    let cfg = PairConfig {
        exclude_same_clip: false,
        seed: o.seed,
        database_stride: o.database_stride,
        ..PairConfig::default()
    };
    let measures = StitchMeasures::fit(&train_set, cfg.window, cfg.window_step);
    p.stage(&format!("segment databases of the {n_train} training clips"));
    let dbs = StitchDatabases::build(&train_set, &cfg.segment_lengths(), cfg.database_stride)?;
    p.stage(&format!("planning the test cases of {n_test} clips (exact KNN)"));
    let specs = plan_pairs(&test_set, &train_set, &dbs, &cfg)?;
    drop(dbs);
    let pairs = specs.iter().map(|s| build_pair(s, &test_set, &train_set, &cfg)).collect::<Result<Vec<_>, _>>()?;
    let gts = pairs.iter().map(|p| p.target.global()).collect();
    let mut free = Vec::new();
    for n in [2, 3] {
        free.extend(free_cases(&test_set, n, o.free_cases, o.seed)?);
    }
    Ok(Cases { measures, pairs, gts, free, frames: cfg.window })
}

/// Runs the benchmark on the training and test clips with `methods`; `data` names the dataset
/// in messages.
pub fn run(
    train: Vec<NamedClip>,
    test: Vec<NamedClip>,
    data: &std::path::Path,
    methods: &[StitchMethod],
    o: &StitchBenchOptions,
    p: &dyn Progress,
) -> RmrResult<StitchBenchResult> {
    let start = Instant::now();
    let skeleton = train.first().context("no training clips: the training split is empty")?.clip.skeleton.clone();
    for m in methods {
        if let StitchMethod::Rmr { name, refiner } = m {
            refiner
                .check_skeleton(&skeleton)
                .with_context(|| format!("method `{name}` and the clips of {}", data.display()))?;
        }
    }
    let clips = (test.len(), train.len());
    let c = cases(train, test, o, p)?;
    p.finish();
    let mut gt_acc = Acc::default();
    for (pair, gt) in c.pairs.iter().zip(&c.gts) {
        measure(&mut gt_acc, &c.measures, &pair.target, &pair.target, &pair.seams, Some(gt), 0.0);
    }
    p.start((methods.len() * (c.pairs.len() + c.free.len())) as u64, "stitching");
    let (mut rows, mut free_rows) = (BTreeMap::new(), BTreeMap::new());
    for m in methods {
        p.note(&m.name());
        let (row, free) = method_rows(m, &c, skeleton.len(), o.blend_frames, p)?;
        rows.insert(m.name(), row);
        free_rows.insert(m.name(), free);
    }
    p.finish();
    Ok(StitchBenchResult {
        cases: c.pairs.len(),
        seams: c.pairs.iter().map(|p| p.seams.len()).sum(),
        free_cases: c.free.len(),
        frames: c.frames,
        speed_p99: c.measures.speed_p99,
        planted: c.measures.layout.planted,
        ground_truth: gt_acc.row(false),
        methods: rows,
        free: free_rows,
        clips,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// One method's rows: on the cases with a ground truth and on the free cases.
fn method_rows(
    m: &StitchMethod,
    c: &Cases,
    joints: usize,
    blend: usize,
    p: &dyn Progress,
) -> RmrResult<(StitchRow, StitchRow)> {
    let mut acc = Acc::default();
    for (pair, gt) in c.pairs.iter().zip(&c.gts) {
        let t0 = Instant::now();
        let out = m.apply(&pair.input, &pair.seams, blend)?;
        let dt = t0.elapsed().as_secs_f64();
        measure(&mut acc, &c.measures, &out, &pair.input, &pair.seams, Some(gt), dt);
        p.advance(1);
    }
    let mut row = acc.row(true);
    row.npss = (acc.cases > 0).then(|| npss(&acc.rot, &acc.gt_rot, acc.cases, c.frames, joints));
    let mut facc = Acc::default();
    for (clip, seams) in &c.free {
        let t0 = Instant::now();
        let out = m.apply(clip, seams, blend)?;
        let dt = t0.elapsed().as_secs_f64();
        measure(&mut facc, &c.measures, &out, clip, seams, None, dt);
        p.advance(1);
    }
    Ok((row, facc.row(false)))
}

impl StitchBenchResult {
    /// The summary line after the table.
    pub fn summary(&self) -> String {
        format!(
            "{} test clips, {} training clips; {} cases with ground truth ({} seams, {} frames each), {} free cases; \
             {:.1} s",
            self.clips.0, self.clips.1, self.cases, self.seams, self.frames, self.free_cases, self.seconds
        )
    }
}

/// The result as a text table.
pub fn table(r: &StitchBenchResult) -> String {
    let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
    let mut s = format!(
        "cases with ground truth ({} cases, {} seams)\n{:<28} {:>8} {:>8} {:>8} {:>9} {:>8} {:>9} {:>7} {:>7} {:>9}\n",
        r.cases, r.seams, "method", "L2P", "L2Q", "NPSS", "sliding", "skate", "root dev", "pops", ">p99", "ms/s"
    );
    let line = |name: &str, row: &StitchRow| {
        format!(
            "{:<28} {:>8} {:>8} {:>8} {:>9.4} {:>8.4} {:>9.3} {:>7.3} {:>7.3} {:>9.3}\n",
            name,
            opt(row.l2p),
            opt(row.l2q),
            opt(row.npss),
            row.foot_sliding,
            row.skate,
            row.root_deviation,
            row.pops_mean,
            row.pops_over_p99,
            row.ms_per_second
        )
    };
    s += &line("ground truth", &r.ground_truth);
    for (name, row) in &r.methods {
        s += &line(name, row);
    }
    s += &format!("\nfree cases (two and three clips, no ground truth: {} cases)\n", r.free_cases);
    for (name, row) in &r.free {
        s += &line(name, row);
    }
    s
}
