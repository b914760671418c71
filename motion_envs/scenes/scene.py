"""A scene: labelled meshes, their occupancy grid, free-space sampling and batched body collisions.

Procedural rooms come from `motion_envs.scenes.layouts`; any trimesh-readable
file loads with `load_scene` (labels from node names, or a per-face `label`
attribute).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import torch
import trimesh
from scipy import ndimage

from motion_envs.scenes.labels import LABELS, label_from_name
from motion_envs.scenes.occupancy import OccupancyGrid, build_occupancy

FLOOR = LABELS.index("floor")


@dataclass(frozen=True)
class ScenePart:
    """One labelled mesh (world coordinates). label: index into `LABELS`."""

    mesh: trimesh.Trimesh
    label: int


class Scene:
    """Labelled parts of a static world (Z up, floor at z = 0).

    vertices: (V, 3) float32, faces: (F, 3) int32, face_labels: (F,) int64 — all parts concatenated
    (what the ray casters load). The floor label's parts are seen but never collide."""

    def __init__(self, parts: list[ScenePart], name: str = "scene", pitch: float = 0.05) -> None:
        if not parts:
            raise ValueError("a scene needs at least one part")
        self.parts, self.name, self.pitch = parts, name, pitch
        self.vertices = np.concatenate([p.mesh.vertices for p in parts]).astype(np.float32)
        offsets = np.cumsum([0] + [len(p.mesh.vertices) for p in parts[:-1]])
        self.faces = np.concatenate([p.mesh.faces + o for p, o in zip(parts, offsets)]).astype(np.int32)
        self.face_labels = np.concatenate([np.full(len(p.mesh.faces), p.label) for p in parts]).astype(np.int64)

    @cached_property
    def grid(self) -> OccupancyGrid:
        """Occupancy and signed distance of the solid (non-floor) parts, built on first use."""
        return build_occupancy([p.mesh for p in self.parts if p.label != FLOOR], self.pitch,
                               floors=[p.mesh for p in self.parts if p.label == FLOOR])  # fmt: skip

    @cached_property
    def walkable(self) -> np.ndarray:
        """(X, Y) bool: the largest connected region of the grid where a body (0.25 m clearance) can stand,
        on the floor (a floor part lies under the cell when the scene has floor parts)."""
        free = self.grid.free_map(clearance=0.25)
        floors = [p.mesh for p in self.parts if p.label == FLOOR]
        if floors:
            x, y = np.meshgrid(self.grid.centres(0), self.grid.centres(1), indexing="ij")
            low = np.min([m.bounds[0] for m in floors], axis=0)
            high = np.max([m.bounds[1] for m in floors], axis=0)
            free &= (x > low[0]) & (x < high[0]) & (y > low[1]) & (y < high[1])
        components, count = ndimage.label(free)
        if count == 0:
            raise ValueError(f"scene {self.name!r} has no free floor where a body fits")
        sizes = ndimage.sum(free, components, index=np.arange(1, count + 1))
        return components == 1 + int(np.argmax(sizes))

    @cached_property
    def walkable_bounds(self) -> np.ndarray:
        """(4,) x0, y0, x1, y1: the rectangle (m) around the walkable region."""
        cells = np.argwhere(self.walkable)
        low = self.grid.origin[:2] + cells.min(axis=0) * self.grid.pitch
        high = self.grid.origin[:2] + (cells.max(axis=0) + 1) * self.grid.pitch
        return np.concatenate([low, high])

    def sample_free(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """(count, 2) xy positions drawn uniformly over the walkable region."""
        cells = np.argwhere(self.walkable)
        chosen = cells[rng.integers(len(cells), size=count)]
        jitter = rng.uniform(-0.5, 0.5, size=(count, 2)) * self.grid.pitch
        return self.grid.origin[:2] + (chosen + 0.5) * self.grid.pitch + jitter

    def sample_start_goal(self, rng: np.random.Generator, min_distance: float = 2.0, tries: int = 100) -> tuple[np.ndarray, np.ndarray]:
        """A start and a goal (2,) each, in the same walkable region (so reachable), at least `min_distance` apart
        (the farthest of `tries` candidates when the region is too small for that)."""
        starts, goals = self.sample_free(rng, tries), self.sample_free(rng, tries)
        distances = np.linalg.norm(starts - goals, axis=1)
        far = np.nonzero(distances >= min_distance)[0]
        best = int(far[0]) if len(far) else int(np.argmax(distances))
        return starts[best], goals[best]

    def cutaway(self, height: float) -> list[ScenePart]:
        """The solid (non-floor) parts with every vertex lowered to at most `height` m (boxes stay boxes, lower;
        other shapes flatten at the cut): walls that hide nothing inside, for views from above the room."""
        parts = []
        for part in self.parts:
            if part.label != FLOOR:
                vertices = part.mesh.vertices.copy()
                vertices[:, 2] = np.minimum(vertices[:, 2], height)
                parts.append(ScenePart(trimesh.Trimesh(vertices, part.mesh.faces, process=False), part.label))
        return parts

    def collisions(self, points: torch.Tensor, radii: torch.Tensor) -> torch.Tensor:
        """Penetration (..., P) in metres (0 where clear) of spheres at `points` (..., P, 3) with `radii` (P,)."""
        return (-self.clearance(points, radii)).clamp(min=0.0)

    def clearance(self, points: torch.Tensor, radii: torch.Tensor) -> torch.Tensor:
        """Signed distance (..., P) in metres from the surfaces of spheres at `points` (..., P, 3) with `radii` (P,)
        to the scene: negative inside it, +inf outside the grid."""
        return self.grid.query(points) - radii


def load_scene(path: str | Path, name: str | None = None) -> Scene:
    """A scene from any file trimesh reads. Labels: a per-face integer attribute `label` (ids into `LABELS`)
    when the mesh has one, else each node's name ('chair_1' -> chair; unknown -> "other")."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no scene file at {path}")
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as error:  # trimesh raises many types for unreadable files
        raise ValueError(f"cannot read scene file {path}: {error}") from error
    if isinstance(loaded, trimesh.Scene):
        names = list(loaded.graph.nodes_geometry)
        meshes = [loaded.geometry[loaded.graph[node][1]].copy().apply_transform(loaded.graph[node][0]) for node in names]
    else:
        names, meshes = [path.stem], [loaded]
    parts = []
    for node_name, mesh in zip(names, meshes):
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        face_labels = _ply_face_labels(mesh)
        if face_labels is None:
            parts.append(ScenePart(mesh, label_from_name(node_name)))
            continue
        for label in np.unique(face_labels):
            if not 0 <= int(label) < len(LABELS):
                raise ValueError(f"{path}: face label {int(label)} is not an id into {LABELS}")
            parts.append(ScenePart(mesh.submesh([np.nonzero(face_labels == label)[0]], append=True), int(label)))
    if not parts:
        raise ValueError(f"{path} holds no triangle mesh")
    return Scene(parts, name or path.stem)


def _ply_face_labels(mesh: trimesh.Trimesh) -> np.ndarray | None:
    """(F,) ints from a PLY face property `label` (trimesh keeps it in the raw PLY metadata), or None."""
    faces = mesh.metadata.get("_ply_raw", {}).get("face", {}).get("data", {})
    if "label" not in faces:
        return None
    return np.asarray(faces["label"]).reshape(-1).astype(np.int64)
