"""Paths through a scene's walkable region, cut into waypoints for a walking body.

`plan_path(scene, start, goal)` runs A* (`pyastar2d`, 8-connected) on the
scene's occupancy grid: cells outside `Scene.walkable` (0.25 m from every
solid between 0.1 and 1.7 m up) are blocked, and a cell costs more the
closer it lies to a solid (`comfort` metres and nearer), so paths keep to the
middle of gaps and doors where they can. The cell path is then shortened by
string pulling: a straight cut replaces a stretch of path when it stays on
walkable cells and costs at most `detour` times what the stretch cost (a cut
may not hug furniture the A* path kept away from). Each straight leg is
split evenly into pieces of at most `spacing` metres; the waypoints are the
pieces' ends, the last one the goal. A goal outside the walkable region
(inside furniture, outside the room, in a part no door joins) raises
`UnreachableGoal`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyastar2d
import skfmm
from scipy import ndimage

from motion_envs.scenes.scene import Scene

COMFORT, CROWDING_COST = 0.6, 8.0
"""Clearance (m) from which a cell costs 1; at the walkable limit (0.25 m) it costs 1 + CROWDING_COST."""


class UnreachableGoal(ValueError):
    """No walkable path joins the start and the goal."""


@dataclass(frozen=True)
class PlannedPath:
    """corners: (C, 2) the shortened path from start to goal (m). waypoints: (W, 2) its pieces' ends, the last
    the goal. length: metres along `corners`."""

    corners: np.ndarray
    waypoints: np.ndarray
    length: float


def cell_costs(scene: Scene, comfort: float = COMFORT) -> np.ndarray:
    """(X, Y) float32 A* weights: inf off the walkable region, 1 at `comfort` m from solids or more, rising linearly
    to 1 + CROWDING_COST at the walkable region's 0.25 m edge."""
    clearance = scene.grid.column_clearance()
    crowding = np.clip((comfort - clearance) / (comfort - 0.25), 0.0, 1.0)
    costs = (1.0 + CROWDING_COST * crowding).astype(np.float32)
    costs[~scene.walkable] = np.inf
    return costs


def plan_path(scene: Scene, start: np.ndarray, goal: np.ndarray, spacing: float = 1.5, detour: float = 1.05,
              costs: np.ndarray | None = None) -> PlannedPath:  # fmt: skip
    """The path from `start` to `goal` ((2,) xy, m) with waypoints at most `spacing` m apart.

    `costs` (from `cell_costs`) may be passed to plan many paths in one scene without recomputing them."""
    if spacing <= 0 or detour < 1:
        raise ValueError(f"spacing must be positive and detour at least 1, got {spacing}, {detour}")
    costs = cell_costs(scene) if costs is None else costs
    start_cell, goal_cell = (_walkable_cell(scene, point, name) for point, name in ((start, "start"), (goal, "goal")))
    cells = pyastar2d.astar_path(costs, tuple(start_cell), tuple(goal_cell), allow_diagonal=True)
    if cells is None:
        raise UnreachableGoal(f"no walkable path in {scene.name} joins start {np.round(start, 2).tolist()} "
                              f"and goal {np.round(goal, 2).tolist()}")  # fmt: skip
    kept = _string_pull(cells, costs, detour)
    corners = scene.grid.origin[:2] + (cells[kept] + 0.5) * scene.grid.pitch
    corners[0], corners[-1] = start, goal
    return PlannedPath(corners, split_legs(corners, spacing), float(np.linalg.norm(np.diff(corners, axis=0), axis=1).sum()))


def split_legs(corners: np.ndarray, spacing: float) -> np.ndarray:
    """(W, 2) ends of the even pieces (each at most `spacing` m) of every leg of the polyline `corners` (C, 2),
    without the start; the last is the polyline's end."""
    points = []
    for a, b in zip(corners[:-1], corners[1:]):
        pieces = max(1, int(np.ceil(np.linalg.norm(b - a) / spacing - 1e-9)))
        points.append(a + np.outer(np.arange(1, pieces + 1) / pieces, b - a))
    return np.concatenate(points)


def _walkable_cell(scene: Scene, point: np.ndarray, name: str) -> np.ndarray:
    """(2,) grid cell of `point` (2,), which must be walkable."""
    point = np.asarray(point, dtype=np.float64)
    if point.shape != (2,) or not np.isfinite(point).all():
        raise ValueError(f"{name} must be 2 finite numbers (x, y), got {point!r}")
    cell = np.floor((point - scene.grid.origin[:2]) / scene.grid.pitch).astype(np.int64)
    inside = bool(np.all(cell >= 0) and np.all(cell < scene.walkable.shape))
    if not inside or not scene.walkable[cell[0], cell[1]]:
        raise UnreachableGoal(f"{name} {np.round(point, 2).tolist()} is not on the walkable floor of {scene.name} "
                              f"(inside furniture or a wall, within 0.25 m of one, or outside the rooms)")  # fmt: skip
    return cell


def _string_pull(cells: np.ndarray, costs: np.ndarray, detour: float) -> list[int]:
    """Indices into `cells` (P, 2) of the shortened path's corners: from each corner, the farthest later cell a
    straight walkable cut reaches for at most `detour` × the path's own cost between them."""
    steps = np.linalg.norm(np.diff(cells, axis=0), axis=1) * 0.5 * (costs[tuple(cells[:-1].T)] + costs[tuple(cells[1:].T)])
    along = np.concatenate([[0.0], np.cumsum(steps)])
    kept = [0]
    while kept[-1] < len(cells) - 1:
        here = kept[-1]
        reach = here + 1
        for later in range(len(cells) - 1, here + 1, -1):  # farthest first; paths have a few hundred cells
            cut = _cut_cost(cells[here], cells[later], costs)
            if np.isfinite(cut) and cut <= detour * (along[later] - along[here]):
                reach = later
                break
        kept.append(reach)
    return kept


def _cut_cost(a: np.ndarray, b: np.ndarray, costs: np.ndarray) -> float:
    """Cost of walking straight from cell `a` to cell `b` (cells sampled every half cell; inf across a blocked one)."""
    length = float(np.linalg.norm(b - a))
    samples = max(2, int(np.ceil(2 * length)) + 1)
    points = np.rint(a + np.outer(np.linspace(0.0, 1.0, samples), b - a)).astype(np.int64)
    return float(costs[points[:, 0], points[:, 1]].mean() * length)


def nearest_walkable(scene: Scene, points: np.ndarray) -> np.ndarray:
    """(K, 2) the centre of the walkable cell nearest to each of `points` (K, 2) (the point's own cell's centre
    when it is walkable): where a body that strayed near furniture re-plans from."""
    grid = scene.grid
    _, (rows, columns) = ndimage.distance_transform_edt(~scene.walkable, return_indices=True)
    cells = np.floor((np.asarray(points, dtype=np.float64) - grid.origin[:2]) / grid.pitch).astype(np.int64)
    cells = np.clip(cells, 0, np.array(scene.walkable.shape) - 1)
    nearest = np.stack([rows[cells[:, 0], cells[:, 1]], columns[cells[:, 0], cells[:, 1]]], axis=-1)
    return grid.origin[:2] + (nearest + 0.5) * grid.pitch


def geodesic_distance(scene: Scene, source: np.ndarray) -> np.ndarray:
    """(X, Y) walking distance (m) over the walkable region from the cell of `source` (2,) (fast marching,
    scikit-fmm); inf off the region."""
    grid = scene.grid
    cell = _walkable_cell(scene, source, "source")
    phi = np.ones(scene.walkable.shape)
    phi[cell[0], cell[1]] = -1.0
    distance = skfmm.distance(np.ma.MaskedArray(phi, ~scene.walkable), dx=grid.pitch)
    return np.ma.filled(np.abs(distance).astype(np.float64), np.inf)


def far_ends(scene: Scene, rng: np.random.Generator, clearance: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """A start and a goal (2,) at the far ends of the walkable region: the place farthest (walking) from a random
    one, and the place farthest from that (a double sweep of `geodesic_distance`). Both keep `clearance` m from
    every solid where the region has such places: a body's swinging hands reach ~0.4 m from its pelvis, and a start
    wedged into a corner (0.25 m from two walls) collides while the body turns."""
    grid = scene.grid
    roomy = scene.walkable & (grid.column_clearance() >= clearance)
    candidates = roomy if roomy.any() else scene.walkable

    def farthest(source: np.ndarray) -> np.ndarray:
        distance = geodesic_distance(scene, source)
        cell = np.unravel_index(np.argmax(np.where(np.isfinite(distance) & candidates, distance, -1.0)), distance.shape)
        return grid.origin[:2] + (np.array(cell) + 0.5) * grid.pitch

    start = farthest(scene.sample_free(rng, 1)[0])
    return start, farthest(start)
