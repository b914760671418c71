"""Third-person images by ray casting (embree through embreex): bodies, scene, ground grid, goal, trail.

Each frame: the posed bodies' mesh (a lower level of detail of the
mannequin-x wooden mesh) goes into an embree scene and only the rays of the
pixels its projection covers are cast; a static scene (walls and furniture,
cut away above `cutaway_height` so that the body stays in sight) is cast
for the pixels whose rays enter its bounding box; the ground (z = 0), its
1 m grid, the goal ring and the soft contact shadows are analytic per pixel,
a goal sphere is intersected analytically; a per-pixel depth buffer decides
what is in front. The pelvis trail is drawn last, where it is not hidden.
No OpenGL, no display.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch
import trimesh

from motion_envs.body import BodyModel
from motion_envs.body.skeleton import rest_body
from motion_envs.render.camera import Camera, pinhole_rays
from motion_envs.render.raycast import RayCaster
from motion_envs.scenes.labels import PALETTE
from motion_envs.scenes.scene import Scene

SKY_TOP, SKY_BOTTOM = np.array([0.55, 0.68, 0.85]), np.array([0.88, 0.91, 0.95])
GROUND, GRID = np.array([0.82, 0.82, 0.80]), np.array([0.62, 0.62, 0.60])
WOOD = np.array([0.80, 0.62, 0.42])
GOAL, TRAIL, PATH = np.array([0.20, 0.70, 0.30]), np.array([0.90, 0.45, 0.10]), np.array([0.15, 0.45, 0.95])
LIGHT = np.array([0.35, -0.45, 0.82]) / np.linalg.norm([0.35, -0.45, 0.82])


@dataclass(frozen=True)
class BodyMesh:
    """A lower-detail body mesh whose vertices are a subset of the full mesh's.

    vertex_ids: (V,) long, full-mesh ids of the kept vertices. faces: (F, 3) into vertex_ids.
    """

    vertex_ids: torch.Tensor
    faces: np.ndarray


@lru_cache(maxsize=4)
def body_mesh(cell: float = 0.035) -> BodyMesh:
    """Vertex clustering at `cell` metres: every rest vertex snaps to one kept vertex of its grid cell,
    collapsed triangles go. 0.035 m keeps 2.1k of 24k vertices and 5.3k of 48k faces (0.015 m: 22k faces),
    which at 480 × 360 looks the same as 0.025 m (9.8k faces); handing the posed mesh to embree every frame
    (embreex copies it element by element) costs time in proportion to its size."""
    rest = rest_body()
    cells = np.floor(rest.vertices / cell).astype(np.int64)
    _, kept, cell_of_vertex = np.unique(cells, axis=0, return_index=True, return_inverse=True)
    faces = kept[cell_of_vertex.reshape(-1)[rest.faces]]
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    used, compact = np.unique(faces, return_inverse=True)
    return BodyMesh(torch.as_tensor(used, dtype=torch.long), compact.reshape(-1, 3).astype(np.int32))


class ThirdPersonRenderer:
    """Renders posed bodies with their goal and trail, optionally in a scene, as (H, W, 3) uint8 images."""

    def __init__(self, body: BodyModel | None = None, width: int = 480, height: int = 360, lod_cell: float = 0.035,
                 scene: Scene | None = None, cutaway_height: float = 1.2, crowd_lod_cell: float = 0.045) -> None:  # fmt: skip
        """`crowd_lod_cell`: the coarser mesh (3.4k faces a body) of images with several bodies, which a camera
        framing all of them shows smaller; embree's rebuild of 8 bodies went from 19 to 12 ms a frame."""
        self.body = body or BodyModel()
        self.width, self.height = width, height
        self.mesh, self.crowd_mesh = body_mesh(lod_cell), body_mesh(crowd_lod_cell)
        self.rows, self.crowd_rows = (self.body.skin_rows(mesh.vertex_ids) for mesh in (self.mesh, self.crowd_mesh))
        self.scene = None if scene is None else _CutawayScene(scene, cutaway_height)

    @torch.no_grad()
    def vertices(self, transl: torch.Tensor, global_orient: torch.Tensor, body_pose: torch.Tensor) -> np.ndarray:
        """Posed mesh vertices (B, V, 3) of B bodies (rotations axis-angle or 6-D), posed on the body model's device
        (an env's model on CUDA poses there) and returned on the CPU."""
        device = self.rows.device
        posed = self.body(*(tensor.to(device, torch.float32) for tensor in (transl, global_orient, body_pose)))
        rows = self.rows if transl.ndim == 1 or len(transl) == 1 else self.crowd_rows
        return self.body.skin_with_rows(posed, rows).cpu().numpy()

    def render(self, vertices: np.ndarray, camera: Camera, goal: np.ndarray | None = None, goal_radius: float = 0.75,
               trail: np.ndarray | list[np.ndarray] | None = None, goal_shape: str = "ring",
               routes: list[np.ndarray] | None = None) -> np.ndarray:  # fmt: skip
        """One image. vertices: (B, V, 3) posed bodies from `vertices`; goal: (3,) or (G, 3); trail: (T, 3) or a
        list of such paths (pelvis trails, orange); routes: planned paths (W, 3) ahead of the bodies (blue).

        goal_shape "ring": a ring of `goal_radius` on the ground under each goal; "sphere": a floating sphere of
        `goal_radius` at each goal, with a ring of the same radius on the ground below it as a height cue."""
        if goal_shape not in ("ring", "sphere"):
            raise ValueError(f"goal_shape must be 'ring' or 'sphere', got {goal_shape!r}")
        goals = np.zeros((0, 3)) if goal is None else np.asarray(goal, dtype=np.float64).reshape(-1, 3)
        directions = camera.ray_directions()  # (H, W, 3) float32, cached per camera orientation
        image, depth = self._background(directions, camera, vertices, goals, goal_radius)
        if self.scene is not None:
            self.scene.draw(image, depth, camera, directions)
        self._draw_bodies(image, depth, vertices, camera, directions)
        if goal_shape == "sphere":
            for centre in goals:
                _draw_sphere(image, depth, camera, directions, centre, goal_radius)
        paths = [] if trail is None else [trail] if isinstance(trail, np.ndarray) and trail.ndim == 2 else list(trail)
        for path in paths:
            if len(path) > 1:
                _draw_trail(image, depth, camera, np.asarray(path))
        for route in routes or []:
            _draw_trail(image, depth, camera, np.asarray(route), PATH)
        return (np.clip(image, 0.0, 1.0) * 255).astype(np.uint8)

    def _background(self, directions: np.ndarray, camera: Camera, vertices: np.ndarray, goals: np.ndarray,
                    goal_radius: float) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """Sky gradient and the analytic ground: grid, goal rings (goals: (G, 3)), contact shadows. Image (H, W, 3)
        float32 and depth (H, W) float32 (distance along each ray; inf for sky)."""
        forward, right, _ = camera.axes()
        view = _ground_view(camera.width, camera.height, camera.fov, tuple(np.round(forward, 9)),
                            tuple(np.round(right, 9)), round(float(camera.eye[2]), 6))  # fmt: skip
        image, depth = view.sky.copy(), view.depth.copy()
        if view.first == camera.height:
            return image, depth
        # x and y as separate (R, W) planes: numpy's reductions over a trailing axis of 2 cost several ms a frame
        points = view.offsets + camera.eye[:2, None, None].astype(np.float32)  # (2, R, W) ground hits
        line = np.abs(points - np.round(points)) < view.line_width  # (2, R, W)
        ground = np.where((line[0] | line[1])[..., None], view.line_colour, view.plain_colour)
        for goal in goals:
            window = _ground_window(camera, view.first, goal[:2], goal_radius)
            if window is not None:
                to_goal = np.hypot(points[0][window] - goal[0], points[1][window] - goal[1])
                patch = ground[window]  # a view: painting it paints the ground
                inside, rim = to_goal < goal_radius, to_goal > goal_radius * 0.85
                patch[inside & ~rim] = 0.6 * patch[inside & ~rim] + 0.4 * GOAL
                patch[inside & rim] = GOAL
        if len(vertices):
            shadow = np.ones(ground.shape[:2], dtype=np.float32)  # (R, W): one plane to darken, then the colours once
            for body in vertices:  # a handful of bodies per image
                _shade_shadow(shadow, points, camera, view.first, body)
            ground *= shadow[..., None]
        image[view.first :] = ground
        return image, depth

    def _draw_bodies(self, image: np.ndarray, depth: np.ndarray, vertices: np.ndarray, camera: Camera,
                     directions: np.ndarray) -> None:  # fmt: skip
        """Cast the rays of the pixels the bodies' projection covers; paint shaded wood where a body is nearest."""
        bodies, count = vertices.shape[:2]
        flat = vertices.reshape(-1, 3)
        window = _pixel_window(camera, flat)
        if window is None:
            return
        rays = directions[window].reshape(-1, 3)
        mesh = self.mesh if count == len(self.mesh.vertex_ids) else self.crowd_mesh  # the LOD `vertices` chose
        faces = (mesh.faces[None] + (np.arange(bodies) * count)[:, None, None]).reshape(-1, 3)
        faces = faces[facing(flat, faces, camera.eye)]
        used = np.zeros(len(flat), dtype=bool)
        used[faces] = True  # embreex copies vertices one by one too: only those of the faces that look at the camera
        compact = np.cumsum(used, dtype=np.int32) - 1
        triangle, distance = RayCaster(flat[used], compact[faces]).cast(np.broadcast_to(camera.eye, rays.shape), rays)
        front = distance < depth[window].reshape(-1)
        if front.any():
            shade = _lambert(flat[faces[triangle[front]]], rays[front])
            _paint(image, depth, window, front, WOOD * shade[:, None], distance[front])


def facing(vertices: np.ndarray, faces: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """(F,) bool: the faces (F, 3) of `vertices` (V, 3) whose front (counter-clockwise) side looks at `eye` (3,).
    A ray from outside a closed mesh hits a front face first, so only these go to embree: half the triangles, and
    embreex's copy of a mesh costs time in proportion to it (8 bodies at 480 x 360 on an AVX2 EPYC, interleaved
    frames: 51.3 -> 44.0 ms bare, 65.4 -> 57.8 ms in a room). The LOD meshes are not perfectly closed: 7 of
    172,800 pixels changed with one body, 27 with eight, all on silhouettes."""
    x, y, z = (vertices[:, axis][faces] for axis in range(3))  # (F, 3) each: coordinate planes, corners in columns
    ux, uy, uz = x[:, 1] - x[:, 0], y[:, 1] - y[:, 0], z[:, 1] - z[:, 0]
    vx, vy, vz = x[:, 2] - x[:, 0], y[:, 2] - y[:, 0], z[:, 2] - z[:, 0]
    to_eye = eye[0] - x[:, 0], eye[1] - y[:, 0], eye[2] - z[:, 0]
    return (uy * vz - uz * vy) * to_eye[0] + (uz * vx - ux * vz) * to_eye[1] + (ux * vy - uy * vx) * to_eye[2] > 0


class _CutawayScene:
    """A scene's walls and furniture with every vertex lowered to at most `height` (boxes stay boxes, other
shapes flatten at the cut; floors are drawn as the analytic ground), ready to cast."""

    def __init__(self, scene: Scene, height: float) -> None:
        parts = scene.cutaway(height)
        labels = [np.full(len(part.mesh.faces), part.label) for part in parts]
        combined = trimesh.util.concatenate([part.mesh for part in parts])
        self.caster = RayCaster(combined.vertices, combined.faces)
        self.normals = combined.face_normals  # (F, 3)
        self.offsets = np.einsum("fk,fk->f", self.normals, combined.triangles[:, 0])  # (F,) normal · a corner
        colours = (PALETTE.astype(np.float32) / 255.0)[np.concatenate(labels)]
        self.shaded = np.stack([colours * _shade(self.normals)[:, None], colours * _shade(-self.normals)[:, None]])  # (2, F, 3)
        self.bounds = combined.bounds

    def draw(self, image: np.ndarray, depth: np.ndarray, camera: Camera, directions: np.ndarray) -> None:
        """Cast the pixels in the screen box of the scene's bounding box (all, with the eye inside it); paint
        where the scene is nearest, each face lit from the side the camera sees: its back where the eye is behind
        the face's plane (per face, not per ray: a planar face shows every ray the same side)."""
        corners = np.array([[x, y, z] for x in self.bounds[:, 0] for y in self.bounds[:, 1] for z in self.bounds[:, 2]])
        inside = np.all((camera.eye >= self.bounds[0]) & (camera.eye <= self.bounds[1]))
        window = (slice(None), slice(None)) if inside or not camera.project(corners)[1].all() else _pixel_window(camera, corners)
        if window is None:
            return
        rays = directions[window].reshape(-1, 3)
        triangle, distance = self.caster.cast(np.broadcast_to(camera.eye, rays.shape), rays)
        front = distance < depth[window].reshape(-1)
        back = (self.normals @ camera.eye < self.offsets).astype(np.int64)  # (F,)
        colours = self.shaded[back, np.arange(len(back))]  # (F, 3) as this camera sees each face
        _paint(image, depth, window, front, colours[triangle[front]], distance[front])


def _paint(image: np.ndarray, depth: np.ndarray, window: tuple[slice, slice], front: np.ndarray, colours: np.ndarray,
           distance: np.ndarray) -> None:  # fmt: skip
    """Write `colours` (K, 3) and `distance` (K,) into the window's pixels where the flat mask `front` is set."""
    mask = front.reshape(depth[window].shape)
    image[window][mask] = colours
    depth[window][mask] = distance

@dataclass(frozen=True)
class _GroundView:
    """What a camera orientation and eye height fix about the ground: sky image (H, W, 3), depth (H, W), first
    ground row, and for the R ground rows the hit offsets from the eye as x and y planes (2, R, W), the grid line
    half-width (R, W)
    and the faded plain and line colours (R, W, 3)."""

    sky: np.ndarray
    depth: np.ndarray
    first: int
    offsets: np.ndarray
    line_width: np.ndarray
    plain_colour: np.ndarray
    line_colour: np.ndarray


@lru_cache(maxsize=8)
def _ground_view(width: int, height: int, fov: float, forward: tuple, right: tuple, eye_height: float) -> _GroundView:
    """The camera has no roll, so the ground is the rows below the horizon (rows run from up > 0 to up < 0)."""
    directions = pinhole_rays(width, height, fov, forward, right)
    up = directions[:, 0, 2]
    sky = np.empty(directions.shape, dtype=np.float32)
    sky[:] = (SKY_BOTTOM + (SKY_TOP - SKY_BOTTOM) * np.clip(up, 0.0, 1.0)[:, None])[:, None, :]
    depth = np.full(directions.shape[:2], np.inf, dtype=np.float32)
    first = int(np.searchsorted(-up, 1e-4))
    rays = directions[first:]
    distance = np.float32(-eye_height) / rays[..., 2]
    depth[first:] = distance
    fade = np.exp(-distance / 25.0)[..., None]  # far ground fades into the horizon
    faded = [((colour * fade + SKY_BOTTOM[0] * (1.0 - fade)) * (GROUND / GROUND[0])).astype(np.float32) for colour in (GROUND[0], GRID[0])]
    offsets = np.ascontiguousarray(np.moveaxis(distance[..., None] * rays[..., :2], -1, 0), dtype=np.float32)
    line_width = np.clip(0.004 * distance, 0.01, 0.06).astype(np.float32)
    return _GroundView(sky, depth, first, offsets, line_width, faded[0], faded[1])


def _ground_window(camera: Camera, first: int, centre: np.ndarray, half: float) -> tuple[slice, slice] | None:
    """Window into the ground rows (rows counted from `first`) covering the screen box of the ground square of
    half-size `half` around `centre` (2,)."""
    corners = np.array([[centre[0] + dx * half, centre[1] + dy * half, 0.0] for dx in (-1, 1) for dy in (-1, 1)])
    window = _pixel_window(camera, corners)
    if window is None or window[0].stop <= first:
        return None
    rows, columns = window
    return slice(max(rows.start, first) - first, rows.stop - first), columns


def _shade_shadow(shadow: np.ndarray, points: np.ndarray, camera: Camera, first: int, body: np.ndarray) -> None:
    """Multiply the ground's brightness `shadow` (R, W) in place: a soft blob under the body (V, 3), darker where
    its lowest vertices touch (the contact cue). `points`: (2, R, W) the ground rows' x and y. Only ground within
    1 m of the body's centre is touched."""
    centre = body[:, :2].mean(axis=0)
    window = _ground_window(camera, first, centre, 1.0)
    if window is None:
        return
    # x and y as separate planes (numpy's reductions over a trailing axis of 2 made this 20 of a frame's 64 ms,
    # 8 bodies at 480 × 360), and the blob over the whole window in float32, masked by a product (gathering the
    # near pixels out and back cost 2 of a 43-ms frame on an AVX2 EPYC; same image)
    x, y = points[0][window], points[1][window]  # (r, w) each
    dx, dy = x - np.float32(centre[0]), y - np.float32(centre[1])
    near = np.maximum(np.abs(dx), np.abs(dy)) < 1.0
    factor = 1.0 - np.float32(0.25) * np.exp((dx * dx + dy * dy) * np.float32(-1.0 / (2 * 0.25**2))) * near
    low = body[body[:, 2] < 0.03, :2]  # vertices within 3 cm of the ground
    if len(low):
        contacts = low[:: max(1, len(low) // 24)]
        (x0, y0), (x1, y1) = contacts.min(axis=0) - 0.2, contacts.max(axis=0) + 0.2
        close = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        squared = (x[close][:, None] - contacts[:, 0]) ** 2 + (y[close][:, None] - contacts[:, 1]) ** 2  # (P, C)
        factor[close] *= np.prod(1.0 - 0.5 * np.exp(-squared / (2 * 0.05**2)), axis=1)
    shadow[window] *= factor


def _lambert(triangles: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """Shade (R,) of hit triangles (R, 3, 3) seen along `rays` (R, 3), on the side the rays see."""
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True) + 1e-12
    normals *= -np.sign(np.sum(normals * rays, axis=-1, keepdims=True))  # face the camera
    return _shade(normals)


def _shade(normals: np.ndarray) -> np.ndarray:
    """Ambient + diffuse from LIGHT for unit normals (..., 3)."""
    return 0.35 + 0.65 * np.clip(normals @ LIGHT, 0.0, None)


def _pixel_window(camera: Camera, points: np.ndarray, pad: int = 2) -> tuple[slice, slice] | None:
    """(rows, columns) slices of the screen box of `points` (P, 3) in front of the camera, or None when empty."""
    pixels, in_front = camera.project(points)
    if not in_front.any():
        return None
    low = np.floor(pixels[in_front].min(axis=0)).astype(int) - pad
    high = np.ceil(pixels[in_front].max(axis=0)).astype(int) + pad
    rows = slice(max(int(low[0]), 0), min(int(high[0]), camera.height))
    columns = slice(max(int(low[1]), 0), min(int(high[1]), camera.width))
    if rows.start >= rows.stop or columns.start >= columns.stop:
        return None
    return rows, columns


def _draw_sphere(image: np.ndarray, depth: np.ndarray, camera: Camera, directions: np.ndarray, centre: np.ndarray,
                 radius: float) -> None:  # fmt: skip
    """A shaded goal sphere, analytic per pixel of its screen box, where it is nearest."""
    offsets = np.array([[dx, dy, dz] for dx in (-1, 1) for dy in (-1, 1) for dz in (-1, 1)]) * radius
    window = _pixel_window(camera, centre + offsets)
    if window is None:
        return
    rays = directions[window].reshape(-1, 3).astype(np.float64)
    to_centre = centre - camera.eye
    along = rays @ to_centre
    miss = to_centre @ to_centre - along**2
    entry = along - np.sqrt(np.clip(radius**2 - miss, 0.0, None))
    hit = (miss <= radius**2) & (entry > 0) & (entry < depth[window].reshape(-1))
    if hit.any():
        normals = (camera.eye + entry[hit, None] * rays[hit] - centre) / radius
        _paint(image, depth, window, hit, GOAL * (0.45 + 0.55 * np.clip(normals @ LIGHT, 0.0, None))[:, None], entry[hit])


def _draw_trail(image: np.ndarray, depth: np.ndarray, camera: Camera, trail: np.ndarray, colour: np.ndarray = TRAIL) -> None:
    """A path (T, 3) on the ground as 2-px dots, densified along each segment, hidden where something is nearer."""
    ground = np.asarray(trail, dtype=np.float64).copy()
    ground[:, 2] = 0.0
    steps = np.linspace(0.0, 1.0, 6)[:-1]
    dense = np.concatenate([(ground[:-1, None] + (ground[1:] - ground[:-1])[:, None] * steps[None, :, None]).reshape(-1, 3), ground[-1:]])
    pixels, in_front = camera.project(dense)
    distance = np.linalg.norm(dense - camera.eye, axis=-1)[in_front]
    pixels = np.round(pixels[in_front]).astype(int)
    for dr in (0, 1):
        for dc in (0, 1):
            r, c = pixels[:, 0] + dr, pixels[:, 1] + dc
            keep = (r >= 0) & (r < image.shape[0]) & (c >= 0) & (c < image.shape[1])
            r, c = r[keep], c[keep]
            visible = distance[keep] <= depth[r, c] * 1.02 + 0.05
            image[r[visible], c[visible]] = colour
