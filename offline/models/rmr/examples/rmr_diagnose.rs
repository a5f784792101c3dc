//! Identity checks of the RMR pipeline on the stitching benchmark's cases, and trained models
//! beside the baselines (a quick, smaller `zoo bench stitch` for diagnosis).
//!
//! Rows: `gt->enc->dec` (the ground truth encoded and decoded: must be ~0 against itself),
//! `identity` (the aligned input through the whole refinement path with a refiner that returns
//! its window: must score like `concat`), `concat`, `inertialize`, and each `--model DIR`.
//!
//! ```text
//! cargo build --workspace --examples
//! target/debug/examples/rmr_diagnose                                   # synthetic locomotion
//! target/debug/examples/rmr_diagnose --data ../shared/data/bandai2 --valid-glob '*_youthful_*' \
//!     --max-test 20 --model runs/rmr-bandai2
//! ```

use std::path::PathBuf;
use zoo_data::metrics::npss;
use zoo_motion::Clip;
use zoo_motion::glam::{DQuat, DVec3};
use zoo_rmr::features::{FeatureLayout, FeatureStats, decode, encode_clip};
use zoo_rmr::footlock::place_ankles;
use zoo_rmr::pairs::baselines::inertialize_seams;
use zoo_rmr::pairs::eval::{StitchMeasures, hemisphere};
use zoo_rmr::pairs::{MotionSet, PairConfig, StitchDatabases, StitchLayout, build_pair, ground_roots, plan_pairs};
use zoo_rmr::stitch::{RefineOptions, refine_clip_full, refine_clip_full_with};

#[derive(Default)]
struct Acc {
    n: usize,
    l2p: f64,
    slide: f64,
    slide_n: usize,
    root: f64,
    pops: Vec<f64>,
    rot: Vec<DQuat>,
    gt_rot: Vec<DQuat>,
}

// Kept whole: a diagnostic script whose steps print in the order they run, read top to bottom
// beside its output; split, each piece would take the same model, data and statistics.
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let get = |k: &str| args.iter().position(|a| a == k).map(|i| args[i + 1].clone());
    let models: Vec<PathBuf> =
        args.iter().enumerate().filter(|(_, a)| *a == "--model").map(|(i, _)| PathBuf::from(&args[i + 1])).collect();
    let max_test: usize = get("--max-test").map(|s| s.parse()).transpose()?.unwrap_or(usize::MAX);
    let (train, test): (Vec<Clip>, Vec<Clip>) = match get("--data") {
        Some(d) => {
            let ds = zoo_data::dataset::load_with(std::path::Path::new(&d), &Default::default())?;
            let (tr, te) = zoo_data::dataset::split(ds.clips, &get("--valid-glob").unwrap_or("*_youthful_*".into()))?;
            (tr.into_iter().map(|c| c.clip).collect(), te.into_iter().map(|c| c.clip).collect())
        }
        None => {
            let cfg = zoo_data::synth::SynthConfig { minutes: 4.0, seed: 3, ..Default::default() };
            let clips: Vec<Clip> = zoo_data::synth::generate(&cfg).into_iter().map(|c| c.clip).collect();
            let n = clips.len();
            let (tr, te): (Vec<_>, Vec<_>) = clips.into_iter().enumerate().partition(|(i, _)| i % 10 != 9);
            println!("synthetic: {n} clips");
            (tr.into_iter().map(|x| x.1).collect(), te.into_iter().map(|x| x.1).collect())
        }
    };
    let test: Vec<Clip> = test.into_iter().take(max_test).collect();
    let layout = StitchLayout::bandai2(&train[0].skeleton)?;
    let train_set = MotionSet::new(train, vec![], layout)?;
    let layout = train_set
        .layout
        .clone()
        .with_planted_heights(train_set.global_positions.iter().map(Vec::as_slice), train_set.joints());
    let train_set = MotionSet { layout: layout.clone(), ..train_set };
    let test_set = MotionSet::new(test, vec![], layout.clone())?;
    let cfg = PairConfig { exclude_same_clip: false, seed: 12, ..PairConfig::default() };
    let measures = StitchMeasures::fit(&train_set, cfg.window, cfg.window_step);
    let dbs = StitchDatabases::build(&train_set, &cfg.segment_lengths(), cfg.database_stride)?;
    let specs = plan_pairs(&test_set, &train_set, &dbs, &cfg)?;
    drop(dbs);
    let pairs = specs.iter().map(|s| build_pair(s, &test_set, &train_set, &cfg)).collect::<Result<Vec<_>, _>>()?;
    println!("{} cases, {} seams", pairs.len(), pairs.iter().map(|p| p.seams.len()).sum::<usize>());
    let j = train_set.joints();
    let fl = FeatureLayout::new(j, layout.lower_body.len());
    let unit = FeatureStats { mean: vec![0.0; fl.dim()], std: vec![1.0; fl.dim()] };
    let opts = RefineOptions { window: 60, stride: 30, blend_frames: 10 };

    let mut loaded = Vec::new();
    for m in &models {
        let (model, stats) = zoo_rmr::checkpoint::load(m, &candle_core::Device::Cpu)?;
        loaded.push((m.display().to_string(), model, stats));
    }
    let mut names = vec!["ground truth".to_string(), "gt->enc->dec".into(), "identity".into(), "identity+ik".into()];
    names.push("concat".into());
    names.push("inertialize".into());
    names.extend(loaded.iter().flat_map(|(n, ..)| [n.clone(), format!("{n} +ik")]));
    let mut accs: Vec<Acc> = names.iter().map(|_| Acc::default()).collect();
    for p in &pairs {
        let gt = p.target.global();
        let mut outs: Vec<Clip> = Vec::new();
        outs.push(p.target.clone());
        let y = encode_clip(&p.target, &layout)?;
        outs.push(decode(&y, &p.target.skeleton, &layout, p.target.frame_time, ground_roots(&p.target, &layout)[0])?.0);
        let id = refine_clip_full_with(|w| Ok(w.to_vec()), &layout, &unit, &p.input, opts)?;
        outs.push(id.clip.clone());
        let mut placed = id.clip;
        place_ankles(&mut placed, &id.ankles, &layout);
        outs.push(placed);
        outs.push(p.input.clone());
        outs.push(inertialize_seams(&p.input, &p.seams, 10));
        for (_, model, stats) in &loaded {
            let r = refine_clip_full(model, stats, &p.input, opts)?;
            outs.push(r.clip.clone());
            let mut placed = r.clip;
            place_ankles(&mut placed, &r.ankles, &layout);
            outs.push(placed);
        }
        for (acc, out) in accs.iter_mut().zip(&outs) {
            let (gr, gp) = out.global();
            let (s, n) = measures.foot_sliding(&gp, j);
            acc.slide += s;
            acc.slide_n += n;
            acc.root += measures.root_deviation(out, &p.input);
            acc.pops.extend(measures.pops(&gp, j, &p.seams));
            acc.l2p += measures.pose_errors((&gr, &gp), (&gt.0, &gt.1), j).0;
            acc.rot.extend(hemisphere(&gr, &gt.0));
            acc.gt_rot.extend_from_slice(&gt.0);
            acc.n += 1;
        }
    }
    println!("{:<40} {:>8} {:>8} {:>9} {:>9} {:>7}", "method", "L2P", "NPSS", "sliding", "root dev", "pops");
    for (name, a) in names.iter().zip(&accs) {
        let n = a.n.max(1) as f64;
        println!(
            "{:<40} {:>8.4} {:>8.4} {:>9.4} {:>9.3} {:>7.3}",
            name,
            a.l2p / n,
            npss(&a.rot, &a.gt_rot, a.n, cfg.window, j),
            a.slide / a.slide_n.max(1) as f64,
            a.root / n,
            a.pops.iter().sum::<f64>() / a.pops.len().max(1) as f64,
        );
    }
    let _ = DVec3::ZERO;
    Ok(())
}
