//! Transition blending: inertialization (Bollo, GDC 2018) and target blending.

use crate::Clip;
use crate::quat::{from_scaled_axis, to_scaled_axis};
use glam::{DQuat, DVec3};

/// Quintic decay of a scalar offset `x0` (>= 0) with initial velocity `v0` towards 0 over
/// `t1` seconds, evaluated at `t` (Bollo, "Inertialization", GDC 2018).
///
/// Overshoot clamp: when the offset already moves towards 0 (`v0 < 0`) the blend time is
/// shortened to `-5 x0 / v0`, and the initial acceleration is clamped to be >= 0, so the
/// curve never crosses zero.
pub fn inertialize_scalar(x0: f64, v0: f64, t1: f64, t: f64) -> f64 {
    if x0 <= 0.0 || t1 <= 0.0 {
        return 0.0;
    }
    let mut t1 = t1;
    if v0 < 0.0 {
        t1 = t1.min(-5.0 * x0 / v0);
    }
    if t >= t1 {
        return 0.0;
    }
    let a0 = ((-8.0 * v0 * t1 - 20.0 * x0) / (t1 * t1)).max(0.0);
    let t12 = t1 * t1;
    let a = -(a0 * t12 + 6.0 * v0 * t1 + 12.0 * x0) / (2.0 * t12 * t12 * t1);
    let b = (3.0 * a0 * t12 + 16.0 * v0 * t1 + 30.0 * x0) / (2.0 * t12 * t12);
    let c = -(3.0 * a0 * t12 + 12.0 * v0 * t1 + 20.0 * x0) / (2.0 * t12 * t1);
    let d = a0 / 2.0;
    ((((a * t + b) * t + c) * t + d) * t + v0) * t + x0
}

/// Inertialization offset of a vector quantity (e.g. root position): the offset
/// `source - target` at the switch and its velocity decay along the offset's direction.
pub fn inertialize_vec(offset: DVec3, velocity: DVec3, t1: f64, t: f64) -> DVec3 {
    let x0 = offset.length();
    if x0 < 1e-12 {
        return DVec3::ZERO;
    }
    let dir = offset / x0;
    dir * inertialize_scalar(x0, velocity.dot(dir), t1, t)
}

/// Inertialization offset of a rotation: `offset = source * target^-1` at the switch,
/// `angular_velocity` (rad/s, world axis) of that offset; returns the offset rotation to
/// apply on top of the target stream (`offset_t * target_t`).
pub fn inertialize_quat(offset: DQuat, angular_velocity: DVec3, t1: f64, t: f64) -> DQuat {
    let v = to_scaled_axis(offset);
    let x0 = v.length();
    if x0 < 1e-12 {
        return DQuat::IDENTITY;
    }
    let axis = v / x0;
    from_scaled_axis(axis * inertialize_scalar(x0, angular_velocity.dot(axis), t1, t))
}

/// Inertialized transition from a source stream into a target stream, per joint.
///
/// Holds the offsets of the source's last two frames against the target's first frame and
/// decays them over `blend_time` seconds. Rotations are local (joints x frames); positions are
/// root translations.
#[derive(Clone, Debug)]
pub struct Inertializer {
    rot_offset: Vec<DQuat>,
    rot_velocity: Vec<DVec3>,
    pos_offset: DVec3,
    pos_velocity: DVec3,
    blend_time: f64,
}

impl Inertializer {
    /// Records the offsets at the switch.
    ///
    /// `src_prev`/`src_last` are the source's last two frames (local rotations, root position),
    /// `dst_first`/`dst_next` the target's first two frames, `dt` seconds per frame.
    pub fn new(
        src_prev: (&[DQuat], DVec3),
        src_last: (&[DQuat], DVec3),
        dst_first: (&[DQuat], DVec3),
        dst_next: (&[DQuat], DVec3),
        dt: f64,
        blend_time: f64,
    ) -> Self {
        let mut inert = Inertializer {
            rot_offset: Vec::new(),
            rot_velocity: Vec::new(),
            pos_offset: DVec3::ZERO,
            pos_velocity: DVec3::ZERO,
            blend_time,
        };
        inert.reset(src_prev, src_last, dst_first, dst_next, dt, blend_time);
        inert
    }

    /// [`Inertializer::new`] in place: records the offsets of another switch, reusing the
    /// storage (no allocation once it has held as many joints).
    pub fn reset(
        &mut self,
        src_prev: (&[DQuat], DVec3),
        src_last: (&[DQuat], DVec3),
        dst_first: (&[DQuat], DVec3),
        dst_next: (&[DQuat], DVec3),
        dt: f64,
        blend_time: f64,
    ) {
        self.rot_offset.clear();
        self.rot_velocity.clear();
        for j in 0..src_last.0.len() {
            // offset at the switch and one frame before, both against the target stream
            let o1 = (src_last.0[j] * dst_first.0[j].inverse()).normalize();
            let o0 =
                (src_prev.0[j] * (dst_first.0[j] * dst_next.0[j].inverse() * dst_first.0[j]).inverse()).normalize();
            let o0 = if o0.dot(o1) < 0.0 { -o0 } else { o0 };
            let dv = to_scaled_axis((o1 * o0.inverse()).normalize()) / dt;
            self.rot_offset.push(o1);
            self.rot_velocity.push(dv);
        }
        let p1 = src_last.1 - dst_first.1;
        let p0 = src_prev.1 - (dst_first.1 - (dst_next.1 - dst_first.1));
        (self.pos_offset, self.pos_velocity, self.blend_time) = (p1, (p1 - p0) / dt, blend_time);
    }

    /// Applies the decayed offsets at time `t` (seconds since the switch) to a target frame.
    pub fn apply(&self, t: f64, rotations: &mut [DQuat], root: &mut DVec3) {
        for (j, r) in rotations.iter_mut().enumerate() {
            let o = inertialize_quat(self.rot_offset[j], self.rot_velocity[j], self.blend_time, t);
            *r = (o * *r).normalize();
        }
        *root += inertialize_vec(self.pos_offset, self.pos_velocity, self.blend_time, t);
    }
}

/// Inertialization at the seams of a sequence, one frame at a time (the offline stitching tools
/// run it over a whole clip, the runtime's stitch stream as frames arrive, so both give the same
/// frames): from each seam `s` (the first frame of a clip) on, the offset between the frames
/// before the seam and the frames from it (local rotations of every joint and the root joint's
/// position, with their velocities) decays to zero over `blend_frames` frames ([`Inertializer`]);
/// frame `s + k` receives the offset at `(k + 1)` frame times, so the motion continues the
/// previous clip's. Seams are treated in order, each on the frames the earlier ones already
/// blended; a seam without two frames on each side is left as it is.
///
/// [`SeamInertializer::push`] takes frame after frame and releases each one once it is final: a
/// seam frame one push later (its offsets need the frame after it), every other frame at once.
/// Allocates only when more blends run at once than ever before (their offsets are reused).
#[derive(Clone, Debug)]
pub struct SeamInertializer {
    joints: usize,
    blend_frames: usize,
    dt: f64,
    /// Blends still running: the seam's frame and its offsets.
    active: Vec<(usize, Inertializer)>,
    /// Offsets of finished blends, reused by the next seams.
    spare: Vec<Inertializer>,
    /// The last two released frames, the older first.
    last: [(Vec<DQuat>, DVec3); 2],
    /// Frames pushed so far.
    pushed: usize,
    /// The frame being pushed.
    cur: Vec<DQuat>,
    /// A seam frame waiting for the frame after it (when `has_held`).
    held: (Vec<DQuat>, DVec3),
    has_held: bool,
    /// The frames released by the last call, in order (`released` of them).
    out: [(Vec<DQuat>, DVec3); 2],
    released: usize,
}

impl SeamInertializer {
    /// For frames of `joints` rotations, blends of `blend_frames` frames (0: none) at `dt`
    /// seconds per frame.
    pub fn new(joints: usize, blend_frames: usize, dt: f64) -> Self {
        let frame = || (vec![DQuat::IDENTITY; joints], DVec3::ZERO);
        SeamInertializer {
            joints,
            blend_frames,
            dt,
            active: Vec::new(),
            spare: Vec::new(),
            last: [frame(), frame()],
            pushed: 0,
            cur: vec![DQuat::IDENTITY; joints],
            held: frame(),
            has_held: false,
            out: [frame(), frame()],
            released: 0,
        }
    }

    /// A whole sequence of `frames` frames with clips starting at `seams` (indices of at least
    /// `frames` are the caller's to refuse first; they are ignored here): `frame(f, rotations)`
    /// fills frame `f`'s rotations and returns its root position (or the caller's error), and
    /// `put` receives every final frame in order.
    pub fn run<E>(
        &mut self,
        frames: usize,
        seams: &[usize],
        mut frame: impl FnMut(usize, &mut Vec<DQuat>) -> Result<DVec3, E>,
        mut put: impl FnMut(&[DQuat], DVec3),
    ) -> Result<(), E> {
        let mut rotations = Vec::with_capacity(self.joints);
        for f in 0..frames {
            let root = frame(f, &mut rotations)?;
            let n = self.push(&rotations, root, seams.contains(&f));
            for i in 0..n {
                let (r, p) = self.released(i);
                put(r, p);
            }
        }
        for i in 0..self.finish() {
            let (r, p) = self.released(i);
            put(r, p);
        }
        Ok(())
    }

    /// Pushes the next frame (`joints` local rotations and the root position); `seam`: a new
    /// clip starts at it. Returns how many frames became final (0, 1 or 2), read in order with
    /// [`SeamInertializer::released`].
    pub fn push(&mut self, rotations: &[DQuat], root: DVec3, seam: bool) -> usize {
        assert_eq!(rotations.len(), self.joints, "a frame of {} rotations", self.joints);
        let (f, dt, blend) = (self.pushed, self.dt, self.blend_frames);
        self.pushed += 1;
        self.released = 0;
        self.cur.copy_from_slice(rotations);
        let mut root = root;
        // The blends of the earlier seams, in order.
        for (s, inert) in &self.active {
            inert.apply((f - s + 1) as f64 * dt, &mut self.cur, &mut root);
        }
        if self.has_held {
            // The seam at f - 1: offsets from the two frames before it and the two from it.
            let [(p, pp), (l, lp)] = &self.last;
            let (h, hroot) = &self.held;
            let frames = ((&p[..], *pp), (&l[..], *lp), (&h[..], *hroot), (&self.cur[..], root));
            let blend_time = blend as f64 * dt;
            let inert = match self.spare.pop() {
                Some(mut inert) => {
                    inert.reset(frames.0, frames.1, frames.2, frames.3, dt, blend_time);
                    inert
                }
                None => Inertializer::new(frames.0, frames.1, frames.2, frames.3, dt, blend_time),
            };
            inert.apply(dt, &mut self.held.0, &mut self.held.1);
            if blend > 1 {
                inert.apply(2.0 * dt, &mut self.cur, &mut root);
            }
            self.active.push((f - 1, inert));
            self.has_held = false;
            self.out[0].0.copy_from_slice(&self.held.0);
            self.out[0].1 = self.held.1;
            self.release(0);
        }
        // Blends that end with this frame (the oldest seams come first) give their storage back.
        while self.active.first().is_some_and(|(s, _)| f + 1 - s >= blend) {
            let (_, inert) = self.active.remove(0);
            self.spare.push(inert);
        }
        if seam && f >= 2 && blend > 0 {
            self.held.0.copy_from_slice(&self.cur);
            self.held.1 = root;
            self.has_held = true;
        } else {
            let i = self.released;
            self.out[i].0.copy_from_slice(&self.cur);
            self.out[i].1 = root;
            self.release(i);
        }
        self.released
    }

    /// Ends the sequence: a seam frame still waiting (the last frame) is released as it is.
    /// Returns how many frames became final (0 or 1).
    pub fn finish(&mut self) -> usize {
        self.released = 0;
        if self.has_held {
            self.has_held = false;
            self.out[0].0.copy_from_slice(&self.held.0);
            self.out[0].1 = self.held.1;
            self.release(0);
        }
        self.released
    }

    /// Final frame `i` (`0..` the count the last [`SeamInertializer::push`] or
    /// [`SeamInertializer::finish`] returned): rotations and root position.
    pub fn released(&self, i: usize) -> (&[DQuat], DVec3) {
        assert!(i < self.released, "frame {i} of {} released", self.released);
        (&self.out[i].0, self.out[i].1)
    }

    /// Releases output slot `i` and keeps it as the newest of the last two frames.
    fn release(&mut self, i: usize) {
        self.last.swap(0, 1);
        self.last[1].0.copy_from_slice(&self.out[i].0);
        self.last[1].1 = self.out[i].1;
        self.released = i + 1;
    }
}

/// Inertialization at each seam (Bollo, GDC 2018; [`Inertializer`]) of an aligned sequence of
/// clips put end to start (joint 0 holding the root): from
/// each seam `s` on (the first frame of a clip), the offset between the frames before the seam
/// and the frames from it (local rotations of every joint and the root joint's position, with
/// their velocities) is decayed to zero over `blend_frames` frames. Frame `s + k` receives the
/// offset at `(k + 1)` frame times, so the motion continues the previous clip's. Seams are
/// treated in order on the already blended sequence; a seam without two frames on each side
/// is left as it is.
pub fn inertialize_seams(aligned: &Clip, seams: &[usize], blend_frames: usize) -> Clip {
    let mut out = aligned.clone();
    let (frames, j) = (out.frames(), out.joints());
    // The frame-by-frame form, which the runtime's stitch stream runs too.
    let mut next = 0;
    let read = |f: usize, r: &mut Vec<DQuat>| {
        r.clear();
        r.extend_from_slice(&aligned.local_rotations[f * j..(f + 1) * j]);
        Ok::<_, std::convert::Infallible>(aligned.local_positions[f * j])
    };
    let write = |r: &[DQuat], p: DVec3| {
        out.local_rotations[next * j..(next + 1) * j].copy_from_slice(r);
        out.local_positions[next * j] = p;
        next += 1;
    };
    let Ok(()) = SeamInertializer::new(j, blend_frames, aligned.frame_time).run(frames, seams, read, write);
    out.remove_sign_flips();
    out
}

/// Target-blend weight of RTN (Harvey & Pal 2018, eq. 15-16): the weight of the generated
/// frame at transition step `t` (0-based) of a blend covering the last `blend_len` steps of a
/// `len`-step transition; 1 before the blend, falling linearly towards 0 at the target.
pub fn target_blend_weight(t: usize, len: usize, blend_len: usize) -> f64 {
    if blend_len == 0 || t + blend_len < len {
        return 1.0;
    }
    let k = (t + blend_len + 1 - len) as f64; // 1..=blend_len
    1.0 - k / (blend_len as f64 + 1.0)
}

/// Offset weight `w = 1 - (target - t) / blend_len` of RTN's target blend (eq. 16) for frame
/// `t` of a generated sequence whose predicted target is frame `target`: 0 outside the last
/// `blend_len` frames, rising linearly to 1 on the target frame.
pub fn target_blend_offset_weight(t: usize, target: usize, blend_len: usize) -> f64 {
    if blend_len == 0 || t > target || target - t >= blend_len {
        return if blend_len == 0 && t == target { 1.0 } else { 0.0 };
    }
    1.0 - (target - t) as f64 / blend_len as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quintic_boundary_conditions() {
        let (x0, v0, t1) = (2.0, 1.0, 0.5);
        assert!((inertialize_scalar(x0, v0, t1, 0.0) - x0).abs() < 1e-12);
        let h = 1e-6;
        let d = (inertialize_scalar(x0, v0, t1, h) - x0) / h;
        assert!((d - v0).abs() < 1e-3);
        assert!(inertialize_scalar(x0, v0, t1, t1).abs() < 1e-9);
        assert!(inertialize_scalar(x0, v0, t1, t1 - 1e-4).abs() < 1e-9);
    }

    #[test]
    fn overshoot_clamp_never_crosses_zero() {
        for v0 in [-100.0, -10.0, -1.0, 0.0, 5.0] {
            for k in 0..=100 {
                let t = k as f64 * 0.01;
                assert!(inertialize_scalar(1.0, v0, 1.0, t) >= -1e-9, "v0={v0} t={t}");
            }
        }
    }

    #[test]
    fn quat_offset_decays_to_identity() {
        let o = DQuat::from_rotation_y(0.7);
        assert!(inertialize_quat(o, DVec3::ZERO, 0.3, 0.0).dot(o) > 1.0 - 1e-12);
        assert!(inertialize_quat(o, DVec3::ZERO, 0.3, 0.3).dot(DQuat::IDENTITY).abs() > 1.0 - 1e-12);
    }

    #[test]
    fn inertializer_starts_at_source_and_ends_at_target() {
        let a = [DQuat::from_rotation_x(0.4), DQuat::from_rotation_z(-0.2)];
        let b = [DQuat::from_rotation_x(-0.1), DQuat::from_rotation_z(0.3)];
        let (pa, pb) = (DVec3::new(0.0, 90.0, 0.0), DVec3::new(10.0, 95.0, 5.0));
        let inert = Inertializer::new((&a, pa), (&a, pa), (&b, pb), (&b, pb), 1.0 / 30.0, 0.5);
        let (mut r, mut p) = (b, pb);
        inert.apply(0.0, &mut r, &mut p);
        for j in 0..2 {
            assert!(r[j].dot(a[j]).abs() > 1.0 - 1e-9);
        }
        assert!((p - pa).length() < 1e-9);
        let (mut r, mut p) = (b, pb);
        inert.apply(0.5, &mut r, &mut p);
        for j in 0..2 {
            assert!(r[j].dot(b[j]).abs() > 1.0 - 1e-12);
        }
        assert!((p - pb).length() < 1e-12);
    }

    #[test]
    fn blend_weights_ramp_down() {
        let w: Vec<f64> = (0..6).map(|t| target_blend_weight(t, 6, 3)).collect();
        assert_eq!(w[..3], [1.0, 1.0, 1.0]);
        assert!(w[3] > w[4] && w[4] > w[5] && w[5] > 0.0);
    }

    #[test]
    fn offset_weights_follow_eq_16() {
        let w: Vec<f64> = (0..=5).map(|t| target_blend_offset_weight(t, 5, 4)).collect();
        assert_eq!(w, [0.0, 0.0, 0.25, 0.5, 0.75, 1.0]);
        assert_eq!(target_blend_offset_weight(5, 5, 0), 1.0);
        assert_eq!(target_blend_offset_weight(4, 5, 0), 0.0);
    }
}
