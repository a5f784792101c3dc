//! Seeded weight initialisation.
//!
//! candle's CPU `randn`/`rand` draw from an unseeded thread generator, so two runs with one seed
//! start from different weights. [`SeededVarMap`] is a [`VarBuilder`] backend around a [`VarMap`]
//! that creates each missing variable from its [`Init`] hint with values drawn from
//! `SplitMix64::with_stream(seed, fnv1a(name))`: the weights depend on the seed and the variable
//! name only, not on the order in which layers are built. The variables live in the `VarMap`, so
//! they are saved, loaded and optimised the usual way.

use crate::rng::SplitMix64;
use candle_core::{DType, Device, Result, Shape, Tensor, Var};
use candle_nn::init::NormalOrUniform;
use candle_nn::var_builder::SimpleBackend;
use candle_nn::{Init, VarBuilder, VarMap};

/// FNV-1a 64 of a variable name: the stream of its generator (stable across platforms and
/// Rust versions, unlike `std`'s hasher).
pub fn name_stream(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3))
}

/// Values of a new variable named `name` of `shape` initialised as `init` with `seed`
/// (row-major, as `f64`).
pub fn init_values(init: Init, shape: &Shape, name: &str, seed: u64) -> Vec<f64> {
    let n = shape.elem_count();
    let mut rng = SplitMix64::with_stream(seed, name_stream(name));
    let uniform = |rng: &mut SplitMix64, lo: f64, up: f64| (0..n).map(|_| rng.range(lo, up)).collect::<Vec<_>>();
    let normal =
        |rng: &mut SplitMix64, mean: f64, std: f64| (0..n).map(|_| mean + std * rng.normal()).collect::<Vec<_>>();
    match init {
        Init::Const(v) => vec![v; n],
        Init::Uniform { lo, up } => uniform(&mut rng, lo, up),
        Init::Randn { mean, stdev } => normal(&mut rng, mean, stdev),
        Init::Kaiming { dist, fan, non_linearity } => {
            let std = non_linearity.gain() / (fan.for_shape(shape) as f64).sqrt();
            match dist {
                NormalOrUniform::Uniform => {
                    let bound = 3f64.sqrt() * std;
                    uniform(&mut rng, -bound, bound)
                }
                NormalOrUniform::Normal => normal(&mut rng, 0.0, std),
            }
        }
    }
}

/// A [`VarMap`] whose missing variables are created with seeded values (see the module docs).
#[derive(Clone)]
pub struct SeededVarMap {
    varmap: VarMap,
    seed: u64,
}

impl SeededVarMap {
    /// Creates missing variables of `varmap` with `seed`; existing ones are returned as they are.
    pub fn new(varmap: VarMap, seed: u64) -> Self {
        SeededVarMap { varmap, seed }
    }

    /// A [`VarBuilder`] over `varmap` that initialises missing variables with `seed`.
    pub fn builder(varmap: &VarMap, seed: u64, dtype: DType, device: &Device) -> VarBuilder<'static> {
        VarBuilder::from_backend(Box::new(SeededVarMap::new(varmap.clone(), seed)), dtype, device.clone())
    }

    /// The variables.
    pub fn varmap(&self) -> &VarMap {
        &self.varmap
    }
}

/// Bytes a trained weight holds: itself, its gradient and Adam's two moments, f32 each.
const BYTES_PER_TRAINED_WEIGHT: u64 = 16;

/// Refuses a variable of `new` values when the model's `held` values and it, trained (weight,
/// gradient, optimizer state), would pass the memory bound (`zoo_data::limits::memory_bound`):
/// checked before the variable is allocated, so that a width typed too large is an error that
/// names it, not an abort of the process.
fn check_memory(held: u64, new: u64) -> Result<()> {
    let need = held.saturating_add(new).saturating_mul(BYTES_PER_TRAINED_WEIGHT);
    let bound = zoo_data::limits::memory_bound();
    if need > bound {
        candle_core::bail!(
            "the network's {} weights need {:.2} GB with their gradients and the optimizer's state, past the \
             memory bound of {:.2} GB: make the network smaller (its widths, e.g. --hidden), or raise the bound \
             with the environment variable ZOO_MEMORY_GB=N",
            held.saturating_add(new),
            need as f64 / 1e9,
            bound as f64 / 1e9
        );
    }
    Ok(())
}

impl SimpleBackend for SeededVarMap {
    fn get(&self, shape: Shape, name: &str, init: Init, dtype: DType, dev: &Device) -> Result<Tensor> {
        let mut data = self.varmap.data().lock().expect("the VarMap lock is not poisoned");
        if let Some(var) = data.get(name) {
            if var.shape() != &shape {
                candle_core::bail!("shape mismatch on {name}: asked for {shape:?}, the variable has {:?}", var.shape())
            }
            return Ok(var.as_tensor().clone());
        }
        check_memory(data.values().map(|v| v.elem_count() as u64).sum::<u64>(), shape.elem_count() as u64)?;
        let values = init_values(init, &shape, name, self.seed);
        let tensor = Tensor::from_vec(values, shape, dev)?.to_dtype(dtype)?;
        let var = Var::from_tensor(&tensor)?;
        let out = var.as_tensor().clone();
        data.insert(name.to_string(), var);
        Ok(out)
    }

    fn get_unchecked(&self, name: &str, _dtype: DType, _dev: &Device) -> Result<Tensor> {
        let data = self.varmap.data().lock().expect("the VarMap lock is not poisoned");
        match data.get(name) {
            Some(v) => Ok(v.as_tensor().clone()),
            None => candle_core::bail!("no variable `{name}`: create it with a shape and an initialisation"),
        }
    }

    fn contains_tensor(&self, name: &str) -> bool {
        self.varmap.data().lock().expect("the VarMap lock is not poisoned").contains_key(name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_nn::init::{DEFAULT_KAIMING_NORMAL, FanInOut, NonLinearity};

    fn build(seed: u64, order: &[&str]) -> VarMap {
        let vm = VarMap::new();
        let vb = SeededVarMap::builder(&vm, seed, DType::F32, &Device::Cpu);
        for name in order {
            vb.get_with_hints((64, 32), name, Init::Randn { mean: 0.5, stdev: 2.0 }).unwrap();
        }
        vm
    }

    fn values(vm: &VarMap, name: &str) -> Vec<f32> {
        vm.data().lock().unwrap()[name].as_tensor().flatten_all().unwrap().to_vec1().unwrap()
    }

    fn mean_std(v: &[f32]) -> (f64, f64) {
        let n = v.len() as f64;
        let mean = v.iter().map(|&x| x as f64).sum::<f64>() / n;
        let var = v.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n;
        (mean, var.sqrt())
    }

    #[test]
    fn same_seed_gives_identical_weights_in_any_creation_order() {
        let a = build(7, &["a", "b"]);
        let b = build(7, &["b", "a"]);
        let c = build(8, &["a", "b"]);
        assert_eq!(values(&a, "a"), values(&b, "a"));
        assert_eq!(values(&a, "b"), values(&b, "b"));
        assert_ne!(values(&a, "a"), values(&c, "a"));
        assert_ne!(values(&a, "a"), values(&a, "b"), "each name draws its own stream");
    }

    #[test]
    fn values_follow_the_hint() {
        let vm = VarMap::new();
        let vb = SeededVarMap::builder(&vm, 1, DType::F32, &Device::Cpu);
        vb.get_with_hints((100, 100), "n", Init::Randn { mean: 0.5, stdev: 2.0 }).unwrap();
        vb.get_with_hints((100, 100), "u", Init::Uniform { lo: -3.0, up: 1.0 }).unwrap();
        vb.get_with_hints((100, 400), "k", DEFAULT_KAIMING_NORMAL).unwrap();
        let ku =
            Init::Kaiming { dist: NormalOrUniform::Uniform, fan: FanInOut::FanIn, non_linearity: NonLinearity::Linear };
        vb.get_with_hints((100, 300), "ku", ku).unwrap();
        vb.get_with_hints(5, "c", Init::Const(0.25)).unwrap();
        let (m, s) = mean_std(&values(&vm, "n"));
        assert!((m - 0.5).abs() < 0.05 && (s - 2.0).abs() < 0.05, "randn: mean {m}, std {s}");
        let u = values(&vm, "u");
        assert!(u.iter().all(|&x| (-3.0..1.0).contains(&x)));
        let (m, s) = mean_std(&u);
        // U(a, b): mean (a + b) / 2, std (b - a) / sqrt(12).
        assert!((m + 1.0).abs() < 0.03 && (s - 4.0 / 12f64.sqrt()).abs() < 0.02, "uniform: mean {m}, std {s}");
        // Kaiming normal, fan-in 400, ReLU gain sqrt(2): std sqrt(2 / 400).
        let (m, s) = mean_std(&values(&vm, "k"));
        assert!(m.abs() < 0.002 && (s - (2.0f64 / 400.0).sqrt()).abs() < 0.002, "kaiming: mean {m}, std {s}");
        // Kaiming uniform, fan-in 300, gain 1: bound sqrt(3 / 300).
        let bound = (3.0f64 / 300.0).sqrt() as f32;
        assert!(values(&vm, "ku").iter().all(|x| x.abs() <= bound));
        assert_eq!(values(&vm, "c"), vec![0.25; 5]);
    }

    #[test]
    fn existing_variables_are_reused_and_shapes_checked() {
        let vm = build(3, &["a"]);
        let before = values(&vm, "a");
        let vb = SeededVarMap::builder(&vm, 99, DType::F32, &Device::Cpu);
        let t = vb.get_with_hints((64, 32), "a", Init::Const(0.0)).unwrap();
        assert_eq!(t.flatten_all().unwrap().to_vec1::<f32>().unwrap(), before);
        let err = vb.get_with_hints((2, 2), "a", Init::Const(0.0)).unwrap_err().to_string();
        assert!(err.contains("shape mismatch on a"), "{err}");
    }
}
