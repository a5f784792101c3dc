//! Times reading every `.bvh`/`.bvh.gz` file of a folder with [`zoo_data::bvh::read_file`]:
//! single-threaded, then in parallel with rayon.
//!
//! `cargo run --release -p zoo-data --example bvh_read_bench -- DATASET_DIR` (e.g. the bandai2 folder)
//!
//! Measured 2026-11-22 on the shared 2-core machine (load average ~10, so wall times are
//! inflated): all 962 bandai2 files (149,239 frames, 199 MB of text) take 1.24 s of CPU
//! single-threaded (3.2-3.6 s wall under that load); `zcat *.gz > /dev/null` takes 0.95-1.04 s
//! of CPU. Profile: gunzip ~30 %, number parsing (fast-float2) ~23 %, row loop ~15 %,
//! Euler -> quaternion ~13 %.

use rayon::prelude::*;
use std::path::PathBuf;
use std::time::Instant;
use zoo_data::bvh::{ReadOptions, read_file};

fn main() {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: bvh_read_bench DATASET_DIR (a folder of .bvh / .bvh.gz files, e.g. bandai2)");
        std::process::exit(2);
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{dir}: {e}"))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            let n = p.to_string_lossy();
            n.ends_with(".bvh") || n.ends_with(".bvh.gz")
        })
        .collect();
    files.sort();
    let opts = ReadOptions { drop_dummy_root: true };
    for round in 0..3 {
        let t = Instant::now();
        let frames: usize = files.iter().map(|p| read_file(p, &opts).unwrap().frames()).sum();
        let single = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let frames_par: usize = files.par_iter().map(|p| read_file(p, &opts).unwrap().frames()).sum();
        let par = t.elapsed().as_secs_f64();
        assert_eq!(frames, frames_par);
        println!(
            "round {round}: {} files, {frames} frames: single-threaded {single:.3} s, rayon ({} threads) {par:.3} s",
            files.len(),
            rayon::current_num_threads()
        );
    }
}
