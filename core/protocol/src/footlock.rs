//! Foot locking: a post-process that removes foot skate from generated transitions.
//!
//! A learned transition places the feet close to the ground where they should be planted, but
//! lets them slide a little (foot skate). [`FootLock`] pins each ankle during each contact and
//! re-solves the leg with two-bone IK so bone lengths are kept:
//!
//! - contact weight of the ankle: `clamp(2 - 2^(h / contact_height), 0, 1)` at height `h` above
//!   its ground level (the lowest height of that joint over the context frame, the transition
//!   and the target: flat ground under each foot), times a speed gate that is 1 up to
//!   `lock_speed` and 0 from `swing_speed` on (a slide is slow, a swing landing is not);
//! - a contact is a run of frames with weight >= 1/2; the ankle is pinned at the weighted mean
//!   of its positions over the run, or at its position in the context frame when the run starts
//!   the transition, or in the target frame when it ends it, so the transition still joins both;
//! - between contacts the horizontal correction is interpolated linearly in time, from zero at
//!   the context frame to zero at the target frame;
//! - only `strength` (default 1/2) of that correction is applied: in the bandai2 benchmark a
//!   full pin moved the legs away from the ground truth more than half a pin did, for a little
//!   less skate;
//! - a foot that moves faster than `lift_speed` while its ankle or a toe is within
//!   `lift_height` of the ground is raised towards that clearance (a swinging foot is off the
//!   ground; a learned transition tends to drag it, which reads as skate);
//! - the ankle reaches its corrected position by two-bone IK of hip, knee and ankle (the knee
//!   stays in its bend plane); the toes move with the ankle, so the foot keeps the orientation
//!   the model gave it (locking toes on their own turns the foot and costs accuracy: on the
//!   bandai2 benchmark at n = 30 it raised L2Q from 0.85 to 1.02 for the same skate).
//!
//! It needs the whole transition (it is applied by `generate`, after the target blend). It
//! changes horizontal positions, and heights only where it lifts a dragged foot. Positions are
//! `f32` global positions, joint-major, `+Y` up, in clip units (cm for bandai2).

/// One leg: joints from the hip down (indices into the skeleton).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Leg {
    /// Upper leg (hip joint).
    pub hip: usize,
    /// Lower leg (knee joint).
    pub knee: usize,
    /// Foot (ankle joint).
    pub ankle: usize,
    /// Children of the ankle (toes), moved with it.
    pub toes: Vec<usize>,
}

/// Foot-lock post-process (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct FootLock {
    /// The legs to clean.
    pub legs: Vec<Leg>,
    /// Height above ground where contact ends, clip units (default 5 cm).
    pub contact_height: f32,
    /// Horizontal speed (clip units per frame) up to which a grounded joint is fully locked
    /// (default 8 cm/frame).
    pub lock_speed: f32,
    /// Horizontal speed from which a joint is moving on purpose and not locked (default 16).
    pub swing_speed: f32,
    /// Fraction of the horizontal correction applied, in `0..=1` (default 0.5: planted feet
    /// keep half their slide; 1 pins them, at a larger departure from the generated motion).
    pub strength: f32,
    /// Horizontal ankle speed (clip units per frame) from which a foot near the ground is lifted
    /// (default 4 cm/frame; 0 turns lifting off).
    pub lift_speed: f32,
    /// Clearance above the ground a moving foot is lifted towards (default 4 cm).
    pub lift_height: f32,
}

impl FootLock {
    /// Finds the legs of a skeleton by joint name: every joint whose name contains `foot`
    /// (any case) and has a parent and grandparent is an ankle. `None` without such a joint.
    /// Defaults suit centimetre units.
    pub fn from_skeleton(names: &[String], parents: &[Option<usize>]) -> Option<FootLock> {
        let legs: Vec<Leg> = names
            .iter()
            .enumerate()
            .filter(|(_, n)| n.to_ascii_lowercase().contains("foot"))
            .filter_map(|(ankle, _)| {
                let knee = parents.get(ankle).copied().flatten()?;
                let hip = parents.get(knee).copied().flatten()?;
                let toes = (0..parents.len()).filter(|&j| parents[j] == Some(ankle)).collect();
                Some(Leg { hip, knee, ankle, toes })
            })
            .collect();
        (!legs.is_empty()).then_some(FootLock {
            legs,
            contact_height: 5.0,
            lock_speed: 8.0,
            swing_speed: 16.0,
            strength: 0.5,
            lift_speed: 4.0,
            lift_height: 4.0,
        })
    }

    /// Applies the lock to `frames` (`n * 3K` values) that follow the frame `prev` (`3K`,
    /// unchanged) and end on the target frame, which is kept. Frames are changed in place.
    pub fn apply(&self, prev: &[f32], frames: &mut [f32]) {
        let d = prev.len();
        if d == 0 || frames.len() < 2 * d || !frames.len().is_multiple_of(d) {
            return;
        }
        let n = frames.len() / d - 1; // transition frames; the last frame is the target
        let raw = frames.to_vec();
        let frame = |t: isize, j: usize| -> [f32; 3] {
            let src = if t < 0 { prev } else { &raw[t as usize * d..] };
            [src[3 * j], src[3 * j + 1], src[3 * j + 2]]
        };
        for leg in &self.legs {
            // Ground level of the ankle and of each toe: its lowest height over the window.
            let ground: Vec<f32> = std::iter::once(leg.ankle)
                .chain(leg.toes.iter().copied())
                .map(|j| (-1..=n as isize).map(|u| frame(u, j)[1]).fold(f32::INFINITY, f32::min))
                .collect();
            let offsets = self.offsets(n, ground[0], |t| frame(t, leg.ankle));
            for (t, o) in offsets.iter().enumerate() {
                let f = &mut frames[t * d..(t + 1) * d];
                let get = |f: &[f32], j: usize| glam::Vec3::new(f[3 * j], f[3 * j + 1], f[3 * j + 2]);
                let (hip, knee, ankle) = (get(f, leg.hip), get(f, leg.knee), get(f, leg.ankle));
                let lift = self.lift(t, leg, &ground, &frame);
                let goal = ankle + glam::Vec3::new(self.strength * o[0], lift, self.strength * o[1]);
                let (new_knee, new_ankle) = two_bone_ik(hip, knee, ankle, goal);
                let set = |f: &mut [f32], j: usize, p: glam::Vec3| f[3 * j..3 * j + 3].copy_from_slice(&p.to_array());
                set(f, leg.knee, new_knee);
                set(f, leg.ankle, new_ankle);
                // The toes move with the ankle: the foot keeps its orientation.
                for &j in &leg.toes {
                    set(f, j, get(f, j) + (new_ankle - ankle));
                }
            }
        }
    }
}

impl FootLock {
    /// Height to add to the ankle (and toes) at transition frame `t`: a foot moving faster than
    /// `lift_speed` with its ankle or a toe closer than `lift_height` to the ground is raised
    /// towards that clearance, fully from twice `lift_speed` on (a swinging foot is off the
    /// ground; a learned transition tends to drag it).
    fn lift(&self, t: usize, leg: &Leg, ground: &[f32], frame: &impl Fn(isize, usize) -> [f32; 3]) -> f32 {
        if self.lift_speed <= 0.0 || self.lift_height <= 0.0 {
            return 0.0;
        }
        let (cur, last) = (frame(t as isize, leg.ankle), frame(t as isize - 1, leg.ankle));
        let v = (cur[0] - last[0]).hypot(cur[2] - last[2]);
        let clearance = std::iter::once(leg.ankle)
            .chain(leg.toes.iter().copied())
            .zip(ground)
            .map(|(j, g)| frame(t as isize, j)[1] - g)
            .fold(f32::INFINITY, f32::min);
        ((v - self.lift_speed) / self.lift_speed).clamp(0.0, 1.0) * (self.lift_height - clearance).max(0.0)
    }

    /// Horizontal corrections `(x, z)` of one joint for transition frames `0..n`; `frame(t)`
    /// gives its position at `t` in `-1..=n` (`-1` the context frame, `n` the target), `ground`
    /// its lowest height over those frames.
    fn offsets(&self, n: usize, ground: f32, frame: impl Fn(isize) -> [f32; 3]) -> Vec<[f32; 2]> {
        let weight: Vec<f32> = (0..n as isize)
            .map(|t| {
                let (cur, last) = (frame(t), frame(t - 1));
                let v = (cur[0] - last[0]).hypot(cur[2] - last[2]);
                let gate = ((self.swing_speed - v) / (self.swing_speed - self.lock_speed).max(1e-6)).clamp(0.0, 1.0);
                (2.0 - ((cur[1] - ground) / self.contact_height).exp2()).clamp(0.0, 1.0) * gate
            })
            .collect();
        // Anchors: (frame, correction) pairs, from zero at the context frame to zero at the target.
        let mut anchors: Vec<(isize, [f32; 2])> = vec![(-1, [0.0; 2])];
        let mut t = 0;
        while t < n {
            if weight[t] < 0.5 {
                t += 1;
                continue;
            }
            let start = t;
            while t < n && weight[t] >= 0.5 {
                t += 1;
            }
            let pin = if start == 0 {
                let p = frame(-1);
                [p[0], p[2]]
            } else if t == n {
                let p = frame(n as isize);
                [p[0], p[2]]
            } else {
                let (mut sum, mut wsum) = ([0f32; 2], 0f32);
                for u in start..t {
                    let p = frame(u as isize);
                    sum = [sum[0] + weight[u] * p[0], sum[1] + weight[u] * p[2]];
                    wsum += weight[u];
                }
                [sum[0] / wsum, sum[1] / wsum]
            };
            for u in start..t {
                let p = frame(u as isize);
                anchors.push((u as isize, [pin[0] - p[0], pin[1] - p[2]]));
            }
        }
        anchors.push((n as isize, [0.0; 2]));
        // Linear interpolation between anchors (every contact frame is an anchor).
        let mut out = vec![[0f32; 2]; n];
        for pair in anchors.windows(2) {
            let ((t0, o0), (t1, o1)) = (pair[0], pair[1]);
            for u in (t0 + 1).max(0)..t1.min(n as isize) {
                let a = (u - t0) as f32 / (t1 - t0) as f32;
                out[u as usize] = [o0[0] + a * (o1[0] - o0[0]), o0[1] + a * (o1[1] - o0[1])];
            }
            if (0..n as isize).contains(&t1) {
                out[t1 as usize] = o1;
            }
        }
        out
    }
}

/// Two-bone IK in positions: moves `ankle` to `goal` (or as close as the leg reaches) keeping
/// `|knee - hip|` and `|ankle - knee|`, the knee staying in the plane of hip, goal and the old
/// knee. Returns the new knee and ankle.
pub fn two_bone_ik(hip: glam::Vec3, knee: glam::Vec3, ankle: glam::Vec3, goal: glam::Vec3) -> (glam::Vec3, glam::Vec3) {
    let (a, b) = ((knee - hip).length(), (ankle - knee).length());
    let to_goal = goal - hip;
    let dist = to_goal.length();
    if a <= 1e-6 || b <= 1e-6 || dist <= 1e-6 {
        return (knee, ankle);
    }
    let u = to_goal / dist;
    let d = dist.clamp((a - b).abs() + 1e-4, a + b - 1e-4);
    let pole = (knee - hip) - u * (knee - hip).dot(u);
    let p = if pole.length() > 1e-5 { pole.normalize() } else { u.any_orthonormal_vector() };
    let x = (a * a - b * b + d * d) / (2.0 * d);
    let y = (a * a - x * x).max(0.0).sqrt();
    (hip + u * x + p * y, hip + u * d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Hip, knee, ankle, toe of one leg.
    fn skeleton() -> (Vec<String>, Vec<Option<usize>>) {
        let names = ["Hips", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L"].map(String::from).to_vec();
        (names, vec![None, Some(0), Some(1), Some(2), Some(3)])
    }

    /// A leg standing with the foot at `(x, z)` on the ground (y = 0), the hips above.
    fn pose(hips_x: f32, foot_x: f32, foot_y: f32) -> Vec<f32> {
        let hips = Vec3::new(hips_x, 84.0, 0.0);
        let hip = hips + Vec3::new(0.0, -5.0, 0.0);
        let ankle = Vec3::new(foot_x, 8.0 + foot_y, 0.0);
        let (knee, ankle) = two_bone_ik(hip, hip + Vec3::new(0.0, -40.0, 5.0), hip + Vec3::new(0.0, -77.0, 0.0), ankle);
        let toe = ankle + Vec3::new(12.0, -8.0, 0.0);
        [hips, hip, knee, ankle, toe].iter().flat_map(|p| p.to_array()).collect()
    }

    /// The benchmark's skate of one joint: horizontal displacement weighted by contact
    /// (`2.5` cm height scale, ground at `ground`).
    fn skate(frames: &[f32], d: usize, joint: usize, ground: f32) -> f32 {
        frames
            .windows(2 * d)
            .step_by(d)
            .map(|w| {
                let (a, b) = (&w[3 * joint..], &w[d + 3 * joint..]);
                let v = ((b[0] - a[0]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
                v * (2.0 - ((b[1] - ground) / 2.5).exp2()).clamp(0.0, 1.0)
            })
            .sum()
    }

    #[test]
    fn legs_are_found_by_name() {
        let (names, parents) = skeleton();
        let lock = FootLock::from_skeleton(&names, &parents).unwrap();
        assert_eq!(lock.legs, vec![Leg { hip: 1, knee: 2, ankle: 3, toes: vec![4] }]);
        assert!(FootLock::from_skeleton(&names[..2], &parents[..2]).is_none());
    }

    #[test]
    fn ik_keeps_bone_lengths_and_reaches() {
        let (hip, knee, ankle) = (Vec3::new(0.0, 85.0, 0.0), Vec3::new(0.0, 45.0, 6.0), Vec3::new(0.0, 8.0, 0.0));
        let goal = Vec3::new(10.0, 10.0, 3.0);
        let (k, a) = two_bone_ik(hip, knee, ankle, goal);
        assert!((a - goal).length() < 1e-3, "{a} vs {goal}");
        assert!(((k - hip).length() - (knee - hip).length()).abs() < 1e-3);
        assert!(((a - k).length() - (ankle - knee).length()).abs() < 1e-3);
        // Out of reach: the leg straightens towards the goal.
        let (_, a) = two_bone_ik(hip, knee, ankle, Vec3::new(0.0, -200.0, 0.0));
        assert!(a.y < ankle.y && a.x.abs() < 1e-3);
    }

    #[test]
    fn a_sliding_planted_foot_is_held_and_the_target_is_kept() {
        let (names, parents) = skeleton();
        let mut lock = FootLock::from_skeleton(&names, &parents).unwrap();
        lock.strength = 1.0;
        let d = 15;
        // The body walks forward while the planted foot slides 0.5 cm per frame (skate), then
        // the foot lifts (frames 10..16) and lands ahead; 20 frames and the target.
        let foot = |t: usize| -> (f32, f32) {
            match t {
                0..10 => (0.5 * t as f32, 0.0),
                10..16 => (5.0 + 6.0 * (t - 9) as f32, 15.0 * ((t - 9) as f32 * 0.5).sin().abs()),
                _ => (41.0 + 0.5 * (t - 16) as f32, 0.0),
            }
        };
        let prev = pose(0.0, 0.0, 0.0);
        let mut frames: Vec<f32> = (1..=21).flat_map(|t| pose(2.0 * t as f32, foot(t).0, foot(t).1)).collect();
        let target = frames[20 * d..].to_vec();
        let raw = frames.clone();
        lock.apply(&prev, &mut frames);
        assert_eq!(&frames[20 * d..], &target[..], "the target frame is kept");
        // Planted frames 1..9: the ankle does not move; the raw one slid 4 cm.
        let ankle_x = |f: &[f32], t: usize| f[t * d + 9];
        for t in 1..9 {
            assert!((ankle_x(&frames, t) - ankle_x(&frames, 0)).abs() < 0.05, "frame {t}");
        }
        assert!((ankle_x(&raw, 8) - ankle_x(&raw, 0)).abs() > 3.9);
        // Less skate overall; bone lengths kept.
        let (after, before) = (skate(&frames[..20 * d], d, 3, 8.0), skate(&raw[..20 * d], d, 3, 8.0));
        assert!(after < 0.4 * before, "skate {after} after the lock, {before} before");
        for t in 0..20 {
            let p = |j: usize| Vec3::from_slice(&frames[t * d + 3 * j..]);
            let q = |j: usize| Vec3::from_slice(&raw[t * d + 3 * j..]);
            for (a, b) in [(1, 2), (2, 3), (3, 4)] {
                let (l, l0) = ((p(a) - p(b)).length(), (q(a) - q(b)).length());
                assert!((l - l0).abs() < 1e-2, "frame {t} bone {a}-{b}: {l} vs {l0}");
            }
            // The foot keeps its orientation.
            let foot = |f: &[f32]| Vec3::from_slice(&f[t * d + 12..]) - Vec3::from_slice(&f[t * d + 9..]);
            assert!((foot(&frames) - foot(&raw)).length() < 1e-4, "frame {t}");
        }
    }

    #[test]
    fn a_dragged_swinging_foot_is_lifted_and_a_planted_one_is_not() {
        let (names, parents) = skeleton();
        let lock = FootLock::from_skeleton(&names, &parents).unwrap();
        let d = 15;
        // Frames 1..=5 planted (foot still), 6..=10 the foot swings forward 10 cm per frame but
        // stays on the ground (dragged), 11..=15 planted again; then the target.
        let foot_x = |t: usize| 10.0 * (t.clamp(5, 10) - 5) as f32;
        let prev = pose(0.0, 0.0, 0.0);
        let raw: Vec<f32> = (1..=16).flat_map(|t| pose(3.0 * t as f32, foot_x(t), 0.0)).collect();
        let mut frames = raw.clone();
        lock.apply(&prev, &mut frames);
        let ankle_y = |f: &[f32], t: usize| f[t * d + 10];
        let toe_y = |f: &[f32], t: usize| f[t * d + 13];
        for t in 5..10 {
            // transition frame t is clip frame t + 1: swinging at 10 cm/frame
            let lifted = ankle_y(&frames, t) - ankle_y(&raw, t);
            assert!(lifted > 3.0, "frame {t} lifted {lifted}");
            assert!((toe_y(&frames, t) - toe_y(&raw, t) - lifted).abs() < 1e-3, "the toes follow");
        }
        for t in (0..4).chain(11..15) {
            assert!((ankle_y(&frames, t) - ankle_y(&raw, t)).abs() < 1e-3, "planted frame {t} is not lifted");
        }
    }

    #[test]
    fn strength_scales_the_correction() {
        let (names, parents) = skeleton();
        let d = 15;
        let prev = pose(0.0, 0.0, 0.0);
        let raw: Vec<f32> = (1..=11).flat_map(|t| pose(2.0 * t as f32, 0.5 * t as f32, 0.0)).collect();
        let ankle_x = |f: &[f32], t: usize| f[t * d + 9];
        let mut lock = FootLock::from_skeleton(&names, &parents).unwrap();
        let mut shift = Vec::new();
        for strength in [0.0, 0.5, 1.0] {
            lock.strength = strength;
            let mut frames = raw.clone();
            lock.apply(&prev, &mut frames);
            shift.push(ankle_x(&frames, 5) - ankle_x(&raw, 5));
        }
        assert_eq!(shift[0], 0.0);
        assert!(shift[2] < -2.0, "the sliding ankle is pulled back: {shift:?}");
        assert!((shift[1] - 0.5 * shift[2]).abs() < 0.05, "{shift:?}");
    }
}
