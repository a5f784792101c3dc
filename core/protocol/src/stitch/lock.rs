//! Foot lock by the predicted contacts (RMR sec. 6: "we lock the foot joints in contact with
//! the ground using inverse kinematics"): the refiner outputs four contacts per frame (heel and
//! toe, left and right); each run of frames with a contact pins that joint horizontally at its
//! mean position over the run, and the leg reaches the pinned foot by two-bone IK
//! ([`crate::footlock::two_bone_ik`]).
//!
//! Per leg and frame, the horizontal correction of the ankle is the one that puts the heel
//! (the ankle joint) on its pin when the heel is in contact, else the toe on its pin when the
//! toe is; between contacts it is interpolated linearly, and held before the first and after the
//! last contact. The hip and knee rotate to reach the corrected ankle (bone lengths are kept,
//! the knee stays in its bend plane) and the foot keeps its global orientation. Heights are not
//! changed.
//!
//! The correction may change by at most [`LOCK_MAX_STEP`] per frame (clip units; applied
//! forwards and backwards and averaged, so it leads a pin as much as it lags it): without the
//! limit, the switch from one pin to the next and from the heel's pin to the toe's moved the
//! ankle by several centimetres in one frame, which the stitching benchmark counts as pops at the
//! seams (measured 2026-11-25, commit 91c7c30: docs/rmr-benchmarks.md, "The foot lock's pops").
//!
//! Each frame's correction reads the frames within [`LOCK_REACH`] of it and no others: it is
//! the correction of the frame in the lock of those frames alone (contact runs, gaps and the
//! rate limit cut at their edges). A rate limit that stays clamped would otherwise carry a
//! correction along the whole sequence, and a stream (the runtime's stitching stream, which
//! locks the frames it releases with this many frames on each side) could not give the whole
//! sequence's lock with any bounded latency. Contact runs and gaps up to about
//! [`LOCK_REACH`] frames long (bandai2's steps: 10 to 25 frames) are locked as by a lock of the
//! whole sequence.
//!
//! In the core layer (`zoo_protocol`) so that the engine's runtime
//! (`zoo_runtime::StitchRefiner`) applies the same lock as the offline `zoo stitch`.

use super::StitchLayout;
use glam::{DQuat, DVec3};
use zoo_motion::Clip;

/// The largest change of a foot's horizontal correction from one frame to the next (clip
/// units per frame: 1 cm at bandai2's scale). Chosen on the bandai2 validation stitching cases
/// among 0.5, 1 and 2 and a moving average of radius 2 or 4 (docs/rmr-benchmarks.md, "The
/// foot lock's pops").
pub const LOCK_MAX_STEP: f64 = 1.0;

/// Frames on each side of a frame that its lock correction reads (module docs).
pub const LOCK_REACH: usize = 45;

/// `corrections` with no step between neighbouring frames longer than `max_step`: the
/// forward-limited and the backward-limited sequences, averaged. `max_step <= 0` or not finite
/// leaves them unchanged.
#[cfg(test)]
fn limit_rate(corrections: &mut [DVec3], max_step: f64) {
    limit_rate_into(corrections, max_step, &mut Vec::new());
}

/// `corrections` rate-limited as `limit_rate` says, with `forward` as scratch.
fn limit_rate_into(corrections: &mut [DVec3], max_step: f64, forward: &mut Vec<DVec3>) {
    if !(max_step > 0.0 && max_step.is_finite()) || corrections.len() < 2 {
        return;
    }
    let clamp = |from: DVec3, to: DVec3| {
        let d = to - from;
        if d.length() > max_step { from + d.normalize() * max_step } else { to }
    };
    forward.clear();
    forward.extend_from_slice(corrections);
    for f in 1..forward.len() {
        forward[f] = clamp(forward[f - 1], forward[f]);
    }
    let n = corrections.len();
    for f in (0..n - 1).rev() {
        corrections[f] = clamp(corrections[f + 1], corrections[f]);
    }
    for (c, fw) in corrections.iter_mut().zip(forward.iter()) {
        *c = (*c + *fw) * 0.5;
    }
}

/// One leg of the lock: hip, knee, ankle joints and the contact indices of its heel and toe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct LockLeg {
    hip: usize,
    knee: usize,
    ankle: usize,
    toe: usize,
    heel_contact: usize,
    toe_contact: usize,
}

fn legs(clip: &Clip, layout: &StitchLayout) -> impl Iterator<Item = LockLeg> + use<> {
    let parents = &clip.skeleton.parents;
    let leg = |h: usize, t: usize| {
        let ankle = layout.contacts[h];
        let knee = parents.get(ankle).copied().flatten()?;
        let hip = parents.get(knee).copied().flatten()?;
        parents.get(hip).copied().flatten()?;
        Some(LockLeg { hip, knee, ankle, toe: layout.contacts[t], heel_contact: h, toe_contact: t })
    };
    [leg(0, 1), leg(2, 3)].into_iter().flatten()
}

/// Whether bending `bent` moves a joint `leg` reads (its hip's parent, hip, knee, ankle, toe):
/// one of them lies below `bent`'s hip, knee or ankle.
fn moves(parents: &[Option<usize>], leg: &LockLeg, bent: &LockLeg) -> bool {
    [leg.hip, leg.knee, leg.ankle, leg.toe].into_iter().any(|joint| {
        let mut at = Some(joint);
        while let Some(k) = at {
            if k == bent.hip || k == bent.knee || k == bent.ankle {
                return true;
            }
            at = parents[k];
        }
        false
    })
}

/// Horizontal corrections `(x, z)` per frame from the corrections known on contact frames
/// (`None` elsewhere): linear in between, held at both ends, zero without any contact.
#[cfg(test)]
fn fill_gaps(known: &[Option<DVec3>]) -> Vec<DVec3> {
    let mut out = Vec::new();
    fill_gaps_into(known, &mut out);
    out
}

/// The corrections of `fill_gaps` into `out` (resized to `known.len()`).
fn fill_gaps_into(known: &[Option<DVec3>], out: &mut Vec<DVec3>) {
    out.clear();
    out.resize(known.len(), DVec3::ZERO);
    let (Some(first), Some(last)) = (known.iter().position(Option::is_some), known.iter().rposition(Option::is_some))
    else {
        return;
    };
    let (mut prev, mut next) = (first, first);
    for (f, o) in out.iter_mut().enumerate() {
        *o = if f <= first {
            known[first].unwrap_or_default()
        } else if f >= last {
            known[last].unwrap_or_default()
        } else if let Some(k) = known[f] {
            prev = f;
            k
        } else {
            if next <= f {
                next = f + known[f..].iter().position(Option::is_some).unwrap_or(0);
            }
            let a = (f - prev) as f64 / (next - prev) as f64;
            known[prev].unwrap_or_default().lerp(known[next].unwrap_or_default(), a)
        };
    }
}

/// Runs of `true` in `flags`: `(first, end)` half-open.
#[cfg(test)]
fn runs(flags: impl Iterator<Item = bool>) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for_runs(flags, |s, e| out.push((s, e)));
    out
}

/// Calls `run(first, end)` (half-open) for each run of `true` in `flags`, in order.
fn for_runs(flags: impl Iterator<Item = bool>, mut run: impl FnMut(usize, usize)) {
    let mut start = None;
    let mut n = 0;
    for (f, on) in flags.enumerate() {
        match (on, start) {
            (true, None) => start = Some(f),
            (false, Some(s)) => {
                run(s, f);
                start = None;
            }
            _ => {}
        }
        n = f + 1;
    }
    if let Some(s) = start {
        run(s, n);
    }
}

/// Scratch space of [`place_ankles_into`] and [`lock_feet_into`], reused from call to call so
/// that a caller running them every few frames (the runtime's stitching stream) allocates
/// nothing once it has grown to the longest clip.
#[derive(Clone, Debug, Default)]
pub struct LockScratch {
    gr: Vec<DQuat>,
    gp: Vec<DVec3>,
    known: Vec<Option<DVec3>>,
    toe_known: Vec<Option<DVec3>>,
    corrections: Vec<DVec3>,
    forward: Vec<DVec3>,
}

impl LockScratch {
    /// The global rotations and positions [`lock_feet_given_globals`] reads, to be filled
    /// with those of the clip it is given (cleared first).
    pub fn globals_mut(&mut self) -> (&mut Vec<DQuat>, &mut Vec<DVec3>) {
        self.gr.clear();
        self.gp.clear();
        (&mut self.gr, &mut self.gp)
    }

    /// Room for clips of up to `frames` frames of `joints` joints.
    pub fn reserve(&mut self, frames: usize, joints: usize) {
        let n = frames * joints;
        self.gr.reserve(n.saturating_sub(self.gr.len()));
        self.gp.reserve(n.saturating_sub(self.gp.len()));
        for v in [&mut self.known, &mut self.toe_known] {
            v.reserve(frames.saturating_sub(v.len()));
        }
        for v in [&mut self.corrections, &mut self.forward] {
            v.reserve(frames.saturating_sub(v.len()));
        }
    }
}

/// Global rotations and positions of every frame of `clip` into `gr`, `gp`.
fn global_into(clip: &Clip, gr: &mut Vec<DQuat>, gp: &mut Vec<DVec3>) {
    let n = clip.local_rotations.len();
    gr.clear();
    gr.resize(n, DQuat::IDENTITY);
    gp.clear();
    gp.resize(n, DVec3::ZERO);
    zoo_motion::fk::forward_kinematics(&clip.skeleton.parents, &clip.local_rotations, &clip.local_positions, gr, gp);
}

fn horizontal(v: DVec3) -> DVec3 {
    DVec3::new(v.x, 0.0, v.z)
}

/// Bends `leg` at frame `f` so that its ankle reaches `goal` by two-bone IK: the hip and knee
/// rotate (bone lengths kept, the knee in its bend plane), the foot keeps its global orientation.
/// Updates the local rotations of `clip` and the global rotations `gr`; `gp` are the global
/// positions before. Returns how far the ankle moved.
fn bend_leg(clip: &mut Clip, gr: &mut [DQuat], gp: &[DVec3], leg: LockLeg, f: usize, goal: DVec3) -> f64 {
    let j = clip.joints();
    let at = |k: usize| gp[f * j + k].as_vec3();
    let (hip, knee, ankle) = (at(leg.hip), at(leg.knee), at(leg.ankle));
    let (new_knee, new_ankle) = crate::footlock::two_bone_ik(hip, knee, ankle, goal.as_vec3());
    let (hip, knee, ankle, new_knee, new_ankle) =
        (hip.as_dvec3(), knee.as_dvec3(), ankle.as_dvec3(), new_knee.as_dvec3(), new_ankle.as_dvec3());
    let arc = |a: DVec3, b: DVec3| {
        if a.length_squared() < 1e-12 || b.length_squared() < 1e-12 {
            DQuat::IDENTITY
        } else {
            DQuat::from_rotation_arc(a.normalize(), b.normalize())
        }
    };
    let r1 = arc(knee - hip, new_knee - hip);
    let r2 = arc(r1 * (ankle - knee), new_ankle - new_knee);
    let parent = clip.skeleton.parents[leg.hip].expect("legs() checked the hip's parent");
    let g_parent = gr[f * j + parent];
    let g_hip = (r1 * gr[f * j + leg.hip]).normalize();
    let g_knee = (r2 * r1 * gr[f * j + leg.knee]).normalize();
    let g_ankle = gr[f * j + leg.ankle];
    clip.local_rotations[f * j + leg.hip] = (g_parent.inverse() * g_hip).normalize();
    clip.local_rotations[f * j + leg.knee] = (g_hip.inverse() * g_knee).normalize();
    clip.local_rotations[f * j + leg.ankle] = (g_knee.inverse() * g_ankle).normalize();
    gr[f * j + leg.hip] = g_hip;
    gr[f * j + leg.knee] = g_knee;
    (new_ankle - ankle).length()
}

/// Places the ankles (`layout.contacts[0]` and `[2]`, the heel joints) of every frame at
/// `goals[f] = [left, right]` (global positions, e.g. the refiner's predicted lower-body
/// positions) by two-bone IK: RMR sec. 5, "because the forward kinematics accumulates the error
/// to the joints at ends, we further process the pose by locking both feet in the output
/// positions using inverse kinematics". Returns the mean ankle displacement (clip units); a
/// clip without legs to bend or with another number of goals than frames is left unchanged.
pub fn place_ankles(clip: &mut Clip, goals: &[[DVec3; 2]], layout: &StitchLayout) -> f64 {
    place_ankles_into(clip, goals, layout, &mut LockScratch::default())
}

/// [`place_ankles`] with its scratch space in `scratch`.
pub fn place_ankles_into(
    clip: &mut Clip,
    goals: &[[DVec3; 2]],
    layout: &StitchLayout,
    scratch: &mut LockScratch,
) -> f64 {
    place_ankles_range_into(clip, goals, layout, scratch, 0..clip.frames())
}

/// [`place_ankles_into`] on the frames `bend` only (each frame's IK reads that frame alone, so
/// they are the frames the whole clip's call gives): for a caller that keeps the frames
/// already placed (the runtime's stitching stream).
pub fn place_ankles_range_into(
    clip: &mut Clip,
    goals: &[[DVec3; 2]],
    layout: &StitchLayout,
    scratch: &mut LockScratch,
    bend: std::ops::Range<usize>,
) -> f64 {
    let frames = clip.frames();
    if goals.len() != frames || frames == 0 {
        return 0.0;
    }
    let bend = bend.start.min(frames)..bend.end.min(frames);
    let (mut total, mut count) = (0.0, 0usize);
    let (gr, gp) = (&mut scratch.gr, &mut scratch.gp);
    global_into(clip, gr, gp);
    let mut prev: Option<LockLeg> = None;
    for leg in legs(clip, layout) {
        let side = leg.heel_contact / 2;
        if prev.is_some_and(|p| moves(&clip.skeleton.parents, &leg, &p)) {
            global_into(clip, gr, gp);
        }
        prev = Some(leg);
        for f in bend.clone() {
            total += bend_leg(clip, gr, gp, leg, f, goals[f][side]);
            count += 1;
        }
    }
    clip.remove_sign_flips();
    if count == 0 { 0.0 } else { total / count as f64 }
}

/// The vectors [`correction_at`] works in: the heel's and the toe's known corrections, the
/// filled corrections and the rate limit's forward pass.
type Scratch<'a> = (&'a mut Vec<Option<DVec3>>, &'a mut Vec<Option<DVec3>>, &'a mut Vec<DVec3>, &'a mut Vec<DVec3>);

/// The horizontal ankle correction of `leg` at frame `f` in the lock of the frames `window`
/// alone (global positions `gp` of `j` joints per frame): pins at each contact run's mean
/// position within the window, the heel's before the toe's, gaps filled linearly and held at
/// the window's edges, the change per frame limited to `max_step`. The vectors are scratch.
#[allow(clippy::too_many_arguments)]
fn correction_at(
    gp: &[DVec3],
    j: usize,
    contacts: &[[bool; 4]],
    leg: LockLeg,
    window: std::ops::Range<usize>,
    f: usize,
    max_step: f64,
    (known, toe_known, corrections, forward): Scratch<'_>,
) -> DVec3 {
    let (w0, n) = (window.start, window.len());
    for target in [&mut *known, &mut *toe_known] {
        target.clear();
        target.resize(n, None);
    }
    for (joint, contact, target) in
        [(leg.ankle, leg.heel_contact, &mut *known), (leg.toe, leg.toe_contact, &mut *toe_known)]
    {
        let at = |i: usize| horizontal(gp[(w0 + i) * j + joint]);
        for_runs(contacts[window.clone()].iter().map(|c| c[contact]), |s, e| {
            let pin = (s..e).map(at).sum::<DVec3>() / (e - s) as f64;
            for i in s..e {
                target[i] = Some(pin - at(i));
            }
        });
    }
    for (k, t) in known.iter_mut().zip(toe_known.iter()) {
        if k.is_none() {
            *k = *t;
        }
    }
    fill_gaps_into(known, corrections);
    limit_rate_into(corrections, max_step, forward);
    corrections[f - w0]
}

/// Locks the feet of `clip` where `contacts` (per frame: heel L, toe L, heel R, toe R) say they
/// are planted; `layout.contacts` names the heel and toe joints. Returns the mean horizontal
/// ankle correction applied (clip units). A clip whose contact joints have no grandparent
/// (no leg to bend) or whose contact count differs from its frames is left unchanged. The
/// correction changes by at most [`LOCK_MAX_STEP`] per frame.
pub fn lock_feet(clip: &mut Clip, contacts: &[[bool; 4]], layout: &StitchLayout) -> f64 {
    lock_feet_with(clip, contacts, layout, LOCK_MAX_STEP)
}

/// [`lock_feet`] with another limit on the correction's change per frame (`f64::INFINITY`:
/// none, the lock before commit f0394c3 of 2026-11-25).
pub fn lock_feet_with(clip: &mut Clip, contacts: &[[bool; 4]], layout: &StitchLayout, max_step: f64) -> f64 {
    lock_feet_into(clip, contacts, layout, max_step, &mut LockScratch::default())
}

/// [`lock_feet_with`] with its scratch space in `scratch`.
pub fn lock_feet_into(
    clip: &mut Clip,
    contacts: &[[bool; 4]],
    layout: &StitchLayout,
    max_step: f64,
    scratch: &mut LockScratch,
) -> f64 {
    lock_feet_range_into(clip, contacts, layout, max_step, scratch, 0..clip.frames())
}

/// [`lock_feet_into`] that bends the legs of the frames `bend` only: each frame's correction
/// reads the frames within [`LOCK_REACH`] of it, so those frames are the whole clip's lock
/// wherever the clip holds [`LOCK_REACH`] frames on each side of them (or starts or ends
/// there): a caller that keeps only them (the runtime's stitching stream keeps the frames it
/// releases) gets the whole sequence's lock.
pub fn lock_feet_range_into(
    clip: &mut Clip,
    contacts: &[[bool; 4]],
    layout: &StitchLayout,
    max_step: f64,
    scratch: &mut LockScratch,
    bend: std::ops::Range<usize>,
) -> f64 {
    if contacts.len() != clip.frames() || clip.frames() == 0 {
        return 0.0;
    }
    global_into(clip, &mut scratch.gr, &mut scratch.gp);
    lock_feet_given_globals(clip, contacts, layout, max_step, scratch, bend)
}

/// [`lock_feet_range_into`] with the global rotations and positions of `clip`'s frames already
/// in `scratch` ([`LockScratch::globals_mut`]): for a caller that keeps them from call to call
/// (the runtime's stitching stream computes each frame's once).
pub fn lock_feet_given_globals(
    clip: &mut Clip,
    contacts: &[[bool; 4]],
    layout: &StitchLayout,
    max_step: f64,
    scratch: &mut LockScratch,
    bend: std::ops::Range<usize>,
) -> f64 {
    let (frames, j) = (clip.frames(), clip.joints());
    if contacts.len() != frames || frames == 0 {
        return 0.0;
    }
    let LockScratch { gr, gp, known, toe_known, corrections, forward } = scratch;
    assert_eq!(gp.len(), frames * j, "the scratch holds the clip's global positions");
    let bend = bend.start.min(frames)..bend.end.min(frames);
    let mut total = 0.0;
    let mut count = 0usize;
    let mut prev: Option<LockLeg> = None;
    for leg in legs(clip, layout) {
        // Positions of the changed leg for this leg's reads, when they depend on it (the legs
        // of a humanoid do not share joints: nothing to update).
        if prev.is_some_and(|p| moves(&clip.skeleton.parents, &leg, &p)) {
            global_into(clip, gr, gp);
        }
        prev = Some(leg);
        for f in bend.clone() {
            let window = f.saturating_sub(LOCK_REACH)..(f + LOCK_REACH + 1).min(frames);
            let parts = (&mut *known, &mut *toe_known, &mut *corrections, &mut *forward);
            let c = correction_at(gp, j, contacts, leg, window, f, max_step, parts);
            if c.length_squared() < 1e-12 {
                continue;
            }
            let goal = gp[f * j + leg.ankle] + DVec3::new(c.x, 0.0, c.z);
            total += bend_leg(clip, gr, gp, leg, f, goal);
            count += 1;
        }
    }
    clip.remove_sign_flips();
    if count == 0 { 0.0 } else { total / count as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_are_filled_linearly_and_held_at_the_ends() {
        let x = |v: f64| Some(DVec3::new(v, 0.0, 0.0));
        let got = fill_gaps(&[None, x(1.0), None, None, x(4.0), None]);
        let xs: Vec<f64> = got.iter().map(|v| v.x).collect();
        assert_eq!(xs, vec![1.0, 1.0, 2.0, 3.0, 4.0, 4.0]);
        assert!(fill_gaps(&[None, None]).iter().all(|v| *v == DVec3::ZERO));
        let got = fill_gaps(&[x(1.0), None, x(3.0), None, None, x(6.0), x(7.0), None, x(9.0)]);
        let xs: Vec<f64> = got.iter().map(|v| v.x).collect();
        assert_eq!(xs, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
        assert_eq!(runs([true, true, false, true].into_iter()), vec![(0, 2), (3, 4)]);
        assert_eq!(runs([false, true, true].into_iter()), vec![(1, 3)]);
    }

    #[test]
    fn the_correction_rate_is_limited_symmetrically() {
        let x = |v: f64| DVec3::new(v, 0.0, 0.0);
        // A jump of 4 between frames 2 and 3, limited to 1 per frame.
        let mut c = vec![x(0.0), x(0.0), x(0.0), x(4.0), x(4.0), x(4.0)];
        limit_rate(&mut c, 1.0);
        let xs: Vec<f64> = c.iter().map(|v| v.x).collect();
        assert_eq!(xs, vec![0.5, 1.0, 1.5, 2.5, 3.0, 3.5]);
        // The average of two 1-limited sequences moves by at most 1 per frame.
        assert!(c.windows(2).all(|w| (w[1] - w[0]).length() <= 1.0 + 1e-12));
        // No limit: unchanged.
        let mut d = vec![x(0.0), x(4.0)];
        limit_rate(&mut d, f64::INFINITY);
        assert_eq!(d, vec![x(0.0), x(4.0)]);
    }
}
