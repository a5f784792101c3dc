"""An armature matched to a model's skeleton, and its keyframes to and from the model's poses.

Matching: each joint of the model's skeleton is the bone of the same name, or the name a bone
map gives it (Mixamo's and Rigify's shipped in `maps/`, or a JSON file); a namespace prefix
(`mixamorig:`) and case are ignored when the exact name is absent. The bone of each joint's parent
must be that bone's parent or one of its ancestors: bones between them (Mixamo's `Spine1`) and
above the model's root (bandai2's `joint_Root`) are taken at rest; other bones are left alone.

Rest pose: when the armature's bones point elsewhere at rest than the model's (an A-pose against
a T-pose, other bone rolls), each joint's rest alignment `C_j` (the rotation taking the
armature's rest directions to its mapped children onto the model's: two children give a whole
frame, one the shortest arc, a leaf bone its parent's) is put between the model's rotations and
the bones', in and out; bone lengths are the armature's (its size is the median ratio of its bone
lengths to the model's).

Conversion: the model's poses are BVH style (the hips' world position and rotation, local
rotations of the other joints, rest orientations the identity) in its frame (`zoo.frame`:
centimetres, Y up). They are converted to Blender's axes and metres with the runtime's
conversion (`zoo.Poses.convert`), to the armature's units by the ratio of its bone lengths to
the model's, and to each pose bone's rest frame:

    basis_j = rest_j^-1 * C_parent^-1 * q_j * C_j * rest_j      (q_j in the armature's axes)
    location_root = rest_root^-1 * (hips - rest_head_root)

which, with every `C` the identity (the model's own rest pose), is what Blender's own BVH importer
writes, so a clip imported with it reads back to the poses of the file. Keys are written in each bone's rotation mode (quaternion, Euler of any
order, axis-angle), Euler angles continuous from the previous key.

Quaternions are `(x, y, z, w)` in numpy arrays, as in `zoo`.
"""

import json
import os

import numpy as np

from .runtime import Refusal, zoo

def qmul(a, b):
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        -1,
    )


def qinv(q):
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def qrot(q, v):
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


MAPS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "maps")
"""The shipped bone maps: `mixamo.json`, `rigify.json` (zoo's joint names to the rig's)."""


def shipped_map(name):
    """The shipped bone map `name` (`"mixamo"`, `"rigify"`)."""
    with open(os.path.join(MAPS, f"{name}.json")) as f:
        return json.load(f)


def strip_namespace(name):
    """A bone name without its namespace: `mixamorig:Hips` -> `Hips`."""
    return name.rsplit(":", 1)[-1]


def read_bone_map(path):
    """The JSON bone map at `path` (`{"model joint": "bone", ...}`), `{}` without one."""
    if not path:
        return {}
    import bpy

    full = bpy.path.abspath(path)
    try:
        with open(full) as f:
            m = json.load(f)
    except (OSError, ValueError) as e:
        raise Refusal(f"bone map {os.path.basename(full)}: {e}") from None
    if not isinstance(m, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in m.items()):
        raise Refusal(f'bone map {os.path.basename(full)}: give a JSON object {{"model joint": "bone name", ...}}')
    return m


def rotation_channel(pose_bone):
    """The data path and size of a pose bone's rotation in its mode."""
    mode = pose_bone.rotation_mode
    if mode == "QUATERNION":
        return "rotation_quaternion", 4
    if mode == "AXIS_ANGLE":
        return "rotation_axis_angle", 4
    return "rotation_euler", 3


class Rig:
    """The armature object `arm` matched to `model`'s skeleton (raises `Refusal` listing the
    joints it cannot match; nothing is changed)."""

    def __init__(self, arm, model, bone_map=None):
        if arm is None or arm.type != "ARMATURE":
            raise Refusal("select an armature (the active object is not one)")
        self.arm = arm
        self.model = model
        z = zoo()
        sk = model.skeleton
        bones = arm.data.bones
        lower, bare = {}, {}
        for b in bones:
            lower.setdefault(b.name.lower(), []).append(b.name)
            bare.setdefault(strip_namespace(b.name).lower(), []).append(b.name)
        bone_map = bone_map or {}
        names, missing = [], []
        for n in sk.names:
            want = bone_map.get(n, n)
            if want in bones:
                names.append(want)
            elif len(lower.get(want.lower(), [])) == 1:
                names.append(lower[want.lower()][0])
            elif len(bare.get(strip_namespace(want).lower(), [])) == 1:
                names.append(bare[strip_namespace(want).lower()][0])
            else:
                missing.append(n if want == n else f"{n} (mapped to {want})")
                names.append(None)
        if missing:
            raise Refusal(
                f"armature '{arm.name}' has no bone for {len(missing)} of the model's {len(sk.names)} joints: "
                f"{', '.join(missing)}. Rename the bones or give a bone map (JSON {{\"joint\": \"bone\"}}); nothing changed"
            )
        if len(set(names)) != len(names):
            dup = sorted({b for b in names if names.count(b) > 1})
            raise Refusal(f"bones {', '.join(dup)} stand for more than one joint of the model: fix the bone map")
        for j in range(1, len(names)):
            p = names[int(sk.parents[j])]
            parent = bones[names[j]].parent
            ancestors = []
            a = parent
            while a is not None:
                ancestors.append(a.name)
                a = a.parent
            if p not in ancestors:
                raise Refusal(
                    f"bone '{names[j]}' (joint {sk.names[j]}) has parent "
                    f"'{parent.name if parent else 'none'}' but the model's parent joint is bone '{p}', which is not "
                    "above it: the armature's hierarchy must be the model's"
                )
        self.bones = names
        k = len(names)
        rest = np.empty((k, 4))
        heads = np.empty((k, 3))
        for j, n in enumerate(names):
            b = bones[n]
            q = b.matrix_local.to_quaternion()
            rest[j] = (q.x, q.y, q.z, q.w)
            heads[j] = tuple(b.head_local)
        self.rest = rest / np.linalg.norm(rest, axis=1, keepdims=True)
        self.rest_head = heads[0].copy()
        # Armature units per metre: the median ratio of the bones' rest lengths to the model's.
        mpu = float(model.frame.metres_per_unit)
        par = sk.parents.astype(int)
        arm_len = np.linalg.norm(heads[1:] - heads[par[1:]], axis=1)
        model_len = np.linalg.norm(sk.offsets[1:].astype(np.float64), axis=1) * mpu
        ok = model_len > 1e-4
        if not ok.any():
            raise Refusal("the model's skeleton has no bone of non-zero length")
        ratios = arm_len[ok] / model_len[ok]
        self.units_per_metre = float(np.median(ratios))
        if not self.units_per_metre > 0:
            raise Refusal(f"armature '{arm.name}' has zero-length bones where the model has bones")
        self.proportion_error = float(np.max(np.abs(ratios / self.units_per_metre - 1.0)))
        # The rest pose: the model's rest offsets in the armature's axes against the bones'.
        off = z.convert_positions(sk.offsets, model.frame, z.BLENDER).astype(np.float64)
        d_arm = heads[1:] - heads[par[1:]]
        d_mod = off[1:]
        n = np.linalg.norm(d_arm, axis=1) * np.linalg.norm(d_mod, axis=1)
        cos = np.sum(d_arm * d_mod, axis=1) / np.where(n > 0, n, 1)
        self.rest_angle = float(np.degrees(np.arccos(np.clip(cos[n > 0], -1, 1))).max()) if (n > 0).any() else 0.0
        # The rest alignment of each joint: the armature's rest directions onto the model's.
        rest_pos = np.zeros((k, 3))
        for j in range(1, k):
            rest_pos[j] = rest_pos[par[j]] + off[j]
        align = np.tile([0.0, 0.0, 0.0, 1.0], (k, 1))
        for j in range(k):
            kids = [c for c in range(1, k) if par[c] == j]
            pairs = [(heads[c] - heads[j], rest_pos[c] - rest_pos[j]) for c in kids]
            pairs = [(a, b) for a, b in pairs if np.linalg.norm(a) > 1e-9 and np.linalg.norm(b) > 1e-9]
            if pairs:
                align[j] = frame_alignment(pairs)
            elif j > 0:
                align[j] = align[par[j]]
        # A rest pose that agrees to 0.001 degrees is the model's: no alignment at all.
        angle = 2 * np.degrees(np.arccos(np.clip(np.abs(align[:, 3]), 0, 1)))
        align[angle < 1e-3] = [0.0, 0.0, 0.0, 1.0]
        self.align = align
        self.parent_align = np.tile([0.0, 0.0, 0.0, 1.0], (k, 1))
        self.parent_align[1:] = align[par[1:]]
        self.aligned_degrees = float(angle.max())

    @property
    def joints(self):
        return len(self.bones)

    def warnings(self):
        """What may make the result differ from the model's (bone lengths, rest pose)."""
        w = []
        if self.proportion_error > 0.05:
            w.append(f"the armature's proportions differ from the model's by up to {100 * self.proportion_error:.0f}%")
        return w

    def describe(self):
        """How the armature maps onto the model, for the status bar."""
        rest = (
            f"rest pose aligned (bones up to {self.rest_angle:.0f} deg from the model's)"
            if self.aligned_degrees > 0
            else "the model's rest pose"
        )
        return f"{self.units_per_metre:.3g} armature units per metre, {rest}"

    # --- reading ------------------------------------------------------------------------------

    def sample(self, action, frames):
        """The action's poses at `frames`, BVH style in the model's frame: `(hips (T, 3),
        rotations (T, K, 4))`, float32. Channels without an F-curve hold the pose bone's value."""
        import mathutils

        z = zoo()
        frames = [float(f) for f in frames]
        t, k = len(frames), self.joints
        basis = np.empty((t, k, 4))
        pose = self.arm.pose.bones
        for j, name in enumerate(self.bones):
            pb = pose[name]
            path, size = rotation_channel(pb)
            values = self._channel_values(action, pb, path, size, frames)
            mode = pb.rotation_mode
            for i in range(t):
                if mode == "QUATERNION":
                    q = mathutils.Quaternion(values[i]).normalized()
                elif mode == "AXIS_ANGLE":
                    q = mathutils.Quaternion(values[i][1:], values[i][0])
                else:
                    q = mathutils.Euler(values[i], mode).to_quaternion()
                basis[i, j] = (q.x, q.y, q.z, q.w)
        loc = self._channel_values(action, pose[self.bones[0]], "location", 3, frames)
        # q_j = C_parent * rest_j * basis_j * rest_j^-1 * C_j^-1
        q = qmul(qmul(qmul(qmul(self.parent_align, self.rest), basis), qinv(self.rest)), qinv(self.align))
        hips = (self.rest_head + qrot(self.rest[0], loc)) / self.units_per_metre
        return z.convert_world(hips, q, z.BLENDER, self.model.frame)

    @staticmethod
    def _channel_values(action, pose_bone, path, size, frames):
        data_path = pose_bone.path_from_id(path)
        out = np.empty((len(frames), size))
        current = getattr(pose_bone, path)
        for i in range(size):
            fc = action.fcurves.find(data_path, index=i) if action else None
            if fc is None:
                out[:, i] = current[i]
            else:
                out[:, i] = [fc.evaluate(f) for f in frames]
        return out

    # --- writing ------------------------------------------------------------------------------

    def channels(self, hips, rotations):
        """Pose-bone values of BVH-style poses in the model's frame: `(basis (T, K, 4),
        location (T, 3))` (the root's location; rotations in the bones' rest frames)."""
        z = zoo()
        h, q = z.convert_world(hips, rotations, self.model.frame, z.BLENDER)
        q = q.astype(np.float64)
        basis = qmul(qmul(qmul(qmul(qinv(self.rest), qinv(self.parent_align)), q), self.align), self.rest)
        h = h.astype(np.float64) * self.units_per_metre
        loc = qrot(qinv(self.rest[0]), h - self.rest_head)
        return basis, loc

    def write(
        self, action, frames, hips, rotations, drop=None, previous=None, strength=1.0, keep_root=False, keys=None, fit=False
    ):
        """Keys the poses (BVH style, the model's frame) at `frames` on every matched bone's
        rotation and the root's location. Existing keys at frames where `drop(frame)` is true
        are removed first (default: those at `frames`). `previous`: the frame whose value the
        first key continues from (quaternion signs, Euler angles); none for a new action.
        `strength` blends each channel between the action's own curves (0: their values at
        `frames`, exactly) and the poses (1); `keep_root`: the root's location keeps the
        action's curves. `keys`: key only these of `frames` (default: all); with `fit`, their
        Bezier handles are fitted to the values at all `frames` (`fit_handles`). Returns the
        largest difference, over every channel, between the F-curves and the values at `frames`
        as the fit predicts Blender evaluates them (0 without `fit`), and the most keys written on
        one F-curve."""
        import mathutils

        basis, loc = self.channels(hips, rotations)
        strength = float(strength)
        old_of = (lambda pb, path, size: self._channel_values(action, pb, path, size, list(frames))) if action else None
        frames = np.asarray(frames, dtype=np.float64)
        keyed = set(np.round(frames).astype(int).tolist())
        if drop is None:
            drop = lambda x: int(round(x)) in keyed  # noqa: E731
        pose = self.arm.pose.bones
        residual, most = 0.0, 0
        for j, name in enumerate(self.bones):
            pb = pose[name]
            path, size = rotation_channel(pb)
            mode = pb.rotation_mode
            prev = None
            if previous is not None:
                prev = self._channel_values(action, pb, path, size, [float(previous)])[0]
            values = np.empty((len(frames), size))
            for i, b in enumerate(basis[:, j]):
                q = mathutils.Quaternion((b[3], b[0], b[1], b[2]))
                if mode == "QUATERNION":
                    v = np.array([q.w, q.x, q.y, q.z])
                    if prev is not None and np.dot(v, prev) < 0:
                        v = -v
                elif mode == "AXIS_ANGLE":
                    axis, angle = q.to_axis_angle()
                    v = np.array([angle, axis.x, axis.y, axis.z])
                else:
                    e = q.to_euler(mode, mathutils.Euler(prev, mode)) if prev is not None else q.to_euler(mode)
                    v = np.array(e)
                values[i] = v
                prev = v
            if strength < 1.0 and old_of is not None:
                values = blend(old_of(pb, path, size), values, strength, mode)
            data_path = pb.path_from_id(path)
            for c in range(size):
                r, n = self._key(action, data_path, c, name, frames, values[:, c], drop, keys, fit)
                residual, most = max(residual, r), max(most, n)
        root = pose[self.bones[0]]
        if old_of is not None and (keep_root or strength < 1.0):
            loc = blend(old_of(root, "location", 3), loc, 0.0 if keep_root else strength, "LOCATION")
        data_path = root.path_from_id("location")
        for c in range(3):
            r, n = self._key(action, data_path, c, self.bones[0], frames, loc[:, c], drop, keys, fit)
            residual, most = max(residual, r), max(most, n)
        return residual, most

    @staticmethod
    def _key(action, data_path, index, group, frames, values, drop, keys, fit):
        """One channel of `write`: every frame keyed, or only `keys` (their handles fitted to
        every frame's value with `fit`); returns the fit's largest residual and the keys written."""
        if keys is None:
            write_channel(action, data_path, index, group, frames, values, drop)
            return 0.0, len(frames)
        at = np.isin(np.round(frames).astype(int), np.round(np.asarray(keys)).astype(int))
        residual = write_channel(
            action, data_path, index, group, frames[at], values[at], drop, fit=(frames, values) if fit else None
        )
        return residual, int(at.sum())


def frame_alignment(pairs):
    """The rotation `(x, y, z, w)` taking the first direction of each pair onto the second: the
    whole frame of the first two that are not parallel, else the shortest arc of the first."""
    import mathutils

    a0, b0 = (mathutils.Vector(v).normalized() for v in pairs[0])
    for a, b in pairs[1:]:
        a1, b1 = mathutils.Vector(a).normalized(), mathutils.Vector(b).normalized()
        if a1.cross(a0).length > 1e-3 and b1.cross(b0).length > 1e-3:

            def frame(x, y):
                z = x.cross(y).normalized()
                return mathutils.Matrix((x, z.cross(x), z)).transposed()

            q = (frame(b0, b1) @ frame(a0, a1).transposed()).to_quaternion()
            return np.array([q.x, q.y, q.z, q.w])
    q = a0.rotation_difference(b0)
    return np.array([q.x, q.y, q.z, q.w])


def blend(old, new, strength, mode):
    """Channel values between the action's (`old`, strength 0: exactly) and the model's (`new`,
    strength 1: exactly): linear, quaternions on the same hemisphere and normalised."""
    if strength <= 0.0:
        return np.array(old, dtype=np.float64)
    if strength >= 1.0:
        return new
    old = np.asarray(old, dtype=np.float64)
    if mode == "QUATERNION":
        new = np.where(np.sum(old * new, axis=-1, keepdims=True) < 0, -new, new)
        v = (1 - strength) * old + strength * new
        return v / np.linalg.norm(v, axis=-1, keepdims=True)
    return (1 - strength) * old + strength * new


def write_channel(action, data_path, index, group, frames, values, drop, fit=None):
    """Keys `values` at `frames` on one F-curve (made when absent), after removing its keys at
    frames where `drop(frame)` is true. The other keys stay as they were, handles included (the
    F-curve's update recomputes automatic handles; theirs are put back). `fit`: `(frames,
    values)` of every frame the keys stand for: the new keys are Bezier keys with aligned handles
    fitted to them (`fit_handles`). Returns the fit's largest residual (0 without one)."""
    fc = action.fcurves.find(data_path, index=index)
    if fc is None:
        fc = action.fcurves.new(data_path, index=index, action_group=group)
    points = fc.keyframe_points
    n_old = len(points)
    interpolation = "LINEAR"
    if n_old:
        co = np.empty(2 * n_old, dtype=np.float32)
        points.foreach_get("co", co)
        xs = co[0::2]
        gone = [i for i in range(n_old) if drop(float(xs[i]))]
        gone_set = set(gone)
        kept = [i for i in range(n_old) if i not in gone_set]
        if kept:
            before = [i for i in kept if xs[i] < frames[0]]
            interpolation = points[before[-1] if before else kept[0]].interpolation
        for i in reversed(gone):
            points.remove(points[i], fast=True)
    if fit is not None:
        interpolation = "BEZIER"
    handle = "AUTO_CLAMPED" if fit is None else "ALIGNED"
    nk = len(points)
    kept_co = np.empty(2 * nk, dtype=np.float32)
    kept_left = np.empty(2 * nk, dtype=np.float32)
    kept_right = np.empty(2 * nk, dtype=np.float32)
    if nk:
        points.foreach_get("co", kept_co)
        points.foreach_get("handle_left", kept_left)
        points.foreach_get("handle_right", kept_right)
    n = len(frames)
    points.add(n)
    co = np.empty(2 * (nk + n), dtype=np.float32)
    points.foreach_get("co", co)
    co[2 * nk :: 2] = frames
    co[2 * nk + 1 :: 2] = values
    points.foreach_set("co", co)
    for i in range(nk, nk + n):
        p = points[i]
        p.interpolation = interpolation
        p.handle_left_type = handle
        p.handle_right_type = handle
        # The keys written are not selected: the next in-between's range is not taken from them.
        p.select_control_point = False
        p.select_left_handle = False
        p.select_right_handle = False
    fc.update()
    total = nk + n
    co = np.empty(2 * total, dtype=np.float32)
    points.foreach_get("co", co)
    xs = co[0::2]
    left = np.empty(2 * total, dtype=np.float32)
    right = np.empty(2 * total, dtype=np.float32)
    points.foreach_get("handle_left", left)
    points.foreach_get("handle_right", right)
    if nk:
        at = np.searchsorted(xs, kept_co[0::2])
        if np.all(at < len(xs)) and np.array_equal(xs[np.minimum(at, len(xs) - 1)], kept_co[0::2]):
            for c in range(2):
                left[2 * at + c] = kept_left[c::2]
                right[2 * at + c] = kept_right[c::2]
            points.foreach_set("handle_left", left)
            points.foreach_set("handle_right", right)
    if fit is None:
        return 0.0
    new = np.isin(xs, np.asarray(frames, dtype=np.float32))
    interp = [p.interpolation for p in points]
    left2, right2, residual = fit_handles(
        xs.astype(np.float64),
        co[1::2].astype(np.float64),
        left.reshape(-1, 2).astype(np.float64),
        right.reshape(-1, 2).astype(np.float64),
        interp,
        new,
        np.asarray(fit[0], dtype=np.float64),
        np.asarray(fit[1], dtype=np.float64),
    )
    points.foreach_set("handle_left", left2.astype(np.float32).ravel())
    points.foreach_set("handle_right", right2.astype(np.float32).ravel())
    return residual


def bezier_t(x0, x1, x2, x3, x):
    """The parameters `t` in [0, 1] where the cubic Bezier with control abscissas `x0..x3`
    (handles within the segment, as Blender's correction makes them) reaches `x` (bisection)."""
    lo, hi = np.zeros_like(x), np.ones_like(x)
    for _ in range(45):
        t = (lo + hi) / 2
        u = 1 - t
        xt = u * u * u * x0 + 3 * u * u * t * x1 + 3 * u * t * t * x2 + t * t * t * x3
        below = xt < x
        lo = np.where(below, t, lo)
        hi = np.where(below, hi, t)
    return (lo + hi) / 2


def fit_handles(xs, ys, left, right, interpolation, new, sx, sy, aligned=True):
    """Handles of the new keys of one F-curve (`new`: a mask over its keys `xs`, `ys`, with
    handles `left`, `right` `(n, 2)` and `interpolation`), fitted to the samples `(sx, sy)`.

    Each new key gets aligned handles a third of the way to its neighbouring keys in time, with
    one slope `m` (the handles at `y -/+ m * dx`); the slopes of all new keys are the least-squares
    solution over every sample strictly between two keys, with Blender's evaluation of the
    segments: a Bezier segment (the left key's interpolation) with each handle longer in time
    than the segment shortened to it, as Blender does; a linear or constant one as it is (no
    slope enters it). The other keys keep their handles. Returns `(left, right, residual)`: the new
    handles and the largest difference between the fitted curve and the samples."""
    left, right = left.copy(), right.copy()
    n = len(xs)
    idx = np.nonzero(new)[0]
    # The unknown slopes: one per new key (aligned handles), or one per handle (free).
    col_l = {int(k): (c if aligned else 2 * c) for c, k in enumerate(idx)}
    col_r = {int(k): (c if aligned else 2 * c + 1) for c, k in enumerate(idx)}
    unknowns = len(idx) if aligned else 2 * len(idx)
    dl = np.zeros(n)
    dr = np.zeros(n)
    for k in idx:
        dl[k] = (xs[k] - xs[k - 1]) / 3 if k > 0 else 1.0
        dr[k] = (xs[k + 1] - xs[k]) / 3 if k + 1 < n else 1.0
    rows, rhs, parts = [], [], []
    for a in range(n - 1):
        b = a + 1
        inside = (sx > xs[a] + 1e-6) & (sx < xs[b] - 1e-6)
        if not inside.any():
            continue
        x, y = sx[inside], sy[inside]
        coef = np.zeros((len(x), unknowns))
        if interpolation[a] == "BEZIER":
            # The handles' time offsets and value offsets (per unit slope for a new key).
            hx_a = dr[a] if new[a] else right[a, 0] - xs[a]
            hx_b = dl[b] if new[b] else xs[b] - left[b, 0]
            # Blender shortens a handle longer in time than the segment to the segment's length.
            span = xs[b] - xs[a]
            fa = min(1.0, span / hx_a) if hx_a > 0 else 1.0
            fb = min(1.0, span / hx_b) if hx_b > 0 else 1.0
            t = bezier_t(xs[a], xs[a] + fa * hx_a, xs[b] - fb * hx_b, xs[b], x)
            u = 1 - t
            b0, b1, b2, b3 = u**3, 3 * u * u * t, 3 * u * t * t, t**3
            known = (b0 + b1) * ys[a] + (b2 + b3) * ys[b]
            if new[a]:
                coef[:, col_r[a]] += b1 * fa * dr[a]
            else:
                known = known + b1 * fa * (right[a, 1] - ys[a])
            if new[b]:
                coef[:, col_l[b]] -= b2 * fb * dl[b]
            else:
                known = known + b2 * fb * (left[b, 1] - ys[b])
        elif interpolation[a] == "LINEAR":
            w = (x - xs[a]) / (xs[b] - xs[a])
            known = (1 - w) * ys[a] + w * ys[b]
        elif interpolation[a] == "CONSTANT":
            known = np.full(len(x), ys[a])
        else:
            continue
        rows.append(coef)
        rhs.append(y - known)
        parts.append(known)
    if not rows or not len(idx):
        return left, right, 0.0
    A, r = np.concatenate(rows), np.concatenate(rhs)
    m = np.linalg.lstsq(A, r, rcond=None)[0] if A.any() else np.zeros(unknowns)
    for k in idx:
        left[k] = (xs[k] - dl[k], ys[k] - m[col_l[int(k)]] * dl[k])
        right[k] = (xs[k] + dr[k], ys[k] + m[col_r[int(k)]] * dr[k])
    residual = float(np.max(np.abs(A @ m - r)))
    return left, right, residual
