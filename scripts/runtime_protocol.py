"""An independent implementation of docs/runtime-protocol.md and its task pages (numpy + the
onnxruntime Python wheel), written from those pages alone: it runs an exported zoo model of any
task (both keyframe designs) on the inputs of a reference file (`zoo export --onnx RUN --out
MODEL.onnx --reference REFERENCE.json`) and compares every step with the reference's numbers.

usage: runtime_protocol.py MODEL.onnx REFERENCE.json [--report REPORT.json] [--atol 1e-3] [--rtol 2e-5]

Prints the largest difference of every compared field per case and exits with status 1 when one
exceeds the documented bound `atol + rtol * S`, in model units, `S` the largest absolute value of
the reference's field in the case (normalised values are compared after scaling by their
deviation; weights, t_rel and quaternions as they are, with S = 1 for quaternions; quaternions of
engine poses up to sign). Discrete values (contacts, key indices, window starts, random
generator states, flags) must match exactly. --report writes the same figures as JSON.
"""
import argparse
import base64
import json
import math
import sys

import numpy as np
import onnxruntime as ort

F = np.float32
MASK64 = (1 << 64) - 1


# ---------------------------------------------------------------------------------------------
# Quaternions (x, y, z, w), float64 unless said otherwise


def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], dtype=a.dtype)


def qconj(q):
    return np.array([-q[0], -q[1], -q[2], q[3]], dtype=q.dtype)


def qrot(q, v):
    u = q[:3]
    t = 2.0 * np.cross(u, v)
    return v + q[3] * t + np.cross(u, t)


def qnormalize(q):
    return q / np.sqrt(np.dot(q, q))


def qy(angle):
    """Rotation about +Y by `angle` radians."""
    return np.array([0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2)])


def q_axis_angle(axis, angle):
    s = math.sin(angle / 2)
    return np.array([axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2)])


def from_scaled_axis(v):
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return qnormalize(np.array([v[0] * 0.5, v[1] * 0.5, v[2] * 0.5, 1.0]))
    return q_axis_angle(v / angle, angle)


def yaw_part(q):
    t = np.array([0.0, q[1], 0.0, q[3]])
    n = np.dot(t, t)
    return np.array([0.0, 0.0, 0.0, 1.0]) if n < 1e-24 else t / math.sqrt(n)


def slerp(a, b, t):
    a = qnormalize(a)
    b = qnormalize(b)
    dot = float(np.dot(a, b))
    if dot < 0.0:
        b = -b
        dot = -dot
    if 1.0 - dot < 0.01:
        wa, wb = 1.0 - t, t
    else:
        omega = math.acos(min(max(dot, -1.0), 1.0))
        s = math.sin(omega)
        wa, wb = math.sin((1.0 - t) * omega) / s, math.sin(t * omega) / s
    return qnormalize(wa * a + wb * b)


def quat_between(a, b):
    c = np.cross(a, b)
    w = math.sqrt(np.dot(a, a) * np.dot(b, b)) + np.dot(a, b)
    return np.array([c[0], c[1], c[2], w])


def shortest_arc(a, b):
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        return np.array([0.0, 0.0, 0.0, 1.0])
    a, b = a / na, b / nb
    if np.dot(a, b) < -1.0 + 1e-12:
        # Half a turn about any axis perpendicular to a (reference inputs avoid this case).
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return q_axis_angle(axis / np.linalg.norm(axis), math.pi)
    return qnormalize(quat_between(a, b))


def wahba(a, b):
    """Horn's method: the unit quaternion of the largest eigenvalue of the 4x4 matrix."""
    s = sum(np.outer(u, v) for u, v in zip(a, b))
    (sxx, sxy, sxz), (syx, syy, syz), (szx, szy, szz) = s
    m = np.array([[sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
                  [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
                  [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
                  [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz]])
    vals, vecs = np.linalg.eigh(m)
    v = vecs[:, int(np.argmax(vals))]
    q = qnormalize(np.array([v[1], v[2], v[3], v[0]]))
    return q if np.all(np.isfinite(q)) else np.array([0.0, 0.0, 0.0, 1.0])


def root_delta(p0, q0, p1, q1):
    """Root motion from (p0, q0) to (p1, q1): displacement in q0's space, turn about +Y."""
    inv = qconj(q0)
    turn = qnormalize(qmul(inv, q1))
    yaw = 2.0 * math.atan2(turn[1], turn[3])
    if yaw > math.pi:
        yaw -= 2 * math.pi
    if yaw < -math.pi:
        yaw += 2 * math.pi
    return qrot(inv, p1 - p0), yaw


class Pose:
    """An engine pose (section 3 of the page)."""

    def __init__(self, d):
        self.root_position = np.array(d["root_position"], dtype=np.float64)
        self.root_rotation = np.array(d["root_rotation"], dtype=np.float64)
        self.hips_position = np.array(d["hips_position"], dtype=np.float64)
        self.local_rotations = [np.array(q, dtype=np.float64) for q in d["local_rotations"]]

    def hips_world(self):
        return self.root_position + qrot(self.root_rotation, self.hips_position)

    def hips_world_rotation(self):
        return qnormalize(qmul(self.root_rotation, self.local_rotations[0]))


def pose_dict(root_position, root_rotation, delta, delta_yaw, hips_position, local, global_positions=None):
    d = {"root_position": root_position, "root_rotation": root_rotation, "root_delta_position": delta,
         "root_delta_yaw": delta_yaw, "hips_position": hips_position, "local_rotations": local}
    if global_positions is not None:
        d["global_positions"] = global_positions
    return d


def set_world(hips, rotations):
    """An engine pose from the hips' world position and the world-space rotations (joint 0: the
    hips' world rotation): section 3's `set_world`."""
    hips_rotation = qnormalize(rotations[0])
    root_position = np.array([hips[0], 0.0, hips[2]])
    root_rotation = yaw_part(hips_rotation)
    inv = qconj(root_rotation)
    local = [qnormalize(q) for q in rotations]
    local[0] = qnormalize(qmul(inv, hips_rotation))
    return root_position, root_rotation, qrot(inv, hips - root_position), local


# ---------------------------------------------------------------------------------------------
# The file


class Model:
    def __init__(self, path):
        self.sess = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
        self.meta = self.sess.get_modelmeta().custom_metadata_map
        if self.meta.get("zoo.format_version") != "5":
            sys.exit(f"{path}: zoo.format_version is {self.meta.get('zoo.format_version')}, this script reads 5")
        self.task = self.meta["zoo.task"]
        self.norm = {k: {m: np.array(v[m], dtype=F) for m in ("mean", "std")}
                     for k, v in json.loads(self.meta["zoo.normalization"]).items()}
        self.skeleton = json.loads(self.meta["zoo.skeleton"])
        self.parents = self.skeleton["parents"]
        self.offsets = [np.array(o, dtype=np.float64) for o in self.skeleton["offsets"]]
        self.slots = json.loads(self.meta["zoo.state"])
        self.inputs = {i.name: i for i in self.sess.get_inputs()}
        self.section = json.loads(self.meta[f"zoo.{self.task}"])

    def normalize(self, v, g):
        return ((v - self.norm[g]["mean"]) / self.norm[g]["std"]).astype(F)

    def denormalize(self, v, g):
        return (v * self.norm[g]["std"] + self.norm[g]["mean"]).astype(F)

    def zero_state(self):
        return {s["input"]: np.zeros((1, self.inputs[s["input"]].shape[1]), dtype=F) for s in self.slots}

    def step(self, state, feed, outputs):
        """One run of the step graph: `feed` the frame inputs, `state` read and replaced."""
        feed = {k: np.asarray(v, dtype=F).reshape(1, -1) for k, v in feed.items()}
        feed.update(state)
        out = self.sess.run(outputs + [s["output"] for s in self.slots], feed)
        for s, value in zip(self.slots, out[len(outputs):]):
            state[s["input"]] = value.astype(F)
        return [o.reshape(-1).astype(F) for o in out[:len(outputs)]]


# ---------------------------------------------------------------------------------------------
# Comparison


MISMATCH = 1e30  # the difference recorded for values of the wrong shape


class Comparison:
    """Per case and field: the largest difference, the number of values compared and the scale
    `S` (the largest absolute value of the reference's field, model units). A field passes when
    its largest difference is at most `atol + rtol * S` (docs/runtime-protocol.md, section 10);
    a discrete field when it matches exactly."""

    def __init__(self, atol, rtol):
        self.atol, self.rtol = atol, rtol
        self.cases = []

    def case(self, name):
        c = {"name": name, "fields": {}}
        self.cases.append(c)
        return c

    @staticmethod
    def add(case, field, diff, values, scale=0.0, exact=False):
        f = case["fields"].setdefault(field, {"max_diff": 0.0, "values": 0, "scale": 0.0, "exact": exact})
        f["max_diff"] = max(f["max_diff"], float(diff))
        f["values"] += int(values)
        f["scale"] = max(f["scale"], float(scale))

    def bound(self, f):
        return 0.0 if f["exact"] else self.atol + self.rtol * f["scale"]

    def values(self, case, field, mine, theirs, scale=None):
        a = np.asarray(mine, dtype=np.float64).reshape(-1)
        b = np.asarray(theirs, dtype=np.float64).reshape(-1)
        if a.shape != b.shape:
            self.add(case, field, MISMATCH, 1)
            return
        if scale is None:
            scale = np.max(np.abs(b)) if b.size else 0.0
        self.add(case, field, np.max(np.abs(a - b)) if a.size else 0.0, a.size, scale)

    def normalised(self, case, field, mine, theirs, std):
        """Normalised values, compared in model units (each difference times its deviation)."""
        std = np.asarray(std, dtype=np.float64)
        a = np.asarray(mine, dtype=np.float64).reshape(-1, len(std))
        b = np.asarray(theirs, dtype=np.float64).reshape(-1, len(std))
        if a.shape != b.shape:
            self.add(case, field, MISMATCH, 1)
            return
        self.add(case, field, np.max(np.abs(a - b) * std), a.size, np.max(np.abs(b) * std))

    def exact(self, case, field, mine, theirs):
        """Discrete values: any mismatch fails (recorded as a difference of 1)."""
        self.add(case, field, 0.0 if mine == theirs else 1.0, 1, exact=True)

    def rotations(self, case, field, mine, theirs):
        """Quaternions, up to sign (q and -q are the same rotation)."""
        a = np.asarray(mine, dtype=np.float64).reshape(-1, 4)
        b = np.asarray(theirs, dtype=np.float64).reshape(-1, 4)
        if a.shape != b.shape:
            self.add(case, field, MISMATCH, 1)
            return
        d = np.minimum(np.abs(a - b).max(axis=1), np.abs(a + b).max(axis=1))
        self.add(case, field, d.max() if d.size else 0.0, a.size, 1.0)

    def poses(self, case, field, mine, theirs):
        if len(mine) != len(theirs):
            self.add(case, field, MISMATCH, 1)
            return
        for m, t in zip(mine, theirs):
            for key in ("root_position", "root_delta_position", "root_delta_yaw", "hips_position"):
                self.values(case, field, m[key], t[key])
            self.rotations(case, field, [m["root_rotation"]], [t["root_rotation"]])
            self.rotations(case, field, m["local_rotations"], t["local_rotations"])
            if "global_positions" in t or "global_positions" in m:
                self.values(case, field, m.get("global_positions", []), t.get("global_positions", []))

    def worst(self):
        return max((f["max_diff"] for c in self.cases for f in c["fields"].values()), default=0.0)

    def failed(self, f):
        return not f["max_diff"] <= self.bound(f)


# ---------------------------------------------------------------------------------------------
# Transition (sections 4 to 6 of the page)


def features(y, r_prev):
    r = y[:3]
    f = np.empty_like(y)
    f[:3] = r - r_prev
    f[3:] = (y[3:].reshape(-1, 3) - r).reshape(-1)
    return f


def decode(f, r_prev):
    r = (r_prev + f[:3]).astype(F)
    y = np.empty_like(f)
    y[:3] = r
    y[3:] = (f[3:].reshape(-1, 3) + r).reshape(-1)
    return y, r


def heightmap_sample(hm, x, z):
    """Bilinear height at (x, z), clamped to the grid, in float32."""
    cols, rows = hm["cols"], hm["rows"]
    cell, ox, oz = F(hm["cell"]), F(hm["origin"][0]), F(hm["origin"][1])
    fx = min(max((F(x) - ox) / cell, F(0)), F(cols - 1))
    fz = min(max((F(z) - oz) / cell, F(0)), F(rows - 1))
    x0, z0 = int(math.floor(fx)), int(math.floor(fz))
    x1, z1 = min(x0 + 1, cols - 1), min(z0 + 1, rows - 1)
    tx, tz = F(fx - F(x0)), F(fz - F(z0))
    h = lambda i, k: F(hm["heights"][k * cols + i])
    a = h(x0, z0) * (F(1) - tx) + h(x1, z0) * tx
    b = h(x0, z1) * (F(1) - tx) + h(x1, z1) * tx
    return F(a * (F(1) - tz) + b * tz)


def terrain_patch(hm, r, side, extent):
    extent = F(extent)
    step = extent / F(side - 1) if side > 1 else F(0)
    half = extent * F(0.5)
    out = np.empty(side * side, dtype=F)
    for i in range(side):
        for j in range(side):
            x = F(r[0]) - half + F(j) * step
            z = F(r[2]) - half + F(i) * step
            out[i * side + j] = heightmap_sample(hm, x, z) - F(r[1])
    return out


class Transition:
    def __init__(self, model):
        self.m = model
        self.task = model.section
        self.start = None
        if "zoo.start_graph" in model.meta:
            self.start = ort.InferenceSession(base64.b64decode(model.meta["zoo.start_graph"]),
                                              providers=["CPUExecutionProvider"])

    def run(self, past, y_t, y_next, n, heightmap):
        """Section 6, steps 1-4: the raw frames p_0 .. p_N."""
        m = self.m
        c = []
        for k, y in enumerate(past):
            if k > 0:
                r_prev = past[k - 1][:3]
            elif len(past) > 1:
                r_prev = 2 * past[0][:3] - past[1][:3]
            else:
                r_prev = past[0][:3]
            c.append(m.normalize(features(y, r_prev), "x"))
        tv = np.concatenate([m.normalize(features(y_t, 2 * y_t[:3] - y_next[:3]), "x"),
                             m.normalize(y_next - y_t, "velocity")])
        state = m.zero_state()
        if self.start is not None:
            feed = {i.name: (tv if i.name == "target" else c[0]).reshape(1, -1) for i in self.start.get_inputs()}
            names = [o.name for o in self.start.get_outputs()]
            for name, value in zip(names, self.start.run(names, feed)):
                state[name] = value.astype(F)
        has_base, y_last = "base" in m.inputs, past[-1]
        terrain = self.task["terrain"]

        def interpolation(i):
            w = F(i + 1) / F(n + 1)
            b = np.empty_like(y_t)
            b[:3] = (y_t[:3] - y_last[:3]) / F(n + 1)
            rel_last = (y_last[3:].reshape(-1, 3) - y_last[:3]).reshape(-1)
            rel_t = (y_t[3:].reshape(-1, 3) - y_t[:3]).reshape(-1)
            b[3:] = (F(1) - w) * rel_last + w * rel_t
            return m.normalize(b, "x")

        tta = self.task.get("time_to_arrival")

        def embed(left):
            # Section 6: the time to arrival, pairs of sin and cos from a quarter turn over
            # `max` frames to one radian a frame, geometric (computed in f64, fed as f32).
            dims, top = int(tta["dims"]), max(int(tta["max"]), 1)
            t, pairs, slow = float(min(left, top)), dims // 2, (np.pi / 2) / top
            out = np.empty(dims, dtype=F)
            for i in range(pairs):
                a = i / (pairs - 1) if pairs > 1 else 0.0
                w = slow * (1.0 / slow) ** a
                out[2 * i], out[2 * i + 1] = np.sin(t * w), np.cos(t * w)
            return out

        def step(x, r, base, left):
            v = m.denormalize(x, "x")
            y = v.copy()
            y[:3] = r
            y[3:] = (v[3:].reshape(-1, 3) + r).reshape(-1)
            feed = {"x": x}
            if has_base:
                feed["base"] = base
            if tta is not None:
                feed["tta"] = embed(left)
            if self.task["offset_input"]:
                feed["offset"] = m.normalize(y_t - y, "offset")
            if terrain is not None:
                patch = terrain_patch(heightmap, r, terrain["side"], terrain["extent"])
                feed["terrain"] = m.normalize(patch, "terrain")
            return m.step(state, feed, ["x_next"])[0]

        x, r = c[0], past[0][:3].copy()
        for k in range(1, len(past)):
            step(x, r, c[k], len(past) + n - k)
            x, r = c[k], past[k][:3].copy()
        raw = []
        for i in range(n + 1):
            x = step(x, r, interpolation(i) if has_base else None, n - i)
            p, r = decode(m.denormalize(x, "x"), r)
            raw.append(p)
        return raw

    def blend(self, raw, y_t):
        """Section 6, steps 5-6: the target blend; returns the blended frames and the miss."""
        n, b = len(raw) - 1, int(self.task["target_blend"])
        e = (y_t - raw[n]).astype(F)
        dist = np.linalg.norm(e.reshape(-1, 3).astype(F), axis=1).astype(F)
        out = []
        for i in range(n + 1):
            if b == 0:
                w = 1.0 if i == n else 0.0
            else:
                w = 1.0 - (n - i) / b if n - i < b else 0.0
            out.append((raw[i] + F(w) * e).astype(F) if w > 0 else raw[i].copy())
        return out, F(dist.sum() / F(len(dist))), F(dist.max())

    @staticmethod
    def fallback(blended, y_last, y_t, miss, thresholds):
        """Section 6, step 7: the fallback towards interpolation; returns the frames and the weight."""
        if thresholds is None:
            return blended, 0.0
        start, full = F(thresholds["start"]), F(thresholds["full"])
        if not math.isfinite(miss):
            w = 1.0
        elif full <= start:
            w = 1.0 if miss >= start else 0.0
        else:
            w = float(np.clip((miss - start) / (full - start), 0.0, 1.0))
        if w <= 0:
            return blended, 0.0
        n = len(blended) - 1
        out = []
        for i, f in enumerate(blended):
            a = F(i + 1) / F(n + 1)
            lerp = y_last + a * (y_t - y_last)
            out.append((f + F(w) * (lerp - f)).astype(F))
        return out, w

    def forward_kinematics(self, pose):
        """Section 6b, step 1: global positions of an engine pose over the model's skeleton."""
        k = len(self.m.parents)
        rot, pos = [None] * k, [None] * k
        for j in range(k):
            if j == 0:
                rot[0] = pose.hips_world_rotation()
                pos[0] = pose.hips_world()
            else:
                p = self.m.parents[j]
                pos[j] = qrot(rot[p], self.m.offsets[j]) + pos[p]
                rot[j] = qmul(rot[p], pose.local_rotations[j])
        return np.concatenate(pos).astype(F)

    def fit(self, positions, reference):
        """Section 6b, step 3: local rotations fitted to one frame of global positions."""
        return fit_rotations(self.m.parents, self.m.offsets, positions, reference)

    def posed(self, past_poses, target_pose, blended):
        """Section 6b: the engine poses of a transition started from engine poses."""
        n = len(blended) - 1
        world = lambda p: [p.hips_world_rotation()] + p.local_rotations[1:]
        last = past_poses[-1]
        q_from, q_to = world(last), world(target_pose)
        root_p, root_q = np.array([last.hips_world()[0], 0.0, last.hips_world()[2]]), yaw_part(last.hips_world_rotation())
        out = []
        for f, frame in enumerate(blended):
            w = (f + 1) / (n + 1)
            positions = [frame[3 * j:3 * j + 3].astype(np.float64) for j in range(len(self.m.parents))]
            reference = [slerp(a, b, w) for a, b in zip(q_from, q_to)]
            fitted = self.fit(positions, reference)
            hips, hips_rotation = positions[0], qnormalize(fitted[0])
            p1, q1 = np.array([hips[0], 0.0, hips[2]]), yaw_part(hips_rotation)
            delta, yaw = root_delta(root_p, root_q, p1, q1)
            root_p, root_q = p1, q1
            inv = qconj(q1)
            local = [qnormalize(q) for q in fitted]
            local[0] = qnormalize(qmul(inv, hips_rotation))
            gr, gp = [None] * len(fitted), [None] * len(fitted)
            for j, q in enumerate(fitted):
                if j == 0:
                    gr[0], gp[0] = q, positions[0]
                else:
                    p = self.m.parents[j]
                    gp[j] = qrot(gr[p], self.m.offsets[j]) + gp[p]
                    gr[j] = qmul(gr[p], q)
            out.append(pose_dict(p1, q1, delta, yaw, qrot(inv, hips - p1), local, gp))
        return out


def check_transition(model, ref, cmp):
    t = Transition(model)
    for case in ref["transition"]:
        c = cmp.case(case["name"])
        past_poses = [Pose(p) for p in case["past_poses"]]
        target_pose, next_pose = Pose(case["target_pose"]), Pose(case["next_pose"])
        past = [t.forward_kinematics(p) for p in past_poses]
        y_t, y_next = t.forward_kinematics(target_pose), t.forward_kinematics(next_pose)
        cmp.values(c, "past", past + [y_t, y_next], case["past"] + [case["target"], case["next"]])
        n = case["length"]
        raw = t.run(past, y_t, y_next, n, case["heightmap"])
        cmp.values(c, "raw", raw, case["raw"])
        blended, miss, miss_max = t.blend(raw, y_t)
        cmp.values(c, "blended", blended, case["blended"])
        cmp.values(c, "miss", [miss, miss_max], [case["miss"]["mean"], case["miss"]["max"]])
        frames, weight = t.fallback(blended, past[-1], y_t, miss, case["fallback"])
        cmp.values(c, "fallback_weight", weight, case["fallback_weight"])
        cmp.values(c, "frames", frames, case["frames"])
        if case["posed"]:  # empty where the skeleton leaves a twist to rounding (section 6b)
            cmp.poses(c, "posed", t.posed(past_poses, target_pose, blended), case["posed"])


# ---------------------------------------------------------------------------------------------
# Keyframes (section 7 and runtime-protocol-keyframes.md)


def interval(frames, t):
    k = 0
    while k + 2 < len(frames) and frames[k + 1] < t:
        k += 1
    a, b = frames[k], frames[k + 1]
    return k, k + 1, F((t - a) / max(b - a, 1))


def hit_keys(poses, keys, frames, key_groups, fixed):
    """Step 4 of the keyframes loop: every key frame set to its key, the miss spread over the
    frames before it (per value, per group; quaternion groups taken on the output's hemisphere).
    The runtime keeps poses and offsets in float32, computing each update in float64."""
    out = np.array(poses, dtype=F)
    n, d = out.shape
    grp = np.array(key_groups, dtype=int) if key_groups else np.zeros(d, dtype=int)
    scratch = np.zeros(d, dtype=F)
    for g in range(int(grp.max()) + 1):
        idx = np.where(grp == g)[0]
        quaternion = len(key_groups) > 0 and len(idx) == 4
        prev = None
        for k, fb in enumerate(frames):
            if fb >= n or (len(fixed) and fixed[k][g] != 1.0):
                continue
            key = keys[k][idx].astype(np.float64)
            dot = float(np.sum(key * out[fb, idx].astype(np.float64)))
            target = (-key if quaternion and dot < 0.0 else key)
            eb = target - out[fb, idx].astype(np.float64)
            ea = eb if prev is None else scratch[idx].astype(np.float64)
            span = max(fb - (prev or 0), 1)
            for f in range(0 if prev is None else prev + 1, fb):
                w = 1.0 if prev is None else (f - prev) / span
                out[f, idx] = (out[f, idx].astype(np.float64) + (1.0 - w) * ea + w * eb).astype(F)
            out[fb, idx] = target.astype(F)
            scratch[idx] = eb.astype(F)
            prev = fb
        if prev is not None:
            for f in range(prev + 1, n):
                out[f, idx] = (out[f, idx].astype(np.float64) + scratch[idx].astype(np.float64)).astype(F)
    return out


# Euler angles: an order is its three channel axes (0 = X, 1 = Y, 2 = Z); the rotation is
# R_axes[0](a) R_axes[1](b) R_axes[2](c), angles in degrees.


def axis_quat(axis, angle):
    v = [0.0, 0.0, 0.0]
    v[axis] = 1.0
    return q_axis_angle(v, angle)


def euler_to_quat(axes, degrees):
    a = [math.radians(v) for v in degrees]
    return qmul(qmul(axis_quat(axes[0], a[0]), axis_quat(axes[1], a[1])), axis_quat(axes[2], a[2]))


def quat_matrix(q):
    """The rotation matrix of a unit quaternion, m[row][col]."""
    x, y, z, w = q
    x2, y2, z2 = x + x, y + y, z + z
    xx, xy, xz, yy, yz, zz = x * x2, x * y2, x * z2, y * y2, y * z2, z * z2
    wx, wy, wz = w * x2, w * y2, w * z2
    return [[1.0 - (yy + zz), xy - wz, xz + wy],
            [xy + wz, 1.0 - (xx + zz), yz - wx],
            [xz - wy, yz + wx, 1.0 - (xx + yy)]]


def quat_to_euler(axes, q):
    i, j, k = axes
    r = quat_matrix(qnormalize(q))
    sign = 1.0 if (j + 3 - i) % 3 == 1 else -1.0
    sb = min(max(sign * r[i][k], -1.0), 1.0)
    b = math.asin(sb)
    if abs(sb) < 1.0 - 1e-12:
        a = math.atan2(-sign * r[j][k], r[k][k])
        c = math.atan2(-sign * r[i][j], r[i][i])
    else:
        a, c = math.atan2(sign * r[k][j], r[j][j]), 0.0
    return [math.degrees(a), math.degrees(b), math.degrees(c)]


def euler_near(axes, q, prev):
    e = quat_to_euler(axes, q)
    if prev is None:
        return e

    def unwrap(v):
        return [v[i] + 360.0 * round_half_away((prev[i] - v[i]) / 360.0) for i in range(3)]

    a = unwrap(e)
    b = unwrap([e[0] + 180.0, 180.0 - e[1], e[2] + 180.0])
    dist = lambda v: sum(abs(v[i] - prev[i]) for i in range(3))
    return b if dist(b) < dist(a) else a


def round_half_away(x):
    return math.floor(x + 0.5) if x >= 0 else -math.floor(-x + 0.5)


# Blender's default F-curve (interpolation BEZIER, handles AUTO_CLAMPED, smoothing CONT_ACCEL).


def fcurve_first_pass(points, i):
    x, y = points[i]
    n = len(points)
    prev = points[i - 1] if i > 0 else None
    nxt = points[i + 1] if i + 1 < n else None
    if prev is None and nxt is None:
        return {"x": x, "y": y, "left": [x, y], "right": [x, y], "locked": True}
    pa = prev if prev is not None else (2 * x - nxt[0], 2 * y - nxt[1])
    pb = nxt if nxt is not None else (2 * x - prev[0], 2 * y - prev[1])
    len_a, len_b = x - pa[0], pb[0] - x
    slope = (y - pa[1]) / len_a + (pb[1] - y) / len_b
    left = [x - len_a / 3.0, y - slope * len_a / 6.0]
    right = [x + len_b / 3.0, y + slope * len_b / 6.0]
    locked = prev is None or nxt is None
    if prev is not None and nxt is not None:
        d1, d2 = prev[1] - y, nxt[1] - y
        if (d1 <= 0 and d2 <= 0) or (d1 >= 0 and d2 >= 0):
            locked = True
        else:
            lv = rv = False
            if (d1 <= 0 and prev[1] > left[1]) or (d1 > 0 and prev[1] < left[1]):
                left[1], lv = prev[1], True
            if (d1 <= 0 and nxt[1] < right[1]) or (d1 > 0 and nxt[1] > right[1]):
                right[1], rv = nxt[1], True
            h1, h2 = left[0] - x, x - right[0]
            if lv:
                right[1] = y + (y - left[1]) / h1 * h2
            elif rv:
                left[1] = y + (y - right[1]) / h2 * h1
    if locked:
        left[1] = right[1] = y
    return {"x": x, "y": y, "left": left, "right": right, "locked": locked}


def thomas(a, b, c, d):
    n = len(b)
    c1, d1 = [0.0] * n, [0.0] * n
    for i in range(n):
        den = b[i] - (a[i] * c1[i - 1] if i > 0 else 0.0)
        if den == 0.0:
            return None
        c1[i] = c[i] / den
        d1[i] = (d[i] - (a[i] * d1[i - 1] if i > 0 else 0.0)) / den
    x = d1
    for i in range(n - 2, -1, -1):
        x[i] -= c1[i] * x[i + 1]
    return x


def solve_within(a, b, c, d, lo, hi):
    n = len(b)
    sa, sb, sc, sd = list(a), list(b), list(c), list(d)
    locked, unlocks = [False] * n, [0] * n

    def lock(i, v):
        sa[i], sb[i], sc[i], sd[i] = 0.0, 1.0, 0.0, v

    while True:
        h = thomas(sa, sb, sc, sd)
        if h is None:
            return None
        overshoot = any_locked = every = False
        while True:
            for i in range(n):
                if lo[i] <= h[i] <= hi[i]:
                    continue
                overshoot = True
                target = hi[i] if h[i] > hi[i] else lo[i]
                if target != 0.0 or every:
                    locked[i] = True
                    lock(i, target)
                    any_locked = True
            every = True
            if not overshoot or any_locked:
                break
        unlocked = False
        if not any_locked:
            for i in range(n):
                if not locked[i] or unlocks[i] >= 2:
                    continue
                prev = h[i - 1] if i > 0 else h[n - 1]
                nxt = h[i + 1] if i + 1 < n else h[0]
                state = a[i] * prev + b[i] * h[i] + c[i] * nxt - d[i]
                relax = -state * b[i]
                if (relax > 0 and h[i] < hi[i]) or (relax < 0 and h[i] > lo[i]):
                    sa[i], sb[i], sc[i], sd[i] = a[i], b[i], c[i], d[i]
                    locked[i] = False
                    unlocks[i] += 1
                    unlocked = True
        if not overshoot and not unlocked:
            return h


def clamp_range(lo, hi, i, dy):
    if dy > 0:
        hi[i], lo[i] = min(hi[i], dy), 0.0
    elif dy < 0:
        hi[i], lo[i] = 0.0, max(lo[i], dy)
    else:
        lo[i] = hi[i] = 0.0


def handle_adjustment(h, dx):
    fac = dx / (h[0] + dx / 3.0)
    if fac < 1.0:
        h[0] *= fac
        h[1] *= fac
    return 1.0 - 3.0 * h[0] / dx


def smooth_run(keys):
    count = len(keys)
    if count <= 2:
        return
    dx, dy = [math.nan] * count, [math.nan] * count
    for i in range(1, count):
        dx[i] = keys[i]["x"] - keys[i - 1]["x"]
        dy[i] = keys[i]["y"] - keys[i - 1]["y"]
    l = [1.0] * count
    for i in range(1, count - 1):
        l[i] = dx[i + 1] / dx[i]
    lo, hi = [-sys.float_info.max] * count, [sys.float_info.max] * count
    for i in range(1, count):
        clamp_range(lo, hi, i - 1, dy[i])
        clamp_range(lo, hi, i, dy[i] * l[i])
    a, b, c, d = [0.0] * count, [0.0] * count, [0.0] * count, [0.0] * count
    first = [keys[0]["right"][0] - keys[0]["x"], keys[0]["right"][1] - keys[0]["y"]]
    first_adj = handle_adjustment(first, dx[1])
    b[0], d[0] = 1.0, first[1]
    k = keys[-1]
    last = [k["x"] - k["left"][0], k["y"] - k["left"][1]]
    last_adj = handle_adjustment(last, dx[count - 1])
    b[-1], d[-1] = 1.0, last[1]
    for i in range(1, count - 1):
        a[i], b[i], c[i], d[i] = l[i] * l[i], 2.0 * (l[i] + 1.0), 1.0 / l[i + 1], dy[i] * l[i] * l[i] + dy[i + 1]
    b[1] += l[1] * first_adj
    b[count - 2] += last_adj
    h = solve_within(a, b, c, d, lo, hi)
    if h is None:
        return
    for i in range(1, count - 1):
        keys[i]["left"][1] = keys[i]["y"] - h[i] / l[i]
        keys[i]["right"][1] = keys[i]["y"] + h[i]


def cubic(q0, q1, q2, q3, s):
    u = 1.0 - s
    return u * u * u * q0 + 3.0 * u * u * s * q1 + 3.0 * u * s * s * q2 + s * s * s * q3


class FCurve:
    def __init__(self, points):
        self.keys = [fcurve_first_pass(points, i) for i in range(len(points))]
        start = 0
        for j in range(1, len(points)):
            if self.keys[j]["locked"]:
                smooth_run(self.keys[start:j + 1])
                start = j

    def eval(self, x):
        first, last = self.keys[0], self.keys[-1]
        if x <= first["x"]:
            return first["y"]
        if x >= last["x"]:
            return last["y"]
        i = max(i for i, k in enumerate(self.keys) if k["x"] <= x)
        a, b = self.keys[i], self.keys[i + 1]
        if x == a["x"]:
            return a["y"]
        p1, p2 = list(a["right"]), list(b["left"])
        # Handles kept within the segment's time span.
        h1 = [a["x"] - p1[0], a["y"] - p1[1]]
        h2 = [b["x"] - p2[0], b["y"] - p2[1]]
        span, len1, len2 = b["x"] - a["x"], abs(h1[0]), abs(h2[0])
        if len1 + len2 != 0.0:
            if len1 > span:
                f = span / len1
                p1 = [a["x"] - f * h1[0], a["y"] - f * h1[1]]
            if len2 > span:
                f = span / len2
                p2 = [b["x"] - f * h2[0], b["y"] - f * h2[1]]
        lo_s, hi_s = 0.0, 1.0
        for _ in range(80):
            m = 0.5 * (lo_s + hi_s)
            if cubic(a["x"], p1[0], p2[0], b["x"], m) < x:
                lo_s = m
            else:
                hi_s = m
        return cubic(a["y"], p1[1], p2[1], b["y"], 0.5 * (lo_s + hi_s))


def pose_quats(pose, joints):
    """Root position and unit rotations [x, y, z, w] of a humanoid pose (w, x, y, z per joint)."""
    rot = []
    for j in range(joints):
        w, x, y, z = pose[3 + 4 * j:7 + 4 * j]
        q = np.array([x, y, z, w], dtype=np.float64)
        rot.append(q / math.sqrt(np.dot(q, q)) if np.dot(q, q) > 1e-12 else np.array([0.0, 0.0, 0.0, 1.0]))
    return np.array(pose[:3], dtype=np.float64), rot


class Inbetween:
    """The in-betweening design: features, Bezier poses, the correction composed."""

    def __init__(self, model):
        s = model.section["inbetween"]
        self.axes = s["euler_axes"]
        self.j = len(self.axes)
        self.d, self.g = 3 + 4 * self.j, 1 + self.j
        self.gap_unit = float(s["gap_unit"])
        self.mean = np.array(s["mean"], dtype=np.float64)
        self.std = np.array(s["std"], dtype=np.float64)
        self.width = s["input_width"]
        self.residual = s.get("residual", "envelope")
        self.fallback = s.get("fallback")
        self.groups = [0, 0, 0] + [1 + j for j in range(self.j) for _ in range(4)]

    def bezier(self, frames, keys, fixes):
        n, j = frames[-1] + 1, self.j
        decoded = [pose_quats(k, j) for k in keys]
        fixing = lambda g: [k for k in range(len(frames)) if fixes(k, g)]
        out = np.zeros((n, self.d))
        for c in range(3):
            curve = FCurve([(float(frames[k]), decoded[k][0][c]) for k in fixing(0)])
            out[:, c] = [curve.eval(float(f)) for f in range(n)]
        for jj in range(j):
            ks = fixing(1 + jj)
            prev, pts = None, []
            for k in ks:
                prev = euler_near(self.axes[jj], decoded[k][1][jj], prev)
                pts.append((float(frames[k]), prev))
            curves = [FCurve([(f, e[c]) for f, e in pts]) for c in range(3)]
            last = decoded[ks[0]][1][jj]
            for f in range(n):
                q = euler_to_quat(self.axes[jj], [curves[c].eval(float(f)) for c in range(3)])
                last = -q if np.dot(q, last) < 0 else q
                out[f, 3 + 4 * jj:7 + 4 * jj] = [last[3], last[0], last[1], last[2]]
        return out

    def shot(self, frames, keys, fixed):
        """Features (f32, frames x width), Bezier poses (f64) and the residual's weights."""
        d, g = self.d, self.g
        keys = [np.array(k, dtype=F).astype(np.float64) for k in keys]
        fixes = lambda k, gr: len(fixed) == 0 or fixed[k][gr] == 1.0
        bez = self.bezier(frames, keys, fixes)
        n = len(bez)
        per_group = [[(k, frames[k]) for k in range(len(frames)) if fixes(k, gr)] for gr in range(g)]

        def around(ks, t):
            i = sum(1 for _, f in ks if f <= t)
            if i == 0:
                return None
            return ks[i - 1], ks[i] if i < len(ks) else ks[i - 1]

        def envelope(a, c, t):
            if c <= a:
                return 0.0
            s = (t - a) / (c - a)
            return 4.0 * s * (1.0 - s)

        def key_value(key, b, i):
            if i < 3:
                return key[i]
            q = 3 + 4 * ((i - 3) // 4)
            return -key[i] if float(np.dot(key[q:q + 4], b[q:q + 4])) < 0.0 else key[i]

        features = np.zeros((n, self.width), dtype=F)
        env = np.zeros((n, d))
        lerp = [[None] * d for _ in range(n)]
        for t in range(n):
            b = bez[t]
            genv = []
            for ks in per_group:
                ar = around(ks, t)
                genv.append(0.0 if ar is None else envelope(ar[0][1], ar[1][1], t))
            prev, nxt = np.zeros(d), np.zeros(d)
            for i in range(d):
                ks = per_group[self.groups[i]]
                ar = around(ks, t)
                a, c = (ar[0][0], ar[1][0]) if ar is not None else (ks[0][0], ks[0][0])
                prev[i] = key_value(keys[a], b, i) - b[i]
                nxt[i] = key_value(keys[c], b, i) - b[i]
                env[t, i] = genv[self.groups[i]]
                if ar is not None and ar[1][1] > ar[0][1] and t > ar[0][1]:
                    fa, fc = ar[0][1], ar[1][1]
                    lerp[t][i] = (fa, fc, (t - fa) / (fc - fa))
                else:
                    lerp[t][i] = (t, t, 0.0)
            ar = around(per_group[0], t)
            a, c = (ar[0][1], ar[1][1]) if ar is not None else (0, 0)
            row = np.concatenate([(b - self.mean) / self.std, prev / self.std, nxt / self.std,
                                  [(t - a) / (c - a) if c > a else 0.0, (c - a) / self.gap_unit],
                                  [1.0 if any(f == t for _, f in ks) else 0.0 for ks in per_group], genv])
            features[t] = row.astype(F)
        return features, bez, env, lerp

    def kept(self, frames, fixed, r):
        """The fallback's kept share of the residual per frame (1 everywhere without one)."""
        n = len(r)
        kept, edge = np.ones(n), np.ones(n)
        if self.fallback is None:
            return kept
        whole = [len(fixed) == 0 or all(v == 1.0 for v in fixed[k]) for k in range(len(frames))]
        pairs = []
        for k, (a, b) in enumerate(zip(frames[:-1], frames[1:])):
            if b - a < 2 or not (whole[k] and whole[k + 1]):
                continue
            # The size and the weight in float32, as the page says the thresholds are.
            z = F(math.sqrt(float(np.mean(r[a + 1:b] ** 2))))
            gaps = self.fallback["gaps"]
            th = next((g for g in gaps if b - a <= g["up_to"]), gaps[-1])
            start, full = F(th["start"]), F(th["full"])
            w = 1.0 if not np.isfinite(z) else min(max(float((z - start) / (full - start)), 0.0), 1.0)
            pairs.append((a, b, 1.0 - w))
            edge[a], edge[b] = min(edge[a], pairs[-1][2]), min(edge[b], pairs[-1][2])
        for a, b, k in pairs:
            for t in range(a, b + 1):
                u = (t - a) / (b - a)
                kept[t] = edge[a] + (k - edge[a]) * 2.0 * u if u <= 0.5 else edge[b] + (k - edge[b]) * 2.0 * (1.0 - u)
        return kept

    def compose(self, frames, fixed, bez, env, lerp, correction):
        n, d = bez.shape
        c = correction.astype(np.float64)
        r = np.zeros((n, d))
        for t in range(n):
            for v in range(d):
                if self.residual == "key-lerp":
                    fa, fc, s = lerp[t][v]
                    r[t, v] = c[t, v] - (c[fa, v] + s * (c[fc, v] - c[fa, v]))
                else:
                    r[t, v] = env[t, v] * c[t, v]
        kept = self.kept(frames, fixed, r)
        out = np.zeros((n, d), dtype=F)
        for t in range(n):
            for v in range(d):
                out[t, v] = F(bez[t, v] + kept[t] * r[t, v] * self.std[v])
        return out


# The foot lock between the keys of a humanoid completion.


def legs_of(skeleton):
    parents = skeleton["parents"]
    legs = []
    for ankle, name in enumerate(skeleton["names"]):
        if "foot" not in name.lower():
            continue
        knee = parents[ankle]
        if knee < 0 or parents[knee] < 0:
            continue
        legs.append({"hip": parents[knee], "knee": knee, "ankle": ankle,
                     "toes": [j for j, p in enumerate(parents) if p == ankle]})
    return legs


CONTACT_HEIGHT, LOCK_SPEED, SWING_SPEED, STRENGTH, LIFT_SPEED, LIFT_HEIGHT = 5.0, 8.0, 16.0, 0.5, 4.0, 4.0


def two_bone_ik(hip, knee, ankle, goal):
    a, b = np.linalg.norm(knee - hip), np.linalg.norm(ankle - knee)
    to_goal = goal - hip
    dist = np.linalg.norm(to_goal)
    if a <= 1e-6 or b <= 1e-6 or dist <= 1e-6:
        return knee, ankle
    u = to_goal / dist
    d = min(max(dist, abs(a - b) + 1e-4), a + b - 1e-4)
    pole = (knee - hip) - u * np.dot(knee - hip, u)
    if np.linalg.norm(pole) > 1e-5:
        p = pole / np.linalg.norm(pole)
    else:  # any unit vector perpendicular to u (glam's any_orthonormal_vector)
        sign = 1.0 if u[2] >= 0 else -1.0
        aa = -1.0 / (sign + u[2])
        bb = u[0] * u[1] * aa
        p = np.array([bb, sign + u[1] * u[1] * aa, -u[1]])
    x = (a * a - b * b + d * d) / (2.0 * d)
    y = math.sqrt(max(a * a - x * x, 0.0))
    return hip + u * x + p * y, hip + u * d


def foot_lock_window(legs, prev, frames):
    """The lock on `frames` (n + 1 frames of joint positions, the last one kept) after `prev`."""
    n = len(frames) - 1
    raw = [f.copy() for f in frames]
    pos = lambda t, j: prev[j] if t < 0 else raw[t][j]
    for leg in legs:
        joints = [leg["ankle"]] + leg["toes"]
        ground = [min(pos(u, j)[1] for u in range(-1, n + 1)) for j in joints]
        speed = lambda t, j: math.hypot(pos(t, j)[0] - pos(t - 1, j)[0], pos(t, j)[2] - pos(t - 1, j)[2])
        weight = []
        for t in range(n):
            v = speed(t, leg["ankle"])
            gate = min(max((SWING_SPEED - v) / max(SWING_SPEED - LOCK_SPEED, 1e-6), 0.0), 1.0)
            contact = 2.0 - 2.0 ** ((pos(t, leg["ankle"])[1] - ground[0]) / CONTACT_HEIGHT)
            weight.append(min(max(contact, 0.0), 1.0) * gate)
        anchors = [(-1, np.zeros(2))]
        t = 0
        while t < n:
            if weight[t] < 0.5:
                t += 1
                continue
            start = t
            while t < n and weight[t] >= 0.5:
                t += 1
            if start == 0:
                pin = pos(-1, leg["ankle"])[[0, 2]]
            elif t == n:
                pin = pos(n, leg["ankle"])[[0, 2]]
            else:
                w = np.array(weight[start:t])
                pin = sum(w[u - start] * pos(u, leg["ankle"])[[0, 2]] for u in range(start, t)) / w.sum()
            for u in range(start, t):
                anchors.append((u, pin - pos(u, leg["ankle"])[[0, 2]]))
        anchors.append((n, np.zeros(2)))
        offsets = [np.zeros(2)] * n
        for (t0, o0), (t1, o1) in zip(anchors, anchors[1:]):
            for u in range(max(t0 + 1, 0), min(t1, n)):
                offsets[u] = o0 + (u - t0) / (t1 - t0) * (o1 - o0)
            if 0 <= t1 < n:
                offsets[t1] = o1
        for t in range(n):
            f = frames[t]
            hip, knee, ankle = f[leg["hip"]], f[leg["knee"]], f[leg["ankle"]]
            v = speed(t, leg["ankle"])
            clearance = min(pos(t, j)[1] - g for j, g in zip(joints, ground))
            lift = min(max((v - LIFT_SPEED) / LIFT_SPEED, 0.0), 1.0) * max(LIFT_HEIGHT - clearance, 0.0)
            goal = ankle + np.array([STRENGTH * offsets[t][0], lift, STRENGTH * offsets[t][1]])
            new_knee, new_ankle = two_bone_ik(hip, knee, ankle, goal)
            moved = new_ankle - ankle
            f[leg["knee"]], f[leg["ankle"]] = new_knee, new_ankle
            for j in leg["toes"]:
                f[j] = f[j] + moved
    return frames


def fit_rotations(parents, offsets, positions, reference):
    """Section 6b, step 3: local rotations fitted to one frame of global positions."""
    k = len(parents)
    glob, out = [None] * k, [None] * k
    for j in range(k):
        pg = glob[parents[j]] if j > 0 else np.array([0.0, 0.0, 0.0, 1.0])
        guess = qnormalize(qmul(pg, reference[j]))
        a, b = [], []
        for c in range(j + 1, k):
            if parents[c] != j:
                continue
            rest = qrot(guess, offsets[c])
            target = positions[c] - positions[j]
            lr, lt = np.linalg.norm(rest), np.linalg.norm(target)
            if lr < 1e-9 or lt < 1e-9:
                continue
            a.append(rest / lr)
            b.append(target / lt)
        if not a:
            fix = np.array([0.0, 0.0, 0.0, 1.0])
        elif len(a) == 1:
            fix = shortest_arc(a[0], b[0])
        else:
            fix = wahba(a, b)
        glob[j] = qnormalize(qmul(fix, guess))
        local = qnormalize(qmul(qconj(pg), glob[j]))
        out[j] = -local if np.dot(local, reference[j]) < 0 else local
    return out


def skeleton_positions(parents, offsets, root, rot):
    """Joint positions (float32, then as float64) of a root position and local rotations."""
    gr, gp = [None] * len(parents), [None] * len(parents)
    for j, p in enumerate(parents):
        if p < 0:
            gr[j], gp[j] = rot[j], root
        else:
            gp[j] = qrot(gr[p], offsets[j]) + gp[p]
            gr[j] = qmul(gr[p], rot[j])
    return [np.array(v, dtype=F).astype(np.float64) for v in gp]


def lock_feet_between_keys(model, frames, poses):
    """Locks the feet of a completed humanoid motion (frames x (3 + 4 J), f32) between its keys."""
    parents, offsets = model.parents, model.offsets
    j = len(parents)
    legs = legs_of(model.skeleton)
    leg_joints = [x for leg in legs for x in (leg["hip"], leg["knee"], leg["ankle"])]
    out = np.array(poses, dtype=F)
    decoded = [pose_quats(p.astype(np.float64), j) for p in out]
    for a, b in zip(frames, frames[1:]):
        if b < a + 2 or b >= len(out):
            continue
        positions = [skeleton_positions(parents, offsets, *decoded[f]) for f in range(a, b + 1)]
        locked = foot_lock_window(legs, positions[0], positions[1:])
        for f in range(a + 1, b):
            root, rot = decoded[f]
            fitted = fit_rotations(parents, offsets, locked[f - a - 1], rot)
            for x in leg_joints:
                q = fitted[x]
                q = -q if np.dot(q, rot[x]) < 0 else q
                out[f, 3 + 4 * x:7 + 4 * x] = np.array([q[3], q[0], q[1], q[2]], dtype=F)
    return out


def locks_feet(model):
    section, j = model.section, len(model.parents)
    humanoid = section["groups"] == 1 + j and section["dofs"] == 3 + 4 * j
    return humanoid and len(legs_of(model.skeleton)) > 0


def check_keyframes(model, ref, cmp):
    section = model.section
    groups, d = section["groups"], section["dofs"]
    inbetween = Inbetween(model) if "inbetween" in section else None
    foot_lock = locks_feet(model)
    for case in ref["keyframes"]:
        c = cmp.case(case["name"])
        frames = case["key_frames"]
        keys = [np.array(p, dtype=F) for p in case["key_poses"]]
        fixed = [np.array(f, dtype=F) for f in case["fixed"]]
        if inbetween is not None:
            features, bez, env, lerp = inbetween.shot(frames, keys, fixed)
            scale = np.concatenate([np.tile(inbetween.std, 3), np.ones(inbetween.width - 3 * d)])
            cmp.normalised(c, "features", features, case["features"], scale)
            cmp.values(c, "bezier", bez, case["bezier"])
            name = model.sess.get_inputs()[0].name
            correction = model.sess.run(None, {name: features.reshape(1, len(features), -1)})[0]
            network = inbetween.compose(frames, fixed, bez, env, lerp, correction.reshape(len(features), d))
        else:
            state = model.zero_state()
            prev, network = keys[0], [keys[0]]
            for t in range(1, frames[-1] + 1):
                a, b, t_rel = interval(frames, t)
                r = case["intervals"][t - 1]
                cmp.exact(c, "intervals", (t, a, b), (r["t"], r["a"], r["b"]))
                cmp.values(c, "t_rel", t_rel, r["t_rel"], 1.0)
                feed = {"prev": prev, "key_a": keys[a], "key_b": keys[b], "t_rel": np.array([t_rel], dtype=F)}
                if groups > 0:
                    feed["fixed_a"] = fixed[a] if fixed else np.ones(groups, dtype=F)
                    feed["fixed_b"] = fixed[b] if fixed else np.ones(groups, dtype=F)
                prev = model.step(state, feed, ["pose"])[0]
                network.append(prev)
            network = np.array(network)
        cmp.values(c, "network", network, case["network"])
        hit = hit_keys(network, keys, frames, section["key_groups"] if groups > 0 else [], fixed)
        cmp.values(c, "hit", hit, case["hit"])
        cmp.exact(c, "foot_lock", foot_lock, case["foot_lock"])
        poses = lock_feet_between_keys(model, frames, hit) if foot_lock else hit
        cmp.values(c, "poses", poses, case["poses"])


# ---------------------------------------------------------------------------------------------
# Stitch (section 8)


def wrap(a):
    a = (a + math.pi) % (2 * math.pi) - math.pi
    return math.pi if a == -math.pi else a


class Root:
    """A ground root: position on y = 0 and heading about +Y."""

    def __init__(self, pos, yaw):
        self.pos, self.yaw = np.asarray(pos, dtype=np.float64), float(yaw)

    def to_local(self, p):
        return qrot(qy(-self.yaw), p - self.pos)

    def to_world(self, p):
        return self.pos + qrot(qy(self.yaw), p)

    def moved(self, dx, dyaw, dz):
        return Root(self.to_world(np.array([dx, 0.0, dz])), self.yaw + dyaw)


def to_scaled_axis(q):
    q = -q if q[3] < 0 else q
    v = q[:3]
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        return v * 2.0
    return v * (2.0 * math.atan2(s, q[3]) / s)


def inertialize_scalar(x0, v0, t1, t):
    """Bollo's quintic decay of an offset x0 >= 0 with velocity v0 over t1 seconds, at t."""
    if x0 <= 0.0 or t1 <= 0.0:
        return 0.0
    if v0 < 0.0:
        t1 = min(t1, -5.0 * x0 / v0)
    if t >= t1:
        return 0.0
    a0 = max((-8.0 * v0 * t1 - 20.0 * x0) / (t1 * t1), 0.0)
    t12 = t1 * t1
    a = -(a0 * t12 + 6.0 * v0 * t1 + 12.0 * x0) / (2.0 * t12 * t12 * t1)
    b = (3.0 * a0 * t12 + 16.0 * v0 * t1 + 30.0 * x0) / (2.0 * t12 * t12)
    c = -(3.0 * a0 * t12 + 12.0 * v0 * t1 + 20.0 * x0) / (2.0 * t12 * t1)
    d = a0 / 2.0
    return ((((a * t + b) * t + c) * t + d) * t + v0) * t + x0


class SeamBlend:
    """The offsets of one seam: source frames s-2, s-1 against target frames s, s+1."""

    def __init__(self, src_prev, src_last, dst_first, dst_next, dt, blend_time):
        self.rot, self.rot_v = [], []
        for j in range(len(src_last[0])):
            o1 = qnormalize(qmul(src_last[0][j], qconj(dst_first[0][j])))
            back = qmul(qmul(dst_first[0][j], qconj(dst_next[0][j])), dst_first[0][j])
            o0 = qnormalize(qmul(src_prev[0][j], qconj(back)))
            o0 = -o0 if np.dot(o0, o1) < 0 else o0
            self.rot.append(o1)
            self.rot_v.append(to_scaled_axis(qnormalize(qmul(o1, qconj(o0)))) / dt)
        p1 = src_last[1] - dst_first[1]
        p0 = src_prev[1] - (dst_first[1] - (dst_next[1] - dst_first[1]))
        self.pos, self.pos_v, self.time = p1, (p1 - p0) / dt, blend_time

    def apply(self, t, frame):
        rot, root = frame
        out = []
        for j, r in enumerate(rot):
            v = to_scaled_axis(self.rot[j])
            x0 = float(np.linalg.norm(v))
            if x0 < 1e-12:
                o = np.array([0.0, 0.0, 0.0, 1.0])
            else:
                axis = v / x0
                o = from_scaled_axis(axis * inertialize_scalar(x0, float(np.dot(self.rot_v[j], axis)), self.time, t))
            out.append(qnormalize(qmul(o, r)))
        x0 = float(np.linalg.norm(self.pos))
        if x0 >= 1e-12:
            direction = self.pos / x0
            root = root + direction * inertialize_scalar(x0, float(np.dot(self.pos_v, direction)), self.time, t)
        return out, root


def inertialize_seams(frames, seams, blend, dt):
    """Section 8's pre-blend: frames are (rotations, hips position) pairs, changed in order."""
    out, active = [], []
    held = None
    for f, frame in enumerate(frames):
        cur = (list(frame[0]), frame[1].copy())
        for s, blend_s in active:
            cur = blend_s.apply((f - s + 1) * dt, cur)
        if held is not None:
            blend_s = SeamBlend(out[-2], out[-1], held, cur, dt, blend * dt)
            out.append(blend_s.apply(dt, held))
            if blend > 1:
                cur = blend_s.apply(2.0 * dt, cur)
            active.append((f - 1, blend_s))
            held = None
        active = [(s, b) for s, b in active if f + 1 - s < blend]
        if f in seams and f >= 2 and blend > 0:
            held = cur
        else:
            out.append(cur)
    if held is not None:
        out.append(held)
    return out


class Stitch:
    def __init__(self, model):
        self.m = model
        s = model.section
        self.layout = s["layout"]
        self.lower = self.layout["lower_body"]
        self.k = len(model.parents)
        self.pos_at = 3
        self.rot_at = 3 + 3 * len(self.lower)
        self.vel_at = self.rot_at + 4 * self.k
        self.con_at = self.vel_at + 3 * len(self.lower)
        self.dim = self.con_at + 4

    def root_of(self, hips_rotation, hips):
        f = qrot(hips_rotation, np.array(self.layout["forward_axis"], dtype=np.float64))
        f = np.array([f[0], 0.0, f[2]])
        n = np.linalg.norm(f)
        f = f / n if n > 0 else f
        return Root([hips[0], 0.0, hips[2]], math.atan2(f[0], f[2]))

    @staticmethod
    def model_space(pose):
        """The model-space rotations (joint 0: the hips' world rotation) and hips position."""
        return [pose.hips_world_rotation()] + [qnormalize(q) for q in pose.local_rotations[1:]], pose.hips_world()

    def frame(self, rot, hips):
        """Global positions and ground root of model-space rotations and the hips' position."""
        m = self.m
        gr, gp = [None] * self.k, [None] * self.k
        for j in range(self.k):
            if j == 0:
                gr[0], gp[0] = rot[0], hips
            else:
                p = m.parents[j]
                gp[j] = qrot(gr[p], m.offsets[j]) + gp[p]
                gr[j] = qmul(gr[p], rot[j])
        return {"rot": rot, "gp": gp, "root": self.root_of(rot[0], hips)}

    def encode(self, poses, seams=(), pre_blend=False):
        """Pose vectors of engine poses; with `pre_blend`, the seams inertialized first."""
        frames = [self.model_space(p) for p in poses]
        if pre_blend:
            dt = 1.0 / float(F(self.m.meta["zoo.fps"]))
            frames = inertialize_seams(frames, list(seams), self.m.section["blend_frames"], dt)
        frames = [self.frame(rot, hips) for rot, hips in frames]
        out, reference = [], [np.array([0.0, 0.0, 0.0, 1.0])] * self.k
        for f, cur in enumerate(frames):
            a, b = (frames[0], frames[1]) if f == 0 else (frames[f - 1], frames[f])
            x = np.zeros(self.dim)
            d = qrot(qy(-a["root"].yaw), b["root"].pos - a["root"].pos)
            x[0:3] = [d[0], wrap(b["root"].yaw - a["root"].yaw), d[2]]
            for i, j in enumerate(self.lower):
                x[self.pos_at + 3 * i:self.pos_at + 3 * i + 3] = cur["root"].to_local(cur["gp"][j])
                x[self.vel_at + 3 * i:self.vel_at + 3 * i + 3] = qrot(qy(-a["root"].yaw), b["gp"][j] - a["gp"][j])
            reference = list(reference)
            for j in range(self.k):
                q = cur["rot"][j]
                if j == 0:
                    q = qmul(qy(-cur["root"].yaw), q)
                if np.dot(q, reference[j]) < 0:
                    q = -q
                reference[j] = q
                x[self.rot_at + 4 * j:self.rot_at + 4 * j + 4] = q
            for i, j in enumerate(self.layout["contacts"]):
                planted = self.layout["planted"][i] + self.layout["contact_thresholds"][i]
                x[self.con_at + i] = 1.0 if cur["gp"][j][1] < planted else 0.0
            out.append(x.astype(F))
        return out

    def window_starts(self, frames, w, s):
        if w > frames:
            return []
        starts = list(range(0, frames - w + 1, s))
        if starts[-1] != frames - w:
            starts.append(frames - w)
        return starts

    def graph(self, x):
        name = self.m.sess.get_inputs()[0].name
        y = self.m.sess.run(None, {name: np.stack(x).reshape(len(x), 1, -1).astype(F)})[0]
        return [row.reshape(-1).astype(F) for row in y]

    def refine(self, sequence, w, s, blend, fallback):
        out = [self.m.normalize(x, "x") for x in sequence]
        starts = self.window_starts(len(out), w, s)
        first, windows = None, []
        pose = self.dim - 4
        for ws in starts:
            x = out[ws:ws + w]
            y = self.graph(x)
            if first is None:
                first = ([o.copy() for o in x], [r.copy() for r in y])
            # The fallback: the correction's size (RMS over the pose values, normalised units).
            e = np.array([r[:pose] - o[:pose] for o, r in zip(x, y)], dtype=F).astype(np.float64)
            size = F(math.sqrt(float(np.mean(e * e))))
            weight = 0.0
            if fallback is not None:
                start, full = F(fallback["start"]), F(fallback["full"])
                if not math.isfinite(size):
                    weight = F(1)
                elif full <= start:
                    weight = F(1) if size >= start else F(0)
                else:
                    weight = F(min(max((size - start) / (full - start), F(0)), F(1)))
                if weight > 0:
                    for o, r in zip(x, y):
                        r[:pose] = (F(1) - weight) * r[:pose] + weight * o[:pose]
            windows.append({"start": ws, "correction": size, "weight": weight})
            if ws > 0:
                offset = out[ws][:pose] - y[0][:pose]
                for k in range(min(blend, w)):
                    y[k][:pose] = y[k][:pose] + F(1.0 - k / blend) * offset
            for r in y:
                r[pose:] = np.where(r[pose:] > 0, F(1), F(0))
            out[ws:ws + w] = y
        refined = []
        for x in out:
            v = self.m.denormalize(x, "x")
            v[pose:] = np.where(v[pose:] > 0.5, F(1), F(0))
            refined.append(v)
        return starts, first, windows, refined

    def decode(self, refined, start):
        hips_slot = self.lower.index(0)
        root, poses, contacts, prev = start, [], [], None
        for f, x in enumerate(refined):
            x = x.astype(np.float64)
            if f > 0:
                root = root.moved(x[0], x[1], x[2])
            rot = []
            for j in range(self.k):
                q = x[self.rot_at + 4 * j:self.rot_at + 4 * j + 4]
                q = qnormalize(q) if np.dot(q, q) > 1e-12 else np.array([0.0, 0.0, 0.0, 1.0])
                if j == 0:
                    q = qmul(qy(root.yaw), q)
                    hips = root.to_world(x[self.pos_at + 3 * hips_slot:self.pos_at + 3 * hips_slot + 3])
                rot.append(q)
            rp, rq, hp, local = set_world(hips, rot)
            delta, yaw = (np.zeros(3), 0.0) if prev is None else root_delta(prev[0], prev[1], rp, rq)
            prev = (rp, rq)
            poses.append(pose_dict(rp, rq, delta, yaw, hp, local))
            contacts.append([bool(x[self.con_at + i] > 0.5) for i in range(4)])
        return poses, contacts


def check_stitch(model, ref, cmp):
    st = Stitch(model)
    blend = model.section["blend_frames"]
    for case in ref["stitch"]:
        c = cmp.case(case["name"])
        poses = [Pose(p) for p in case["input_poses"]]
        # Seams given are inertialized before encoding (section 8b).
        pre_blend = len(case["seams"]) > 0
        cmp.exact(c, "pre_blend", pre_blend, case["pre_blend"])
        cmp.values(c, "sequence", st.encode(poses, case["seams"], pre_blend), case["sequence"])
        # Refining starts from the reference's pose vectors, the input of `refine_sequence`: the
        # 1-ulp differences of encoding would otherwise weigh on components of tiny deviation.
        sequence = [np.array(x, dtype=F) for x in case["sequence"]]
        starts, first, windows, refined = st.refine(sequence, case["window"], case["stride"], blend,
                                                    case["fallback"])
        cmp.exact(c, "window_starts", starts, case["window_starts"])
        cmp.exact(c, "window_starts", [w["start"] for w in windows], [w["start"] for w in case["windows"]])
        cmp.values(c, "windows", [[w["correction"], w["weight"]] for w in windows],
                   [[w["correction"], w["weight"]] for w in case["windows"]])
        std = model.norm["x"]["std"]
        cmp.normalised(c, "first_window", first[0], case["first_window"]["input"], std)
        cmp.normalised(c, "first_window", first[1], case["first_window"]["output"], std)
        cmp.values(c, "refined", refined, case["refined"])
        # Decoding starts from the ground root of the (inertialized) input's first frame, which
        # the pre-blend leaves as it is.
        first_frame = st.frame(*st.model_space(poses[0]))
        out, contacts = st.decode(refined, first_frame["root"])
        cmp.poses(c, "poses", out, case["poses"])
        for mine, theirs in zip(contacts, case["contacts"]):
            cmp.exact(c, "contacts", mine, theirs)


# ---------------------------------------------------------------------------------------------
# Synthesis (section 9)


class SplitMix64:
    def __init__(self, seed):
        self.state = seed & MASK64

    def next_u64(self):
        self.state = (self.state + 0x9E3779B97F4A7C15) & MASK64
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
        return z ^ (z >> 31)

    def next_f64(self):
        return (self.next_u64() >> 11) / float(1 << 53)

    def normal(self):
        u1 = 1.0 - self.next_f64()
        u2 = self.next_f64()
        return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


class Synthesis:
    def __init__(self, model):
        self.m = model
        s = model.section
        self.d, self.mix = s["frame_dim"], s["components"]
        self.references = [qnormalize(np.array(q, dtype=np.float64)) for q in s["references"]]
        # Offsets as the runtime reads them: float32 values.
        self.offsets32 = [np.array(o, dtype=F).astype(np.float64) for o in model.skeleton["offsets"]]
        self.refiner = None
        if s["refiner"] is not None:
            self.refiner = s["refiner"]
            self.rsess = ort.InferenceSession(base64.b64decode(model.meta["zoo.synthesis.refiner_graph"]),
                                              providers=["CPUExecutionProvider"])
            self.hidden = self.rsess.get_inputs()[2].shape[1]

    def values(self, x):
        """The frame in model units, computed in float32, then as float64."""
        return (x * self.m.norm["x"]["std"] + self.m.norm["x"]["mean"]).astype(F).astype(np.float64)

    def draw(self, rng, w, mu, sd, temperature):
        u = rng.next_f64()
        acc, k = 0.0, self.mix - 1
        for i, wi in enumerate(w):
            acc += float(wi)
            if u < acc:
                k = i
                break
        x = np.empty(self.d, dtype=F)
        for j in range(self.d):
            z = rng.normal()
            x[j] = F(float(mu[k * self.d + j]) + temperature * float(sd[k * self.d + j]) * z)
        return x

    def effectors(self, x):
        v = self.values(x)
        parents = self.m.parents
        rot = [from_scaled_axis(np.array([v[4], 0.0, v[5]]))]
        pos = [np.array([0.0, v[3], 0.0])]
        for j in range(1, len(parents)):
            p, i = parents[j], 6 + 3 * (j - 1)
            local = qmul(self.references[j], from_scaled_axis(v[i:i + 3]))
            pos.append(pos[p] + qrot(rot[p], self.offsets32[j]))
            rot.append(qmul(rot[p], local))
        return [pos[j] for j in self.refiner["effectors"]]

    def decode(self, x, placement):
        v = self.values(x)
        px, pz, yaw = placement
        step = qrot(qy(yaw), np.array([v[0], 0.0, v[1]]))
        placement = (px + step[0], pz + step[2], yaw + v[2])
        root_position = np.array([placement[0], 0.0, placement[1]], dtype=F).astype(np.float64)
        root_rotation = qy(float(F(placement[2])))
        hips_position = np.array([0.0, v[3], 0.0])
        local = [from_scaled_axis(np.array([v[4], 0.0, v[5]]))]
        for j in range(1, len(self.m.parents)):
            i = 6 + 3 * (j - 1)
            local.append(qnormalize(qmul(self.references[j], from_scaled_axis(v[i:i + 3]))))
        world = [qmul(root_rotation, local[0])]
        gp = [root_position + qrot(root_rotation, hips_position)]
        for j in range(1, len(self.m.parents)):
            p = self.m.parents[j]
            gp.append(gp[p] + qrot(world[p], self.offsets32[j]))
            world.append(qmul(world[p], local[j]))
        pose = pose_dict(root_position, root_rotation, np.array([v[0], 0.0, v[1]]), v[2], hips_position, local, gp)
        return pose, [bool(v[self.d - 2] > 0.5), bool(v[self.d - 1] > 0.5)], placement


def check_synthesis(model, ref, cmp):
    syn = Synthesis(model)
    for case in ref["synthesis"]:
        c = cmp.case(case["name"])
        if case["refined"] and syn.refiner is None:
            sys.exit("the reference has refined frames but the file has no refiner")
        rng = SplitMix64(case["seed"])
        temperature = float(F(case["temperature"]))
        x = model.normalize(np.array(case["start_frame"], dtype=F), "x")
        placement = tuple(float(F(v)) for v in case["start_placement"])
        state = model.zero_state()
        if case["refined"]:
            r = syn.refiner
            rh = np.zeros((1, syn.hidden), dtype=F)
            rc = np.zeros((1, syn.hidden), dtype=F)
            prev_eff = syn.effectors(x)
            emean, estd = np.array(r["mean"], dtype=F), np.array(r["std"], dtype=F)
        std = model.norm["x"]["std"]
        for s in case["steps"]:
            cmp.normalised(c, "x", x, s["x"], std)
            w, mu, sd = model.step(state, {"x": x}, ["weights", "means", "stds"])
            cmp.values(c, "weights", w, s["weights"])
            cmp.normalised(c, "means", mu, s["means"], std)
            cmp.normalised(c, "stds", sd, s["stds"], std)
            x = syn.draw(rng, w, mu, sd, temperature)
            cmp.normalised(c, "sampled", x, s["sampled"], std)
            cmp.exact(c, "rng_state", rng.state, s["rng_state"])
            frame = x
            if case["refined"]:
                v = syn.values(x)
                eff = syn.effectors(x)
                step, turn = np.array([v[0], 0.0, v[1]]), qy(v[2])
                e = np.concatenate([np.concatenate(eff),
                                    np.concatenate([step + qrot(turn, p) - q for p, q in zip(eff, prev_eff)])])
                prev_eff = eff
                e = ((e.astype(F) - emean) / estd).astype(F)
                names = [i.name for i in syn.rsess.get_inputs()]
                feed = dict(zip(names, [x.reshape(1, -1), e.reshape(1, -1), rh, rc]))
                frame, rh, rc = syn.rsess.run(None, feed)
                frame = frame.reshape(-1).astype(F)
                rh, rc = rh.astype(F), rc.astype(F)
                cmp.normalised(c, "refined", frame, s["refined"], std)
            pose, contacts, placement = syn.decode(frame, placement)
            cmp.poses(c, "poses", [pose], [s["pose"]])
            cmp.exact(c, "contacts", contacts, s["contacts"])


# ---------------------------------------------------------------------------------------------


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model")
    parser.add_argument("reference")
    parser.add_argument("--report")
    parser.add_argument("--atol", type=float, default=1e-3, help="absolute part of the bound (model units)")
    parser.add_argument("--rtol", type=float, default=2e-5, help="part of the bound relative to the field's scale")
    args = parser.parse_args()
    model = Model(args.model)
    ref = json.load(open(args.reference))
    if ref.get("format") != "zoo-reference-vectors" or ref.get("version") != 2:
        sys.exit(f"{args.reference}: not a version 2 zoo-reference-vectors file (re-export it with `zoo export "
                 f"--onnx RUN --out MODEL.onnx --reference FILE.json`)")
    if ref["task"] != model.task:
        sys.exit(f"the reference is for a `{ref['task']}` model, {args.model} is a `{model.task}` model")
    cmp = Comparison(args.atol, args.rtol)
    {"transition": check_transition, "keyframes": check_keyframes, "stitch": check_stitch,
     "synthesis": check_synthesis}[model.task](model, ref, cmp)
    failed = False
    for case in cmp.cases:
        print(f"{model.task}: {case['name']}")
        for field, f in case["fields"].items():
            bad = cmp.failed(f)
            failed |= bad
            f["bound"] = cmp.bound(f)
            bound = "exact" if f["exact"] else f"bound {f['bound']:.2e}"
            print(f"  {field:16} {f['max_diff']:.2e} over {f['values']} values ({bound}){'  FAIL' if bad else ''}")
    worst = cmp.worst()
    print(f"{model.task}: largest difference {worst:.2e} (bound {args.atol:.0e} + {args.rtol:.0e} x the field's "
          f"largest value): {'FAIL' if failed else 'OK'}")
    if args.report:
        json.dump({"task": model.task, "max_diff": worst, "atol": args.atol, "rtol": args.rtol, "failed": failed,
                   "cases": cmp.cases}, open(args.report, "w"), indent=1)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
