//! Procedural biped locomotion over terrain, deterministic by seed.
//!
//! The skeleton is bandai2's after dropping its dummy root (21 joints, `Hips` root, cm, Y up,
//! rest bones along local X, the offsets of `dataset-2_walk_normal_001.bvh`), so every
//! pipeline runs unchanged on synthetic or real data. Local axes follow bandai2's conventions
//! (Hips: X up, Y right, Z forward; spine: X up, Y forward; legs: Y to the character's left).
//!
//! Each clip is built by one function per stage, in this order: a root trajectory
//! ([`trajectory`]: speed, turn rate and strafe targets per segment, smoothed), terrain around
//! it ([`terrain`]), a phase-driven leg cycle ([`cycle`]), the feet ([`feet`]: stance / swing
//! per foot, foot plants computed ahead of time so that planted feet stay fixed in the world),
//! the pelvis ([`pelvis`]: height from the ground and the legs' reach), then the pose
//! ([`pose`]): two-bone leg IK, pelvis bob / sway / twist, spine and head counter-rotation,
//! arm swing opposite the legs. The
//! random numbers come from [`SplitMix64`], one stream per clip, so the same seed gives the
//! same clips on every platform and thread count.
//!
//! Ground-truth foot contacts come with every clip: a foot is in contact while its stance
//! lasts (toes planted; the heel lifts at the end of stance).

mod cycle;
mod feet;
mod geometry;
mod pelvis;
mod pose;
mod skeleton;
mod terrain;
mod trajectory;
mod write;

pub use geometry::{look_rotation, two_bone_ik};
pub use skeleton::{
    ANKLE_HEIGHT, FOOT_JOINTS, JOINT_NAMES, JOINT_OFFSETS, JOINT_PARENTS, TOE_HEIGHT, check_mixable, skeleton,
};
pub use write::{SynthWriteError, write_dir};

use crate::terrain::Heightmap;
use glam::{DQuat, DVec3};
use rayon::prelude::*;
use serde::Serialize;
use zoo_motion::Clip;
use zoo_motion::rng::SplitMix64;

/// What to generate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SynthConfig {
    /// Total length of motion, in minutes (split into clips of `clip_seconds`).
    pub minutes: f64,
    /// Seed: the same seed gives the same clips.
    pub seed: u64,
    /// Put the clips on uneven terrain (slopes, steps, bumps); flat floor y = 0 otherwise.
    pub terrain: bool,
    /// Frames per second.
    pub fps: f64,
    /// Length of each clip, seconds.
    pub clip_seconds: f64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig { minutes: 10.0, seed: 0, terrain: false, fps: 30.0, clip_seconds: 10.0 }
    }
}

impl SynthConfig {
    /// Number of clips this configuration generates.
    pub fn clip_count(&self) -> usize {
        ((self.minutes * 60.0 / self.clip_seconds).ceil() as usize).max(1)
    }
}

/// The gait a clip was planned with (its label; speeds vary continuously within a clip).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Gait {
    /// Standing, turning in place, shuffling (0 - 0.6 m/s).
    Idle,
    /// Walking (about 1 - 1.9 m/s, with stops, side and back steps).
    Walk,
    /// Jogging (about 2 - 3 m/s).
    Jog,
    /// Running (about 3.3 - 4.8 m/s).
    Run,
}

impl Gait {
    /// Lower-case name, used in file names (`synth_walk_0001.bvh`).
    pub fn name(self) -> &'static str {
        match self {
            Gait::Idle => "idle",
            Gait::Walk => "walk",
            Gait::Jog => "jog",
            Gait::Run => "run",
        }
    }
}

/// The kind of ground a clip walks on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TerrainKind {
    /// Flat floor at y = 0.
    Flat,
    /// An inclined plane with gentle undulation.
    Slope,
    /// Raised and lowered platforms (step edges 8 - 18 cm high).
    Steps,
    /// Smooth bumps and hollows.
    Bumps,
    /// Slope, bumps and steps together.
    Mixed,
}

impl TerrainKind {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            TerrainKind::Flat => "flat",
            TerrainKind::Slope => "slope",
            TerrainKind::Steps => "steps",
            TerrainKind::Bumps => "bumps",
            TerrainKind::Mixed => "mixed",
        }
    }
}

/// Per-clip style parameters (drawn from the clip's random stream).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Style {
    /// Multiplies the gait's speeds (longer strides at the same cadence).
    pub stride: f64,
    /// Multiplies the step frequency.
    pub cadence: f64,
    /// Multiplies the arm swing amplitude.
    pub arm_swing: f64,
    /// Extra forward lean of the trunk, degrees.
    pub lean_deg: f64,
    /// Lateral distance of each foot from the path, cm.
    pub step_half_width: f64,
    /// Multiplies the swing foot's lift.
    pub swing_height: f64,
    /// Outward rotation of the feet, degrees.
    pub toe_out_deg: f64,
    /// Extra knee bend expressed as a lower pelvis, cm.
    pub crouch: f64,
    /// Elbow flexion at rest, degrees.
    pub elbow_deg: f64,
    /// Lateral pelvis sway amplitude, cm.
    pub sway: f64,
}

impl Style {
    fn sample(rng: &mut SplitMix64) -> Style {
        Style {
            stride: rng.range(0.92, 1.08),
            cadence: rng.range(0.93, 1.07),
            arm_swing: rng.range(0.6, 1.3),
            lean_deg: rng.range(-1.0, 6.0),
            step_half_width: rng.range(7.0, 11.0),
            swing_height: rng.range(0.85, 1.2),
            toe_out_deg: rng.range(3.0, 10.0),
            crouch: rng.range(0.0, 3.0),
            elbow_deg: rng.range(10.0, 30.0),
            sway: rng.range(1.0, 2.5),
        }
    }
}

/// One generated clip with its ground truth.
#[derive(Clone, Debug)]
pub struct SynthClip {
    /// File stem, e.g. `synth_walk_0001`.
    pub name: String,
    /// The motion on [`skeleton()`].
    pub clip: Clip,
    /// The ground under the clip (`None`: flat floor at y = 0).
    pub terrain: Option<Heightmap>,
    /// Kind of ground.
    pub terrain_kind: TerrainKind,
    /// The gait the clip was planned with.
    pub gait: Gait,
    /// Per frame: is the left / right foot planted.
    pub contacts: Vec<[bool; 2]>,
    /// The clip's style parameters.
    pub style: Style,
}

impl SynthClip {
    /// Ground height under world `(x, z)` (cm).
    pub fn ground(&self, x: f64, z: f64) -> f64 {
        self.terrain.as_ref().map_or(0.0, |t| t.height(x, z))
    }

    /// The RTN 13 x 13 terrain patch around the root at `frame` (see
    /// [`crate::terrain::local_patch`]; flat floor when the clip has no terrain).
    pub fn terrain_patch(&self, frame: usize) -> [f64; 169] {
        let flat;
        let hf = match &self.terrain {
            Some(t) => t,
            None => {
                flat = Heightmap::flat_area(-1.0, -1.0, 1.0, 1.0, 1.0, 0.0);
                &flat
            }
        };
        local_patch_at(&self.clip, hf, frame)
    }
}

/// The RTN terrain patch of any clip whose root's local +Z is its forward axis (bandai2 and
/// the synthetic data): heights relative to the root, rotated with the root's facing.
pub fn local_patch_at(clip: &Clip, terrain: &Heightmap, frame: usize) -> [f64; 169] {
    let j = clip.joints();
    let root_rot = clip.local_rotations[frame * j];
    let fwd = zoo_motion::facing::ground_forward(root_rot, DVec3::Z);
    let facing = DQuat::from_rotation_y(zoo_motion::facing::heading_angle(fwd));
    crate::terrain::local_patch(terrain, clip.root_position(frame), facing)
}

/// Pre- and post-roll frames simulated around each clip so that foot plants near the ends
/// are planned like any other.
const ROLL: usize = 45;

impl Gait {
    /// Draws a clip's gait: idle 10%, walk 45%, jog 15%, run 30%.
    fn draw(rng: &mut SplitMix64) -> Gait {
        let g = rng.next_f64();
        if g < 0.1 {
            Gait::Idle
        } else if g < 0.55 {
            Gait::Walk
        } else if g < 0.7 {
            Gait::Jog
        } else {
            Gait::Run
        }
    }
}

impl TerrainKind {
    /// Draws a clip's terrain: flat 15%, slope 20%, steps 30%, bumps 20%, mixed 15%.
    fn draw(rng: &mut SplitMix64) -> TerrainKind {
        let k = rng.next_f64();
        if k < 0.15 {
            TerrainKind::Flat
        } else if k < 0.35 {
            TerrainKind::Slope
        } else if k < 0.65 {
            TerrainKind::Steps
        } else if k < 0.85 {
            TerrainKind::Bumps
        } else {
            TerrainKind::Mixed
        }
    }
}

/// Generates clip `index` (0-based) of `cfg`; the same (seed, index) gives the same clip.
pub fn generate_clip(cfg: &SynthConfig, index: usize) -> SynthClip {
    generate_clip_with(cfg, index, Plan::Default)
}

/// Share of the segments of a stepping clip ([`generate_stepping_clip`]) that step sideways
/// (left or right) or backwards; the others stop or walk forwards.
pub const STEPPING_STRAFE_SHARE: f64 = 0.75;

/// Clip `index` of the stepping data of `cfg`: walks in which most segments
/// ([`STEPPING_STRAFE_SHARE`]) are side steps or backward steps (0.5 - 0.9 m/s), the content
/// a forward-only mocap session lacks (issue 19). Named `synth_step_NNNN`; the same
/// (seed, index) gives the same clip, and a different one from [`generate_clip`]'s.
pub fn generate_stepping_clip(cfg: &SynthConfig, index: usize) -> SynthClip {
    let mut c = generate_clip_with(cfg, index, Plan::Stepping(STEPPING_STRAFE_SHARE));
    c.name = format!("synth_step_{:04}", index + 1);
    c
}

/// Every clip of the stepping data of `cfg` ([`generate_stepping_clip`]).
pub fn generate_stepping(cfg: &SynthConfig) -> Vec<SynthClip> {
    (0..cfg.clip_count()).into_par_iter().map(|i| generate_stepping_clip(cfg, i)).collect()
}

/// Clip `index` of the running data of `cfg`: jogging (a third of the clips) and running
/// (2 - 4.8 m/s), the content a walking-only capture lacks (issue 48). Named
/// `synth_jog_NNNN` / `synth_run_NNNN` like the default data's clips of those gaits; the same
/// (seed, index) gives the same clip, and a different one from [`generate_clip`]'s and
/// [`generate_stepping_clip`]'s.
pub fn generate_running_clip(cfg: &SynthConfig, index: usize) -> SynthClip {
    generate_clip_with(cfg, index, Plan::Running)
}

/// Every clip of the running data of `cfg` ([`generate_running_clip`]).
pub fn generate_running(cfg: &SynthConfig) -> Vec<SynthClip> {
    (0..cfg.clip_count()).into_par_iter().map(|i| generate_running_clip(cfg, i)).collect()
}

/// What a clip is planned as.
#[derive(Clone, Copy)]
enum Plan {
    /// The gait drawn as the default data does.
    Default,
    /// A walk with this share of side / back step segments, from a stream of its own.
    Stepping(f64),
    /// Jogging or running, from a stream of its own.
    Running,
}

fn generate_clip_with(cfg: &SynthConfig, index: usize, plan: Plan) -> SynthClip {
    // The stepping and running data use streams above 2^32 so that their clips differ from
    // the default ones.
    let stream = index as u64
        + match plan {
            Plan::Default => 0,
            Plan::Stepping(_) => 1 << 32,
            Plan::Running => 2 << 32,
        };
    let mut rng = SplitMix64::with_stream(cfg.seed, stream);
    let gait = match plan {
        Plan::Stepping(_) => Gait::Walk,
        Plan::Running => {
            if rng.next_f64() < 1.0 / 3.0 {
                Gait::Jog
            } else {
                Gait::Run
            }
        }
        Plan::Default => Gait::draw(&mut rng),
    };
    let stepping = match plan {
        Plan::Stepping(share) => Some(share),
        _ => None,
    };
    let style = Style::sample(&mut rng);
    let terrain_kind = if cfg.terrain { TerrainKind::draw(&mut rng) } else { TerrainKind::Flat };
    let fps = cfg.fps;
    let n_out = ((cfg.clip_seconds * fps).round() as usize).max(2);
    let n = n_out + 2 * ROLL;
    let strafe_share = stepping.unwrap_or(trajectory::WALK_STRAFE_SHARE);
    let traj = trajectory::plan_trajectory(&mut rng, gait, &style, n, fps, strafe_share);
    let terrain = cfg.terrain.then(|| terrain::make_terrain(&mut rng, terrain_kind, &traj));
    let ground = |x: f64, z: f64| terrain.as_ref().map_or(0.0, |t| t.height(x, z));
    let cycle = cycle::plan_cycle(&mut rng, &traj, &style, fps);
    let feet = feet::plan_feet(&traj, &cycle, &style, &ground);
    let pelvis = pelvis::plan_pelvis(&traj, &cycle, &style, &feet, &ground, fps);
    let (local_rotations, local_positions, contacts) =
        pose::pose_frames(&traj, &cycle, &pelvis, &feet, &style, ROLL..ROLL + n_out);
    let mut clip = Clip { skeleton: skeleton(), frame_time: 1.0 / fps, local_rotations, local_positions };
    clip.remove_sign_flips();
    SynthClip {
        name: format!("synth_{}_{:04}", gait.name(), index + 1),
        clip,
        terrain,
        terrain_kind,
        gait,
        contacts,
        style,
    }
}

/// Generates every clip of `cfg` (in parallel; the result does not depend on thread count).
pub fn generate(cfg: &SynthConfig) -> Vec<SynthClip> {
    (0..cfg.clip_count()).into_par_iter().map(|i| generate_clip(cfg, i)).collect()
}

/// [`generate`] calling `progress` once per finished clip (from worker threads).
pub fn generate_with_progress(cfg: &SynthConfig, progress: &(dyn Fn() + Sync)) -> Vec<SynthClip> {
    (0..cfg.clip_count())
        .into_par_iter()
        .map(|i| {
            let c = generate_clip(cfg, i);
            progress();
            c
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::skeleton::{FOOT, TOES};
    use super::*;
    use crate::plausibility;

    #[test]
    fn data_mixes_with_the_generators_clips_only_on_its_skeleton_and_frame_rate() {
        let sk = skeleton();
        assert_eq!(check_mixable("--opt", "a", &sk, Some(30.0), 30.0), Ok(()));
        assert_eq!(check_mixable("--opt", "a", &sk, None, 30.0), Ok(()));
        let rate = check_mixable("--opt", "clip_a", &sk, Some(60.0), 30.0).unwrap_err();
        assert!(rate.contains("clip_a") && rate.contains("60.000 fps") && rate.contains("leave --opt out"), "{rate}");
        let mut other = sk.clone();
        other.parents[4] = Some(1);
        let parents = check_mixable("--opt", "b", &other, None, 30.0).unwrap_err();
        assert!(parents.contains("bandai2's skeleton") && parents.contains("21 joints"), "{parents}");
        let mut fewer = sk.clone();
        fewer.names.pop();
        fewer.parents.pop();
        assert!(check_mixable("--opt", "c", &fewer, None, 30.0).unwrap_err().contains("on 20 joints"));
    }

    fn cfg(seed: u64, terrain: bool, minutes: f64) -> SynthConfig {
        SynthConfig { minutes, seed, terrain, ..SynthConfig::default() }
    }

    #[test]
    fn skeleton_is_bandai2_without_dummy_root() {
        let s = skeleton();
        s.validate().unwrap();
        assert_eq!(s.len(), 21);
        assert_eq!(s.names[0], "Hips");
        assert!(s.channels[0].position && !s.channels[1].position);
        assert_eq!(s.parents[s.index_of("Toes_R").unwrap()], s.index_of("Foot_R"));
    }

    #[test]
    fn same_seed_same_clips_other_seed_other_clips() {
        let a = generate(&cfg(7, true, 0.5));
        let b = generate(&cfg(7, true, 0.5));
        let c = generate(&cfg(8, true, 0.5));
        assert_eq!(a.len(), 3);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.clip, y.clip);
            assert_eq!(x.terrain, y.terrain);
            assert_eq!(x.contacts, y.contacts);
            assert_eq!(x.name, y.name);
        }
        assert_ne!(a[0].clip.local_rotations, c[0].clip.local_rotations);
        // A clip does not depend on how many others are generated with it.
        let single = generate_clip(&cfg(7, true, 0.5), 2);
        assert_eq!(single.clip, a[2].clip);
    }

    #[test]
    fn ik_within_reach_hits_target_exactly() {
        let root = DVec3::new(1.0, 90.0, -3.0);
        for target in [DVec3::new(10.0, 20.0, 15.0), DVec3::new(-5.0, 50.0, 0.0), DVec3::new(0.0, 15.0, -20.0)] {
            let (knee, ankle) = two_bone_ik(root, target, DVec3::Z, 39.0811, 40.9854);
            assert!((ankle - target).length() < 1e-6, "{ankle} vs {target}");
            assert!(((knee - root).length() - 39.0811).abs() < 1e-6);
            assert!(((ankle - knee).length() - 40.9854).abs() < 1e-6);
            // Knee bends toward the pole (+Z) relative to the hip-ankle line.
            let dir = (target - root).normalize();
            let off = (knee - root) - dir * (knee - root).dot(dir);
            assert!(off.z > 0.0);
        }
    }

    #[test]
    fn ik_beyond_reach_extends_fully_without_nan() {
        let root = DVec3::new(0.0, 100.0, 0.0);
        let target = DVec3::new(30.0, -200.0, 40.0);
        let (knee, ankle) = two_bone_ik(root, target, DVec3::Z, 39.0, 41.0);
        assert!(knee.is_finite() && ankle.is_finite());
        let dir = (target - root).normalize();
        assert!((ankle - (root + dir * 80.0)).length() < 1e-9);
        assert!((knee - (root + dir * 39.0)).length() < 1e-9);
        // Degenerate inputs: target on the root, pole parallel to the leg.
        let (k2, a2) = two_bone_ik(root, root, DVec3::Z, 39.0, 41.0);
        assert!(k2.is_finite() && a2.is_finite());
        let (k3, a3) = two_bone_ik(root, root - DVec3::Y * 50.0, DVec3::Y, 39.0, 41.0);
        assert!(k3.is_finite() && a3.is_finite());
    }

    #[test]
    fn planted_feet_touch_the_terrain_and_never_sink() {
        let clips = generate(&cfg(3, true, 2.0));
        let foot = [FOOT[0], FOOT[1]];
        let toes = [TOES[0], TOES[1]];
        for c in &clips {
            let (_, gp) = c.clip.global();
            let j = c.clip.joints();
            for f in 0..c.clip.frames() {
                for side in 0..2 {
                    let a = gp[f * j + foot[side]];
                    let t = gp[f * j + toes[side]];
                    let ha = a.y - c.ground(a.x, a.z);
                    let ht = t.y - c.ground(t.x, t.z);
                    assert!(ha > -1.0 && ht > -1.0, "{} frame {f}: below ground ({ha}, {ht})", c.name);
                    if c.contacts[f][side] {
                        assert!((ht - TOE_HEIGHT).abs() < 1.0, "{} frame {f}: planted toe at {ht}", c.name);
                        assert!(ha > ANKLE_HEIGHT - 1.0, "{} frame {f}: planted ankle at {ha}", c.name);
                    }
                }
            }
        }
    }

    #[test]
    fn planted_feet_do_not_move() {
        let clips = generate(&cfg(4, true, 1.0));
        for c in &clips {
            let (_, gp) = c.clip.global();
            let j = c.clip.joints();
            for f in 1..c.clip.frames() {
                for side in 0..2 {
                    if c.contacts[f][side] && c.contacts[f - 1][side] {
                        let d = gp[f * j + TOES[side]] - gp[(f - 1) * j + TOES[side]];
                        assert!(d.length() < 1e-4, "{} frame {f}: planted toe moved {}", c.name, d.length());
                    }
                }
            }
        }
    }

    #[test]
    fn skate_speeds_and_bones_are_plausible() {
        let clips = generate(&cfg(1, true, 4.0));
        let set: Vec<(&Clip, Option<&Heightmap>, &str)> =
            clips.iter().map(|c| (&c.clip, c.terrain.as_ref(), c.gait.name())).collect();
        let p = plausibility::measure(&set);
        // bandai2's own skate is measured in the report (see the closing note of issue 3);
        // the synthetic data must stay well under 2x of it.
        assert!(p.foot_skate < 0.3, "{p:?}");
        for (label, v) in &p.median_root_speed {
            match label.as_str() {
                "walk" => assert!((1.0..=2.0).contains(v), "{p:?}"),
                "run" => assert!((3.0..=5.0).contains(v), "{p:?}"),
                _ => {}
            }
        }
        assert!(p.max_foot_penetration <= 1.0, "{p:?}");
        assert!(p.max_bone_length_error < 1e-6, "{p:?}");
    }

    /// Share of the moving frames (root faster than 0.3 m/s) whose ground velocity points more
    /// than 60 degrees away from the character's facing (side and back steps).
    fn off_facing_share(clips: &[SynthClip]) -> f64 {
        let (mut off, mut moving) = (0usize, 0usize);
        for c in clips {
            let j = c.clip.joints();
            for f in 1..c.clip.frames() {
                let v = c.clip.root_position(f) - c.clip.root_position(f - 1);
                let v = DVec3::new(v.x, 0.0, v.z);
                if v.length() / c.clip.frame_time < 30.0 {
                    continue;
                }
                moving += 1;
                let fwd = zoo_motion::facing::ground_forward(c.clip.local_rotations[f * j], DVec3::Z);
                if v.normalize().dot(fwd.normalize()) < 0.5 {
                    off += 1;
                }
            }
        }
        off as f64 / moving.max(1) as f64
    }

    #[test]
    fn stepping_clips_step_sideways_and_backwards_plausibly() {
        let c = cfg(2, false, 3.0);
        let stepping = generate_stepping(&c);
        assert_eq!(stepping.len(), 18);
        assert!(stepping.iter().all(|s| s.gait == Gait::Walk && s.name.starts_with("synth_step_")));
        let (ours, default) = (off_facing_share(&stepping), off_facing_share(&generate(&c)));
        assert!(ours > 0.3 && ours > 3.0 * default, "side/back share {ours:.3} (default data {default:.3})");
        let set: Vec<(&Clip, Option<&Heightmap>, &str)> = stepping.iter().map(|c| (&c.clip, None, "walk")).collect();
        let p = plausibility::measure(&set);
        assert!(p.foot_skate < 0.3 && p.max_foot_penetration <= 1.0 && p.max_bone_length_error < 1e-6, "{p:?}");
        // Deterministic, and not the default data's clips.
        assert_eq!(generate_stepping_clip(&c, 4).clip, stepping[4].clip);
        assert_ne!(generate_clip(&c, 4).clip.local_rotations, stepping[4].clip.local_rotations);
    }

    #[test]
    fn running_clips_jog_and_run_plausibly() {
        let c = cfg(2, false, 3.0);
        let running = generate_running(&c);
        assert_eq!(running.len(), 18);
        assert!(running.iter().all(|s| matches!(s.gait, Gait::Jog | Gait::Run)));
        assert!(running.iter().any(|s| s.gait == Gait::Jog) && running.iter().any(|s| s.gait == Gait::Run));
        let set: Vec<(&Clip, Option<&Heightmap>, &str)> =
            running.iter().map(|c| (&c.clip, None, c.gait.name())).collect();
        let p = plausibility::measure(&set);
        assert!(p.max_foot_penetration <= 1.0 && p.max_bone_length_error < 1e-6, "{p:?}");
        // Faster than the default data's walks (1 - 1.9 m/s): at least 1.9 m/s at the median.
        for (label, v) in &p.median_root_speed {
            assert!(*v > 1.9, "{label}: median root speed {v} m/s");
        }
        // Deterministic, and neither the default nor the stepping data's clips.
        assert_eq!(generate_running_clip(&c, 4).clip, running[4].clip);
        assert_ne!(generate_clip(&c, 4).clip.local_rotations, running[4].clip.local_rotations);
        assert_ne!(generate_stepping_clip(&c, 4).clip.local_rotations, running[4].clip.local_rotations);
    }

    #[test]
    fn terrain_patch_is_relative_to_the_root() {
        let c = generate_clip(&cfg(5, false, 0.2), 0);
        let p = c.terrain_patch(10);
        let y = c.clip.root_position(10).y;
        assert!(p.iter().all(|h| (h + y).abs() < 1e-9));
    }
}
