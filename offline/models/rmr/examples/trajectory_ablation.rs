//! RMR Figure 9 on bandai2: how far the refined root drifts from the input's path over a long
//! stitched sequence, for models trained with and without the root trajectory loss.
//!
//! Stitches `--clips N` (default 6) validation clips, each cut to frames 20..110, into one
//! sequence (540 frames), refines it with every `--model DIR` (runtime windows of each model's
//! configuration) and prints, per model, the horizontal distance between the refined ground root
//! and the aligned input's at every 30th frame, its mean and its maximum; `--png FILE` plots the
//! distance over frames (one line per model in the order given: blue, orange, green, red).
//!
//! ```text
//! cargo run --release -p zoo-rmr --example trajectory_ablation -- --data ../shared/data/bandai2 \
//!     --valid-glob '*_youthful_*' --model runs/rmr-with --model runs/rmr-without --png docs/rmr-trajectory.png
//! ```

use std::path::{Path, PathBuf};
use zoo_rmr::pairs::ground_roots;
use zoo_rmr::stitch::{RefineOptions, stitch_clips};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let get = |k: &str| args.iter().position(|a| a == k).and_then(|i| args.get(i + 1)).cloned();
    let data = PathBuf::from(get("--data").ok_or("--data DIR is required")?);
    let glob = get("--valid-glob").unwrap_or_else(|| "*_youthful_*".into());
    let n: usize = get("--clips").map(|s| s.parse()).transpose()?.unwrap_or(6);
    let models: Vec<PathBuf> = args
        .iter()
        .enumerate()
        .filter(|(_, a)| *a == "--model")
        .filter_map(|(i, _)| args.get(i + 1))
        .map(PathBuf::from)
        .collect();
    if models.is_empty() {
        return Err("give at least one --model DIR".into());
    }
    let mut clips = zoo_data::dataset::load_matching(&data, Some(&glob))?;
    clips.sort_by(|a, b| a.name.cmp(&b.name));
    // Every content in turn (walk, run, turns), spread over the styles' takes.
    let step = (clips.len() / n.max(1)).max(1);
    let picked: Vec<_> = clips.iter().step_by(step).take(n).filter(|c| c.clip.frames() >= 110).collect();
    let cut: Vec<_> = picked.iter().map(|c| c.clip.slice(20, 110)).collect();
    println!("{} clips: {}", cut.len(), picked.iter().map(|c| c.name.as_str()).collect::<Vec<_>>().join(", "));
    let palette = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40)];
    let mut series: Vec<Vec<f64>> = Vec::new();
    for dir in &models {
        let (model, stats) = zoo_rmr::checkpoint::load(dir, &candle_core::Device::Cpu)?;
        let layout = model.config().layout.clone();
        let out = stitch_clips(&model, &stats, &cut, RefineOptions::of(model.config()))?;
        let (a, b) = (ground_roots(&out.input, &layout), ground_roots(&out.output, &layout));
        let d: Vec<f64> = a.iter().zip(&b).map(|(p, q)| (p.pos - q.pos).length()).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let max = d.iter().copied().fold(0.0, f64::max);
        let every: Vec<String> = d.iter().step_by(30).map(|v| format!("{v:.1}")).collect();
        println!(
            "{}: {} frames, root distance to the input mean {mean:.2} cm, max {max:.2} cm; every 30th frame: {}",
            dir.display(),
            d.len(),
            every.join(" ")
        );
        series.push(d);
    }
    if let Some(png) = get("--png") {
        let s: Vec<(&[f64], (u8, u8, u8))> =
            series.iter().zip(palette.iter().cycle()).map(|(v, c)| (v.as_slice(), *c)).collect();
        zoo_nn::plot::lines(Path::new(&png), &s, 10.0)?;
        println!("plot: {png} (grey lines every 10 cm)");
    }
    Ok(())
}
