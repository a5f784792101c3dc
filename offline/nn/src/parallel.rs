//! Data-parallel training steps inside one process.
//!
//! A batch is cut into contiguous shards, one per worker. Every worker computes its shard's
//! loss and gradients on the same variables (candle tensors are shared read-only between
//! threads, each worker builds its own graph), then the gradients are summed in memory, in
//! shard order, before the one optimiser step. The update equals the one-thread update of the
//! whole batch up to the order of float summation; for a fixed thread count it is the same bit
//! for bit, run to run.
//!
//! Each shard's loss runs with a weight-gradient tape collection active ([`crate::tape`]): the
//! weights that layers multiply frame by frame get their gradient in one matmul over every
//! frame after the backward pass, instead of one weight-sized matmul and sum per frame.
//!
//! Each worker runs inside its own single-thread rayon pool: candle's matmul (gemm) and its
//! other parallel kernels run in the pool of the calling thread, so a worker's kernels stay on
//! its one thread instead of competing with the other worker's for a shared pool. At the
//! model shapes of the zoo (batches of 16-64 rows), splitting each matmul across cores scales
//! badly (barriers per op), while whole shards scale nearly linearly.
//!
//! The model's loss must be a mean over the samples of the batch (every model of the zoo
//! averages its loss over samples, frames and values): shard `k` of `n_k` samples returns its
//! own mean, and its gradients are weighted by `n_k / n`, so the sum is the gradient of the
//! whole batch's mean. Randomness that a step draws (rotations, teacher forcing, noise) must be
//! drawn before the split, in the batch's order, so that the draws do not depend on the
//! thread count.

use candle_core::backprop::GradStore;
use candle_core::{Result, Tensor, Var};
use std::ops::Range;

/// Workers of data-parallel training steps (see the module documentation).
pub struct DataParallel {
    pools: Vec<rayon::ThreadPool>,
}

impl std::fmt::Debug for DataParallel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DataParallel").field("threads", &self.pools.len()).finish()
    }
}

/// The most worker threads a training run may ask for.
pub const MAX_THREADS: usize = 256;

impl DataParallel {
    /// `threads` workers (at least 1, at most [`MAX_THREADS`]).
    pub fn new(threads: usize) -> Result<Self> {
        if threads == 0 || threads > MAX_THREADS {
            candle_core::bail!("training threads must be in 1..={MAX_THREADS}, got {threads}");
        }
        let pools = (0..threads)
            .map(|k| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(1)
                    .thread_name(move |_| format!("zoo-train-{k}"))
                    .build()
                    .map_err(|e| candle_core::Error::Msg(format!("cannot start training thread {k}: {e}")))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(DataParallel { pools })
    }

    /// The number of workers.
    pub fn threads(&self) -> usize {
        self.pools.len()
    }

    /// The shards of a batch of `n` samples: contiguous ranges in order, sizes differing by at
    /// most one, none empty (fewer shards than workers when `n` is smaller).
    pub fn shards(&self, n: usize) -> Vec<Range<usize>> {
        let k = self.pools.len().min(n).max(1);
        let (base, extra) = (n / k, n % k);
        let mut start = 0;
        (0..k)
            .map(|i| {
                let len = base + usize::from(i < extra);
                let r = start..start + len;
                start += len;
                r
            })
            .collect()
    }

    /// Runs `f` on the first worker's thread (for work outside a training step that should see
    /// the same single-thread kernels, such as a one-worker benchmark).
    pub fn install<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        self.pools[0].install(f)
    }

    /// `f(0)`, ..., `f(n - 1)` in order, the indices shared out among the workers in contiguous
    /// ranges ([`DataParallel::shards`]), each worker running its own on its one thread: for
    /// work without gradients, such as validation, whose items do not depend on each other.
    pub fn map<T: Send>(&self, n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
        let shards = self.shards(n);
        let run = |k: usize, r: Range<usize>| -> Vec<T> { self.pools[k].install(|| r.map(&f).collect()) };
        std::thread::scope(|s| {
            let run = &run;
            let handles: Vec<_> =
                shards.iter().enumerate().skip(1).map(|(k, r)| s.spawn(move || run(k, r.clone()))).collect();
            let mut out = run(0, shards[0].clone());
            for h in handles {
                out.extend(h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)));
            }
            out
        })
    }

    /// The loss of a batch of `n` samples and its gradients with respect to `vars`.
    ///
    /// `loss(range)` returns the mean loss (a scalar tensor) of the samples `range` of the
    /// batch. Returns the whole batch's mean loss and a gradient store holding, for each of
    /// `vars` that the loss depends on, the gradient of that mean (ready for an optimiser's
    /// `step`). A non-finite loss is returned as it is (no gradients are computed for it).
    pub fn backward<F>(&self, n: usize, vars: &[Var], loss: F) -> Result<(f64, Option<GradStore>)>
    where
        F: Fn(Range<usize>) -> Result<Tensor> + Sync,
    {
        if n == 0 {
            candle_core::bail!("a training step needs at least one sample");
        }
        let shards = self.shards(n);
        let shared = std::sync::Arc::new(crate::tape::SharedCopies::default());
        if shards.len() == 1 {
            return self.pools[0].install(|| {
                let (l, tapes) = crate::tape::collect_shared(&shared, || loss(0..n));
                let l = l?;
                let value = l.to_scalar::<f32>()? as f64;
                if !value.is_finite() {
                    return Ok((value, None));
                }
                let mut grads = l.backward()?;
                for t in &tapes {
                    t.finish(&mut grads, vars)?;
                }
                Ok((value, Some(grads)))
            });
        }
        let run = |k: usize, r: Range<usize>| -> Result<(f64, Option<GradStore>)> {
            self.pools[k].install(|| {
                let w = r.len() as f64 / n as f64;
                let (l, tapes) = crate::tape::collect_shared(&shared, || loss(r));
                let l = l?;
                let value = l.to_scalar::<f32>()? as f64;
                if !value.is_finite() {
                    return Ok((value, None));
                }
                let mut grads = l.affine(w, 0.0)?.backward()?;
                for t in &tapes {
                    t.finish(&mut grads, vars)?;
                }
                Ok((w * value, Some(grads)))
            })
        };
        let results: Vec<Result<(f64, Option<GradStore>)>> = std::thread::scope(|s| {
            let handles: Vec<_> = shards
                .iter()
                .enumerate()
                .skip(1)
                .map(|(k, r)| {
                    let r = r.clone();
                    let run = &run;
                    s.spawn(move || run(k, r))
                })
                .collect();
            let mut out = vec![run(0, shards[0].clone())];
            for h in handles {
                out.push(
                    h.join().unwrap_or_else(|_| Err(candle_core::Error::Msg("a training thread panicked".into()))),
                );
            }
            out
        });
        let mut total = 0.0;
        let mut stores = Vec::with_capacity(results.len());
        for r in results {
            let (value, grads) = r?;
            match grads {
                Some(g) => {
                    total += value;
                    stores.push(g);
                }
                None => return Ok((value, None)),
            }
        }
        let mut iter = stores.into_iter();
        let mut first = iter.next().expect("at least two shards");
        let rest: Vec<GradStore> = iter.collect();
        for v in vars {
            let t = v.as_tensor();
            let mut sum = first.get(t).cloned();
            for g in rest.iter().filter_map(|s| s.get(t)) {
                sum = Some(match sum {
                    Some(acc) => (acc + g)?,
                    None => g.clone(),
                });
            }
            if let Some(sum) = sum {
                first.insert(t, sum);
            }
        }
        Ok((total, Some(first)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};

    fn setup() -> (Var, Var, Tensor, Tensor) {
        let dev = Device::Cpu;
        let w = Var::from_tensor(
            &Tensor::arange(0f32, 12.0, &dev).unwrap().reshape((4, 3)).unwrap().affine(0.1, -0.3).unwrap(),
        )
        .unwrap();
        let b = Var::zeros(3, DType::F32, &dev).unwrap();
        let x = Tensor::arange(0f32, 28.0, &dev).unwrap().reshape((7, 4)).unwrap().affine(0.05, -0.4).unwrap();
        let y = Tensor::arange(0f32, 21.0, &dev).unwrap().reshape((7, 3)).unwrap().sin().unwrap();
        (w, b, x, y)
    }

    fn loss(w: &Var, b: &Var, x: &Tensor, y: &Tensor, r: Range<usize>) -> Result<Tensor> {
        let xs = x.narrow(0, r.start, r.len())?;
        let ys = y.narrow(0, r.start, r.len())?;
        let pred = xs.matmul(w.as_tensor())?.broadcast_add(b.as_tensor())?.tanh()?;
        (pred - ys)?.sqr()?.mean_all()
    }

    #[test]
    fn map_returns_every_item_in_order_on_the_workers_threads() {
        for threads in [1, 2, 3] {
            let dp = DataParallel::new(threads).unwrap();
            let out = dp.map(7, |i| (i * i, std::thread::current().name().map(str::to_string)));
            assert_eq!(out.iter().map(|(v, _)| *v).collect::<Vec<_>>(), [0, 1, 4, 9, 16, 25, 36]);
            // Each item ran on a worker, contiguous ranges per worker.
            let names: Vec<String> = out.iter().map(|(_, n)| n.clone().unwrap_or_default()).collect();
            assert!(names.iter().all(|n| n.starts_with("zoo-train-")), "{names:?}");
            let mut distinct = names.clone();
            distinct.dedup();
            assert_eq!(distinct.len(), threads, "{names:?}");
            assert!(dp.map(0, |i| i).is_empty());
        }
    }

    #[test]
    fn shards_are_contiguous_balanced_and_never_empty() {
        let dp = DataParallel::new(3).unwrap();
        assert_eq!(dp.shards(7), vec![0..3, 3..5, 5..7]);
        assert_eq!(dp.shards(2), vec![0..1, 1..2]);
        assert_eq!(dp.shards(1), vec![0..1]);
        assert!(DataParallel::new(0).unwrap_err().to_string().contains("1..=256"));
    }

    #[test]
    fn sharded_gradients_equal_the_whole_batch_gradients() {
        let (w, b, x, y) = setup();
        let vars = [w.clone(), b.clone()];
        let one = DataParallel::new(1).unwrap();
        let (l1, g1) = one.backward(7, &vars, |r| loss(&w, &b, &x, &y, r)).unwrap();
        let g1 = g1.unwrap();
        for threads in [2, 3, 7] {
            let dp = DataParallel::new(threads).unwrap();
            let (l, g) = dp.backward(7, &vars, |r| loss(&w, &b, &x, &y, r)).unwrap();
            let g = g.unwrap();
            assert!((l - l1).abs() <= 1e-6 * l1.abs(), "{threads} threads: loss {l} vs {l1}");
            for v in &vars {
                let a = g1.get(v.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
                let c = g.get(v.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
                let scale = a.iter().fold(0f32, |m, v| m.max(v.abs()));
                for (p, q) in a.iter().zip(&c) {
                    assert!((p - q).abs() <= 1e-5 * scale, "{threads} threads: {p} vs {q}");
                }
            }
            // Same thread count, same bits.
            let (l2, g2) = dp.backward(7, &vars, |r| loss(&w, &b, &x, &y, r)).unwrap();
            assert_eq!(l.to_bits(), l2.to_bits());
            let g2 = g2.unwrap();
            for v in &vars {
                let a = g.get(v.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
                let c = g2.get(v.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
                assert_eq!(a, c);
            }
        }
    }

    #[test]
    fn a_non_finite_shard_loss_computes_no_gradients() {
        let (w, b, x, y) = setup();
        let vars = [w.clone(), b.clone()];
        let dp = DataParallel::new(2).unwrap();
        let (l, g) = dp
            .backward(7, &vars, |r| {
                let l = loss(&w, &b, &x, &y, r.clone())?;
                if r.start > 0 { l.affine(f64::INFINITY, 0.0) } else { Ok(l) }
            })
            .unwrap();
        assert!(!l.is_finite());
        assert!(g.is_none());
    }
}
