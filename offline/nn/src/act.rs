//! A fused bias + activation + dropout: one custom op forward and one backward in place of the
//! bias broadcast, the activation (SELU alone is an `elu` and a scale forward, and half a dozen
//! masks, exponentials and products backward) and the dropout product, each with its own output
//! buffer. At the ARNN's shapes (8-16 rows of 10-100 units, six such layers per frame) those ops
//! cost more than their matmuls (issue 18).
//!
//! [`bias_add`] is the same op without activation (a linear layer's or a recurrent cell's bias).
//!
//! Tests: `fused_activation_equals_the_tensor_ops` (values and gradients within 1e-5 of the
//! tensor-op path, every activation, with and without bias and dropout, and the bias add).

use crate::layers::{Activation, SELU_ALPHA, SELU_SCALE};
use candle_core::{CpuStorage, CustomOp1, CustomOp2, DType, Layout, Result, Shape, Tensor};
use std::borrow::Cow;

/// The activation of `z` and its derivative (`None`: the identity).
#[inline]
pub(crate) fn act(a: Option<Activation>, z: f32) -> (f32, f32) {
    let Some(a) = a else { return (z, 1.0) };
    match a {
        Activation::Relu => {
            if z > 0.0 {
                (z, 1.0)
            } else {
                (0.0, 0.0)
            }
        }
        Activation::LeakyRelu(alpha) => {
            if z >= 0.0 {
                (z, 1.0)
            } else {
                (alpha as f32 * z, alpha as f32)
            }
        }
        Activation::Selu => {
            let (s, a) = (SELU_SCALE as f32, SELU_ALPHA as f32);
            if z > 0.0 {
                (s * z, s)
            } else {
                let e = z.exp();
                (s * a * (e - 1.0), s * a * e)
            }
        }
    }
}

/// The values of an f32 CPU storage in row-major order: borrowed when contiguous, gathered
/// when a 2-D layout is strided (a transposed view); `what` names the input in the error for
/// other layouts.
pub(crate) fn values<'a>(s: &'a CpuStorage, l: &Layout, what: &str) -> Result<Cow<'a, [f32]>> {
    let v = s.as_slice::<f32>()?;
    if let Some((a, b)) = l.contiguous_offsets() {
        return Ok(Cow::Borrowed(&v[a..b]));
    }
    let Ok((r, c)) = l.shape().dims2() else { candle_core::bail!("fused op: a non-contiguous {what} {:?}", l.dims()) };
    let (rs, cs, o) = (l.stride()[0], l.stride()[1], l.start_offset());
    Ok(Cow::Owned((0..r).flat_map(|i| (0..c).map(move |j| v[o + i * rs + j * cs])).collect()))
}

/// The values of an f32 tensor in row-major order.
pub(crate) fn tensor_values(t: &Tensor) -> Result<Vec<f32>> {
    t.flatten_all()?.to_vec1::<f32>()
}

/// The sums over the rows of `values` (rows of `n`), rows in order: a broadcast bias's gradient.
pub(crate) fn column_sums(values: &[f32], n: usize) -> Vec<f32> {
    let mut sums = vec![0f32; n];
    for row in values.chunks(n.max(1)) {
        for (s, v) in sums.iter_mut().zip(row) {
            *s += v;
        }
    }
    sums
}

/// `y * mask` with the mask's values in `y`'s shape (the dropout product).
pub(crate) fn apply_mask(y: &Tensor, mask: Vec<f32>) -> Result<Tensor> {
    y.mul(&Tensor::from_vec(mask, y.shape(), y.device())?.to_dtype(y.dtype())?)
}

/// `mask * act(x + bias)`; `bias` broadcast over the rows (the last dimension), the mask (the
/// dropout's, scale included) over every value.
pub(crate) struct BiasAct {
    pub(crate) act: Option<Activation>,
    pub(crate) mask: Option<Vec<f32>>,
}

impl BiasAct {
    /// Whether the op only adds the bias (no activation, no mask).
    pub(crate) fn is_bias_only(&self) -> bool {
        self.act.is_none() && self.mask.is_none()
    }

    pub(crate) fn forward(&self, x: &[f32], bias: Option<&[f32]>) -> Vec<f32> {
        let mut out = x.to_vec();
        self.forward_in_place(&mut out, bias);
        out
    }

    /// [`BiasAct::forward`] over `x` itself.
    pub(crate) fn forward_in_place(&self, x: &mut [f32], bias: Option<&[f32]>) {
        let n = bias.map_or(1, |b| b.len().max(1));
        for (i, v) in x.iter_mut().enumerate() {
            let z = bias.map_or(*v, |b| *v + b[i % n]);
            let y = act(self.act, z).0;
            *v = self.mask.as_ref().map_or(y, |m| y * m[i]);
        }
    }

    /// The gradient of the pre-activation `x + bias` from the output's.
    pub(crate) fn backward(&self, x: &[f32], bias: Option<&[f32]>, dy: &[f32]) -> Vec<f32> {
        let n = bias.map_or(1, |b| b.len().max(1));
        x.iter()
            .zip(dy)
            .enumerate()
            .map(|(i, (&v, &g))| {
                let z = bias.map_or(v, |b| v + b[i % n]);
                let g = self.mask.as_ref().map_or(g, |m| g * m[i]);
                g * act(self.act, z).1
            })
            .collect()
    }

    /// Refuses a mask whose length is not the output's `count` values.
    pub(crate) fn check(&self, count: usize) -> Result<()> {
        match &self.mask {
            Some(m) if m.len() != count => {
                candle_core::bail!("fused activation: a dropout mask of {} values for {count}", m.len())
            }
            _ => Ok(()),
        }
    }
}

impl CustomOp1 for BiasAct {
    fn name(&self) -> &'static str {
        "zoo-act"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        self.check(l.shape().elem_count())?;
        Ok((CpuStorage::F32(self.forward(&values(s, l, "input")?, None)), l.shape().clone()))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> Result<Option<Tensor>> {
        let dz = self.backward(&tensor_values(arg)?, None, &tensor_values(grad_res)?);
        Ok(Some(Tensor::from_vec(dz, arg.shape(), arg.device())?))
    }
}

impl CustomOp2 for BiasAct {
    fn name(&self) -> &'static str {
        "zoo-bias-act"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        self.check(l1.shape().elem_count())?;
        if l2.dims() != [*l1.dims().last().unwrap_or(&0)] {
            candle_core::bail!("fused activation: bias {:?} for values {:?}", l2.dims(), l1.dims())
        }
        let (x, b) = (values(s1, l1, "input")?, values(s2, l2, "bias")?);
        Ok((CpuStorage::F32(self.forward(&x, Some(&b))), l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        b: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let bias = tensor_values(b)?;
        let dz = self.backward(&tensor_values(x)?, Some(&bias), &tensor_values(grad_res)?);
        let db = column_sums(&dz, bias.len());
        Ok((Some(Tensor::from_vec(dz, x.shape(), x.device())?), Some(Tensor::from_vec(db, b.shape(), b.device())?)))
    }
}

/// `dropout(act(x + bias))` in one op when `x` is an f32 tensor on the CPU, with the tensor ops
/// otherwise. `mask` is the dropout's (scale included, [`crate::Dropout::mask`]), `None` when
/// no value is dropped.
pub fn bias_act(x: &Tensor, bias: Option<&Tensor>, a: Activation, mask: Option<Vec<f32>>) -> Result<Tensor> {
    let fused =
        x.dtype() == DType::F32 && x.device().is_cpu() && bias.is_none_or(|b| b.dtype() == DType::F32 && b.rank() == 1);
    if !fused {
        let z = match bias {
            Some(b) => x.broadcast_add(b)?,
            None => x.clone(),
        };
        let y = a.apply(&z)?;
        return match mask {
            Some(m) => apply_mask(&y, m),
            None => Ok(y),
        };
    }
    let op = BiasAct { act: Some(a), mask };
    let x = x.contiguous()?;
    match bias {
        Some(b) => x.apply_op2(&b.contiguous()?, op),
        None => x.apply_op1(op),
    }
}

/// `x + bias` (`bias` broadcast over the rows), one op forward and backward when `x` is an f32
/// tensor on the CPU (the bias gradient is one pass over the rows instead of candle's strided
/// reduction).
pub fn bias_add(x: &Tensor, bias: &Tensor) -> Result<Tensor> {
    if x.dtype() != DType::F32 || !x.device().is_cpu() || bias.dtype() != DType::F32 || bias.rank() != 1 {
        return x.broadcast_add(bias);
    }
    x.contiguous()?.apply_op2(&bias.contiguous()?, BiasAct { act: None, mask: None })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::tests::{close, var};
    use candle_core::Device;

    #[test]
    fn fused_activation_equals_the_tensor_ops() {
        let (rows, n) = (3, 7);
        let (x, b, w) = (var((rows, n), 0.2), var((1, n), -0.6), var((rows, n), 1.3));
        let bias = b.as_tensor().squeeze(0).unwrap();
        let mask: Vec<f32> = (0..rows * n).map(|i| if i % 3 == 0 { 0.0 } else { 1.25 }).collect();
        for a in [Activation::Selu, Activation::Relu, Activation::LeakyRelu(0.2)] {
            for with_bias in [false, true] {
                for m in [None, Some(mask.clone())] {
                    let what = format!("{a:?}, bias {with_bias}, mask {}", m.is_some());
                    let bias = with_bias.then_some(&bias);
                    let fused = bias_act(x.as_tensor(), bias, a, m.clone()).unwrap();
                    let mut ops = match bias {
                        Some(b) => a.apply(&x.as_tensor().broadcast_add(b).unwrap()).unwrap(),
                        None => a.apply(x.as_tensor()).unwrap(),
                    };
                    if let Some(m) = &m {
                        ops = ops.mul(&Tensor::from_vec(m.clone(), (rows, n), &Device::Cpu).unwrap()).unwrap();
                    }
                    close(&fused, &ops, &format!("{what}: values"));
                    let loss = |y: &Tensor| (y * w.as_tensor()).unwrap().sum_all().unwrap().backward().unwrap();
                    let (ga, gb) = (loss(&fused), loss(&ops));
                    close(ga.get(x.as_tensor()).unwrap(), gb.get(x.as_tensor()).unwrap(), &format!("{what}: dx"));
                    if with_bias {
                        close(ga.get(b.as_tensor()).unwrap(), gb.get(b.as_tensor()).unwrap(), &format!("{what}: db"));
                    }
                }
            }
        }
        let fused = bias_add(x.as_tensor(), &bias).unwrap();
        let ops = x.as_tensor().broadcast_add(&bias).unwrap();
        close(&fused, &ops, "bias add: values");
        let loss = |y: &Tensor| (y * w.as_tensor()).unwrap().sum_all().unwrap().backward().unwrap();
        let (ga, gb) = (loss(&fused), loss(&ops));
        close(ga.get(x.as_tensor()).unwrap(), gb.get(x.as_tensor()).unwrap(), "bias add: dx");
        close(ga.get(b.as_tensor()).unwrap(), gb.get(b.as_tensor()).unwrap(), "bias add: db");
    }
}
