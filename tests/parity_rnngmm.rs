//! Parity of the exported RNN-GMM generator step: candle (`zoo-rnngmm`), tract (through
//! `zoo-runtime`'s `MotionRunner`) and onnxruntime (through `ort`, `load-dynamic`) run the same
//! frames for a batch of characters, each carrying its LSTM state from step to step.
//!
//! Where the expected numbers come from: candle's `Generator::step` from the zero state and
//! `Generator::mixture` (eq. 7: softmax weights, means, `exp` of the clamped log stds). The
//! generator is `Config::tiny` with its seeded initial weights, on the feature of the synthetic
//! skeleton; the inputs are fixed LCG draws of 1.5 normalised units. Every pair must agree within
//! 1e-4 on every output of every step.
//!
//! onnxruntime: `bash scripts/onnxruntime.sh` (or `ORT_DYLIB_PATH`); a missing library fails.

use candle_core::{Device, Tensor};
use zoo_data::synth::{SynthConfig, generate_clip};
use zoo_motion::Clip;
use zoo_rnngmm::export::{MODEL_KIND, export_generator};
use zoo_rnngmm::prelude::*;
use zoo_runtime::metadata::keys;
use zoo_runtime::{MotionModel, MotionState};
use zoo_tests::onnxruntime::OrtSession;
use zoo_tests::toy_onnx::lcg;

const BATCH: usize = 3;
const STEPS: usize = 12;
const TOLERANCE: f32 = 1e-4;

/// `[step] -> (weights, means, stds)`, each character-major.
type Trace = Vec<[Vec<f32>; 3]>;

fn fixture() -> (Config, GeneratorTrainer) {
    let cfg = SynthConfig { minutes: 0.2, seed: 3, terrain: false, fps: 30.0, clip_seconds: 6.0 };
    let clips: Vec<Clip> = (0..2).map(|i| generate_clip(&cfg, i).clip).collect();
    let refs: Vec<&Clip> = clips.iter().collect();
    let config = Config::tiny();
    let data = TrainingData::from_clips(&config, 30.0, &refs[..1], &refs[1..]).unwrap();
    let config = config.with_dim(data.spec.dim());
    let trainer = GeneratorTrainer::new(&config, data.spec.clone(), data.norm.clone(), &Device::Cpu).unwrap();
    (config, trainer)
}

fn inputs(d: usize) -> Vec<Vec<f32>> {
    (0..STEPS).map(|s| lcg(77 + s as u64, BATCH * d, 1.5)).collect()
}

fn candle_trace(config: &Config, g: &Generator, xs: &[Vec<f32>]) -> Trace {
    let mut state = g.zero_state(BATCH).unwrap();
    let flat = |t: Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    xs.iter()
        .map(|x| {
            let (raw, next) =
                g.step(&Tensor::from_slice(x, (BATCH, config.dim), &Device::Cpu).unwrap(), &state).unwrap();
            state = next;
            let mix = g.mixture(&raw).unwrap();
            [flat(mix.log_weights.exp().unwrap()), flat(mix.means), flat(mix.log_stds.exp().unwrap())]
        })
        .collect()
}

fn tract_trace(onnx: &[u8], config: &Config, xs: &[Vec<f32>]) -> Trace {
    let model = MotionModel::from_bytes(onnx).expect("zoo-runtime loads the exported generator");
    let names: Vec<&str> = model.outputs().iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["weights", "means", "stds"]);
    let mut runner = model.runner().unwrap();
    let mut states: Vec<MotionState> = (0..BATCH).map(|_| model.new_state()).collect();
    let (m, d) = (config.components, config.dim);
    xs.iter()
        .map(|x| {
            let (mut w, mut mu, mut sd) = (vec![0.0; BATCH * m], vec![0.0; BATCH * m * d], vec![0.0; BATCH * m * d]);
            runner.step_batch(&mut states, &[x], &mut [&mut w, &mut mu, &mut sd]).unwrap();
            [w, mu, sd]
        })
        .collect()
}

fn ort_trace(onnx: &zoo_export::OnnxModel, config: &Config, xs: &[Vec<f32>]) -> Trace {
    let mut session = OrtSession::new(onnx);
    let layers = config.lstm_layers;
    let state_names: Vec<String> = (0..layers).flat_map(|k| [format!("h{k}"), format!("c{k}")]).collect();
    let mut state: Vec<Vec<f32>> = vec![vec![0.0; BATCH * config.lstm]; 2 * layers];
    let mut outs = vec!["weights".to_string(), "means".to_string(), "stds".to_string()];
    outs.extend(state_names.iter().map(|s| format!("{s}_next")));
    let out_refs: Vec<&str> = outs.iter().map(String::as_str).collect();
    xs.iter()
        .map(|x| {
            let mut feed: Vec<(&str, usize, &[f32])> = vec![("x", BATCH, x)];
            feed.extend(state_names.iter().zip(&state).map(|(n, s)| (n.as_str(), BATCH, s.as_slice())));
            let mut values = session.run(&feed, &out_refs);
            state = values.split_off(3);
            let [w, mu, sd]: [Vec<f32>; 3] = values.try_into().unwrap();
            [w, mu, sd]
        })
        .collect()
}

fn worst(a: &Trace, b: &Trace) -> f32 {
    let mut worst = 0f32;
    for (sa, sb) in a.iter().zip(b) {
        for (va, vb) in sa.iter().zip(sb) {
            assert_eq!(va.len(), vb.len());
            for (x, y) in va.iter().zip(vb) {
                assert!(x.is_finite() && y.is_finite());
                worst = worst.max((x - y).abs());
            }
        }
    }
    worst
}

#[test]
fn the_exported_generator_step_matches_candle_in_tract_and_onnxruntime() {
    let (config, trainer) = fixture();
    let onnx = export_generator(&config, None, trainer.spec(), trainer.norm(), trainer.varmap()).unwrap();
    assert_eq!(onnx.metadata_value(keys::MODEL_KIND), Some(MODEL_KIND));
    assert_eq!(onnx.metadata_value(keys::TASK), Some("step"));
    let xs = inputs(config.dim);
    let candle = candle_trace(&config, trainer.model(), &xs);
    // The mixture weights of each character sum to 1 and the states carry over (later steps differ).
    for w in candle[0][0].chunks(config.components) {
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    }
    let tract = tract_trace(&onnx.to_bytes(), &config, &xs);
    let ort = ort_trace(&onnx, &config, &xs);
    let (ct, co, to) = (worst(&candle, &tract), worst(&candle, &ort), worst(&tract, &ort));
    println!(
        "largest difference over {STEPS} steps of {BATCH} characters: candle/tract {ct:.2e}, candle/onnxruntime {co:.2e}, tract/onnxruntime {to:.2e}"
    );
    assert!(
        ct <= TOLERANCE && co <= TOLERANCE && to <= TOLERANCE,
        "candle/tract {ct}, candle/ort {co}, tract/ort {to}"
    );
    // Parameters: every weight of the generator plus the two log-std bounds.
    assert_eq!(onnx.summary().parameters, trainer.model().parameter_count() + 2);
}

#[test]
fn a_generator_export_refuses_mismatched_statistics() {
    let (config, trainer) = fixture();
    let mut norm = trainer.norm().clone();
    norm.mean.pop();
    let err = export_generator(&config, None, trainer.spec(), &norm, trainer.varmap()).unwrap_err().to_string();
    assert!(err.contains("statistics"), "{err}");
}
