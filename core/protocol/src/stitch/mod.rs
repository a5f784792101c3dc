//! The stitching pose vector of the Recurrent Motion Refiner (Kim et al. 2023, sec. 4) and what
//! it is made of: which joints are the lower body and the feet ([`StitchLayout`]), the ground
//! root (the hips projected on the floor, [`GroundRoot`]), foot contacts, and the encoding of
//! poses into pose vectors and back ([`encode_pose`], [`decode_pose`]).
//!
//! It lives in the core layer (`zoo_protocol`) because three sides share it: the offline pair generator and
//! benchmark (`zoo_rmr::pairs`), the candle model (`zoo_rmr`) and the engine's runtime, which
//! turns the poses it is given (root transform plus local joint rotations) into pose vectors
//! and the refined pose vectors back into poses, frame by frame. [`lock`] is the foot lock by
//! the predicted contacts that follows the refiner offline and in the runtime.
//!
//! Frame `t` of a sequence is `x_t = {r_t, p_t, q_t, v_t, c_t}` (`f32`):
//! - `r_t` (3): root displacement `(dx, dtheta, dz)` from the previous frame's ground root, in
//!   that root's frame (clip units, radians);
//! - `p_t` (3 J_lower): lower-body joint positions in the frame's ground root;
//! - `q_t` (4 J): local rotation quaternions `(x, y, z, w)` of every joint, the root joint's
//!   relative to the ground root's heading; each joint's quaternions are made continuous along
//!   time starting from `w >= 0` at frame 0;
//! - `v_t` (3 J_lower): lower-body joint displacements since the previous frame, in the
//!   previous frame's ground root;
//! - `c_t` (4): contacts (0 or 1) of left heel, left toe, right heel, right toe.
//!
//! The first frame has no predecessor: its `r` and `v` repeat frame 1's. The layout is
//! contiguous, so the "pose" part is the first `dim - 4` values.

pub mod guard;
pub mod lock;
pub mod reach;

use glam::{DQuat, DVec3};
use zoo_motion::facing::{ground_forward, heading_angle};
use zoo_motion::fk::forward_kinematics_frame;
use zoo_motion::{Clip, Skeleton};

/// Lower-body joints of bandai2 (and of the synthetic skeleton, which is bandai2's): the hips,
/// both legs and both feet. The paper's LaFAN1 list has 11 joints; bandai2 has no second
/// spine joint below the chest worth counting as lower body, so 9 remain.
pub const BANDAI2_LOWER_BODY: [&str; 9] =
    ["Hips", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R"];

/// Contact joints of bandai2 in the order of the contact vector: left heel (the ankle,
/// `Foot_L`), left toe, right heel, right toe.
pub const BANDAI2_CONTACTS: [&str; 4] = ["Foot_L", "Toes_L", "Foot_R", "Toes_R"];

/// Contact height thresholds (cm above each joint's planted height): heel 2.5, toe 1.6 (RMR sec. 4).
pub const CONTACT_THRESHOLDS: [f64; 4] = [2.5, 1.6, 2.5, 1.6];

/// Why a stitching layout does not fit a skeleton, or poses do not fit a layout.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LayoutError {
    /// A joint the layout needs is missing from the skeleton.
    #[error(
        "the skeleton has no joint `{joint}` (needed as {role}); pass a StitchLayout with explicit joint \
         indices for this rig"
    )]
    MissingJoint {
        /// Joint name looked for.
        joint: String,
        /// What it is needed for.
        role: &'static str,
    },
    /// A joint index is out of range.
    #[error("joint index {index} ({role}) is out of range for a skeleton of {joints} joints")]
    JointIndex {
        /// The index.
        index: usize,
        /// What it is used for.
        role: &'static str,
        /// Joints of the skeleton.
        joints: usize,
    },
    /// The layout is not usable as it is.
    #[error("{0}")]
    Invalid(String),
}

/// The `q`-th percentile (`0..=100`, linear between ranks) of `values`, which it sorts; NaN when
/// empty.
pub fn percentile(values: &mut [f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(|a, b| a.total_cmp(b));
    let pos = q / 100.0 * (values.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    values[lo] + (values[hi] - values[lo]) * (pos - lo as f64)
}

/// Which joints the stitching features read, and how contacts and the root are defined.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StitchLayout {
    /// Lower-body joints (root-relative positions and velocities of the pose vector). Joint 0
    /// (the hips, the root joint) must be among them. Every other joint is "upper body".
    pub lower_body: Vec<usize>,
    /// Contact joints: left heel, left toe, right heel, right toe.
    pub contacts: [usize; 4],
    /// A contact joint is planted while its height is below `planted + threshold` (clip units).
    pub contact_thresholds: [f64; 4],
    /// Planted height of each contact joint (clip units; the 5th percentile of its height over
    /// the training clips, as the benchmark's skate measure defines it).
    pub planted: [f64; 4],
    /// Local axis of the hips whose ground projection is the character's forward direction
    /// (bandai2 and the synthetic skeleton: +Z).
    pub forward_axis: DVec3,
}

impl StitchLayout {
    /// The bandai2 layout (also the synthetic skeleton's), found by joint name. Planted heights
    /// start at bandai2's measured rest heights (ankle 11.7 cm, toes 4.3 cm); call
    /// [`StitchLayout::with_planted_heights`] to measure them on the training clips.
    pub fn bandai2(skeleton: &Skeleton) -> Result<StitchLayout, LayoutError> {
        let find = |name: &str, role: &'static str| {
            skeleton.index_of(name).ok_or_else(|| LayoutError::MissingJoint { joint: name.to_string(), role })
        };
        let lower_body =
            BANDAI2_LOWER_BODY.iter().map(|n| find(n, "a lower-body joint")).collect::<Result<Vec<_>, _>>()?;
        let mut contacts = [0; 4];
        for (c, n) in contacts.iter_mut().zip(BANDAI2_CONTACTS) {
            *c = find(n, "a contact joint")?;
        }
        let layout = StitchLayout {
            lower_body,
            contacts,
            contact_thresholds: CONTACT_THRESHOLDS,
            planted: [11.7, 4.3, 11.7, 4.3],
            forward_axis: DVec3::Z,
        };
        layout.validate(skeleton)?;
        Ok(layout)
    }

    /// Checks joint indices against `skeleton` and that the root joint is in the lower body.
    pub fn validate(&self, skeleton: &Skeleton) -> Result<(), LayoutError> {
        let joints = skeleton.len();
        for (&index, role) in
            self.lower_body.iter().map(|j| (j, "lower body")).chain(self.contacts.iter().map(|j| (j, "contact")))
        {
            if index >= joints {
                return Err(LayoutError::JointIndex { index, role, joints });
            }
        }
        if !self.lower_body.contains(&0) {
            return Err(LayoutError::Invalid("the lower body must contain joint 0 (the root joint, the hips)".into()));
        }
        if self.forward_axis.length_squared() < 1e-12 {
            return Err(LayoutError::Invalid("forward_axis must not be zero".into()));
        }
        Ok(())
    }

    /// Sets the planted heights to the 5th percentile of each contact joint's height over
    /// every frame of `global_positions` (one slice per clip, frame-major, `joints` per frame).
    pub fn with_planted_heights<'a>(
        mut self,
        global_positions: impl IntoIterator<Item = &'a [DVec3]>,
        joints: usize,
    ) -> StitchLayout {
        let mut heights: [Vec<f64>; 4] = Default::default();
        for gp in global_positions {
            for frame in gp.chunks_exact(joints) {
                for (h, &j) in heights.iter_mut().zip(&self.contacts) {
                    h.push(frame[j].y);
                }
            }
        }
        for (p, h) in self.planted.iter_mut().zip(heights.iter_mut()) {
            if !h.is_empty() {
                *p = percentile(h, 5.0);
            }
        }
        self
    }

    /// Joints that are not in the lower body, in index order.
    pub fn upper_body(&self, joints: usize) -> Vec<usize> {
        (0..joints).filter(|j| !self.lower_body.contains(j)).collect()
    }

    /// Whether `joint` belongs to the lower body.
    pub fn is_lower(&self, joint: usize) -> bool {
        self.lower_body.contains(&joint)
    }

    /// Contact labels of one frame of global positions: heel L, toe L, heel R, toe R.
    pub fn contacts_of(&self, frame: &[DVec3]) -> [bool; 4] {
        std::array::from_fn(|k| frame[self.contacts[k]].y < self.planted[k] + self.contact_thresholds[k])
    }

    /// The ground root of the hips' global transform (see [`GroundRoot`]).
    pub fn root_of(&self, hips_rotation: DQuat, hips_position: DVec3) -> GroundRoot {
        let f = ground_forward(hips_rotation, self.forward_axis);
        GroundRoot { pos: DVec3::new(hips_position.x, 0.0, hips_position.z), yaw: heading_angle(f) }
    }

    /// The offsets of the parts of the pose vector for a skeleton of `joints` joints.
    pub fn pose_layout(&self, joints: usize) -> PoseLayout {
        PoseLayout::new(joints, self.lower_body.len())
    }
}

/// The character's root on the ground: the hips projected on the floor (y = 0) and the
/// heading about +Y (radians; 0 faces +Z, positive turns towards +X). As a transform it maps
/// root-local coordinates to world: `p_world = pos + yaw_rotation * p_local`.
#[derive(Clone, Copy, Debug, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct GroundRoot {
    /// Position on the ground (y = 0).
    pub pos: DVec3,
    /// Heading, radians about +Y.
    pub yaw: f64,
}

impl GroundRoot {
    /// The identity root (origin, facing +Z).
    pub const IDENTITY: GroundRoot = GroundRoot { pos: DVec3::ZERO, yaw: 0.0 };

    /// The rotation about +Y.
    pub fn rotation(&self) -> DQuat {
        DQuat::from_rotation_y(self.yaw)
    }

    /// The forward direction on the ground, `(sin yaw, 0, cos yaw)`.
    pub fn forward(&self) -> DVec3 {
        DVec3::new(self.yaw.sin(), 0.0, self.yaw.cos())
    }

    /// `self ∘ other`: `other` is expressed in `self`'s frame.
    pub fn compose(&self, other: &GroundRoot) -> GroundRoot {
        GroundRoot { pos: self.pos + self.rotation() * other.pos, yaw: self.yaw + other.yaw }
    }

    /// The inverse transform.
    pub fn inverse(&self) -> GroundRoot {
        let inv = DQuat::from_rotation_y(-self.yaw);
        GroundRoot { pos: -(inv * self.pos), yaw: -self.yaw }
    }

    /// A world point in root-local coordinates.
    pub fn to_local(&self, p: DVec3) -> DVec3 {
        DQuat::from_rotation_y(-self.yaw) * (p - self.pos)
    }

    /// A root-local point in world coordinates.
    pub fn to_world(&self, p: DVec3) -> DVec3 {
        self.pos + self.rotation() * p
    }

    /// Moves a global transform (rotation, position) by this root: `self ∘ (r, p)`.
    pub fn apply(&self, r: DQuat, p: DVec3) -> (DQuat, DVec3) {
        (self.rotation() * r, self.to_world(p))
    }
}

/// The ground root of every frame of a clip (joint 0 is the hips).
pub fn ground_roots(clip: &Clip, layout: &StitchLayout) -> Vec<GroundRoot> {
    let j = clip.joints();
    (0..clip.frames()).map(|f| layout.root_of(clip.local_rotations[f * j], clip.local_positions[f * j])).collect()
}

/// Offsets of the parts of the pose vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoseLayout {
    /// Joints J.
    pub joints: usize,
    /// Lower-body joints J_lower.
    pub lower: usize,
}

impl PoseLayout {
    /// The layout for `joints` joints of which `lower` are lower body.
    pub fn new(joints: usize, lower: usize) -> Self {
        PoseLayout { joints, lower }
    }

    /// Values per frame: `3 + 3 J_lower + 4 J + 3 J_lower + 4`.
    pub fn dim(&self) -> usize {
        7 + 6 * self.lower + 4 * self.joints
    }

    /// Start of `p_t`.
    pub fn positions(&self) -> usize {
        3
    }

    /// Start of `q_t`.
    pub fn rotations(&self) -> usize {
        3 + 3 * self.lower
    }

    /// Start of `v_t`.
    pub fn velocities(&self) -> usize {
        self.rotations() + 4 * self.joints
    }

    /// Start of `c_t` (= number of pose values `r, p, q, v`).
    pub fn contacts(&self) -> usize {
        self.velocities() + 3 * self.lower
    }
}

fn wrap(a: f64) -> f64 {
    let a = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if a == -std::f64::consts::PI { std::f64::consts::PI } else { a }
}

/// One frame as the encoder reads it: its ground root, the global positions of every joint and
/// the local rotations. Reusable: [`PoseFrame::set`] refills it without allocating.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PoseFrame {
    /// Ground root of the frame.
    pub root: GroundRoot,
    /// Global position of every joint.
    pub global_positions: Vec<DVec3>,
    /// Local rotation of every joint (joint 0's is the hips' global rotation).
    pub local_rotations: Vec<DQuat>,
    global_rotations: Vec<DQuat>,
    local_positions: Vec<DVec3>,
}

impl PoseFrame {
    /// The frame of a pose on `skeleton`: the hips' position `root_position` and the local
    /// rotation of every joint (`rotations.len() == skeleton.len()`; the caller checks); the
    /// other joints sit at the skeleton's offsets.
    pub fn set(&mut self, skeleton: &Skeleton, layout: &StitchLayout, rotations: &[DQuat], root_position: DVec3) {
        self.local_positions.clear();
        self.local_positions.extend_from_slice(&skeleton.offsets);
        self.local_positions[0] = root_position;
        self.run_fk(&skeleton.parents, layout, rotations);
    }

    /// The frame of a clip (its own local positions, which may differ from the offsets).
    pub fn set_from_clip(&mut self, clip: &Clip, layout: &StitchLayout, frame: usize) {
        self.local_positions.clear();
        self.local_positions.extend_from_slice(clip.positions_at(frame));
        self.run_fk(&clip.skeleton.parents, layout, clip.rotations_at(frame));
    }

    fn run_fk(&mut self, parents: &[Option<usize>], layout: &StitchLayout, rotations: &[DQuat]) {
        let j = parents.len();
        self.local_rotations.clear();
        self.local_rotations.extend_from_slice(&rotations[..j]);
        self.global_rotations.resize(j, DQuat::IDENTITY);
        self.global_positions.resize(j, DVec3::ZERO);
        forward_kinematics_frame(
            parents,
            &self.local_rotations,
            &self.local_positions,
            &mut self.global_rotations,
            &mut self.global_positions,
        );
        self.root = layout.root_of(rotations[0], self.local_positions[0]);
    }
}

/// Writes the pose vector of `cur` into `out` (`dim` values): `r` and `v` are the motion from
/// `from` to `to` (the previous frame and `cur`, or frames 0 and 1 for the first frame), the
/// quaternions are put in the hemisphere of `continuity` (the previous frame's encoded
/// quaternions, `None` for the first frame: `w >= 0`), and `continuity` is updated to this
/// frame's.
pub fn encode_pose(
    layout: &StitchLayout,
    cur: &PoseFrame,
    from: &PoseFrame,
    to: &PoseFrame,
    continuity: &mut Option<Vec<DQuat>>,
    out: &mut [f32],
) {
    let j = cur.local_rotations.len();
    let fl = layout.pose_layout(j);
    let disp = from.root.inverse().compose(&to.root);
    out[..3].copy_from_slice(&[disp.pos.x as f32, wrap(disp.yaw) as f32, disp.pos.z as f32]);
    let from_rot = from.root.rotation().inverse();
    for (k, &jl) in layout.lower_body.iter().enumerate() {
        let p = cur.root.to_local(cur.global_positions[jl]);
        out[fl.positions() + 3 * k..][..3].copy_from_slice(&[p.x as f32, p.y as f32, p.z as f32]);
        let v = from_rot * (to.global_positions[jl] - from.global_positions[jl]);
        out[fl.velocities() + 3 * k..][..3].copy_from_slice(&[v.x as f32, v.y as f32, v.z as f32]);
    }
    let reference = continuity.get_or_insert_with(|| vec![DQuat::IDENTITY; j]);
    reference.resize(j, DQuat::IDENTITY);
    for (k, r) in reference.iter_mut().enumerate() {
        let mut q = cur.local_rotations[k];
        if k == 0 {
            q = cur.root.rotation().inverse() * q;
        }
        if q.dot(*r) < 0.0 {
            q = -q;
        }
        *r = q;
        out[fl.rotations() + 4 * k..][..4].copy_from_slice(&[q.x as f32, q.y as f32, q.z as f32, q.w as f32]);
    }
    let c = layout.contacts_of(&cur.global_positions);
    for k in 0..4 {
        out[fl.contacts() + k] = if c[k] { 1.0 } else { 0.0 };
    }
}

/// Encodes every frame of `clip` (at least 2 frames) into pose vectors (`frames * dim`).
pub fn encode_clip(clip: &Clip, layout: &StitchLayout) -> Result<Vec<f32>, LayoutError> {
    let (frames, j) = (clip.frames(), clip.joints());
    if frames < 2 {
        return Err(LayoutError::Invalid(format!("a sequence needs at least 2 frames to encode, found {frames}")));
    }
    layout.validate(&clip.skeleton)?;
    let d = layout.pose_layout(j).dim();
    let poses: Vec<PoseFrame> = (0..frames)
        .map(|f| {
            let mut p = PoseFrame::default();
            p.set_from_clip(clip, layout, f);
            p
        })
        .collect();
    let mut out = vec![0.0f32; frames * d];
    encode_frames(layout, &poses, &mut out);
    Ok(out)
}

/// Encodes consecutive frames (at least 2) into `out` (`frames.len() * dim` values, the caller
/// checks): frame 0 takes frame 1's root motion and velocities.
pub fn encode_frames(layout: &StitchLayout, frames: &[PoseFrame], out: &mut [f32]) {
    let d = out.len() / frames.len().max(1);
    let mut continuity = None;
    for (f, x) in out.chunks_exact_mut(d).enumerate() {
        let (a, b) = if f == 0 { (0, 1) } else { (f - 1, f) };
        encode_pose(layout, &frames[f], &frames[a], &frames[b], &mut continuity, x);
    }
}

/// The ground root of a pose vector's frame: `prev` moved by its `r_t` (RMR sec. 5.1:
/// "accumulating the predicted root displacement").
pub fn next_root(prev: &GroundRoot, x: &[f32]) -> GroundRoot {
    prev.compose(&GroundRoot { pos: DVec3::new(x[0] as f64, 0.0, x[2] as f64), yaw: x[1] as f64 })
}

/// Ground roots of a sequence of pose vectors: frame 0 is `start`, frame `t` is frame `t - 1`'s
/// root moved by `r_t`.
pub fn accumulate_roots(features: &[f32], dim: usize, start: GroundRoot) -> Vec<GroundRoot> {
    let mut roots = Vec::with_capacity(features.len() / dim);
    let mut root = start;
    for (f, x) in features.chunks_exact(dim).enumerate() {
        if f > 0 {
            root = next_root(&root, x);
        }
        roots.push(root);
    }
    roots
}

/// Global positions of the ankles (the heel joints `layout.contacts[0]` and `[2]`) that raw pose
/// vectors predict: their lower-body positions `p` placed in the ground roots accumulated from
/// `start`. Empty when a heel joint is not in the lower body.
pub fn predicted_ankles(features: &[f32], fl: PoseLayout, layout: &StitchLayout, start: GroundRoot) -> Vec<[DVec3; 2]> {
    let slot = |joint: usize| layout.lower_body.iter().position(|&k| k == joint);
    let (Some(l), Some(r)) = (slot(layout.contacts[0]), slot(layout.contacts[2])) else { return Vec::new() };
    let d = fl.dim();
    let roots = accumulate_roots(features, d, start);
    features
        .chunks_exact(d)
        .zip(&roots)
        .map(|(x, root)| {
            let p = |k: usize| {
                let v = &x[fl.positions() + 3 * k..][..3];
                root.to_world(DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
            };
            [p(l), p(r)]
        })
        .collect()
}

/// Decodes one pose vector whose frame has the ground root `root` into the local rotation of
/// every joint (`rotations`, `J` values, normalised; joint 0's is the hips' global rotation)
/// and returns the hips' global position and the contacts (`c > 0.5`).
pub fn decode_pose(layout: &StitchLayout, x: &[f32], root: &GroundRoot, rotations: &mut [DQuat]) -> (DVec3, [bool; 4]) {
    let fl = layout.pose_layout(rotations.len());
    let hips_slot = layout.lower_body.iter().position(|&k| k == 0).unwrap_or(0);
    let mut hips = DVec3::ZERO;
    for (k, r) in rotations.iter_mut().enumerate() {
        let q = &x[fl.rotations() + 4 * k..][..4];
        let q = DQuat::from_xyzw(q[0] as f64, q[1] as f64, q[2] as f64, q[3] as f64);
        let q = if q.length_squared() > 1e-12 { q.normalize() } else { DQuat::IDENTITY };
        *r = q;
        if k == 0 {
            let p = &x[fl.positions() + 3 * hips_slot..][..3];
            let (g, p) = root.apply(q, DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            *r = g;
            hips = p;
        }
    }
    (hips, std::array::from_fn(|k| x[fl.contacts() + k] > 0.5))
}

/// Decodes pose vectors into a clip on `skeleton` (frame 0's ground root is `start`; non-root
/// joints take the skeleton's offsets; quaternions are normalised) and the contacts
/// (`c > 0.5`; pass probabilities, e.g. the sigmoid of the model's contact outputs).
pub fn decode(
    features: &[f32],
    skeleton: &Skeleton,
    layout: &StitchLayout,
    frame_time: f64,
    start: GroundRoot,
) -> Result<(Clip, Vec<[bool; 4]>), LayoutError> {
    let j = skeleton.len();
    let d = layout.pose_layout(j).dim();
    if features.is_empty() || !features.len().is_multiple_of(d) {
        return Err(LayoutError::Invalid(format!(
            "{} pose-vector values are not a whole number of frames of {d} = 7 + 6 x {} lower-body joints + 4 x {j} \
             joints",
            features.len(),
            layout.lower_body.len()
        )));
    }
    layout.validate(skeleton)?;
    let frames = features.len() / d;
    let mut clip = Clip {
        skeleton: skeleton.clone(),
        frame_time,
        local_rotations: vec![DQuat::IDENTITY; frames * j],
        local_positions: Vec::with_capacity(frames * j),
    };
    let mut contacts = Vec::with_capacity(frames);
    let mut root = start;
    for (f, x) in features.chunks_exact(d).enumerate() {
        if f > 0 {
            root = next_root(&root, x);
        }
        let (hips, c) = decode_pose(layout, x, &root, &mut clip.local_rotations[f * j..(f + 1) * j]);
        clip.local_positions.push(hips);
        clip.local_positions.extend_from_slice(&skeleton.offsets[1..]);
        contacts.push(c);
    }
    Ok((clip, contacts))
}
