//! Times loading a BVH dataset and the same clips converted to glTF (`.glb`), in one run:
//! every clip is written as glb into a scratch folder, then both folders are loaded with
//! [`zoo_data::dataset::load_with`] (what `zoo train`, `zoo bench` and `zoo data stats` do)
//! in alternation, and with a single-threaded loop of [`zoo_data::clip_io::read_model_clip`].
//!
//! `cargo run --release -p zoo-data --example clip_read_bench -- DATASET_DIR [ROUNDS]`
//!
//! Issue 44's acceptance: the glb folder loads in at most 2x the BVH folder's time. The figures
//! are in docs/formats.md.

use std::path::PathBuf;
use std::time::Instant;
use zoo_data::clip_io;
use zoo_data::dataset::{self, LoadOptions};

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(dir) = args.next().map(PathBuf::from) else {
        eprintln!("usage: clip_read_bench DATASET_DIR [ROUNDS] (a folder of BVH clips, e.g. bandai2)");
        std::process::exit(2);
    };
    let rounds: usize = args.next().and_then(|r| r.parse().ok()).unwrap_or(5);
    let files = dataset::find_clip_files(&dir).unwrap_or_else(|e| panic!("{e}"));
    let scratch = tempfile::tempdir().expect("a scratch folder");
    let t = Instant::now();
    let mut bytes = (0u64, 0u64);
    for f in &files {
        let clip = zoo_data::bvh::read_file(f, &Default::default()).unwrap_or_else(|e| panic!("{e}"));
        let stem = f.file_name().unwrap().to_string_lossy().replace(".bvh.gz", "").replace(".bvh", "");
        let glb = scratch.path().join(format!("{stem}.glb"));
        clip_io::write(&clip, &glb).unwrap_or_else(|e| panic!("{e}"));
        bytes.0 += std::fs::metadata(f).map(|m| m.len()).unwrap_or(0);
        bytes.1 += std::fs::metadata(&glb).map(|m| m.len()).unwrap_or(0);
    }
    println!(
        "converted {} clips to glb in {:.2} s ({:.1} MB of BVH files, {:.1} MB of glb)",
        files.len(),
        t.elapsed().as_secs_f64(),
        bytes.0 as f64 / 1e6,
        bytes.1 as f64 / 1e6
    );
    let (mut bvh, mut glb, mut bvh1, mut glb1) = (vec![], vec![], vec![], vec![]);
    let opts = LoadOptions::default();
    for round in 0..rounds {
        let t = Instant::now();
        let a = dataset::load_with(&dir, &opts).unwrap_or_else(|e| panic!("{e}"));
        bvh.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let b = dataset::load_with(scratch.path(), &opts).unwrap_or_else(|e| panic!("{e}"));
        glb.push(t.elapsed().as_secs_f64());
        assert_eq!(a.clips.len(), b.clips.len());
        let frames: usize = a.clips.iter().map(|c| c.clip.frames()).sum();
        let t = Instant::now();
        for f in &files {
            clip_io::read_model_clip(f).unwrap();
        }
        bvh1.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for c in &b.clips {
            clip_io::read_model_clip(&c.path).unwrap();
        }
        glb1.push(t.elapsed().as_secs_f64());
        println!(
            "round {round}: {} clips, {frames} frames: load_with BVH {:.3} s, glb {:.3} s; one thread BVH {:.3} s, glb {:.3} s",
            a.clips.len(),
            bvh[round],
            glb[round],
            bvh1[round],
            glb1[round]
        );
    }
    let (b, g, b1, g1) = (median(&mut bvh), median(&mut glb), median(&mut bvh1), median(&mut glb1));
    println!(
        "median of {rounds}: load_with BVH {b:.3} s, glb {g:.3} s (glb/BVH {:.2}x); one thread BVH {b1:.3} s, glb {g1:.3} s ({:.2}x)",
        g / b,
        g1 / b1
    );
}
