"""Third-person images by ray casting (embree through embreex): bodies, ground grid, goal, trail.

Each frame: the posed bodies' mesh (a lower level of detail of the
mannequin-x wooden mesh) goes into an embree scene and only the rays of the
pixels its projection covers are cast; the ground (z = 0), its 1 m grid, the
goal ring and the soft contact shadows are analytic per pixel; the pelvis
trail is drawn on top. No OpenGL, no display.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from motion_envs.body import BodyModel
from motion_envs.body.skeleton import rest_body
from motion_envs.render.camera import Camera

SKY_TOP, SKY_BOTTOM = np.array([0.55, 0.68, 0.85]), np.array([0.88, 0.91, 0.95])
GROUND, GRID = np.array([0.82, 0.82, 0.80]), np.array([0.62, 0.62, 0.60])
WOOD = np.array([0.80, 0.62, 0.42])
GOAL, TRAIL = np.array([0.20, 0.70, 0.30]), np.array([0.90, 0.45, 0.10])
LIGHT = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])


@dataclass(frozen=True)
class BodyMesh:
    """A lower-detail body mesh whose vertices are a subset of the full mesh's.

    vertex_ids: (V,) long, full-mesh ids of the kept vertices. faces: (F, 3) into vertex_ids.
    """

    vertex_ids: torch.Tensor
    faces: np.ndarray


@lru_cache(maxsize=4)
def body_mesh(cell: float = 0.015) -> BodyMesh:
    """Vertex clustering at `cell` metres: every rest vertex snaps to one kept vertex of its grid cell,
    collapsed triangles go. 0.015 m keeps 9.6k of 24k vertices and 22k of 48k faces."""
    rest = rest_body()
    cells = np.floor(rest.vertices / cell).astype(np.int64)
    _, kept, cell_of_vertex = np.unique(cells, axis=0, return_index=True, return_inverse=True)
    faces = kept[cell_of_vertex.reshape(-1)[rest.faces]]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    used, compact = np.unique(faces, return_inverse=True)
    return BodyMesh(torch.as_tensor(used, dtype=torch.long), compact.reshape(-1, 3).astype(np.int32))


class ThirdPersonRenderer:
    """Renders posed bodies with their goal and trail as (H, W, 3) uint8 images."""

    def __init__(self, body: BodyModel | None = None, width: int = 480, height: int = 360, lod_cell: float = 0.015) -> None:
        self.body = body or BodyModel()
        self.width, self.height = width, height
        self.mesh = body_mesh(lod_cell)
        self.rows = self.body.skin_rows(self.mesh.vertex_ids)

    @torch.no_grad()
    def vertices(self, transl: torch.Tensor, global_orient: torch.Tensor, body_pose: torch.Tensor) -> np.ndarray:
        """Posed mesh vertices (B, V, 3) of B bodies (rotations axis-angle or 6-D)."""
        posed = self.body(transl.float(), global_orient.float(), body_pose.float())
        return self.body.skin_with_rows(posed, self.rows).numpy()

    def render(self, vertices: np.ndarray, camera: Camera, goal: np.ndarray | None = None, goal_radius: float = 0.75,
               trail: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """One image. vertices: (B, V, 3) posed bodies from `vertices`; goal: (3,) on the ground; trail: (T, 3)."""
        height, width = camera.height, camera.width
        directions = camera.ray_directions()  # (H, W, 3) float32, cached per camera orientation
        image = self._background(directions, camera, vertices, goal, goal_radius)
        hit = self._cast_bodies(vertices, camera, directions)
        if hit is not None:
            rows, columns, normals = hit
            shade = 0.35 + 0.65 * np.clip(normals @ LIGHT, 0.0, None)
            image[rows, columns] = WOOD * shade[:, None]
        if trail is not None and len(trail) > 1:
            self._draw_trail(image, camera, trail, occupied=None if hit is None else (hit[0], hit[1]))
        return (np.clip(image, 0.0, 1.0) * 255).astype(np.uint8).reshape(height, width, 3)

    def _background(self, directions: np.ndarray, camera: Camera, vertices: np.ndarray, goal: np.ndarray | None,
                    goal_radius: float) -> np.ndarray:  # fmt: skip
        """Sky gradient and the analytic ground: grid, goal ring, contact shadows. (H, W, 3) float32.

        The camera has no roll, so the ground is the rows below the horizon: only those are shaded."""
        up = directions[:, 0, 2]
        image = np.empty(directions.shape, dtype=np.float32)
        image[:] = (SKY_BOTTOM + (SKY_TOP - SKY_BOTTOM) * np.clip(up, 0.0, 1.0)[:, None])[:, None, :]
        first = int(np.searchsorted(-up, 1e-4))  # rows are ordered top (up > 0) to bottom (up < 0)
        rays = directions[first:]
        if len(rays) == 0:
            return image
        distance = np.float32(-camera.eye[2]) / rays[..., 2]
        points = camera.eye[:2].astype(np.float32) + distance[..., None] * rays[..., :2]  # ground hits (x, y)
        fraction = np.abs(points - np.round(points))
        line = (fraction < np.clip(0.004 * distance, 0.01, 0.06)[..., None]).any(-1)
        fade = np.exp(-distance / 25.0)  # far ground fades into the horizon
        shade = (np.where(line, GRID[0], GROUND[0]) * fade + SKY_BOTTOM[0] * (1.0 - fade))[..., None]
        ground = (shade * (GROUND / GROUND[0])).astype(np.float32)
        if goal is not None:
            to_goal = np.hypot(points[..., 0] - goal[0], points[..., 1] - goal[1])
            inside = to_goal < goal_radius
            ground[inside] = 0.6 * ground[inside] + 0.4 * GOAL
            ground[inside & (to_goal > goal_radius - 0.08)] = GOAL
        self._shade_shadows(ground, points, vertices)
        image[first:] = ground
        return image

    @staticmethod
    def _shade_shadows(ground: np.ndarray, points: np.ndarray, vertices: np.ndarray) -> None:
        """Darken `ground` (R, W, 3) in place: a soft blob under each body, darker where its lowest
        vertices touch (the contact cue). Only ground points within 1 m of a body are touched."""
        for body in vertices:  # a handful of bodies per image
            centre = body[:, :2].mean(axis=0)
            near = np.nonzero((np.abs(points[..., 0] - centre[0]) < 1.0) & (np.abs(points[..., 1] - centre[1]) < 1.0))
            if len(near[0]) == 0:
                continue
            local = points[near]
            factor = 1.0 - 0.25 * np.exp(-np.sum((local - centre) ** 2, axis=-1) / (2 * 0.25**2))
            low = body[body[:, 2] < 0.03]  # vertices within 3 cm of the ground
            for contact in low[:: max(1, len(low) // 24), :2]:
                factor *= 1.0 - 0.5 * np.exp(-np.sum((local - contact) ** 2, axis=-1) / (2 * 0.05**2))
            ground[near] *= factor[:, None].astype(np.float32)

    def _cast_bodies(self, vertices: np.ndarray, camera: Camera, directions: np.ndarray):
        """Rays of the pixels the bodies' projection covers -> (rows, columns, unit normals) of hits, or None."""
        bodies, count = vertices.shape[:2]
        flat = vertices.reshape(-1, 3)
        pixels, in_front = camera.project(flat)
        if not in_front.any():
            return None
        low = np.floor(pixels[in_front].min(axis=0)).astype(int) - 2
        high = np.ceil(pixels[in_front].max(axis=0)).astype(int) + 2
        row_range = np.arange(max(low[0], 0), min(high[0], camera.height))
        column_range = np.arange(max(low[1], 0), min(high[1], camera.width))
        if len(row_range) == 0 or len(column_range) == 0:
            return None
        rows, columns = np.meshgrid(row_range, column_range, indexing="ij")
        rays = directions[rows, columns].reshape(-1, 3).astype(np.float32)
        origins = np.broadcast_to(np.asarray(camera.eye, dtype=np.float32), rays.shape).copy()
        faces = (self.mesh.faces[None] + (np.arange(bodies) * count)[:, None, None]).reshape(-1, 3)
        scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene, flat.astype(np.float32), faces.astype(np.int32))
        result = scene.run(origins, rays, output=1)
        hits = result["primID"] >= 0
        if not hits.any():
            return None
        triangles = flat[faces[result["primID"][hits]]]
        normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True) + 1e-12
        normals *= -np.sign(np.sum(normals * rays[hits], axis=-1, keepdims=True))  # face the camera
        return rows.reshape(-1)[hits], columns.reshape(-1)[hits], normals

    @staticmethod
    def _draw_trail(image: np.ndarray, camera: Camera, trail: np.ndarray, occupied) -> None:
        """Pelvis trail on the ground as 2-px dots, densified along each segment, hidden behind bodies."""
        ground = np.asarray(trail, dtype=np.float64).copy()
        ground[:, 2] = 0.0
        steps = np.linspace(0.0, 1.0, 6)[:-1]
        dense = (ground[:-1, None] + (ground[1:] - ground[:-1])[:, None] * steps[None, :, None]).reshape(-1, 3)
        pixels, in_front = camera.project(np.concatenate([dense, ground[-1:]]))
        pixels = np.round(pixels[in_front]).astype(int)
        mask = np.zeros(image.shape[:2], dtype=bool)
        for dr in (0, 1):
            for dc in (0, 1):
                r, c = pixels[:, 0] + dr, pixels[:, 1] + dc
                keep = (r >= 0) & (r < image.shape[0]) & (c >= 0) & (c < image.shape[1])
                mask[r[keep], c[keep]] = True
        if occupied is not None:
            mask[occupied] = False
        image[mask] = TRAIL
