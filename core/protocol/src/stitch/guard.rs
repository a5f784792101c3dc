//! The seam guard (not in the paper): no seam of a stitched sequence moves a joint
//! faster than the inertialized sequence does there, at little cost in foot sliding.
//!
//! A refiner meeting motion it never saw can add a pop at a seam: the largest joint speed within
//! a few frames of the seam comes out above what inertialization gives there (docs/rmr.md, "On
//! moves it never saw"). The guard measures, at every seam, that largest speed (every joint,
//! global positions, frames `seam - GUARD_FRAMES ..= seam + GUARD_FRAMES`: the span of the
//! stitching benchmark's pop measure) in the output and in the reference, the aligned clips
//! inertialized at their seams. Where the output's is higher, the output is blended towards
//! itself smoothed over three frames (weights 1, 2, 1) by the smallest weight (bisection) that
//! brings it down to the reference's, constant over the seam's frames and eased out over
//! [`GUARD_RAMP`] frames on each side; a seam that full smoothing cannot bring down gets the
//! full weight. The blend keeps the output's ground root (its path and heading) and changes
//! what is relative to it: the hips' height and rotation relative to the root's heading and
//! every other joint's local rotation.
//!
//! Smoothing the output, rather than blending it towards the inertialized clips, lowers a short
//! burst of speed and leaves a planted foot where it is: on held-out turns of bandai2 the blend
//! towards inertialization cost 11 % more foot sliding for the same pops, the smoothing nothing
//! measurable (docs/rmr-benchmarks.md, "The seam guard: how it works"). `zoo stitch` runs it
//! after the ankle IK and before the foot lock, whose correction changes by at most 1 cm per
//! frame.

use super::StitchLayout;
use glam::{DQuat, DVec3};
use zoo_motion::Clip;
use zoo_motion::fk::forward_kinematics_frame;

/// Frames on each side of a seam over which the largest joint speed is compared.
pub const GUARD_FRAMES: usize = 5;
/// Frames over which a guarded seam's weight eases out on each side.
pub const GUARD_RAMP: usize = 10;
/// Frames on each side of the smoothing the guard blends towards (weights 1, 2, 1).
pub const SMOOTH_RADIUS: usize = 1;
/// Bisection steps of a seam's weight (the weight is found to `2^-10`).
const STEPS: usize = 10;

/// What the guard did to one seam.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuardedSeam {
    /// The seam's first frame.
    pub seam: usize,
    /// Largest joint speed near the seam before the guard (clip units per frame).
    pub before: f64,
    /// The reference's largest joint speed there.
    pub reference: f64,
    /// Blend weight towards the reference (0: untouched).
    pub weight: f64,
}

/// Frames `lo ..= hi` whose speeds (frame minus the one before) are compared at `seam`, or
/// `None` when the sequence is too short.
fn zone(seam: usize, frames: usize) -> Option<(usize, usize)> {
    if seam == 0 || seam >= frames {
        return None;
    }
    let lo = seam.saturating_sub(GUARD_FRAMES).max(1);
    let hi = (seam + GUARD_FRAMES).min(frames.checked_sub(1)?);
    (lo <= hi).then_some((lo, hi))
}

/// The largest joint speed over frames `lo ..= hi` of global positions `gp` (`joints` per frame).
fn top_speed(gp: &[DVec3], joints: usize, lo: usize, hi: usize) -> f64 {
    let mut m: f64 = 0.0;
    for f in lo..=hi {
        for k in 0..joints {
            m = m.max((gp[f * joints + k] - gp[(f - 1) * joints + k]).length());
        }
    }
    m
}

/// Local rotations and hips position of frame `f` of a target the guard blends towards.
#[derive(Clone, Copy)]
struct Target<'a> {
    rotations: &'a [DQuat],
    positions: &'a [DVec3],
    joints: usize,
}

/// Pose of frame `f` of `out` blended towards `target` by `w` on `out`'s ground root, into `rot`
/// (local rotations) and the returned hips position.
fn blend_frame(out: &Clip, target: Target<'_>, layout: &StitchLayout, f: usize, w: f64, rot: &mut [DQuat]) -> DVec3 {
    let j = target.joints;
    let (ro, rr) = (out.rotations_at(f), &target.rotations[f * j..(f + 1) * j]);
    let (po, pr) = (out.positions_at(f)[0], target.positions[f * j]);
    if w <= 0.0 {
        rot.copy_from_slice(ro);
        return po;
    }
    let (go, gr) = (layout.root_of(ro[0], po), layout.root_of(rr[0], pr));
    let local_o = go.rotation().inverse() * ro[0];
    let local_r = gr.rotation().inverse() * rr[0];
    rot[0] = (go.rotation() * local_o.slerp(local_r, w)).normalize();
    for k in 1..rot.len() {
        rot[k] = ro[k].slerp(rr[k], w).normalize();
    }
    DVec3::new(po.x, po.y + w * (pr.y - po.y), po.z)
}

/// `clip` smoothed over `radius` frames on each side (triangular weights), for the frames
/// `wanted` accepts (the others' rotations left as they were): local rotations averaged in the
/// centre frame's hemisphere, the hips' position averaged; its local rotations and positions
/// into `rotations` and `positions`.
fn smooth_frames_into(
    clip: &Clip,
    radius: usize,
    rotations: &mut Vec<DQuat>,
    positions: &mut Vec<DVec3>,
    wanted: impl Fn(usize) -> bool,
) {
    let (frames, j) = (clip.frames(), clip.joints());
    rotations.resize(clip.local_rotations.len(), DQuat::IDENTITY);
    positions.resize(clip.local_positions.len(), DVec3::ZERO);
    positions.copy_from_slice(&clip.local_positions);
    for f in (0..frames).filter(|&f| wanted(f)) {
        let lo = f.saturating_sub(radius);
        let hi = (f + radius).min(frames - 1);
        for k in 0..j {
            let c = clip.local_rotations[f * j + k];
            let mut acc = glam::DVec4::ZERO;
            let mut pos = DVec3::ZERO;
            let mut total = 0.0;
            for g in lo..=hi {
                let w = (radius + 1 - f.abs_diff(g)) as f64;
                let mut q = clip.local_rotations[g * j + k];
                if q.dot(c) < 0.0 {
                    q = -q;
                }
                acc += w * glam::DVec4::from(q);
                if k == 0 {
                    pos += w * clip.local_positions[g * j];
                }
                total += w;
            }
            rotations[f * j + k] = DQuat::from_vec4(acc).normalize();
            if k == 0 {
                positions[f * j] = pos / total;
            }
        }
    }
}

/// A seam's weight profile: 1 over the compared frames (and the frame before them), easing to
/// 0 over [`GUARD_RAMP`] frames on each side.
fn profile(f: usize, lo: usize, hi: usize) -> f64 {
    let d = if f + 1 < lo {
        lo - 1 - f
    } else if f > hi {
        f - hi
    } else {
        return 1.0;
    };
    if d > GUARD_RAMP {
        return 0.0;
    }
    let x = 1.0 - d as f64 / (GUARD_RAMP + 1) as f64;
    x * x * (3.0 - 2.0 * x)
}

/// Guards the seams of `out` against `reference` (the same frames and skeleton: the aligned clips
/// inertialized at `seams`), changing `out` in place; returns what it did per seam. A `reference`
/// of another size leaves `out` as it is and returns nothing; a seam out of `1..frames` is
/// skipped.
pub fn guard_seams(out: &mut Clip, reference: &Clip, seams: &[usize], layout: &StitchLayout) -> Vec<GuardedSeam> {
    let mut report = Vec::with_capacity(seams.len());
    guard_seams_into(out, reference, seams, layout, &mut GuardScratch::default(), &mut report);
    report
}

/// Scratch space of [`guard_seams_into`], reused from call to call so that a caller guarding
/// every few frames (the runtime's stitching stream) allocates nothing once it has grown to the
/// longest clip.
#[derive(Clone, Debug, Default)]
pub struct GuardScratch {
    ref_gr: Vec<DQuat>,
    ref_gp: Vec<DVec3>,
    smooth_rot: Vec<DQuat>,
    smooth_pos: Vec<DVec3>,
    weights: Vec<f64>,
    zone_gp: Vec<DVec3>,
    rot: Vec<DQuat>,
    grot: Vec<DQuat>,
    gpos: Vec<DVec3>,
    local_pos: Vec<DVec3>,
}

impl GuardScratch {
    /// Room for clips of up to `frames` frames of `joints` joints.
    pub fn reserve(&mut self, frames: usize, joints: usize) {
        let n = frames * joints;
        for v in [&mut self.ref_gr, &mut self.smooth_rot] {
            v.reserve(n.saturating_sub(v.len()));
        }
        for v in [&mut self.ref_gp, &mut self.smooth_pos] {
            v.reserve(n.saturating_sub(v.len()));
        }
        self.weights.reserve(frames.saturating_sub(self.weights.len()));
        self.zone_gp.reserve((2 * GUARD_FRAMES + 2) * joints);
        for v in [&mut self.rot, &mut self.grot] {
            v.reserve(joints);
        }
        for v in [&mut self.gpos, &mut self.local_pos] {
            v.reserve(joints);
        }
    }
}

/// [`guard_seams`] with its scratch space in `scratch` and what it did per seam into `report`
/// (cleared first).
pub fn guard_seams_into(
    out: &mut Clip,
    reference: &Clip,
    seams: &[usize],
    layout: &StitchLayout,
    scratch: &mut GuardScratch,
    report: &mut Vec<GuardedSeam>,
) {
    report.clear();
    let mut weights = std::mem::take(&mut scratch.weights);
    weights.clear();
    weights.resize(out.frames(), 0.0);
    guard_weights_into(out, reference, seams, layout, scratch, &mut weights, report);
    apply_guard_weights(out, &weights, layout, scratch);
    scratch.weights = weights;
}

/// The first half of [`guard_seams_into`]: the guard's blend weight of every frame for
/// `seams` (in order, each seam's weight found with those of the seams before it), combined
/// with the weights already in `weights` (one per frame of `out`; zeros for a fresh clip) by
/// their largest, and a report per seam appended to `report`. `out` is not changed.
pub fn guard_weights_into(
    out: &Clip,
    reference: &Clip,
    seams: &[usize],
    layout: &StitchLayout,
    scratch: &mut GuardScratch,
    weights: &mut [f64],
    report: &mut Vec<GuardedSeam>,
) {
    for &seam in seams {
        let Some(mut weighing) = SeamWeighing::start(out, reference, seam, layout, scratch, weights) else { continue };
        while weighing.run(usize::MAX, out, layout, scratch, weights).is_none() {}
        weighing.apply(weights);
        report.push(weighing.report());
    }
}

/// One seam's guard weight (what [`guard_weights_into`] does per seam), found a few evaluations
/// at a time: each evaluation blends the frames the seam compares at one weight and measures
/// their largest joint speed (the bisection takes `STEPS`). A seam reads the frames within
/// [`GUARD_FRAMES`] `+ 2` of it and weighs those within [`GUARD_FRAMES`] `+` [`GUARD_RAMP`] `+ 1`:
/// a caller holding part of a sequence (the runtime's stitching stream, which spreads the
/// evaluations over its pushes) gets the whole sequence's weight from a clip of those frames.
#[derive(Clone, Debug)]
pub struct SeamWeighing {
    seam: usize,
    lo: usize,
    hi: usize,
    reference_top: f64,
    before: f64,
    /// The bisection's bounds and steps taken; the weight once found.
    a: f64,
    b: f64,
    steps: usize,
    weight: Option<f64>,
}

impl SeamWeighing {
    /// Starts weighing `seam` of `out` (its reference the inertialized `reference`, the weights
    /// of the seams before it in `weights`): one evaluation. `None` for a seam with no frames to
    /// compare (frame 0, or past the end).
    pub fn start(
        out: &Clip,
        reference: &Clip,
        seam: usize,
        layout: &StitchLayout,
        scratch: &mut GuardScratch,
        weights: &[f64],
    ) -> Option<SeamWeighing> {
        let (frames, j) = (out.frames(), out.joints());
        if reference.frames() != frames || reference.joints() != j || frames < 2 || weights.len() != frames {
            return None;
        }
        let (lo, hi) = zone(seam, frames)?;
        let GuardScratch { ref_gr, ref_gp, .. } = scratch;
        let n = reference.local_rotations.len();
        ref_gr.resize(n, DQuat::IDENTITY);
        ref_gp.resize(n, DVec3::ZERO);
        for f in lo - 1..=hi {
            let at = f * j..(f + 1) * j;
            forward_kinematics_frame(
                &reference.skeleton.parents,
                &reference.local_rotations[at.clone()],
                &reference.local_positions[at.clone()],
                &mut ref_gr[at.clone()],
                &mut ref_gp[at],
            );
        }
        let reference_top = top_speed(ref_gp, j, lo, hi);
        let mut w = SeamWeighing { seam, lo, hi, reference_top, before: 0.0, a: 0.0, b: 1.0, steps: 0, weight: None };
        w.before = w.speed_at(0.0, out, layout, scratch, weights);
        if w.before <= reference_top {
            w.weight = Some(0.0);
        }
        Some(w)
    }

    /// Runs up to `evaluations` more steps of the bisection; the weight once found.
    pub fn run(
        &mut self,
        evaluations: usize,
        out: &Clip,
        layout: &StitchLayout,
        scratch: &mut GuardScratch,
        weights: &[f64],
    ) -> Option<f64> {
        for _ in 0..evaluations {
            if self.weight.is_some() {
                break;
            }
            let m = 0.5 * (self.a + self.b);
            if self.speed_at(m, out, layout, scratch, weights) > self.reference_top {
                self.a = m;
            } else {
                self.b = m;
            }
            self.steps += 1;
            if self.steps == STEPS {
                self.weight = Some(self.b);
            }
        }
        self.weight
    }

    /// Combines the found weight into `weights` by the largest (the seam's profile: constant
    /// over its compared frames, eased out over [`GUARD_RAMP`] frames on each side).
    pub fn apply(&self, weights: &mut [f64]) {
        let Some(weight) = self.weight.filter(|&w| w > 0.0) else { return };
        let (lo, hi) = (self.lo, self.hi);
        let from = (lo - 1).saturating_sub(GUARD_RAMP);
        let frames = weights.len();
        for (f, wf) in weights.iter_mut().enumerate().take((hi + GUARD_RAMP + 1).min(frames)).skip(from) {
            *wf = wf.max(weight * profile(f, lo, hi));
        }
    }

    /// The seam's first frame in the weighed clip.
    pub fn seam(&self) -> usize {
        self.seam
    }

    /// What the guard did to the seam (weight 0 until found).
    pub fn report(&self) -> GuardedSeam {
        GuardedSeam {
            seam: self.seam,
            before: self.before,
            reference: self.reference_top,
            weight: self.weight.unwrap_or(0.0),
        }
    }

    /// The largest joint speed over the seam's compared frames with the output blended towards
    /// itself smoothed by `w` there (by the weights of the seams before it elsewhere).
    fn speed_at(&self, w: f64, out: &Clip, layout: &StitchLayout, scratch: &mut GuardScratch, weights: &[f64]) -> f64 {
        let (lo, hi, j) = (self.lo, self.hi, out.joints());
        let GuardScratch { smooth_rot, smooth_pos, zone_gp, rot, grot, gpos, local_pos, .. } = scratch;
        smooth_frames_into(out, SMOOTH_RADIUS, smooth_rot, smooth_pos, |f| f + 1 >= lo && f <= hi);
        let smoothed = Target { rotations: smooth_rot, positions: smooth_pos, joints: j };
        for v in [&mut *rot, &mut *grot] {
            v.resize(j, DQuat::IDENTITY);
        }
        for v in [&mut *gpos, &mut *local_pos] {
            v.resize(j, DVec3::ZERO);
        }
        zone_gp.clear();
        for f in lo - 1..=hi {
            let wf = weights[f].max(w * profile(f, lo, hi));
            let hips = blend_frame(out, smoothed, layout, f, wf, rot);
            local_pos.copy_from_slice(out.positions_at(f));
            local_pos[0] = hips;
            forward_kinematics_frame(&out.skeleton.parents, rot, local_pos, grot, gpos);
            zone_gp.extend_from_slice(gpos);
        }
        top_speed(zone_gp, j, 1, hi - lo + 1)
    }
}

/// The second half of [`guard_seams_into`]: blends each frame of `out` with a weight in
/// `weights` (one per frame) towards `out` smoothed.
pub fn apply_guard_weights(out: &mut Clip, weights: &[f64], layout: &StitchLayout, scratch: &mut GuardScratch) {
    let (frames, j) = (out.frames(), out.joints());
    if weights.len() != frames || weights.iter().all(|&w| w <= 0.0) {
        return;
    }
    let GuardScratch { smooth_rot, smooth_pos, rot, .. } = scratch;
    smooth_frames_into(out, SMOOTH_RADIUS, smooth_rot, smooth_pos, |f| weights[f] > 0.0);
    rot.clear();
    rot.resize(j, DQuat::IDENTITY);
    for f in 0..frames {
        if weights[f] > 0.0 {
            let smoothed = Target { rotations: smooth_rot, positions: smooth_pos, joints: j };
            let hips = blend_frame(out, smoothed, layout, f, weights[f], rot);
            out.local_rotations[f * j..(f + 1) * j].copy_from_slice(rot);
            out.local_positions[f * j] = hips;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::Skeleton;

    /// A three-joint leg walking along +Z whose middle joint swings; `wiggle` adds a
    /// frame-to-frame jitter of that joint around frame 20.
    fn clip(wiggle: f64) -> Clip {
        let skeleton = Skeleton {
            names: vec!["Hips".into(), "Leg".into(), "Foot".into()],
            parents: vec![None, Some(0), Some(1)],
            offsets: vec![DVec3::ZERO, DVec3::new(0.0, -40.0, 0.0), DVec3::new(0.0, -40.0, 0.0)],
            end_sites: vec![None; 3],
            channels: vec![zoo_motion::JointChannels::default(); 3],
        };
        let mut local_rotations = Vec::new();
        let mut local_positions = Vec::new();
        for f in 0..40 {
            let sign = if f % 2 == 0 { 1.0 } else { -1.0 };
            let swing = 0.3 * (f as f64 * 0.2).sin() + if (8..33).contains(&f) { wiggle * sign } else { 0.0 };
            local_rotations.extend([DQuat::IDENTITY, DQuat::from_rotation_x(swing), DQuat::IDENTITY]);
            local_positions.extend([
                DVec3::new(0.0, 90.0, 2.0 * f as f64),
                DVec3::new(0.0, -40.0, 0.0),
                DVec3::new(0.0, -40.0, 0.0),
            ]);
        }
        Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations, local_positions }
    }

    fn layout() -> StitchLayout {
        StitchLayout {
            lower_body: vec![0, 1, 2],
            contacts: [2, 2, 2, 2],
            contact_thresholds: [2.5; 4],
            planted: [0.0; 4],
            forward_axis: DVec3::Z,
        }
    }

    #[test]
    fn a_seam_faster_than_the_reference_is_brought_down_to_it_and_a_calm_one_is_left_alone() {
        let reference = clip(0.0);
        let mut out = clip(0.1);
        let (_, gp) = out.global();
        let report = guard_seams(&mut out, &reference, &[20], &layout());
        assert_eq!(report.len(), 1);
        let g = report[0];
        assert!(g.before > 2.0 * g.reference, "{g:?}");
        assert!(g.weight > 0.0 && g.weight <= 1.0, "{g:?}");
        let (_, after) = out.global();
        let (lo, hi) = zone(20, 40).unwrap();
        let top = top_speed(&after, 3, lo, hi);
        assert!(top <= g.reference * (1.0 + 1e-3), "{top} > {}", g.reference);
        // Far from the seam the output is untouched, and the root's path is the output's.
        assert_eq!(&after[..3], &gp[..3]);
        assert_eq!(&after[3 * 36..], &gp[3 * 36..]);
        for f in 0..40 {
            let (a, b) = (out.positions_at(f)[0], clip(0.1).positions_at(f)[0]);
            assert!((a.x - b.x).abs() < 1e-12 && (a.z - b.z).abs() < 1e-12, "frame {f}");
        }

        let mut calm = clip(0.0);
        let before = calm.clone();
        let report = guard_seams(&mut calm, &clip(0.1), &[20], &layout());
        assert_eq!(report[0].weight, 0.0);
        assert_eq!(calm.local_rotations, before.local_rotations);
    }
}
