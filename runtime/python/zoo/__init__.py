"""zoo: learned character animation in Python, on zoo's engine runtime.

Load any model exported by ``zoo export --onnx`` and run its task on numpy arrays::

    import zoo
    model = zoo.load("rtn.onnx")            # TransitionModel, KeyframeModel, StitchModel or SynthesisModel
    clip = zoo.read_bvh("walk.bvh")
    poses = clip.poses()                     # zoo.Poses: one array per field, every frame
    out = model.transition(poses[0:10], poses[40], poses[41])   # 30 in-between frames + the target

Conventions (the runtime's):

* Positions are in the model's units and axes (``model.frame``: zoo's data is centimetres, Y up,
  right-handed); ``Poses.convert`` converts to another frame.
* Quaternions are ``(x, y, z, w)``.
* A pose is given "BVH style": the hips' world position (``hips``) and rotations (``rotations``:
  the hips' world rotation, then every other joint's rotation relative to its parent), in the
  model skeleton's joint order. ``zoo.Poses`` also holds the engine form (root motion on the
  ground plus local rotations) and the global joint positions.
* Arrays go in and out whole: nothing allocates a Python object per joint or per frame.

Every error is a ``zoo.ZooError``; the runtime's are ``zoo.MotionError`` with its message (and
``kind``, the runtime's variant), ``zoo.WrongTaskError`` for a model of another task and
``zoo.ModelFileError`` for a file that is not an exported model (a training run's folder is
answered with the ``zoo export --onnx`` command that makes one); arrays of the wrong shape raise
``zoo.ShapeError``, a NaN or an infinity ``zoo.NonFiniteError``.

Every setting is the call's own: nothing one call sets carries over to the next. The defaults
are the CLI's (``transition_positions``: the model's calibrated fallback on, the foot lock off,
as ``zoo transition``; ``complete_poses``: every key hit and the feet locked, as ``zoo complete``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import (  # noqa: F401  (re-exported)
    BvhError,
    ModelFileError,
    MotionError,
    NonFiniteError,
    ShapeError,
    WrongTaskError,
    ZooError,
)

__version__: str = _native.__version__
FORMAT_VERSION: int = _native.FORMAT_VERSION

__all__ = [
    "load",
    "load_bytes",
    "read_bvh",
    "write_bvh",
    "Poses",
    "Clip",
    "convert_positions",
    "convert_world",
    "resample_world",
    "ZOO_CM",
    "BLENDER",
    "Skeleton",
    "CoordinateFrame",
    "Model",
    "TransitionModel",
    "KeyframeModel",
    "StitchModel",
    "StitchStream",
    "SynthesisModel",
    "Controller",
    "ZooError",
    "MotionError",
    "WrongTaskError",
    "ModelFileError",
    "ShapeError",
    "NonFiniteError",
    "BvhError",
    "FORMAT_VERSION",
]

PathLike = Union[str, "os.PathLike[str]"]


def _f32(a, name: str) -> np.ndarray:
    try:
        return np.ascontiguousarray(a, dtype=np.float32)
    except (TypeError, ValueError) as e:
        raise ShapeError(f"`{name}` must be an array of numbers: {e}") from None


def _f64(a, name: str) -> np.ndarray:
    try:
        return np.ascontiguousarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ShapeError(f"`{name}` must be an array of numbers: {e}") from None


@dataclass(frozen=True)
class CoordinateFrame:
    """Units and axes of positions and rotations.

    ``metres_per_unit``: 0.01 for centimetres, 1 for metres; ``up_axis``: ``"y"`` or ``"z"``;
    ``handedness``: ``"right"`` or ``"left"``. zoo's data: ``CoordinateFrame(0.01, "y", "right")``;
    Blender: ``CoordinateFrame(1.0, "z", "right")``.
    """

    metres_per_unit: float
    up_axis: str
    handedness: str

    def _tuple(self) -> Tuple[float, str, str]:
        return (float(self.metres_per_unit), self.up_axis, self.handedness)


ZOO_CM = CoordinateFrame(0.01, "y", "right")
BLENDER = CoordinateFrame(1.0, "z", "right")


@dataclass(frozen=True)
class Skeleton:
    """A model's skeleton: joint ``names``, ``parents`` (int32 ``(K,)``, -1 for the root, parents
    before children) and rest ``offsets`` from the parent (float32 ``(K, 3)``, model units)."""

    names: List[str]
    parents: np.ndarray
    offsets: np.ndarray

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """The index of joint ``name`` (``ValueError`` when absent)."""
        return self.names.index(name)


_POSE_FIELDS = (
    "root_position",
    "root_rotation",
    "root_delta_position",
    "root_delta_yaw",
    "hips_position",
    "local_rotations",
    "global_positions",
    "hips",
    "rotations",
)


@dataclass
class Poses:
    """Poses of a character, one array per field, any number of frames (and characters).

    Shapes, for a prefix ``P`` such as ``(T,)`` (frames) or ``(N, T)`` (characters, frames) and
    ``K`` joints:

    * ``root_position`` ``P + (3,)``: the hips projected on the ground (root motion).
    * ``root_rotation`` ``P + (4,)``: the character's facing, a rotation about the up axis.
    * ``root_delta_position`` ``P + (3,)``, ``root_delta_yaw`` ``P``: the root's motion since the
      previous frame, in the previous frame's root space (radians about the up axis).
    * ``hips_position`` ``P + (3,)``: the hips in root space.
    * ``local_rotations`` ``P + (K, 4)``: every joint's local rotation, the hips' relative to
      the root.
    * ``global_positions`` ``P + (K, 3)``: every joint's world position.
    * ``hips`` ``P + (3,)`` and ``rotations`` ``P + (K, 4)``: the same pose BVH style (the hips'
      world position and rotation, then local rotations): what the models take as input.

    Index a ``Poses`` like an array (``poses[3]``, ``poses[10:40]``, ``poses[:, 5]``) to slice every
    field at once.
    """

    root_position: np.ndarray
    root_rotation: np.ndarray
    root_delta_position: np.ndarray
    root_delta_yaw: np.ndarray
    hips_position: np.ndarray
    local_rotations: np.ndarray
    global_positions: np.ndarray
    hips: np.ndarray
    rotations: np.ndarray

    @classmethod
    def _from_dict(cls, d: Dict[str, np.ndarray]) -> "Poses":
        return cls(**{k: d[k] for k in _POSE_FIELDS})

    def _dict(self) -> Dict[str, np.ndarray]:
        return {k: _f32(getattr(self, k), k) for k in _POSE_FIELDS}

    @classmethod
    def from_world(cls, hips, rotations, skeleton: Skeleton) -> "Poses":
        """Poses from BVH-style arrays on ``skeleton``: ``hips`` ``(T, 3)`` (the hips' world
        positions) and ``rotations`` ``(T, K, 4)`` (the hips' world rotation, then local rotations,
        ``(x, y, z, w)``). Global positions come from forward kinematics over the skeleton, root
        deltas from consecutive frames."""
        h = _f32(hips, "hips")
        r = _f32(rotations, "rotations")
        return cls._from_dict(
            _native.poses_from_world(
                h,
                r,
                np.ascontiguousarray(skeleton.parents, dtype=np.int32),
                _f32(skeleton.offsets, "offsets"),
            )
        )

    @property
    def shape(self) -> Tuple[int, ...]:
        """The prefix shape (frames, or characters and frames)."""
        return tuple(self.root_delta_yaw.shape)

    def __len__(self) -> int:
        return self.shape[0] if self.shape else 1

    def __getitem__(self, index) -> "Poses":
        return Poses(**{k: getattr(self, k)[index] for k in _POSE_FIELDS})

    def convert(self, from_frame: CoordinateFrame, to_frame: CoordinateFrame) -> "Poses":
        """The poses in another coordinate frame (e.g. ``model.frame`` to ``zoo.BLENDER``), as the
        runtime's ``EnginePose::convert``. Skeleton offsets convert with ``convert_positions``."""
        return Poses._from_dict(_native.convert_poses(self._dict(), from_frame._tuple(), to_frame._tuple()))

    @staticmethod
    def concatenate(parts: Sequence["Poses"], axis: int = 0) -> "Poses":
        """Joins poses along ``axis`` of the prefix."""
        return Poses(**{k: np.concatenate([getattr(p, k) for p in parts], axis=axis) for k in _POSE_FIELDS})


def convert_positions(positions, from_frame: CoordinateFrame, to_frame: CoordinateFrame) -> np.ndarray:
    """Positions ``(..., 3)`` converted from one coordinate frame to another."""
    p = _f32(positions, "positions")
    if p.ndim == 0 or p.shape[-1] != 3:
        raise ShapeError(f"`positions` must have shape (..., 3), found {p.shape}")
    return _native.convert_poses({"hips": p}, from_frame._tuple(), to_frame._tuple())["hips"]


def convert_world(hips, rotations, from_frame: CoordinateFrame, to_frame: CoordinateFrame) -> Tuple[np.ndarray, np.ndarray]:
    """BVH-style poses (``hips`` ``(..., 3)``, ``rotations`` ``(..., K, 4)``) converted from one
    coordinate frame to another (positions scaled and re-axed, rotations conjugated)."""
    d = _native.convert_poses(
        {"hips": _f32(hips, "hips"), "rotations": _f32(rotations, "rotations")}, from_frame._tuple(), to_frame._tuple()
    )
    return d["hips"], d["rotations"]


def resample_world(hips, rotations, fps: float, new_fps: float) -> Tuple[np.ndarray, np.ndarray]:
    """BVH-style poses (``hips`` ``(T, 3)``, ``rotations`` ``(T, K, 4)``), one every ``1 / fps``
    seconds, at ``new_fps`` over the same span, resampled as ``zoo data resample`` and
    ``Clip.resample`` do (the same code): ``(hips (T', 3), rotations (T', K, 4))``, float32,
    ``T' = floor((T - 1) * new_fps / fps) + 1``; the first frame stays where it is."""
    h = _f64(hips, "hips")
    r = _f64(rotations, "rotations")
    if h.ndim != 2 or h.shape[1] != 3 or r.ndim != 3 or r.shape[2] != 4 or r.shape[0] != h.shape[0]:
        raise ShapeError(f"resample_world takes hips (T, 3) and rotations (T, K, 4), found {h.shape} and {r.shape}")
    if not (float(fps) > 0 and float(new_fps) > 0):
        raise ShapeError(f"resample_world: the frame rates must be positive, found {fps} and {new_fps}")
    pos = np.zeros(r.shape[:2] + (3,))
    pos[:, 0] = h
    rot, pos = _native.resample(r, pos, 1.0 / float(fps), float(new_fps))
    return pos[:, 0].astype(np.float32), rot.astype(np.float32)


class Model:
    """A loaded model (``zoo.load``): what every task tells about itself."""

    task: str
    """The task: ``"transition"``, ``"keyframes"``, ``"stitch"`` or ``"synthesis"``."""

    def __init__(self, native, path: str):
        self._native = native
        self.path = path
        meta = native.metadata
        self.task = meta["task"]
        self.kind: str = meta["kind"]
        """The model kind (``"rtn"``, ``"arnn"``, ``"rmr"``, ``"rnn-gmm"``)."""
        self.fps: float = float(meta["fps"])
        """Frames per second of the training data (clips must have it)."""
        f = meta["frame"]
        self.frame = CoordinateFrame(float(f["metres_per_unit"]), f["up_axis"], f["handedness"])
        """Units and axes of the model's positions and rotations."""
        s = meta["skeleton"]
        self.skeleton = Skeleton(list(s["names"]), s["parents"], s["offsets"])
        """The skeleton the model was trained on (poses must have its joints, in its order)."""
        self.feature_layout: List[Tuple[str, int, int]] = list(meta["feature_layout"])
        """Named ranges ``(name, start, len)`` of the model's frame vector."""
        self.format_version: int = int(meta["format_version"])

    @property
    def joints(self) -> int:
        """Joints of the skeleton."""
        return len(self.skeleton)

    def poses(self, hips, rotations) -> Poses:
        """``Poses.from_world`` on this model's skeleton."""
        return Poses.from_world(hips, rotations, self.skeleton)

    def __repr__(self) -> str:
        return f"<zoo.{type(self).__name__} {self.kind} ({self.task}) {self.joints} joints at {self.fps:g} fps: {self.path}>"

    def __getattr__(self, name: str):
        # Only reached for attributes the model does not have: a method of another task's
        # model is a `WrongTaskError` naming both tasks, anything else the usual AttributeError.
        for task, cls in _MODEL_TYPES.items():
            if task != self.__dict__.get("task") and name in vars(cls) and not name.startswith("_"):
                raise WrongTaskError(
                    f"`{name}` is a method of {task} models, but {self.__dict__.get('path')} is a "
                    f"{self.__dict__.get('task')} model ({self.__dict__.get('kind')}): load a {task} model"
                )
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def check_fps(self, fps: float, what: str = "the clip") -> None:
        """Raises ``zoo.ShapeError`` unless ``fps`` is the model's frame rate within 0.01 %
        (a BVH frame time is stored rounded: 30.00003 fps is 30), naming the fix."""
        if not abs(float(fps) - self.fps) <= 1e-4 * self.fps:
            raise ShapeError(
                f"{what} is at {float(fps):g} fps but the model was trained at {self.fps:g} fps: resample it first "
                f"(`zoo.Clip.resample({self.fps:g})`)"
            )


def _bvh_style(p: Union[Poses, Tuple[np.ndarray, np.ndarray]], name: str) -> Tuple[np.ndarray, np.ndarray]:
    if isinstance(p, Poses):
        return _f32(p.hips, f"{name}.hips"), _f32(p.rotations, f"{name}.rotations")
    if isinstance(p, tuple) and len(p) == 2:
        return _f32(p[0], f"{name} hips"), _f32(p[1], f"{name} rotations")
    raise ShapeError(f"`{name}` must be zoo.Poses or a (hips, rotations) tuple")


class TransitionModel(Model):
    """A transition model (RTN): the frames from context frames to a target pose."""

    @property
    def past_frames(self) -> int:
        """Context frames the model was trained with (the paper's 10)."""
        return self._native.past_frames

    @property
    def transition_frames(self) -> int:
        """Transition length the model was trained on, frames (the paper's 30)."""
        return self._native.transition_frames

    @property
    def target_blend(self) -> int:
        """Frames over which the network's motion is blended onto the target (RTN eq. 15-16)."""
        return self._native.target_blend

    def transition(
        self,
        past: Union[Poses, Tuple[np.ndarray, np.ndarray]],
        target: Union[Poses, Tuple[np.ndarray, np.ndarray]],
        next: Union[Poses, Tuple[np.ndarray, np.ndarray]],
        frames: Optional[int] = None,
        allow_beyond_trained: bool = False,
        foot_lock: bool = False,
        fallback: bool = True,
    ) -> Poses:
        """A transition in engine poses.

        ``past``: the context frames ``(P,)`` (the model was trained with ``past_frames``; at
        least one), ``target``: the target pose, ``next``: the pose after it (for the target's
        velocity); each ``zoo.Poses`` or ``(hips, rotations)``. For ``N`` characters at once give
        ``past`` with prefix ``(N, P)`` and ``target``/``next`` with prefix ``(N,)``.

        Returns ``Poses`` with prefix ``(frames + 1,)`` (or ``(N, frames + 1)``): the ``frames``
        in-between frames (default ``transition_frames``) then the target frame; local rotations
        are fitted to the network's joint positions and ``global_positions`` are those rotations'
        (the skeleton's bone lengths). Longer than the trained length only with
        ``allow_beyond_trained``. As ``zoo transition --in-place`` on the same poses: moved
        towards the interpolation when the target is missed by more than the model's calibrated
        thresholds (``fallback``, on by default) and foot-locked with ``foot_lock`` (off by
        default). The settings hold for this call only.
        """
        ph, pr = _bvh_style(past, "past")
        th, tr = _bvh_style(target, "target")
        nh, nr = _bvh_style(next, "next")
        single = ph.ndim == 2
        if single:
            ph, pr, th, tr, nh, nr = ph[None], pr[None], th[None], tr[None], nh[None], nr[None]
        d = self._native.poses(ph, pr, th, tr, nh, nr, frames, allow_beyond_trained, foot_lock, fallback)
        out = Poses._from_dict(d)
        return out[0] if single else out

    def transition_positions(
        self,
        past,
        target,
        next,
        frames: Optional[int] = None,
        allow_beyond_trained: bool = False,
        foot_lock: bool = False,
        fallback: bool = True,
    ) -> np.ndarray:
        """A transition in global joint positions: ``past`` ``(P, K, 3)``, ``target`` and
        ``next`` ``(K, 3)`` (or with a leading ``N`` for ``N`` characters). Returns
        ``(frames + 1, K, 3)`` (or ``(N, frames + 1, K, 3)``), the last frame the target:
        the network's positions, target-blended, then (as ``zoo transition``) moved towards the
        interpolation when the target is missed by more than the model's calibrated thresholds
        (``fallback``, on by default) and foot-locked with ``foot_lock`` (off by default). The
        settings hold for this call only."""
        p = _f32(past, "past")
        t = _f32(target, "target")
        n = _f32(next, "next")
        single = p.ndim == 3
        if single:
            p, t, n = p[None], t[None], n[None]
        out = self._native.positions(p, t, n, frames, allow_beyond_trained, foot_lock, fallback)
        return out[0] if single else out


class KeyframeModel(Model):
    """A keyframe completion model (ARNN): every frame between keys."""

    @property
    def dofs(self) -> int:
        """Values per pose vector."""
        return self._native.dofs

    @property
    def groups(self) -> int:
        """Key groups a partial key can fix or leave free (0: whole keys only)."""
        return self._native.groups

    @property
    def humanoid(self) -> bool:
        """Whether the model completes humanoid poses of its skeleton (``complete_poses``);
        otherwise raw pose vectors (``complete``, e.g. the lamp's 6 values)."""
        return self._native.humanoid

    def complete(self, frames, poses, fixed=None) -> np.ndarray:
        """Completes keys given as raw pose vectors: ``frames`` ``(n,)`` strictly increasing
        integers, ``poses`` ``(n, dofs)``, ``fixed`` ``(n, groups)`` 0/1 flags or ``None``.
        Returns ``(frames[-1] - frames[0] + 1, dofs)``."""
        f = np.ascontiguousarray(frames, dtype=np.int64)
        fx = None if fixed is None else _f32(fixed, "fixed")
        return self._native.complete(f, _f32(poses, "poses"), fx)

    def complete_poses(self, frames, keys: Union[Poses, Tuple[np.ndarray, np.ndarray]], fixed=None) -> Tuple[np.ndarray, np.ndarray]:
        """Completes humanoid keys: ``frames`` ``(n,)``, ``keys`` the key poses (``Poses`` with
        prefix ``(n,)`` or ``(hips, rotations)``), ``fixed`` ``(n, 1 + K)`` flags (group 0 the root
        position, ``1 + j`` joint ``j``'s rotation; the first key fixes all) or ``None``.
        Returns ``(hips, rotations)`` for every frame from the first key to the last: every key
        hit, and the feet locked between the keys when the skeleton has legs (as ``zoo
        complete``)."""
        h, r = _bvh_style(keys, "keys")
        f = np.ascontiguousarray(frames, dtype=np.int64)
        fx = None if fixed is None else _f32(fixed, "fixed")
        return self._native.complete_poses(f, h, r, fx)


def _reach(seam_reach: Optional[int], refine_everywhere: bool) -> Optional[int]:
    """The native seams' reach: None for the model's, 0 for none."""
    if refine_everywhere:
        if seam_reach is not None:
            raise ValueError("seam_reach and refine_everywhere=True contradict each other: give one of them")
        return 0
    if seam_reach is not None and (not isinstance(seam_reach, (int, np.integer)) or seam_reach < 1):
        raise ValueError(f"seam_reach is {seam_reach!r}: give a number of frames of at least 1, or refine_everywhere=True")
    return None if seam_reach is None else int(seam_reach)


class StitchModel(Model):
    """A stitching model (RMR): clips joined end to start and refined into one motion."""

    @property
    def window(self) -> int:
        """The refiner's window, frames: the shortest sequence it refines."""
        return self._native.window

    @property
    def stride(self) -> int:
        """Frames between windows."""
        return self._native.stride

    @property
    def dim(self) -> int:
        """Values per pose vector."""
        return self._native.dim

    @property
    def min_clip_frames(self) -> int:
        """The shortest clip stitched."""
        return self._native.min_clip_frames

    @property
    def pre_blend(self) -> bool:
        """Whether the model was trained on clips inertialized at their seams (``zoo train
        rmr``'s default): ``stitch`` then inertializes the seams it refines."""
        return self._native.pre_blend

    def align(self, clips: Sequence[Union[Poses, Tuple[np.ndarray, np.ndarray]]]) -> Tuple[np.ndarray, np.ndarray, List[int]]:
        """Puts clips end to start (each moved on the ground so that it starts where the previous
        one ends), as ``zoo stitch`` does. Returns ``(hips, rotations, starts)``."""
        parts = [_bvh_style(c, f"clips[{i}]") for i, c in enumerate(clips)]
        return self._native.align(parts)

    def stitch(
        self,
        clips: Sequence[Union[Poses, Tuple[np.ndarray, np.ndarray]]],
        place_ankles: bool = True,
        lock_feet: bool = True,
        pre_blend: Optional[bool] = None,
        seam_reach: Optional[int] = None,
        refine_everywhere: bool = False,
    ) -> Tuple[Poses, np.ndarray, List[int]]:
        """Aligns ``clips`` end to start and refines the whole, as ``zoo stitch`` does: with
        ``pre_blend`` (by default the model's own, ``self.pre_blend``) the seams are inertialized
        first and guarded against pops after the ankle IK (``zoo stitch --pre-blend``), and the
        frames ``seam_reach`` (default: the model's window) or more from every seam are the
        clips as given (``refine_everywhere=True``: none are).
        Returns ``(poses, contacts, starts)``: the refined ``Poses`` (prefix ``(T,)``), the
        predicted contacts ``(T, 4)`` (heel L, toe L, heel R, toe R) and the first frame of each
        clip in the result."""
        h, r, starts = self.align(clips)
        if pre_blend is None:
            pre_blend = self.pre_blend
        seams = starts[1:] if pre_blend else ()
        poses, contacts = self.refine_poses((h, r), place_ankles, lock_feet, seams, seam_reach, refine_everywhere)
        return poses, contacts, starts

    def refine_poses(
        self,
        sequence: Union[Poses, Tuple[np.ndarray, np.ndarray]],
        place_ankles: bool = True,
        lock_feet: bool = True,
        seams: Sequence[int] = (),
        seam_reach: Optional[int] = None,
        refine_everywhere: bool = False,
    ) -> Tuple[Poses, np.ndarray]:
        """Refines an aligned sequence (at least ``window`` frames); ``seams``: the frames where a
        clip starts, inertialized before refining (``zoo stitch --pre-blend``); frames
        ``seam_reach`` (default: the model's window) or more from every seam are kept as given
        (``zoo stitch --seam-reach``; ``refine_everywhere=True``: ``--refine-everywhere``).
        Returns ``(poses, contacts)``."""
        h, r = _bvh_style(sequence, "sequence")
        reach = _reach(seam_reach, refine_everywhere)
        d, contacts = self._native.refine_poses(h, r, place_ankles, lock_feet, [int(s) for s in seams], reach)
        return Poses._from_dict(d), contacts

    def encode(self, sequence: Union[Poses, Tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        """Raw pose vectors ``(T, dim)`` of a sequence of poses."""
        h, r = _bvh_style(sequence, "sequence")
        return self._native.encode(h, r)

    def refine(self, features) -> np.ndarray:
        """Refines raw pose vectors ``(T, dim)`` (``T >= window``)."""
        return self._native.refine(_f32(features, "features"))

    def stream(
        self,
        place_ankles: bool = True,
        lock_feet: bool = True,
        seam_guard: bool = True,
        seam_reach: Optional[int] = None,
        refine_everywhere: bool = False,
    ) -> "StitchStream":
        """A stream for motion matching: push frames as they are decided, pop them refined
        ``latency`` frames later, with the ankle IK, the seam guard, the foot lock and the seams'
        reach of ``zoo stitch`` (what ``refine_poses`` gives for the same frames and seams; with
        a reach, frames away from every marked seam pass through as pushed)."""
        return StitchStream(self, place_ankles, lock_feet, seam_guard, seam_reach, refine_everywhere)


class StitchStream:
    """Stitching as a stream (``zoo_runtime::StitchStream``): ``push`` the aligned motion as it is
    decided (``mark_seam`` before a clip's first frame), ``pop`` what is refined; the refined
    frame ``t`` is ready once frame ``t + latency`` is pushed, or after ``finish``."""

    def __init__(
        self,
        model: StitchModel,
        place_ankles: bool = True,
        lock_feet: bool = True,
        seam_guard: bool = True,
        seam_reach: Optional[int] = None,
        refine_everywhere: bool = False,
    ):
        self.model = model
        reach = _reach(seam_reach, refine_everywhere)
        self._native = _native.StitchStream(model._native, place_ankles, lock_feet, seam_guard, reach)

    @property
    def latency(self) -> int:
        """Frames between pushing a frame and popping it refined: the window, plus the lookahead
        of the seam guard and the foot lock when they run."""
        return self._native.latency

    @property
    def pushed(self) -> int:
        """Frames pushed so far."""
        return self._native.pushed

    @property
    def popped(self) -> int:
        """Frames popped so far."""
        return self._native.popped

    def mark_seam(self) -> None:
        """Marks the next pushed frame as the first of a new clip: inertialized and guarded."""
        self._native.mark_seam()

    def push(self, frames: Union[Poses, Tuple[np.ndarray, np.ndarray]]) -> None:
        """Pushes frames of the aligned motion (``Poses`` or BVH-style ``(hips, rotations)``)."""
        h, r = _bvh_style(frames, "frames")
        self._native.push(h, r)

    def pop(self) -> Tuple[Poses, np.ndarray]:
        """Every refined frame that is ready: ``(poses, contacts)`` (prefix ``(N,)``, ``N`` may be 0)."""
        d, contacts = self._native.pop()
        return Poses._from_dict(d), contacts

    def finish(self) -> None:
        """Ends the motion: every remaining frame becomes ready to pop."""
        self._native.finish()


class SynthesisModel(Model):
    """A synthesis model (RNN-GMM): random locomotion of seeded characters, and its speed /
    heading control (``Controller``)."""

    @property
    def frame_dim(self) -> int:
        """Values per feature frame."""
        return self._native.frame_dim

    @property
    def has_refiner(self) -> bool:
        """Whether the file embeds the refiner behind the generator."""
        return self._native.has_refiner

    @property
    def mean_frame(self) -> np.ndarray:
        """The data's mean feature frame ``(frame_dim,)``: a neutral start frame."""
        return self._native.mean_frame

    def encode(self, sequence: Union[Poses, Tuple[np.ndarray, np.ndarray]], contacts=None) -> Tuple[np.ndarray, np.ndarray]:
        """Feature frames ``(T, frame_dim)`` of a sequence of poses (``T >= 2``, at ``fps``) and
        the ground placement ``(T, 3)`` (``x``, ``z``, heading) of each frame; ``contacts``
        ``(T, 2)`` (left, right) or ``None`` for the data's mean."""
        h, r = _bvh_style(sequence, "sequence")
        c = None if contacts is None else _f32(contacts, "contacts")
        return self._native.encode(h, r, c)

    def generate(
        self,
        frames: int,
        start=None,
        placements=None,
        seeds: Union[int, Sequence[int]] = 0,
        temperature: float = 1.0,
        refine: bool = True,
    ) -> Tuple[Poses, np.ndarray]:
        """Random motion: ``frames`` frames for each character. ``seeds``: one seed per
        character (an int for one character); ``start`` ``(N, frame_dim)`` start frames (default
        ``mean_frame``); ``placements`` ``(N, 3)`` (``x``, ``z``, heading; default the origin
        facing +Z). Returns ``(poses, contacts)`` with prefix ``(N, frames)`` (``(frames,)`` for an
        int seed)."""
        single = np.ndim(seeds) == 0
        s = np.atleast_1d(np.asarray(seeds, dtype=np.uint64))
        n = len(s)
        x0 = np.broadcast_to(self.mean_frame, (n, self.frame_dim)) if start is None else np.atleast_2d(start)
        pl = np.zeros((n, 3), np.float32) if placements is None else np.atleast_2d(placements)
        d, contacts = self._native.generate(int(frames), _f32(x0, "start"), _f32(pl, "placements"), s, float(temperature), refine)
        poses = Poses._from_dict(d)
        return (poses[0], contacts[0]) if single else (poses, contacts)

    def controller(self, seeds: Union[int, Sequence[int]] = 0, **settings) -> "Controller":
        """A ``Controller`` of ``len(seeds)`` characters (settings: ``batch``, ``speed_offsets``,
        ``turn_offsets``, ``sigma_speed``, ``sigma_heading``, ``temperature``; the runtime's
        defaults otherwise)."""
        return Controller(self, seeds, **settings)

    def follow_path(
        self,
        points,
        speed: Optional[float] = None,
        seed: int = 0,
        start=None,
        max_frames: Optional[int] = None,
        progress=None,
        **settings,
    ) -> Tuple[Poses, np.ndarray, bool]:
        """Walks one character along a ground path in real time (``zoo_runtime::follow``: the
        online controller planning towards the path). ``points`` ``(M, 2)``: the path's ground
        ``x``, ``z`` in model units; ``speed`` in model units per second (default: the data's
        mean speed, ``mean_frame``'s step times ``fps``); the character starts on the first
        point facing along the first segment from ``start`` seed feature frames ``(S,
        frame_dim)`` (default the mean frame) and walks until the path's end, or ``max_frames``
        (default: three times the frames the path takes at ``speed``, plus a second).
        ``progress(done, total)`` is called every 10 frames. ``settings``: ``sigma_fit``,
        ``sigma_progress``, ``sigma_heading``, ``lookahead``, ``batch``, ``speed_offsets``,
        ``turn_offsets``, ``side_offsets``, ``temperature`` (the runtime's defaults otherwise).
        Returns ``(poses, contacts, reached_end)``: prefix ``(T,)``."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float32))
        if speed is None:
            mf = self.mean_frame
            speed = float(np.hypot(mf[0], mf[1]) * self.fps)
        native = _native.PathFollower(self._native, _f32(pts, "points"), float(speed), int(seed), **settings)
        x0 = np.atleast_2d(self.mean_frame if start is None else np.asarray(start))
        native.start(_f32(x0, "start"))
        if max_frames is None:
            max_frames = int(3 * native.length / speed * self.fps) + int(self.fps)
        if max_frames < 1:
            raise ValueError(f"follow_path: max_frames is {max_frames}; give at least 1 frame")
        parts, bits = [], []
        done = 0
        while done < max_frames and not native.reached_end:
            d, c = native.step(min(10, max_frames - done))
            parts.append(Poses._from_dict(d))
            bits.append(c)
            done += len(c)
            if progress is not None:
                progress(done, max_frames)
        return Poses.concatenate(parts), np.concatenate(bits), bool(native.reached_end)

    def path_distances(self, points, positions) -> np.ndarray:
        """The distance of each ground point ``positions`` ``(T, 2)`` (``x``, ``z``) to the
        path through ``points`` ``(M, 2)``, model units."""
        pts = np.atleast_2d(np.asarray(points, dtype=np.float32))
        native = _native.PathFollower(self._native, _f32(pts, "points"), 1.0, 0)
        return native.distances(_f32(np.atleast_2d(positions), "positions"))


class Controller:
    """Speed and heading control of ``N`` characters of a synthesis model
    (``zoo_runtime::control``: sampling-based model-predictive control over the generator).

    ``start`` them from seed feature frames, then ``step`` once per frame with each character's
    target speed (model units per second) and facing yaw (radians about the up axis, 0 facing
    +Z, positive turning +Z towards +X)."""

    def __init__(self, model: SynthesisModel, seeds: Union[int, Sequence[int]] = 0, **settings):
        self.model = model
        s = np.atleast_1d(np.asarray(seeds, dtype=np.uint64))
        self._native = _native.Controller(model._native, s, **settings)

    @property
    def characters(self) -> int:
        """Characters controlled."""
        return self._native.characters

    def start(self, frames=None, placements=None) -> None:
        """Starts every character: ``frames`` ``(N, S, frame_dim)`` seed feature frames, oldest
        first (default: the mean frame), the last one placed at ``placements`` ``(N, 3)``
        (``x``, ``z``, heading; default the origin facing +Z)."""
        n, d = self.characters, self.model.frame_dim
        f = np.broadcast_to(self.model.mean_frame, (n, 1, d)) if frames is None else np.asarray(frames)
        if f.ndim == 2:
            f = f[:, None, :]
        pl = np.zeros((n, 3), np.float32) if placements is None else np.atleast_2d(placements)
        self._native.start(_f32(f, "frames"), _f32(pl, "placements"))

    def step(self, speed, heading) -> Tuple[Poses, np.ndarray]:
        """Plays the next frame of every character: ``speed`` and ``heading`` per character
        (scalars apply to all). Returns ``(poses, contacts)`` with prefix ``(N,)``."""
        n = self.characters
        s = _f32(np.broadcast_to(np.asarray(speed, np.float32), (n,)), "speed")
        h = _f32(np.broadcast_to(np.asarray(heading, np.float32), (n,)), "heading")
        d, contacts = self._native.step(s, h)
        return Poses._from_dict(d), contacts

    @property
    def placements(self) -> np.ndarray:
        """``(N, 3)``: each character's ground ``x``, ``z`` and heading after the last frame."""
        return self._native.placements


_MODEL_TYPES = {
    "transition": TransitionModel,
    "keyframes": KeyframeModel,
    "stitch": StitchModel,
    "synthesis": SynthesisModel,
}


def load(path: PathLike) -> Union[TransitionModel, KeyframeModel, StitchModel, SynthesisModel]:
    """Loads any model file of ``zoo export --onnx`` (the runtime's one loader) and returns the
    type of its task. Raises ``zoo.ModelFileError`` for a file that is not an exported model
    (with the runtime's message: the key, the version, the fix), or a folder (a training run:
    the message gives the ``zoo export --onnx`` command)."""
    p = os.fspath(path)
    task, native = _native.load(p)
    return _MODEL_TYPES[task](native, p)


def load_bytes(data: bytes) -> Union[TransitionModel, KeyframeModel, StitchModel, SynthesisModel]:
    """Loads a model from the bytes of an exported file (e.g. read from an archive or a
    database): the same model, and the same outputs, as ``load`` of that file. Its ``path`` is
    ``"<bytes>"``."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise TypeError(f"load_bytes takes the file's bytes, not {type(data).__name__}: use zoo.load for a path")
    task, native = _native.load_bytes(bytes(data))
    return _MODEL_TYPES[task](native, "<bytes>")


@dataclass
class Clip:
    """A BVH clip as arrays (float64, the file's units): ``names``, ``parents`` ``(J,)`` (-1 for
    the root), ``offsets`` ``(J, 3)``, ``rotations`` ``(F, J, 4)`` (local, the root's in world
    space, ``(x, y, z, w)``), ``positions`` ``(F, J, 3)`` (local translations, the root's its world
    position), ``frame_time`` (seconds), and what writing it back needs: ``euler_orders`` (channel
    order per joint), ``end_sites`` ``(J, 3)`` (NaN where none), ``position_channels`` ``(J,)``."""

    names: List[str]
    parents: np.ndarray
    offsets: np.ndarray
    rotations: np.ndarray
    positions: np.ndarray
    frame_time: float
    euler_orders: List[str] = field(default_factory=list)
    end_sites: Optional[np.ndarray] = None
    position_channels: Optional[np.ndarray] = None

    @property
    def frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def resample(self, fps: float) -> "Clip":
        """The clip at another frame rate, resampled as ``zoo data resample`` does (the same
        code): the same span from the first frame to the last (the last new frame at or before
        the clip's end), rotations by slerp on the shortest path and positions linearly between
        the two frames around each new frame. A rate within 0.01 % of the clip's returns it
        unchanged (a BVH frame time is stored rounded: 30.00003 fps is 30)."""
        fps = float(fps)
        if not fps > 0:
            raise ShapeError(f"resample: the frame rate must be positive, found {fps}")
        if abs(fps - self.fps) <= 1e-4 * fps:
            return self
        rot, pos = _native.resample(
            _f64(self.rotations, "rotations"), _f64(self.positions, "positions"), float(self.frame_time), fps
        )
        return Clip(
            names=list(self.names),
            parents=self.parents,
            offsets=self.offsets,
            rotations=rot,
            positions=pos,
            frame_time=1.0 / fps,
            euler_orders=list(self.euler_orders),
            end_sites=self.end_sites,
            position_channels=self.position_channels,
        )

    @property
    def skeleton(self) -> Skeleton:
        """The clip's skeleton (offsets in float32)."""
        return Skeleton(list(self.names), self.parents.astype(np.int32), self.offsets.astype(np.float32))

    @property
    def hips(self) -> np.ndarray:
        """``(F, 3)``: the root's world position in every frame."""
        return self.positions[:, 0]

    def poses(self, joints: Optional[Sequence[str]] = None) -> Poses:
        """The clip's frames as ``Poses`` (float32). ``joints``: the names of a model's skeleton,
        in its order (``model.skeleton.names``), to take only those joints, in that order (the
        clip's own joints otherwise)."""
        if joints is None:
            return Poses.from_world(self.hips, self.rotations, self.skeleton)
        missing = [n for n in joints if n not in self.names]
        if missing:
            raise ShapeError(f"the clip has no joint named {', '.join(missing)}")
        idx = [self.names.index(n) for n in joints]
        if self.parents[idx[0]] != -1:
            raise ShapeError(f"joint `{joints[0]}` is not the clip's root; read the clip with drop_dummy_root=True")
        sk = Skeleton(list(joints), np.array([-1] + [idx.index(self.parents[i]) for i in idx[1:]], np.int32), self.offsets[idx].astype(np.float32))
        return Poses.from_world(self.hips, self.rotations[:, idx], sk)


def read_bvh(path: PathLike, drop_dummy_root: bool = False) -> Clip:
    """Reads a ``.bvh`` (or ``.bvh.gz``) file with zoo's reader. ``drop_dummy_root`` drops an
    all-zero root joint as zoo's datasets do (bandai2's ``joint_Root``)."""
    d = _native.read_bvh(os.fspath(path), drop_dummy_root)
    return Clip(
        names=list(d["names"]),
        parents=d["parents"],
        offsets=d["offsets"],
        rotations=d["rotations"],
        positions=d["positions"],
        frame_time=float(d["frame_time"]),
        euler_orders=list(d["euler_orders"]),
        end_sites=d["end_sites"],
        position_channels=d["position_channels"],
    )


def write_bvh(path: PathLike, clip: Clip) -> None:
    """Writes ``clip`` to a ``.bvh`` file (``.bvh.gz`` compressed) with zoo's writer."""
    _native.write_bvh(
        os.fspath(path),
        list(clip.names),
        np.ascontiguousarray(clip.parents, dtype=np.int32),
        _f64(clip.offsets, "offsets"),
        _f64(clip.rotations, "rotations"),
        _f64(clip.positions, "positions"),
        float(clip.frame_time),
        list(clip.euler_orders) if clip.euler_orders else None,
        None if clip.end_sites is None else _f64(clip.end_sites, "end_sites"),
        None if clip.position_channels is None else np.ascontiguousarray(clip.position_channels, dtype=bool),
    )
