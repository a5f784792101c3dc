//! Differentiable forward kinematics from state features (candle), for the refiner's input and
//! the discriminator's (sec. 4.2.1, eq. 11-12: end-effector positions `p_end(x)` and velocities
//! `v_end(x)`), and the root trajectory of the self-regularisation term (eq. 13).
//!
//! Positions are in the character's heading frame (the root's x-z position removed and its
//! heading undone; heights kept), so they do not depend on where the character is. Velocities
//! are world displacements since the previous frame, in the previous frame's heading frame:
//! `v_t = (dtx, 0, dtz)_t + yaw(dry_t) p_t - p_(t-1)`, so a planted foot has zero velocity
//! whatever the root does (foot sliding shows directly); frame 0 of a window repeats frame 1's.
//! Joint rotations use Rodrigues' formula `R = I + (sin a / a) K + (2 sin^2(a/2) / a^2) K^2`
//! (stable near 0), times the joint's reference rotation.

use crate::error::{RnnGmmError, RnnGmmResult};
use crate::features::{FeatureSpec, Normalization};
use candle_core::{D, DType, Device, Result, Tensor};
use glam::DMat3;

/// The end effectors of a skeleton: every leaf joint (head, hands, toes) and both ankles.
pub fn end_effectors(spec: &FeatureSpec) -> Vec<usize> {
    let s = &spec.skeleton;
    let mut e: Vec<usize> = (1..s.len()).filter(|&j| s.children(j).is_empty()).collect();
    for ankle in [spec.left_foot[0], spec.right_foot[0]] {
        if !e.contains(&ankle) {
            e.push(ankle);
        }
    }
    e.sort_unstable();
    e
}

/// Forward kinematics of normalised state features, batched over `(batch, time)`.
#[derive(Clone, Debug)]
pub struct TensorFk {
    parents: Vec<Option<usize>>,
    /// Rest offsets `(J, 3, 1)`.
    offsets: Tensor,
    /// Reference rotations as matrices `(J, 3, 3)`.
    reference: Tensor,
    effectors: Vec<usize>,
    mean: Tensor,
    std: Tensor,
    dim: usize,
}

fn col(x: &Tensor, i: usize) -> Result<Tensor> {
    x.narrow(D::Minus1, i, 1)
}

/// Rotation matrices `(n, 3, 3)` of rotation vectors `(n, 3)`.
pub fn rodrigues(v: &Tensor) -> Result<Tensor> {
    let n = v.dim(0)?;
    let a = (v.sqr()?.sum_keepdim(1)? + 1e-12)?.sqrt()?; // (n, 1)
    let s = (a.sin()? / &a)?;
    let half = (a.clone() * 0.5)?.sin()?;
    let c = ((half.sqr()? * 2.0)? / a.sqr()?)?;
    let (x, y, z) = (col(v, 0)?, col(v, 1)?, col(v, 2)?);
    let zero = x.zeros_like()?;
    let k = Tensor::cat(&[&zero, &z.neg()?, &y, &z, &zero, &x.neg()?, &y.neg()?, &x, &zero], 1)?.reshape((n, 3, 3))?;
    let eye = Tensor::eye(3, v.dtype(), v.device())?.unsqueeze(0)?.broadcast_as((n, 3, 3))?;
    let k2 = mat3_mul(&k, &k)?;
    eye + k.broadcast_mul(&s.unsqueeze(2)?)? + k2.broadcast_mul(&c.unsqueeze(2)?)?
}

/// Batched 3x3 products `a b` of `a` `(n, 3, 3)` (or `(1, 3, 3)`) and `b` `(n or 1, 3, k)`, as
/// element-wise products and a sum: many tiny matrices are faster this way on the CPU than as
/// one batched matmul per joint.
fn mat3_mul(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    a.unsqueeze(3)?.broadcast_mul(&b.unsqueeze(1)?)?.sum(2)
}

impl TensorFk {
    /// FK for `spec`'s skeleton, reading features normalised with `norm`, reporting `effectors`.
    pub fn new(spec: &FeatureSpec, norm: &Normalization, effectors: &[usize], device: &Device) -> RnnGmmResult<Self> {
        let j = spec.skeleton.len();
        if norm.dim() != spec.dim() {
            return Err(RnnGmmError::Config(format!(
                "statistics of {} values for a feature of {}",
                norm.dim(),
                spec.dim()
            )));
        }
        if let Some(&e) = effectors.iter().find(|&&e| e == 0 || e >= j) {
            return Err(RnnGmmError::Config(format!("end effector {e} is not a non-root joint of the {j} joints")));
        }
        let offsets: Vec<f32> =
            spec.skeleton.offsets.iter().flat_map(|o| [o.x as f32, o.y as f32, o.z as f32]).collect();
        let reference: Vec<f32> = spec
            .reference
            .iter()
            .flat_map(|q| {
                // Row-major 3x3 (glam stores columns).
                let m = DMat3::from_quat(*q).transpose().to_cols_array();
                m.map(|v| v as f32)
            })
            .collect();
        Ok(TensorFk {
            parents: spec.skeleton.parents.clone(),
            offsets: Tensor::from_vec(offsets, (j, 3, 1), device)?,
            reference: Tensor::from_vec(reference, (j, 3, 3), device)?,
            effectors: effectors.to_vec(),
            mean: Tensor::from_slice(&norm.mean, norm.dim(), device)?,
            std: Tensor::from_slice(&norm.std, norm.dim(), device)?,
            dim: spec.dim(),
        })
    }

    /// Number of end effectors `E`.
    pub fn effector_count(&self) -> usize {
        self.effectors.len()
    }

    /// Features in clip units from normalised ones (same shape).
    pub fn denormalize(&self, x: &Tensor) -> Result<Tensor> {
        x.broadcast_mul(&self.std)?.broadcast_add(&self.mean)
    }

    /// End-effector positions in the heading frame, `(batch, time, E, 3)`, of normalised
    /// features `(batch, time, D)`.
    pub fn positions(&self, x: &Tensor) -> Result<Tensor> {
        let (b, t, d) = x.dims3()?;
        if d != self.dim {
            candle_core::bail!("FK: expected {} feature values per frame, found {d}", self.dim)
        }
        let n = b * t;
        let x = self.denormalize(x)?.reshape((n, d))?;
        let joints = self.parents.len();
        // Root: tilt (rx, 0, rz) at height ty.
        let zero = col(&x, 0)?.zeros_like()?;
        let tilt = Tensor::cat(&[&col(&x, 4)?, &zero, &col(&x, 5)?], 1)?;
        let angles = x.narrow(1, 6, 3 * (joints - 1))?.reshape((n * (joints - 1), 3))?;
        let local = rodrigues(&angles)?.reshape((n, joints - 1, 3, 3))?;
        let mut rot: Vec<Tensor> = Vec::with_capacity(joints);
        let mut pos: Vec<Tensor> = Vec::with_capacity(joints);
        rot.push(rodrigues(&tilt)?);
        pos.push(Tensor::cat(&[&zero, &col(&x, 3)?, &zero], 1)?.unsqueeze(2)?); // (n, 3, 1)
        for j in 1..joints {
            let p = self.parents[j].ok_or_else(|| candle_core::Error::Msg(format!("joint {j} has no parent")))?;
            let r_local = mat3_mul(&self.reference.get(j)?.unsqueeze(0)?, &local.narrow(1, j - 1, 1)?.squeeze(1)?)?;
            let p_j = (mat3_mul(&rot[p], &self.offsets.get(j)?.unsqueeze(0)?)? + &pos[p])?;
            let r_j = mat3_mul(&rot[p], &r_local)?;
            pos.push(p_j);
            rot.push(r_j);
        }
        let e: Vec<Tensor> = self.effectors.iter().map(|&j| pos[j].squeeze(2)).collect::<Result<_>>()?;
        Tensor::stack(&e, 1)?.reshape((b, t, self.effectors.len(), 3))
    }

    /// End-effector positions and velocities (see the module docs), `(batch, time, 6 E)`:
    /// positions of every effector (x, y, z), then velocities.
    pub fn effector_features(&self, x: &Tensor) -> Result<Tensor> {
        let (b, t, _) = x.dims3()?;
        if t < 2 {
            candle_core::bail!("effector velocities need windows of at least 2 frames, found {t}")
        }
        let e = self.effectors.len();
        let p = self.positions(x)?; // (b, t, e, 3)
        let raw = self.denormalize(x)?;
        let (dtx, dtz, dry) = (col(&raw, 0)?, col(&raw, 1)?, col(&raw, 2)?); // (b, t, 1)
        let (c, s) = (dry.cos()?.unsqueeze(3)?, dry.sin()?.unsqueeze(3)?); // (b, t, 1, 1)
        let (px, py, pz) = (col(&p, 0)?, col(&p, 1)?, col(&p, 2)?); // (b, t, e, 1)
        // yaw(a) (x, y, z) = (c x + s z, y, -s x + c z).
        let rx = (px.broadcast_mul(&c)? + pz.broadcast_mul(&s)?)?;
        let rz = (pz.broadcast_mul(&c)? - px.broadcast_mul(&s)?)?;
        let wx = rx.broadcast_add(&dtx.unsqueeze(3)?)?;
        let wz = rz.broadcast_add(&dtz.unsqueeze(3)?)?;
        let moved = Tensor::cat(&[&wx, &py, &wz], 3)?; // (b, t, e, 3)
        let v = (moved.narrow(1, 1, t - 1)? - p.narrow(1, 0, t - 1)?)?;
        let v = Tensor::cat(&[&v.narrow(1, 0, 1)?, &v], 1)?;
        Tensor::cat(&[&p.reshape((b, t, 3 * e))?, &v.reshape((b, t, 3 * e))?], 2)
    }

    /// Root trajectory of each window from the origin `(0, 0)` with heading 0 (eq. 4),
    /// `(batch, time, 3)`: accumulated x, height, accumulated z, in clip units.
    pub fn root_trajectory(&self, x: &Tensor) -> Result<Tensor> {
        let raw = self.denormalize(x)?;
        let (dtx, dtz, dry, ty) = (col(&raw, 0)?, col(&raw, 1)?, col(&raw, 2)?, col(&raw, 3)?);
        // Heading before frame t: sum of dry over frames < t.
        let heading = (dry.cumsum(1)? - &dry)?;
        let (c, s) = (heading.cos()?, heading.sin()?);
        let step_x = ((&c * &dtx)? + (&s * &dtz)?)?;
        let step_z = ((&c * &dtz)? - (&s * &dtx)?)?;
        Tensor::cat(&[&step_x.cumsum(1)?, &ty, &step_z.cumsum(1)?], 2)
    }

    /// The feature dtype (f32).
    pub fn dtype(&self) -> DType {
        self.mean.dtype()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::RootPlacement;
    use glam::{DQuat, DVec3};
    use zoo_data::synth::{SynthConfig, generate_clip};

    #[test]
    fn tensor_fk_matches_the_clip_and_velocities_see_world_motion() {
        let s = generate_clip(&SynthConfig { minutes: 1.0, seed: 4, terrain: false, fps: 30.0, clip_seconds: 2.0 }, 1);
        let spec = FeatureSpec::fit(&s.clip.skeleton, 30.0, &[&s.clip]).unwrap();
        let enc = spec.encode(&s.clip).unwrap();
        let norm = Normalization::fit(std::slice::from_ref(&enc)).unwrap();
        let eff = end_effectors(&spec);
        let names: Vec<&str> = eff.iter().map(|&j| spec.skeleton.names[j].as_str()).collect();
        assert_eq!(names, ["Head", "Hand_L", "Hand_R", "Foot_L", "Toes_L", "Foot_R", "Toes_R"]);
        let fk = TensorFk::new(&spec, &norm, &eff, &Device::Cpu).unwrap();
        let mut v = enc.values.clone();
        norm.normalize(&mut v);
        let frames = enc.frames();
        let x = Tensor::from_vec(v, (1, frames, spec.dim()), &Device::Cpu).unwrap();
        let feats = fk.effector_features(&x).unwrap().squeeze(0).unwrap().to_vec2::<f32>().unwrap();
        let traj = fk.root_trajectory(&x).unwrap().squeeze(0).unwrap().to_vec2::<f32>().unwrap();
        // Reference: decode from the identity placement (eq. 4) and take global positions.
        let dec = spec.decode(&enc.values, RootPlacement::default()).unwrap();
        let (gr, gp) = dec.clip.global();
        let j = spec.skeleton.len();
        let e = eff.len();
        let mut placement = RootPlacement::default();
        for f in 0..frames {
            let x = enc.frame(f);
            placement = placement.advance(x[0] as f64, x[1] as f64, x[2] as f64);
            let root = gp[f * j];
            let t = DVec3::new(traj[f][0] as f64, traj[f][1] as f64, traj[f][2] as f64);
            assert!((t - root).length() < 1e-2, "frame {f}: root {root} vs {t}");
            let unyaw = DQuat::from_rotation_y(-placement.yaw);
            for (k, &jj) in eff.iter().enumerate() {
                let want = unyaw * (gp[f * j + jj] - DVec3::new(root.x, 0.0, root.z));
                let got = DVec3::new(feats[f][3 * k] as f64, feats[f][3 * k + 1] as f64, feats[f][3 * k + 2] as f64);
                assert!((want - got).length() < 1e-2, "frame {f} joint {jj}: {want} vs {got}");
                if f > 0 {
                    let prev_yaw = placement.yaw - x[2] as f64;
                    let want_v = DQuat::from_rotation_y(-prev_yaw) * (gp[f * j + jj] - gp[(f - 1) * j + jj]);
                    let o = 3 * e + 3 * k;
                    let got_v = DVec3::new(feats[f][o] as f64, feats[f][o + 1] as f64, feats[f][o + 2] as f64);
                    assert!((want_v - got_v).length() < 1e-2, "frame {f} joint {jj}: velocity {want_v} vs {got_v}");
                }
            }
            let _ = gr[f * j];
        }
    }

    #[test]
    fn rodrigues_matches_glam_and_is_finite_at_zero() {
        let v = [[0.0f32, 0.0, 0.0], [0.3, -1.2, 0.5], [1e-7, 0.0, 0.0], [3.0, 0.1, -0.2]];
        let t = Tensor::new(&v, &Device::Cpu).unwrap();
        let r = rodrigues(&t).unwrap().to_vec3::<f32>().unwrap();
        for (k, a) in v.iter().enumerate() {
            let q = zoo_motion::quat::from_scaled_axis(DVec3::new(a[0] as f64, a[1] as f64, a[2] as f64));
            let m = DMat3::from_quat(q);
            for row in 0..3 {
                for c in 0..3 {
                    assert!((r[k][row][c] as f64 - m.col(c)[row]).abs() < 1e-5, "{k} {row} {c}");
                }
            }
        }
        let var = candle_core::Var::from_tensor(&Tensor::zeros((1, 3), DType::F32, &Device::Cpu).unwrap()).unwrap();
        let g = rodrigues(var.as_tensor()).unwrap().sum_all().unwrap().backward().unwrap();
        assert!(g.get(&var).unwrap().to_vec2::<f32>().unwrap()[0].iter().all(|v| v.is_finite()));
    }

    #[test]
    #[ignore = "timing: element-wise 3x3 products against batched matmuls"]
    fn mat3_mul_is_faster_than_batched_matmul() {
        let n = 1600;
        let dev = Device::Cpu;
        let a = Tensor::randn(0f32, 1.0, (n, 3, 3), &dev).unwrap();
        let b = Tensor::randn(0f32, 1.0, (n, 3, 3), &dev).unwrap();
        let diff = (mat3_mul(&a, &b).unwrap() - a.matmul(&b).unwrap()).unwrap().abs().unwrap().max_all().unwrap();
        assert!(diff.to_scalar::<f32>().unwrap() < 1e-5);
        let time = |f: &dyn Fn() -> Tensor| {
            let t = std::time::Instant::now();
            for _ in 0..200 {
                f();
            }
            t.elapsed().as_secs_f64() / 200.0 * 1e6
        };
        // Interleaved, so a change in the machine's load hits both.
        let (mut e, mut m) = (0.0, 0.0);
        for _ in 0..5 {
            e += time(&|| mat3_mul(&a, &b).unwrap());
            m += time(&|| a.matmul(&b).unwrap());
        }
        eprintln!("n = {n}: element-wise {:.0} us, batched matmul {:.0} us", e / 5.0, m / 5.0);
    }
}
