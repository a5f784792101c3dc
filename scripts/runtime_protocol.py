"""An independent implementation of docs/runtime-protocol.md (numpy + the onnxruntime Python
wheel), written from that page alone: it runs an exported zoo transition model and prints the
blended transition as JSON. tests/protocol.rs compares it with the Rust runtime.

usage: runtime_protocol.py MODEL.onnx INPUT.json OUTPUT.json
INPUT.json: {"past": [[D floats] * P], "target": [D], "next": [D], "frames": N, "fallback": bool}
OUTPUT.json: {"frames": [[D floats] * (N + 1)], "miss_mean": float, "miss_max": float,
              "fallback_weight": float}
"""
import base64
import json
import sys

import numpy as np
import onnxruntime as ort

F = np.float32


def features(y, r_prev):
    """Section 2: the feature frame of global positions y given the previous root."""
    r = y[:3]
    f = np.empty_like(y)
    f[:3] = r - r_prev
    f[3:] = (y[3:].reshape(-1, 3) - r).reshape(-1)
    return f


def decode(f, r_prev):
    r = r_prev + f[:3]
    y = np.empty_like(f)
    y[:3] = r
    y[3:] = (f[3:].reshape(-1, 3) + r).reshape(-1)
    return y, r


def main(model_path, input_path, output_path):
    sess = ort.InferenceSession(model_path, providers=["CPUExecutionProvider"])
    meta = sess.get_modelmeta().custom_metadata_map
    assert meta["zoo.format_version"] == "4", meta["zoo.format_version"]
    norm = {k: {m: np.array(v[m], dtype=F) for m in ("mean", "std")}
            for k, v in json.loads(meta["zoo.normalization"]).items()}
    task = json.loads(meta["zoo.transition"])
    slots = json.loads(meta["zoo.state"])
    start = None
    if "zoo.start_graph" in meta:
        start = ort.InferenceSession(base64.b64decode(meta["zoo.start_graph"]), providers=["CPUExecutionProvider"])

    def normalize(v, g):
        return ((v - norm[g]["mean"]) / norm[g]["std"]).astype(F)

    def denormalize(v, g):
        return (v * norm[g]["std"] + norm[g]["mean"]).astype(F)

    data = json.load(open(input_path))
    past = [np.array(p, dtype=F) for p in data["past"]]
    y_t = np.array(data["target"], dtype=F)
    y_next = np.array(data["next"], dtype=F)
    n = int(data["frames"])
    d = y_t.shape[0]

    # 1. The context, encoded and normalised.
    c = []
    for k, y in enumerate(past):
        if k > 0:
            r_prev = past[k - 1][:3]
        elif len(past) > 1:
            r_prev = 2 * past[0][:3] - past[1][:3]
        else:
            r_prev = past[0][:3]
        c.append(normalize(features(y, r_prev), "x"))

    # The target vector.
    tv = np.concatenate([normalize(features(y_t, 2 * y_t[:3] - y_next[:3]), "x"),
                         normalize(y_next - y_t, "velocity")])

    # 2. The start graph sets the state slots it outputs; the others start at zero.
    inputs = {i.name: i for i in sess.get_inputs()}
    state = {s["input"]: np.zeros((1, inputs[s["input"]].shape[1]), dtype=F) for s in slots}
    if start is not None:
        feed = {}
        for i in start.get_inputs():
            feed[i.name] = (tv if i.name == "target" else c[0]).reshape(1, -1)
        names = [o.name for o in start.get_outputs()]
        for name, value in zip(names, start.run(names, feed)):
            state[name] = value.astype(F)

    step_outputs = ["x_next"] + [s["output"] for s in slots]
    has_base = "base" in inputs
    y_last = past[-1]

    def interpolation(i):
        """Section 3: the interpolation frame i of 0..N (normalised features)."""
        w = F(i + 1) / F(n + 1)
        b = np.empty_like(y_t)
        b[:3] = (y_t[:3] - y_last[:3]) / F(n + 1)
        rel_last = (y_last[3:].reshape(-1, 3) - y_last[:3]).reshape(-1)
        rel_t = (y_t[3:].reshape(-1, 3) - y_t[:3]).reshape(-1)
        b[3:] = (F(1) - w) * rel_last + w * rel_t
        return normalize(b, "x")

    def step(x, r, base):
        # Section 3: the offset input.
        v = denormalize(x, "x")
        y = v.copy()
        y[:3] = r
        y[3:] = (v[3:].reshape(-1, 3) + r).reshape(-1)
        feed = {"x": x.reshape(1, -1)}
        if has_base:
            feed["base"] = base.reshape(1, -1)
        if task["offset_input"]:
            feed["offset"] = normalize(y_t - y, "offset").reshape(1, -1)
        for s in slots:
            feed[s["input"]] = state[s["input"]]
        out = sess.run(step_outputs, feed)
        for s, value in zip(slots, out[1:]):
            state[s["input"]] = value.astype(F)
        return out[0].reshape(-1).astype(F)

    # 3. The context frames after the first.
    x, r = c[0], past[0][:3].copy()
    for k in range(1, len(past)):
        step(x, r, c[k])
        x, r = c[k], past[k][:3].copy()

    # 4. N + 1 generated frames.
    frames = []
    for i in range(n + 1):
        x = step(x, r, interpolation(i) if has_base else None)
        p, r = decode(denormalize(x, "x"), r)
        frames.append(p)

    # 5. The target blend.
    b = int(task["target_blend"])
    e = y_t - frames[n]
    dist = np.linalg.norm(e.reshape(-1, 3), axis=1)
    for i in range(n + 1):
        if b == 0:
            w = 1.0 if i == n else 0.0
        else:
            w = 1.0 - (n - i) / b if n - i < b else 0.0
        if w > 0:
            frames[i] = (frames[i] + F(w) * e).astype(F)
    # 6. The fallback towards interpolation, when asked for and the file carries thresholds.
    weight = 0.0
    fallback = json.loads(meta["zoo.transition"])["fallback"]
    if data.get("fallback") and fallback is not None:
        start, full = F(fallback["start"]), F(fallback["full"])
        miss = F(dist.mean())
        if full <= start:
            weight = 1.0 if miss >= start else 0.0
        else:
            weight = float(np.clip((miss - start) / (full - start), 0.0, 1.0))
        for i in range(n + 1):
            a = F(i + 1) / F(n + 1)
            lerp = y_last + a * (y_t - y_last)
            frames[i] = (frames[i] + F(weight) * (lerp - frames[i])).astype(F)
    json.dump({"frames": [f.tolist() for f in frames], "miss_mean": float(dist.mean()),
               "miss_max": float(dist.max()), "fallback_weight": weight}, open(output_path, "w"))


if __name__ == "__main__":
    main(*sys.argv[1:4])
