//! glTF 2.0 in and out.
//!
//! Reading (`.glb` or `.gltf`; the `gltf` crate parses and validates the JSON, zoo-data reads
//! the container, the buffers and the accessors itself with every bound checked): the first
//! skin's joints are the skeleton (parents from the node tree; nodes between joints and above
//! the root are folded in), one animation (by name with [`ReadOptions::take`], else the first)
//! is sampled at the clip's frame rate with each channel's interpolation (`STEP`, `LINEAR`:
//! lerp and slerp, `CUBICSPLINE`: Hermite), before its first key at its first value, after its
//! last at its last. The frame rate is the one zoo wrote (`extras.zoo.frame_time` of the
//! animation), else the key spacing of the channel with the most keys (a whole number of frames
//! per second when it is one within float rounding). Scale channels whose
//! values are not 1 are refused; a static uniform scale on a node is folded in. glTF is
//! metres, Y up, right-handed: positions are converted to centimetres. Leaf joints named
//! `*_end` / `*End` / `*Nub` become their parent's end site.
//!
//! Writing (`.glb` binary, `.gltf` JSON with the buffer embedded as a data URI): one node per
//! joint in skeleton order at its rest offset (identity rotation: zoo's rest pose), a `*_end`
//! node per end site, a skin over all of them, a stick-figure mesh (a thin double pyramid per
//! bone, each rigidly bound to its parent joint) so that any viewer shows the character, and
//! one animation: every joint's rotation and the translation of the root (and of any joint
//! whose translation moves), one key per frame, `LINEAR`, the frame time in
//! `extras.zoo.frame_time`.

use crate::clip_io::{ClipError, ClipFormat, ClipSource, ReadOptions};
use crate::scene::{self, AxisConversion, SceneRig, Trs, Xform};
use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::animation::{Interpolation, Property};
use base64::Engine;
use glam::{DQuat, DVec3};
use serde_json::json;
use std::borrow::Cow;
use std::path::Path;
use zoo_motion::Clip;
use zoo_motion::frame::{CoordinateFrame, Handedness, UpAxis};

const GLB_MAGIC: &[u8; 4] = b"glTF";
/// Most elements an accessor without data may declare.
const MAX_KEYS: usize = 1 << 24;
/// Most joint-frames a clip may have (a bound on what a damaged file can make zoo allocate:
/// 100 joints at 120 fps for 2.3 hours).
pub(crate) const MAX_JOINT_FRAMES: usize = 100_000_000;
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

fn err(path: &Path, message: impl Into<String>) -> ClipError {
    ClipError::Format { path: path.to_path_buf(), format: "glTF", message: message.into() }
}

/// Reads a `.glb` or `.gltf` clip (see the module documentation).
pub fn read_file(path: &Path, opts: &ReadOptions) -> Result<(Clip, ClipSource), ClipError> {
    read_bytes(&file_bytes(path)?, path, opts)
}

/// The bytes of the file at `path`.
fn file_bytes(path: &Path) -> Result<Vec<u8>, ClipError> {
    crate::limits::read_file(path).map_err(|source| ClipError::Io {
        path: path.to_path_buf(),
        action: "cannot read",
        source,
    })
}

/// Reads a glTF clip from bytes; `path` names it in messages and locates external buffers.
pub fn read_bytes(bytes: &[u8], path: &Path, opts: &ReadOptions) -> Result<(Clip, ClipSource), ClipError> {
    Ok(read_document(bytes, path, opts, Sampling::Frames)?.0)
}

/// Reads the key poses of a glTF clip: one frame per time at which any joint is keyed (the
/// union of the animation's key times), not a resampling at a frame rate, and those times in
/// seconds from the first key. What an animator's blocking pass exported with only its keys
/// holds: `zoo complete --poses FILE.glb` in-betweens them at the frames of these times.
pub fn read_key_poses(path: &Path, opts: &ReadOptions) -> Result<(Clip, Vec<f64>), ClipError> {
    let ((clip, _), times) = read_document(&file_bytes(path)?, path, opts, Sampling::Keys)?;
    Ok((clip, times))
}

/// Where an animation is sampled.
#[derive(Clone, Copy, PartialEq)]
enum Sampling {
    /// Every frame at the clip's frame rate from the first key to the last.
    Frames,
    /// At the union of the channels' key times.
    Keys,
}

/// The JSON and the BIN chunk of a `.glb`, or the whole file as JSON.
fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), String> {
    if !bytes.starts_with(GLB_MAGIC) {
        let text = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
        return match text.iter().find(|b| !b.is_ascii_whitespace()) {
            Some(b'{') => Ok((text, None)),
            None => Err("empty file: expected a binary glTF (`glTF` magic) or glTF JSON".into()),
            Some(_) => Err("not glTF: no `glTF` magic (binary .glb) and not JSON (.gltf)".into()),
        };
    }
    let u32_at =
        |o: usize| -> Option<u32> { bytes.get(o..o + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])) };
    let trunc = |what: &str| {
        format!(
            "truncated .glb: the file ends inside {what} ({} bytes); the file was cut short, copy or export it again",
            bytes.len()
        )
    };
    let version = u32_at(4).ok_or_else(|| trunc("its header"))?;
    if version != 2 {
        return Err(format!("binary glTF version {version}: zoo reads glTF 2.0 (re-export as glTF 2.0)"));
    }
    let declared = u32_at(8).ok_or_else(|| trunc("its header"))? as usize;
    if declared > bytes.len() {
        return Err(format!(
            "truncated .glb: the header declares {declared} bytes but the file has {}; the file was cut short, \
             copy or export it again",
            bytes.len()
        ));
    }
    let body = &bytes[..declared.max(12).min(bytes.len())];
    let mut at = 12;
    let mut json = None;
    let mut bin = None;
    while at < body.len() {
        let len = u32_at(at).filter(|_| at + 8 <= body.len()).ok_or_else(|| trunc("a chunk header"))? as usize;
        let kind = u32_at(at + 4).ok_or_else(|| trunc("a chunk header"))?;
        let data = body.get(at + 8..at + 8 + len).ok_or_else(|| trunc("a chunk"))?;
        match kind {
            CHUNK_JSON if json.is_none() => json = Some(data),
            CHUNK_BIN if bin.is_none() && json.is_some() => bin = Some(data),
            _ => {} // unknown chunks are skipped (glTF 2.0, GLB chunks)
        }
        at += 8 + len;
    }
    let json = json.ok_or("binary glTF without a JSON chunk")?;
    Ok((json, bin))
}

/// Every buffer's bytes: the GLB BIN chunk, a base64 data URI or a file beside `path`.
fn load_buffers<'a>(
    doc: &::gltf::Document,
    bin: Option<&'a [u8]>,
    path: &Path,
) -> Result<Vec<Cow<'a, [u8]>>, ClipError> {
    let mut out = Vec::new();
    for b in doc.buffers() {
        let data: Cow<[u8]> = match b.source() {
            ::gltf::buffer::Source::Bin => Cow::Borrowed(bin.ok_or_else(|| {
                err(path, format!("buffer {} refers to the GLB BIN chunk, which is missing", b.index()))
            })?),
            ::gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let (_, data) = uri
                    .split_once(";base64,")
                    .ok_or_else(|| err(path, format!("buffer {}: a data URI that is not base64", b.index())))?;
                Cow::Owned(
                    base64::engine::general_purpose::STANDARD
                        .decode(data)
                        .map_err(|e| err(path, format!("buffer {}: bad base64 data: {e}", b.index())))?,
                )
            }
            ::gltf::buffer::Source::Uri(uri) => {
                let file = path.parent().unwrap_or(Path::new(".")).join(uri.replace("%20", " "));
                Cow::Owned(crate::limits::read_file(&file).map_err(|e| {
                    err(
                        path,
                        format!(
                            "buffer {}: cannot read `{}` ({e}); keep it beside the .gltf",
                            b.index(),
                            file.display()
                        ),
                    )
                })?)
            }
        };
        if data.len() < b.length() {
            return Err(err(
                path,
                format!(
                    "buffer {} declares {} bytes but has {}: the file or its .bin was cut short",
                    b.index(),
                    b.length(),
                    data.len()
                ),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// An accessor's values as `f32` (FLOAT, or normalized integers), `dims` per element, every
/// bound checked.
fn read_accessor(
    acc: &::gltf::Accessor,
    buffers: &[Cow<[u8]>],
    path: &Path,
    dims: &[Dimensions],
) -> Result<Vec<f32>, ClipError> {
    let what = || format!("accessor {}", acc.index());
    if acc.sparse().is_some() {
        return Err(err(
            path,
            format!("{} is sparse, which zoo does not read (export without sparse accessors)", what()),
        ));
    }
    if !dims.contains(&acc.dimensions()) {
        return Err(err(path, format!("{} has type {:?}, expected one of {dims:?}", what(), acc.dimensions())));
    }
    let comps = acc.dimensions().multiplicity();
    let (size, normalized) = (acc.data_type().size(), acc.normalized());
    if acc.data_type() != DataType::F32 && !normalized {
        return Err(err(
            path,
            format!("{} holds {:?} values that are not normalized; expected floats", what(), acc.data_type()),
        ));
    }
    let count = acc.count();
    let Some(view) = acc.view() else {
        if count > MAX_KEYS {
            return Err(err(path, format!("{} declares {count} elements without data: the file is damaged", what())));
        }
        return Ok(vec![0.0; count * comps]); // no view: all zeros (glTF 2.0, 3.6.2.3)
    };
    let buf = &buffers[view.buffer().index()];
    let elem = size * comps;
    let stride = view.stride().unwrap_or(elem).max(elem);
    let end = |n: usize| {
        stride
            .checked_mul(n.saturating_sub(1))
            .and_then(|x| x.checked_add(acc.offset()))
            .and_then(|x| x.checked_add(elem))
    };
    let view_bytes = buf.get(view.offset()..view.offset().saturating_add(view.length())).ok_or_else(|| {
        err(path, format!("buffer view {} runs past the end of its buffer: the file is damaged", view.index()))
    })?;
    if count > 0 && end(count).is_none_or(|e| e > view_bytes.len()) {
        return Err(err(path, format!("{} runs past the end of its buffer view: the file is damaged", what())));
    }
    let mut out = Vec::with_capacity(count * comps);
    for i in 0..count {
        let base = acc.offset() + i * stride;
        for c in 0..comps {
            let b = &view_bytes[base + c * size..base + (c + 1) * size];
            let v = match acc.data_type() {
                DataType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                DataType::I8 => (b[0] as i8 as f32 / 127.0).max(-1.0),
                DataType::U8 => b[0] as f32 / 255.0,
                DataType::I16 => (i16::from_le_bytes([b[0], b[1]]) as f32 / 32767.0).max(-1.0),
                DataType::U16 => u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0,
                DataType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32 / u32::MAX as f32,
            };
            if !v.is_finite() {
                return Err(err(path, format!("{} holds a value that is not a finite number", what())));
            }
            out.push(v);
        }
    }
    Ok(out)
}

/// One animation channel on a node of the skeleton.
struct Channel {
    node: usize,
    property: Property,
    interpolation: Interpolation,
    times: Vec<f32>,
    /// Values: `comps` per key, or (in-tangent, value, out-tangent) per key for CUBICSPLINE.
    values: Vec<f32>,
    comps: usize,
}

impl Channel {
    fn value(&self, k: usize, which: usize) -> &[f32] {
        let per = if self.interpolation == Interpolation::CubicSpline { 3 } else { 1 };
        let at = (k * per + which) * self.comps;
        &self.values[at..at + self.comps]
    }

    fn key(&self, k: usize) -> &[f32] {
        self.value(k, if self.interpolation == Interpolation::CubicSpline { 1 } else { 0 })
    }

    /// The value at time `t`, `cursor` being a key index at or before `t` (advanced here:
    /// times are sampled in increasing order).
    fn sample(&self, t: f64, eps: f64, cursor: &mut usize, out: &mut [f64; 4]) {
        let times = &self.times;
        let m = times.len();
        let put = |v: &[f32], out: &mut [f64; 4]| {
            for (o, x) in out.iter_mut().zip(v) {
                *o = *x as f64;
            }
        };
        if m == 1 || t <= times[0] as f64 + eps {
            return put(self.key(0), out);
        }
        if t >= times[m - 1] as f64 - eps {
            return put(self.key(m - 1), out);
        }
        while *cursor + 1 < m && (times[*cursor + 1] as f64) <= t {
            *cursor += 1;
        }
        let k = *cursor;
        let (t0, t1) = (times[k] as f64, times[k + 1] as f64);
        if t - t0 <= eps || self.interpolation == Interpolation::Step {
            return put(self.key(k), out);
        }
        if t1 - t <= eps {
            return put(self.key(k + 1), out);
        }
        let u = (t - t0) / (t1 - t0);
        let (a, b) = (self.key(k), self.key(k + 1));
        match self.interpolation {
            Interpolation::Linear if self.property == Property::Rotation => {
                let qa = DQuat::from_xyzw(a[0] as f64, a[1] as f64, a[2] as f64, a[3] as f64).normalize();
                let qb = DQuat::from_xyzw(b[0] as f64, b[1] as f64, b[2] as f64, b[3] as f64).normalize();
                let q = qa.slerp(qb, u);
                *out = [q.x, q.y, q.z, q.w];
            }
            Interpolation::Linear | Interpolation::Step => {
                for c in 0..self.comps {
                    out[c] = a[c] as f64 + (b[c] as f64 - a[c] as f64) * u;
                }
            }
            Interpolation::CubicSpline => {
                // glTF 2.0, Appendix C: Hermite with tangents scaled by the key interval.
                let d = t1 - t0;
                let (u2, u3) = (u * u, u * u * u);
                let (h00, h10, h01, h11) =
                    (2.0 * u3 - 3.0 * u2 + 1.0, u3 - 2.0 * u2 + u, -2.0 * u3 + 3.0 * u2, u3 - u2);
                let (out_tan, in_tan) = (self.value(k, 2), self.value(k + 1, 0));
                for c in 0..self.comps {
                    out[c] = h00 * a[c] as f64
                        + h10 * d * out_tan[c] as f64
                        + h01 * b[c] as f64
                        + h11 * d * in_tan[c] as f64;
                }
            }
        }
    }
}

/// The frame time zoo's writer records in an animation's extras.
fn zoo_frame_time(anim: &::gltf::Animation) -> Option<f64> {
    let raw = anim.extras().as_ref()?;
    let v: serde_json::Value = serde_json::from_str(raw.get()).ok()?;
    v.get("zoo")?.get("frame_time")?.as_f64().filter(|t| t.is_finite() && *t > 0.0)
}

fn node_name(n: &::gltf::Node) -> String {
    n.name().map_or_else(|| format!("node{}", n.index()), str::to_string)
}

// One function: every step (the skin's joint order, the tips, the nodes that matter, the
// sampled animation) reads and refines the same node tables; split, each would take them all.
fn read_document(
    bytes: &[u8],
    path: &Path,
    opts: &ReadOptions,
    sampling: Sampling,
) -> Result<((Clip, ClipSource), Vec<f64>), ClipError> {
    let (json, bin) = split_glb(bytes).map_err(|m| err(path, m))?;
    let doc =
        ::gltf::Gltf::from_slice(json).map_err(|e| err(path, format!("not a valid glTF 2.0 document: {e}")))?.document;
    let buffers = load_buffers(&doc, bin, path)?;
    let (doc, buffers) = (&doc, &buffers[..]);
    let nodes: Vec<::gltf::Node> = doc.nodes().collect();
    let nn = nodes.len();
    let mut parent = vec![None; nn];
    for n in &nodes {
        for c in n.children() {
            if parent[c.index()].is_some() {
                return Err(err(path, format!("node `{}` has two parents: not a tree", node_name(&c))));
            }
            parent[c.index()] = Some(n.index());
        }
    }
    let skin = doc.skins().next().ok_or_else(|| {
        err(
            path,
            "no skin: zoo reads a skinned character (a skin whose joints are the skeleton); export the armature \
             with its mesh, or with `Include > Skinning` on",
        )
    })?;
    let mut notes = Vec::new();
    if doc.skins().len() > 1 {
        notes.push(format!("{} skins: read the first, `{}`", doc.skins().len(), skin.name().unwrap_or("")));
    }
    let mut is_joint = vec![false; nn];
    for j in skin.joints() {
        is_joint[j.index()] = true;
    }
    // Nearest joint ancestor; no cycles (a node has one parent, the chain is bounded by nn).
    let joint_parent = |mut i: usize| -> Option<usize> {
        for _ in 0..nn {
            i = parent[i]?;
            if is_joint[i] {
                return Some(i);
            }
        }
        None
    };
    // Joint order: the skin's when parents come first in it, else depth first.
    let skin_order: Vec<usize> = skin.joints().map(|j| j.index()).collect();
    let mut seen = vec![false; nn];
    let topological = skin_order.iter().all(|&j| {
        let ok = joint_parent(j).is_none_or(|p| seen[p]);
        seen[j] = true;
        ok
    });
    let roots: Vec<usize> = skin_order.iter().copied().filter(|&j| joint_parent(j).is_none()).collect();
    if roots.len() != 1 {
        let names: Vec<String> = roots.iter().map(|&r| format!("`{}`", node_name(&nodes[r]))).collect();
        return Err(err(
            path,
            format!(
                "the skin's joints form {} trees (roots {}): zoo reads one skeleton with a single root",
                roots.len(),
                names.join(", ")
            ),
        ));
    }
    let order: Vec<usize> = if topological {
        skin_order.clone()
    } else {
        let mut out = Vec::new();
        let mut stack = vec![roots[0]];
        while let Some(j) = stack.pop() {
            out.push(j);
            let kids: Vec<usize> = skin_order.iter().copied().filter(|&c| joint_parent(c) == Some(j)).collect();
            stack.extend(kids.into_iter().rev());
        }
        out
    };
    // Tips: leaf joints named like end sites become their parent's end site.
    let has_joint_child = |j: usize| order.iter().any(|&c| joint_parent(c) == Some(j));
    let mut tips = Vec::new();
    let mut tip_of = std::collections::HashSet::new();
    let mut joints = Vec::new();
    for &j in &order {
        let name = node_name(&nodes[j]);
        match joint_parent(j) {
            Some(p) if !has_joint_child(j) && scene::is_tip_name(&name) && tip_of.insert(p) => tips.push((j, p)),
            _ => joints.push(j),
        }
    }
    if !tips.is_empty() {
        notes.push(format!("{} end-site joints (`*_end`, `*Nub`) read as end sites", tips.len()));
    }
    let index_of: std::collections::HashMap<usize, usize> = joints.iter().enumerate().map(|(i, &n)| (n, i)).collect();

    // Nodes whose transforms matter: the joints, the tips and their ancestors, parents first.
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
    let mut topo = Vec::new();
    let mut stack: Vec<usize> = (0..nn).filter(|&i| parent[i].is_none() && needed[i]).collect();
    stack.reverse();
    while let Some(i) = stack.pop() {
        topo.push(i);
        stack.extend(nodes[i].children().map(|c| c.index()).filter(|&c| needed[c]));
    }
    let rest_local: Vec<Trs> = nodes
        .iter()
        .map(|n| {
            let (t, r, s) = n.transform().decomposed();
            Trs {
                t: DVec3::new(t[0] as f64, t[1] as f64, t[2] as f64),
                r: DQuat::from_xyzw(r[0] as f64, r[1] as f64, r[2] as f64, r[3] as f64),
                s: DVec3::new(s[0] as f64, s[1] as f64, s[2] as f64),
            }
        })
        .collect();
    let world = |local: &dyn Fn(usize) -> Trs, out: &mut Vec<Xform>| -> Result<(), String> {
        for &i in &topo {
            let x = local(i).uniform().map_err(|m| format!("node `{}`: {m}", node_name(&nodes[i])))?;
            out[i] = match parent[i] {
                Some(p) => out[p].then(&x),
                None => x,
            };
        }
        Ok(())
    };
    let mut rest_world = vec![Xform::IDENTITY; nn];
    world(&|i| rest_local[i], &mut rest_world).map_err(|m| err(path, m))?;

    // The animation.
    let anims: Vec<::gltf::Animation> = doc.animations().collect();
    let anim = match &opts.take {
        Some(name) => anims.iter().find(|a| a.name() == Some(name.as_str())).ok_or_else(|| {
            let have: Vec<String> = anims.iter().map(|a| format!("`{}`", a.name().unwrap_or(""))).collect();
            err(
                path,
                format!(
                    "no animation named `{name}`; the file has {}",
                    if have.is_empty() { "none".into() } else { have.join(", ") }
                ),
            )
        })?,
        None => anims.first().ok_or_else(|| {
            err(path, "no animation: zoo reads an animated skin (export with animation, one action baked)")
        })?,
    };
    if opts.take.is_none() && anims.len() > 1 {
        notes.push(format!(
            "{} animations: read the first, `{}` (choose with --take NAME)",
            anims.len(),
            anim.name().unwrap_or("")
        ));
    }
    let mut channels = Vec::new();
    for ch in anim.channels() {
        let node = ch.target().node().index();
        let property = ch.target().property();
        if !needed[node] || property == Property::MorphTargetWeights {
            continue;
        }
        let s = ch.sampler();
        let times = read_accessor(&s.input(), buffers, path, &[Dimensions::Scalar])?;
        let (dims, comps) = match property {
            Property::Rotation => (Dimensions::Vec4, 4),
            _ => (Dimensions::Vec3, 3),
        };
        let values = read_accessor(&s.output(), buffers, path, &[dims])?;
        let per = if s.interpolation() == Interpolation::CubicSpline { 3 } else { 1 };
        let name = node_name(&nodes[node]);
        if times.is_empty() || values.len() != times.len() * per * comps {
            return Err(err(
                path,
                format!(
                    "animation `{}`, {property:?} of `{name}`: {} keys need {} values of {comps} numbers ({} per key \
                     with {:?} interpolation), the file has {}; the file is damaged",
                    anim.name().unwrap_or(""),
                    times.len(),
                    times.len() * per,
                    per,
                    s.interpolation(),
                    values.len() / comps
                ),
            ));
        }
        if times.windows(2).any(|w| w[1] <= w[0]) {
            return Err(err(path, format!("{property:?} of `{name}`: key times do not increase; the file is damaged")));
        }
        let c = Channel { node, property, interpolation: s.interpolation(), times, values, comps };
        if property == Property::Scale {
            if let Some(k) = (0..c.times.len()).find(|&k| c.key(k).iter().any(|v| (v - 1.0).abs() > 1e-4)) {
                let v = c.key(k);
                return Err(err(
                    path,
                    format!(
                        "non-unit scale keys: `{name}` is scaled by ({}, {}, {}) at {:.4} s in animation `{}`; zoo reads \
                         rigid skeletons (scale 1): apply or remove the scale animation before exporting",
                        v[0],
                        v[1],
                        v[2],
                        c.times[k],
                        anim.name().unwrap_or("")
                    ),
                ));
            }
            continue; // all ones: nothing to do
        }
        channels.push(c);
    }
    if channels.is_empty() {
        return Err(err(
            path,
            format!("animation `{}` moves none of the skin's joints: nothing to read", anim.name().unwrap_or("")),
        ));
    }
    let t0 = channels.iter().map(|c| c.times[0] as f64).fold(f64::INFINITY, f64::min);
    let t1 = channels.iter().map(|c| *c.times.last().unwrap_or(&0.0) as f64).fold(f64::NEG_INFINITY, f64::max);
    let frame_time = zoo_frame_time(anim).unwrap_or_else(|| {
        let c = channels.iter().max_by_key(|c| c.times.len()).expect("channels is not empty");
        let n = c.times.len();
        if n < 2 {
            return 1.0 / 30.0;
        }
        let dt = (c.times[n - 1] as f64 - c.times[0] as f64) / (n - 1) as f64;
        // f32 key times: a whole frame rate within float rounding is that rate.
        let fps = 1.0 / dt;
        if (fps - fps.round()).abs() < 1e-5 * fps { 1.0 / fps.round() } else { dt }
    });
    let span = (t1 - t0) / frame_time;
    if !(span.is_finite() && span < 1e7) {
        return Err(err(path, format!("animation spans {:.3} s at {frame_time} s a frame: too many frames", t1 - t0)));
    }
    let frames = span.round() as usize + 1;
    if frames.saturating_mul(joints.len()) > MAX_JOINT_FRAMES {
        return Err(err(
            path,
            format!(
                "{frames} frames of {} joints is more than zoo reads in one clip ({MAX_JOINT_FRAMES} joint-frames)",
                joints.len()
            ),
        ));
    }
    let eps = (1e-4 * frame_time).max(4.0 * f32::EPSILON as f64 * t1.abs());
    // The times sampled, from the first key.
    let times: Vec<f64> = match sampling {
        Sampling::Frames => (0..frames).map(|f| f as f64 * frame_time).collect(),
        Sampling::Keys => {
            let mut all: Vec<f64> = channels.iter().flat_map(|c| c.times.iter().map(|&t| t as f64 - t0)).collect();
            all.sort_by(f64::total_cmp);
            all.dedup_by(|b, a| *b - *a <= eps);
            all
        }
    };
    let frames = times.len();

    let mut by_node: Vec<Vec<usize>> = vec![Vec::new(); nn];
    for (k, c) in channels.iter().enumerate() {
        by_node[c.node].push(k);
    }
    let mut cursors = vec![0usize; channels.len()];
    let mut world_now = vec![Xform::IDENTITY; nn];
    let mut samples = vec![Xform::IDENTITY; frames * joints.len()];
    let mut local = rest_local.clone();
    for (f, dt) in times.iter().enumerate() {
        let t = t0 + dt;
        for &i in &topo {
            let mut trs = rest_local[i];
            for &k in &by_node[i] {
                let c = &channels[k];
                let mut v = [0.0; 4];
                c.sample(t, eps, &mut cursors[k], &mut v);
                match c.property {
                    Property::Translation => trs.t = DVec3::new(v[0], v[1], v[2]),
                    Property::Rotation => trs.r = DQuat::from_xyzw(v[0], v[1], v[2], v[3]),
                    _ => {}
                }
            }
            local[i] = trs;
        }
        world(&|i| local[i], &mut world_now).map_err(|m| err(path, format!("at {t:.4} s: {m}")))?;
        for (jj, &j) in joints.iter().enumerate() {
            samples[f * joints.len() + jj] = world_now[j];
        }
    }
    let rig = SceneRig {
        names: joints.iter().map(|&j| node_name(&nodes[j])).collect(),
        parents: joints.iter().map(|&j| joint_parent(j).map(|p| index_of[&p])).collect(),
        rest: joints.iter().map(|&j| rest_world[j]).collect(),
        end_sites: tips.iter().map(|&(t, p)| (index_of[&p], rest_world[t].t)).collect(),
    };
    let mut seen_names = std::collections::HashSet::new();
    if let Some(dup) = rig.names.iter().find(|n| !seen_names.insert(n.as_str())) {
        return Err(err(path, format!("two joints are named `{dup}`: joint names must be unique")));
    }
    let mut clip = scene::build_clip(&rig, &samples, frame_time, &AxisConversion::gltf());
    if opts.drop_dummy_root {
        scene::drop_still_dummy_root(&mut clip);
    }
    let source = ClipSource {
        format: ClipFormat::Gltf,
        frame: CoordinateFrame::metres(UpAxis::Y, Handedness::Right),
        take: anim.name().unwrap_or("").to_string(),
        notes,
    };
    Ok(((clip, source), times))
}

// ---- writing ----

/// Appends little-endian `f32`s, padded to 4 bytes; returns (offset, length).
fn push_f32(buf: &mut Vec<u8>, values: impl IntoIterator<Item = f32>) -> (usize, usize) {
    let start = buf.len();
    for v in values {
        buf.extend_from_slice(&v.to_le_bytes());
    }
    (start, buf.len() - start)
}

/// The `*_end` name of an end-site node, unique among `names`.
fn tip_name(name: &str, names: &std::collections::HashSet<String>) -> String {
    let mut t = format!("{name}_end");
    while names.contains(&t) {
        t.push('_');
    }
    t
}

/// The document of a clip: JSON and the binary buffer (see the module documentation).
// One function: the JSON document and its binary buffer are built together, each accessor
// pointing at the bytes just appended; split, both would travel through every piece.
fn document(clip: &Clip) -> (serde_json::Value, Vec<u8>) {
    let sk = &clip.skeleton;
    let nj = sk.len();
    let frames = clip.frames();
    let to_m = 0.01; // zoo's centimetres to glTF's metres
    let m3 = |v: DVec3| [(v.x * to_m) as f32, (v.y * to_m) as f32, (v.z * to_m) as f32];
    let names: std::collections::HashSet<String> = sk.names.iter().cloned().collect();
    // Nodes: joints 0..nj, tips nj..nj+tips, then the mesh node.
    let tips: Vec<usize> = (0..nj).filter(|&j| sk.end_sites[j].is_some()).collect();
    let mut rest = vec![DVec3::ZERO; nj];
    for j in 0..nj {
        rest[j] = sk.parents[j].map_or(sk.offsets[j], |p| rest[p] + sk.offsets[j]);
    }
    let mut nodes = Vec::new();
    for j in 0..nj {
        let mut kids: Vec<usize> = (0..nj).filter(|&c| sk.parents[c] == Some(j)).collect();
        if let Some(t) = tips.iter().position(|&t| t == j) {
            kids.push(nj + t);
        }
        let mut node = json!({ "name": sk.names[j], "translation": m3(sk.offsets[j]) });
        if !kids.is_empty() {
            node["children"] = json!(kids);
        }
        nodes.push(node);
    }
    for &j in &tips {
        let e = sk.end_sites[j].unwrap_or_default();
        nodes.push(json!({ "name": tip_name(&sk.names[j], &names), "translation": m3(e) }));
    }
    let bones = nj + tips.len();
    let bone_rest =
        |b: usize| if b < nj { rest[b] } else { rest[tips[b - nj]] + sk.end_sites[tips[b - nj]].unwrap_or_default() };

    let mut buf: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut add = |(off, len): (usize, usize), acc: serde_json::Value| -> usize {
        views.push(json!({ "buffer": 0, "byteOffset": off, "byteLength": len }));
        let mut acc = acc;
        acc["bufferView"] = json!(views.len() - 1);
        accessors.push(acc);
        accessors.len() - 1
    };
    // Inverse bind matrices: the rest pose has identity rotations, so translations only.
    let ibm = push_f32(
        &mut buf,
        (0..bones).flat_map(|b| {
            let p = m3(bone_rest(b));
            [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -p[0], -p[1], -p[2], 1.0]
        }),
    );
    let ibm = add(ibm, json!({ "componentType": 5126, "count": bones, "type": "MAT4" }));

    // Stick figure: a double pyramid along each bone, bound to the bone's start joint.
    let mut pos: Vec<[f32; 3]> = Vec::new();
    let mut jnt: Vec<u16> = Vec::new();
    let mut idx: Vec<u32> = Vec::new();
    for b in 1..bones {
        let (from, owner) = if b < nj {
            match sk.parents[b] {
                Some(p) => (p, p),
                None => continue,
            }
        } else {
            (tips[b - nj], tips[b - nj])
        };
        let (a, z) = (rest[from], bone_rest(b));
        let d = z - a;
        let len = d.length();
        if len < 1e-6 {
            continue;
        }
        let axis = d / len;
        let (u, v) = axis.any_orthonormal_pair();
        let r = (0.08 * len).clamp(0.3, 3.0);
        let mid = a + 0.2 * d;
        let base = pos.len() as u32;
        let pts = [a, z, mid + r * u, mid + r * v, mid - r * u, mid - r * v];
        for p in pts {
            pos.push(m3(p));
            jnt.push(owner as u16);
        }
        for k in 0..4u32 {
            let (c, n) = (base + 2 + k, base + 2 + (k + 1) % 4);
            idx.extend_from_slice(&[base, n, c, base + 1, c, n]);
        }
    }
    let mut meshes = Vec::new();
    let mut mesh_node = None;
    if !idx.is_empty() && bones <= u16::MAX as usize {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for p in &pos {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let pa = push_f32(&mut buf, pos.iter().flatten().copied());
        let pa = add(pa, json!({ "componentType": 5126, "count": pos.len(), "type": "VEC3", "min": lo, "max": hi }));
        let start = buf.len();
        for j in &jnt {
            for k in [*j, 0, 0, 0] {
                buf.extend_from_slice(&k.to_le_bytes());
            }
        }
        let ja = add((start, buf.len() - start), json!({ "componentType": 5123, "count": jnt.len(), "type": "VEC4" }));
        let wa = push_f32(&mut buf, jnt.iter().flat_map(|_| [1.0, 0.0, 0.0, 0.0]));
        let wa = add(wa, json!({ "componentType": 5126, "count": jnt.len(), "type": "VEC4" }));
        let start = buf.len();
        for i in &idx {
            buf.extend_from_slice(&i.to_le_bytes());
        }
        let ia =
            add((start, buf.len() - start), json!({ "componentType": 5125, "count": idx.len(), "type": "SCALAR" }));
        meshes.push(json!({
            "name": "zoo_stick_figure",
            "primitives": [{ "attributes": { "POSITION": pa, "JOINTS_0": ja, "WEIGHTS_0": wa }, "indices": ia }]
        }));
        nodes.push(json!({ "name": "zoo_stick_figure", "mesh": 0, "skin": 0 }));
        mesh_node = Some(nodes.len() - 1);
    }

    // Animation: one key per frame.
    let mut animations = Vec::new();
    if frames > 0 {
        let ft = clip.frame_time;
        let t = push_f32(&mut buf, (0..frames).map(|f| (f as f64 * ft) as f32));
        let last = ((frames - 1) as f64 * ft) as f32;
        let input =
            add(t, json!({ "componentType": 5126, "count": frames, "type": "SCALAR", "min": [0.0], "max": [last] }));
        let mut samplers = Vec::new();
        let mut channels = Vec::new();
        for j in 0..nj {
            let moves = sk.parents[j].is_none()
                || (0..frames).any(|f| (clip.local_positions[f * nj + j] - sk.offsets[j]).abs().max_element() > 1e-9);
            if moves {
                let v = push_f32(&mut buf, (0..frames).flat_map(|f| m3(clip.local_positions[f * nj + j])));
                let out = add(v, json!({ "componentType": 5126, "count": frames, "type": "VEC3" }));
                samplers.push(json!({ "input": input, "output": out, "interpolation": "LINEAR" }));
                channels.push(json!({ "sampler": samplers.len() - 1, "target": { "node": j, "path": "translation" } }));
            }
            let v = push_f32(
                &mut buf,
                (0..frames).flat_map(|f| {
                    let q = clip.local_rotations[f * nj + j].normalize();
                    [q.x as f32, q.y as f32, q.z as f32, q.w as f32]
                }),
            );
            let out = add(v, json!({ "componentType": 5126, "count": frames, "type": "VEC4" }));
            samplers.push(json!({ "input": input, "output": out, "interpolation": "LINEAR" }));
            channels.push(json!({ "sampler": samplers.len() - 1, "target": { "node": j, "path": "rotation" } }));
        }
        animations.push(json!({
            "name": "zoo",
            "channels": channels,
            "samplers": samplers,
            "extras": { "zoo": { "frame_time": ft, "frames": frames } }
        }));
    }
    let mut scene_nodes = vec![0usize];
    scene_nodes.extend(mesh_node);
    let mut skin =
        json!({ "name": "zoo_skeleton", "joints": (0..bones).collect::<Vec<_>>(), "inverseBindMatrices": ibm });
    if nj > 0 {
        skin["skeleton"] = json!(0);
    }
    let mut doc = json!({
        "asset": { "version": "2.0", "generator": "zoo (zoo-data glTF writer)",
                   "extras": { "zoo": { "source_units": "cm", "written_in": "metres, Y up, right-handed" } } },
        "scene": 0,
        "scenes": [{ "name": "zoo", "nodes": scene_nodes }],
        "nodes": nodes,
        "skins": [skin],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{ "byteLength": buf.len() }],
        "animations": animations,
    });
    if !meshes.is_empty() {
        doc["meshes"] = json!(meshes);
    }
    (doc, buf)
}

/// A clip (zoo's frame: centimetres, Y up, right-handed) as binary glTF bytes.
pub fn to_glb(clip: &Clip) -> Vec<u8> {
    let (doc, bin) = document(clip);
    let mut json = serde_json::to_vec(&doc).expect("a JSON value serializes");
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let mut bin = bin;
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(GLB_MAGIC);
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
    out.extend_from_slice(&bin);
    out
}

/// A clip as glTF JSON text with the buffer embedded as a base64 data URI.
pub fn to_gltf_json(clip: &Clip) -> String {
    let (mut doc, bin) = document(clip);
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&bin));
    doc["buffers"][0]["uri"] = json!(uri);
    serde_json::to_string_pretty(&doc).expect("a JSON value serializes")
}

/// The largest offset or position (clip units) the glTF writer accepts: 32-bit floats hold
/// about 3.4e38, and 1e30 leaves room for the unit conversion and the sums of the skin.
pub const MAX_WRITE_VALUE: f64 = 1e30;

/// What glTF cannot hold: no frame (an animation needs a key), a value past [`MAX_WRITE_VALUE`].
fn check_writable(clip: &Clip) -> Result<(), String> {
    if clip.frames() == 0 {
        return Err("the clip has no frame, and a glTF animation needs at least one key".into());
    }
    let j = clip.joints();
    let far = |v: &zoo_motion::glam::DVec3| v.abs().max_element() > MAX_WRITE_VALUE;
    if let Some(i) = clip.skeleton.offsets.iter().position(far) {
        return Err(format!(
            "joint `{}` has the offset {:?}, past the {MAX_WRITE_VALUE:e} that glTF's 32-bit floats hold",
            clip.skeleton.names[i], clip.skeleton.offsets[i]
        ));
    }
    if let Some(i) = clip.local_positions.iter().position(far) {
        return Err(format!(
            "frame {} joint `{}` has the position {:?}, past the {MAX_WRITE_VALUE:e} that glTF's 32-bit floats hold",
            i / j.max(1),
            clip.skeleton.names[i % j.max(1)],
            clip.local_positions[i]
        ));
    }
    Ok(())
}

/// Writes a clip as `.glb` (binary) or, for any other name, `.gltf` JSON (see the module
/// documentation), through a temporary file and a rename.
/// A clip holding NaN or infinity is refused ([`zoo_motion::finite::check_clip`]).
/// A clip with no frame, or with an offset or position past [`MAX_WRITE_VALUE`] (glTF stores
/// 32-bit floats: a larger value would be written as infinity or `null`), is refused too.
pub fn write_file(clip: &Clip, path: &Path) -> std::io::Result<()> {
    zoo_motion::finite::check_clip(&path.display().to_string(), clip)?;
    check_writable(clip).map_err(|m| {
        std::io::Error::new(std::io::ErrorKind::InvalidData, format!("{}: {m}; nothing was written", path.display()))
    })?;
    let glb = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let bytes = if glb { to_glb(clip) } else { to_gltf_json(clip).into_bytes() };
    zoo_format::atomic::write(path, &bytes)
}
