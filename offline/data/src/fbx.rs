//! FBX in, through ufbx (the official Rust bindings of the ufbx C library; MIT OR Unlicense).
//!
//! The skeleton is the file's bone nodes (FBX `LimbNode`s: what Blender, Maya, MotionBuilder,
//! Mixamo and capture tools export for an armature); they must form one tree. One animation
//! stack (take) is read: by name with [`ReadOptions::take`], else the first. It is sampled at
//! the file's frame rate (its global settings' time mode) from the stack's start to its end,
//! each bone's local transform evaluated by ufbx (pre- and post-rotations, pivots and rotation
//! orders included) and composed with every node above it. The file's units and axes (its
//! global settings: `UnitScaleFactor`, up/front/coord axes) are converted to zoo's centimetres,
//! Y up, right-handed, and rotations are expressed relative to the bind (rest) pose of the
//! nodes, as for glTF (`scene.rs`). Leaf bones named `*_end` (Blender's leaf bones),
//! `*End` or `*Nub` become their parent's end site. Scale must be uniform and positive on
//! every bone and above it.

use crate::clip_io::{ClipError, ClipFormat, ClipSource, ReadOptions};
use crate::scene::{self, AxisConversion, SceneRig, Trs, Xform};
use glam::{DQuat, DVec3};
use std::path::Path;
use zoo_motion::Clip;
use zoo_motion::frame::{CoordinateFrame, Handedness, UpAxis};

fn err(path: &Path, message: impl Into<String>) -> ClipError {
    ClipError::Format { path: path.to_path_buf(), format: "FBX", message: message.into() }
}

fn trs(t: &ufbx::Transform) -> Trs {
    Trs {
        t: DVec3::new(t.translation.x, t.translation.y, t.translation.z),
        r: DQuat::from_xyzw(t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w),
        s: DVec3::new(t.scale.x, t.scale.y, t.scale.z),
    }
}

/// A ufbx axis as `0..3` = +X, +Y, +Z and `3..6` = -X, -Y, -Z.
fn axis(a: ufbx::CoordinateAxis) -> Option<usize> {
    use ufbx::CoordinateAxis as A;
    match a {
        A::PositiveX => Some(0),
        A::PositiveY => Some(1),
        A::PositiveZ => Some(2),
        A::NegativeX => Some(3),
        A::NegativeY => Some(4),
        A::NegativeZ => Some(5),
        A::Unknown => None,
    }
}

/// Reads an FBX clip (see the module documentation).
pub fn read_file(path: &Path, opts: &ReadOptions) -> Result<(Clip, ClipSource), ClipError> {
    let bytes = crate::limits::read_file(path).map_err(|source| ClipError::Io {
        path: path.to_path_buf(),
        action: "cannot read",
        source,
    })?;
    read_bytes(&bytes, path, opts)
}

/// Reads an FBX clip from bytes; `path` names it in messages.
// One function: the ufbx scene is borrowed from its loader for the whole read (skeleton, take,
// sampled frames); split, every piece would carry the scene's lifetime and the same tables.
pub fn read_bytes(bytes: &[u8], path: &Path, opts: &ReadOptions) -> Result<(Clip, ClipSource), ClipError> {
    if bytes.is_empty() {
        return Err(err(path, "empty file: expected a binary FBX (`Kaydara FBX Binary` header)"));
    }
    let load = ufbx::LoadOpts { ignore_geometry: true, ignore_embedded: true, ..Default::default() };
    let scene = ufbx::load_memory(bytes, load).map_err(|e| {
        let mut why = e.description.to_string();
        if why.is_empty() {
            why = format!("{e:?}");
        }
        err(path, format!("cannot parse: {why} (is it a complete FBX file? re-export it as binary FBX 7.x)"))
    })?;
    let mut notes = Vec::new();
    let nodes = &scene.nodes;
    let nn = nodes.len();
    let is_bone: Vec<bool> = nodes.iter().map(|n| n.bone.is_some()).collect();
    let parent: Vec<Option<usize>> =
        nodes.iter().map(|n| n.parent.as_ref().map(|p| p.element.typed_id as usize).filter(|&p| p < nn)).collect();
    let joint_parent = |mut i: usize| -> Option<usize> {
        for _ in 0..nn {
            i = parent[i]?;
            if is_bone[i] {
                return Some(i);
            }
        }
        None
    };
    let name = |i: usize| nodes[i].element.name.to_string();
    let roots: Vec<usize> = (0..nn).filter(|&i| is_bone[i] && joint_parent(i).is_none()).collect();
    match roots.len() {
        0 => {
            return Err(err(
                path,
                "no skeleton: the file has no bone (LimbNode) nodes; export the armature (in Blender: Object Types > \
                 Armature)",
            ));
        }
        1 => {}
        n => {
            let names: Vec<String> = roots.iter().map(|&r| format!("`{}`", name(r))).collect();
            return Err(err(
                path,
                format!(
                    "{n} separate skeletons (roots {}): zoo reads one skeleton with a single root",
                    names.join(", ")
                ),
            ));
        }
    }
    // Depth first from the root, children in file order.
    let mut order = Vec::new();
    let mut stack = vec![roots[0]];
    while let Some(i) = stack.pop() {
        order.push(i);
        let kids: Vec<usize> =
            nodes[i].children.iter().map(|c| c.element.typed_id as usize).filter(|&c| c < nn && is_bone[c]).collect();
        stack.extend(kids.into_iter().rev());
    }
    let has_bone_child = |i: usize| nodes[i].children.iter().any(|c| is_bone[c.element.typed_id as usize]);
    let mut tips = Vec::new();
    let mut tip_of = std::collections::HashSet::new();
    let mut joints = Vec::new();
    for &i in &order {
        match joint_parent(i) {
            Some(p) if !has_bone_child(i) && scene::is_tip_name(&name(i)) && tip_of.insert(p) => tips.push((i, p)),
            _ => joints.push(i),
        }
    }
    if !tips.is_empty() {
        notes.push(format!("{} leaf bones (`*_end`, `*Nub`) read as end sites", tips.len()));
    }
    let index_of: std::collections::HashMap<usize, usize> = joints.iter().enumerate().map(|(k, &i)| (i, k)).collect();
    // Every node whose transform moves a joint: the joints, the tips and their ancestors.
    let mut needed = vec![false; nn];
    for &j in joints.iter().chain(tips.iter().map(|(t, _)| t)) {
        let mut i = Some(j);
        while let Some(k) = i {
            if needed[k] {
                break;
            }
            needed[k] = true;
            i = parent[k];
        }
    }
    // Parents first: ufbx's node depth orders them.
    let mut topo: Vec<usize> = (0..nn).filter(|&i| needed[i]).collect();
    topo.sort_by_key(|&i| nodes[i].node_depth);
    let compose = |local: &dyn Fn(usize) -> Trs, out: &mut Vec<Xform>| -> Result<(), String> {
        for &i in &topo {
            let x = local(i).uniform().map_err(|m| format!("node `{}`: {m}", name(i)))?;
            out[i] = match parent[i] {
                Some(p) if needed[p] => out[p].then(&x),
                _ => x,
            };
        }
        Ok(())
    };
    // The rest pose: the bind pose where the file has one (the bones' world matrices the
    // mesh was bound at), else the nodes' default transforms.
    let mut bind: Vec<Option<Xform>> = vec![None; nn];
    for pose in scene.poses.iter().filter(|p| p.is_bind_pose) {
        for bp in pose.bone_poses.iter() {
            let i = bp.bone_node.element.typed_id as usize;
            if i < nn && needed[i] && bind[i].is_none() {
                bind[i] = Some(
                    matrix_xform(&bp.bone_to_world)
                        .map_err(|m| err(path, format!("bind pose of `{}`: {m}", name(i))))?,
                );
            }
        }
    }
    let bound = joints.iter().filter(|&&j| bind[j].is_some()).count();
    if bound == 0 {
        notes.push(
            "no bind pose: the rest pose is the bones' default transforms (for an armature exported without its \
             mesh, often the pose at the export frame), so rotations are relative to it"
                .into(),
        );
    }
    let mut rest_world = vec![Xform::IDENTITY; nn];
    compose(&|i| trs(&nodes[i].local_transform), &mut rest_world).map_err(|m| err(path, m))?;
    for &i in &topo {
        match (bind[i], parent[i]) {
            (Some(b), _) => rest_world[i] = b,
            (None, Some(p)) if needed[p] => {
                let local = trs(&nodes[i].local_transform)
                    .uniform()
                    .map_err(|m| err(path, format!("node `{}`: {m}", name(i))))?;
                rest_world[i] = rest_world[p].then(&local);
            }
            _ => {}
        }
    }

    // The take.
    let stacks = &scene.anim_stacks;
    let stack = match &opts.take {
        Some(t) => stacks.iter().find(|s| s.element.name.as_ref() == t.as_str()).ok_or_else(|| {
            let have: Vec<String> = stacks.iter().map(|s| format!("`{}`", s.element.name)).collect();
            err(
                path,
                format!(
                    "no animation stack (take) named `{t}`; the file has {}",
                    if have.is_empty() { "none".into() } else { have.join(", ") }
                ),
            )
        })?,
        None => stacks.iter().next().ok_or_else(|| {
            err(
                path,
                "no animation: the file has no animation stack (take); export it with animation baked (in Blender: \
                 Bake Animation on)",
            )
        })?,
    };
    if opts.take.is_none() && stacks.len() > 1 {
        notes.push(format!(
            "{} takes: read the first, `{}` (choose with --take NAME)",
            stacks.len(),
            stack.element.name
        ));
    }
    let settings = &scene.settings;
    let mut fps = settings.frames_per_second;
    if !(fps.is_finite() && fps > 0.0) {
        notes.push("no frame rate in the file's settings: sampled at 30 fps".into());
        fps = 30.0;
    }
    let (t0, t1) = (stack.time_begin, stack.time_end);
    let span = (t1 - t0) * fps;
    if !(0.0..1e7).contains(&span) {
        let why = if span.is_nan() || span < 0.0 {
            "it ends before it begins".to_string()
        } else {
            format!("{span:.0} frames at {fps} fps, past the 10000000 frames zoo reads")
        };
        return Err(err(path, format!("take `{}` runs from {t0} s to {t1} s: {why}", stack.element.name)));
    }
    let frames = span.round() as usize + 1;
    if frames.saturating_mul(joints.len()) > crate::gltf::MAX_JOINT_FRAMES {
        return Err(err(
            path,
            format!(
                "take `{}`: {frames} frames of {} joints is more than zoo reads in one clip",
                stack.element.name,
                joints.len()
            ),
        ));
    }
    let (right, up, front) = (axis(settings.axes.right), axis(settings.axes.up), axis(settings.axes.front));
    let (right, up, front) = match (right, up, front) {
        (Some(r), Some(u), Some(f)) => (r, u, f),
        _ => {
            notes.push("the file does not say its axes: read as Y up, right-handed".into());
            (0, 1, 2)
        }
    };
    let mut unit = settings.unit_meters;
    if !(unit.is_finite() && unit > 0.0) {
        notes.push("the file does not say its unit: read as centimetres (FBX's default)".into());
        unit = 0.01;
    }
    let conv =
        AxisConversion::from_axes(right, up, front, unit).map_err(|m| err(path, format!("the file's axes: {m}")))?;
    let anim = &stack.anim;
    let mut world = vec![Xform::IDENTITY; nn];
    let mut samples = vec![Xform::IDENTITY; frames * joints.len()];
    for f in 0..frames {
        let t = t0 + f as f64 / fps;
        compose(&|i| trs(&ufbx::evaluate_transform(anim, &nodes[i], t)), &mut world)
            .map_err(|m| err(path, format!("at {t:.4} s: {m}")))?;
        for (k, &j) in joints.iter().enumerate() {
            samples[f * joints.len() + k] = world[j];
        }
    }
    let rig = SceneRig {
        names: joints.iter().map(|&j| name(j)).collect(),
        parents: joints.iter().map(|&j| joint_parent(j).map(|p| index_of[&p])).collect(),
        rest: joints.iter().map(|&j| rest_world[j]).collect(),
        end_sites: tips.iter().map(|&(t, p)| (index_of[&p], rest_world[t].t)).collect(),
    };
    let mut seen = std::collections::HashSet::new();
    if let Some(dup) = rig.names.iter().find(|n| !seen.insert(n.as_str())) {
        return Err(err(path, format!("two bones are named `{dup}`: joint names must be unique")));
    }
    let mut clip = scene::build_clip(&rig, &samples, 1.0 / fps, &conv);
    if opts.drop_dummy_root {
        scene::drop_still_dummy_root(&mut clip);
    }
    let frame = file_frame(right, up, front, unit);
    Ok((clip, ClipSource { format: ClipFormat::Fbx, frame, take: stack.element.name.to_string(), notes }))
}

/// A bind matrix as a rotation, translation and uniform scale.
fn matrix_xform(m: &ufbx::Matrix) -> Result<Xform, String> {
    let c = [DVec3::new(m.m00, m.m10, m.m20), DVec3::new(m.m01, m.m11, m.m21), DVec3::new(m.m02, m.m12, m.m22)];
    let s = c[0].length();
    let uniform = c.iter().all(|v| (v.length() - s).abs() <= 1e-4 * s);
    let orthogonal = c[0].dot(c[1]).abs() + c[1].dot(c[2]).abs() + c[0].dot(c[2]).abs() <= 1e-4 * s * s;
    if !(s.is_finite() && s > 0.0 && uniform && orthogonal) {
        return Err("not a rotation with a uniform scale".into());
    }
    let r = DQuat::from_mat3(&glam::DMat3::from_cols(c[0] / s, c[1] / s, c[2] / s));
    if glam::DMat3::from_cols(c[0], c[1], c[2]).determinant() <= 0.0 {
        return Err("a mirrored (negative-scale) matrix".into());
    }
    Ok(Xform { r: r.normalize(), t: DVec3::new(m.m03, m.m13, m.m23), s })
}

/// The file's frame as a [`CoordinateFrame`] (the nearest: up axis Y or Z, handedness).
fn file_frame(right: usize, up: usize, front: usize, unit: f64) -> CoordinateFrame {
    let e = |a: usize| {
        let mut v = DVec3::ZERO;
        v[a % 3] = if a < 3 { 1.0 } else { -1.0 };
        v
    };
    let right_handed = e(right).cross(e(up)).dot(e(front)) > 0.0;
    CoordinateFrame {
        metres_per_unit: unit as f32,
        up_axis: if up % 3 == 2 { UpAxis::Z } else { UpAxis::Y },
        handedness: if right_handed { Handedness::Right } else { Handedness::Left },
    }
}
