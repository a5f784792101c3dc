//! The planar articulated lamp of ARNN section 4.2, simulated with rapier2d.
//!
//! Four links in a chain, base -> leg -> neck -> head, joined by three revolute joints. Six
//! degrees of freedom: the base's x and y (metres, its centre) and angle, and the three joint
//! angles (radians, counter-clockwise positive, 0 when the child link points along its
//! parent's local +y). With every angle 0 the lamp is a vertical stick standing on its base;
//! the lamp faces +x, so it hops forward along +x.
//!
//! Each joint is driven by a PD controller `tau = kp (theta_d - theta) - kd omega` (section
//! 4.2): a rapier joint motor in [`MotorModel::ForceBased`] mode with stiffness `kp` and
//! damping `kd`, which rapier integrates implicitly (stable at any gain) and clamps at
//! `max_torque`. The ground is a fixed half-plane `y <= 0` with Coulomb friction; the lamp's
//! links collide with the ground, not with each other.

use rapier2d::prelude::*;
use serde::{Deserialize, Serialize};

/// Names of the six degrees of freedom, in [`LampPose`] order.
pub const DOF_NAMES: [&str; 6] = ["base_x", "base_y", "base_angle", "theta1", "theta2", "theta3"];

/// Number of degrees of freedom of the lamp.
pub const DOFS: usize = 6;

/// A pose of the lamp: base x, base y (metres, the base's centre), base angle, and the three
/// joint angles base-leg, leg-neck, neck-head (radians).
pub type LampPose = [f64; DOFS];

/// The largest length of a lamp part, metres.
pub const MAX_LENGTH: f64 = 10.0;
/// The largest mass of a lamp part, kilograms.
pub const MAX_MASS: f64 = 1000.0;
/// The largest PD gain or torque limit (N m/rad, N m s/rad, N m).
pub const MAX_GAIN: f64 = 1e6;
/// The largest friction coefficient.
pub const MAX_FRICTION: f64 = 100.0;
/// The largest gravity, m/s^2 either way.
pub const MAX_GRAVITY: f64 = 1000.0;
/// The finest integration step, seconds (100 kHz; the default is 1/480 s).
pub const MIN_DT: f64 = 1e-5;
/// The coarsest integration step the hop controller works with, seconds.
pub const MAX_DT: f64 = 0.01;
/// The most solver iterations per step.
pub const MAX_SOLVER_ITERATIONS: usize = 100;

/// Geometry, masses, controller gains and simulation settings of the lamp.
///
/// Lengths in metres, masses in kilograms, gains in N m/rad and N m s/rad. The defaults
/// ([`LampParams::default`]) are a desk lamp about 55 cm tall and 1.8 kg; `docs/arnn.md` says
/// why each number was chosen. In JSON, a missing field takes its default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LampParams {
    /// Half the width of the base plate.
    pub base_half_width: f64,
    /// Half the height of the base plate.
    pub base_half_height: f64,
    /// Mass of the base.
    pub base_mass: f64,
    /// Length of the leg (joint 1 to joint 2).
    pub leg_length: f64,
    /// Length of the neck (joint 2 to joint 3).
    pub neck_length: f64,
    /// Radius of the leg and neck capsules.
    pub link_radius: f64,
    /// Mass of the leg.
    pub leg_mass: f64,
    /// Mass of the neck.
    pub neck_mass: f64,
    /// Length of the head (the lamp shade) along its axis.
    pub head_length: f64,
    /// Half the width of the head.
    pub head_half_width: f64,
    /// Mass of the head.
    pub head_mass: f64,
    /// PD stiffness of joints 1, 2, 3.
    pub kp: [f64; 3],
    /// PD damping of joints 1, 2, 3.
    pub kd: [f64; 3],
    /// Torque limit of joints 1, 2, 3.
    pub max_torque: [f64; 3],
    /// Joint angle limits `[lower, upper]` of joints 1, 2, 3 (radians).
    pub joint_limits: [[f64; 2]; 3],
    /// Friction coefficient of the ground and of the lamp's links.
    pub friction: f64,
    /// Gravity (m/s^2, pointing down).
    pub gravity: f64,
    /// Integration step in seconds.
    pub dt: f64,
    /// Solver iterations (rapier substeps) per step.
    pub solver_iterations: usize,
    /// A link closer to the ground than this touches it (metres).
    pub contact_tolerance: f64,
}

impl Default for LampParams {
    fn default() -> Self {
        LampParams {
            base_half_width: 0.13,
            base_half_height: 0.02,
            base_mass: 1.0,
            leg_length: 0.22,
            neck_length: 0.22,
            link_radius: 0.015,
            leg_mass: 0.25,
            neck_mass: 0.25,
            head_length: 0.12,
            head_half_width: 0.05,
            head_mass: 0.3,
            kp: [30.0, 20.0, 5.0],
            kd: [3.0, 2.0, 0.4],
            max_torque: [10.0, 7.5, 2.5],
            joint_limits: [[-1.6, 1.6], [-2.7, 2.7], [-2.7, 2.7]],
            friction: 0.9,
            gravity: 9.81,
            dt: 1.0 / 480.0,
            solver_iterations: 2,
            contact_tolerance: 0.003,
        }
    }
}

impl LampParams {
    /// Checks that every length, mass, gain and setting is finite and in range: lengths in
    /// (0, [`MAX_LENGTH`]] m, masses in (0, [`MAX_MASS`]] kg, gains and torques in
    /// [0, [`MAX_GAIN`]], joint limits within +-2 pi, friction in [0, [`MAX_FRICTION`]],
    /// gravity within +-[`MAX_GRAVITY`] m/s^2, `dt` in [[`MIN_DT`], [`MAX_DT`]] s, solver
    /// iterations in 1..=[`MAX_SOLVER_ITERATIONS`], the contact tolerance in (0, 1] m. Each
    /// message names the parameter, the value and the range.
    pub fn validate(&self) -> Result<(), String> {
        let lengths = [
            ("base_half_width", self.base_half_width),
            ("base_half_height", self.base_half_height),
            ("leg_length", self.leg_length),
            ("neck_length", self.neck_length),
            ("link_radius", self.link_radius),
            ("head_length", self.head_length),
            ("head_half_width", self.head_half_width),
        ];
        for (name, v) in lengths {
            if !(v.is_finite() && v > 0.0 && v <= MAX_LENGTH) {
                return Err(format!("lamp parameter {name} is {v:?} m: give a length in (0, {MAX_LENGTH}] metres"));
            }
        }
        let masses = [
            ("base_mass", self.base_mass),
            ("leg_mass", self.leg_mass),
            ("neck_mass", self.neck_mass),
            ("head_mass", self.head_mass),
        ];
        for (name, v) in masses {
            if !(v.is_finite() && v > 0.0 && v <= MAX_MASS) {
                return Err(format!("lamp parameter {name} is {v:?} kg: give a mass in (0, {MAX_MASS}] kg"));
            }
        }
        for j in 0..3 {
            for (name, v) in [("kp", self.kp[j]), ("kd", self.kd[j]), ("max_torque", self.max_torque[j])] {
                if !(v.is_finite() && (0.0..=MAX_GAIN).contains(&v)) {
                    return Err(format!("lamp parameter {name}[{j}] is {v:?}: give a number in [0, {MAX_GAIN}]"));
                }
            }
            let [lo, hi] = self.joint_limits[j];
            let tau = std::f64::consts::TAU;
            if !(lo.is_finite() && hi.is_finite() && lo < hi && lo >= -tau && hi <= tau) {
                return Err(format!(
                    "joint_limits[{j}] is [{lo:?}, {hi:?}]: give finite angles with lower < upper, within [-2 pi, 2 pi] \
                     radians"
                ));
            }
        }
        if 2.0 * self.link_radius >= self.leg_length.min(self.neck_length) {
            return Err("link_radius must be less than half the leg and neck lengths".into());
        }
        if !(self.friction.is_finite() && (0.0..=MAX_FRICTION).contains(&self.friction)) {
            return Err(format!(
                "lamp parameter friction is {:?}: give a coefficient in [0, {MAX_FRICTION}]",
                self.friction
            ));
        }
        if !(self.gravity.is_finite() && self.gravity.abs() <= MAX_GRAVITY) {
            return Err(format!(
                "lamp parameter gravity is {:?} m/s^2: give a number in [-{MAX_GRAVITY}, {MAX_GRAVITY}]",
                self.gravity
            ));
        }
        if !(self.dt.is_finite() && self.dt >= MIN_DT) {
            return Err(format!(
                "lamp parameter dt is {:?} s: give an integration step in [{MIN_DT}, {MAX_DT}] seconds (the default is \
                 1/480 s)",
                self.dt
            ));
        }
        if self.dt > MAX_DT {
            return Err(format!(
                "dt {:?} s is too coarse for the hop controller: give an integration step in [{MIN_DT}, {MAX_DT}] \
                 seconds",
                self.dt
            ));
        }
        if !(1..=MAX_SOLVER_ITERATIONS).contains(&self.solver_iterations) {
            return Err(format!(
                "lamp parameter solver_iterations is {}: give a whole number in 1..={MAX_SOLVER_ITERATIONS}",
                self.solver_iterations
            ));
        }
        if !(self.contact_tolerance.is_finite() && self.contact_tolerance > 0.0 && self.contact_tolerance <= 1.0) {
            return Err(format!(
                "lamp parameter contact_tolerance is {:?} m: give a distance in (0, 1] metres",
                self.contact_tolerance
            ));
        }
        Ok(())
    }

    /// Offset of each joint from its parent's joint with every angle 0 (metres, +y up):
    /// base (0), leg (on top of the base), neck, head; and the head's tip.
    pub fn joint_offsets(&self) -> ([f64; 4], f64) {
        ([0.0, self.base_half_height, self.leg_length, self.neck_length], self.head_length)
    }

    /// Total mass of the lamp.
    pub fn total_mass(&self) -> f64 {
        self.base_mass + self.leg_mass + self.neck_mass + self.head_mass
    }

    /// The base's height when it lies flat on the ground.
    pub fn rest_height(&self) -> f64 {
        self.base_half_height
    }
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let w = a - t * (a / t).round();
    if w <= -std::f64::consts::PI { w + t } else { w }
}

/// Pose of every link (x, y, angle) from the six degrees of freedom: base, leg, neck, head,
/// each at its joint (the base at its centre). Forward kinematics of the chain.
pub fn link_frames(params: &LampParams, pose: &LampPose) -> [[f64; 3]; 4] {
    let mut frames = [[0.0; 3]; 4];
    frames[0] = [pose[0], pose[1], pose[2]];
    let (offsets, _) = params.joint_offsets();
    for k in 1..4 {
        let [px, py, pa] = frames[k - 1];
        let (s, c) = pa.sin_cos();
        // The parent's local +y axis rotated by its angle is (-sin, cos).
        frames[k] = [px - s * offsets[k], py + c * offsets[k], pa + pose[2 + k]];
    }
    frames
}

/// The lamp in a rapier2d world.
pub struct Lamp {
    world: PhysicsWorld,
    params: LampParams,
    links: [RigidBodyHandle; 4],
    colliders: [ColliderHandle; 4],
    joints: [ImpulseJointHandle; 3],
    /// Base angle, unwrapped across steps (the lamp may turn more than half a turn).
    base_angle: f64,
    time: f64,
}

impl Lamp {
    /// A lamp standing on the ground at x = 0 with its base flat and the given joint angles,
    /// at rest, each joint's PD target set to its current angle.
    pub fn new(params: &LampParams, joint_angles: [f64; 3]) -> Result<Lamp, String> {
        params.validate()?;
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::new(0.0, -params.gravity as f32);
        world.integration_parameters.dt = params.dt as f32;
        world.integration_parameters.num_solver_iterations = params.solver_iterations;

        let ground_groups = InteractionGroups::new(Group::GROUP_1, Group::GROUP_2, InteractionTestMode::And);
        let lamp_groups = InteractionGroups::new(Group::GROUP_2, Group::GROUP_1, InteractionTestMode::And);
        let ground = world.bodies.insert(RigidBodyBuilder::fixed().translation(Vector::new(0.0, -1.0)));
        world.colliders.insert_with_parent(
            ColliderBuilder::cuboid(10_000.0, 1.0).friction(params.friction as f32).collision_groups(ground_groups),
            ground,
            &mut world.bodies,
        );

        let pose = [0.0, params.rest_height(), 0.0, joint_angles[0], joint_angles[1], joint_angles[2]];
        let frames = link_frames(params, &pose);
        let f = |v: f64| v as f32;
        let r = params.link_radius;
        let shapes = [
            ColliderBuilder::cuboid(f(params.base_half_width), f(params.base_half_height)).mass(f(params.base_mass)),
            ColliderBuilder::capsule_y(f(params.leg_length / 2.0 - r), f(r))
                .translation(Vector::new(0.0, f(params.leg_length / 2.0)))
                .mass(f(params.leg_mass)),
            ColliderBuilder::capsule_y(f(params.neck_length / 2.0 - r), f(r))
                .translation(Vector::new(0.0, f(params.neck_length / 2.0)))
                .mass(f(params.neck_mass)),
            ColliderBuilder::cuboid(f(params.head_half_width), f(params.head_length / 2.0))
                .translation(Vector::new(0.0, f(params.head_length / 2.0)))
                .mass(f(params.head_mass)),
        ];
        let mut links = [RigidBodyHandle::invalid(); 4];
        let mut colliders = [ColliderHandle::invalid(); 4];
        for (k, shape) in shapes.into_iter().enumerate() {
            let [x, y, a] = frames[k];
            let body = RigidBodyBuilder::dynamic().translation(Vector::new(f(x), f(y))).rotation(f(a)).can_sleep(false);
            links[k] = world.bodies.insert(body);
            colliders[k] = world.colliders.insert_with_parent(
                shape.friction(f(params.friction)).restitution(0.0).collision_groups(lamp_groups),
                links[k],
                &mut world.bodies,
            );
        }
        let (offsets, _) = params.joint_offsets();
        let mut joints = [ImpulseJointHandle::invalid(); 3];
        for j in 0..3 {
            let joint = RevoluteJointBuilder::new()
                .local_anchor1(Vector::new(0.0, f(offsets[j + 1])))
                .local_anchor2(Vector::new(0.0, 0.0))
                .contacts_enabled(false)
                .limits([f(params.joint_limits[j][0]), f(params.joint_limits[j][1])])
                .motor_model(MotorModel::ForceBased)
                .motor_position(f(joint_angles[j]), f(params.kp[j]), f(params.kd[j]))
                .motor_max_force(f(params.max_torque[j]));
            joints[j] = world.impulse_joints.insert(links[j], links[j + 1], joint, true);
        }
        Ok(Lamp { world, params: params.clone(), links, colliders, joints, base_angle: 0.0, time: 0.0 })
    }

    /// The lamp's parameters.
    pub fn params(&self) -> &LampParams {
        &self.params
    }

    /// Seconds simulated so far.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Sets the PD targets of the three joints (radians, clamped to the joint limits).
    pub fn set_targets(&mut self, targets: [f64; 3]) {
        for j in 0..3 {
            let [lo, hi] = self.params.joint_limits[j];
            let t = targets[j].clamp(lo, hi) as f32;
            let (kp, kd) = (self.params.kp[j] as f32, self.params.kd[j] as f32);
            if let Some(joint) = self.world.impulse_joints.get_mut(self.joints[j], true) {
                joint.data.set_motor_position(JointAxis::AngX, t, kp, kd);
            }
        }
    }

    /// Advances the simulation by one step of [`LampParams::dt`].
    pub fn step(&mut self) {
        let before = self.body_angle(0);
        self.world.step();
        let after = self.body_angle(0);
        self.base_angle += wrap_angle(after - before);
        self.time += self.params.dt;
    }

    fn body_angle(&self, k: usize) -> f64 {
        self.world.bodies.get(self.links[k]).map_or(0.0, |b| b.rotation().angle() as f64)
    }

    /// The six degrees of freedom now (the base angle unwrapped since the start).
    pub fn pose(&self) -> LampPose {
        let base = self.world.bodies.get(self.links[0]).map_or(Vector::ZERO, |b| b.translation());
        let a: [f64; 4] = std::array::from_fn(|k| self.body_angle(k));
        [
            base.x as f64,
            base.y as f64,
            self.base_angle,
            wrap_angle(a[1] - a[0]),
            wrap_angle(a[2] - a[1]),
            wrap_angle(a[3] - a[2]),
        ]
    }

    /// Lowest point of link `k` (0 base, 1 leg, 2 neck, 3 head) above the ground (metres).
    pub fn link_clearance(&self, k: usize) -> f64 {
        self.world.colliders.get(self.colliders[k]).map_or(f64::INFINITY, |c| c.compute_aabb().mins.y as f64)
    }

    /// Lowest point of the whole lamp above the ground (metres; negative when it sinks in).
    pub fn clearance(&self) -> f64 {
        (0..4).map(|k| self.link_clearance(k)).fold(f64::INFINITY, f64::min)
    }

    /// True when some link is within [`LampParams::contact_tolerance`] of the ground.
    pub fn touches_ground(&self) -> bool {
        self.clearance() <= self.params.contact_tolerance
    }

    /// True when the lamp has fallen: a link other than the base touches the ground, or the
    /// base is tilted by more than 60 degrees.
    pub fn has_fallen(&self) -> bool {
        (1..4).any(|k| self.link_clearance(k) <= self.params.contact_tolerance)
            || self.base_angle.abs() > 60f64.to_radians()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_frames_stack_the_links() {
        let p = LampParams::default();
        let f = link_frames(&p, &[1.0, 0.02, 0.0, 0.0, 0.0, 0.0]);
        assert!((f[3][1] - (0.02 + p.base_half_height + p.leg_length + p.neck_length)).abs() < 1e-12);
        let f = link_frames(&p, &[0.0, 0.0, 0.0, -std::f64::consts::FRAC_PI_2, 0.0, 0.0]);
        // The leg turned clockwise by 90 degrees points along +x.
        assert!((f[2][0] - p.leg_length).abs() < 1e-12);
    }

    #[test]
    fn wrap_angle_stays_in_range() {
        for a in [-7.0, -3.2, 0.0, 3.2, 7.0, std::f64::consts::PI] {
            let w = wrap_angle(a);
            assert!(w > -std::f64::consts::PI && w <= std::f64::consts::PI, "{a} -> {w}");
            assert!(((a - w) / std::f64::consts::TAU - ((a - w) / std::f64::consts::TAU).round()).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_parameters_are_named() {
        let p = LampParams { leg_mass: -1.0, ..LampParams::default() };
        assert!(p.validate().unwrap_err().contains("leg_mass"));
        let p = LampParams { dt: 0.05, ..LampParams::default() };
        assert!(p.validate().unwrap_err().contains("dt"));
    }
}
