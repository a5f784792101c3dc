//! Fused CPU kernels for hot element-wise ops (candle's `leaky_relu` is five ops forward and
//! more backward; one pass each way here).

use candle_core::{CpuStorage, CustomOp1, CustomOp2, DType, Layout, Result, Shape, Tensor};

struct LeakyRelu(f32);

struct LeakyReluGrad(f32);

fn contiguous_f32<'a>(s: &'a CpuStorage, l: &Layout) -> Result<&'a [f32]> {
    match (s, l.contiguous_offsets()) {
        (CpuStorage::F32(v), Some((a, b))) => Ok(&v[a..b]),
        _ => candle_core::bail!("leaky_relu kernel expects contiguous f32 tensors"),
    }
}

impl CustomOp1 for LeakyRelu {
    fn name(&self) -> &'static str {
        "leaky-relu"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = contiguous_f32(s, l)?;
        let a = self.0;
        let y: Vec<f32> = x.iter().map(|&v| if v > 0.0 { v } else { v * a }).collect();
        Ok((CpuStorage::F32(y), l.shape().clone()))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(arg.apply_op2_no_bwd(&grad.contiguous()?, &LeakyReluGrad(self.0))?))
    }
}

impl CustomOp2 for LeakyReluGrad {
    fn name(&self) -> &'static str {
        "leaky-relu-grad"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (x, g) = (contiguous_f32(s1, l1)?, contiguous_f32(s2, l2)?);
        let a = self.0;
        let y: Vec<f32> = x.iter().zip(g).map(|(&v, &g)| if v > 0.0 { g } else { g * a }).collect();
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }
}

/// Leaky ReLU `max(x, 0) + slope * min(x, 0)`; one fused pass on CPU f32, candle's version elsewhere.
pub fn leaky_relu(x: &Tensor, slope: f64) -> Result<Tensor> {
    if x.device().is_cpu() && x.dtype() == DType::F32 {
        x.contiguous()?.apply_op1(LeakyRelu(slope as f32))
    } else {
        candle_nn::ops::leaky_relu(x, slope)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn fused_leaky_relu_matches_candle_forward_and_backward() -> Result<()> {
        let x = Var::from_vec(vec![-2.0f32, -0.5, 0.0, 0.5, 3.0, -1.0], (2, 3), &Device::Cpu)?;
        let w = Tensor::new(&[[1.0f32, 2.0, 3.0], [4.0, 5.0, 6.0]], &Device::Cpu)?;
        let a = leaky_relu(x.as_tensor(), 0.1)?;
        let b = candle_nn::ops::leaky_relu(x.as_tensor(), 0.1)?;
        assert_eq!(a.to_vec2::<f32>()?, b.to_vec2::<f32>()?);
        let ga = a.mul(&w)?.sum_all()?.backward()?;
        let ga = ga.get(&x).unwrap().to_vec2::<f32>()?;
        assert_eq!(ga, vec![vec![0.1, 0.2, 0.3], vec![4.0, 5.0, 0.6]]);
        Ok(())
    }
}
