//! `zoo bench runtime --per-call` with the system allocator, as an engine linking the C library
//! or the Rust crate gets it (the `zoo` command runs on mimalloc, which its training needs, and
//! whose way of returning memory to the system shows in the slowest calls of 64 streams).
//!
//! ```text
//! cargo build --release --workspace --example frame_budget
//! target/release/examples/frame_budget MODEL.onnx [CALLS] [BATCHES]     # e.g. rmr.onnx 1000 1,64
//! ```

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().ok_or("usage: frame_budget MODEL.onnx [CALLS] [BATCHES]")?;
    let calls: usize = args.get(1).map_or(Ok(1000), |c| c.parse())?;
    let batches: Vec<usize> =
        args.get(2).map_or("1,64", String::as_str).split(',').map(str::parse).collect::<Result<_, _>>()?;
    let figures = zoo_bench::frame_budget::run(&std::fs::read(path)?, &batches, calls)?;
    println!(
        "per-call times of {path} on one thread, system allocator ({}):",
        zoo_bench::runtime::cpu_features().unwrap_or_else(|| "CPU features unknown".into())
    );
    println!("{}", zoo_bench::frame_budget::table(&figures));
    Ok(())
}
