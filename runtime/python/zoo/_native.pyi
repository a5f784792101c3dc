"""Type stubs of ``zoo._native``, the extension module (the runtime). Use the ``zoo`` package's API;
these are its building blocks. Arrays are float32 and C-contiguous unless stated; quaternions
``(x, y, z, w)``. Pose dicts hold the fields of ``zoo.Poses``."""

from os import PathLike
from typing import Dict, List, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

F32 = npt.NDArray[np.float32]
PoseDict = Dict[str, F32]
Frame = Tuple[float, str, str]

__version__: str
FORMAT_VERSION: int

class ZooError(Exception): ...

class MotionError(ZooError):
    kind: str
    """The runtime's variant (``MotionError`` of ``zoo_runtime``), e.g. ``"BufferLength"``."""

class WrongTaskError(MotionError): ...
class ModelFileError(MotionError): ...
class ShapeError(ZooError): ...
class BvhError(ZooError): ...
class NonFiniteError(ZooError): ...

def load(path: Union[str, PathLike[str]]) -> Tuple[str, Union["Transition", "Keyframes", "Stitch", "Synthesis"]]: ...
def load_bytes(data: bytes) -> Tuple[str, Union["Transition", "Keyframes", "Stitch", "Synthesis"]]: ...
def poses_from_world(
    hips: F32, rotations: F32, parents: npt.NDArray[np.int32], offsets: F32
) -> PoseDict: ...
def convert_poses(poses: PoseDict, from_frame: Frame, to_frame: Frame) -> PoseDict: ...
def read_bvh(path: Union[str, PathLike[str]], drop_dummy_root: bool = False) -> Dict[str, object]: ...
def write_bvh(
    path: Union[str, PathLike[str]],
    names: List[str],
    parents: npt.NDArray[np.int32],
    offsets: npt.NDArray[np.float64],
    rotations: npt.NDArray[np.float64],
    positions: npt.NDArray[np.float64],
    frame_time: float,
    euler_orders: Optional[List[str]] = None,
    end_sites: Optional[npt.NDArray[np.float64]] = None,
    position_channels: Optional[npt.NDArray[np.bool_]] = None,
) -> None: ...
def resample(
    rotations: npt.NDArray[np.float64], positions: npt.NDArray[np.float64], frame_time: float, fps: float
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...

class Transition:
    metadata: Dict[str, object]
    past_frames: int
    transition_frames: int
    target_blend: int
    joints: int
    terrain: bool
    def positions(
        self,
        past: F32,
        target: F32,
        next: F32,
        frames: Optional[int] = None,
        allow_beyond_trained: bool = False,
        foot_lock: bool = False,
        fallback: bool = True,
    ) -> F32: ...
    def poses(
        self,
        past_hips: F32,
        past_rotations: F32,
        target_hips: F32,
        target_rotations: F32,
        next_hips: F32,
        next_rotations: F32,
        frames: Optional[int] = None,
        allow_beyond_trained: bool = False,
    ) -> PoseDict: ...

class Keyframes:
    metadata: Dict[str, object]
    dofs: int
    groups: int
    humanoid: bool
    def complete(self, frames: npt.NDArray[np.int64], poses: F32, fixed: Optional[F32] = None) -> F32: ...
    def complete_poses(
        self, frames: npt.NDArray[np.int64], hips: F32, rotations: F32, fixed: Optional[F32] = None
    ) -> Tuple[F32, F32]: ...

class Stitch:
    metadata: Dict[str, object]
    window: int
    stride: int
    dim: int
    min_clip_frames: int
    pre_blend: bool
    def encode(self, hips: F32, rotations: F32) -> F32: ...
    def refine(self, features: F32) -> F32: ...
    def align(self, clips: List[Tuple[F32, F32]]) -> Tuple[F32, F32, List[int]]: ...
    def refine_poses(
        self, hips: F32, rotations: F32, place_ankles: bool = True, lock_feet: bool = True
    ) -> Tuple[PoseDict, npt.NDArray[np.bool_]]: ...

class StitchStream:
    latency: int
    pushed: int
    popped: int
    def __init__(self, model: Stitch, place_ankles: bool = True, lock_feet: bool = True, seam_guard: bool = True) -> None: ...
    def mark_seam(self) -> None: ...
    def push(self, hips: F32, rotations: F32) -> None: ...
    def pop(self) -> Tuple[PoseDict, npt.NDArray[np.bool_]]: ...
    def finish(self) -> None: ...

class Synthesis:
    metadata: Dict[str, object]
    frame_dim: int
    has_refiner: bool
    mean_frame: F32
    def encode(self, hips: F32, rotations: F32, contacts: Optional[F32] = None) -> Tuple[F32, F32]: ...
    def generate(
        self,
        frames: int,
        start: F32,
        placements: F32,
        seeds: npt.NDArray[np.uint64],
        temperature: float = 1.0,
        refine: bool = True,
    ) -> Tuple[PoseDict, npt.NDArray[np.bool_]]: ...

class Controller:
    characters: int
    placements: F32
    def __init__(
        self,
        model: Synthesis,
        seeds: npt.NDArray[np.uint64],
        batch: Optional[int] = None,
        speed_offsets: Optional[List[float]] = None,
        turn_offsets: Optional[List[float]] = None,
        sigma_speed: Optional[float] = None,
        sigma_heading: Optional[float] = None,
        temperature: Optional[float] = None,
    ) -> None: ...
    def start(self, frames: F32, placements: F32) -> None: ...
    def step(self, speeds: F32, headings: F32) -> Tuple[PoseDict, npt.NDArray[np.bool_]]: ...

class PathFollower:
    progress: float
    length: float
    reached_end: bool
    def __init__(
        self,
        model: Synthesis,
        points: F32,
        speed: float,
        seed: int = 0,
        sigma_fit: Optional[float] = None,
        sigma_progress: Optional[float] = None,
        sigma_heading: Optional[float] = None,
        lookahead: Optional[float] = None,
        batch: Optional[int] = None,
        speed_offsets: Optional[List[float]] = None,
        turn_offsets: Optional[List[float]] = None,
        side_offsets: Optional[List[float]] = None,
        temperature: Optional[float] = None,
    ) -> None: ...
    def start(self, frames: F32) -> None: ...
    def step(self, frames: int) -> Tuple[PoseDict, npt.NDArray[np.bool_]]: ...
    def distances(self, points: F32) -> npt.NDArray[np.float64]: ...
