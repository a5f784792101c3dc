//! Runs the runtime's synthesis task on an exported RNN-GMM for a while and prints a digest of
//! every pose, so that two runs (or two machines) can be compared bit for bit.
//!
//! ```sh
//! cargo run --release --example synthesis_run -- gmm.onnx [SECONDS=60] [CHARACTERS=1] [SEED=1]
//! ```
//!
//! Each character starts from the mean frame of the file's normalisation (standing where the
//! training data's average frame stands) with the zero generator state, is seeded with
//! `SEED + c`, and is stepped in one batch at temperature 1 (refined when the file embeds the
//! refiner). The digest is FNV-1a over the bits of every root position, root rotation, local
//! rotation and contact bit; the last root position shows how far each character walked.

use std::time::Instant;
use zoo_runtime::EnginePose;
use zoo_runtime::synthesis::SynthesisModel;

fn fnv(hash: &mut u64, bits: u32) {
    for b in bits.to_le_bytes() {
        *hash ^= b as u64;
        *hash = hash.wrapping_mul(0x100000001b3);
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        return Err("usage: synthesis_run FILE.onnx [SECONDS=60] [CHARACTERS=1] [SEED=1]".into());
    };
    let seconds: f64 = args.get(1).map_or(Ok(60.0), |s| s.parse())?;
    let n: usize = args.get(2).map_or(Ok(1), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(1), |s| s.parse())?;
    let model = SynthesisModel::load(path)?;
    let meta = model.model().metadata();
    let frames = (seconds * meta.fps as f64).round() as usize;
    let start = meta.normalization.get("x").map(|g| g.mean.clone()).ok_or("the file has no normalisation of `x`")?;
    let mut characters = Vec::with_capacity(n);
    for c in 0..n {
        let mut ch = model.new_character(seed + c as u64);
        ch.start(&model, &start, 0.0, 0.0, 0.0)?;
        characters.push(ch);
    }
    let mut runner = model.runner(n)?;
    let mut poses: Vec<EnginePose> = (0..n).map(|_| EnginePose::new(model.joints())).collect();
    let mut contacts = vec![[false; 2]; n];
    let mut hash = 0xcbf29ce484222325u64;
    let t = Instant::now();
    for _ in 0..frames {
        runner.step_batch(&mut characters, 1.0, &mut poses, &mut contacts)?;
        for (p, c) in poses.iter().zip(&contacts) {
            let values = p
                .root_position
                .to_array()
                .into_iter()
                .chain(p.root_rotation.to_array())
                .chain(p.local_rotations.iter().flat_map(|q| q.to_array()));
            for v in values {
                fnv(&mut hash, v.to_bits());
            }
            fnv(&mut hash, u32::from(c[0]) | (u32::from(c[1]) << 1));
        }
    }
    let elapsed = t.elapsed().as_secs_f64();
    println!(
        "{path}: {n} character(s) x {frames} frames ({seconds} s at {:.2} fps), seed {seed}, refiner: {}",
        meta.fps,
        if model.has_refiner() { "yes" } else { "no" }
    );
    for (c, p) in poses.iter().enumerate() {
        let r = p.root_position;
        println!("character {c}: last root position ({:.1}, {:.1}, {:.1})", r.x, r.y, r.z);
    }
    println!("digest {hash:016x}");
    println!("{:.3} ms per frame of the batch ({} thread)", 1e3 * elapsed / frames as f64, 1);
    Ok(())
}
