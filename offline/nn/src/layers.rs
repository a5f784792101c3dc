//! Feed-forward layers: a multi-layer perceptron with a chosen activation, and seeded dropout.

use crate::rng::SplitMix64;
use candle_core::{Module, Result, Tensor};
use candle_nn::{Linear, VarBuilder};

/// The activation of an [`Mlp`]'s hidden layers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Activation {
    /// `max(x, 0) + alpha * min(x, 0)`.
    LeakyRelu(f64),
    /// `max(x, 0)`.
    Relu,
    /// SELU (Klambauer et al. 2017, eq. 2): `scale * (x if x > 0 else alpha * (exp(x) - 1))`,
    /// with `alpha = 1.6732632423543772` and `scale = 1.0507009873554805`.
    Selu,
}

/// SELU's `alpha`.
pub const SELU_ALPHA: f64 = 1.673_263_242_354_377_2;
/// SELU's `scale`.
pub const SELU_SCALE: f64 = 1.050_700_987_355_480_5;

impl Activation {
    /// Applies the activation element-wise.
    pub fn apply(&self, x: &Tensor) -> Result<Tensor> {
        match *self {
            Activation::LeakyRelu(alpha) => crate::ops::leaky_relu(x, alpha),
            Activation::Relu => x.relu(),
            Activation::Selu => x.elu(SELU_ALPHA)? * SELU_SCALE,
        }
    }
}

/// A stack of linear layers `input -> widths[0] -> ... -> widths[n-1]`; every layer but the last
/// is followed by the activation, the last one only when `activate_last`.
///
/// Tensor names: `{prefix}.{i}.weight` `(widths[i], fan_in)` and `{prefix}.{i}.bias`, candle's
/// `Linear` initialisation. Input `(..., input)`, output `(..., widths[n-1])`.
#[derive(Clone, Debug)]
pub struct Mlp {
    layers: Vec<Linear>,
    activation: Activation,
    activate_last: bool,
}

impl Mlp {
    /// Builds (or loads, depending on `vb`) the layers.
    pub fn new(
        input: usize,
        widths: &[usize],
        activation: Activation,
        activate_last: bool,
        vb: VarBuilder,
    ) -> Result<Self> {
        let mut layers = Vec::with_capacity(widths.len());
        let mut prev = input;
        for (i, &w) in widths.iter().enumerate() {
            layers.push(candle_nn::linear(prev, w, vb.pp(i))?);
            prev = w;
        }
        Ok(Mlp { layers, activation, activate_last })
    }

    /// The linear layers, input side first.
    pub fn layers(&self) -> &[Linear] {
        &self.layers
    }

    /// Output size (0 without layers).
    pub fn out_dim(&self) -> usize {
        self.layers.last().map_or(0, |l| l.weight().dim(0).unwrap_or(0))
    }

    /// The forward pass with dropout after each activated layer: `rng` `Some` in training,
    /// `None` at evaluation (then equal to [`Module::forward`]).
    pub fn forward_dropout(&self, x: &Tensor, dropout: &Dropout, mut rng: Option<&mut RowRngs>) -> Result<Tensor> {
        let n = self.layers.len();
        let mut h = x.clone();
        for (i, l) in self.layers.iter().enumerate() {
            h = if i + 1 < n || self.activate_last {
                linear_act(l, &h, self.activation, dropout, rng.as_deref_mut())?
            } else {
                linear_forward(l, &h)?
            };
        }
        Ok(h)
    }
}

/// A linear layer's forward pass; for a 2-D input the weight goes through
/// [`crate::tape::matmul_weight`] (taped while a data-parallel worker collects tapes).
pub fn linear_forward(l: &Linear, x: &Tensor) -> Result<Tensor> {
    if x.rank() != 2 {
        return l.forward(x);
    }
    match l.bias() {
        Some(b) => crate::tape::linear(x, l.weight(), b, None, None),
        None => crate::tape::matmul_weight(x, l.weight(), true),
    }
}

/// `dropout(act(linear(x)))`: for a 2-D input one op in training ([`crate::tape::linear`]), the
/// matmul and one fused bias, activation and dropout op otherwise.
pub fn linear_act(
    l: &Linear,
    x: &Tensor,
    act: Activation,
    dropout: &Dropout,
    rng: Option<&mut RowRngs>,
) -> Result<Tensor> {
    if x.rank() != 2 {
        return dropout.forward(&act.apply(&l.forward(x)?)?, rng);
    }
    let rows = x.dim(0)?;
    let mask = dropout.mask_of(rows, rows * l.weight().dim(0)?, rng)?;
    match l.bias() {
        Some(b) => crate::tape::linear(x, l.weight(), b, Some(act), mask),
        None => crate::act::bias_act(&crate::tape::matmul_weight(x, l.weight(), true)?, None, act, mask),
    }
}

impl Module for Mlp {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_dropout(x, &Dropout::new(0.0), None)
    }
}

/// The dropout generators of one training step: one stream per sample of the batch, sample `i`
/// (its index in the whole batch) drawing from `SplitMix64::with_stream(seed, i)`. A sample's
/// masks therefore do not depend on the data-parallel shard it lands in, so a step over two
/// workers draws what one worker would ([`crate::parallel`]).
#[derive(Clone, Debug)]
pub struct RowRngs {
    streams: Vec<SplitMix64>,
}

impl RowRngs {
    /// The streams of the samples `rows` of a batch whose step drew `seed`.
    pub fn new(seed: u64, rows: std::ops::Range<usize>) -> Self {
        RowRngs { streams: rows.map(|i| SplitMix64::with_stream(seed, i as u64)).collect() }
    }

    /// The number of samples (rows).
    pub fn rows(&self) -> usize {
        self.streams.len()
    }
}

/// Inverted dropout: in training each value is zeroed with probability `p` and the others are
/// scaled by `1 / (1 - p)`; at evaluation it is the identity. The masks are drawn from the
/// step's per-sample generators, so a seeded run is reproducible, a resumed run draws the same
/// masks and the thread count does not change them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dropout {
    p: f64,
}

impl Dropout {
    /// Dropout with drop probability `p`, clamped to `[0, 1)`.
    pub fn new(p: f64) -> Self {
        Dropout { p: p.clamp(0.0, 1.0 - 1e-9) }
    }

    /// The drop probability.
    pub fn p(&self) -> f64 {
        self.p
    }

    /// Applies dropout to a batch-first `x` (`(batch, ...)`): training when `rng` is `Some`
    /// (sample `i` draws its values, row-major, from its own stream), identity when `None` or
    /// `p == 0`.
    pub fn forward(&self, x: &Tensor, rng: Option<&mut RowRngs>) -> Result<Tensor> {
        match self.mask(x, rng)? {
            Some(mask) => crate::act::apply_mask(x, mask),
            None => Ok(x.clone()),
        }
    }

    /// The mask [`Dropout::forward`] multiplies `x` by (0 or `1 / (1 - p)` per value, row-major),
    /// drawn from the generators; `None` at evaluation or when `p == 0` (nothing is drawn).
    pub fn mask(&self, x: &Tensor, rng: Option<&mut RowRngs>) -> Result<Option<Vec<f32>>> {
        self.mask_of(x.dim(0)?, x.elem_count(), rng)
    }

    /// [`Dropout::mask`] for a batch-first tensor of `rows` samples and `count` values.
    pub fn mask_of(&self, rows: usize, count: usize, rng: Option<&mut RowRngs>) -> Result<Option<Vec<f32>>> {
        let Some(rng) = rng else { return Ok(None) };
        if self.p == 0.0 {
            return Ok(None);
        }
        if rows != rng.rows() {
            candle_core::bail!("dropout: {rows} samples in the batch, {} generators", rng.rows());
        }
        let per_row = count / rows.max(1);
        let keep = (1.0 / (1.0 - self.p)) as f32;
        let mut mask = Vec::with_capacity(count);
        for s in rng.streams.iter_mut() {
            mask.extend((0..per_row).map(|_| if s.next_f64() < self.p { 0.0 } else { keep }));
        }
        Ok(Some(mask))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::init::SeededVarMap;
    use candle_core::{DType, Device};
    use candle_nn::VarMap;

    #[test]
    fn mlp_names_shapes_and_activations() -> Result<()> {
        let vm = VarMap::new();
        let vb = SeededVarMap::builder(&vm, 1, DType::F32, &Device::Cpu);
        let mlp = Mlp::new(3, &[8, 5], Activation::Relu, false, vb.pp("enc"))?;
        let mut names: Vec<String> = vm.data().lock().unwrap().keys().cloned().collect();
        names.sort();
        assert_eq!(names, ["enc.0.bias", "enc.0.weight", "enc.1.bias", "enc.1.weight"]);
        assert_eq!(mlp.out_dim(), 5);
        let x = Tensor::ones((2, 3), DType::F32, &Device::Cpu)?;
        let y = mlp.forward(&x)?;
        assert_eq!(y.dims(), &[2, 5]);
        // Hand-computed: relu(x W0^T + b0) W1^T + b1, the last layer not activated.
        let data = vm.data().lock().unwrap();
        let w = |n: &str| data[n].as_tensor().clone();
        let h = x.matmul(&w("enc.0.weight").t()?)?.broadcast_add(&w("enc.0.bias"))?.relu()?;
        let want = h.matmul(&w("enc.1.weight").t()?)?.broadcast_add(&w("enc.1.bias"))?;
        assert_eq!(y.to_vec2::<f32>()?, want.to_vec2::<f32>()?);
        Ok(())
    }

    #[test]
    fn activations_match_their_formulas() -> Result<()> {
        let x = Tensor::new(&[-2.0f64, -0.5, 0.0, 1.5], &Device::Cpu)?;
        let leaky = Activation::LeakyRelu(0.1).apply(&x)?.to_vec1::<f64>()?;
        assert_eq!(leaky, [-0.2, -0.05, 0.0, 1.5]);
        assert_eq!(Activation::Relu.apply(&x)?.to_vec1::<f64>()?, [0.0, 0.0, 0.0, 1.5]);
        let selu = Activation::Selu.apply(&x)?.to_vec1::<f64>()?;
        for (got, v) in selu.iter().zip([-2.0f64, -0.5, 0.0, 1.5]) {
            let want = SELU_SCALE * if v > 0.0 { v } else { SELU_ALPHA * (v.exp() - 1.0) };
            assert!((got - want).abs() < 1e-12, "selu({v}) = {got}, want {want}");
        }
        Ok(())
    }

    #[test]
    fn dropout_is_seeded_scaled_and_off_in_evaluation() -> Result<()> {
        let x = Tensor::ones((100, 100), DType::F32, &Device::Cpu)?;
        let d = Dropout::new(0.25);
        assert_eq!(d.forward(&x, None)?.to_vec2::<f32>()?, x.to_vec2::<f32>()?);
        let a = d.forward(&x, Some(&mut RowRngs::new(3, 0..100)))?.flatten_all()?.to_vec1::<f32>()?;
        let b = d.forward(&x, Some(&mut RowRngs::new(3, 0..100)))?.flatten_all()?.to_vec1::<f32>()?;
        let c = d.forward(&x, Some(&mut RowRngs::new(4, 0..100)))?.flatten_all()?.to_vec1::<f32>()?;
        assert_eq!(a, b);
        assert_ne!(a, c);
        // A shard of the batch draws its samples' masks: the same as the whole batch's rows.
        let tail =
            d.forward(&x.narrow(0, 60, 40)?, Some(&mut RowRngs::new(3, 60..100)))?.flatten_all()?.to_vec1::<f32>()?;
        assert_eq!(tail, a[60 * 100..]);
        assert!(d.forward(&x, Some(&mut RowRngs::new(3, 0..99))).unwrap_err().to_string().contains("99 generators"));
        let dropped = a.iter().filter(|&&v| v == 0.0).count() as f64 / a.len() as f64;
        assert!((dropped - 0.25).abs() < 0.02, "dropped {dropped}");
        assert!(a.iter().all(|&v| v == 0.0 || (v - 4.0 / 3.0).abs() < 1e-6));
        Ok(())
    }
}
