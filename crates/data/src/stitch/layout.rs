//! The joints RMR reads (lower body, feet), the ground root and foot contacts (RMR sec. 4).

use super::StitchError;
use glam::{DQuat, DVec3};
use zoo_motion::facing::{ground_forward, heading_angle};
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
    pub fn bandai2(skeleton: &Skeleton) -> Result<StitchLayout, StitchError> {
        let find = |name: &str, role: &'static str| {
            skeleton.index_of(name).ok_or_else(|| StitchError::MissingJoint { joint: name.to_string(), role })
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
    pub fn validate(&self, skeleton: &Skeleton) -> Result<(), StitchError> {
        let joints = skeleton.len();
        for (&index, role) in
            self.lower_body.iter().map(|j| (j, "lower body")).chain(self.contacts.iter().map(|j| (j, "contact")))
        {
            if index >= joints {
                return Err(StitchError::JointIndex { index, role, joints });
            }
        }
        if !self.lower_body.contains(&0) {
            return Err(StitchError::Config("the lower body must contain joint 0 (the root joint, the hips)".into()));
        }
        if self.forward_axis.length_squared() < 1e-12 {
            return Err(StitchError::Config("forward_axis must not be zero".into()));
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
                *p = crate::dataset::percentile(h, 5.0);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_algebra_round_trips() {
        let a = GroundRoot { pos: DVec3::new(3.0, 0.0, -2.0), yaw: 0.7 };
        let b = GroundRoot { pos: DVec3::new(-1.0, 0.0, 5.0), yaw: -2.1 };
        let p = DVec3::new(0.3, 1.5, -0.8);
        assert!((a.compose(&b).to_world(p) - a.to_world(b.to_world(p))).length() < 1e-12);
        let id = a.compose(&a.inverse());
        assert!(id.pos.length() < 1e-12 && id.yaw.abs() < 1e-12);
        assert!((a.to_local(a.to_world(p)) - p).length() < 1e-12);
        assert!((a.rotation() * DVec3::Z - a.forward()).length() < 1e-12);
    }

    #[test]
    fn root_of_hips_projects_and_takes_the_heading() {
        let skeleton = crate::synth::skeleton();
        let layout = StitchLayout::bandai2(&skeleton).unwrap();
        // Synthetic rest frame of the hips (local X up, local Z forward), turned by 0.4 rad.
        let hips = DQuat::from_rotation_y(0.4) * DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let r = layout.root_of(hips, DVec3::new(1.0, 90.0, 2.0));
        assert_eq!(r.pos, DVec3::new(1.0, 0.0, 2.0));
        assert!((r.yaw - 0.4).abs() < 1e-12, "{}", r.yaw);
    }

    #[test]
    fn bandai2_layout_names_and_bad_rigs() {
        let mut skeleton = crate::synth::skeleton();
        let layout = StitchLayout::bandai2(&skeleton).unwrap();
        assert_eq!(layout.lower_body.len(), 9);
        assert_eq!(layout.upper_body(21).len(), 12);
        assert_eq!(layout.contacts, [15, 16, 19, 20]);
        skeleton.names[16] = "LeftToeBase".into();
        let err = StitchLayout::bandai2(&skeleton).unwrap_err().to_string();
        assert!(err.contains("Toes_L"), "{err}");
        let bad = StitchLayout { lower_body: vec![1, 2], ..layout.clone() };
        assert!(bad.validate(&crate::synth::skeleton()).unwrap_err().to_string().contains("joint 0"));
        let bad = StitchLayout { contacts: [15, 16, 19, 40], ..layout };
        assert!(bad.validate(&crate::synth::skeleton()).unwrap_err().to_string().contains("40"));
    }

    #[test]
    fn contacts_use_each_joints_threshold() {
        let layout = StitchLayout::bandai2(&crate::synth::skeleton()).unwrap();
        let mut frame = vec![DVec3::ZERO; 21];
        frame[15].y = 11.7 + 2.4; // heel below 2.5
        frame[16].y = 4.3 + 1.7; // toe above 1.6
        frame[19].y = 11.7 + 2.6;
        frame[20].y = 4.3 + 1.5;
        assert_eq!(layout.contacts_of(&frame), [true, false, false, true]);
    }
}
