"""Saved rollouts: what bodies did, frame by frame, for the browser viewer (`motion-envs view`) and plots.

A rollout file is an `.npz` with
  transl (T, B, 3) pelvis positions, rotations (T, B, 22, 3) axis-angle (pelvis first, then the 21 local
  joint rotations), goal (T, B, 3), and the scalars fps, goal_shape ("ring" | "sphere"), goal_radius,
  env_id and scene ("" or "family:seed").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from motion_envs.atomic import atomic_write
from motion_envs.body.rotations import matrix_to_axis_angle, rotation_matrix

ARRAYS = ("transl", "rotations", "goal")


@dataclass(frozen=True)
class Rollout:
    """transl: (T, B, 3); rotations: (T, B, 22, 3) axis-angle; goal: (T, B, 3); all float32."""

    transl: np.ndarray
    rotations: np.ndarray
    goal: np.ndarray
    fps: float
    goal_shape: str = "ring"
    goal_radius: float = 0.5
    env_id: str = ""
    scene: str = ""

    def __post_init__(self) -> None:
        frames, bodies = self.transl.shape[:2]
        expected = {"transl": (frames, bodies, 3), "rotations": (frames, bodies, 22, 3), "goal": (frames, bodies, 3)}
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise ValueError(f"rollout {name} must be {shape}, got {getattr(self, name).shape}")
        if frames == 0:
            raise ValueError("a rollout needs at least one frame")

    @property
    def frames(self) -> int:
        return self.transl.shape[0]

    @property
    def bodies(self) -> int:
        return self.transl.shape[1]

    def save(self, path: str | Path) -> Path:
        """Write the `.npz` atomically."""
        arrays = {name: getattr(self, name) for name in ARRAYS}
        scalars = {"fps": np.float64(self.fps), "goal_shape": np.str_(self.goal_shape), "goal_radius": np.float64(self.goal_radius),
                   "env_id": np.str_(self.env_id), "scene": np.str_(self.scene)}  # fmt: skip
        return atomic_write(path, lambda file: np.savez_compressed(file, **arrays, **scalars))

    @classmethod
    def load(cls, path: str | Path) -> Rollout:
        """Read a rollout file; a clear error names what is missing or malformed."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                contents = {name: data[name] for name in data.files}
        except (OSError, EOFError, ValueError) as error:
            raise ValueError(f"cannot read rollout {path}: {error}") from error
        missing = [name for name in (*ARRAYS, "fps") if name not in contents]
        if missing:
            raise ValueError(f"{path} is not a rollout file: missing {missing}")
        text = {name: str(contents[name]) for name in ("goal_shape", "env_id", "scene") if name in contents}
        radius = float(contents["goal_radius"]) if "goal_radius" in contents else 0.5
        return cls(*(contents[name].astype(np.float32) for name in ARRAYS), fps=float(contents["fps"]), goal_radius=radius, **text)


@dataclass
class RolloutRecorder:
    """Collects frames of B bodies (`add`) into a `Rollout` (`rollout`)."""

    fps: float
    goal_shape: str = "ring"
    goal_radius: float = 0.5
    env_id: str = ""
    scene: str = ""
    _frames: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)

    def add(self, transl: torch.Tensor, global_orient: torch.Tensor, body_pose: torch.Tensor, goal: torch.Tensor) -> None:
        """One frame of B bodies: transl (B, 3); rotations axis-angle (B, 3) / (B, 21, 3), 6-D, or matrices
        (B, 3, 3) / (B, 21, 3, 3); goal (B, 3)."""
        orient = _axis_angle(global_orient.detach().cpu(), matrices=global_orient.ndim == 3)[:, None]
        pose = _axis_angle(body_pose.detach().cpu(), matrices=body_pose.ndim == 4)
        rotations = torch.cat([orient, pose], dim=1)
        self._frames.append((transl.detach().cpu().numpy(), rotations.numpy(), goal.detach().cpu().numpy()))

    def __len__(self) -> int:
        """Frames recorded so far."""
        return len(self._frames)

    def rollout(self) -> Rollout:
        if not self._frames:
            raise ValueError("no frames recorded")
        transl, rotations, goal = (np.stack(parts).astype(np.float32) for parts in zip(*self._frames))
        return Rollout(transl, rotations, goal, self.fps, self.goal_shape, self.goal_radius, self.env_id, self.scene)


def _axis_angle(rotation: torch.Tensor, matrices: bool) -> torch.Tensor:
    """Axis-angle (..., 3), 6-D (..., 6) or, with `matrices`, (..., 3, 3) -> axis-angle (..., 3)."""
    if matrices:
        return matrix_to_axis_angle(rotation.float())
    return matrix_to_axis_angle(rotation_matrix(rotation.float()))
