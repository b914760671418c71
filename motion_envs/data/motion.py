"""In-memory motion representations shared by the readers, retargeting and the cache."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np


class MocapFormatError(ValueError):
    """A motion file that cannot be read; the message names the file and line."""

    def __init__(self, path: str | Path, line: int | None, problem: str) -> None:
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {problem}")
        self.path = Path(path)
        self.line = line


@dataclass(frozen=True)
class SourceSkeleton:
    """A mocap skeleton as joints (each at the start of its bone).

    names: (J,) joint names. parents: (J,) parent index, -1 for the root.
    offsets: (J, 3) joint position relative to its parent at rest (zero
    rotations), in the file's units and axes.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray

    def rest_positions(self) -> np.ndarray:
        """(J, 3) joint positions at rest, root at the origin."""
        positions = np.zeros_like(self.offsets)
        for joint, parent in enumerate(self.parents):
            if parent >= 0:
                positions[joint] = positions[parent] + self.offsets[joint]
        return positions


@dataclass(frozen=True)
class SourceMotion:
    """Captured motion on a `SourceSkeleton`.

    root_positions: (T, 3) root joint position. local_rotations: (T, J, 3, 3)
    rotation of each joint relative to its parent (rest = identity).
    `metres_per_unit` converts the file's lengths to metres.
    """

    path: Path
    skeleton: SourceSkeleton
    fps: float
    root_positions: np.ndarray
    local_rotations: np.ndarray
    metres_per_unit: float

    @property
    def num_frames(self) -> int:
        return int(self.root_positions.shape[0])

    def global_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: (T, J, 3) positions and (T, J, 3, 3) world rotations."""
        num_frames, num_joints = self.local_rotations.shape[:2]
        rotations = np.empty_like(self.local_rotations)
        positions = np.empty((num_frames, num_joints, 3))
        for joint, parent in enumerate(self.skeleton.parents):  # loop over joints, batched over frames
            if parent < 0:
                rotations[:, joint] = self.local_rotations[:, joint]
                positions[:, joint] = self.root_positions
            else:
                rotations[:, joint] = rotations[:, parent] @ self.local_rotations[:, joint]
                positions[:, joint] = positions[:, parent] + rotations[:, parent] @ self.skeleton.offsets[joint]
        return positions, rotations

    def frames(self, start: int, stop: int | None = None) -> SourceMotion:
        """The frames [start, stop) of this motion."""
        return replace(
            self,
            root_positions=self.root_positions[start:stop],
            local_rotations=self.local_rotations[start:stop],
        )


@dataclass(frozen=True)
class BodyMotion:
    """Motion of our body (see `motion_envs.body.kinematics` for the convention).

    transl: (T, 3). global_orient: (T, 3) axis-angle. body_pose: (T, 21, 3).
    """

    name: str
    subject: str
    fps: float
    transl: np.ndarray
    global_orient: np.ndarray
    body_pose: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(self.transl.shape[0])
