//! The pose vector of RMR sec. 4 and back (defined in the core layer,
//! [`zoo_protocol::stitch`], which the engine's runtime shares: see there for the layout), and
//! its normalisation statistics.

use crate::error::{RmrError, RmrResult};
use crate::pairs::StitchLayout;
use serde::{Deserialize, Serialize};

pub use zoo_protocol::stitch::{PoseLayout as FeatureLayout, accumulate_roots, decode, encode_clip};

/// Per-value mean and standard deviation of the pose vector over the generated training data
/// (RMR sec. 5). Contacts are left as they are (mean 0, std 1) so that the sigmoid of the
/// contact outputs compares with 0/1 labels; values that never vary get std 1.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureStats {
    /// Mean per value.
    pub mean: Vec<f32>,
    /// Standard deviation per value.
    pub std: Vec<f32>,
}

impl FeatureStats {
    /// Fits the statistics over every frame of `sequences` (each `frames * dim`).
    pub fn fit<'a>(sequences: impl IntoIterator<Item = &'a [f32]>, fl: FeatureLayout) -> FeatureStats {
        let d = fl.dim();
        let (mut n, mut sum, mut sq) = (0usize, vec![0.0f64; d], vec![0.0f64; d]);
        for s in sequences {
            for x in s.chunks_exact(d) {
                n += 1;
                for (i, &v) in x.iter().enumerate() {
                    sum[i] += v as f64;
                    sq[i] += (v as f64) * (v as f64);
                }
            }
        }
        let n = n.max(1) as f64;
        let mut mean: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
        let mut std: Vec<f32> = sum
            .iter()
            .zip(&sq)
            .map(|(s, q)| {
                let m = s / n;
                let sd = (q / n - m * m).max(0.0).sqrt();
                if sd < 1e-6 { 1.0 } else { sd as f32 }
            })
            .collect();
        for i in fl.contacts()..d {
            mean[i] = 0.0;
            std[i] = 1.0;
        }
        FeatureStats { mean, std }
    }

    /// Values per frame.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Normalises whole frames in place.
    pub fn normalize(&self, x: &mut [f32]) {
        let d = self.dim();
        for f in x.chunks_exact_mut(d) {
            for ((v, m), s) in f.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = (*v - m) / s;
            }
        }
    }

    /// Undoes [`FeatureStats::normalize`] in place.
    pub fn denormalize(&self, x: &mut [f32]) {
        let d = self.dim();
        for f in x.chunks_exact_mut(d) {
            for ((v, m), s) in f.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = *v * s + m;
            }
        }
    }
}

/// Encoded pairs: `count` input and target sequences of `frames` frames of `dim` values,
/// `[pair][frame][value]`.
#[derive(Clone, Debug, PartialEq)]
pub struct PairFeatures {
    /// Number of pairs.
    pub count: usize,
    /// Frames per sequence.
    pub frames: usize,
    /// Values per frame.
    pub dim: usize,
    /// Inputs `X`.
    pub inputs: Vec<f32>,
    /// Ground truths `Y`.
    pub targets: Vec<f32>,
    /// First frame of each retrieved segment of each pair (the seams; empty when unknown).
    pub seams: Vec<Vec<usize>>,
}

impl PairFeatures {
    /// Encodes stitching pairs (all the same length).
    pub fn encode(pairs: &[crate::pairs::StitchPair], layout: &StitchLayout) -> RmrResult<PairFeatures> {
        let first = pairs.first().ok_or_else(|| RmrError::Config("no stitching pairs to encode".into()))?;
        let frames = first.target.frames();
        let dim = FeatureLayout::new(first.target.joints(), layout.lower_body.len()).dim();
        let mut inputs = Vec::with_capacity(pairs.len() * frames * dim);
        let mut targets = Vec::with_capacity(pairs.len() * frames * dim);
        let mut seams = Vec::with_capacity(pairs.len());
        for (i, p) in pairs.iter().enumerate() {
            if p.input.frames() != frames || p.target.frames() != frames {
                return Err(RmrError::Config(format!("pair {i} has {} frames, pair 0 {frames}", p.input.frames())));
            }
            inputs.extend(encode_clip(&p.input, layout)?);
            targets.extend(encode_clip(&p.target, layout)?);
            seams.push(p.seams.clone());
        }
        Ok(PairFeatures { count: pairs.len(), frames, dim, inputs, targets, seams })
    }

    /// Sequence `i` of the inputs.
    pub fn input(&self, i: usize) -> &[f32] {
        &self.inputs[i * self.frames * self.dim..(i + 1) * self.frames * self.dim]
    }

    /// Sequence `i` of the targets.
    pub fn target(&self, i: usize) -> &[f32] {
        &self.targets[i * self.frames * self.dim..(i + 1) * self.frames * self.dim]
    }

    /// A normalised copy.
    pub fn normalized(&self, stats: &FeatureStats) -> RmrResult<PairFeatures> {
        if stats.dim() != self.dim {
            return Err(RmrError::Config(format!(
                "statistics have {} values per frame, the pairs {}",
                stats.dim(),
                self.dim
            )));
        }
        let mut out = self.clone();
        stats.normalize(&mut out.inputs);
        stats.normalize(&mut out.targets);
        Ok(out)
    }
}
