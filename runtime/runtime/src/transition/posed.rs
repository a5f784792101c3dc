//! Transitions in engine poses ([`EnginePose`]): the context and target go in as root motion
//! plus local joint rotations, and every generated frame comes out the same way, ready for a
//! skinned character.
//!
//! The network works on global joint positions; around it, forward kinematics turns the input
//! poses into positions, and the rotation fit of `zoo_protocol::fit` turns each generated frame
//! back into local rotations (twist, which positions cannot see, slerped from the last context
//! frame's rotations to the target's, as `zoo transition` does). The fit runs on buffers
//! allocated once per runner and state: stepping allocates nothing of its own.

use super::{TransitionRunner, TransitionState, wrong_len};
use crate::error::MotionError;
use crate::pose::{EnginePose, root_delta, root_of, to_dquat, to_dvec3};
use glam::{DQuat, DVec3, Quat, Vec3};
use zoo_motion::quat::slerp;
use zoo_protocol::fit::{FitScratch, fit_rotations_with};

/// Per-runner buffers of posed transitions.
#[derive(Debug, Default)]
pub(super) struct PosedScratch {
    past: Vec<f32>,
    target: Vec<f32>,
    next: Vec<f32>,
    poses: Vec<f32>,
    positions: Vec<DVec3>,
    reference: Vec<DQuat>,
    fitted: Vec<DQuat>,
    global_rot: Vec<DQuat>,
    global_pos: Vec<DVec3>,
    fit: FitScratch,
}

/// Per-character rotations of a posed transition.
#[derive(Clone, Debug, Default)]
pub(super) struct PosedState {
    /// Whether the transition was started from engine poses.
    pub(super) active: bool,
    /// Local rotations of the last context frame (the hips' in world space).
    from: Vec<Quat>,
    /// Local rotations of the target frame (the hips' in world space).
    to: Vec<Quat>,
    /// Root transform of the frame returned last.
    root: (Vec3, Quat),
}

impl PosedState {
    pub(super) fn new(joints: usize) -> Self {
        PosedState {
            active: false,
            from: vec![Quat::IDENTITY; joints],
            to: vec![Quat::IDENTITY; joints],
            root: (Vec3::ZERO, Quat::IDENTITY),
        }
    }
}

/// The world-space rotations of `pose` as BVH stores them (the hips' world rotation first).
fn world_rotations(pose: &EnginePose, out: &mut [Quat]) {
    out.copy_from_slice(&pose.local_rotations);
    out[0] = pose.hips_world_rotation();
}

impl TransitionRunner {
    /// Checks that pose `name[index]` has the model's joint count (allocates only to report).
    fn check_pose(&self, name: &str, index: usize, pose: &EnginePose) -> Result<(), MotionError> {
        let k = self.model.joints;
        if pose.joints() != k {
            return Err(wrong_len(&format!("{name}[{index}].local_rotations"), k, 1, pose.joints()));
        }
        if !pose.global_positions.is_empty() && pose.global_positions.len() != k {
            return Err(wrong_len(&format!("{name}[{index}].global_positions"), k, 1, pose.global_positions.len()));
        }
        Ok(())
    }

    /// Global joint positions of `pose` by forward kinematics over the model's skeleton,
    /// appended to `out`.
    fn pose_positions(&mut self, pose: &EnginePose, out: &mut Vec<f32>) {
        let m = &self.model;
        let s = &mut self.posed;
        let k = m.joints;
        s.global_rot.resize(k, DQuat::IDENTITY);
        s.global_pos.resize(k, DVec3::ZERO);
        for j in 0..k {
            match m.parents[j] {
                None => {
                    s.global_rot[j] = to_dquat(pose.hips_world_rotation());
                    s.global_pos[j] = to_dvec3(pose.hips_world());
                }
                Some(p) => {
                    s.global_pos[j] = s.global_rot[p] * m.offsets[j] + s.global_pos[p];
                    s.global_rot[j] = s.global_rot[p] * to_dquat(pose.local_rotations[j]);
                }
            }
        }
        out.extend(s.global_pos.iter().flat_map(|p| [p.x as f32, p.y as f32, p.z as f32]));
    }

    /// [`TransitionRunner::start`] from engine poses: `past` holds the context frames (at
    /// least one; the model was trained with [`super::TransitionModel::past_frames`]), `target`
    /// the target pose and `next` the pose after it. Then [`TransitionRunner::step_posed`]
    /// returns the transition's frames as engine poses. The deltas of the input poses are not
    /// read.
    pub fn start_posed(
        &mut self,
        state: &mut TransitionState,
        past: &[EnginePose],
        target: &EnginePose,
        next: &EnginePose,
    ) -> Result<(), MotionError> {
        let length = self.model.transition_frames;
        self.start_posed_batch_for(
            std::slice::from_mut(state),
            past,
            std::slice::from_ref(target),
            std::slice::from_ref(next),
            length,
        )
    }

    /// [`TransitionRunner::start_posed`] for `states.len()` characters with a transition of
    /// `length` frames (see [`TransitionRunner::start_for`]): `past` holds the same number of
    /// context frames per character, character-major; `target` and `next` one pose each.
    pub fn start_posed_batch_for(
        &mut self,
        states: &mut [TransitionState],
        past: &[EnginePose],
        target: &[EnginePose],
        next: &[EnginePose],
        length: usize,
    ) -> Result<(), MotionError> {
        self.check_posed_inputs(states.len(), past, target, next)?;
        self.with_positions([past, target, next], |r, [p, t, x]| r.start_batch_for(states, p, t, x, length))?;
        Self::set_posed(states, past, target);
        Ok(())
    }

    /// The checks of the posed starts before any work: a batch, the same number of context
    /// frames per character, one target and next pose each, every pose of the model's joints.
    fn check_posed_inputs(
        &self,
        n: usize,
        past: &[EnginePose],
        target: &[EnginePose],
        next: &[EnginePose],
    ) -> Result<(), MotionError> {
        if n == 0 {
            return Err(MotionError::EmptyBatch);
        }
        if past.is_empty() || !past.len().is_multiple_of(n) {
            return Err(MotionError::BufferLength {
                name: "past".into(),
                expected: n * self.model.past_frames,
                batch: n,
                width: self.model.past_frames,
                found: past.len(),
            });
        }
        for (name, poses) in [("target", target), ("next", next)] {
            if poses.len() != n {
                return Err(wrong_len(name, 1, n, poses.len()));
            }
        }
        for (name, poses) in [("past", past), ("target", target), ("next", next)] {
            for (i, p) in poses.iter().enumerate() {
                self.check_pose(name, i, p)?;
            }
        }
        Ok(())
    }

    /// Records, per character of a posed start, the rotations the fit's twist goes between
    /// (the last context frame's and the target's) and the root it starts from.
    fn set_posed(states: &mut [TransitionState], past: &[EnginePose], target: &[EnginePose]) {
        let per = past.len() / states.len();
        for (c, s) in states.iter_mut().enumerate() {
            let last = &past[(c + 1) * per - 1];
            world_rotations(last, &mut s.posed.from);
            world_rotations(&target[c], &mut s.posed.to);
            s.posed.root = root_of(last.hips_world(), last.hips_world_rotation());
            s.posed.active = true;
        }
    }

    /// A whole transition of `length` frames for `states.len()` characters from engine poses
    /// (`past`, `target` and `next` as in [`TransitionRunner::start_posed_batch_for`]) into
    /// `out` (`N * (length + 1)` poses, character-major: the transition, then the target frame):
    /// the frames of [`TransitionRunner::generate_batch`] (target blend, then the fallback and
    /// the foot lock this runner is set to, [`TransitionRunner::set_model_fallback`] and
    /// [`TransitionRunner::set_foot_lock`]) with local rotations fitted as
    /// [`TransitionRunner::step_posed`] fits them. With neither set, the poses
    /// [`TransitionRunner::start_posed_batch_for`] and `length + 1` steps return (bit for bit for
    /// one character; for several, up to the rounding of tract's batched kernels). This is what
    /// `zoo transition --in-place` writes for the same poses: the fallback and the foot lock
    /// look at the whole transition, so only a whole one gets them (per-frame stepping
    /// returns frames before the target is reached).
    pub fn generate_posed_batch(
        &mut self,
        states: &mut [TransitionState],
        past: &[EnginePose],
        target: &[EnginePose],
        next: &[EnginePose],
        length: usize,
        out: &mut [EnginePose],
    ) -> Result<(), MotionError> {
        let n = states.len();
        self.check_posed_inputs(n, past, target, next)?;
        let steps = length.checked_add(1).ok_or_else(|| MotionError::BeyondTrainedLength {
            requested: length,
            trained: self.model.transition_frames,
        })?;
        if out.len() != n.saturating_mul(steps) {
            return Err(wrong_len("out", steps, n, out.len()));
        }
        for (i, p) in out.iter().enumerate() {
            self.check_pose("out", i, p)?;
        }
        if length > self.model.transition_frames && !self.beyond_trained {
            return Err(MotionError::BeyondTrainedLength { requested: length, trained: self.model.transition_frames });
        }
        let d = 3 * self.model.joints;
        let mut flat = std::mem::take(&mut self.posed.poses);
        flat.resize(n * steps * d, 0.0);
        let result =
            self.with_positions([past, target, next], |r, [p, t, x]| r.generate_batch(states, p, t, x, &mut flat));
        if result.is_ok() {
            Self::set_posed(states, past, target);
            for (c, s) in states.iter_mut().enumerate() {
                for f in 0..steps {
                    let at = (c * steps + f) * d;
                    self.fit_pose(s, f, &flat[at..at + d], &mut out[c * steps + f]);
                }
            }
        }
        self.posed.poses = flat;
        result
    }

    /// [`TransitionRunner::begin_batch`] from engine poses: `first` holds each character's first
    /// context frame, `target` and `next` one pose each; then
    /// [`TransitionRunner::feed_posed_batch`] the other `past_frames - 1` context frames as the
    /// game plays them, and [`TransitionRunner::step_posed_batch`]. The transition
    /// [`TransitionRunner::start_posed_batch_for`] starts from the same poses, bit for bit.
    pub fn begin_posed_batch(
        &mut self,
        states: &mut [TransitionState],
        first: &[EnginePose],
        target: &[EnginePose],
        next: &[EnginePose],
        past_frames: usize,
        length: usize,
    ) -> Result<(), MotionError> {
        let n = states.len();
        if n == 0 {
            return Err(MotionError::EmptyBatch);
        }
        for (name, poses) in [("first", first), ("target", target), ("next", next)] {
            if poses.len() != n {
                return Err(wrong_len(name, 1, n, poses.len()));
            }
            for (i, p) in poses.iter().enumerate() {
                self.check_pose(name, i, p)?;
            }
        }
        self.with_positions([first, target, next], |r, [p, t, x]| r.begin_batch(states, p, t, x, past_frames, length))?;
        for (c, s) in states.iter_mut().enumerate() {
            world_rotations(&first[c], &mut s.posed.from);
            world_rotations(&target[c], &mut s.posed.to);
            s.posed.root = root_of(first[c].hips_world(), first[c].hips_world_rotation());
            s.posed.active = true;
        }
        Ok(())
    }

    /// [`TransitionRunner::feed_batch`] from engine poses: the next context frame of each
    /// character of a transition begun with [`TransitionRunner::begin_posed_batch`].
    pub fn feed_posed_batch(
        &mut self,
        states: &mut [TransitionState],
        frame: &[EnginePose],
    ) -> Result<(), MotionError> {
        let n = states.len();
        if frame.len() != n {
            return Err(wrong_len("frame", 1, n, frame.len()));
        }
        for (i, p) in frame.iter().enumerate() {
            self.check_pose("frame", i, p)?;
        }
        if let Some(c) = states.iter().position(|s| !s.posed.active) {
            return Err(MotionError::TransitionSequence {
                character: c,
                reason: "this transition was begun from positions (begin_batch); feed it positions (feed_batch)".into(),
            });
        }
        self.with_positions([frame, &[], &[]], |r, [p, _, _]| r.feed_batch(states, p))?;
        for (c, s) in states.iter_mut().enumerate() {
            world_rotations(&frame[c], &mut s.posed.from);
            s.posed.root = root_of(frame[c].hips_world(), frame[c].hips_world_rotation());
        }
        Ok(())
    }

    /// Runs `f` on the global positions of three groups of poses (past, target, next), held in
    /// the runner's buffers, which are kept for the next call.
    fn with_positions<R>(&mut self, groups: [&[EnginePose]; 3], f: impl FnOnce(&mut Self, [&[f32]; 3]) -> R) -> R {
        let mut buffers = [
            std::mem::take(&mut self.posed.past),
            std::mem::take(&mut self.posed.target),
            std::mem::take(&mut self.posed.next),
        ];
        for (poses, buffer) in groups.iter().zip(buffers.iter_mut()) {
            buffer.clear();
            for pose in *poses {
                self.pose_positions(pose, buffer);
            }
        }
        let result = f(self, [&buffers[0], &buffers[1], &buffers[2]]);
        let [p, t, x] = buffers;
        (self.posed.past, self.posed.target, self.posed.next) = (p, t, x);
        result
    }

    /// The next frame of a transition started with [`TransitionRunner::start_posed`], as an
    /// engine pose: the frame [`TransitionRunner::step`] returns, with local rotations fitted
    /// to it, the root motion since the previous frame (the last context frame for the first
    /// one), and global positions when `pose` has room for them (forward kinematics of the
    /// fitted rotations: the skeleton's bone lengths, exactly).
    pub fn step_posed(&mut self, state: &mut TransitionState, pose: &mut EnginePose) -> Result<(), MotionError> {
        self.step_posed_batch(std::slice::from_mut(state), std::slice::from_mut(pose))
    }

    /// [`TransitionRunner::step_posed`] for `states.len()` characters in one graph run.
    pub fn step_posed_batch(
        &mut self,
        states: &mut [TransitionState],
        poses: &mut [EnginePose],
    ) -> Result<(), MotionError> {
        let (n, k) = (states.len(), self.model.joints);
        let d = 3 * k;
        if poses.len() != n {
            return Err(wrong_len("poses", 1, n, poses.len()));
        }
        for (c, p) in poses.iter().enumerate() {
            self.check_pose("poses", c, p)?;
        }
        if let Some(c) = states.iter().position(|s| s.started && !s.posed.active) {
            return Err(MotionError::TransitionSequence {
                character: c,
                reason:
                    "this transition was started from positions (start); start it with start_posed to step engine poses"
                        .into(),
            });
        }
        let mut flat = std::mem::take(&mut self.posed.poses);
        flat.resize(n * d, 0.0);
        let result = self.step_batch(states, &mut flat);
        if result.is_ok() {
            for (c, (s, pose)) in states.iter_mut().zip(poses.iter_mut()).enumerate() {
                let f = s.frames - 1;
                self.fit_pose(s, f, &flat[c * d..(c + 1) * d], pose);
            }
        }
        self.posed.poses = flat;
        result
    }

    /// Fits the local rotations of frame `f` of `0..=L` (`positions`, `3K` values), the frame
    /// after the one fitted last, and writes the engine pose.
    fn fit_pose(&mut self, s: &mut TransitionState, f: usize, positions: &[f32], pose: &mut EnginePose) {
        let m = &self.model;
        let scratch = &mut self.posed;
        let k = m.joints;
        // Frame f of 0..=L: the twist goes from the last context frame (w = 0) to the target (w = 1).
        let w = (f + 1) as f64 / (s.length + 1) as f64;
        scratch.positions.clear();
        scratch.positions.extend(positions.chunks_exact(3).map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)));
        scratch.reference.clear();
        scratch
            .reference
            .extend(s.posed.from.iter().zip(&s.posed.to).map(|(a, b)| slerp(to_dquat(*a), to_dquat(*b), w)));
        scratch.fitted.resize(k, DQuat::IDENTITY);
        fit_rotations_with(
            &mut scratch.fit,
            &m.parents,
            &m.offsets,
            &scratch.positions,
            &scratch.reference,
            &mut scratch.fitted,
        );
        let hips = scratch.positions[0].as_vec3();
        let hips_rotation = scratch.fitted[0].as_quat().normalize();
        let (root_position, root_rotation) = root_of(hips, hips_rotation);
        let (delta, yaw) = root_delta(s.posed.root.0, s.posed.root.1, root_position, root_rotation);
        s.posed.root = (root_position, root_rotation);
        let inverse = root_rotation.inverse();
        pose.root_position = root_position;
        pose.root_rotation = root_rotation;
        pose.root_delta_position = delta;
        pose.root_delta_yaw = yaw;
        pose.hips_position = inverse * (hips - root_position);
        for (out, q) in pose.local_rotations.iter_mut().zip(&scratch.fitted) {
            *out = q.as_quat().normalize();
        }
        pose.local_rotations[0] = (inverse * hips_rotation).normalize();
        if pose.global_positions.len() == k {
            let (gr, gp) = (&mut scratch.global_rot, &mut scratch.global_pos);
            gr.resize(k, DQuat::IDENTITY);
            gp.resize(k, DVec3::ZERO);
            for j in 0..k {
                match m.parents[j] {
                    None => {
                        gr[j] = scratch.fitted[j];
                        gp[j] = scratch.positions[0];
                    }
                    Some(p) => {
                        gp[j] = gr[p] * m.offsets[j] + gp[p];
                        gr[j] = gr[p] * scratch.fitted[j];
                    }
                }
            }
            for (out, p) in pose.global_positions.iter_mut().zip(gp.iter()) {
                *out = p.as_vec3();
            }
        }
    }
}
