//! Why `zoo_nn::tape` keeps every taped weight in both orientations: the time of candle's
//! one-thread matmul (gemm) at the RTN's gate shape for each layout of the weight operand, at
//! the rows a data-parallel worker gets (16-64), and of the once-per-step weight-gradient
//! matmul. A transposed view makes gemm repack the whole weight at every call.
//!
//! ```text
//! RAYON_NUM_THREADS=1 cargo run --release -p zoo-nn --example gemm_layouts
//! ```

use candle_core::{Device, Tensor};
use std::time::Instant;

fn time(label: &str, a: &Tensor, b: &Tensor) {
    let _ = a.matmul(b).unwrap();
    let n = 200;
    let t0 = Instant::now();
    for _ in 0..n {
        let _ = a.matmul(b).unwrap();
    }
    let dt = t0.elapsed().as_secs_f64() / n as f64;
    let (m, k) = a.dims2().unwrap();
    let nn = b.dims2().unwrap().1;
    println!("{label:40} {m}x{k}x{nn}: {:8.1} us {:6.1} GFLOP/s", dt * 1e6, 2.0 * (m * k * nn) as f64 / dt / 1e9);
}

fn main() {
    let dev = Device::Cpu;
    let (k, n) = (1152, 2048);
    let w = Tensor::randn(0f32, 1.0, (k, n), &dev).unwrap(); // (in, out) contiguous
    let wt = w.t().unwrap().contiguous().unwrap(); // (out, in) contiguous
    for m in [16, 32, 64] {
        let x = Tensor::randn(0f32, 1.0, (m, k), &dev).unwrap();
        let g = Tensor::randn(0f32, 1.0, (m, n), &dev).unwrap();
        time("fwd x @ W (W contiguous in,out)", &x, &w);
        time("fwd x @ Wt.t() (view)", &x, &wt.t().unwrap());
        time("bwd g @ W.t() (view)", &g, &w.t().unwrap());
        time("bwd g @ Wt (contiguous out,in)", &g, &wt);
    }
    let xs = Tensor::randn(0f32, 1.0, (640, k), &dev).unwrap();
    let dys = Tensor::randn(0f32, 1.0, (640, n), &dev).unwrap();
    time("wgrad xs.t() @ dys (view)", &xs.t().unwrap(), &dys);
    time("wgrad xs.t().contiguous() @ dys", &xs.t().unwrap().contiguous().unwrap(), &dys);
    time("wgrad dys.t() @ xs (view)", &dys.t().unwrap(), &xs);
    time("wgrad dys.t().contiguous() @ xs", &dys.t().unwrap().contiguous().unwrap(), &xs);
    let t0 = Instant::now();
    for _ in 0..20 {
        let _ = w.t().unwrap().contiguous().unwrap();
    }
    println!("transpose copy of W: {:.1} us", t0.elapsed().as_secs_f64() / 20.0 * 1e6);
}
