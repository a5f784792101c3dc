//! Aligning clips end to start (RMR sec. 3 and 6): each clip is moved rigidly on the ground so
//! that its first ground root lands on the previous clip's last ground root, then the clips are
//! concatenated into one sequence `K`.

use super::StitchError;
use super::layout::StitchLayout;
use zoo_motion::Clip;

/// Shortest clip RMR stitches: the shortest segment of its training data (RMR sec. 6).
pub const MIN_CLIP_FRAMES: usize = 10;

/// The aligned sequence and where each clip starts in it.
#[derive(Clone, Debug)]
pub struct AlignedClips {
    /// The concatenated, aligned clips (the first clip unchanged).
    pub clip: Clip,
    /// First frame of each clip in `clip` (the first is 0; the others are the seams).
    pub starts: Vec<usize>,
}

/// Aligns and concatenates `clips` (joint 0 is the hips). Each clip after the first is moved by
/// the ground transform (translation on the floor and rotation about +Y) that puts its first
/// ground root on the previous clip's last one, as the training pairs' segments are placed.
///
/// Errors (nothing panics): no clips, a clip of another rig or frame rate than the first, a
/// clip shorter than `min_frames` (use [`MIN_CLIP_FRAMES`]).
pub fn align_clips(clips: &[Clip], layout: &StitchLayout, min_frames: usize) -> Result<AlignedClips, StitchError> {
    let first = clips.first().ok_or(StitchError::NoClips { needed: min_frames })?;
    layout.validate(&first.skeleton)?;
    let fps = first.fps();
    for (i, c) in clips.iter().enumerate() {
        if let Some(why) = first.skeleton.topology_difference(&c.skeleton) {
            return Err(StitchError::Skeleton { index: i, name: String::new(), why });
        }
        if !c.plays_at(fps) {
            return Err(StitchError::FrameRate { index: i, name: String::new(), expected: fps, found: c.fps() });
        }
        if c.frames() < min_frames.max(1) {
            return Err(StitchError::Config(format!(
                "clip {i} has {} frames; stitching needs at least {} per clip (the shortest segment it was \
                 trained on): give a longer range",
                c.frames(),
                min_frames.max(1)
            )));
        }
    }
    let j = first.joints();
    let mut out = first.clone();
    let mut starts = vec![0];
    for c in &clips[1..] {
        let last = out.frames() - 1;
        let anchor = layout.root_of(out.local_rotations[last * j], out.local_positions[last * j]);
        let head = layout.root_of(c.local_rotations[0], c.local_positions[0]);
        let mv = anchor.compose(&head.inverse());
        starts.push(out.frames());
        for f in 0..c.frames() {
            let (r, p) = mv.apply(c.local_rotations[f * j], c.local_positions[f * j]);
            out.local_rotations.push(r);
            out.local_positions.push(p);
            out.local_rotations.extend_from_slice(&c.local_rotations[f * j + 1..(f + 1) * j]);
            out.local_positions.extend_from_slice(&c.local_positions[f * j + 1..(f + 1) * j]);
        }
    }
    out.remove_sign_flips();
    Ok(AlignedClips { clip: out, starts })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pairs::ground_roots;
    use zoo_data::synth::{SynthConfig, generate};

    fn clips() -> Vec<Clip> {
        let cfg = SynthConfig { minutes: 0.3, seed: 9, clip_seconds: 6.0, ..SynthConfig::default() };
        generate(&cfg).into_iter().map(|c| c.clip).collect()
    }

    #[test]
    fn each_clip_starts_on_the_previous_last_root() {
        let c = clips();
        let parts = [c[0].slice(0, 40), c[1].slice(50, 75), c[2].slice(10, 60)];
        let layout = StitchLayout::bandai2(&c[0].skeleton).unwrap();
        let a = align_clips(&parts, &layout, MIN_CLIP_FRAMES).unwrap();
        assert_eq!(a.starts, vec![0, 40, 65]);
        assert_eq!(a.clip.frames(), 115);
        let roots = ground_roots(&a.clip, &layout);
        for (k, &s) in a.starts.iter().enumerate().skip(1) {
            let d = roots[s - 1].inverse().compose(&roots[s]);
            assert!(d.pos.length() < 1e-9 && d.yaw.sin().abs() < 1e-9, "seam {s}: {d:?}");
            // Inside a clip the motion relative to its first frame is unchanged.
            let own = ground_roots(&parts[k], &layout);
            let end = a.starts.get(k + 1).copied().unwrap_or(115);
            for f in s..end {
                let got = roots[s].inverse().compose(&roots[f]);
                let want = own[0].inverse().compose(&own[f - s]);
                assert!((got.pos - want.pos).length() < 1e-9 && (got.yaw - want.yaw).sin().abs() < 1e-9);
            }
        }
        // The first clip is untouched; hips height is kept.
        let j = a.clip.joints();
        assert_eq!(a.clip.local_positions[..40 * j], parts[0].local_positions[..]);
        assert!((a.clip.local_positions[41 * j].y - parts[1].local_positions[j].y).abs() < 1e-9);
    }

    #[test]
    fn bad_clips_are_refused_with_a_reason() {
        let c = clips();
        let layout = StitchLayout::bandai2(&c[0].skeleton).unwrap();
        let err = align_clips(&[c[0].clone(), c[1].slice(0, 9)], &layout, MIN_CLIP_FRAMES).unwrap_err().to_string();
        assert!(err.contains("clip 1 has 9 frames") && err.contains("at least 10"), "{err}");
        let mut fast = c[1].clone();
        fast.frame_time = 1.0 / 60.0;
        assert!(align_clips(&[c[0].clone(), fast], &layout, 10).unwrap_err().to_string().contains("60 fps"));
        let mut other = c[1].clone();
        other.skeleton.names[3] = "Neck1".into();
        assert!(align_clips(&[c[0].clone(), other], &layout, 10).unwrap_err().to_string().contains("Neck1"));
        assert!(align_clips(&[], &layout, 10).unwrap_err().to_string().contains("no clips"));
    }
}
