"""A voxel occupancy grid of a scene's solid parts and its signed distance, for collisions and free space.

The floor is not an obstacle; the grid spans the solid parts' xy extent
(plus a margin) and z from the floor to `height`. Watertight parts are
filled (trimesh's `contains`), open ones are voxelised on their surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import trimesh
from scipy import ndimage


@dataclass(frozen=True)
class OccupancyGrid:
    """origin: (3,) world position of voxel (0, 0, 0)'s corner; pitch: voxel edge (m).

    occupied: (X, Y, Z) bool. signed_distance: (X, Y, Z) float32 metres from each voxel
    centre to the nearest solid (negative inside a solid)."""

    origin: np.ndarray
    pitch: float
    occupied: np.ndarray
    signed_distance: np.ndarray

    def centres(self, axis: int) -> np.ndarray:
        """World coordinates (n,) of the voxel centres along `axis`."""
        return self.origin[axis] + (np.arange(self.occupied.shape[axis]) + 0.5) * self.pitch

    def query(self, points: torch.Tensor) -> torch.Tensor:
        """Signed distance (...,) at world points (..., 3), nearest voxel; +inf outside the grid's xy and above it,
        the floor level's value below z = 0."""
        grid = torch.as_tensor(self.signed_distance, device=points.device)
        origin = torch.as_tensor(self.origin, dtype=points.dtype, device=points.device)
        index = torch.floor((points - origin) / self.pitch).long()
        size = torch.tensor(self.occupied.shape, device=points.device)
        index[..., 2] = index[..., 2].clamp(min=0)
        inside = ((index >= 0) & (index < size)).all(-1)
        clamped = torch.minimum(index.clamp(min=0), size - 1)
        values = grid[clamped[..., 0], clamped[..., 1], clamped[..., 2]].to(points.dtype)
        return torch.where(inside, values, torch.full_like(values, float("inf")))

    def column_clearance(self, low: float = 0.1, high: float = 1.7) -> np.ndarray:
        """(X, Y) float32: per column, the least signed distance (m) of its voxels between `low` and `high` m up."""
        z = self.centres(2)
        band = (z >= low) & (z <= high)
        return self.signed_distance[:, :, band].min(axis=2)

    def free_map(self, clearance: float, low: float = 0.1, high: float = 1.7) -> np.ndarray:
        """(X, Y) bool: columns where every voxel between `low` and `high` m is at least `clearance` from a solid."""
        return self.column_clearance(low, high) >= clearance


def build_occupancy(solids: list[trimesh.Trimesh], pitch: float = 0.05, height: float = 2.0,
                    margin: float = 0.5, floors: list[trimesh.Trimesh] = ()) -> OccupancyGrid:  # fmt: skip
    """Voxelise `solids` (world meshes) on a grid of `pitch` m that spans them and the `floors` (plus `margin`), so
    that open floor beyond the furniture is on the grid too. Raises ValueError when there are no solids."""
    if not solids:
        raise ValueError("a scene needs at least one solid (non-floor) part to build its occupancy grid")
    low = np.min([mesh.bounds[0] for mesh in [*solids, *floors]], axis=0)
    high = np.max([mesh.bounds[1] for mesh in [*solids, *floors]], axis=0)
    origin = np.array([low[0] - margin, low[1] - margin, 0.0])
    shape = tuple(int(np.ceil(extent / pitch)) for extent in (high[0] + margin - origin[0], high[1] + margin - origin[1], height))
    occupied = np.zeros(shape, dtype=bool)
    centres = [origin[axis] + (np.arange(shape[axis]) + 0.5) * pitch for axis in range(3)]
    for mesh in solids:
        _mark(occupied, mesh, centres, origin, pitch)
    outside = ndimage.distance_transform_edt(~occupied, sampling=pitch)
    inside = ndimage.distance_transform_edt(occupied, sampling=pitch)
    signed = np.where(occupied, -inside, outside).astype(np.float32)
    return OccupancyGrid(origin, pitch, occupied, signed)


def _mark(occupied: np.ndarray, mesh: trimesh.Trimesh, centres: list[np.ndarray], origin: np.ndarray, pitch: float) -> None:
    """Set the voxels of one solid in `occupied` (in place)."""
    if mesh.is_watertight:
        ranges = [np.nonzero((c >= mesh.bounds[0][a]) & (c <= mesh.bounds[1][a]))[0] for a, c in enumerate(centres)]
        if any(len(r) == 0 for r in ranges):
            return
        grid = np.stack(np.meshgrid(*ranges, indexing="ij"), axis=-1).reshape(-1, 3)
        points = np.stack([centres[a][grid[:, a]] for a in range(3)], axis=-1)
        inside = _inside_convex_or_mesh(mesh, points)
        hits = grid[inside]
    else:
        surface = mesh.voxelized(pitch).points
        hits = np.floor((surface - origin) / pitch).astype(np.int64)
        hits = hits[((hits >= 0) & (hits < occupied.shape)).all(axis=1)]
    occupied[hits[:, 0], hits[:, 1], hits[:, 2]] = True


def _inside_convex_or_mesh(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Inside test: half-spaces for convex meshes (every furniture box), ray parity (`contains`) otherwise."""
    if mesh.is_convex:
        normals, origins = mesh.face_normals, mesh.triangles[:, 0]
        return np.all(np.einsum("pk,fk->pf", points, normals) <= np.sum(normals * origins, axis=1) + 1e-9, axis=1)
    return mesh.contains(points)
