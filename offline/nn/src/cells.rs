//! Fused recurrent cells: one custom op per LSTM or GRU step, forward and backward, in place of
//! the dozen elementwise candle ops (each with its own output buffer, and as many again in the
//! backward pass) that a cell step is built from. At the zoo's shapes (16-64 rows of 100-512
//! units) those ops cost more than the step's matmuls (issue 18); the fused step reads its
//! inputs once and writes one output.
//!
//! The formulas are PyTorch's (see [`crate::recurrent`]): LSTM gates i, f, g, o; GRU gates r,
//! z, n with the reset gate applied to the hidden projection (`linear_before_reset`). Tests:
//! `fused_cells_equal_the_tensor_op_cells` (values and gradients within 1e-5 of the candle-op
//! cells).

use crate::act::{tensor_values, values};
use candle_core::{CpuStorage, CustomOp2, CustomOp3, Layout, Result, Shape, Tensor};

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

struct LstmCell;

impl CustomOp2 for LstmCell {
    fn name(&self) -> &'static str {
        "zoo-lstm-cell"
    }

    /// `g` `(B, 4H)` (the summed gate pre-activations), `c` `(B, H)` -> `[h'; c']` `(2, B, H)`
    /// (so that both halves are contiguous).
    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, g4) = l1.shape().dims2()?;
        let (b2, hu) = l2.shape().dims2()?;
        if b != b2 || g4 != 4 * hu {
            candle_core::bail!("LSTM cell: gates {:?} and cell state {:?} do not match", l1.dims(), l2.dims());
        }
        let (g, c) = (values(s1, l1, "cell input")?, values(s2, l2, "cell input")?);
        let mut out = vec![0f32; 2 * b * hu];
        let (hs, cs) = out.split_at_mut(b * hu);
        for r in 0..b {
            let (g, c) = (&g[r * g4..(r + 1) * g4], &c[r * hu..(r + 1) * hu]);
            for k in 0..hu {
                let (i, f, gg, og) = (sigmoid(g[k]), sigmoid(g[hu + k]), g[2 * hu + k].tanh(), sigmoid(g[3 * hu + k]));
                let c2 = f * c[k] + i * gg;
                cs[r * hu + k] = c2;
                hs[r * hu + k] = og * c2.tanh();
            }
        }
        Ok((CpuStorage::F32(out), Shape::from((2, b, hu))))
    }

    fn bwd(&self, g: &Tensor, c: &Tensor, res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let (b, hu) = c.dims2()?;
        let dev = res.device().clone();
        // `res` and `grad` are `(2, B, H)`: h' then c'.
        let (g, c, res, grad) = (tensor_values(g)?, tensor_values(c)?, tensor_values(res)?, tensor_values(grad)?);
        let (mut dg, mut dc) = (vec![0f32; b * 4 * hu], vec![0f32; b * hu]);
        for r in 0..b {
            let gr = &g[r * 4 * hu..(r + 1) * 4 * hu];
            let cr = &c[r * hu..(r + 1) * hu];
            let (dgr, dcr) = (&mut dg[r * 4 * hu..(r + 1) * 4 * hu], &mut dc[r * hu..(r + 1) * hu]);
            for k in 0..hu {
                let (i, f, gg, og) =
                    (sigmoid(gr[k]), sigmoid(gr[hu + k]), gr[2 * hu + k].tanh(), sigmoid(gr[3 * hu + k]));
                let tc = res[b * hu + r * hu + k].tanh();
                let (dh, dc2_out) = (grad[r * hu + k], grad[b * hu + r * hu + k]);
                let dc2 = dc2_out + dh * og * (1.0 - tc * tc);
                dgr[k] = dc2 * gg * i * (1.0 - i);
                dgr[hu + k] = dc2 * cr[k] * f * (1.0 - f);
                dgr[2 * hu + k] = dc2 * i * (1.0 - gg * gg);
                dgr[3 * hu + k] = dh * tc * og * (1.0 - og);
                dcr[k] = dc2 * f;
            }
        }
        Ok((Some(Tensor::from_vec(dg, (b, 4 * hu), &dev)?), Some(Tensor::from_vec(dc, (b, hu), &dev)?)))
    }
}

/// One LSTM step from the summed gate pre-activations `g = W x + b_i + U h + b_h` `(B, 4H)`
/// (gates i, f, g, o) and the cell state `c` `(B, H)`: returns `(h', c')`, each `(B, H)`.
///
/// f32 tensors run the fused op; other dtypes (the f64 gradient checks) the tensor ops.
pub fn lstm_cell(g: &Tensor, c: &Tensor) -> Result<(Tensor, Tensor)> {
    if g.dtype() != candle_core::DType::F32 || c.dtype() != candle_core::DType::F32 {
        return lstm_ops(g, c);
    }
    let hc = g.apply_op2(c, LstmCell)?;
    Ok((hc.get(0)?, hc.get(1)?))
}

/// [`lstm_cell`] with candle's tensor ops.
fn lstm_ops(g: &Tensor, c: &Tensor) -> Result<(Tensor, Tensor)> {
    let hu = c.dim(1)?;
    let i = candle_nn::ops::sigmoid(&g.narrow(1, 0, hu)?)?;
    let f = candle_nn::ops::sigmoid(&g.narrow(1, hu, hu)?)?;
    let gg = g.narrow(1, 2 * hu, hu)?.tanh()?;
    let o = candle_nn::ops::sigmoid(&g.narrow(1, 3 * hu, hu)?)?;
    let c2 = ((f * c)? + (i * gg)?)?;
    Ok(((o * c2.tanh()?)?, c2))
}

struct GruCell;

impl CustomOp3 for GruCell {
    fn name(&self) -> &'static str {
        "zoo-gru-cell"
    }

    /// `gx` `(B, 3H)` (`W x + b_i`), `gh` `(B, 3H)` (`U h + b_h`), `h` `(B, H)` -> `h'` `(B, H)`.
    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (b, g3) = l1.shape().dims2()?;
        let (b3, hu) = l3.shape().dims2()?;
        if l2.dims() != l1.dims() || b3 != b || g3 != 3 * hu {
            candle_core::bail!("GRU cell: {:?}, {:?} and {:?} do not match", l1.dims(), l2.dims(), l3.dims());
        }
        let (gx, gh, h) = (values(s1, l1, "cell input")?, values(s2, l2, "cell input")?, values(s3, l3, "cell input")?);
        let mut out = vec![0f32; b * hu];
        for r in 0..b {
            let (x, y, hr) = (&gx[r * g3..(r + 1) * g3], &gh[r * g3..(r + 1) * g3], &h[r * hu..(r + 1) * hu]);
            for k in 0..hu {
                let rg = sigmoid(x[k] + y[k]);
                let z = sigmoid(x[hu + k] + y[hu + k]);
                let n = (x[2 * hu + k] + rg * y[2 * hu + k]).tanh();
                out[r * hu + k] = (1.0 - z) * n + z * hr[k];
            }
        }
        Ok((CpuStorage::F32(out), Shape::from((b, hu))))
    }

    fn bwd(
        &self,
        gx: &Tensor,
        gh: &Tensor,
        h: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let (b, hu) = h.dims2()?;
        let g3 = 3 * hu;
        let (x, y, hv, d) = (tensor_values(gx)?, tensor_values(gh)?, tensor_values(h)?, tensor_values(grad)?);
        let (mut dx, mut dy, mut dh) = (vec![0f32; b * g3], vec![0f32; b * g3], vec![0f32; b * hu]);
        for r in 0..b {
            let (xr, yr) = (&x[r * g3..(r + 1) * g3], &y[r * g3..(r + 1) * g3]);
            for k in 0..hu {
                let rg = sigmoid(xr[k] + yr[k]);
                let z = sigmoid(xr[hu + k] + yr[hu + k]);
                let n = (xr[2 * hu + k] + rg * yr[2 * hu + k]).tanh();
                let dout = d[r * hu + k];
                let da_n = dout * (1.0 - z) * (1.0 - n * n);
                let da_z = dout * (hv[r * hu + k] - n) * z * (1.0 - z);
                let da_r = da_n * yr[2 * hu + k] * rg * (1.0 - rg);
                dx[r * g3 + k] = da_r;
                dy[r * g3 + k] = da_r;
                dx[r * g3 + hu + k] = da_z;
                dy[r * g3 + hu + k] = da_z;
                dx[r * g3 + 2 * hu + k] = da_n;
                dy[r * g3 + 2 * hu + k] = da_n * rg;
                dh[r * hu + k] = dout * z;
            }
        }
        let dev = h.device();
        Ok((
            Some(Tensor::from_vec(dx, (b, g3), dev)?),
            Some(Tensor::from_vec(dy, (b, g3), dev)?),
            Some(Tensor::from_vec(dh, (b, hu), dev)?),
        ))
    }
}

/// One GRU step from the input projection `gx = W x + b_i` `(B, 3H)`, the hidden projection
/// `gh = U h + b_h` `(B, 3H)` (gates r, z, n) and the state `h` `(B, H)`: returns `h'` `(B, H)`.
///
/// f32 tensors run the fused op; other dtypes (the f64 gradient checks) the tensor ops.
pub fn gru_cell(gx: &Tensor, gh: &Tensor, h: &Tensor) -> Result<Tensor> {
    if [gx, gh, h].iter().any(|t| t.dtype() != candle_core::DType::F32) {
        return gru_ops(gx, gh, h);
    }
    gx.apply_op3(gh, h, GruCell)
}

/// [`gru_cell`] with candle's tensor ops.
fn gru_ops(gx: &Tensor, gh: &Tensor, h: &Tensor) -> Result<Tensor> {
    let hu = h.dim(1)?;
    let r = candle_nn::ops::sigmoid(&(gx.narrow(1, 0, hu)? + gh.narrow(1, 0, hu)?)?)?;
    let z = candle_nn::ops::sigmoid(&(gx.narrow(1, hu, hu)? + gh.narrow(1, hu, hu)?)?)?;
    let n = (gx.narrow(1, 2 * hu, hu)? + (r * gh.narrow(1, 2 * hu, hu)?)?)?.tanh()?;
    ((z.ones_like()? - &z)? * n)?.add(&(z * h)?)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use candle_core::{Device, Var};

    /// A variable of `shape` holding `2.5 sin(0.37 i + phase)`.
    pub(crate) fn var(shape: (usize, usize), phase: f64) -> Var {
        let n = shape.0 * shape.1;
        let t = Tensor::arange(0f32, n as f32, &Device::Cpu).unwrap().affine(0.37, phase).unwrap().sin().unwrap();
        Var::from_tensor(&(t * 2.5).unwrap().reshape(shape).unwrap()).unwrap()
    }

    /// `a` and `b` agree within 1e-5 of `a`'s largest value.
    pub(crate) fn close(a: &Tensor, b: &Tensor, what: &str) {
        let a = a.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let b = b.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let scale = a.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-5 * scale, "{what}: {x} vs {y}");
        }
    }

    #[test]
    fn fused_cells_equal_the_tensor_op_cells() {
        let (b, hu) = (3, 5);
        // LSTM, the next step's inputs as views (as the layers feed them).
        let (g, c) = (var((b, 4 * hu), 0.1), var((b, 2 * hu), -0.4));
        let cv = c.as_tensor().narrow(1, hu, hu).unwrap();
        let (h1, c1) = lstm_cell(g.as_tensor(), &cv).unwrap();
        let (h2, c2) = lstm_ops(g.as_tensor(), &cv).unwrap();
        close(&h1, &h2, "lstm h");
        close(&c1, &c2, "lstm c");
        let w = var((b, hu), 0.7);
        let loss = |h: &Tensor, c: &Tensor| {
            ((h * w.as_tensor()).unwrap().sum_all().unwrap() + c.sqr().unwrap().sum_all().unwrap()).unwrap()
        };
        let (ga, gb) = (loss(&h1, &c1).backward().unwrap(), loss(&h2, &c2).backward().unwrap());
        for v in [&g, &c] {
            close(ga.get(v.as_tensor()).unwrap(), gb.get(v.as_tensor()).unwrap(), "lstm gradient");
        }
        // GRU.
        let (gx, gh, h) = (var((b, 3 * hu), 0.3), var((b, 3 * hu), 1.1), var((b, hu), -0.9));
        let o1 = gru_cell(gx.as_tensor(), gh.as_tensor(), h.as_tensor()).unwrap();
        let o2 = gru_ops(gx.as_tensor(), gh.as_tensor(), h.as_tensor()).unwrap();
        close(&o1, &o2, "gru h");
        let (ga, gb) = (
            (&o1 * w.as_tensor()).unwrap().sum_all().unwrap().backward().unwrap(),
            (&o2 * w.as_tensor()).unwrap().sum_all().unwrap().backward().unwrap(),
        );
        for v in [&gx, &gh, &h] {
            close(ga.get(v.as_tensor()).unwrap(), gb.get(v.as_tensor()).unwrap(), "gru gradient");
        }
    }
}
