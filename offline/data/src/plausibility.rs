//! Plausibility figures of a motion set (real or synthetic): foot skate as defined in
//! `BENCHMARK.md`, root speeds, foot penetration of the ground and bone-length drift.
//!
//! Every function takes clips with an optional terrain each (`None`: flat floor at y = 0);
//! heights are measured above the ground under the joint.

use crate::terrain::Heightmap;
use serde::Serialize;
use zoo_motion::Clip;

/// One clip and the ground under it.
pub type ClipOnGround<'a> = (&'a Clip, Option<&'a Heightmap>);

/// The foot joints of the foot-skate metric (bandai2 names).
pub const SKATE_JOINTS: [&str; 4] = ["Foot_L", "Toes_L", "Foot_R", "Toes_R"];

fn ground(t: Option<&Heightmap>, x: f64, z: f64) -> f64 {
    t.map_or(0.0, |t| t.height(x, z))
}

/// Percentile `q` in [0, 100] (numpy's linear interpolation) of unsorted `values`, without
/// reordering them: [`crate::dataset::percentile`] on a copy.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    crate::dataset::percentile(&mut values.to_vec(), q)
}

/// Median of unsorted values.
pub fn median(values: &[f64]) -> f64 {
    percentile(values, 50.0)
}

/// Heights above the ground of each skate joint, per clip, frame-major (`frames x 4`),
/// and the global positions. Joints missing from the skeleton make the clip's entry empty.
fn foot_tracks(clip: &Clip, terrain: Option<&Heightmap>) -> Option<Vec<[(f64, f64, f64); 4]>> {
    let idx: Vec<usize> = SKATE_JOINTS.iter().map(|n| clip.skeleton.index_of(n)).collect::<Option<_>>()?;
    let (_, gp) = clip.global();
    let j = clip.joints();
    Some(
        (0..clip.frames())
            .map(|f| {
                let mut out = [(0.0, 0.0, 0.0); 4];
                for (k, &i) in idx.iter().enumerate() {
                    let p = gp[f * j + i];
                    out[k] = (p.x, p.z, p.y - ground(terrain, p.x, p.z));
                }
                out
            })
            .collect(),
    )
}

/// Planted height `g` of each skate joint: the 5th percentile of its height above the
/// ground over every frame of every clip (BENCHMARK.md).
pub fn planted_heights(clips: &[ClipOnGround]) -> [f64; 4] {
    let tracks: Vec<_> = clips.iter().filter_map(|(c, t)| foot_tracks(c, *t)).collect();
    let mut g = [0.0; 4];
    for k in 0..4 {
        let h: Vec<f64> = tracks.iter().flat_map(|tr| tr.iter().map(move |f| f[k].2)).collect();
        g[k] = percentile(&h, 5.0);
    }
    g
}

/// Foot skate (cm per frame, BENCHMARK.md): for each skate joint with height `h` above its
/// planted height `g` and horizontal displacement `v` since the previous frame,
/// `v * clamp(2 - 2^(h / 2.5), 0, 1)`; mean over joints and frames (frames 1.. of each clip).
/// `g` comes from [`planted_heights`] over the same clips when `planted` is `None`.
pub fn foot_skate(clips: &[ClipOnGround], planted: Option<[f64; 4]>) -> f64 {
    let g = planted.unwrap_or_else(|| planted_heights(clips));
    let (mut sum, mut count) = (0.0, 0usize);
    for (c, t) in clips {
        let Some(tr) = foot_tracks(c, *t) else {
            continue;
        };
        for f in 1..tr.len() {
            for k in 0..4 {
                let (x, z, h) = tr[f][k];
                let (px, pz, _) = tr[f - 1][k];
                let v = ((x - px).powi(2) + (z - pz).powi(2)).sqrt();
                let w = (2.0 - 2f64.powf((h - g[k]) / 2.5)).clamp(0.0, 1.0);
                sum += v * w;
                count += 1;
            }
        }
    }
    if count == 0 { f64::NAN } else { sum / count as f64 }
}

/// Root (joint 0) horizontal speed of each frame transition, m/s (positions in cm).
pub fn root_speeds(clip: &Clip) -> Vec<f64> {
    (1..clip.frames())
        .map(|f| {
            let d = clip.root_position(f) - clip.root_position(f - 1);
            (d.x * d.x + d.z * d.z).sqrt() / clip.frame_time / 100.0
        })
        .collect()
}

/// Median root speed (m/s) over all frames of `clips`.
pub fn median_root_speed<'a>(clips: impl IntoIterator<Item = &'a Clip>) -> f64 {
    let v: Vec<f64> = clips.into_iter().flat_map(root_speeds).collect();
    median(&v)
}

/// Deepest penetration of any skate joint below the ground (cm; 0 when never below).
pub fn max_foot_penetration(clips: &[ClipOnGround]) -> f64 {
    let mut worst: f64 = 0.0;
    for (c, t) in clips {
        if let Some(tr) = foot_tracks(c, *t) {
            for f in &tr {
                for k in f {
                    worst = worst.max(-k.2);
                }
            }
        }
    }
    worst
}

/// Largest deviation (cm) of any bone's length (distance between a joint and its parent
/// after forward kinematics) from its rest offset length.
pub fn max_bone_length_error(clips: &[&Clip]) -> f64 {
    let mut worst: f64 = 0.0;
    for c in clips {
        let (_, gp) = c.global();
        let j = c.joints();
        let rest = c.skeleton.bone_lengths();
        for f in 0..c.frames() {
            for k in 1..j {
                let p = c.skeleton.parents[k].unwrap_or(0);
                let len = (gp[f * j + k] - gp[f * j + p]).length();
                worst = worst.max((len - rest[k]).abs());
            }
        }
    }
    worst
}

/// The plausibility figures of a motion set.
#[derive(Clone, Debug, Serialize)]
pub struct Plausibility {
    /// Clips measured.
    pub clips: usize,
    /// Frames measured.
    pub frames: usize,
    /// Planted height of Foot_L, Toes_L, Foot_R, Toes_R (cm above ground).
    pub planted_heights: [f64; 4],
    /// Mean foot skate, cm per frame.
    pub foot_skate: f64,
    /// Median root speed per label (m/s), labels sorted.
    pub median_root_speed: Vec<(String, f64)>,
    /// Deepest foot joint below the ground, cm.
    pub max_foot_penetration: f64,
    /// Largest bone length deviation, cm.
    pub max_bone_length_error: f64,
}

/// All figures of a labelled motion set (`label` groups clips for the median speeds, e.g.
/// `walk` / `run`).
pub fn measure(clips: &[(&Clip, Option<&Heightmap>, &str)]) -> Plausibility {
    let on_ground: Vec<ClipOnGround> = clips.iter().map(|(c, t, _)| (*c, *t)).collect();
    let g = planted_heights(&on_ground);
    let mut labels: Vec<&str> = clips.iter().map(|c| c.2).collect();
    labels.sort();
    labels.dedup();
    let median_root_speed = labels
        .iter()
        .map(|l| (l.to_string(), median_root_speed(clips.iter().filter(|c| c.2 == *l).map(|c| c.0))))
        .collect();
    let only: Vec<&Clip> = clips.iter().map(|c| c.0).collect();
    Plausibility {
        clips: clips.len(),
        frames: clips.iter().map(|c| c.0.frames()).sum(),
        planted_heights: g,
        foot_skate: foot_skate(&on_ground, Some(g)),
        median_root_speed,
        max_foot_penetration: max_foot_penetration(&on_ground),
        max_bone_length_error: max_bone_length_error(&only),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_matches_numpy_linear() {
        // numpy.percentile([1, 2, 3, 4, 10], 5) = 1.2; median = 3.
        let v = [4.0, 1.0, 10.0, 3.0, 2.0];
        assert!((percentile(&v, 5.0) - 1.2).abs() < 1e-12);
        assert!((median(&v) - 3.0).abs() < 1e-12);
    }
}
