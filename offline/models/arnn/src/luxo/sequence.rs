//! A generated hop sequence: the lamp's degrees of freedom over time, its liftoff and landing
//! events, the keys of section 5, and its files (BVH for Blender, JSON for training).

use super::LuxoError;
use super::anneal::{AnnealStats, Evaluation};
use super::controller::{HopPolicy, Rollout};
use super::lamp::{DOF_NAMES, DOFS, LampParams, LampPose};
use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};
use std::path::Path;
use zoo_motion::{Clip, EulerOrder, JointChannels, Skeleton};

/// Format name written in every sequence file.
pub const FORMAT: &str = "zoo-luxo-sequence";
/// Version of the sequence file format.
pub const VERSION: u32 = 1;
/// BVH units per metre (the BVH is written in centimetres, like the project's other data).
pub const BVH_UNITS_PER_METRE: f64 = 100.0;
/// Samples per hop from liftoff to landing (section 5).
pub const HOP_SAMPLES: usize = 25;

/// One hop: the lamp leaves the ground at `liftoff_s` and touches it again at `landing_s`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hop {
    /// First instant with no link touching the ground (seconds from the start).
    pub liftoff_s: f64,
    /// First instant after the liftoff with a link touching the ground.
    pub landing_s: f64,
}

/// Finds the hops in a contact track: `touching[i]` is the contact after step `i`, at time
/// `(i + 1) * dt`. An airborne phase shorter than `min_air_s` is a bounce and is skipped; one
/// still in the air at the end of the track is not a hop.
pub fn detect_hops(touching: &[bool], dt: f64, min_air_s: f64) -> Vec<Hop> {
    let mut hops = Vec::new();
    let mut start: Option<usize> = None;
    for (i, &t) in touching.iter().enumerate() {
        match (t, start) {
            (false, None) => start = Some(i),
            (true, Some(s)) => {
                let hop = Hop { liftoff_s: (s + 1) as f64 * dt, landing_s: (i + 1) as f64 * dt };
                if hop.landing_s - hop.liftoff_s >= min_air_s {
                    hops.push(hop);
                }
                start = None;
            }
            _ => {}
        }
    }
    hops
}

/// What a key marks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KeyKind {
    /// The pose at liftoff.
    Liftoff,
    /// A pose in the air.
    InAir,
    /// The pose at landing.
    Landing,
}

/// A key of section 5: a pose at a time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LuxoKey {
    /// What the key marks.
    pub kind: KeyKind,
    /// The hop (0-based) it belongs to.
    pub hop: usize,
    /// Time in seconds from the start of the sequence.
    pub time_s: f64,
    /// The lamp's degrees of freedom at that time.
    pub pose: LampPose,
}

/// A hop with its in-air key.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HopEvents {
    /// Liftoff and landing times.
    #[serde(flatten)]
    pub hop: Hop,
    /// The in-air key is sample `in_air_sample` (1..=23) of the hop's 25 evenly spaced
    /// samples from liftoff (0) to landing (24).
    pub in_air_sample: usize,
}

/// One generated sequence as written to `NAME.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LuxoSequence {
    /// Always [`FORMAT`].
    pub format: String,
    /// File format version ([`VERSION`]).
    pub version: u32,
    /// File stem, e.g. `luxo_0007`.
    pub name: String,
    /// Index of the sequence in its data set.
    pub index: usize,
    /// Seed of the data set.
    pub seed: u64,
    /// Frames per second of `frames`.
    pub fps: f64,
    /// Names of the six degrees of freedom ([`DOF_NAMES`]).
    pub dof_names: Vec<String>,
    /// The degrees of freedom at every frame; frame 0 is time 0.
    pub frames: Vec<LampPose>,
    /// Liftoff and landing of each hop.
    pub hops: Vec<HopEvents>,
    /// Keys: liftoff, in-air and landing of every hop, in time order.
    pub keys: Vec<LuxoKey>,
    /// The hop policy found by simulated annealing.
    pub policy: HopPolicy,
    /// The energy weight `w_e` of its annealing run.
    pub w_e: f64,
    /// What the policy achieved.
    pub evaluation: Evaluation,
    /// Annealing runs needed to find a satisfactory policy.
    pub attempts: usize,
    /// What happened to the candidates of those runs (absent in files written before it was
    /// recorded).
    #[serde(default)]
    pub anneal: AnnealStats,
}

/// Linear interpolation of a track sampled at `fps` at time `t` (clamped to the track).
pub fn sample(frames: &[LampPose], fps: f64, t: f64) -> LampPose {
    if frames.is_empty() {
        return [0.0; DOFS];
    }
    let u = (t * fps).clamp(0.0, (frames.len() - 1) as f64);
    let i = (u.floor() as usize).min(frames.len() - 1);
    let j = (i + 1).min(frames.len() - 1);
    let w = u - i as f64;
    std::array::from_fn(|d| frames[i][d] * (1.0 - w) + frames[j][d] * w)
}

impl LuxoSequence {
    /// Builds a sequence from a rollout: frames every `record_every` steps, the hops and the
    /// keys. `in_air_samples[h]` picks hop `h`'s in-air key (1..=23).
    pub fn from_rollout(
        name: String,
        index: usize,
        seed: u64,
        rollout: &Rollout,
        record_every: usize,
        hops: &[Hop],
        in_air_samples: &[usize],
        policy: HopPolicy,
        w_e: f64,
        evaluation: Evaluation,
        attempts: usize,
    ) -> LuxoSequence {
        let record_every = record_every.max(1);
        let steps = rollout.poses.len();
        let frames: Vec<LampPose> = (0..=steps).step_by(record_every).map(|i| rollout.pose_at_step(i)).collect();
        let fps = 1.0 / (rollout.dt * record_every as f64);
        let hops: Vec<HopEvents> = hops
            .iter()
            .zip(in_air_samples)
            .map(|(&hop, &k)| HopEvents { hop, in_air_sample: k.clamp(1, HOP_SAMPLES - 2) })
            .collect();
        let mut keys = Vec::with_capacity(hops.len() * 3);
        for (h, e) in hops.iter().enumerate() {
            let air = e.hop.liftoff_s
                + (e.hop.landing_s - e.hop.liftoff_s) * e.in_air_sample as f64 / (HOP_SAMPLES - 1) as f64;
            for (kind, t) in
                [(KeyKind::Liftoff, e.hop.liftoff_s), (KeyKind::InAir, air), (KeyKind::Landing, e.hop.landing_s)]
            {
                keys.push(LuxoKey { kind, hop: h, time_s: t, pose: sample(&frames, fps, t) });
            }
        }
        LuxoSequence {
            format: FORMAT.into(),
            version: VERSION,
            name,
            index,
            seed,
            fps,
            dof_names: DOF_NAMES.iter().map(|s| s.to_string()).collect(),
            frames,
            hops,
            keys,
            policy,
            w_e,
            evaluation,
            attempts,
            anneal: AnnealStats::default(),
        }
    }

    /// Duration of the track in seconds.
    pub fn duration(&self) -> f64 {
        self.frames.len().saturating_sub(1) as f64 / self.fps
    }

    /// The pose at time `t` (linear interpolation between frames).
    pub fn pose_at(&self, t: f64) -> LampPose {
        sample(&self.frames, self.fps, t)
    }

    /// Checks what a reader relies on: format, version, finite frames, hops in order inside
    /// the track, three keys per hop in time order.
    pub fn validate(&self) -> Result<(), String> {
        if self.format != FORMAT || self.version != VERSION {
            return Err(format!(
                "not a {FORMAT} version {VERSION} file (found format {:?} version {}); regenerate it with `zoo data luxo`",
                self.format, self.version
            ));
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(format!("fps must be positive, found {}", self.fps));
        }
        if self.frames.len() < 2 {
            return Err(format!("needs at least 2 frames, found {}", self.frames.len()));
        }
        if let Some(f) = self.frames.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
            return Err(format!("frame {f} has a value that is not finite"));
        }
        let end = self.duration();
        let mut last = 0.0;
        for (h, e) in self.hops.iter().enumerate() {
            let (a, b) = (e.hop.liftoff_s, e.hop.landing_s);
            if !(a >= last && a < b && b <= end + 1e-9) {
                return Err(format!("hop {h} ({a} s to {b} s) is out of order or past the end of the track ({end} s)"));
            }
            if !(1..=HOP_SAMPLES - 2).contains(&e.in_air_sample) {
                return Err(format!("hop {h}: in_air_sample must be in 1..={}", HOP_SAMPLES - 2));
            }
            last = b;
        }
        if self.keys.len() != 3 * self.hops.len() {
            return Err(format!("expected 3 keys per hop ({}), found {}", 3 * self.hops.len(), self.keys.len()));
        }
        if self.keys.windows(2).any(|w| w[1].time_s <= w[0].time_s) {
            return Err("keys are not in increasing time order".into());
        }
        Ok(())
    }

    /// Writes the sequence as JSON (atomically: a temporary file renamed into place).
    pub fn write_json(&self, path: &Path) -> Result<(), LuxoError> {
        zoo_motion::finite::check_serialize("the lamp sequence", self)
            .map_err(|e| LuxoError::Json { path: path.to_path_buf(), message: e.to_string() })?;
        let text = serde_json::to_string(self)
            .map_err(|e| LuxoError::Json { path: path.to_path_buf(), message: e.to_string() })?;
        write_atomic(path, text.as_bytes())
    }

    /// Reads and validates a sequence JSON file.
    pub fn read_json(path: &Path) -> Result<LuxoSequence, LuxoError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| LuxoError::Io { path: path.to_path_buf(), source })?;
        let seq: LuxoSequence = serde_json::from_str(&text)
            .map_err(|e| LuxoError::Json { path: path.to_path_buf(), message: e.to_string() })?;
        seq.validate().map_err(|message| LuxoError::BadSequence { path: path.to_path_buf(), message })?;
        Ok(seq)
    }

    /// The sequence as a clip on [`lamp_skeleton`] (centimetres, Y up, the lamp in the XY
    /// plane), for the BVH writer.
    pub fn to_clip(&self, params: &LampParams) -> Clip {
        poses_to_clip(&self.frames, self.fps, params)
    }
}

/// Writes bytes to `path` through a temporary file in the same folder.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), LuxoError> {
    zoo_format::atomic::write(path, bytes).map_err(|source| LuxoError::Io { path: path.to_path_buf(), source })
}

/// The lamp as a BVH skeleton: `base` (root, with position channels), `leg`, `neck`, `head`
/// and an end site at the tip of the head; offsets in centimetres along +Y; every joint
/// rotates about Z.
pub fn lamp_skeleton(params: &LampParams) -> Skeleton {
    let (offsets, tip) = params.joint_offsets();
    let s = BVH_UNITS_PER_METRE;
    Skeleton {
        names: ["base", "leg", "neck", "head"].iter().map(|n| n.to_string()).collect(),
        parents: vec![None, Some(0), Some(1), Some(2)],
        offsets: offsets.iter().map(|&o| DVec3::new(0.0, o * s, 0.0)).collect(),
        end_sites: vec![None, None, None, Some(DVec3::new(0.0, tip * s, 0.0))],
        channels: vec![
            JointChannels { position: true, order: EulerOrder::Zxy },
            JointChannels { position: false, order: EulerOrder::Zxy },
            JointChannels { position: false, order: EulerOrder::Zxy },
            JointChannels { position: false, order: EulerOrder::Zxy },
        ],
    }
}

/// Lamp poses (metres, radians) as a clip on [`lamp_skeleton`].
pub fn poses_to_clip(frames: &[LampPose], fps: f64, params: &LampParams) -> Clip {
    let skeleton = lamp_skeleton(params);
    let mut local_rotations = Vec::with_capacity(frames.len() * 4);
    let mut local_positions = Vec::with_capacity(frames.len() * 4);
    for p in frames {
        local_positions.push(DVec3::new(p[0], p[1], 0.0) * BVH_UNITS_PER_METRE);
        local_positions.extend_from_slice(&skeleton.offsets[1..]);
        local_rotations.extend((2..6).map(|d| DQuat::from_rotation_z(p[d])));
    }
    Clip { skeleton, frame_time: 1.0 / fps, local_rotations, local_positions }
}

/// Lamp poses back from a clip on [`lamp_skeleton`] (angles in (-pi, pi]).
pub fn clip_to_poses(clip: &Clip) -> Result<Vec<LampPose>, String> {
    let names = ["base", "leg", "neck", "head"];
    if clip.skeleton.names != names {
        return Err(format!(
            "not a lamp clip: expected joints {names:?}, found {:?} (use a BVH written by `zoo data luxo`)",
            clip.skeleton.names
        ));
    }
    Ok((0..clip.frames())
        .map(|f| {
            let r = clip.rotations_at(f);
            let angle = |q: DQuat| {
                let (axis, a) = q.to_axis_angle();
                super::lamp::wrap_angle(if axis.z < 0.0 { -a } else { a })
            };
            let p = clip.root_position(f) / BVH_UNITS_PER_METRE;
            [p.x, p.y, angle(r[0]), angle(r[1]), angle(r[2]), angle(r[3])]
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hops_are_found_and_bounces_skipped() {
        let dt = 0.01;
        // 10 on the ground, 30 in the air, 5 down, 2 in the air (a bounce), 10 down, 3 up.
        let mut t = vec![true; 10];
        t.extend(vec![false; 30]);
        t.extend(vec![true; 5]);
        t.extend(vec![false; 2]);
        t.extend(vec![true; 10]);
        t.extend(vec![false; 3]);
        let hops = detect_hops(&t, dt, 0.05);
        assert_eq!(hops.len(), 1);
        assert!((hops[0].liftoff_s - 0.11).abs() < 1e-12);
        assert!((hops[0].landing_s - 0.41).abs() < 1e-12);
    }

    #[test]
    fn sample_interpolates_and_clamps() {
        let frames = vec![[0.0; 6], [1.0; 6], [3.0; 6]];
        assert_eq!(sample(&frames, 10.0, 0.05)[0], 0.5);
        assert_eq!(sample(&frames, 10.0, 0.15)[3], 2.0);
        assert_eq!(sample(&frames, 10.0, 9.0)[5], 3.0);
        assert_eq!(sample(&frames, 10.0, -1.0)[1], 0.0);
    }

    #[test]
    fn clip_round_trips_poses() {
        let params = LampParams::default();
        let poses = vec![[0.1, 0.02, 0.05, 0.5, -1.1, -1.2], [0.2, 0.1, -0.1, -0.3, -2.0, 1.0]];
        let clip = poses_to_clip(&poses, 120.0, &params);
        let back = clip_to_poses(&clip).unwrap();
        for (a, b) in poses.iter().zip(&back) {
            for d in 0..6 {
                assert!((a[d] - b[d]).abs() < 1e-9, "{a:?} vs {b:?}");
            }
        }
    }
}
