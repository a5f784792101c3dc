//! The seams' reach (not in the paper): a stitch leaves the clips as they are away from their
//! seams.
//!
//! The refiner runs over every window of the joined sequence, and its output is decoded from the
//! sequence's first ground root by summing the refined root displacements: a model that learned
//! little (or meets motion it never saw) moves frames far from any seam, and its root drift
//! grows along the sequence. [`keep_untouched`] makes the rule hold by design: every frame
//! `reach` or more frames from the nearest seam is the input frame exactly; frames within
//! `reach / 2` keep the stitched output; between, the output is eased back to the input
//! (smoothstep weight; hips position interpolated, every rotation slerped). Each stretch of
//! frames near seams that starts after the sequence's first frame is first moved rigidly on the
//! ground (a turn about +Y and a shift) so that its first frame's ground root is the input's
//! there: the drift the output gathered before the stretch does not reach it.

use super::StitchLayout;
use glam::{DQuat, DVec3};
use zoo_motion::Clip;
use zoo_motion::fk::forward_kinematics_frame;

/// The reach of a refiner of `window` frames when none is given (`zoo stitch`'s default):
/// the window.
pub fn default_reach(window: usize) -> usize {
    window.max(1)
}

/// Frames from frame `f` to the nearest seam: a seam `s` (the first frame of a clip) is 0 frames
/// from `s - 1` and from `s`. `None` without seams.
pub fn seam_distance(f: usize, seams: &[usize]) -> Option<usize> {
    seams.iter().map(|&s| if f >= s { f - s } else { s - 1 - f }).min()
}

/// The weight of the stitched output at frame `f` (1: the output, 0: the input): 1 within
/// `reach / 2` frames of a seam, 0 from `reach` frames on, a smoothstep between. Without seams
/// or with `reach` 0 it is 1 (nothing kept). It reads the seams within `reach` frames of `f`.
pub fn weight(f: usize, seams: &[usize], reach: usize) -> f64 {
    let inner = reach / 2;
    match seam_distance(f, seams) {
        None => 1.0,
        _ if reach == 0 => 1.0,
        Some(d) if d <= inner => 1.0,
        Some(d) if d >= reach => 0.0,
        Some(d) => {
            let x = (reach - d) as f64 / (reach - inner) as f64;
            x * x * (3.0 - 2.0 * x)
        }
    }
}

/// [`weight`] of each of `frames` frames.
pub fn weights(frames: usize, seams: &[usize], reach: usize) -> Vec<f64> {
    (0..frames).map(|f| weight(f, seams, reach)).collect()
}

/// [`keep_untouched`] one frame at a time, in order (the runtime's stitching stream keeps the
/// frames it releases this way): the move of the stretch near seams the last frame was in.
#[derive(Clone, Copy, Debug, Default)]
pub struct KeepUntouched {
    /// The ground move of the current stretch (`None`: the stretch that starts the sequence,
    /// or no stretch).
    to_input: Option<super::GroundRoot>,
    /// Whether the frame before was in a stretch near seams.
    in_stretch: bool,
}

impl KeepUntouched {
    /// Keeps frame `f` (its weight `w` of [`weight`]; frames given in order from 0): the
    /// output frame's rotations (joint 0 the hips') and hips position become the input's where
    /// `w` is 0, are moved with their stretch and eased towards the input where it is below 1.
    /// Returns whether the frame was set to the input.
    pub fn frame(
        &mut self,
        (f, w): (usize, f64),
        (rotations, hips): (&mut [DQuat], &mut DVec3),
        (input_rotations, input_hips): (&[DQuat], DVec3),
        layout: &StitchLayout,
    ) -> bool {
        if w == 0.0 {
            rotations.copy_from_slice(input_rotations);
            *hips = input_hips;
            self.in_stretch = false;
            self.to_input = None;
            return true;
        }
        if !self.in_stretch {
            // A stretch near seams starts: after frame 0, on the input's ground root.
            self.in_stretch = true;
            self.to_input = (f > 0).then(|| {
                let (ri, ro) = (layout.root_of(input_rotations[0], input_hips), layout.root_of(rotations[0], *hips));
                ri.compose(&ro.inverse())
            });
        }
        if let Some(m) = self.to_input {
            (rotations[0], *hips) = m.apply(rotations[0], *hips);
        }
        if w < 1.0 {
            *hips = input_hips.lerp(*hips, w);
            for (qo, &qi) in rotations.iter_mut().zip(input_rotations) {
                let o = if qi.dot(*qo) < 0.0 { -*qo } else { *qo };
                *qo = qi.slerp(o, w).normalize();
            }
        }
        false
    }
}

/// Keeps `input`'s frames beyond `reach` frames of every seam in `output` (same skeleton and
/// frame count; joint 0 the hips' world transform), eases the output back to the input between
/// `reach / 2` and `reach`, and moves each stretch near seams that starts after frame 0 so that
/// it starts on the input's ground root (module docs). Returns the number of frames set to the
/// input. Nothing changes without seams or with `reach` 0.
pub fn keep_untouched(output: &mut Clip, input: &Clip, seams: &[usize], reach: usize, layout: &StitchLayout) -> usize {
    let (frames, j) = (output.frames(), output.joints());
    assert_eq!(frames, input.frames(), "the output and the input must have the same frames");
    assert_eq!(j, input.joints(), "the output and the input must have the same joints");
    let mut keep = KeepUntouched::default();
    let mut kept = 0;
    for f in 0..frames {
        let mut hips = output.local_positions[f * j];
        let rotations = &mut output.local_rotations[f * j..(f + 1) * j];
        let inputs = (&input.local_rotations[f * j..(f + 1) * j], input.local_positions[f * j]);
        kept += usize::from(keep.frame((f, weight(f, seams, reach)), (rotations, &mut hips), inputs, layout));
        output.local_positions[f * j] = hips;
    }
    kept
}

/// The largest distance (clip units) between a joint of `a` and the same joint of `b` (global
/// positions by forward kinematics) over the frames at least `reach` frames from every seam:
/// how far a stitch moved the parts of the clips it should leave alone. 0 when there is no such
/// frame.
pub fn largest_move_beyond(a: &Clip, b: &Clip, seams: &[usize], reach: usize) -> f64 {
    let j = a.joints();
    let (mut ga, mut gb) = (vec![DVec3::ZERO; j], vec![DVec3::ZERO; j]);
    let mut rot = vec![glam::DQuat::IDENTITY; j];
    let mut m: f64 = 0.0;
    for f in 0..a.frames().min(b.frames()) {
        if seam_distance(f, seams).is_some_and(|d| d < reach) {
            continue;
        }
        forward_kinematics_frame(&a.skeleton.parents, a.rotations_at(f), a.positions_at(f), &mut rot, &mut ga);
        forward_kinematics_frame(&b.skeleton.parents, b.rotations_at(f), b.positions_at(f), &mut rot, &mut gb);
        for (x, y) in ga.iter().zip(&gb) {
            m = m.max((*x - *y).length());
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_keep_the_output_near_seams_and_the_input_beyond_reach() {
        let w = weights(100, &[40], 20);
        assert_eq!(w[40], 1.0);
        assert_eq!(w[39], 1.0);
        assert_eq!(w[50], 1.0);
        assert_eq!(w[29], 1.0);
        assert!(w[55] > 0.0 && w[55] < 1.0);
        assert_eq!(w[60], 0.0);
        assert_eq!(w[19], 0.0);
        assert!(w.iter().all(|&x| (0.0..=1.0).contains(&x)));
        assert!(weights(10, &[], 20).iter().all(|&x| x == 1.0));
        assert!(weights(10, &[5], 0).iter().all(|&x| x == 1.0));
    }

    /// A three-joint leg walking along +Z, its middle joint swinging.
    fn walk(frames: usize) -> Clip {
        let skeleton = zoo_motion::Skeleton {
            names: vec!["Hips".into(), "Leg".into(), "Foot".into()],
            parents: vec![None, Some(0), Some(1)],
            offsets: vec![DVec3::ZERO, DVec3::new(0.0, -40.0, 0.0), DVec3::new(0.0, -40.0, 0.0)],
            end_sites: vec![None; 3],
            channels: vec![zoo_motion::JointChannels::default(); 3],
        };
        let (mut local_rotations, mut local_positions) = (Vec::new(), Vec::new());
        for f in 0..frames {
            let swing = 0.3 * (f as f64 * 0.2).sin();
            local_rotations.extend([DQuat::IDENTITY, DQuat::from_rotation_x(swing), DQuat::IDENTITY]);
            local_positions.extend([
                DVec3::new(0.0, 90.0, 2.0 * f as f64),
                DVec3::new(0.0, -40.0, 0.0),
                DVec3::new(0.0, -40.0, 0.0),
            ]);
        }
        Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations, local_positions }
    }

    #[test]
    fn frames_beyond_reach_are_the_input_and_a_late_stretch_starts_on_it() {
        let clip = walk(120);
        let layout = StitchLayout {
            lower_body: vec![0, 1, 2],
            contacts: [2, 2, 2, 2],
            contact_thresholds: [2.5; 4],
            planted: [0.0; 4],
            forward_axis: DVec3::Z,
        };
        let mut out = clip.clone();
        // A drift that grows along the sequence, a turn, and a bent knee everywhere.
        let j = out.joints();
        for f in 0..out.frames() {
            out.local_positions[f * j] += DVec3::new(0.5 * f as f64, 0.0, 0.0);
            out.local_rotations[f * j] = DQuat::from_rotation_y(0.01 * f as f64) * out.local_rotations[f * j];
            out.local_rotations[f * j + 1] = DQuat::from_rotation_x(0.5) * out.local_rotations[f * j + 1];
        }
        let seams = [80];
        let kept = keep_untouched(&mut out, &clip, &seams, 30, &layout);
        assert_eq!(kept, 50 + 10, "frames 0-49 and 110-119");
        assert_eq!(largest_move_beyond(&out, &clip, &seams, 30), 0.0);
        // The stretch near the seam starts at frame 50, on the input's ground root: the drift
        // of 25 units gathered before it is gone.
        let start = 50;
        let d = (out.local_positions[start * j] - clip.local_positions[start * j]).length();
        assert!(d < 1e-6, "stretch start moved by {d}");
        assert!(largest_move_beyond(&out, &clip, &seams, 0) > 1.0, "the knee stays bent near the seam");
    }
}
