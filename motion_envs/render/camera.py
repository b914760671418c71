"""Pinhole cameras for ray casting: rays through every pixel and the projection back to pixels."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

WORLD_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Camera:
    """A pinhole camera at `eye` looking at `target` (world, Z up); `fov` is the vertical field of view (degrees)."""

    eye: np.ndarray
    target: np.ndarray
    width: int = 480
    height: int = 360
    fov: float = 50.0

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit forward, right and up vectors (3,) each (read-only)."""
        return self._axes

    @cached_property
    def _axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Computed once per camera: a frame projects points a dozen times (bodies, shadows, goal, trail, scene
        box), and numpy's small cross products and norms cost ~0.2 ms each time."""
        forward = np.asarray(self.target, dtype=np.float64) - np.asarray(self.eye, dtype=np.float64)
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, WORLD_UP)
        right = right / max(np.linalg.norm(right), 1e-9)
        axes = forward, right, np.cross(right, forward)
        for axis in axes:
            axis.flags.writeable = False
        return axes

    @property
    def focal(self) -> float:
        """Focal length in pixels."""
        return 0.5 * self.height / np.tan(np.radians(self.fov) / 2.0)

    def ray_directions(self) -> np.ndarray:
        """Unit directions (H, W, 3) float32 of the rays through pixel centres (read-only: cached by orientation)."""
        forward, right, _ = self.axes()
        return pinhole_rays(self.width, self.height, self.fov, tuple(np.round(forward, 9)), tuple(np.round(right, 9)))

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (P, 3) -> pixel (row, column) floats (P, 2) and a mask of points in front of the camera."""
        forward, right, up = self.axes()
        relative = np.asarray(points, dtype=np.float64) - np.asarray(self.eye, dtype=np.float64)
        depth = relative @ forward
        safe = np.where(depth > 1e-6, depth, 1e-6)
        column = self.width / 2.0 + self.focal * (relative @ right) / safe - 0.5
        row = self.height / 2.0 - self.focal * (relative @ up) / safe - 0.5
        return np.stack([row, column], axis=-1), depth > 1e-6


@lru_cache(maxsize=8)
def pinhole_rays(width: int, height: int, fov: float, forward: tuple, right: tuple) -> np.ndarray:
    """Unit ray directions (H, W, 3) float32 of a camera with unit `forward` and `right` (3-tuples); read-only."""
    forward, right = np.asarray(forward), np.asarray(right)
    up = np.cross(right, forward)
    rows, columns = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    focal = 0.5 * height / np.tan(np.radians(fov) / 2.0)
    u = columns + 0.5 - width / 2.0
    v = height / 2.0 - rows - 0.5
    directions = focal * forward + u[..., None] * right + v[..., None] * up
    directions = (directions / np.linalg.norm(directions, axis=-1, keepdims=True)).astype(np.float32)
    directions.flags.writeable = False
    return directions


def follow_camera(target: np.ndarray, width: int = 480, height: int = 360, distance: float = 5.5,
                  height_above: float = 2.6, azimuth: float = -2.2) -> Camera:  # fmt: skip
    """A camera `distance` m away on the ground from `target` in direction `azimuth` (radians), raised by `height_above`."""
    target = np.asarray(target, dtype=np.float64)
    eye = target + np.array([distance * np.cos(azimuth), distance * np.sin(azimuth), height_above])
    return Camera(eye, target, width, height)
