//! Per-node time of an exported step graph in tract: where a step's time goes.
//!
//! `cargo run --release -p zoo-runtime --example profile_step -- MODEL.onnx [BATCH] [STEPS] [FRAMES]`
//!
//! Plans the step graph for a concrete batch like `MotionRunner` does, runs it `STEPS` times on
//! fixed inputs and prints the nodes of the optimized plan by total time, with the heap
//! allocations each makes per run and those of a whole run. With `FRAMES`, a
//! window graph (RMR): inputs `[FRAMES, BATCH, values]`; with `FRAMES batch-first`, a whole-shot
//! graph (the in-betweening design): `[BATCH, FRAMES, values]`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;
use tract_onnx::prelude::*;
use tract_onnx::tract_core::plan::eval;

/// Heap allocations of this process, to show which nodes allocate per run.
struct Counting;
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards every call to the system allocator unchanged; only counts.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn main() -> TractResult<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: profile_step MODEL.onnx [BATCH] [STEPS]");
    let batch: usize = args.get(2).map_or(1, |s| s.parse().expect("batch"));
    let steps: usize = args.get(3).map_or(2000, |s| s.parse().expect("steps"));
    let frames: Option<usize> = args.get(4).map(|s| s.parse().expect("frames"));
    let batch_first = args.get(5).is_some_and(|s| s == "batch-first");
    let bytes = std::fs::read(path)?;
    let proto = <tract_onnx::pb::ModelProto as prost::Message>::decode(bytes.as_slice())?;
    // Through the runtime's loader (its load-time rewrite included; `ZOO_RUNTIME_FUSE=0` for
    // the graph as written).
    let mut model = zoo_runtime::model::tract_graph(&bytes)?;
    let mut widths = Vec::new();
    for (i, v) in proto.graph.as_ref().expect("graph").input.iter().enumerate() {
        use tract_onnx::pb::tensor_shape_proto::dimension::Value;
        let Some(tract_onnx::pb::type_proto::Value::TensorType(t)) = v.r#type.as_ref().and_then(|t| t.value.as_ref())
        else {
            panic!("input {} has no tensor type", v.name)
        };
        let dims = &t.shape.as_ref().expect("shape").dim;
        let skip = if frames.is_some() { 2 } else { 1 };
        let w: usize = dims[skip..]
            .iter()
            .map(|d| match d.value {
                Some(Value::DimValue(n)) => n as usize,
                _ => 1,
            })
            .product();
        widths.push(w);
        match frames {
            Some(f) if batch_first => model.set_input_fact(i, f32::fact([batch, f, w]).into())?,
            Some(f) => model.set_input_fact(i, f32::fact([f, batch, w]).into())?,
            None => model.set_input_fact(i, f32::fact([batch, w]).into())?,
        }
    }
    let plan = zoo_runtime::model::planned(model)?;
    let mut state = plan.spawn()?;
    let inputs: TVec<TValue> = widths
        .iter()
        .map(|&w| {
            let rows = batch * frames.unwrap_or(1);
            let v: Vec<f32> = (0..rows * w).map(|i| ((i * 37 % 101) as f32 / 101.0 - 0.5) * 0.5).collect();
            let shape = match frames {
                Some(f) if batch_first => vec![batch, f, w],
                Some(f) => vec![f, batch, w],
                None => vec![batch, w],
            };
            tensor1(&v).into_shape(&shape).unwrap().into_tvalue()
        })
        .collect();
    for _ in 0..20 {
        state.run(inputs.clone())?;
    }
    let mut per_node: HashMap<String, (f64, usize, usize)> = HashMap::new();
    let t0 = Instant::now();
    for _ in 0..steps {
        state.run(inputs.clone())?;
    }
    let plain = t0.elapsed().as_secs_f64() / steps as f64;
    for _ in 0..steps {
        state.run_plan_with_eval(inputs.clone(), |ctx, op_state, node, input| {
            let (t, a) = (Instant::now(), ALLOCATIONS.load(Ordering::Relaxed));
            let r = eval(ctx, op_state, node, input);
            let (t, a) = (t.elapsed().as_secs_f64(), ALLOCATIONS.load(Ordering::Relaxed) - a);
            let info = node.op().info().unwrap_or_default().join("; ");
            let e = per_node.entry(format!("{} ({}) {info}", node.name, node.op().name())).or_default();
            e.0 += t;
            e.1 += 1;
            e.2 += a;
            r
        })?;
    }
    let mut rows: Vec<_> = per_node.into_iter().collect();
    rows.sort_by(|a, b| b.1.0.total_cmp(&a.1.0));
    let total: f64 = rows.iter().map(|r| r.1.0).sum::<f64>() / steps as f64;
    println!("batch {batch}: plain run {:.1} us/step; sum of node times {:.1} us/step", plain * 1e6, total * 1e6);
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    for _ in 0..steps {
        state.run(inputs.clone())?;
    }
    let whole = (ALLOCATIONS.load(Ordering::Relaxed) - before) as f64 / steps as f64;
    println!("allocations per run: {whole:.1} (nodes' own below, per run)");
    for (name, (t, _, a)) in rows.iter().take(usize::MAX) {
        println!("{:>9.2} us {:>5.1} alloc  {name}", t / steps as f64 * 1e6, *a as f64 / steps as f64);
    }
    Ok(())
}
