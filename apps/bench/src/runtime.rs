//! A step's latency (batch 1) and throughput (batch 64) through candle, tract (`zoo-runtime`)
//! and onnxruntime, side by side in one run (`zoo bench runtime --model FILE.onnx`): an
//! exported RTN through all three; an exported RNN-GMM's generator step through tract and
//! onnxruntime and the runtime's whole synthesis frame (`tract frame`).
//!
//! All three run the same step (`x`, `offset`, LSTM state in; `x_next`, state out) with the
//! same weights: candle's are read back from the file's initializers. Each backend runs on one
//! thread (candle inside a one-thread rayon pool, onnxruntime with one intra-op thread; tract is
//! single-threaded), and the backends take turns round by round so that machine noise hits
//! them alike. The figure per backend is the median over rounds of the mean step time.

use crate::{Result, msg};
use candle_core::{Device, Tensor};
use serde::Serialize;
use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::time::Instant;
use zoo_data::{Context, Progress, bail};
use zoo_export::WeightWidth;
use zoo_rtn::{Rtn, RtnInputs, RtnState};
use zoo_runtime::{LoadedModel, MotionModel, MotionState, MotionTaskKind};

/// The benchmark's settings (also those of [`crate::keyframes`]).
#[derive(Clone, Debug)]
pub struct RuntimeOptions {
    /// A file written by `zoo export --onnx`.
    pub model: PathBuf,
    /// Batch sizes to measure (characters per step).
    pub batch: Vec<usize>,
    /// Rounds per batch size (each backend runs once per round).
    pub rounds: usize,
    /// Character-steps per backend per round (steps = this / batch, at least 5).
    pub work: usize,
    /// The onnxruntime library (`None`: `ORT_DYLIB_PATH`, else `.onnxruntime/` of the current
    /// folder or one of its parents).
    pub onnxruntime: Option<PathBuf>,
    /// The weight widths to measure tract and onnxruntime at (`zoo bench runtime`; the file's
    /// own width when empty): the file's f32 weights rewritten at each
    /// (`zoo_export::with_weights`, what `zoo export --weights` writes).
    pub widths: Vec<WeightWidth>,
}

/// Figures of one backend at one batch size.
#[derive(Clone, Debug, Serialize)]
pub struct BackendFigure {
    /// `candle`, `tract` or `onnxruntime` (`zoo bench keyframes`: `tract step`, `onnxruntime
    /// step`, `tract completion`).
    pub backend: String,
    /// Batch size.
    pub batch: usize,
    /// Median over rounds of the mean time of one step of the whole batch, milliseconds.
    pub step_ms: f64,
    /// Character-frames per second at that median.
    pub frames_per_second: f64,
    /// Every round's mean step time, milliseconds.
    pub rounds_ms: Vec<f64>,
    /// Multiply-adds per second at that median, billions (0 when not counted).
    pub gmacs: f64,
    /// `gmacs` as a fraction of this core's peak for the backend's arithmetic (f32 FMA, or
    /// 8-bit dot products for int8), when measured.
    pub of_peak: Option<f64>,
}

/// What one step costs and what the core can do: the roofline of `zoo bench runtime`.
#[derive(Clone, Debug, Serialize)]
pub struct Roofline {
    /// Multiply-adds of the graph's matrix products per character and step.
    pub macs_per_character: u64,
    /// Bytes of the weight matrices per width measured, as the files store them.
    pub weight_bytes: Vec<(String, u64)>,
    /// f32 multiply-adds per second of one core, billions: 8-lane FMA loops on registers.
    pub f32_peak_gmacs: Option<f64>,
    /// 8-bit multiply-adds per second of one core, billions: AVX-512 VNNI's `vpdpbusd` on 256
    /// bits where the CPU has it, else AVX2's `vpmaddwd` (16-bit pairs).
    pub int8_peak_gmacs: Option<f64>,
    /// Which instruction `int8_peak_gmacs` was measured with.
    pub int8_peak_with: &'static str,
}

/// A backend under test: one step of the whole batch per call.
pub(crate) trait StepBackend {
    fn name(&self) -> &str;
    fn step(&mut self) -> Result<()>;
    /// The frame output of the last step (for the agreement check; empty: not compared).
    fn output(&self) -> &[f32];
}

/// The whole synthesis frame of an RNN-GMM file through the runtime's task
/// (`zoo_runtime::synthesis::SynthesisRunner`: the generator step, sampling, the refiner step when the
/// file has one, decoding into poses with global positions).
struct SynthesisBackend {
    runner: zoo_runtime::synthesis::SynthesisRunner,
    characters: Vec<zoo_runtime::synthesis::SynthesisCharacter>,
    poses: Vec<zoo_runtime::EnginePose>,
    contacts: Vec<[bool; 2]>,
}

impl SynthesisBackend {
    fn new(bytes: &[u8], batch: usize) -> Result<Self> {
        let model = zoo_runtime::synthesis::SynthesisModel::from_bytes(bytes)?;
        let meta = model.model().metadata();
        let start = meta
            .normalization
            .get("x")
            .map(|n| n.mean.clone())
            .ok_or_else(|| msg!("the synthesis model has no normalisation of `x`"))?;
        let mut characters = Vec::with_capacity(batch);
        for c in 0..batch {
            let mut ch = model.new_character(c as u64 + 1);
            ch.start(&model, &start, 0.0, 0.0, 0.0)?;
            characters.push(ch);
        }
        Ok(SynthesisBackend {
            runner: model.runner(batch)?,
            characters,
            poses: (0..batch).map(|_| zoo_runtime::EnginePose::with_global_positions(model.joints())).collect(),
            contacts: vec![[false; 2]; batch],
        })
    }
}

impl StepBackend for SynthesisBackend {
    fn name(&self) -> &'static str {
        "tract frame"
    }

    fn step(&mut self) -> Result<()> {
        self.runner.step_batch(&mut self.characters, 1.0, &mut self.poses, &mut self.contacts)?;
        Ok(())
    }

    fn output(&self) -> &[f32] {
        &[]
    }
}

/// Deterministic inputs in [-1, 1) (normalized units).
fn inputs(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = zoo_motion::rng::SplitMix64::new(seed);
    (0..n).map(|_| (2.0 * rng.next_f64() - 1.0) as f32).collect()
}

/// The frame inputs of the step graph, by name.
pub(crate) struct Frame {
    pub(crate) names: Vec<String>,
    pub(crate) data: Vec<Vec<f32>>,
}

struct CandleBackend {
    model: Rtn,
    sequence: zoo_rtn::RtnSequence,
    x: Tensor,
    offset: Option<Tensor>,
    /// The step graph's `terrain`, `base` and `tta` inputs, for the models that take them.
    terrain: Option<Tensor>,
    base: Option<Tensor>,
    tta: Option<Tensor>,
    state: RtnState,
    out: Vec<f32>,
    pool: rayon::ThreadPool,
}

impl StepBackend for CandleBackend {
    fn name(&self) -> &'static str {
        "candle"
    }

    fn step(&mut self) -> Result<()> {
        let (model, sequence, x, offset, state) = (&self.model, &self.sequence, &self.x, &self.offset, &self.state);
        let (terrain, base, tta) = (self.terrain.as_ref(), self.base.as_ref(), self.tta.as_ref());
        let (next, state) = self.pool.install(|| {
            let inputs = RtnInputs { sequence, x, offset: offset.as_ref(), terrain, base, tta };
            model.step(&inputs, state)
        })?;
        self.out = next.flatten_all()?.to_vec1::<f32>()?;
        self.state = state;
        Ok(())
    }

    fn output(&self) -> &[f32] {
        &self.out
    }
}

pub(crate) struct TractBackend {
    /// `tract`, or `tract WIDTH` when several widths are measured.
    pub(crate) label: String,
    runner: zoo_runtime::MotionRunner,
    states: Vec<MotionState>,
    frame: Frame,
    /// One buffer per graph output; the first is compared.
    outs: Vec<Vec<f32>>,
}

impl StepBackend for TractBackend {
    fn name(&self) -> &str {
        &self.label
    }

    fn step(&mut self) -> Result<()> {
        let inputs: Vec<&[f32]> = self.frame.data.iter().map(Vec::as_slice).collect();
        let mut outs: Vec<&mut [f32]> = self.outs.iter_mut().map(Vec::as_mut_slice).collect();
        self.runner.step_batch(&mut self.states, &inputs, &mut outs)?;
        Ok(())
    }

    fn output(&self) -> &[f32] {
        &self.outs[0]
    }
}

pub(crate) struct OrtBackend {
    /// `onnxruntime`, or `onnxruntime WIDTH` when several widths are measured.
    pub(crate) label: String,
    session: ort::session::Session,
    batch: usize,
    frame: Frame,
    /// State slots: (graph input, graph output, values).
    states: Vec<(String, String, Vec<f32>)>,
    out_name: String,
    out: Vec<f32>,
}

impl StepBackend for OrtBackend {
    fn name(&self) -> &str {
        &self.label
    }

    fn step(&mut self) -> Result<()> {
        let b = self.batch;
        let tensor = |data: &[f32]| {
            ort::value::Tensor::from_array((vec![b as i64, (data.len() / b) as i64], data.to_vec()))
                .map_err(|e| msg!("onnxruntime tensor: {e}"))
        };
        let mut values: Vec<(Cow<'_, str>, ort::session::SessionInputValue<'_>)> = Vec::new();
        for (name, data) in self.frame.names.iter().zip(&self.frame.data) {
            values.push((Cow::Owned(name.clone()), tensor(data)?.into()));
        }
        for (input, _, data) in &self.states {
            values.push((Cow::Owned(input.clone()), tensor(data)?.into()));
        }
        let out = self.session.run(values).map_err(|e| msg!("onnxruntime run: {e}"))?;
        let extract = |name: &str| -> Result<Vec<f32>> {
            Ok(out[name].try_extract_tensor::<f32>().map_err(|e| msg!("onnxruntime output `{name}`: {e}"))?.1.to_vec())
        };
        let next = extract(&self.out_name)?;
        let mut new_states = Vec::with_capacity(self.states.len());
        for (_, output, _) in &self.states {
            new_states.push(extract(output)?);
        }
        drop(out);
        self.out = next;
        for (slot, v) in self.states.iter_mut().zip(new_states) {
            slot.2 = v;
        }
        Ok(())
    }

    fn output(&self) -> &[f32] {
        &self.out
    }
}

/// The onnxruntime library to load.
pub fn onnxruntime_library(explicit: Option<&Path>) -> Result<PathBuf> {
    let help = "run `bash scripts/onnxruntime.sh` in the zoo workspace (it fetches the onnxruntime wheel from PyPI \
                into .onnxruntime/), or pass --onnxruntime /path/to/libonnxruntime.so, or set ORT_DYLIB_PATH";
    if let Some(p) = explicit.map(Path::to_path_buf).or_else(|| std::env::var_os("ORT_DYLIB_PATH").map(PathBuf::from)) {
        if p.is_file() {
            return Ok(p);
        }
        bail!("onnxruntime library {} does not exist: {help}", p.display());
    }
    let cwd = std::env::current_dir().context("the current folder")?;
    for dir in cwd.ancestors() {
        let folder = dir.join(".onnxruntime");
        let Ok(entries) = std::fs::read_dir(&folder) else { continue };
        let mut libs: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("libonnxruntime.so")))
            .collect();
        libs.sort();
        if let Some(lib) = libs.pop() {
            return Ok(lib);
        }
    }
    bail!("no onnxruntime library found (looked in .onnxruntime/ of {} and its parents): {help}", cwd.display())
}

fn frame_inputs(model: &MotionModel, batch: usize) -> Frame {
    let names: Vec<String> = model.inputs().iter().map(|i| i.name.clone()).collect();
    let data = model.inputs().iter().enumerate().map(|(k, i)| inputs(batch * i.width, 7 + k as u64)).collect();
    Frame { names, data }
}

/// The candle (f32), tract and onnxruntime backends at `batch`, tract and onnxruntime once per
/// width of `files` (the file at that width), labelled with the width when there are several.
fn make_backends(
    files: &[(WeightWidth, Vec<u8>)],
    model: &MotionModel,
    candle: Option<&Rtn>,
    env: &ort::environment::Environment,
    batch: usize,
) -> Result<Vec<Box<dyn StepBackend>>> {
    let frame = frame_inputs(model, batch);
    // Initial recurrent state: small deterministic values, the same for every backend.
    let states: Vec<Vec<f32>> =
        model.states().iter().enumerate().map(|(k, s)| inputs(batch * s.width, 101 + k as u64)).collect();
    let mut states: Vec<Vec<f32>> = states.into_iter().map(|v| v.into_iter().map(|x| 0.5 * x).collect()).collect();
    let mut backends: Vec<Box<dyn StepBackend>> = Vec::new();
    if let Some(candle) = candle {
        backends.push(Box::new(candle_backend(candle, model, &frame, &mut states, batch)?));
    }

    let label = |backend: &str, width: WeightWidth| match files.len() {
        1 => backend.to_string(),
        _ => format!("{backend} {width}"),
    };
    for (width, bytes) in files {
        let at_width = MotionModel::from_bytes(bytes)?;
        let mut tract = tract_backend(&at_width, &frame, &states, batch)?;
        tract.label = label("tract", *width);
        backends.push(Box::new(tract));
        let mut ort = ort_backend(
            env,
            bytes,
            &at_width,
            Frame { names: frame.names.clone(), data: frame.data.clone() },
            states.clone(),
            batch,
        )?;
        ort.label = label("onnxruntime", *width);
        backends.push(Box::new(ort));
        if *width == WeightWidth::Int8 {
            // onnxruntime's fastest int8 form of the same model, as its speed reference.
            let fast = onnxruntime_u8s8(bytes)?;
            let frame = Frame { names: frame.names.clone(), data: frame.data.clone() };
            let mut ort = ort_backend(env, &fast, &at_width, frame, states.clone(), batch)?;
            ort.label = U8S8_LABEL.into();
            backends.push(Box::new(ort));
        }
    }
    Ok(backends)
}

/// The label of onnxruntime on [`onnxruntime_u8s8`]'s form of the int8 file.
pub const U8S8_LABEL: &str = "onnxruntime int8 u8s8-7bit";

/// onnxruntime's fastest int8 form of an int8 file, a speed reference only: every
/// `MatMulInteger`'s weights re-quantized to 7 bits (`|q| <= 63`, one scale per output
/// channel) and stored as s8 with zero point 0, which onnxruntime runs on its u8 x s8 kernels
/// (2.5-3x its u8 x u8 ones on AVX-512 VNNI) and which stay exact without VNNI (`255 * 63 * 2`
/// fits the 16-bit pair sums). Not what `zoo export` writes: 7-bit weights cost quality
/// (docs/runtime.md).
pub fn onnxruntime_u8s8(bytes: &[u8]) -> Result<Vec<u8>> {
    use zoo_export::pb::tensor_proto::DataType;
    let model = zoo_export::OnnxModel::from_bytes(bytes, "the int8 file").map_err(|e| msg!("{e}"))?;
    let mut proto = model.proto().clone();
    let Some(graph) = proto.graph.as_mut() else { bail!("the int8 file has no graph") };
    let zero = "int8.zero_point_s8";
    graph.initializer.push(zoo_export::pb::TensorProto {
        name: zero.into(),
        data_type: DataType::Int8 as i32,
        raw_data: vec![0],
        ..Default::default()
    });
    let mut done = std::collections::HashSet::new();
    let nodes = graph.node.clone();
    for (i, node) in nodes.iter().enumerate() {
        if node.op_type != "MatMulInteger" || node.input.len() != 4 {
            continue;
        }
        // The weight initializer, directly (`[in, out]`) or through a Transpose (`[out, in]`).
        let w = &node.input[1];
        let (init, axis) = match nodes.iter().find(|t| t.op_type == "Transpose" && t.output.first() == Some(w)) {
            Some(t) => (t.input[0].clone(), 0),
            None => (w.clone(), 1),
        };
        graph.node[i].input[3] = zero.into();
        if !done.insert(init.clone()) {
            continue;
        }
        let base = init.strip_suffix(".int8").ok_or_else(|| msg!("`{init}` is not an int8 weight"))?;
        let scale_name = format!("{base}.scale");
        let t = graph.initializer.iter().find(|t| t.name == init).ok_or_else(|| msg!("no `{init}`"))?.clone();
        let st = graph.initializer.iter().find(|t| t.name == scale_name).ok_or_else(|| msg!("no `{scale_name}`"))?;
        let scales: Vec<f32> =
            st.raw_data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        let (rows, cols) = (t.dims[0] as usize, t.dims[1] as usize);
        let channel = |j: usize| if axis == 0 { j / cols } else { j % cols };
        let w: Vec<f32> =
            t.raw_data.iter().enumerate().map(|(j, b)| (f32::from(*b) - 128.0) * scales[channel(j)]).collect();
        let mut max = vec![0f32; scales.len()];
        for (j, v) in w.iter().enumerate() {
            max[channel(j)] = max[channel(j)].max(v.abs());
        }
        let s7: Vec<f32> = max.iter().map(|m| if *m > 0.0 { m / 63.0 } else { 1.0 }).collect();
        let q: Vec<u8> =
            w.iter().enumerate().map(|(j, v)| (v / s7[channel(j)]).round().clamp(-63.0, 63.0) as i8 as u8).collect();
        debug_assert_eq!(q.len(), rows * cols);
        let wt = graph.initializer.iter_mut().find(|t| t.name == init).expect("found above");
        wt.data_type = DataType::Int8 as i32;
        wt.raw_data = q;
        let st = graph.initializer.iter_mut().find(|t| t.name == scale_name).expect("found above");
        st.raw_data = s7.iter().flat_map(|v| v.to_le_bytes()).collect();
    }
    Ok(zoo_export::OnnxModel::from_proto(proto).to_bytes())
}

/// The file's bytes at each width asked (the file as it is when none is asked, or when the one
/// asked is its own); other widths are rewritten from an f32 file.
fn files_at_widths(o: &RuntimeOptions, bytes: &[u8]) -> Result<Vec<(WeightWidth, Vec<u8>)>> {
    let origin = o.model.display().to_string();
    let own = zoo_runtime::metadata::MotionModelMetadata::read(bytes, &origin).map_err(|e| msg!("{e}"))?.weights;
    if o.widths.is_empty() || o.widths == [own] {
        return Ok(vec![(own, bytes.to_vec())]);
    }
    if own != WeightWidth::F32 {
        bail!(
            "{} stores {own} weights; `--weights` rewrites an f32 file at each width: pass the file of \
             `zoo export --onnx RUN --weights f32`",
            o.model.display()
        );
    }
    let model = zoo_export::OnnxModel::from_bytes(bytes, &origin).map_err(|e| msg!("{e}"))?;
    let at = |w: WeightWidth| zoo_export::with_weights(&model, w).map_err(|e| msg!("{origin} at {w}: {e}"));
    o.widths.iter().map(|w| Ok((*w, at(*w)?.to_bytes()))).collect()
}

/// Refuses a portable export (`zoo export --portable`): its recurrent layers are unrolled into
/// cell equations and its start graph is a file of its own, so neither candle nor the timed
/// backends read it as the runtime's file; the message says so and names the file to measure.
pub fn refuse_portable(path: &Path, bytes: &[u8]) -> Result<()> {
    let origin = path.display().to_string();
    let model = zoo_export::OnnxModel::from_bytes(bytes, &origin).map_err(|e| msg!("{e}"))?;
    if model.metadata_value(zoo_runtime::portable::PORTABLE_KEY).is_some() {
        bail!(
            "{origin} is a portable export (`zoo export --portable`: recurrent layers unrolled for Unity Inference \
             Engine, the start graph in a file beside it); `zoo bench runtime` measures the engine runtime's file: \
             export the run without --portable (`zoo export --onnx RUN --out FILE.onnx`) and measure that"
        );
    }
    Ok(())
}

/// The CPU features that decide which matrix kernels tract and onnxruntime pick (x86-64;
/// `None` elsewhere).
pub fn cpu_features() -> Option<String> {
    #[cfg(target_arch = "x86_64")]
    {
        // What CPUID says, as tract and onnxruntime read it when they pick their kernels (an
        // emulated CPU included), not /proc/cpuinfo. AMX is read from CPUID leaf 7 (its
        // feature test is unstable in std).
        let amx = std::arch::x86_64::__cpuid_count(7, 0).edx;
        let flags = [
            (std::arch::is_x86_feature_detected!("avx2"), "AVX2"),
            (std::arch::is_x86_feature_detected!("fma"), "FMA"),
            (std::arch::is_x86_feature_detected!("f16c"), "F16C"),
            (std::arch::is_x86_feature_detected!("avx512f"), "AVX-512F"),
            (std::arch::is_x86_feature_detected!("avx512bw"), "AVX-512BW"),
            (std::arch::is_x86_feature_detected!("avx512vnni"), "AVX-512 VNNI"),
            (std::arch::is_x86_feature_detected!("avxvnni"), "AVX-VNNI"),
            (std::arch::is_x86_feature_detected!("avx512bf16"), "AVX-512 BF16"),
            (amx >> 24 & 1 == 1, "AMX"),
            (amx >> 25 & 1 == 1, "AMX-INT8"),
            (amx >> 22 & 1 == 1, "AMX-BF16"),
        ];
        let have: Vec<&str> = flags.iter().filter(|(f, _)| *f).map(|(_, n)| *n).collect();
        let lack: Vec<&str> = flags.iter().filter(|(f, _)| !*f).map(|(_, n)| *n).collect();
        Some(format!(
            "CPU features: {}; absent: {}",
            if have.is_empty() { "none".into() } else { have.join(", ") },
            if lack.is_empty() { "none".into() } else { lack.join(", ") }
        ))
    }
    #[cfg(not(target_arch = "x86_64"))]
    None
}

/// The step graph through tract from the frame inputs `frame` and the initial states `states`
/// (per slot, `batch` rows each).
pub(crate) fn tract_backend(
    model: &MotionModel,
    frame: &Frame,
    states: &[Vec<f32>],
    batch: usize,
) -> Result<TractBackend> {
    let mut tract_states: Vec<MotionState> = (0..batch).map(|_| model.new_state()).collect();
    for (c, s) in tract_states.iter_mut().enumerate() {
        for (k, info) in model.states().iter().enumerate() {
            s.slot_mut(k).copy_from_slice(&states[k][c * info.width..(c + 1) * info.width]);
        }
    }
    Ok(TractBackend {
        label: "tract".into(),
        runner: model.runner()?,
        states: tract_states,
        frame: Frame { names: frame.names.clone(), data: frame.data.clone() },
        outs: model.outputs().iter().map(|o| vec![0.0; batch * o.width]).collect(),
    })
}

/// The step graph of the file `bytes` through onnxruntime (one thread), from the same inputs
/// and states.
pub(crate) fn ort_backend(
    env: &ort::environment::Environment,
    bytes: &[u8],
    model: &MotionModel,
    frame: Frame,
    states: Vec<Vec<f32>>,
    batch: usize,
) -> Result<OrtBackend> {
    let opt = |e: ort::Error<_>| msg!("onnxruntime session options: {e}");
    let session = ort::session::Session::builder(env)
        .map_err(|e| msg!("onnxruntime session: {e}"))?
        .with_intra_threads(1)
        .map_err(opt)?
        .with_inter_threads(1)
        .map_err(|e| msg!("onnxruntime session options: {e}"))?
        .commit_from_memory(bytes)
        .map_err(|e| msg!("onnxruntime cannot load the model: {e}"))?;
    Ok(OrtBackend {
        label: "onnxruntime".into(),
        session,
        batch,
        frame,
        states: model.states().iter().zip(states).map(|(s, v)| (s.input.clone(), s.output.clone(), v)).collect(),
        out_name: model.outputs()[0].name.clone(),
        out: Vec::new(),
    })
}

/// The RTN's step in candle with the weights of the file, from the same inputs and state as
/// the other backends (the per-sequence gate bias is written into its state slot).
fn candle_backend(
    candle: &Rtn,
    model: &MotionModel,
    frame: &Frame,
    states: &mut [Vec<f32>],
    batch: usize,
) -> Result<CandleBackend> {
    let d = model.outputs()[0].width;
    let dev = Device::Cpu;
    let hu = candle.config().lstm;
    let get = |name: &str| -> Result<Tensor> {
        let k = frame.names.iter().position(|n| n == name).ok_or_else(|| msg!("the step graph has no `{name}`"))?;
        Ok(Tensor::from_slice(&frame.data[k], (batch, frame.data[k].len() / batch), &dev)?)
    };
    let x = get("x")?;
    let offset = if candle.config().future_conditioning { Some(get("offset")?) } else { None };
    // The same values as the graph's inputs, so that the backends compute the same step.
    let terrain = if candle.config().terrain { Some(get("terrain")?) } else { None };
    let base = if candle.config().interp_residual { Some(get("base")?) } else { None };
    let tta = if candle.config().time_to_arrival.is_some() { Some(get("tta")?) } else { None };
    let target = Tensor::from_vec(inputs(batch * 2 * d, 55), (batch, 2 * d), &dev)?;
    let sequence = candle.begin(&target)?;
    // The exported step graph carries the per-sequence gate bias as a state slot.
    if let Some(k) = model.states().iter().position(|s| s.input == "gate_bias") {
        states[k] = sequence.gate_bias().flatten_all()?.to_vec1::<f32>()?;
    }
    let slot = |name: &str| -> Result<Tensor> {
        let k = model
            .states()
            .iter()
            .position(|s| s.input == name)
            .ok_or_else(|| msg!("the step graph has no state `{name}`"))?;
        Ok(Tensor::from_slice(&states[k], (batch, hu), &dev)?)
    };
    let state = RtnState { h: slot("h")?, c: slot("c")? };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().map_err(|e| msg!("a one-thread pool: {e}"))?;
    Ok(CandleBackend { model: candle.clone(), sequence, x, offset, terrain, base, tta, state, out: Vec::new(), pool })
}

/// The onnxruntime environment from `lib`.
pub fn onnxruntime_env(lib: &Path) -> Result<ort::environment::Environment> {
    Ok(ort::init_from(lib)
        .map_err(|e| msg!("cannot load onnxruntime from {}: {e}", lib.display()))?
        .build()
        .map_err(|e| msg!("onnxruntime environment: {e}"))?)
}

/// The file's step graph, and the RTN in candle with the file's weights for a transition model.
fn models(o: &RuntimeOptions, bytes: &[u8]) -> Result<(MotionModel, Option<Rtn>)> {
    let loaded = crate::exported::load(
        &o.model,
        &[MotionTaskKind::Transition, MotionTaskKind::Synthesis],
        "`zoo bench runtime`",
    )?;
    // An RTN runs in candle too (its weights read back from the file); an RNN-GMM generator
    // runs its step in tract and onnxruntime, and its whole synthesis frame in the runtime.
    Ok(match &loaded {
        LoadedModel::Transition(t) => {
            let (config, weights) = zoo_rtn::export::import_rtn(bytes)
                .with_context(|| format!("reading the RTN weights of {} for candle", o.model.display()))?;
            let rtn =
                Rtn::new(&config, candle_nn::VarBuilder::from_tensors(weights, candle_core::DType::F32, &Device::Cpu))?;
            (t.model().clone(), Some(rtn))
        }
        LoadedModel::Synthesis(s) => (s.model().clone(), None),
        other => {
            bail!("{} is a `{}` model, which `zoo bench runtime` does not measure", o.model.display(), other.task())
        }
    })
}

/// One step of every backend from the same state and inputs, each compared with the f32
/// reference (tract f32; tract at the file's width when f32 is not measured). Never refuses a
/// width: the difference is reported, with a note when it is above what that width usually
/// costs ([`USUAL_DIFFERENCE`]). Returns `(backend, largest difference, note)`.
fn check_agreement(backends: &mut [Box<dyn StepBackend>]) -> Result<Vec<(String, f32, Option<String>)>> {
    for b in backends.iter_mut() {
        b.step().with_context(|| format!("{} step", b.name()))?;
    }
    let reference = backends
        .iter()
        .find(|r| r.name() == "tract f32" || r.name() == "tract")
        .or_else(|| backends.iter().find(|r| r.name().starts_with("tract")))
        .ok_or_else(|| msg!("no tract backend"))?;
    let mut diffs = Vec::new();
    for b in backends.iter().filter(|b| !b.output().is_empty() && b.name() != reference.name()) {
        if b.output().len() != reference.output().len() {
            bail!(
                "{} gives {} values a step and {} gives {}: they do not run the same computation",
                b.name(),
                b.output().len(),
                reference.name(),
                reference.output().len()
            );
        }
        let diff = b.output().iter().zip(reference.output()).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
        let width = b.name().split(' ').nth(1).unwrap_or("f32");
        let usual = USUAL_DIFFERENCE.iter().find(|(w, _)| w.name() == width).map_or(1e-3, |(_, t)| *t);
        let note = (!(diff <= usual)).then(|| {
            format!(
                "{} is {diff:.1e} from {} on the first step, more than the usual {usual:.0e} at {width}: its time is \
                 of a computation that differs from the model's",
                b.name(),
                reference.name()
            )
        });
        diffs.push((b.name().to_string(), diff, note));
    }
    Ok(diffs)
}

/// The largest first-step difference from the f32 reference that each width usually gives
/// (normalized units): f32 and f16 sum in other orders (f16 also rounds the weights); int8
/// rounds the weights and each character's activations. Measured on the README's RTN and the
/// RNN-GMM generator on AVX2 and AVX-512 VNNI machines (docs/runtime.md); a larger one is
/// reported, not refused.
pub const USUAL_DIFFERENCE: [(WeightWidth, f32); 3] =
    [(WeightWidth::F32, 1e-3), (WeightWidth::F16, 1e-2), (WeightWidth::Int8, 1e-1)];

/// Times `rounds` rounds of every backend at batch `batch` (after a warm-up).
fn time_backends(
    o: &RuntimeOptions,
    backends: &mut [Box<dyn StepBackend>],
    batch: usize,
    p: &dyn Progress,
) -> Result<Vec<BackendFigure>> {
    for b in backends.iter_mut() {
        for _ in 0..5 {
            b.step()?;
        }
    }
    let steps = (o.work / batch).max(5);
    p.start((o.rounds * backends.len()) as u64, &format!("batch {batch}: backend rounds"));
    let mut times = vec![Vec::with_capacity(o.rounds); backends.len()];
    for _ in 0..o.rounds {
        for (k, b) in backends.iter_mut().enumerate() {
            let t = Instant::now();
            for _ in 0..steps {
                b.step()?;
            }
            times[k].push(t.elapsed().as_secs_f64() * 1e3 / steps as f64);
            p.advance(1);
        }
    }
    p.finish();
    Ok(backends.iter().zip(times).map(|(b, t)| BackendFigure::new(b.name(), batch, t)).collect())
}

impl BackendFigure {
    /// The figure of `backend` at `batch` from every round's mean step time (ms).
    pub fn new(backend: &str, batch: usize, rounds_ms: Vec<f64>) -> BackendFigure {
        let step_ms = zoo_data::dataset::percentile(&mut rounds_ms.clone(), 50.0);
        BackendFigure {
            backend: backend.to_string(),
            batch,
            step_ms,
            frames_per_second: batch as f64 * 1e3 / step_ms,
            rounds_ms,
            gmacs: 0.0,
            of_peak: None,
        }
    }

    /// Sets [`Self::gmacs`] and [`Self::of_peak`] from the roofline.
    pub fn with_roofline(mut self, r: &Roofline) -> BackendFigure {
        self.gmacs = r.macs_per_character as f64 * self.frames_per_second / 1e9;
        let peak = if self.backend.contains("int8") { r.int8_peak_gmacs } else { r.f32_peak_gmacs };
        self.of_peak = peak.filter(|p| *p > 0.0 && self.gmacs > 0.0).map(|p| self.gmacs / p);
        self
    }
}

/// Multiply-adds per character and step, and weight bytes, of the matrix products of an
/// exported file (`Gemm`, `MatMul`, `MatMulInteger` on a weight initializer, directly or through
/// `Cast`, `Transpose` or `DequantizeLinear`; the `W` and `R` of recurrent ops once per step).
pub fn graph_cost(bytes: &[u8]) -> Result<(u64, u64)> {
    let model = zoo_export::OnnxModel::from_bytes(bytes, "the file").map_err(|e| msg!("{e}"))?;
    let Some(graph) = model.proto().graph.as_ref() else { bail!("the file has no graph") };
    let init = |name: &str| graph.initializer.iter().find(|t| t.name == name);
    let weight = |name: &str| {
        let mut name = name.to_string();
        for _ in 0..3 {
            if let Some(t) = init(&name) {
                return (t.dims.len() >= 2).then_some(t);
            }
            let through = graph.node.iter().find(|n| {
                n.output.first() == Some(&name)
                    && matches!(n.op_type.as_str(), "Cast" | "Transpose" | "DequantizeLinear")
            });
            name = through?.input.first()?.clone();
        }
        None
    };
    let (mut macs, mut bytes) = (0u64, 0u64);
    let mut seen = std::collections::HashSet::new();
    for n in &graph.node {
        let slots: &[usize] = match n.op_type.as_str() {
            "Gemm" | "MatMul" | "MatMulInteger" => &[1],
            "LSTM" | "GRU" | "RNN" => &[1, 2],
            _ => &[],
        };
        for &slot in slots {
            let Some(t) = n.input.get(slot).and_then(|i| weight(i)) else { continue };
            let count: i64 = t.dims.iter().product();
            macs += count.max(0) as u64;
            if seen.insert(t.name.clone()) {
                bytes += if t.raw_data.is_empty() { 4 * count.max(0) as u64 } else { t.raw_data.len() as u64 };
            }
        }
    }
    Ok((macs, bytes))
}

/// This core's f32 and 8-bit multiply-add peaks (billions per second) and the instruction of
/// the latter, measured with loops of 12 independent accumulators held in registers (best of
/// 3 runs of ~20 ms). `None` off x86-64 or without AVX2/FMA.
pub fn peaks() -> (Option<f64>, Option<f64>, &'static str) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        if !(has!("avx2") && has!("fma")) {
            return (None, None, "none");
        }
        let best = |f: &dyn Fn() -> f64| (0..3).map(|_| f()).fold(0f64, f64::max);
        // SAFETY: each loop runs only where the CPU has the features it is compiled for.
        #[allow(unsafe_code)]
        let f32_peak = best(&|| unsafe { peak::fma() });
        #[allow(unsafe_code)]
        let (int8, with) = if has!("avx512vnni") && has!("avx512vl") {
            (best(&|| unsafe { peak::vnni() }), "AVX-512 VNNI vpdpbusd (256-bit)")
        } else {
            (best(&|| unsafe { peak::madd() }), "AVX2 vpmaddwd")
        };
        (Some(f32_peak), Some(int8), with)
    }
    #[cfg(not(target_arch = "x86_64"))]
    (None, None, "none")
}

#[cfg(target_arch = "x86_64")]
mod peak {
    use std::arch::x86_64::*;
    use std::time::Instant;

    const ROUNDS: usize = 2_000_000;

    /// f32 multiply-adds per second (billions) of 8-lane FMAs.
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn fma() -> f64 {
        let (b, c) = (std::hint::black_box(_mm256_set1_ps(0.999)), std::hint::black_box(_mm256_set1_ps(1e-3)));
        let mut a = std::hint::black_box([_mm256_set1_ps(1.0); 12]);
        let t = Instant::now();
        for _ in 0..ROUNDS {
            for v in a.iter_mut() {
                *v = _mm256_fmadd_ps(*v, b, c);
            }
        }
        let secs = t.elapsed().as_secs_f64();
        let sum = a.iter().fold(_mm256_setzero_ps(), |s, v| _mm256_add_ps(s, *v));
        std::hint::black_box(sum);
        (ROUNDS * 12 * 8) as f64 / secs / 1e9
    }

    /// 8-bit multiply-adds per second (billions) of 256-bit `vpdpbusd` (32 a call).
    #[target_feature(enable = "avx2,avx512f,avx512vl,avx512vnni")]
    pub(super) fn vnni() -> f64 {
        let (b, c) = (std::hint::black_box(_mm256_set1_epi8(3)), std::hint::black_box(_mm256_set1_epi8(5)));
        let mut a = std::hint::black_box([_mm256_set1_epi32(1); 12]);
        let t = Instant::now();
        for _ in 0..ROUNDS {
            for v in a.iter_mut() {
                *v = _mm256_dpbusd_epi32(*v, b, c);
            }
        }
        let secs = t.elapsed().as_secs_f64();
        let sum = a.iter().fold(_mm256_setzero_si256(), |s, v| _mm256_add_epi32(s, *v));
        std::hint::black_box(sum);
        (ROUNDS * 12 * 32) as f64 / secs / 1e9
    }

    /// 16-bit multiply-adds per second (billions) of AVX2's `vpmaddwd` and the `vpaddd` that
    /// accumulates it (16 a pair).
    #[target_feature(enable = "avx2")]
    pub(super) fn madd() -> f64 {
        let (b, c) = (std::hint::black_box(_mm256_set1_epi16(3)), std::hint::black_box(_mm256_set1_epi16(5)));
        let mut a = std::hint::black_box([_mm256_set1_epi32(1); 12]);
        let t = Instant::now();
        for _ in 0..ROUNDS {
            for v in a.iter_mut() {
                *v = _mm256_add_epi32(*v, _mm256_madd_epi16(b, c));
            }
        }
        let secs = t.elapsed().as_secs_f64();
        let sum = a.iter().fold(_mm256_setzero_si256(), |s, v| _mm256_add_epi32(s, *v));
        std::hint::black_box(sum);
        (ROUNDS * 12 * 16) as f64 / secs / 1e9
    }
}

/// What `zoo bench runtime` measured.
#[derive(Clone, Debug)]
pub struct RuntimeReport {
    /// What ran, in one line (the model, the onnxruntime library).
    pub header: String,
    /// The figures, one per backend and batch size (the JSON of the command).
    pub figures: Vec<BackendFigure>,
    /// The step's cost and the core's peaks.
    pub roofline: Roofline,
}

/// Runs the benchmark.
pub fn run(o: &RuntimeOptions, p: &dyn Progress) -> Result<RuntimeReport> {
    let bytes = std::fs::read(&o.model).with_context(|| format!("reading {}", o.model.display()))?;
    refuse_portable(&o.model, &bytes)?;
    let (model, candle) = models(o, &bytes)?;
    let lib = onnxruntime_library(o.onnxruntime.as_deref())?;
    let env = onnxruntime_env(&lib)?;
    if o.rounds == 0 || o.batch.is_empty() || o.batch.contains(&0) {
        bail!("--rounds and every --batch must be at least 1");
    }
    let header = match &candle {
        Some(rtn) => format!(
            "{}: RTN, {} parameters, LSTM {} units; onnxruntime {}; one thread per backend",
            o.model.display(),
            rtn.parameter_count(),
            rtn.config().lstm,
            lib.display()
        ),
        None => format!(
            "{}: RNN-GMM generator step (tract, onnxruntime) and the runtime's whole synthesis frame (`tract frame`: \
             step, sampling, refiner, decoding); onnxruntime {}; one thread per backend",
            o.model.display(),
            lib.display()
        ),
    };
    let files = files_at_widths(o, &bytes)?;
    let header = match cpu_features() {
        Some(cpu) => format!("{header}\n{cpu}"),
        None => header,
    };
    let mut figures = Vec::new();
    let mut agreement = Vec::new();
    for &batch in &o.batch {
        let mut backends = make_backends(&files, &model, candle.as_ref(), &env, batch)?;
        if candle.is_none() {
            backends.push(Box::new(SynthesisBackend::new(&bytes, batch)?));
        }
        agreement.extend(check_agreement(&mut backends)?.into_iter().map(|(b, d, note)| (batch, b, d, note)));
        figures.extend(time_backends(o, &mut backends, batch, p)?);
    }
    let (macs, _) = graph_cost(&bytes)?;
    let mut weight_bytes = Vec::new();
    for (w, b) in &files {
        weight_bytes.push((w.name().to_string(), graph_cost(b)?.1));
    }
    let (f32_peak, int8_peak, with) = peaks();
    let roofline = Roofline {
        macs_per_character: macs,
        weight_bytes,
        f32_peak_gmacs: f32_peak,
        int8_peak_gmacs: int8_peak,
        int8_peak_with: with,
    };
    let figures: Vec<BackendFigure> = figures.into_iter().map(|f| f.with_roofline(&roofline)).collect();
    let notes: Vec<&str> = agreement.iter().filter_map(|(_, _, _, note)| note.as_deref()).collect();
    let agreement: Vec<String> = agreement.iter().map(|(b, n, d, _)| format!("{n} at batch {b}: {d:.1e}")).collect();
    let mut header = format!("{header}\nfirst step, max abs difference from tract f32: {}", agreement.join(", "));
    for note in notes {
        header += &format!("\nnote: {note}");
    }
    header += &format!("\n{}", roofline_line(&roofline));
    Ok(RuntimeReport { header, figures, roofline })
}

/// The roofline in one line.
pub fn roofline_line(r: &Roofline) -> String {
    let mb: Vec<String> = r.weight_bytes.iter().map(|(w, b)| format!("{w} {:.1} MB", *b as f64 / 1e6)).collect();
    let gm = |p: Option<f64>| p.map_or("not measured".to_string(), |p| format!("{p:.0} GMAC/s"));
    format!(
        "roofline: {:.2} M multiply-adds per character and step; weights {}; this core's peak (one thread, \
         measured): f32 FMA {}, 8-bit {} ({}); `of peak` below is each backend's multiply-adds per second over \
         the peak of its arithmetic",
        r.macs_per_character as f64 / 1e6,
        mb.join(", "),
        gm(r.f32_peak_gmacs),
        gm(r.int8_peak_gmacs),
        r.int8_peak_with
    )
}

/// The figures as a text table with ratios to onnxruntime.
pub fn table(figures: &[BackendFigure], rounds: usize, work: usize) -> String {
    let mut s = format!(
        "median of {rounds} rounds, ~{work} character-steps per backend per round\n\
         {:<6} {:<27} {:>12} {:>16} {:>12} {:>14} {:>8} {:>8}\n",
        "batch", "backend", "step (ms)", "frames/s", "time/ort", "throughput/ort", "GMAC/s", "of peak"
    );
    for f in figures {
        let ort = figures
            .iter()
            .find(|g| g.batch == f.batch && (g.backend == "onnxruntime" || g.backend == "onnxruntime f32"))
            .or_else(|| figures.iter().find(|g| g.batch == f.batch && g.backend.starts_with("onnxruntime")));
        let (rt, rf) =
            ort.map_or((f64::NAN, f64::NAN), |o| (f.step_ms / o.step_ms, f.frames_per_second / o.frames_per_second));
        let peak = f.of_peak.map_or("-".to_string(), |p| format!("{:.0}%", 100.0 * p));
        s += &format!(
            "{:<6} {:<27} {:>12.4} {:>16.0} {:>11.2}x {:>13.2}x {:>8.1} {:>8}\n",
            f.batch, f.backend, f.step_ms, f.frames_per_second, rt, rf, f.gmacs, peak
        );
    }
    s
}
