"""An independent implementation of docs/runtime-protocol.md (numpy + the onnxruntime Python
wheel), written from that page alone: it runs an exported zoo model of any task on the inputs of
a reference file (`zoo export --onnx RUN --out MODEL.onnx --reference REFERENCE.json`) and
compares every step with the reference's numbers.

usage: runtime_protocol.py MODEL.onnx REFERENCE.json [--report REPORT.json] [--tolerance 1e-3]

Prints the largest difference of every compared field per case and exits with status 1 when one
exceeds the tolerance, in model units (normalised values are compared after scaling by their
deviation; weights, t_rel and quaternions as they are; quaternions of engine poses up to sign).
Discrete values (contacts, key indices, window starts, random generator states) must match
exactly. --report writes the same figures as JSON.
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


class Comparison:
    def __init__(self, tolerance):
        self.tolerance = tolerance
        self.cases = []

    def case(self, name):
        c = {"name": name, "fields": {}}
        self.cases.append(c)
        return c

    @staticmethod
    def add(case, field, diff, values):
        f = case["fields"].setdefault(field, {"max_diff": 0.0, "values": 0})
        f["max_diff"] = max(f["max_diff"], float(diff))
        f["values"] += int(values)

    def values(self, case, field, mine, theirs):
        a = np.asarray(mine, dtype=np.float64).reshape(-1)
        b = np.asarray(theirs, dtype=np.float64).reshape(-1)
        if a.shape != b.shape:
            self.add(case, field, math.inf, 1)
            return
        self.add(case, field, np.max(np.abs(a - b)) if a.size else 0.0, a.size)

    def normalised(self, case, field, mine, theirs, std):
        """Normalised values, compared in model units (each difference times its deviation)."""
        a = np.asarray(mine, dtype=np.float64).reshape(-1, len(std))
        b = np.asarray(theirs, dtype=np.float64).reshape(-1, len(std))
        if a.shape != b.shape:
            self.add(case, field, math.inf, 1)
            return
        self.add(case, field, np.max(np.abs(a - b) * np.asarray(std, dtype=np.float64)), a.size)

    def exact(self, case, field, mine, theirs):
        """Discrete values: a mismatch counts as a difference of 1 (or more)."""
        self.add(case, field, 0.0 if mine == theirs else max(1.0, self.tolerance * 10), 1)

    def rotations(self, case, field, mine, theirs):
        """Quaternions, up to sign (q and -q are the same rotation)."""
        a = np.asarray(mine, dtype=np.float64).reshape(-1, 4)
        b = np.asarray(theirs, dtype=np.float64).reshape(-1, 4)
        if a.shape != b.shape:
            self.add(case, field, math.inf, 1)
            return
        d = np.minimum(np.abs(a - b).max(axis=1), np.abs(a + b).max(axis=1))
        self.add(case, field, d.max() if d.size else 0.0, a.size)

    def poses(self, case, field, mine, theirs):
        if len(mine) != len(theirs):
            self.add(case, field, math.inf, 1)
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
        parents, offsets = self.m.parents, self.m.offsets
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
# Keyframes (section 7)


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
            if fb >= n or (fixed and fixed[k][g] != 1.0):
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


def check_keyframes(model, ref, cmp):
    groups = model.section["groups"]
    for case in ref["keyframes"]:
        c = cmp.case(case["name"])
        frames = case["key_frames"]
        keys = [np.array(p, dtype=F) for p in case["key_poses"]]
        fixed = [np.array(f, dtype=F) for f in case["fixed"]]
        state = model.zero_state()
        prev, poses = keys[0], [keys[0]]
        for t in range(1, frames[-1] + 1):
            a, b, t_rel = interval(frames, t)
            r = case["intervals"][t - 1]
            cmp.exact(c, "intervals", (t, a, b), (r["t"], r["a"], r["b"]))
            cmp.values(c, "intervals", t_rel, r["t_rel"])
            feed = {"prev": prev, "key_a": keys[a], "key_b": keys[b], "t_rel": np.array([t_rel], dtype=F)}
            if groups > 0:
                feed["fixed_a"] = fixed[a] if fixed else np.ones(groups, dtype=F)
                feed["fixed_b"] = fixed[b] if fixed else np.ones(groups, dtype=F)
            prev = model.step(state, feed, ["pose"])[0]
            poses.append(prev)
        poses = hit_keys(np.array(poses), keys, frames, model.section["key_groups"] if groups > 0 else [], fixed)
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

    def frame(self, pose):
        """Model-space rotations, global positions and ground root of an engine pose."""
        m = self.m
        rot = [pose.hips_world_rotation()] + [qnormalize(q) for q in pose.local_rotations[1:]]
        hips = pose.hips_world()
        gr, gp = [None] * self.k, [None] * self.k
        for j in range(self.k):
            if j == 0:
                gr[0], gp[0] = rot[0], hips
            else:
                p = m.parents[j]
                gp[j] = qrot(gr[p], m.offsets[j]) + gp[p]
                gr[j] = qmul(gr[p], rot[j])
        return {"rot": rot, "gp": gp, "root": self.root_of(rot[0], hips)}

    def encode(self, poses):
        frames = [self.frame(p) for p in poses]
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

    def refine(self, sequence, w, s, blend):
        out = [self.m.normalize(x, "x") for x in sequence]
        starts = self.window_starts(len(out), w, s)
        first = None
        pose = self.dim - 4
        for ws in starts:
            y = self.graph(out[ws:ws + w])
            if first is None:
                first = ([o.copy() for o in out[ws:ws + w]], [r.copy() for r in y])
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
        return starts, first, refined

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
        cmp.values(c, "sequence", st.encode(poses), case["sequence"])
        # Refining starts from the reference's pose vectors, the input of `refine_sequence`: the
        # 1-ulp differences of encoding would otherwise weigh on components of tiny deviation.
        sequence = [np.array(x, dtype=F) for x in case["sequence"]]
        starts, first, refined = st.refine(sequence, case["window"], case["stride"], blend)
        cmp.exact(c, "window_starts", starts, case["window_starts"])
        std = model.norm["x"]["std"]
        cmp.normalised(c, "first_window", first[0], case["first_window"]["input"], std)
        cmp.normalised(c, "first_window", first[1], case["first_window"]["output"], std)
        cmp.values(c, "refined", refined, case["refined"])
        first_frame = st.frame(poses[0])
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
    parser.add_argument("--tolerance", type=float, default=1e-3)
    args = parser.parse_args()
    model = Model(args.model)
    ref = json.load(open(args.reference))
    if ref.get("format") != "zoo-reference-vectors" or ref.get("version") != 1:
        sys.exit(f"{args.reference}: not a version 1 zoo-reference-vectors file")
    if ref["task"] != model.task:
        sys.exit(f"the reference is for a `{ref['task']}` model, {args.model} is a `{model.task}` model")
    cmp = Comparison(args.tolerance)
    {"transition": check_transition, "keyframes": check_keyframes, "stitch": check_stitch,
     "synthesis": check_synthesis}[model.task](model, ref, cmp)
    failed = False
    for case in cmp.cases:
        print(f"{model.task}: {case['name']}")
        for field, f in case["fields"].items():
            bad = not f["max_diff"] <= args.tolerance
            failed |= bad
            print(f"  {field:16} {f['max_diff']:.2e} over {f['values']} values{'  FAIL' if bad else ''}")
    worst = cmp.worst()
    print(f"{model.task}: largest difference {worst:.2e} (tolerance {args.tolerance:.0e}): {'FAIL' if failed else 'OK'}")
    if args.report:
        json.dump({"task": model.task, "max_diff": worst, "tolerance": args.tolerance, "cases": cmp.cases},
                  open(args.report, "w"), indent=1)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
