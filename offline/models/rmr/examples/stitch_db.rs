//! Builds the RMR segment databases (RMR sec. 4) for the training split of a dataset, prints
//! the build time, then plans the training pairs and prints how long the searches took.
//!
//! ```text
//! cargo build --workspace --examples
//! target/debug/examples/stitch_db [DATA] [VALID_GLOB] [STRIDE]
//! ```
//! Defaults: `../shared/data/bandai2`, `*_youthful_*` (the fixed bandai2 split), stride 1.

use rayon::prelude::*;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::dataset;
use zoo_rmr::pairs::{MotionSet, PairConfig, StitchDatabases, StitchLayout, build_pair, plan_pairs};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let data = PathBuf::from(args.next().unwrap_or_else(|| "../shared/data/bandai2".into()));
    let valid_glob = args.next().unwrap_or_else(|| "*_youthful_*".into());
    let stride: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    let threads = rayon::current_num_threads();

    let t0 = Instant::now();
    let (train, valid) = dataset::split(dataset::load(&data)?, &valid_glob)?;
    let load_s = t0.elapsed().as_secs_f64();
    let layout = StitchLayout::bandai2(&train[0].clip.skeleton)?;

    let t1 = Instant::now();
    let set = MotionSet::from_named(train, layout)?;
    let layout = set.layout.clone().with_planted_heights(set.global_positions.iter().map(Vec::as_slice), set.joints());
    let set = MotionSet { layout, ..set };
    let fk_s = t1.elapsed().as_secs_f64();

    // Forward axis check: the heading should point along the direction of travel.
    let (mut cos, mut n) = (0.0, 0usize);
    for roots in &set.roots {
        for w in roots.windows(11) {
            let d = w[10].pos - w[0].pos;
            if d.length() > 30.0 {
                cos += d.normalize().dot(w[5].forward());
                n += 1;
            }
        }
    }

    let cfg = PairConfig { database_stride: stride, ..PairConfig::default() };
    let t2 = Instant::now();
    let dbs = StitchDatabases::build(&set, &cfg.segment_lengths(), cfg.database_stride)?;
    let build_s = t2.elapsed().as_secs_f64();

    let t3 = Instant::now();
    let specs = plan_pairs(&set, &set, &dbs, &cfg)?;
    let plan_s = t3.elapsed().as_secs_f64();
    let mean_k: f64 = specs.iter().map(|s| s.c.k as f64).sum::<f64>() / specs.len() as f64;

    // What the seams look like: foot (ankle and toe) displacement across each seam in the input
    // X and in the ground truth Y, and the mean foot position gap between X and Y.
    let feet = set.layout.contacts;
    let (jx, jy, gap, n_seams) = specs
        .par_iter()
        .map(|spec| {
            let pair = build_pair(spec, &set, &set, &cfg).expect("planned pairs build");
            let ((_, gx), (_, gy)) = (pair.input.global(), pair.target.global());
            let j = pair.input.joints();
            let (mut jx, mut jy, mut gap) = (0.0, 0.0, 0.0);
            for &s in &pair.seams {
                for &f in &feet {
                    jx += (gx[s * j + f] - gx[(s - 1) * j + f]).length();
                    jy += (gy[s * j + f] - gy[(s - 1) * j + f]).length();
                }
            }
            for t in spec.lengths[0]..cfg.window {
                for &f in &feet {
                    gap += (gx[t * j + f] - gy[t * j + f]).length();
                }
            }
            let retrieved = (cfg.window - spec.lengths[0]) as f64;
            (jx, jy, gap / retrieved, pair.seams.len())
        })
        .reduce(|| (0.0, 0.0, 0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2, a.3 + b.3));
    let per_seam = |v: f64| v / (n_seams * feet.len()) as f64;

    println!(
        "data: {} ({} training clips, {} frames; {} validation clips)",
        data.display(),
        set.clips.len(),
        set.total_frames(),
        valid.len()
    );
    println!("threads: {threads}");
    println!("planted heights (heel L, toe L, heel R, toe R): {:.2?} cm", set.layout.planted);
    println!("heading vs direction of travel: mean cos {:.3} over {n} moving 10-frame spans", cos / n.max(1) as f64);
    println!("loading BVH: {load_s:.2} s; forward kinematics and roots: {fk_s:.2} s");
    for db in &dbs.databases {
        println!("  length {:>2}: {:>7} segments x {:>3} values", db.length, db.len(), db.dim);
    }
    println!(
        "databases for lengths {:?} (stride {}): {} segments, {:.0} MB, built in {build_s:.2} s",
        cfg.segment_lengths(),
        stride,
        dbs.total_segments(),
        dbs.feature_bytes() as f64 / 1e6
    );
    println!("planned {} training pairs (exact k-th neighbour searches) in {plan_s:.2} s", specs.len());
    println!("mean k of segment C: {mean_k:.2}");
    println!(
        "seams: {n_seams}; foot displacement across a seam: input {:.2} cm, ground truth {:.2} cm; \
         mean foot gap input-truth over B and C: {:.2} cm",
        per_seam(jx),
        per_seam(jy),
        gap / (specs.len() * feet.len()) as f64
    );
    Ok(())
}
