//! Throughput of each of tract-linalg's matrix kernels this CPU runs, on the products of a
//! step graph: what a plan can reach at best, kernel by kernel.
//!
//! `cargo run --release -p zoo-runtime --example mmm_kernels -- [M,K,N ...]`
//! (default: the RTN gate product at batch 64 and 1, `2048,1152,64 2048,1152,1`).
//!
//! Each kernel multiplies packed A (`M x K`, the weights, packed once) by packed B (`K x N`,
//! the activations, packed once) into a plain `N x M` output, best of 7 rounds of ~20 ms.
//! f32 kernels run on f32; i32 kernels on i8 x i8 (their `i8i8` packing). The runtime's own
//! f32 tiles (`zoo_*`) are timed as the runtime calls them: the activations packed in each call.
#![allow(unsafe_code)] // runs tract-linalg's kernels directly, as tract's own matmul op does

use std::time::Instant;
use tract_onnx::prelude::tract_linalg::mmm::{AsInputValue, FusedSpec, MatMatMul};
use tract_onnx::prelude::tract_linalg::{self, isa};
use tract_onnx::prelude::*;
use zoo_runtime::tiles::{Epilogue, TileIsa, Tiles};

fn bench(ker: &dyn MatMatMul, packing: usize, m: usize, k: usize, n: usize) -> TractResult<f64> {
    let (pa, pb) = &ker.packings()[packing];
    let dt = if ker.internal_type() == DatumType::I32 { DatumType::I8 } else { DatumType::F32 };
    let a = Tensor::zero_dt(dt, &[m, k])?;
    let b = Tensor::zero_dt(dt, &[k, n])?;
    let a = pa.prepare_one(&a, 1, 0)?;
    let b = pb.prepare_one(&b, 0, 1)?;
    let mut c = Tensor::zero_dt(ker.internal_type(), &[n, m])?;
    let mut scratch = unsafe { ker.allocate_scratch_space() };
    let mut best = f64::MAX;
    let macs = (m * k * n) as f64;
    let reps = ((20e-3 * 30e9 / macs) as usize).clamp(3, 100_000);
    for _ in 0..7 {
        let t = Instant::now();
        for _ in 0..reps {
            unsafe {
                let store = ker.c_from_data_and_strides(ker.internal_type().size_of(), 1, m as isize);
                let view = c.view_mut();
                let ops = [
                    FusedSpec::AddMatMul { a: AsInputValue::Borrowed(&*a), b: AsInputValue::Borrowed(&*b), packing },
                    FusedSpec::Store(store.wrap(&view)),
                ];
                ker.run_with_scratch_space(m, n, &mut *scratch, &ops)?;
            }
        }
        best = best.min(t.elapsed().as_secs_f64() / reps as f64);
    }
    Ok(macs / best / 1e9)
}

fn bench_tiles(isa: TileIsa, m: usize, k: usize, n: usize) -> f64 {
    let tiles = Tiles::new(isa, &vec![0.0; m * k], m, k);
    let x = vec![0.0; n * k];
    let mut out = vec![0.0; n * m];
    let mut packed = Vec::new();
    let macs = (m * k * n) as f64;
    let reps = ((20e-3 * 30e9 / macs) as usize).clamp(3, 100_000);
    let mut best = f64::MAX;
    for _ in 0..7 {
        let t = Instant::now();
        for _ in 0..reps {
            tiles.run(&[&x], &[k], n, Epilogue::default(), &mut out, &mut packed);
        }
        best = best.min(t.elapsed().as_secs_f64() / reps as f64);
    }
    macs / best / 1e9
}

fn main() -> TractResult<()> {
    let shapes: Vec<(usize, usize, usize)> = {
        let args: Vec<String> = std::env::args().skip(1).collect();
        let args = if args.is_empty() { vec!["2048,1152,64".into(), "2048,1152,1".into()] } else { args };
        args.iter()
            .map(|s| {
                let v: Vec<usize> = s.split(',').map(|x| x.parse().expect("M,K,N")).collect();
                (v[0], v[1], v[2])
            })
            .collect()
    };
    println!("ISA: {:?}", isa::native());
    for (m, k, n) in shapes {
        println!("M={m} K={k} N={n}: GMAC/s (best of 7)");
        let isas = match TileIsa::native() {
            Some(TileIsa::Avx512) => vec![TileIsa::Avx512, TileIsa::Avx2],
            Some(TileIsa::Avx2) => vec![TileIsa::Avx2],
            None => vec![],
        };
        for isa in isas.into_iter().filter(|_| n > 1) {
            let g = bench_tiles(isa, m, k, n);
            println!("  {:<32} {:>3}x{:<3} {:>7.1}", isa.name(), isa.mr(), isa.nr(), g);
        }
        for ker in tract_linalg::MmmDispatch::native().runnable() {
            let packing = match ker.internal_type() {
                DatumType::F32 => 0,
                DatumType::I32 => match ker.packings().iter().position(|(a, _)| format!("{a:?}").contains("I8")) {
                    Some(p) => p,
                    None => continue,
                },
                _ => continue,
            };
            if ker.emulated() || (n > 1 && ker.nr() == 1) {
                continue;
            }
            match bench(&**ker, packing, m, k, n) {
                Ok(g) => println!("  {:<32} {:>3}x{:<3} {:>7.1}", ker.name(), ker.mr(), ker.nr(), g),
                Err(e) => println!("  {:<32} failed: {e}", ker.name()),
            }
        }
    }
    Ok(())
}
