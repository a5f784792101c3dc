"""Walking along a path with a synthesis model's speed / heading control, in the model's frame
(no Blender here: the add-on and its tests call the same function).

Each frame, the heading steered to is the direction from the character's ground position to
the point of the path `lookahead` further along than the point nearest to it (pure pursuit,
0.35 s of walking ahead by default); the speed is the walking speed, lowered near the end.
"""

import math

import numpy as np


def arc_lengths(path):
    """Cumulative length along a polyline `(M, 2)`."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def point_at(path, s_along, s):
    """The point of the polyline at arc length `s` (clamped to its ends)."""
    s = min(max(s, 0.0), s_along[-1])
    i = int(np.searchsorted(s_along, s, side="right")) - 1
    i = min(max(i, 0), len(path) - 2)
    seg = s_along[i + 1] - s_along[i]
    w = 0.0 if seg <= 0 else (s - s_along[i]) / seg
    return path[i] + w * (path[i + 1] - path[i])


def nearest(path, s_along, p, from_index=0, window=60):
    """The arc length of the point of the polyline nearest to `p`, searching the segments from
    `from_index` on (the character goes forward), and its segment index and distance."""
    best = (math.inf, 0.0, from_index)
    for i in range(from_index, min(from_index + window, len(path) - 1)):
        a, b = path[i], path[i + 1]
        ab = b - a
        den = float(ab @ ab)
        w = 0.0 if den <= 0 else float(np.clip((p - a) @ ab / den, 0.0, 1.0))
        q = a + w * ab
        d = float(np.linalg.norm(p - q))
        if d < best[0]:
            best = (d, s_along[i] + w * math.sqrt(den), i)
    return best[1], best[2], best[0]


def distances_to_path(path, points):
    """The distance of each point `(T, 2)` to the polyline."""
    s_along = arc_lengths(path)
    return np.array([nearest(path, s_along, p, 0, len(path))[2] for p in points])


def natural_speed(model):
    """The speed of the model's mean feature frame (model units per second): its data's walking
    speed. The runtime's controller cannot slow a character much below it without walking it
    backwards (the speed term counts speed, not direction; docs/blender.md)."""
    mf = model.mean_frame
    return float(math.hypot(mf[0], mf[1]) * model.fps)


def walk_frames(path, speed, fps):
    """Frames to walk the whole path at `speed` (units per second)."""
    return max(2, int(math.ceil(arc_lengths(path)[-1] / speed * fps)) + 1)


def follow(model, path, speed, seed=0, frames=None, lookahead=None, progress=None):
    """Walks a character of the synthesis `model` along `path` (`(M, 2)` ground points `(x, z)`
    in the model's units, `M >= 2`) at `speed` (model units per second), starting on the first
    point facing along the first segment. Returns `(poses, distances)`: `zoo.Poses` with prefix
    `(frames,)` (default `walk_frames`) and each frame's root distance to the path."""
    import zoo

    path = np.asarray(path, dtype=np.float64)
    s_along = arc_lengths(path)
    total = s_along[-1]
    fps = model.fps
    if frames is None:
        frames = walk_frames(path, speed, fps)
    if lookahead is None:
        lookahead = max(speed * 0.35, 0.3 / model.frame.metres_per_unit)
    d0 = path[1] - path[0]
    ctl = model.controller(seeds=[seed])
    ctl.start(placements=[[path[0, 0], path[0, 1], math.atan2(d0[0], d0[1])]])
    index, parts, dist = 0, [], []
    for t in range(frames):
        x, z, _ = ctl.placements[0]
        p = np.array([x, z])
        s, index, _ = nearest(path, s_along, p, index)
        target = point_at(path, s_along, s + lookahead)
        d = target - p
        heading = math.atan2(d[0], d[1]) if np.linalg.norm(d) > 1e-6 else float(ctl.placements[0][2])
        left = max(total - s, 0.0)
        poses, _ = ctl.step(min(speed, left * fps / 10.0 + 0.1 * speed), heading)
        parts.append(poses)
        root = poses.root_position[0]
        dist.append(nearest(path, s_along, np.array([root[0], root[2]]), max(index - 5, 0))[2])
        if progress is not None:
            progress(t + 1, frames)
    return zoo.Poses.concatenate(parts), np.asarray(dist)
