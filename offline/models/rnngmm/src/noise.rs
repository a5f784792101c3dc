//! The motion-denoising benchmark's noise and its Savitzky-Golay baseline (issue 15; protocol in
//! `docs/rnn-gmm-control.md`).
//!
//! - [`corrupt`]: seeded noise on a clean clip: every joint's local rotation (the root's too)
//!   turned by a rotation vector with Gaussian components of `angle_deg`; the root position
//!   moved by Gaussian components of `root` (clip units); a fraction of frames replaced by
//!   outlier poses whose rotations are turned by Gaussian components of `outlier_deg`.
//! - [`savgol`]: the classic filter: each root coordinate and each joint's local quaternion
//!   (its sign made continuous) filtered with a Savitzky-Golay filter (`sci-rs`), quaternions
//!   normalised again.

use glam::{DQuat, DVec3};
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;

/// Noise added by [`corrupt`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Noise {
    /// Standard deviation of each rotation-vector component of the joint-angle noise, degrees.
    pub angle_deg: f64,
    /// Standard deviation of each root-position component's jitter, clip units (cm for bandai2).
    pub root: f64,
    /// Fraction of frames replaced by outlier poses, `[0, 1)`.
    pub outlier_fraction: f64,
    /// Standard deviation of each rotation-vector component of an outlier pose's noise, degrees.
    pub outlier_deg: f64,
}

impl Noise {
    /// Checks the values: finite, not negative, the outlier fraction below 1.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in
            [("angle noise", self.angle_deg), ("root jitter", self.root), ("outlier noise", self.outlier_deg)]
        {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("the {name} must be finite and not negative, found {v}"));
            }
        }
        if !(self.outlier_fraction.is_finite() && (0.0..1.0).contains(&self.outlier_fraction)) {
            return Err(format!("the outlier fraction must be in [0, 1), found {}", self.outlier_fraction));
        }
        Ok(())
    }
}

/// A rotation by a rotation vector of Gaussian components with standard deviation `sigma` (radians).
fn random_turn(rng: &mut SplitMix64, sigma: f64) -> DQuat {
    let v = DVec3::new(rng.normal(), rng.normal(), rng.normal()) * sigma;
    DQuat::from_scaled_axis(v)
}

/// `clip` with `noise` added, deterministic for `seed`. Returns the noisy clip and the indices of
/// its outlier frames (`round(fraction * frames)` of them, distinct).
pub fn corrupt(clip: &Clip, noise: &Noise, seed: u64) -> (Clip, Vec<usize>) {
    let mut rng = SplitMix64::new(seed);
    let (frames, joints) = (clip.frames(), clip.joints());
    let mut out = clip.clone();
    let mut order: Vec<usize> = (0..frames).collect();
    rng.shuffle(&mut order);
    let mut outliers: Vec<usize> =
        order[..((noise.outlier_fraction * frames as f64).round() as usize).min(frames)].to_vec();
    outliers.sort_unstable();
    let (angle, outlier) = (noise.angle_deg.to_radians(), noise.outlier_deg.to_radians());
    for f in 0..frames {
        let is_outlier = outliers.binary_search(&f).is_ok();
        for j in 0..joints {
            let i = f * joints + j;
            let mut q = out.local_rotations[i] * random_turn(&mut rng, angle);
            if is_outlier {
                q *= random_turn(&mut rng, outlier);
            }
            out.local_rotations[i] = q.normalize();
        }
        let jitter = DVec3::new(rng.normal(), rng.normal(), rng.normal()) * noise.root;
        out.local_positions[f * joints] += jitter;
    }
    (out, outliers)
}

/// Savitzky-Golay smoothing of `clip` (window `window`, odd, polynomial order `order <
/// window - 1`): root positions per coordinate, local quaternions per component after making
/// their sign continuous, then normalised. Edges are padded with the nearest value (`sci-rs`).
pub fn savgol(clip: &Clip, window: usize, order: usize) -> Result<Clip, String> {
    let (frames, joints) = (clip.frames(), clip.joints());
    if window.is_multiple_of(2) || window < order + 2 {
        return Err(format!(
            "a Savitzky-Golay window must be odd and at least the order + 2: window {window}, order {order}"
        ));
    }
    let mut out = clip.clone();
    if frames < 2 {
        return Ok(out);
    }
    let filter = |values: Vec<f64>| -> Vec<f64> {
        sci_rs::signal::filter::savgol_filter_dyn(values.into_iter(), window, order, None, None)
    };
    for a in 0..3 {
        let smooth = filter((0..frames).map(|f| clip.local_positions[f * joints][a]).collect());
        for (f, v) in smooth.into_iter().enumerate() {
            out.local_positions[f * joints][a] = v;
        }
    }
    for j in 0..joints {
        let mut q: Vec<DQuat> = (0..frames).map(|f| clip.local_rotations[f * joints + j]).collect();
        for f in 1..frames {
            if q[f].dot(q[f - 1]) < 0.0 {
                q[f] = -q[f];
            }
        }
        let comps: Vec<Vec<f64>> = (0..4).map(|c| filter(q.iter().map(|x| x.to_array()[c]).collect())).collect();
        for f in 0..frames {
            let s = DQuat::from_xyzw(comps[0][f], comps[1][f], comps[2][f], comps[3][f]);
            out.local_rotations[f * joints + j] = if s.length() > 1e-9 { s.normalize() } else { q[f] };
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::{EulerOrder, JointChannels, Skeleton};

    fn clip(frames: usize) -> Clip {
        let skeleton = Skeleton {
            names: vec!["Hips".into(), "Leg".into()],
            parents: vec![None, Some(0)],
            offsets: vec![DVec3::ZERO, DVec3::new(0.0, -40.0, 0.0)],
            end_sites: vec![None, None],
            channels: vec![JointChannels { position: true, order: EulerOrder::Zxy }; 2],
        };
        let mut rot = Vec::new();
        let mut pos = Vec::new();
        for f in 0..frames {
            let t = f as f64 / 30.0;
            rot.push(DQuat::from_rotation_y(0.3 * t));
            rot.push(DQuat::from_rotation_x(0.5 * (2.0 * t).sin()));
            pos.push(DVec3::new(100.0 * t, 90.0, 0.0));
            pos.push(DVec3::new(0.0, -40.0, 0.0));
        }
        Clip { skeleton, frame_time: 1.0 / 30.0, local_rotations: rot, local_positions: pos }
    }

    #[test]
    fn corrupt_is_seeded_and_has_the_asked_outliers() {
        let c = clip(200);
        let n = Noise { angle_deg: 2.0, root: 2.0, outlier_fraction: 0.01, outlier_deg: 20.0 };
        let (a, oa) = corrupt(&c, &n, 3);
        let (b, ob) = corrupt(&c, &n, 3);
        assert_eq!(a, b);
        assert_eq!(oa, ob);
        assert_eq!(oa.len(), 2);
        let (d, _) = corrupt(&c, &n, 4);
        assert_ne!(a, d);
        // Root jitter of about 2 units per coordinate; offsets of other joints untouched.
        let rms = (0..200).map(|f| (a.local_positions[2 * f] - c.local_positions[2 * f]).length_squared()).sum::<f64>()
            / 200.0;
        assert!((rms.sqrt() - 2.0 * 3f64.sqrt()).abs() < 0.6, "root jitter rms {}", rms.sqrt());
        assert!((0..200).all(|f| a.local_positions[2 * f + 1] == c.local_positions[2 * f + 1]));
        assert!(Noise { outlier_fraction: 1.0, ..n }.validate().is_err());
        assert!(Noise { angle_deg: f64::NAN, ..n }.validate().is_err());
    }

    #[test]
    fn savgol_keeps_smooth_motion_and_removes_noise() {
        let c = clip(120);
        let n = Noise { angle_deg: 3.0, root: 2.0, outlier_fraction: 0.0, outlier_deg: 0.0 };
        let (noisy, _) = corrupt(&c, &n, 1);
        let err = |x: &Clip| {
            (0..120).map(|f| x.local_rotations[2 * f + 1].angle_between(c.local_rotations[2 * f + 1])).sum::<f64>()
                / 120.0
        };
        let smooth = savgol(&noisy, 9, 2).unwrap();
        assert!(err(&smooth) < 0.6 * err(&noisy), "{} vs {}", err(&smooth), err(&noisy));
        // A clean smooth clip passes nearly unchanged (away from the padded edges).
        let same = savgol(&c, 9, 2).unwrap();
        for f in 10..110 {
            assert!(same.local_rotations[2 * f + 1].angle_between(c.local_rotations[2 * f + 1]) < 1e-3);
            assert!((same.local_positions[2 * f] - c.local_positions[2 * f]).length() < 1e-6);
        }
        assert!(savgol(&c, 8, 2).is_err());
        assert!(savgol(&c, 3, 2).is_err());
    }
}
