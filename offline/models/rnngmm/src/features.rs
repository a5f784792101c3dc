//! The state feature `x` of the RNN-GMM (Wang, Chai & Xia, sec. 4.1.1 eq. 2-4, and the
//! contact bits of sec. 4.3), its inverse, and the normalisation statistics.
//!
//! Layout of one frame (`D = 6 + 3 (J - 1) + 2` values for `J` joints; 68 for bandai2):
//!
//! | index | value | unit |
//! | --- | --- | --- |
//! | 0, 1 | `dtx`, `dtz`: root translation since the previous frame, in the previous frame's heading frame | clip units per frame |
//! | 2 | `dry`: heading change since the previous frame (about +Y), wrapped to (-pi, pi] | radians |
//! | 3 | `ty`: root height | clip units |
//! | 4, 5 | `rx`, `rz`: the root's tilt (swing), rotation-vector x and z | radians |
//! | 6 + 3 (j - 1) .. + 3 | joint `j >= 1`: rotation vector of `reference_j^-1 * q_j` | radians |
//! | D - 2, D - 1 | contact of the left and right foot (1 planted, 0 not) | - |
//!
//! Root: its rotation is split into a heading (twist about world +Y) and a tilt
//! (`q_root = yaw(heading) * tilt`, swing-twist), so the tilt's rotation vector has no y
//! component and two numbers hold it, like the paper's `rx, rz`. Joint angles: the rotation
//! vector (exponential map) of each joint's local rotation relative to a per-joint reference
//! rotation (the mean of that joint's rotations over the training clips). Three numbers per
//! joint, every value decodes to a valid rotation (a sample of the mixture needs no projection),
//! and, measured from the joint's mean, locomotion stays far from the map's discontinuity at
//! pi. Non-root joint translations are the skeleton's rest offsets.
//!
//! Decoding accumulates the root as eq. 4: `M_t = M_(t-1) M_local(dtx, dtz, dry)`, from an
//! origin `M` (the identity in the paper; [`EncodedClip::origin`] reproduces the clip's own
//! placement). Frame 0 has no predecessor: its `dtx, dtz, dry` repeat frame 1's, and the origin
//! is the placement they imply one frame before frame 0.

use crate::error::{RnnGmmError, RnnGmmResult};
use glam::{DQuat, DVec3};
use serde::{Deserialize, Serialize};
use zoo_motion::quat::{from_scaled_axis, to_scaled_axis};
use zoo_motion::{Clip, Skeleton};

/// Values of the root block (`dtx, dtz, dry, ty, rx, rz`).
pub const ROOT_DIMS: usize = 6;
/// Values of the contact block (left, right).
pub const CONTACT_DIMS: usize = 2;

/// The state feature size for a skeleton of `joints` joints: `6 + 3 (joints - 1) + 2`.
pub fn feature_dim(joints: usize) -> usize {
    ROOT_DIMS + 3 * joints.saturating_sub(1) + CONTACT_DIMS
}

/// How foot contacts are detected. The rule is the foot lock's
/// (`zoo_protocol::footlock::FootLock`) with its default thresholds: each foot joint (ankle and
/// toes) has a contact weight `clamp(2 - 2^(h / height), 0, 1) * gate(v)` at height `h` above
/// its ground level and horizontal speed `v`, the gate being 1 up to `lock_speed` and 0 from
/// `swing_speed` on; a foot is planted when one of its joints has a weight of at least 1/2.
/// The ground level of a joint is the `ground_percentile`-th percentile of its height over the
/// clip (the foot-skate metric's planted height, taken per clip: flat ground).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactParams {
    /// Height above the ground level where the contact weight falls to 0 (clip units; 5 for cm).
    pub height: f64,
    /// Horizontal speed (clip units per second) up to which a low joint is fully in contact.
    pub lock_speed: f64,
    /// Horizontal speed (clip units per second) from which a joint is moving, not planted.
    pub swing_speed: f64,
    /// Percentile (0-100) of a joint's height over the clip taken as its ground level.
    pub ground_percentile: f64,
}

impl Default for ContactParams {
    /// Centimetres: 5 cm, and the foot lock's 8 and 16 cm per frame at 30 fps (240, 480 cm/s);
    /// the 5th percentile.
    fn default() -> Self {
        ContactParams { height: 5.0, lock_speed: 240.0, swing_speed: 480.0, ground_percentile: 5.0 }
    }
}

/// Where the character stands on the ground: the homogeneous transform `M` of eq. 4 (a
/// heading about +Y and a position on the x-z plane).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RootPlacement {
    /// World x (clip units).
    pub x: f64,
    /// World z (clip units).
    pub z: f64,
    /// Heading about +Y (radians).
    pub yaw: f64,
}

impl RootPlacement {
    /// `M_t = M_(t-1) M_local` (eq. 4): moves by `(dtx, 0, dtz)` in the current heading frame,
    /// then turns by `dry`.
    pub fn advance(&self, dtx: f64, dtz: f64, dry: f64) -> RootPlacement {
        let d = DQuat::from_rotation_y(self.yaw) * DVec3::new(dtx, 0.0, dtz);
        RootPlacement { x: self.x + d.x, z: self.z + d.z, yaw: self.yaw + dry }
    }
}

/// A clip as state features.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedClip {
    /// Feature values, `frames * dim`, frame-major.
    pub values: Vec<f32>,
    /// Values per frame.
    pub dim: usize,
    /// The placement one frame before frame 0: decoding from it reproduces the clip's global
    /// positions.
    pub origin: RootPlacement,
}

impl EncodedClip {
    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.values.len() / self.dim.max(1)
    }

    /// Features of frame `f`.
    pub fn frame(&self, f: usize) -> &[f32] {
        &self.values[f * self.dim..(f + 1) * self.dim]
    }
}

/// A decoded motion: the clip and the contact labels of each frame.
#[derive(Clone, Debug, PartialEq)]
pub struct DecodedMotion {
    /// The motion on the feature's skeleton.
    pub clip: Clip,
    /// Per frame: is the left / right foot planted (contact value above 1/2).
    pub contacts: Vec<[bool; 2]>,
}

/// Everything the feature depends on besides the clip: skeleton, frame rate, per-joint reference
/// rotations and the feet. Saved beside a trained model (`features.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureSpec {
    /// The skeleton (names, parents, rest offsets used for non-root joints).
    pub skeleton: Skeleton,
    /// Frames per second the features are defined at (the paper: 30).
    pub fps: f64,
    /// Reference rotation of each joint (the root's is unused and the identity), unit to 1e-9.
    pub reference: Vec<DQuat>,
    /// Joints of the left foot (ankle, then its children), for the contact bit.
    pub left_foot: Vec<usize>,
    /// Joints of the right foot.
    pub right_foot: Vec<usize>,
    /// Contact detection thresholds.
    pub contact: ContactParams,
}

/// Which side a joint name is on: `Some(true)` left, `Some(false)` right.
fn side_of(name: &str) -> Option<bool> {
    let n = name.to_ascii_lowercase();
    let left =
        n.contains("left") || n.ends_with("_l") || n.ends_with(".l") || n.starts_with("l_") || n.starts_with("lfoot");
    let right =
        n.contains("right") || n.ends_with("_r") || n.ends_with(".r") || n.starts_with("r_") || n.starts_with("rfoot");
    match (left, right) {
        (true, false) => Some(true),
        (false, true) => Some(false),
        _ => None,
    }
}

/// The ankle (a joint whose name contains `foot`) of each side and its children.
fn find_feet(skeleton: &Skeleton) -> RnnGmmResult<(Vec<usize>, Vec<usize>)> {
    let mut sides: [Option<usize>; 2] = [None, None];
    for (j, name) in skeleton.names.iter().enumerate() {
        if !name.to_ascii_lowercase().contains("foot") {
            continue;
        }
        if let Some(left) = side_of(name) {
            let slot = &mut sides[usize::from(!left)];
            // The first such joint down the hierarchy is the ankle.
            if slot.is_none() {
                *slot = Some(j);
            }
        }
    }
    let foot = |ankle: usize| -> Vec<usize> { std::iter::once(ankle).chain(skeleton.children(ankle)).collect() };
    match sides {
        [Some(l), Some(r)] => Ok((foot(l), foot(r))),
        _ => Err(RnnGmmError::Motion(format!(
            "the skeleton needs a left and a right ankle for the contact bits: joint names containing `foot` \
             and a side (`Left`/`Right`, `_L`/`_R`); found left {:?}, right {:?} among {:?}",
            sides[0].map(|j| &skeleton.names[j]),
            sides[1].map(|j| &skeleton.names[j]),
            skeleton.names
        ))),
    }
}

/// Heading and tilt of a root rotation: `q = yaw(heading) * tilt` with the tilt's y component 0.
fn split_root(q: DQuat, frame: usize) -> RnnGmmResult<(f64, DQuat)> {
    let norm = (q.y * q.y + q.w * q.w).sqrt();
    if norm < 1e-6 {
        return Err(RnnGmmError::Motion(format!(
            "frame {frame}: the root is turned half-way round a horizontal axis, so its heading about +Y is \
             undefined; the state feature needs a root whose rotation is an upright heading times a tilt \
             below 180 degrees (re-export the clip with a Y-up root)"
        )));
    }
    let heading = 2.0 * q.y.atan2(q.w);
    let tilt = DQuat::from_rotation_y(-heading) * q;
    Ok((heading, tilt))
}

/// Wraps an angle to (-pi, pi].
fn wrap(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let w = a - tau * (a / tau).round();
    if w <= -std::f64::consts::PI { w + tau } else { w }
}

impl FeatureSpec {
    /// The feature of `skeleton` at `fps`, with reference rotations fitted on `clips` (the mean
    /// rotation of each joint; the identity without clips) and the default contact thresholds.
    pub fn fit(skeleton: &Skeleton, fps: f64, clips: &[&Clip]) -> RnnGmmResult<Self> {
        skeleton.validate().map_err(|e| RnnGmmError::Motion(format!("skeleton: {e}")))?;
        if !(fps.is_finite() && fps > 0.0) {
            return Err(RnnGmmError::Config(format!("frames per second must be positive, found {fps}")));
        }
        let (left_foot, right_foot) = find_feet(skeleton)?;
        let joints = skeleton.len();
        let mut sum = vec![[0f64; 4]; joints];
        let mut first: Vec<Option<DQuat>> = vec![None; joints];
        for (i, clip) in clips.iter().enumerate() {
            if let Some(d) = skeleton.topology_difference(&clip.skeleton) {
                return Err(RnnGmmError::Motion(format!("clip {i} is on another skeleton: {d}")));
            }
            for (k, q) in clip.local_rotations.iter().enumerate() {
                let j = k % joints;
                let r = *first[j].get_or_insert(*q);
                let q = if q.dot(r) < 0.0 { -*q } else { *q };
                for (s, v) in sum[j].iter_mut().zip([q.x, q.y, q.z, q.w]) {
                    *s += v;
                }
            }
        }
        let reference = (0..joints)
            .map(|j| {
                let [x, y, z, w] = sum[j];
                let q = DQuat::from_xyzw(x, y, z, w);
                if j == 0 || q.length().is_nan() || q.length() <= 1e-9 {
                    return DQuat::IDENTITY;
                }
                // On a 1e-9 grid, so the reference survives `features.json` bit for bit (serde_json
                // parses a 9-digit decimal exactly; a 17-digit one may come back 1 ULP off).
                let q = q.normalize();
                let snap = |v: f64| (v * 1e9).round() / 1e9;
                DQuat::from_xyzw(snap(q.x), snap(q.y), snap(q.z), snap(q.w))
            })
            .collect();
        Ok(FeatureSpec {
            skeleton: skeleton.clone(),
            fps,
            reference,
            left_foot,
            right_foot,
            contact: ContactParams::default(),
        })
    }

    /// Checks that the parts agree (e.g. after reading `features.json`): a valid skeleton, one
    /// reference rotation per joint, feet that are joints, positive frame rate and thresholds.
    pub fn validate(&self) -> RnnGmmResult<()> {
        let bad = |m: String| Err(RnnGmmError::Config(format!("feature definition: {m}")));
        self.skeleton.validate().map_err(|e| RnnGmmError::Config(format!("feature definition: skeleton: {e}")))?;
        let j = self.skeleton.len();
        if self.reference.len() != j || self.reference.iter().any(|q| !q.is_finite()) {
            return bad(format!(
                "{} finite reference rotations needed for {j} joints, found {}",
                j,
                self.reference.len()
            ));
        }
        if self.left_foot.is_empty()
            || self.right_foot.is_empty()
            || self.left_foot.iter().chain(&self.right_foot).any(|&f| f == 0 || f >= j)
        {
            return bad(format!(
                "feet {:?} and {:?} must be non-empty lists of non-root joints (below {j})",
                self.left_foot, self.right_foot
            ));
        }
        let c = &self.contact;
        let sane = self.fps > 0.0
            && c.height > 0.0
            && c.lock_speed >= 0.0
            && c.swing_speed > c.lock_speed
            && (0.0..=100.0).contains(&c.ground_percentile);
        if !sane {
            return bad(format!(
                "fps ({}) and contact height ({}) must be positive, 0 <= lock_speed ({}) < swing_speed ({}), \
                 ground_percentile ({}) in [0, 100]",
                self.fps, c.height, c.lock_speed, c.swing_speed, c.ground_percentile
            ));
        }
        Ok(())
    }

    /// Values per frame.
    pub fn dim(&self) -> usize {
        feature_dim(self.skeleton.len())
    }

    /// Index of the first contact value (left; right follows).
    pub fn contact_index(&self) -> usize {
        self.dim() - CONTACT_DIMS
    }

    /// Index of the first of joint `j`'s three angle values (`j >= 1`).
    pub fn joint_index(&self, j: usize) -> usize {
        ROOT_DIMS + 3 * (j - 1)
    }

    /// Per frame: is the left / right foot planted (see [`ContactParams`]), from global positions.
    /// `global_pos` holds `frames * joints` positions (frame-major); fewer frames are read when
    /// it is shorter.
    pub fn detect_contacts(&self, global_pos: &[DVec3], frames: usize) -> Vec<[bool; 2]> {
        let joints = self.skeleton.len();
        let frames = frames.min(global_pos.len() / joints.max(1));
        if frames == 0 {
            return Vec::new();
        }
        let c = &self.contact;
        let dt = 1.0 / self.fps;
        let percentile = |j: usize| {
            let mut h: Vec<f64> = (0..frames).map(|f| global_pos[f * joints + j].y).collect();
            h.sort_by(f64::total_cmp);
            let rank = (c.ground_percentile / 100.0).clamp(0.0, 1.0) * (frames - 1) as f64;
            let (lo, hi) = (rank.floor() as usize, rank.ceil() as usize);
            h[lo] + (h[hi] - h[lo]) * (rank - lo as f64)
        };
        let feet = [&self.left_foot, &self.right_foot];
        let ground: Vec<Vec<f64>> = feet.iter().map(|foot| foot.iter().map(|&j| percentile(j)).collect()).collect();
        (0..frames)
            .map(|f| {
                let mut out = [false; 2];
                for (side, foot) in feet.iter().enumerate() {
                    out[side] = foot.iter().zip(&ground[side]).any(|(&j, &g)| {
                        let p = global_pos[f * joints + j];
                        // Frame 0 has no previous frame: its speed is frame 1's.
                        let (a, b) = if f == 0 { (1.min(frames - 1), 0) } else { (f, f - 1) };
                        let (pa, pb) = (global_pos[a * joints + j], global_pos[b * joints + j]);
                        let v = (pa.x - pb.x).hypot(pa.z - pb.z) / dt;
                        let gate = ((c.swing_speed - v) / (c.swing_speed - c.lock_speed).max(1e-9)).clamp(0.0, 1.0);
                        let w = (2.0 - ((p.y - g) / c.height).exp2()).clamp(0.0, 1.0) * gate;
                        w >= 0.5
                    });
                }
                out
            })
            .collect()
    }

    /// Encodes a clip (at least 2 frames, on this skeleton, at this frame rate) with the contacts
    /// detected from its motion.
    pub fn encode(&self, clip: &Clip) -> RnnGmmResult<EncodedClip> {
        self.check_clip(clip)?;
        let (_, gp) = clip.global();
        let contacts = self.detect_contacts(&gp, clip.frames());
        self.encode_with_contacts(clip, &contacts)
    }

    fn check_clip(&self, clip: &Clip) -> RnnGmmResult<()> {
        if let Some(d) = self.skeleton.topology_difference(&clip.skeleton) {
            return Err(RnnGmmError::Motion(format!("the clip is on another skeleton than the feature's: {d}")));
        }
        let frames = clip.frames();
        if frames < 2 || clip.local_positions.len() != clip.local_rotations.len() {
            return Err(RnnGmmError::Motion(format!(
                "a clip needs at least 2 frames of rotations and positions, found {} rotations and {} positions \
                 for {} joints",
                clip.local_rotations.len(),
                clip.local_positions.len(),
                clip.joints()
            )));
        }
        let fps = clip.fps();
        let off = (fps - self.fps).abs();
        if off.is_nan() || off > 0.01 * self.fps {
            return Err(RnnGmmError::Motion(format!(
                "the clip is at {fps:.2} fps, the features are defined at {} fps: resample the clip first",
                self.fps
            )));
        }
        let joints = clip.joints();
        for f in 0..frames {
            for j in 0..joints {
                let (q, p) = (clip.local_rotations[f * joints + j], clip.local_positions[f * joints + j]);
                if !(q.is_finite() && p.is_finite()) {
                    return Err(RnnGmmError::Motion(format!(
                        "frame {f}, joint `{}`: NaN or infinite rotation or position",
                        self.skeleton.names[j]
                    )));
                }
                if j > 0 {
                    let off = self.skeleton.offsets[j];
                    let drift = (p - off).length();
                    if drift > 0.1 + 1e-3 * off.length() {
                        return Err(RnnGmmError::Motion(format!(
                            "frame {f}: joint `{}` is translated {drift:.3} units away from its rest offset; the \
                             state feature holds joint angles only (the translation of joints other than the root \
                             must be the skeleton's offset)",
                            self.skeleton.names[j]
                        )));
                    }
                }
            }
        }
        Ok(())
    }

    /// Encodes a clip with given contact labels (one per frame), e.g. a dataset's own.
    pub fn encode_with_contacts(&self, clip: &Clip, contacts: &[[bool; 2]]) -> RnnGmmResult<EncodedClip> {
        self.check_clip(clip)?;
        let (frames, joints, dim) = (clip.frames(), clip.joints(), self.dim());
        if contacts.len() != frames {
            return Err(RnnGmmError::Size {
                what: "contact labels".into(),
                expected: frames,
                detail: "one per frame".into(),
                found: contacts.len(),
            });
        }
        let mut heading = Vec::with_capacity(frames);
        let mut tilt = Vec::with_capacity(frames);
        for f in 0..frames {
            let (h, t) = split_root(clip.local_rotations[f * joints], f)?;
            heading.push(h);
            tilt.push(t);
        }
        // Root motion of frame f relative to frame f - 1 (frame 0 repeats frame 1's).
        let delta = |f: usize| -> [f64; 3] {
            let f = f.max(1);
            let d = DQuat::from_rotation_y(-heading[f - 1]) * (clip.root_position(f) - clip.root_position(f - 1));
            [d.x, d.z, wrap(heading[f] - heading[f - 1])]
        };
        let mut values = vec![0f32; frames * dim];
        for f in 0..frames {
            let x = &mut values[f * dim..(f + 1) * dim];
            let [dtx, dtz, dry] = delta(f);
            let r = to_scaled_axis(tilt[f]);
            let root = [dtx, dtz, dry, clip.root_position(f).y, r.x, r.z];
            for (v, r) in x[..ROOT_DIMS].iter_mut().zip(root) {
                *v = r as f32;
            }
            for j in 1..joints {
                let q = self.reference[j].inverse() * clip.local_rotations[f * joints + j];
                let a = to_scaled_axis(q);
                let i = self.joint_index(j);
                x[i..i + 3].copy_from_slice(&[a.x as f32, a.y as f32, a.z as f32]);
            }
            let c = self.contact_index();
            x[c] = f32::from(u8::from(contacts[f][0]));
            x[c + 1] = f32::from(u8::from(contacts[f][1]));
        }
        // The placement before frame 0 from which frame 0's (stored) deltas lead to frame 0.
        let x0 = &values[..dim];
        let yaw = heading[0] - x0[2] as f64;
        let step = DQuat::from_rotation_y(yaw) * DVec3::new(x0[0] as f64, 0.0, x0[1] as f64);
        let p0 = clip.root_position(0);
        let origin = RootPlacement { x: p0.x - step.x, z: p0.z - step.z, yaw };
        Ok(EncodedClip { values, dim, origin })
    }

    /// Decodes one frame of features into local rotations and positions (one per joint),
    /// advancing `placement` (eq. 4). Returns the contact bits.
    pub fn decode_frame(
        &self,
        x: &[f32],
        placement: &mut RootPlacement,
        rotations: &mut [DQuat],
        positions: &mut [DVec3],
    ) -> RnnGmmResult<[bool; 2]> {
        let (joints, dim) = (self.skeleton.len(), self.dim());
        if x.len() != dim || rotations.len() != joints || positions.len() != joints {
            return Err(RnnGmmError::Size {
                what: "decoded frame".into(),
                expected: dim,
                detail: format!("features of {joints} joints, and {joints} rotations and positions"),
                found: x.len(),
            });
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(RnnGmmError::Motion(format!("feature value {i} is {}: cannot decode it", x[i])));
        }
        let v = |i: usize| x[i] as f64;
        *placement = placement.advance(v(0), v(1), v(2));
        rotations[0] = DQuat::from_rotation_y(placement.yaw) * from_scaled_axis(DVec3::new(v(4), 0.0, v(5)));
        positions[0] = DVec3::new(placement.x, v(3), placement.z);
        for j in 1..joints {
            let i = self.joint_index(j);
            rotations[j] = (self.reference[j] * from_scaled_axis(DVec3::new(v(i), v(i + 1), v(i + 2)))).normalize();
            positions[j] = self.skeleton.offsets[j];
        }
        let c = self.contact_index();
        Ok([x[c] > 0.5, x[c + 1] > 0.5])
    }

    /// Decodes frames of features (`frames * dim`) from `origin`, the placement before the first
    /// frame ([`RootPlacement::default`] is the paper's identity).
    pub fn decode(&self, values: &[f32], origin: RootPlacement) -> RnnGmmResult<DecodedMotion> {
        let (joints, dim) = (self.skeleton.len(), self.dim());
        if values.is_empty() || !values.len().is_multiple_of(dim) {
            return Err(RnnGmmError::Size {
                what: "features to decode".into(),
                expected: dim,
                detail: format!("a whole number of frames of {dim} values, at least one"),
                found: values.len(),
            });
        }
        let frames = values.len() / dim;
        let mut rot = vec![DQuat::IDENTITY; frames * joints];
        let mut pos = vec![DVec3::ZERO; frames * joints];
        let mut contacts = Vec::with_capacity(frames);
        let mut placement = origin;
        for f in 0..frames {
            let r = f * joints..(f + 1) * joints;
            let c = self
                .decode_frame(&values[f * dim..(f + 1) * dim], &mut placement, &mut rot[r.clone()], &mut pos[r])
                .map_err(|e| match e {
                    RnnGmmError::Motion(m) => RnnGmmError::Motion(format!("frame {f}: {m}")),
                    e => e,
                })?;
            contacts.push(c);
        }
        let clip = Clip {
            skeleton: self.skeleton.clone(),
            frame_time: 1.0 / self.fps,
            local_rotations: rot,
            local_positions: pos,
        };
        Ok(DecodedMotion { clip, contacts })
    }
}

/// Per-dimension mean and standard deviation of the features over the training frames; the
/// networks see `(x - mean) / std`. Saved beside a trained model (`normalization.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    /// Mean of each feature value.
    pub mean: Vec<f32>,
    /// Standard deviation of each feature value (population); a value that does not vary
    /// (std below [`Normalization::MIN_STD`]) gets 1, so it is only centred.
    pub std: Vec<f32>,
}

impl Normalization {
    /// Standard deviations below this are replaced by 1.
    pub const MIN_STD: f64 = 1e-5;

    /// Fits the statistics on every frame of `clips` (at least one frame, all of one size).
    pub fn fit(clips: &[EncodedClip]) -> RnnGmmResult<Self> {
        let Some(dim) = clips.first().map(|c| c.dim) else {
            return Err(RnnGmmError::Config("no clips to fit the normalisation statistics on".into()));
        };
        let (mut sum, mut sq, mut n) = (vec![0f64; dim], vec![0f64; dim], 0usize);
        for (i, c) in clips.iter().enumerate() {
            if c.dim != dim {
                return Err(RnnGmmError::Config(format!(
                    "clip {i} has {} feature values per frame, clip 0 {dim}",
                    c.dim
                )));
            }
            for frame in c.values.chunks_exact(dim) {
                for (k, &v) in frame.iter().enumerate() {
                    sum[k] += v as f64;
                    sq[k] += v as f64 * v as f64;
                }
                n += 1;
            }
        }
        if n == 0 {
            return Err(RnnGmmError::Config("the clips have no frames to fit the normalisation statistics on".into()));
        }
        let mean: Vec<f64> = sum.iter().map(|s| s / n as f64).collect();
        let std = sq
            .iter()
            .zip(&mean)
            .map(|(q, m)| {
                let s = (q / n as f64 - m * m).max(0.0).sqrt();
                if s < Self::MIN_STD { 1.0 } else { s as f32 }
            })
            .collect();
        Ok(Normalization { mean: mean.iter().map(|&m| m as f32).collect(), std })
    }

    /// Values per frame.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// `(x - mean) / std` in place, frame by frame.
    pub fn normalize(&self, values: &mut [f32]) {
        for frame in values.chunks_exact_mut(self.dim()) {
            for ((v, m), s) in frame.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = (*v - m) / s;
            }
        }
    }

    /// `x * std + mean` in place, frame by frame.
    pub fn denormalize(&self, values: &mut [f32]) {
        for frame in values.chunks_exact_mut(self.dim()) {
            for ((v, m), s) in frame.iter_mut().zip(&self.mean).zip(&self.std) {
                *v = *v * s + m;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_data::synth::{SynthConfig, generate_clip};

    fn synth(index: usize, seconds: f64) -> zoo_data::synth::SynthClip {
        generate_clip(&SynthConfig { minutes: 1.0, seed: 7, terrain: false, fps: 30.0, clip_seconds: seconds }, index)
    }

    #[test]
    fn the_layout_has_the_papers_root_block_joint_angles_and_two_contacts() {
        let s = synth(0, 2.0);
        let spec = FeatureSpec::fit(&s.clip.skeleton, 30.0, &[&s.clip]).unwrap();
        assert_eq!(spec.dim(), 68);
        assert_eq!((spec.joint_index(1), spec.contact_index()), (6, 66));
        let names = |f: &[usize]| f.iter().map(|&j| spec.skeleton.names[j].clone()).collect::<Vec<_>>();
        assert_eq!(names(&spec.left_foot), ["Foot_L", "Toes_L"]);
        assert_eq!(names(&spec.right_foot), ["Foot_R", "Toes_R"]);
    }

    #[test]
    fn round_trip_reproduces_global_positions() {
        for index in 0..4 {
            let s = synth(index, 6.0);
            let clip = &s.clip;
            let spec = FeatureSpec::fit(&clip.skeleton, 30.0, &[clip]).unwrap();
            let enc = spec.encode(clip).unwrap();
            assert_eq!(enc.frames(), clip.frames());
            let dec = spec.decode(&enc.values, enc.origin).unwrap();
            let (_, a) = clip.global();
            let (_, b) = dec.clip.global();
            let err = a.iter().zip(&b).map(|(p, q)| (*p - *q).length()).fold(0.0, f64::max);
            assert!(err < 1e-4, "clip {index} ({:?}): largest position error {err} cm", s.gait);
            let travelled = (clip.root_position(clip.frames() - 1) - clip.root_position(0)).length();
            assert!(index != 1 || travelled > 0.0);
        }
    }

    #[test]
    fn features_do_not_depend_on_where_the_clip_is_or_which_way_it_faces() {
        let s = synth(2, 3.0);
        let spec = FeatureSpec::fit(&s.clip.skeleton, 30.0, &[&s.clip]).unwrap();
        let mut moved = s.clip.clone();
        let turn = DQuat::from_rotation_y(1.3);
        let j = moved.joints();
        for f in 0..moved.frames() {
            moved.local_rotations[f * j] = turn * moved.local_rotations[f * j];
            moved.local_positions[f * j] = turn * moved.local_positions[f * j] + DVec3::new(500.0, 0.0, -300.0);
        }
        let (a, b) = (spec.encode(&s.clip).unwrap(), spec.encode(&moved).unwrap());
        let err = a.values.iter().zip(&b.values).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max);
        assert!(err < 1e-4, "{err}");
        assert!((b.origin.yaw - a.origin.yaw - 1.3).abs() < 1e-9);
    }

    #[test]
    fn detected_contacts_agree_with_the_synthetic_ground_truth() {
        let (mut agree, mut total) = (0usize, 0usize);
        for index in 0..6 {
            let s = synth(index, 6.0);
            let spec = FeatureSpec::fit(&s.clip.skeleton, 30.0, &[&s.clip]).unwrap();
            let enc = spec.encode(&s.clip).unwrap();
            let c = spec.contact_index();
            for (f, truth) in s.contacts.iter().enumerate() {
                for side in 0..2 {
                    agree += usize::from((enc.frame(f)[c + side] > 0.5) == truth[side]);
                    total += 1;
                }
            }
        }
        let rate = agree as f64 / total as f64;
        assert!(rate > 0.9, "contact agreement {rate}");
    }

    #[test]
    fn bad_clips_are_refused_with_the_reason() {
        let s = synth(0, 1.0);
        let spec = FeatureSpec::fit(&s.clip.skeleton, 30.0, &[&s.clip]).unwrap();
        let mut slow = s.clip.clone();
        slow.frame_time = 1.0 / 120.0;
        assert!(spec.encode(&slow).unwrap_err().to_string().contains("resample"));
        let mut nan = s.clip.clone();
        nan.local_positions[0].x = f64::NAN;
        assert!(spec.encode(&nan).unwrap_err().to_string().contains("NaN"));
        let one = s.clip.slice(0, 1);
        assert!(spec.encode(&one).unwrap_err().to_string().contains("at least 2 frames"));
        let mut stretched = s.clip.clone();
        stretched.local_positions[5] += DVec3::new(3.0, 0.0, 0.0);
        assert!(spec.encode(&stretched).unwrap_err().to_string().contains("rest offset"));
        let mut flipped = s.clip.clone();
        flipped.local_rotations[0] = DQuat::from_rotation_x(std::f64::consts::PI);
        assert!(spec.encode(&flipped).unwrap_err().to_string().contains("heading"));
        assert!(spec.decode(&[0.0; 67], RootPlacement::default()).is_err());
        let mut bad = spec.encode(&s.clip).unwrap().values;
        bad[70] = f32::INFINITY;
        assert!(spec.decode(&bad, RootPlacement::default()).unwrap_err().to_string().contains("frame 1"));
        let mut skel = s.clip.skeleton.clone();
        skel.names[15] = "Ankle_L".into();
        assert!(FeatureSpec::fit(&skel, 30.0, &[]).unwrap_err().to_string().contains("left"));
    }

    #[test]
    fn a_damaged_feature_definition_is_refused() {
        let s = synth(0, 1.0);
        let spec = FeatureSpec::fit(&s.clip.skeleton, 30.0, &[&s.clip]).unwrap();
        spec.validate().unwrap();
        let mut short = spec.clone();
        short.reference.pop();
        assert!(short.validate().unwrap_err().to_string().contains("reference rotations"));
        let mut feet = spec.clone();
        feet.left_foot = vec![99];
        assert!(feet.validate().unwrap_err().to_string().contains("feet"));
        let mut c = spec.clone();
        c.contact.swing_speed = 0.0;
        assert!(c.validate().unwrap_err().to_string().contains("swing_speed"));
        assert!(spec.detect_contacts(&[], 10).is_empty());
    }

    #[test]
    fn normalization_centres_and_scales_and_inverts() {
        let s = synth(1, 2.0);
        let spec = FeatureSpec::fit(&s.clip.skeleton, 30.0, &[&s.clip]).unwrap();
        let enc = spec.encode(&s.clip).unwrap();
        let norm = Normalization::fit(std::slice::from_ref(&enc)).unwrap();
        let mut v = enc.values.clone();
        norm.normalize(&mut v);
        let d = enc.dim;
        let n = enc.frames() as f64;
        for k in 0..d {
            let col: Vec<f64> = v.chunks_exact(d).map(|f| f[k] as f64).collect();
            let m = col.iter().sum::<f64>() / n;
            let sd = (col.iter().map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt();
            assert!(m.abs() < 1e-3, "dim {k}: mean {m}");
            assert!((sd - 1.0).abs() < 1e-3 || sd < 1e-3, "dim {k}: std {sd}");
        }
        norm.denormalize(&mut v);
        let err = v.iter().zip(&enc.values).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert!(err < 1e-3, "{err}");
        assert!(Normalization::fit(&[]).is_err());
    }
}
