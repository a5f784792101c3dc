//! The largest difference between the step graph as written and as the runtime plans it (its
//! load-time rewrite into zoo ops), per output, on deterministic inputs.
//!
//! `cargo run --release -p zoo-runtime --example fused_diff -- MODEL.onnx [BATCH]`

use tract_onnx::prelude::*;

fn main() -> TractResult<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: fused_diff MODEL.onnx [BATCH]");
    let batch: usize = args.get(2).map_or(64, |s| s.parse().expect("batch"));
    let bytes = std::fs::read(path)?;
    let proto = <tract_onnx::pb::ModelProto as prost::Message>::decode(bytes.as_slice())?;
    let plain = tract_onnx::onnx().model_for_proto_model(&proto)?;
    let fused = zoo_runtime::model::tract_graph(&bytes)?;
    let graph = proto.graph.as_ref().expect("graph");
    let mut widths = Vec::new();
    for v in &graph.input {
        use tract_onnx::pb::tensor_shape_proto::dimension::Value;
        let Some(tract_onnx::pb::type_proto::Value::TensorType(t)) = v.r#type.as_ref().and_then(|t| t.value.as_ref())
        else {
            panic!("input {} has no tensor type", v.name)
        };
        let dims = &t.shape.as_ref().expect("shape").dim;
        widths.push(
            dims[1..].iter().map(|d| if let Some(Value::DimValue(n)) = d.value { n as usize } else { 1 }).product(),
        );
    }
    let plan = |mut m: InferenceModel| -> TractResult<_> {
        for (i, w) in widths.iter().enumerate() {
            m.set_input_fact(i, f32::fact([batch, *w]).into())?;
        }
        m.into_optimized()?.into_runnable()
    };
    let (plain, fused) = (plan(plain)?, plan(fused)?);
    let inputs: TVec<TValue> = widths
        .iter()
        .enumerate()
        .map(|(j, &w)| {
            let v: Vec<f32> = (0..batch * w).map(|i| (((i * 37 + j * 11) % 101) as f32 / 101.0 - 0.5) * 2.0).collect();
            tensor1(&v).into_shape(&[batch, w]).unwrap().into_tvalue()
        })
        .collect();
    let a = plain.run(inputs.clone())?;
    let b = fused.run(inputs)?;
    for (o, (a, b)) in graph.output.iter().zip(a.iter().zip(b.iter())) {
        let a = a.try_as_plain_ram()?.as_slice::<f32>()?.to_vec();
        let b = b.try_as_plain_ram()?.as_slice::<f32>()?.to_vec();
        let d = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
        let scale = a.iter().map(|x| x.abs()).fold(0f32, f32::max);
        println!("{:<16} max |diff| {d:.3e} (max |value| {scale:.3})", o.name);
    }
    Ok(())
}
