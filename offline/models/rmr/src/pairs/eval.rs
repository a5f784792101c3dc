//! Measures of the stitching benchmark (`zoo bench stitch`, docs/rmr.md): pose error to the
//! ground truth (L2P, L2Q, NPSS), foot sliding as RMR measures it, the benchmark's foot skate,
//! root trajectory deviation from the input, and pops at the seams.

use super::layout::{StitchLayout, ground_roots};
use super::segments::MotionSet;
use glam::{DQuat, DVec3};
use zoo_data::metrics::{FootSkate, l2p, l2q};
use zoo_motion::Clip;

/// Height above a foot joint's planted height under which RMR's foot sliding counts its
/// horizontal displacement (RMR sec. 7.3: "when the distance between the floor and each foot was
/// less than 2 cm"), clip units (cm).
pub const SLIDE_HEIGHT: f64 = 2.0;

/// Frames on each side of a seam searched for the largest joint speed (pops).
pub const POP_FRAMES: usize = 5;

/// What the measures need from the training data: per-coordinate position spread (L2P), the
/// 99th percentile of joint speeds (pops) and the planted heights of the feet (in `layout`).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct StitchMeasures {
    /// Contact joints and planted heights.
    pub layout: StitchLayout,
    /// Population standard deviation of each coordinate (joint-major, xyz) of the global
    /// positions of the training windows, each window expressed in its first frame's ground
    /// root (the coordinates the test cases are in).
    pub position_std: Vec<f64>,
    /// 99th percentile of the per-frame displacement of every joint over the training clips
    /// (clip units per frame).
    pub speed_p99: f64,
}

impl StitchMeasures {
    /// Fits the statistics on the training set: windows of `window` frames every `step`.
    pub fn fit(train: &MotionSet, window: usize, step: usize) -> StitchMeasures {
        let j = train.joints();
        let (mut sum, mut sq, mut n) = (vec![0.0; 3 * j], vec![0.0; 3 * j], 0usize);
        let mut speeds = Vec::new();
        for (c, gp) in train.global_positions.iter().enumerate() {
            let frames = train.frames(c);
            for f in 1..frames {
                for k in 0..j {
                    speeds.push((gp[f * j + k] - gp[(f - 1) * j + k]).length());
                }
            }
            let mut start = 0;
            while start + window <= frames {
                let origin = train.roots[c][start].inverse();
                for f in start..start + window {
                    for k in 0..j {
                        let p = origin.to_world(gp[f * j + k]);
                        for a in 0..3 {
                            sum[3 * k + a] += p[a];
                            sq[3 * k + a] += p[a] * p[a];
                        }
                    }
                    n += 1;
                }
                start += step.max(1);
            }
        }
        let position_std = (0..3 * j)
            .map(|i| {
                let m = sum[i] / n.max(1) as f64;
                let v = (sq[i] / n.max(1) as f64 - m * m).max(0.0).sqrt();
                if v > 1e-9 { v } else { 1.0 }
            })
            .collect();
        let speed_p99 = zoo_data::dataset::percentile(&mut speeds, 99.0);
        StitchMeasures { layout: train.layout.clone(), position_std, speed_p99 }
    }

    /// RMR's foot sliding: the summed horizontal displacement of the contact joints (heels and
    /// toes) since the previous frame over the frames where the joint is within
    /// [`SLIDE_HEIGHT`] of its planted height, and the number of such joint-frames.
    pub fn foot_sliding(&self, gp: &[DVec3], joints: usize) -> (f64, usize) {
        let frames = gp.len() / joints;
        let (mut total, mut count) = (0.0, 0);
        for f in 1..frames {
            for (k, &jt) in self.layout.contacts.iter().enumerate() {
                let (cur, prev) = (gp[f * joints + jt], gp[(f - 1) * joints + jt]);
                if cur.y - self.layout.planted[k] < SLIDE_HEIGHT {
                    total += ((cur.x - prev.x).powi(2) + (cur.z - prev.z).powi(2)).sqrt();
                    count += 1;
                }
            }
        }
        (total, count)
    }

    /// The benchmark's foot skate (`BENCHMARK.md`) of the contact joints, mean per joint-frame.
    pub fn skate(&self, gp: &[DVec3], joints: usize) -> f64 {
        let fs = FootSkate { joints: self.layout.contacts.to_vec(), planted: self.layout.planted.to_vec(), scale: 2.5 };
        fs.skate(gp, gp.len() / joints, joints)
    }

    /// The largest joint speed within [`POP_FRAMES`] frames of each seam, relative to the
    /// training data's 99th percentile (one value per seam).
    pub fn pops(&self, gp: &[DVec3], joints: usize, seams: &[usize]) -> Vec<f64> {
        let frames = gp.len() / joints;
        seams
            .iter()
            .map(|&s| {
                let lo = s.saturating_sub(POP_FRAMES).max(1);
                let hi = (s + POP_FRAMES).min(frames - 1);
                let mut m: f64 = 0.0;
                for f in lo..=hi {
                    for k in 0..joints {
                        m = m.max((gp[f * joints + k] - gp[(f - 1) * joints + k]).length());
                    }
                }
                m / self.speed_p99
            })
            .collect()
    }

    /// Mean horizontal distance between the ground roots of `output` and `input`, per frame.
    pub fn root_deviation(&self, output: &Clip, input: &Clip) -> f64 {
        let (a, b) = (ground_roots(output, &self.layout), ground_roots(input, &self.layout));
        a.iter().zip(&b).map(|(p, q)| (p.pos - q.pos).length()).sum::<f64>() / a.len().max(1) as f64
    }

    /// L2P and L2Q of `pred` against `gt` (global positions and rotations of the same frames),
    /// with each predicted quaternion put in the ground truth's hemisphere first (decoded
    /// rotations have an arbitrary sign).
    pub fn pose_errors(&self, pred: (&[DQuat], &[DVec3]), gt: (&[DQuat], &[DVec3]), joints: usize) -> (f64, f64) {
        let aligned = hemisphere(pred.0, gt.0);
        (l2p(pred.1, gt.1, joints, &self.position_std), l2q(&aligned, gt.0, joints))
    }
}

/// `pred` with each quaternion flipped into the hemisphere of the matching one in `gt`.
pub fn hemisphere(pred: &[DQuat], gt: &[DQuat]) -> Vec<DQuat> {
    pred.iter().zip(gt).map(|(p, g)| if p.dot(*g) < 0.0 { -*p } else { *p }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn measures() -> StitchMeasures {
        let layout = StitchLayout {
            lower_body: vec![0],
            contacts: [1, 1, 1, 1],
            contact_thresholds: [2.5; 4],
            planted: [0.0; 4],
            forward_axis: DVec3::Z,
        };
        StitchMeasures { layout, position_std: vec![1.0; 6], speed_p99: 2.0 }
    }

    #[test]
    fn sliding_counts_low_feet_and_pops_are_relative() {
        let m = measures();
        // Joint 1 slides 1 unit per frame on the floor, then 3 units per frame 5 units up.
        let gp =
            [DVec3::ZERO, DVec3::ZERO, DVec3::ZERO, DVec3::new(1.0, 0.0, 0.0), DVec3::ZERO, DVec3::new(4.0, 5.0, 0.0)];
        let (total, count) = m.foot_sliding(&gp, 2);
        assert_eq!((total, count), (4.0, 4), "frame 1 counts once per contact entry (4 entries, 1 unit each)");
        let pops = m.pops(&gp, 2, &[2]);
        assert!((pops[0] - (9.0f64 + 25.0).sqrt() / 2.0).abs() < 1e-12, "{pops:?}");
        let q = [DQuat::IDENTITY, -DQuat::IDENTITY];
        let (l2p, l2q) = m.pose_errors((&q, &gp[..2]), (&[DQuat::IDENTITY; 2], &gp[..2]), 2);
        assert_eq!((l2p, l2q), (0.0, 0.0), "a flipped sign is the same rotation");
    }
}
