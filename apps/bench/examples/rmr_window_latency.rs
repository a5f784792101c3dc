//! Latency of refining one window at batch 1 on one thread: the exported RMR on tract
//! (`zoo_runtime::StitchRefiner`) and on onnxruntime, side by side, with candle for reference.
//! The backends take turns round by round so that machine noise hits them alike; the figure
//! per backend is the median over rounds of the mean time per window.
//!
//! ```text
//! cargo build --workspace --examples
//! RAYON_NUM_THREADS=1 target/debug/examples/rmr_window_latency [RUN_DIR] [--window 60] [--rounds 11] [--reps 10] [--weights f32,f16,int8]
//! ```
//! Without `RUN_DIR`, the seeded paper-size model (BGRU 2 x 256) is used: latency does not
//! depend on the weights. onnxruntime: `ORT_DYLIB_PATH`, else `.onnxruntime/libonnxruntime.so.1.31.1`.
//! `--weights` lists the widths to measure (the file rewritten at each as `zoo export --weights`
//! writes it); each is timed on tract and on onnxruntime at that width, and compared with
//! onnxruntime's f32 too.
//!
//! Then the runtime's streaming form (`zoo_runtime::StitchStream`) over synthetic walking and
//! running (`--stream-frames`, default 600): its latency in frames, the median cost per frame
//! (push and pop, a window every `s` frames included) and of the pushes that run a window. The
//! heap allocations per window are counted by `cargo test --workspace --test runtime_alloc`.

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use std::borrow::Cow;
use std::path::PathBuf;
use std::time::Instant;
use zoo_rmr::features::FeatureStats;
use zoo_rmr::{Config, Rmr};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let opt = |k: &str| args.iter().position(|a| a == k).and_then(|i| args.get(i + 1)).map(|s| s.parse::<usize>());
    let window = opt("--window").transpose()?.unwrap_or(60);
    let rounds = opt("--rounds").transpose()?.unwrap_or(11);
    let reps = opt("--reps").transpose()?.unwrap_or(10);
    let run = args.first().filter(|a| !a.starts_with("--")).map(PathBuf::from);
    let (config, stats, varmap) = match &run {
        Some(dir) => {
            let (config, stats) = zoo_rmr::checkpoint::read_meta(dir)?;
            let varmap = VarMap::new();
            Rmr::new(&config, candle_nn::VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu))?;
            zoo_rmr::checkpoint::load_weights(dir, &varmap)?;
            (config, stats, varmap)
        }
        None => {
            let config = Config::paper();
            let d = config.dim();
            let varmap = VarMap::new();
            Rmr::new(&config, zoo_nn::SeededVarMap::builder(&varmap, 7, DType::F32, &Device::Cpu))?;
            (config, FeatureStats { mean: vec![0.0; d], std: vec![1.0; d] }, varmap)
        }
    };
    let model = Rmr::new(&config, candle_nn::VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu))?;
    let d = config.dim();
    let widths = args.iter().position(|a| a == "--weights").and_then(|i| args.get(i + 1));
    let widths = widths
        .map_or("f32", String::as_str)
        .split(',')
        .map(zoo_export::WeightWidth::parse)
        .collect::<Result<Vec<_>, _>>()?;
    let lib = std::env::var_os("ORT_DYLIB_PATH")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(".onnxruntime/libonnxruntime.so.1.31.1"));
    if !lib.is_file() {
        return Err(format!("onnxruntime library not found at {}: set ORT_DYLIB_PATH", lib.display()).into());
    }
    let env = ort::init_from(&lib)?.build()?;
    let f32_onnx = zoo_rmr::export::export_rmr(&config, &stats, &varmap)?;
    // Each width's tract refiner and onnxruntime session, onnxruntime's f32 one always (the
    // figure every width is compared with).
    let mut backends = Vec::new();
    for width in widths.iter().copied().chain([zoo_export::WeightWidth::F32]) {
        if backends.iter().any(|(w, _, _)| *w == width) {
            continue;
        }
        let bytes = zoo_export::with_weights(&f32_onnx, width)?.to_bytes();
        println!("weights: {width} ({} bytes)", bytes.len());
        let mut tract = zoo_runtime::StitchRefiner::from_bytes(&bytes)?;
        tract.set_window(window, window / 2)?;
        let session = ort::session::Session::builder(&env)?.with_intra_threads(1)?.commit_from_memory(&bytes)?;
        backends.push((width, tract, session));
    }
    let x: Vec<f32> = (0..window * d).map(|i| ((i * 7919 % 1000) as f32 / 500.0) - 1.0).collect();
    let mut y = vec![0.0f32; window * d];
    let xs = Tensor::from_slice(&x, (1, window, d), &Device::Cpu)?;
    let ort_once = |session: &mut ort::session::Session, x: &[f32]| -> Result<Vec<f32>, Box<dyn std::error::Error>> {
        let t = ort::value::Tensor::from_array((vec![window as i64, 1, d as i64], x.to_vec()))?;
        let inputs: Vec<(Cow<'_, str>, ort::session::SessionInputValue<'_>)> = vec![(Cow::Borrowed("x"), t.into())];
        let out = session.run(inputs)?;
        Ok(out["y"].try_extract_tensor::<f32>()?.1.to_vec())
    };
    let diff = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
    let c: Vec<f32> = model.forward(&xs, None)?.flatten_all()?.to_vec1()?;
    println!(
        "{} (dim {d}, {:?} x {}), window {window}, batch 1",
        run.as_ref().map_or("seeded paper-size RMR".to_string(), |p| p.display().to_string()),
        config.cell,
        config.hidden,
    );
    // Agreement first (time-major [window, 1, d] equals batch-first [1, window, d] at batch 1).
    for (width, tract, session) in &mut backends {
        tract.refine_window_normalized(&x, &mut y)?;
        let o = ort_once(session, &x)?;
        println!("{width}: max |diff| tract-ort {:e}, tract-candle f32 {:e}", diff(&y, &o), diff(&y, &c));
    }
    let mut times = vec![(Vec::new(), Vec::new()); backends.len()];
    let mut t_candle = Vec::new();
    for _ in 0..rounds {
        for ((_, tract, session), (t_tract, t_ort)) in backends.iter_mut().zip(times.iter_mut()) {
            let t0 = Instant::now();
            for _ in 0..reps {
                tract.refine_window_normalized(&x, &mut y)?;
            }
            t_tract.push(t0.elapsed().as_secs_f64() * 1e3 / reps as f64);
            let t0 = Instant::now();
            for _ in 0..reps {
                std::hint::black_box(ort_once(session, &x)?);
            }
            t_ort.push(t0.elapsed().as_secs_f64() * 1e3 / reps as f64);
        }
        let t0 = Instant::now();
        for _ in 0..reps {
            std::hint::black_box(model.forward(&xs, None)?);
        }
        t_candle.push(t0.elapsed().as_secs_f64() * 1e3 / reps as f64);
    }
    let medians: Vec<(f64, f64)> = times.into_iter().map(|(a, b)| (median(a), median(b))).collect();
    let ort_f32 =
        backends.iter().zip(&medians).find(|((w, _, _), _)| *w == zoo_export::WeightWidth::F32).map(|(_, m)| m.1);
    let ort_f32 = ort_f32.ok_or("no f32 session")?;
    println!("median ms per window over {rounds} rounds of {reps} (candle f32 {:.3}):", median(t_candle));
    println!("| weights | tract | onnxruntime | tract / onnxruntime | tract / onnxruntime f32 |");
    println!("| --- | --- | --- | --- | --- |");
    for ((width, _, _), (a, b)) in backends.iter().zip(&medians) {
        println!("| {width} | {a:.3} | {b:.3} | {:.2}x | {:.2}x |", a / b, a / ort_f32);
    }
    let tract = backends.swap_remove(0).1;
    stream(&tract, &config, opt("--stream-frames").transpose()?.unwrap_or(600), rounds)
}

/// The streaming form over synthetic walking and running on the model's skeleton.
fn stream(
    refiner: &zoo_runtime::StitchRefiner,
    config: &Config,
    frames: usize,
    rounds: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    use zoo_runtime::EnginePose;
    use zoo_runtime::glam::Quat;
    let synth = zoo_data::synth::SynthConfig { minutes: 1.0, seed: 3, clip_seconds: 10.0, ..Default::default() };
    let clips: Vec<zoo_motion::Clip> = zoo_data::synth::generate(&synth).into_iter().map(|c| c.clip).collect();
    config.check_skeleton(&clips[0].skeleton)?;
    let aligned = zoo_rmr::pairs::align_clips(&clips, &config.layout, 10)?.clip;
    if aligned.frames() < frames {
        return Err(format!("--stream-frames {frames}: the synthetic motion has {} frames", aligned.frames()).into());
    }
    let poses: Vec<EnginePose> = (0..frames)
        .map(|f| {
            let r: Vec<Quat> = aligned.rotations_at(f).iter().map(|q| q.as_quat()).collect();
            EnginePose::from_world(aligned.root_position(f).as_vec3(), &r)
        })
        .collect();
    let mut out = EnginePose::new(refiner.joints());
    let (mut per_frame, mut window_push) = (Vec::new(), Vec::new());
    let mut latency = 0;
    for _ in 0..rounds {
        let mut s = refiner.stream();
        latency = s.latency();
        let (mut windows, mut popped) = (0usize, 0usize);
        let (mut total, mut spikes) = (0.0f64, Vec::new());
        for p in &poses {
            let t0 = Instant::now();
            s.push(p)?;
            let ran =
                s.pushed() >= refiner.window() && (s.pushed() - refiner.window()).is_multiple_of(refiner.stride());
            while s.pop(&mut out)?.is_some() {
                popped += 1;
            }
            let dt = t0.elapsed().as_secs_f64() * 1e3;
            total += dt;
            if ran {
                windows += 1;
                spikes.push(dt);
            }
        }
        if windows == 0 {
            return Err("the motion is shorter than one window".into());
        }
        s.finish()?;
        while s.pop(&mut out)?.is_some() {
            popped += 1;
        }
        assert_eq!(popped, frames);
        per_frame.push(total / frames as f64);
        window_push.push(median(spikes));
    }
    println!(
        "stream: window {} stride {}, latency {latency} frames ({:.2} s at {} fps), {frames} frames per round",
        refiner.window(),
        refiner.stride(),
        latency as f64 / config.fps,
        config.fps
    );
    println!(
        "stream: median over {rounds} rounds: {:.3} ms per frame (push + pop, windows included), {:.3} ms for a push \
         that runs a window",
        median(per_frame),
        median(window_push)
    );
    Ok(())
}
