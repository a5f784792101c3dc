//! A clip: per-frame local rotations and local translations of every joint.

use crate::euler::EulerOrder;
use crate::fk::forward_kinematics;
use crate::skeleton::Skeleton;
use glam::{DQuat, DVec3};

/// An animation clip on a skeleton.
///
/// `local_rotations[f * J + j]` is joint `j`'s rotation relative to its parent at frame `f`;
/// `local_positions[f * J + j]` its translation relative to its parent (for the root: the
/// world position; for other joints usually the bone offset, but BVH files with position
/// channels on every joint may animate it).
#[derive(Clone, Debug, PartialEq)]
pub struct Clip {
    /// The skeleton.
    pub skeleton: Skeleton,
    /// Seconds per frame.
    pub frame_time: f64,
    /// Local rotations, frame-major.
    pub local_rotations: Vec<DQuat>,
    /// Local translations, frame-major.
    pub local_positions: Vec<DVec3>,
}

impl Clip {
    /// The frame times a clip file may declare, in seconds: 10,000 fps to 0.1 fps. Outside it,
    /// speeds and durations overflow or mean nothing; readers refuse such a file.
    pub const FRAME_TIME_RANGE: (f64, f64) = (1e-4, 10.0);

    /// Checks a frame time read from a file against [`Clip::FRAME_TIME_RANGE`].
    pub fn check_frame_time(frame_time: f64) -> Result<(), String> {
        let (lo, hi) = Self::FRAME_TIME_RANGE;
        if frame_time.is_finite() && (lo..=hi).contains(&frame_time) {
            return Ok(());
        }
        Err(format!(
            "frame time {frame_time:?} s is outside the valid range [{lo}, {hi}] s ({} to {} fps)",
            1.0 / hi,
            1.0 / lo
        ))
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.local_rotations.len() / self.skeleton.len().max(1)
    }

    /// Number of joints.
    pub fn joints(&self) -> usize {
        self.skeleton.len()
    }

    /// Frames per second.
    pub fn fps(&self) -> f64 {
        1.0 / self.frame_time
    }

    /// Whether this clip plays at `fps` ([`same_frame_rate`]).
    pub fn plays_at(&self, fps: f64) -> bool {
        same_frame_rate(self.fps(), fps)
    }

    /// Duration in seconds.
    pub fn duration(&self) -> f64 {
        self.frames() as f64 * self.frame_time
    }

    /// Local rotations of frame `f`.
    pub fn rotations_at(&self, f: usize) -> &[DQuat] {
        let j = self.joints();
        &self.local_rotations[f * j..(f + 1) * j]
    }

    /// Local positions of frame `f`.
    pub fn positions_at(&self, f: usize) -> &[DVec3] {
        let j = self.joints();
        &self.local_positions[f * j..(f + 1) * j]
    }

    /// Root (joint 0) translation of frame `f`.
    pub fn root_position(&self, f: usize) -> DVec3 {
        self.local_positions[f * self.joints()]
    }

    /// Global rotations and positions of every frame (frame-major).
    pub fn global(&self) -> (Vec<DQuat>, Vec<DVec3>) {
        let n = self.local_rotations.len();
        let mut gr = vec![DQuat::IDENTITY; n];
        let mut gp = vec![DVec3::ZERO; n];
        forward_kinematics(&self.skeleton.parents, &self.local_rotations, &self.local_positions, &mut gr, &mut gp);
        (gr, gp)
    }

    /// Frames `from..to` as a new clip.
    pub fn slice(&self, from: usize, to: usize) -> Clip {
        let j = self.joints();
        Clip {
            skeleton: self.skeleton.clone(),
            frame_time: self.frame_time,
            local_rotations: self.local_rotations[from * j..to * j].to_vec(),
            local_positions: self.local_positions[from * j..to * j].to_vec(),
        }
    }

    /// The number of frames of this clip resampled at `fps` ([`Clip::resampled`]): the same
    /// span from the first frame to the last, at most one frame past it left out.
    pub fn resampled_frames(&self, fps: f64) -> usize {
        let n = self.frames();
        if n == 0 {
            return 0;
        }
        let span = (n - 1) as f64 * self.frame_time * fps;
        // A span a hair under a whole number of frames (rounding) keeps its last frame.
        (span + 1e-6).floor() as usize + 1
    }

    /// This clip at `fps` frames per second over the same span: frame `k` at `k / fps` s is
    /// interpolated between the two source frames around it, rotations by slerp (shortest path)
    /// and positions linearly. The caller bounds the size first ([`Clip::resampled_frames`]).
    pub fn resampled(&self, fps: f64) -> Clip {
        let (j, n, m) = (self.joints(), self.frames(), self.resampled_frames(fps));
        let mut local_rotations = Vec::with_capacity(m * j);
        let mut local_positions = Vec::with_capacity(m * j);
        for k in 0..m {
            let t = k as f64 / fps / self.frame_time;
            let i = (t.floor() as usize).min(n.saturating_sub(1));
            let (i1, a) = if i + 1 < n { (i + 1, t - i as f64) } else { (i, 0.0) };
            for joint in 0..j {
                let (r0, r1) = (self.local_rotations[i * j + joint], self.local_rotations[i1 * j + joint]);
                let r1 = if r0.dot(r1) < 0.0 { -r1 } else { r1 };
                local_rotations.push(if a == 0.0 { r0 } else { r0.slerp(r1, a).normalize() });
                let (p0, p1) = (self.local_positions[i * j + joint], self.local_positions[i1 * j + joint]);
                local_positions.push(p0.lerp(p1, a));
            }
        }
        Clip { skeleton: self.skeleton.clone(), frame_time: 1.0 / fps, local_rotations, local_positions }
    }

    /// Makes consecutive quaternions of each joint lie in the same hemisphere
    /// (see [`crate::quat::remove_sign_flips`]).
    pub fn remove_sign_flips(&mut self) {
        let j = self.joints();
        crate::quat::remove_sign_flips(&mut self.local_rotations, j);
    }

    /// Euler angles (degrees, channel order of each joint) of frame `f`, joint `j`.
    pub fn euler_deg(&self, f: usize, j: usize, order: EulerOrder) -> [f64; 3] {
        order.from_quat_deg(self.local_rotations[f * self.joints() + j])
    }

    /// Removes the root joint when it only carries its child: the child becomes the root with
    /// the composed transform. Returns false (and changes nothing) when the root has more
    /// than one child.
    pub fn drop_root(&mut self) -> bool {
        let s = &self.skeleton;
        let kids = s.children(0);
        if kids.len() != 1 || kids[0] != 1 || s.len() < 2 {
            return false;
        }
        let jn = s.len();
        let frames = self.frames();
        let mut rot = Vec::with_capacity(frames * (jn - 1));
        let mut pos = Vec::with_capacity(frames * (jn - 1));
        for f in 0..frames {
            let r0 = self.local_rotations[f * jn];
            let p0 = self.local_positions[f * jn];
            for j in 1..jn {
                let (r, p) = (self.local_rotations[f * jn + j], self.local_positions[f * jn + j]);
                if j == 1 {
                    rot.push(r0 * r);
                    pos.push(p0 + r0 * p);
                } else {
                    rot.push(r);
                    pos.push(p);
                }
            }
        }
        let old = &self.skeleton;
        let mut offsets: Vec<DVec3> = old.offsets[1..].to_vec();
        offsets[0] = old.offsets[0] + old.offsets[1];
        self.skeleton = Skeleton {
            names: old.names[1..].to_vec(),
            parents: old.parents[1..].iter().map(|p| p.and_then(|p| p.checked_sub(1))).collect(),
            offsets,
            end_sites: old.end_sites[1..].to_vec(),
            channels: old.channels[1..].to_vec(),
        };
        self.skeleton.parents[0] = None;
        self.local_rotations = rot;
        self.local_positions = pos;
        true
    }
}

/// Whether two frame rates are the same rate: within 0.01 %, as BVH files store the frame time
/// rounded (bandai2's 0.0333333 s is 30.00003 fps) and exported models store their rate as f32.
pub fn same_frame_rate(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-4 * b.abs()
}

#[cfg(test)]
mod resample_tests {
    use super::*;

    /// A one-joint clip turning about Y at `deg` degrees per frame and moving 1 unit a frame.
    fn turning(frames: usize, fps: f64, deg: f64) -> Clip {
        let skeleton = Skeleton {
            names: vec!["root".into()],
            parents: vec![None],
            offsets: vec![DVec3::ZERO],
            end_sites: vec![None],
            channels: vec![Default::default()],
        };
        Clip {
            skeleton,
            frame_time: 1.0 / fps,
            local_rotations: (0..frames).map(|f| DQuat::from_rotation_y((f as f64 * deg).to_radians())).collect(),
            local_positions: (0..frames).map(|f| DVec3::new(f as f64, 0.0, 0.0)).collect(),
        }
    }

    #[test]
    fn resampling_slerps_rotations_and_lerps_positions_over_the_same_span() {
        let c = turning(31, 60.0, 10.0);
        let half = c.resampled(30.0);
        assert_eq!(half.frames(), 16);
        assert!((half.fps() - 30.0).abs() < 1e-12);
        // Frame 3 at 30 fps is frame 6 at 60 fps.
        assert!(half.local_rotations[3].angle_between(c.local_rotations[6]) < 1e-9);
        let double = c.resampled(120.0);
        assert_eq!(double.frames(), 61);
        // Halfway between frames 0 and 1: 5 degrees, 0.5 units.
        assert!(double.local_rotations[1].angle_between(DQuat::from_rotation_y(5f64.to_radians())) < 1e-9);
        assert!((double.local_positions[1].x - 0.5).abs() < 1e-12);
        assert!((double.local_positions[60].x - 30.0).abs() < 1e-9);
    }
}
