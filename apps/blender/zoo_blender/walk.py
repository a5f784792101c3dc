"""Walking along a path with a synthesis model, in the model's frame (no Blender here: the
add-on and its tests call the same function).

The runtime's path follower (`zoo_runtime::follow`, through `SynthesisModel.follow_path`) plans
every few frames among candidates that walk faster or slower, turn and step sideways, and keeps
the one whose root stays closest to the path while making progress along it and facing the
point a little further on.
"""

import math

import numpy as np


def arc_lengths(path):
    """Cumulative length along a polyline `(M, 2)`."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


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
    speed."""
    mf = model.mean_frame
    return float(math.hypot(mf[0], mf[1]) * model.fps)


def walk_frames(path, speed, fps):
    """Frames to walk the whole path at `speed` (units per second)."""
    return max(2, int(math.ceil(arc_lengths(path)[-1] / speed * fps)) + 1)


def follow(model, path, speed=None, seed=0, max_frames=None, progress=None):
    """Walks a character of the synthesis `model` along `path` (`(M, 2)` ground points `(x, z)`
    in the model's units, `M >= 2`) at `speed` (model units per second; default
    `natural_speed`), starting on the first point facing along the first segment, until the
    path's end (or `max_frames`, default three times the frames the path takes at `speed`).
    Returns `(poses, distances, reached_end)`: `zoo.Poses` with prefix `(frames,)`, each frame's
    root distance to the path, and whether the end was reached."""
    path = np.asarray(path, dtype=np.float64)
    if speed is None:
        speed = natural_speed(model)
    poses, _, reached = model.follow_path(path, speed, seed=seed, max_frames=max_frames, progress=progress)
    root = poses.root_position
    return poses, model.path_distances(path, root[:, [0, 2]]), reached
