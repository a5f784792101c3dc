//! Stitching baselines on an aligned sequence ([`super::align_clips`]): inertialization at each
//! seam and interpolation across each seam. Plain aligned concatenation is the aligned sequence
//! itself.

use zoo_motion::Clip;
use zoo_motion::quat::slerp;

pub use zoo_motion::blend::inertialize_seams;

/// Interpolation across each seam: the `2h` frames `s - h .. s + h` around seam `s`
/// (`h = max(blend_frames / 2, 1)`) are replaced by a linear blend from the frame before them
/// to the frame after them (root joint position LERP, local rotations SLERP; weights
/// `k / (2h + 1)`), the in-betweening benchmark's interpolation baseline placed on the seam.
/// The span is shortened where the sequence ends.
pub fn interpolate_seams(aligned: &Clip, seams: &[usize], blend_frames: usize) -> Clip {
    let mut out = aligned.clone();
    let (frames, j) = (out.frames(), out.joints());
    let h = (blend_frames / 2).max(1);
    for &s in seams {
        let a = s.saturating_sub(h + 1);
        let b = (s + h).min(frames - 1);
        if b <= a + 1 {
            continue;
        }
        let n = b - a;
        let (ra, pa) = (out.local_rotations[a * j..(a + 1) * j].to_vec(), out.local_positions[a * j]);
        let (rb, pb) = (out.local_rotations[b * j..(b + 1) * j].to_vec(), out.local_positions[b * j]);
        for f in a + 1..b {
            let w = (f - a) as f64 / n as f64;
            out.local_positions[f * j] = pa.lerp(pb, w);
            for k in 0..j {
                out.local_rotations[f * j + k] = slerp(ra[k], rb[k], w);
            }
        }
    }
    out.remove_sign_flips();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pairs::{MIN_CLIP_FRAMES, StitchLayout, align_clips};
    use zoo_data::synth::{SynthConfig, generate};

    fn aligned() -> (Clip, Vec<usize>) {
        let cfg = SynthConfig { minutes: 0.2, seed: 5, clip_seconds: 4.0, ..SynthConfig::default() };
        let c: Vec<Clip> = generate(&cfg).into_iter().map(|c| c.clip).collect();
        let layout = StitchLayout::bandai2(&c[0].skeleton).unwrap();
        let a = align_clips(&[c[0].slice(0, 40), c[1].slice(17, 60)], &layout, MIN_CLIP_FRAMES).unwrap();
        (a.clip, a.starts[1..].to_vec())
    }

    fn jump(c: &Clip, s: usize) -> f64 {
        let (_, gp) = c.global();
        let j = c.joints();
        (0..j).map(|k| (gp[s * j + k] - gp[(s - 1) * j + k]).length()).fold(0.0, f64::max)
    }

    #[test]
    fn baselines_smooth_the_seam_and_keep_the_rest() {
        let (clip, seams) = aligned();
        let s = seams[0];
        let j = clip.joints();
        let raw = jump(&clip, s);
        let inert = inertialize_seams(&clip, &seams, 10);
        let interp = interpolate_seams(&clip, &seams, 10);
        assert!(jump(&inert, s) < 0.5 * raw, "inertialized jump {} vs raw {raw}", jump(&inert, s));
        assert!(jump(&interp, s) < 0.5 * raw, "interpolated jump {} vs raw {raw}", jump(&interp, s));
        // Before the seam inertialization changes nothing; after the blend neither does.
        assert_eq!(inert.local_rotations[..s * j], clip.local_rotations[..s * j]);
        assert_eq!(inert.local_positions[(s + 10) * j..], clip.local_positions[(s + 10) * j..]);
        assert_eq!(interp.local_positions[..(s - 6) * j], clip.local_positions[..(s - 6) * j]);
        assert_eq!(interp.local_positions[(s + 5) * j..], clip.local_positions[(s + 5) * j..]);
        assert_eq!(inert.frames(), clip.frames());
    }

    /// The definition, seam after seam over the whole clip, that the frame-by-frame form must
    /// reproduce.
    fn seam_by_seam(aligned: &Clip, seams: &[usize], blend_frames: usize) -> Clip {
        use zoo_motion::blend::Inertializer;
        let mut out = aligned.clone();
        let (frames, j) = (out.frames(), out.joints());
        let dt = out.frame_time;
        for &s in seams {
            if s < 2 || s + 2 > frames || blend_frames == 0 {
                continue;
            }
            let frame = |c: &Clip, f: usize| (c.local_rotations[f * j..(f + 1) * j].to_vec(), c.local_positions[f * j]);
            let (rp, pp) = frame(&out, s - 2);
            let (rl, pl) = frame(&out, s - 1);
            let (rf, pf) = frame(&out, s);
            let (rn, pn) = frame(&out, s + 1);
            let inert = Inertializer::new((&rp, pp), (&rl, pl), (&rf, pf), (&rn, pn), dt, blend_frames as f64 * dt);
            for k in 0..blend_frames.min(frames - s) {
                let f = s + k;
                let mut root = out.local_positions[f * j];
                inert.apply((k + 1) as f64 * dt, &mut out.local_rotations[f * j..(f + 1) * j], &mut root);
                out.local_positions[f * j] = root;
            }
        }
        out.remove_sign_flips();
        out
    }

    /// Adjacent seams, seams within each other's blend, seams near both ends, one blend frame
    /// or none: frame by frame gives the seam-by-seam frames exactly.
    #[test]
    fn frame_by_frame_inertialization_is_the_seam_by_seam_definition() {
        let (clip, _) = aligned();
        let n = clip.frames();
        let cases: [&[usize]; 6] =
            [&[30], &[30, 31], &[12, 16, 20, 50], &[0, 1, 2, n - 2, n - 1], &[2, 3, 4, 5, 6, 7], &[]];
        for seams in cases {
            for blend in [0, 1, 2, 10] {
                let a = inertialize_seams(&clip, seams, blend);
                let b = seam_by_seam(&clip, seams, blend);
                assert_eq!(a.local_rotations, b.local_rotations, "seams {seams:?}, blend {blend}");
                assert_eq!(a.local_positions, b.local_positions, "seams {seams:?}, blend {blend}");
            }
        }
    }
}
