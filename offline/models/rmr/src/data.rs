//! From clips to encoded training pairs (RMR sec. 4 via [`pairs`]).
//!
//! Training pairs come from the training clips' windows with B and C retrieved from the
//! training clips' databases (never from the window's own clip); validation pairs come from
//! the validation clips' windows with B and C retrieved from the same training databases. The
//! planted heights of the contact joints are measured on the training clips, and the
//! normalisation statistics on the generated training pairs (inputs and ground truths).

use crate::config::Config;
use crate::error::RmrResult;
use crate::features::{FeatureLayout, FeatureStats, PairFeatures, encode_clip};
use crate::pairs::{MotionSet, PairConfig, PairPlan, PairSpec, StitchDatabases, build_pair, plan_pairs};
use rayon::prelude::*;
use std::time::Instant;
use zoo_motion::Clip;

/// Encoded pairs ready for training, with what made them.
#[derive(Clone, Debug)]
pub struct RmrData {
    /// The configuration with the measured planted heights in its layout.
    pub config: Config,
    /// Normalisation statistics (from the training pairs).
    pub stats: FeatureStats,
    /// Normalised training pairs.
    pub train: PairFeatures,
    /// Normalised validation pairs.
    pub valid: PairFeatures,
    /// Plans of the training pairs (cacheable).
    pub train_specs: Vec<PairSpec>,
    /// Plans of the validation pairs.
    pub valid_specs: Vec<PairSpec>,
    /// Segments in the databases (0 when every plan came from the cache).
    pub database_segments: usize,
    /// Seconds spent building the databases (0 when every plan came from the cache).
    pub database_seconds: f64,
}

/// [`make_pairs_from_sets`] on unnamed clips.
pub fn make_pairs(config: &Config, train: Vec<Clip>, valid: Vec<Clip>) -> RmrResult<RmrData> {
    for c in train.iter().chain(&valid) {
        config.check_skeleton(&c.skeleton)?;
    }
    let layout = config.layout.clone();
    let train = MotionSet::new(train, vec![], layout.clone())?;
    let valid = MotionSet::new(valid, vec![], layout)?;
    make_pairs_from_sets(config, train, valid)
}

/// Builds the databases on `train`, plans and encodes the training and validation pairs, and
/// fits the statistics.
pub fn make_pairs_from_sets(config: &Config, train: MotionSet, valid: MotionSet) -> RmrResult<RmrData> {
    make_pairs_cached(config, train, valid, None)
}

/// Training plan file in a cache folder.
pub const TRAIN_PLAN_FILE: &str = "pairs_train.json";
/// Validation plan file in a cache folder.
pub const VALID_PLAN_FILE: &str = "pairs_valid.json";

/// [`make_pairs_from_sets`], reusing the planned pairs saved in `cache` ([`TRAIN_PLAN_FILE`],
/// [`VALID_PLAN_FILE`]) when they were made from the same clips and configuration, and saving
/// them there otherwise (the databases are then built only when a plan is missing).
pub fn make_pairs_cached(
    config: &Config,
    train: MotionSet,
    valid: MotionSet,
    cache: Option<&std::path::Path>,
) -> RmrResult<RmrData> {
    config.validate()?;
    config.check_skeleton(&train.clips[0].skeleton)?;
    train.check_compatible(&valid)?;
    let layout =
        train.layout.clone().with_planted_heights(train.global_positions.iter().map(Vec::as_slice), train.joints());
    let mut config = config.clone();
    config.layout = layout.clone();
    config.fps = train.fps;
    let train = MotionSet { layout: layout.clone(), ..train };
    let valid = MotionSet { layout, ..valid };

    let pc = &config.pairs;
    let train_cfg = PairConfig { exclude_same_clip: true, ..pc.clone() };
    let valid_cfg = PairConfig { exclude_same_clip: false, seed: pc.seed ^ 0x7a11d, ..pc.clone() };
    let mut dbs: Option<StitchDatabases> = None;
    let mut database_seconds = 0.0;
    let mut plan = |gt: &MotionSet, cfg: &PairConfig, file: &str| -> RmrResult<Vec<PairSpec>> {
        let mut run = || {
            if dbs.is_none() {
                let t0 = Instant::now();
                dbs = Some(StitchDatabases::build(&train, &pc.segment_lengths(), pc.database_stride)?);
                database_seconds = t0.elapsed().as_secs_f64();
            }
            plan_pairs(gt, &train, dbs.as_ref().expect("built above"), cfg)
        };
        Ok(match cache {
            Some(dir) => PairPlan::load_or_plan(&dir.join(file), cfg, gt, &train, run)?.0,
            None => run()?,
        })
    };
    let train_specs = plan(&train, &train_cfg, TRAIN_PLAN_FILE)?;
    let valid_specs = plan(&valid, &valid_cfg, VALID_PLAN_FILE)?;
    let database_segments = dbs.as_ref().map_or(0, StitchDatabases::total_segments);
    // A model trained on inertialized seams ([`Config::pre_blend`]) sees its inputs so blended.
    let blend = config.pre_blend.then_some(config.blend_frames);
    let train_raw = encode_specs(&train_specs, &train, &train, &train_cfg, blend)?;
    let valid_raw = encode_specs(&valid_specs, &valid, &train, &valid_cfg, blend)?;
    let fl = FeatureLayout::new(config.joints, config.layout.lower_body.len());
    let stats = FeatureStats::fit((0..train_raw.count).flat_map(|i| [train_raw.input(i), train_raw.target(i)]), fl);
    Ok(RmrData {
        train: train_raw.normalized(&stats)?,
        valid: valid_raw.normalized(&stats)?,
        config,
        stats,
        train_specs,
        valid_specs,
        database_segments,
        database_seconds,
    })
}

/// Builds and encodes planned pairs (in parallel; the clips of each pair are dropped once
/// encoded); `pre_blend`: the inputs inertialized at their seams over that many frames first.
pub fn encode_specs(
    specs: &[PairSpec],
    gt: &MotionSet,
    db_set: &MotionSet,
    cfg: &PairConfig,
    pre_blend: Option<usize>,
) -> RmrResult<PairFeatures> {
    let seams_of = |s: &PairSpec| {
        let [a, b, _] = s.lengths;
        if b > 0 { vec![a, a + b] } else { vec![a] }
    };
    let encoded: Vec<(Vec<f32>, Vec<f32>)> = specs
        .par_iter()
        .map(|s| {
            let pair = build_pair(s, gt, db_set, cfg)?;
            let input = match pre_blend {
                Some(blend) => crate::pairs::baselines::inertialize_seams(&pair.input, &seams_of(s), blend),
                None => pair.input,
            };
            Ok((encode_clip(&input, &gt.layout)?, encode_clip(&pair.target, &gt.layout)?))
        })
        .collect::<RmrResult<_>>()?;
    let dim = FeatureLayout::new(gt.joints(), gt.layout.lower_body.len()).dim();
    let seams = specs.iter().map(seams_of).collect();
    let mut out = PairFeatures { count: specs.len(), frames: cfg.window, dim, inputs: vec![], targets: vec![], seams };
    out.inputs.reserve(specs.len() * cfg.window * dim);
    out.targets.reserve(specs.len() * cfg.window * dim);
    for (x, y) in encoded {
        out.inputs.extend(x);
        out.targets.extend(y);
    }
    Ok(out)
}
