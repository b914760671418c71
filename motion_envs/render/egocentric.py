"""Egocentric views from the bodies' head cameras: depth, semantic colours and a goal-sphere mask (CLOPS).

The bodies are split into as many chunks as torch has threads, each cast
(B/threads × H × W rays in one embree call, which frees the GIL) and shaded
on its own thread; the goal
sphere is intersected analytically per ray and is visible only where it is
nearer than the scene (so walls hide it). The body itself is not in the
view (the camera sits 1 cm inside the face; CLOPS renders the scene only).
"""

from __future__ import annotations

import numpy as np
import torch

from motion_envs.render.raycast import RayCaster, thread_pool
from motion_envs.scenes.labels import PALETTE
from motion_envs.scenes.scene import Scene

CHANNELS = ("depth", "red", "green", "blue", "goal")


class EgocentricRenderer:
    """Renders (B, 5, H, W) float32 views: depth in metres (planar, clipped to `max_depth`; `max_depth` where
    nothing is hit), semantic RGB in [0, 1] from `PALETTE` (black for nothing), goal mask in {0, 1}.

    fov: horizontal field of view in degrees (square pixels)."""

    def __init__(self, scene: Scene, width: int = 64, height: int = 64, fov: float = 90.0, max_depth: float = 10.0) -> None:
        if width < 1 or height < 1 or not 0 < fov < 180:
            raise ValueError(f"need width, height >= 1 and 0 < fov < 180, got {width}, {height}, {fov}")
        self.scene, self.width, self.height, self.max_depth = scene, width, height, max_depth
        self.caster = RayCaster(scene.vertices, scene.faces)
        self.colours = PALETTE.astype(np.float32) / 255.0
        focal = 0.5 * width / np.tan(np.radians(fov) / 2)
        u = np.arange(width) + 0.5 - width / 2
        v = height / 2 - np.arange(height) - 0.5
        local = np.stack(np.broadcast_arrays(u[None, :], focal, v[:, None]), axis=-1).reshape(-1, 3)  # right, gaze, up
        self.local_directions = (local / np.linalg.norm(local, axis=-1, keepdims=True)).astype(np.float32)  # (H·W, 3)

    def render(self, eye: torch.Tensor | np.ndarray, rotation: torch.Tensor | np.ndarray,
               goal: torch.Tensor | np.ndarray | None = None, goal_radius: float = 0.25) -> np.ndarray:  # fmt: skip
        """eye: (B, 3); rotation: (B, 3, 3) with columns right, gaze, up (`head_camera`); goal: (B, 3) or None.
        Returns (B, 5, H, W) float32 in `CHANNELS` order."""
        eye, rotation = _numpy(eye), _numpy(rotation)
        if eye.ndim != 2 or eye.shape[1] != 3 or rotation.shape != (len(eye), 3, 3):
            raise ValueError(f"need eye (B, 3) and rotation (B, 3, 3), got {eye.shape} and {rotation.shape}")
        goals = None if goal is None else _numpy(goal).reshape(len(eye), 3)
        chunks = np.array_split(np.arange(len(eye)), min(torch.get_num_threads(), len(eye)))
        if len(chunks) == 1:
            return self._render_chunk(eye, rotation, goals, goal_radius)
        views = thread_pool(len(chunks)).map(lambda rows: self._render_chunk(eye[rows], rotation[rows], None if goals is None else goals[rows], goal_radius), chunks)
        return np.concatenate(list(views))

    def _render_chunk(self, eye: np.ndarray, rotation: np.ndarray, goal: np.ndarray | None, goal_radius: float) -> np.ndarray:
        bodies, pixels = len(eye), len(self.local_directions)
        # R d as three explicit products and sums (no einsum/BLAS reduction): elementwise IEEE operations give every
        # body the same bits in a batch of any size on any CPU, so batched views equal single ones by construction
        local = self.local_directions
        directions = (rotation[:, None, :, 0] * local[None, :, 0, None] + rotation[:, None, :, 1] * local[None, :, 1, None]
                      + rotation[:, None, :, 2] * local[None, :, 2, None]).reshape(-1, 3)  # (B·H·W, 3)  # fmt: skip
        origins = np.repeat(eye, pixels, axis=0)
        triangle, distance = self.caster.cast(origins, directions, parallel=False)
        label = np.where(triangle >= 0, self.scene.face_labels[triangle.clip(min=0)], 0)
        view = np.empty((bodies, 5, self.height * self.width), dtype=np.float32)
        view[:, 0] = np.minimum(distance.reshape(bodies, pixels) * self.local_directions[:, 1], self.max_depth)
        view[:, 1:4] = self.colours[label].reshape(bodies, pixels, 3).transpose(0, 2, 1)
        view[:, 4] = 0.0 if goal is None else _sphere_mask(origins, directions, np.repeat(goal, pixels, axis=0), goal_radius,
                                                            distance).reshape(bodies, pixels)  # fmt: skip
        return view.reshape(bodies, 5, self.height, self.width)


def _sphere_mask(origins: np.ndarray, directions: np.ndarray, centres: np.ndarray, radius: float,
                 occluder: np.ndarray) -> np.ndarray:  # fmt: skip
    """1 where the ray (R, 3) meets the sphere before `occluder` (R,) metres (or starts inside it), else 0. Dot
    products as explicit sums of the three components: numpy's reduction over a trailing axis of 3 was a fifth
    of a one-body 64 x 64 view (and elementwise sums keep every ray's bits independent of the batch)."""
    x, y, z = (centres - origins).T
    dx, dy, dz = directions.T
    along = x * dx + y * dy + z * dz
    squared = x * x + y * y + z * z
    miss = squared - along**2
    entry = along - np.sqrt(np.clip(radius**2 - miss, 0.0, None))
    inside = squared <= radius**2
    return (inside | ((miss <= radius**2) & (entry > 0) & (entry < occluder))).astype(np.float32)


def _numpy(array: torch.Tensor | np.ndarray) -> np.ndarray:
    if isinstance(array, torch.Tensor):
        array = array.detach().cpu().numpy()
    return np.asarray(array, dtype=np.float32)
