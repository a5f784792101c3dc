//! Another rig of the same kind: joint names mapped, rest poses aligned, root motion scaled.
//!
//! A [`RigMap`] (a small JSON file) says which joint of a clip's rig plays each joint of a
//! target rig (a model's training skeleton). Names that are the same need no entry, and a
//! namespace prefix on the clip's names (`mixamorig:Hips`, `Character1:Hips`: anything up to
//! the last `:`) is ignored, so a Mixamo-style rig whose joints carry the target's names needs
//! an empty map. Joints the target needs and the rig lacks are refused with their list.
//!
//! [`retarget`] moves a clip onto the target skeleton: every target joint takes the *global*
//! rotation of its rig joint relative to the rig's rest pose (zoo's rest pose: identity
//! rotations, see `scene.rs`), turned by the rest-pose difference of the two rigs (the
//! rotation that takes the target's rest bone directions onto the rig's: T-pose against
//! A-pose); local rotations follow from the target's hierarchy, bone lengths are the target's,
//! and the root's translation is scaled by the ratio of the rigs' leg lengths. Supported: the
//! same joints under other names, other bone lengths and proportions, another rest pose, extra
//! joints in the rig (ignored, their motion folds into the mapped joints' global rotations).
//! Not supported: a rig that lacks a joint the target needs, twist about a bone whose rest
//! pose differs between the rigs (only bone directions are aligned), IK or foot-contact
//! correction after retargeting (feet may slide when proportions differ).

use glam::{DMat3, DQuat, DVec3};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use zoo_motion::{Clip, Skeleton};

/// The range of a name map's `root_scale`: units from kilometres to micrometres and back, with
/// room to spare; a larger scale moves the root past what a clip may hold.
pub const ROOT_SCALE_RANGE: std::ops::RangeInclusive<f64> = 1e-6..=1e6;

/// A joint-name map from a clip's rig to a target rig, read from JSON:
///
/// ```json
/// { "joints": { "Hips": "mixamorig:Hips", "Foot_L": "LeftFoot" }, "root_scale": 0.91 }
/// ```
///
/// `joints` maps a target joint name to the rig's joint name (optional: same names, up to a
/// namespace prefix, need no entry); `root_scale` fixes the root translation scale (optional:
/// by default the ratio of the rigs' leg lengths).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigMap {
    /// Target joint name -> the rig's joint name.
    #[serde(default)]
    pub joints: BTreeMap<String, String>,
    /// Target units per rig unit for the root's translation (default: the leg-length ratio).
    #[serde(default)]
    pub root_scale: Option<f64>,
}

/// Why a rig cannot be mapped.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The map file could not be read or parsed.
    #[error("{path}: {message}")]
    File {
        /// The map file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The rig lacks joints the target needs.
    #[error(
        "the rig lacks {} joint(s) the model needs: {}; map each to one of the rig's joints in the name map's \
         `joints` (target name: rig name){}", missing.len(), missing.join(", "), hint
    )]
    Missing {
        /// Target joint names with no rig joint.
        missing: Vec<String>,
        /// Nearby rig names, for the message.
        hint: String,
    },
    /// Something else is wrong with the map against these rigs.
    #[error("{0}")]
    Invalid(String),
}

/// The rig joint of every target joint, and the root translation scale.
#[derive(Clone, Debug, PartialEq)]
pub struct RigMatch {
    /// For each target joint, the rig's joint that drives it (`None`: rest pose).
    pub source_of: Vec<Option<usize>>,
    /// Target units per rig unit for the root's translation.
    pub root_scale: f64,
}

/// A name without its namespace: `mixamorig:Hips` -> `Hips`.
pub fn strip_namespace(name: &str) -> &str {
    name.rsplit_once(':').map_or(name, |(_, n)| n)
}

impl RigMap {
    /// Reads a map from a JSON file.
    pub fn read(path: &Path) -> Result<Self, RigError> {
        let file = |message: String| RigError::File { path: path.to_path_buf(), message };
        let text = std::fs::read_to_string(path).map_err(|e| file(format!("cannot read: {e}")))?;
        let map: RigMap = serde_json::from_str(&text).map_err(|e| {
            file(format!(
                "not a joint-name map ({e}); expected {{\"joints\": {{\"TargetName\": \"RigName\", ...}}, \"root_scale\": \
                 optional number}}"
            ))
        })?;
        if let Some(s) = map.root_scale
            && !(s.is_finite() && ROOT_SCALE_RANGE.contains(&s))
        {
            return Err(file(format!(
                "root_scale {s:e} is outside its range [{:e}, {:e}]: it is the model's length units per rig unit \
                 (100 for a rig in metres driving a model in centimetres); leave it out to use the ratio of the \
                 rigs' leg lengths",
                ROOT_SCALE_RANGE.start(),
                ROOT_SCALE_RANGE.end()
            )));
        }
        Ok(map)
    }

    /// Matches `target`'s joints to `rig`'s: the map's entry, else the same name, else the
    /// same name without a namespace prefix (ASCII case ignored last). With `require_all`,
    /// every target joint must find one (a model needs them all).
    pub fn match_rigs(&self, rig: &Skeleton, target: &Skeleton, require_all: bool) -> Result<RigMatch, RigError> {
        for (t, r) in &self.joints {
            if target.index_of(t).is_none() {
                return Err(RigError::Invalid(format!(
                    "the name map maps `{t}`, which is not a joint of the model (its joints: {})",
                    target.names.join(", ")
                )));
            }
            if rig.index_of(r).is_none() {
                return Err(RigError::Invalid(format!(
                    "the name map maps `{t}` to `{r}`, which is not a joint of the clip's rig (its joints: {})",
                    rig.names.join(", ")
                )));
            }
        }
        let find = |name: &str| -> Option<usize> {
            if let Some(r) = self.joints.get(name) {
                return rig.index_of(r);
            }
            rig.index_of(name)
                .or_else(|| rig.names.iter().position(|n| strip_namespace(n) == name))
                .or_else(|| rig.names.iter().position(|n| strip_namespace(n).eq_ignore_ascii_case(name)))
        };
        let source_of: Vec<Option<usize>> = target.names.iter().map(|n| find(n)).collect();
        let missing: Vec<String> =
            target.names.iter().zip(&source_of).filter(|(_, s)| s.is_none()).map(|(n, _)| format!("`{n}`")).collect();
        if source_of[0].is_none() || (require_all && !missing.is_empty()) {
            let sample: Vec<&str> = rig.names.iter().take(12).map(String::as_str).collect();
            let hint =
                format!(" (the rig's joints: {}{})", sample.join(", "), if rig.len() > 12 { ", ..." } else { "" });
            return Err(RigError::Missing { missing, hint });
        }
        let mut used = vec![None; rig.len()];
        for (t, s) in source_of.iter().enumerate() {
            if let Some(s) = *s {
                if let Some(prev) = used[s] {
                    return Err(RigError::Invalid(format!(
                        "the rig's joint `{}` would drive both `{}` and `{}`; map each target joint to its own joint",
                        rig.names[s], target.names[prev], target.names[t]
                    )));
                }
                used[s] = Some(t);
            }
        }
        let root_scale = match self.root_scale {
            Some(s) => s,
            None => leg_ratio(rig, target, &source_of)?,
        };
        Ok(RigMatch { source_of, root_scale })
    }
}

impl RigMatch {
    /// The match the other way: from the target back onto the rig (`rig_joints` joints).
    pub fn inverse(&self, rig_joints: usize) -> RigMatch {
        let mut source_of = vec![None; rig_joints];
        for (t, s) in self.source_of.iter().enumerate() {
            if let Some(s) = *s {
                source_of[s] = Some(t);
            }
        }
        RigMatch { source_of, root_scale: 1.0 / self.root_scale }
    }
}

/// Rest (identity-rotation) global positions.
fn rest_positions(s: &Skeleton) -> Vec<DVec3> {
    let mut p = vec![DVec3::ZERO; s.len()];
    for j in 0..s.len() {
        p[j] = s.parents[j].map_or(s.offsets[j], |q| p[q] + s.offsets[j]);
    }
    p
}

/// Length of the chain from the root down to joint `j` (sum of bone lengths).
fn chain_length(s: &Skeleton, mut j: usize) -> f64 {
    let mut len = 0.0;
    while let Some(p) = s.parents[j] {
        len += s.offsets[j].length();
        j = p;
    }
    len
}

/// Target leg length over the rig's: the chain from the root to the lowest mapped joint at
/// rest (a toe or a foot).
fn leg_ratio(rig: &Skeleton, target: &Skeleton, source_of: &[Option<usize>]) -> Result<f64, RigError> {
    let rest = rest_positions(target);
    let lowest = (1..target.len())
        .filter(|&j| source_of[j].is_some())
        .min_by(|&a, &b| rest[a].y.total_cmp(&rest[b].y))
        .ok_or_else(|| RigError::Invalid("only the root is mapped: nothing to measure the legs by".into()))?;
    let (t, r) = (chain_length(target, lowest), chain_length(rig, source_of[lowest].unwrap_or(0)));
    if !(t > 1e-9 && r > 1e-9) {
        return Err(RigError::Invalid(format!(
            "cannot measure the legs (to `{}`): set \"root_scale\" in the name map",
            target.names[lowest]
        )));
    }
    Ok(t / r)
}

/// The rotation taking the target's rest directions at joint `j` onto the rig's (identity
/// when the rigs' rest poses agree). Directions are to the mapped children (two give a full
/// frame, one the shortest arc) or to the end sites.
fn rest_alignment(rig: &Skeleton, target: &Skeleton, m: &RigMatch, j: usize, rr: &[DVec3], tr: &[DVec3]) -> DQuat {
    let Some(sj) = m.source_of[j] else { return DQuat::IDENTITY };
    let mut pairs: Vec<(DVec3, DVec3)> = Vec::new();
    for c in 0..target.len() {
        if target.parents[c] == Some(j)
            && let Some(sc) = m.source_of[c]
        {
            pairs.push((tr[c] - tr[j], rr[sc] - rr[sj]));
        }
    }
    if pairs.is_empty()
        && let (Some(a), Some(b)) = (target.end_sites[j], rig.end_sites[sj])
    {
        pairs.push((a, b));
    }
    pairs.retain(|(a, b)| a.length() > 1e-9 && b.length() > 1e-9);
    let Some(&(t0, r0)) = pairs.first() else { return DQuat::IDENTITY };
    let (t0, r0) = (t0.normalize(), r0.normalize());
    let second = pairs
        .iter()
        .skip(1)
        .find(|(a, b)| a.normalize().cross(t0).length() > 1e-3 && b.normalize().cross(r0).length() > 1e-3);
    match second {
        Some(&(t1, r1)) => {
            let frame = |x: DVec3, y: DVec3| {
                let z = x.cross(y).normalize();
                DMat3::from_cols(x, z.cross(x), z)
            };
            DQuat::from_mat3(&(frame(r0, r1) * frame(t0, t1).transpose())).normalize()
        }
        None => DQuat::from_rotation_arc(t0, r0),
    }
}

/// The clip on `target`'s skeleton (see the module documentation): `m` says which of the
/// clip's joints drives each target joint. Unmapped target joints keep their rest pose
/// relative to their parent. The result has the target's names, hierarchy and bone lengths.
pub fn retarget(clip: &Clip, target: &Skeleton, m: &RigMatch) -> Clip {
    let rig = &clip.skeleton;
    let (ns, nt) = (rig.len(), target.len());
    let frames = clip.frames();
    let (rr, tr) = (rest_positions(rig), rest_positions(target));
    let align: Vec<DQuat> = (0..nt).map(|j| rest_alignment(rig, target, m, j, &rr, &tr)).collect();
    let (gr, gp) = clip.global();
    let mut rot = vec![DQuat::IDENTITY; frames * nt];
    let mut pos = vec![DVec3::ZERO; frames * nt];
    let mut g = vec![DQuat::IDENTITY; nt];
    for f in 0..frames {
        for j in 0..nt {
            g[j] = match (m.source_of[j], target.parents[j]) {
                (Some(s), _) => (gr[f * ns + s] * align[j]).normalize(),
                (None, Some(p)) => g[p],
                (None, None) => DQuat::IDENTITY,
            };
            let (r, p) = match target.parents[j] {
                None => {
                    let root = m.source_of[j].map_or(DVec3::ZERO, |s| gp[f * ns + s]);
                    (g[j], m.root_scale * root)
                }
                Some(p) => ((g[p].inverse() * g[j]).normalize(), target.offsets[j]),
            };
            rot[f * nt + j] = r;
            pos[f * nt + j] = p;
        }
    }
    let mut skeleton = target.clone();
    if let Some(s) = m.source_of[0] {
        skeleton.offsets[0] = m.root_scale * rr[s];
    }
    skeleton.channels[0].position = true;
    Clip { skeleton, frame_time: clip.frame_time, local_rotations: rot, local_positions: pos }
}

/// The clip with its joints in `reference`'s order, when it has the same joints (names) with
/// the same parents in another order (as an FBX or glTF exporter may write them); `None`
/// otherwise (or when the order is already the same).
pub fn reorder_like(clip: &Clip, reference: &Skeleton) -> Option<Clip> {
    let s = &clip.skeleton;
    let n = s.len();
    if n != reference.len() || s.names == reference.names {
        return None;
    }
    let perm: Vec<usize> = reference.names.iter().map(|name| s.index_of(name)).collect::<Option<_>>()?;
    let new_parents: Vec<Option<usize>> =
        perm.iter().map(|&old| s.parents[old].and_then(|p| reference.index_of(&s.names[p]))).collect();
    if new_parents != reference.parents {
        return None;
    }
    let skeleton = Skeleton {
        names: reference.names.clone(),
        parents: new_parents,
        offsets: perm.iter().map(|&o| s.offsets[o]).collect(),
        end_sites: perm.iter().map(|&o| s.end_sites[o]).collect(),
        channels: perm.iter().map(|&o| s.channels[o]).collect(),
    };
    let frames = clip.frames();
    let mut rot = Vec::with_capacity(frames * n);
    let mut pos = Vec::with_capacity(frames * n);
    for f in 0..frames {
        for &o in &perm {
            rot.push(clip.local_rotations[f * n + o]);
            pos.push(clip.local_positions[f * n + o]);
        }
    }
    Some(Clip { skeleton, frame_time: clip.frame_time, local_rotations: rot, local_positions: pos })
}

#[cfg(test)]
mod tests {
    use super::*;
    use zoo_motion::JointChannels;

    fn chain(names: &[&str], offsets: &[DVec3]) -> Skeleton {
        Skeleton {
            names: names.iter().map(|s| s.to_string()).collect(),
            parents: (0..names.len()).map(|j| j.checked_sub(1)).collect(),
            offsets: offsets.to_vec(),
            end_sites: vec![None; names.len()],
            channels: vec![JointChannels::default(); names.len()],
        }
    }

    /// A `root_scale` past its range (1e300 was blamed on the model's normalization.json) is
    /// refused where it enters, naming the map file.
    #[test]
    fn a_root_scale_out_of_range_is_refused_naming_the_map() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.json");
        for bad in ["1e300", "1e-300", "0", "-2"] {
            std::fs::write(&path, format!(r#"{{"joints": {{}}, "root_scale": {bad}}}"#)).unwrap();
            let e = RigMap::read(&path).unwrap_err().to_string();
            assert!(e.contains("map.json: root_scale") && e.contains("is outside its range [1e-6, 1e6]"), "{e}");
        }
        std::fs::write(&path, r#"{"joints": {}, "root_scale": 100}"#).unwrap();
        assert_eq!(RigMap::read(&path).unwrap().root_scale, Some(100.0));
    }

    #[test]
    fn namespaces_are_ignored_and_missing_joints_listed() {
        let target = chain(&["Hips", "Leg", "Foot"], &[DVec3::Y * 90.0, -DVec3::Y * 40.0, -DVec3::Y * 40.0]);
        let rig = chain(&["mixamorig:Hips", "mixamorig:Leg", "mixamorig:Foot"], &target.offsets);
        let m = RigMap::default().match_rigs(&rig, &target, true).unwrap();
        assert_eq!(m.source_of, [Some(0), Some(1), Some(2)]);
        assert!((m.root_scale - 1.0).abs() < 1e-12);
        let short = chain(&["mixamorig:Hips", "mixamorig:Leg"], &target.offsets[..2]);
        let e = RigMap::default().match_rigs(&short, &target, true).unwrap_err().to_string();
        assert!(e.contains("lacks 1 joint(s) the model needs: `Foot`"), "{e}");
    }

    #[test]
    fn a_scaled_renamed_rig_round_trips_and_a_rotated_rest_is_aligned() {
        let target = chain(&["Hips", "Leg", "Foot"], &[DVec3::Y * 90.0, -DVec3::Y * 40.0, DVec3::new(0.0, -40.0, 5.0)]);
        // The rig: 1.1x longer bones, and the leg's rest pointing along +X instead of -Y.
        let turn = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let rig = chain(
            &["r:Hips", "r:Leg", "r:Foot"],
            &[DVec3::Y * 99.0, turn * (-DVec3::Y * 44.0), turn * DVec3::new(0.0, -44.0, 5.5)],
        );
        let m = RigMap::default().match_rigs(&rig, &target, true).unwrap();
        assert!((m.root_scale - 1.0 / 1.1).abs() < 1e-12, "{}", m.root_scale);
        // The rig's motion: its leg rest turned back to pointing down, then swung.
        let swing = DQuat::from_rotation_x(0.3);
        let q0 = DQuat::from_rotation_y(0.2);
        let clip = Clip {
            skeleton: rig.clone(),
            frame_time: 1.0 / 30.0,
            local_rotations: vec![q0, q0.inverse() * swing * turn.inverse(), DQuat::IDENTITY],
            local_positions: vec![DVec3::new(11.0, 99.0, 22.0), rig.offsets[1], rig.offsets[2]],
        };
        let out = retarget(&clip, &target, &m);
        let (_, p_rig) = clip.global();
        let (_, p_out) = out.global();
        for j in 0..3 {
            let want = p_rig[j] / 1.1;
            assert!((p_out[j] - want).length() < 1e-9, "joint {j}: {} vs {want}", p_out[j]);
        }
        let back = retarget(&out, &rig, &m.inverse(3));
        let (_, p_back) = back.global();
        for j in 0..3 {
            assert!((p_back[j] - p_rig[j]).length() < 1e-9, "joint {j}");
        }
    }
}
