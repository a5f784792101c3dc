//! The transition's foot lock, the one every entry point runs (`zoo transition --foot-lock`,
//! the benchmark's `+lock` methods, the C ABI, Python, Unity): the generated positions are
//! first put on the model's skeleton (rotations fitted, `zoo_protocol::fit`; bones at their rest
//! lengths), the skeleton's own positions locked (`zoo_protocol::footlock`), and the locked
//! positions fitted again. Locking the skeleton's positions rather than the network's makes the
//! fitted result keep the locked feet exactly: a skinned character, or a clip written from the
//! rotations, shows what was locked.

use glam::{DQuat, DVec3};
use zoo_motion::fk::forward_kinematics_frame;
use zoo_protocol::fit::{FitScratch, fit_rotations_with};
use zoo_protocol::footlock::FootLock;

/// A [`FootLock`] on a skeleton, with its buffers.
#[derive(Clone, Debug)]
pub(crate) struct FittedLock {
    lock: FootLock,
    parents: Vec<Option<usize>>,
    offsets: Vec<DVec3>,
    scratch: FitScratch,
    rot: Vec<DQuat>,
    pos: Vec<DVec3>,
    global_rot: Vec<DQuat>,
    global_pos: Vec<DVec3>,
}

impl FittedLock {
    /// The lock on the skeleton of `parents` and rest `offsets` (the root's ignored).
    pub(crate) fn new(lock: FootLock, parents: Vec<Option<usize>>, offsets: Vec<DVec3>) -> FittedLock {
        let k = parents.len();
        FittedLock {
            lock,
            parents,
            offsets,
            scratch: FitScratch::default(),
            rot: vec![DQuat::IDENTITY; k],
            pos: vec![DVec3::ZERO; k],
            global_rot: vec![DQuat::IDENTITY; k],
            global_pos: vec![DVec3::ZERO; k],
        }
    }

    /// The lock itself.
    pub(crate) fn lock(&self) -> &FootLock {
        &self.lock
    }

    /// Replaces `frame` (`3K` global positions) by the positions of the skeleton fitted to it.
    fn on_skeleton(&mut self, frame: &mut [f32]) {
        let k = self.parents.len();
        for (p, v) in self.pos.iter_mut().zip(frame.chunks_exact(3)) {
            *p = DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
        }
        // Positions do not depend on the twist the reference gives (only rotations do): the
        // identity serves.
        let reference = vec![DQuat::IDENTITY; k];
        fit_rotations_with(&mut self.scratch, &self.parents, &self.offsets, &self.pos, &reference, &mut self.rot);
        let mut local = self.offsets.clone();
        local[0] = self.pos[0];
        forward_kinematics_frame(&self.parents, &self.rot, &local, &mut self.global_rot, &mut self.global_pos);
        for (v, p) in frame.chunks_exact_mut(3).zip(&self.global_pos) {
            v.copy_from_slice(&[p.x as f32, p.y as f32, p.z as f32]);
        }
    }

    /// Locks `frames` (`(n + 1) * 3K` values: the transition, then the target frame, which is
    /// kept) that follow the frame `prev` (`3K`).
    pub(crate) fn apply(&mut self, prev: &[f32], frames: &mut [f32]) {
        let d = prev.len();
        if d == 0 || frames.len() < 2 * d || !frames.len().is_multiple_of(d) {
            return;
        }
        let n = frames.len() / d - 1;
        for f in frames[..n * d].chunks_exact_mut(d) {
            self.on_skeleton(f);
        }
        self.lock.apply(prev, frames);
        for f in frames[..n * d].chunks_exact_mut(d) {
            self.on_skeleton(f);
        }
    }
}
