"""Procedural furnished rooms in five layout families, standing in for the CLOPS paper's Replica scenes S1–S5.

| family | what | difficulty |
|---|---|---|
| `open` | one 5–7 m room, 2–3 pieces against the walls | easiest |
| `corridor` | a 2–2.6 m wide, 8–11 m long corridor, shelves and cabinets along both sides | narrow |
| `living` | a 6–8 × 5–7 m living room: sofa, dining table with chairs, shelf, cabinet, free-standing pieces | cluttered |
| `two_rooms` | two rooms joined by one 1 m door | a door to find |
| `apartment` | three rooms, two doors, 6–9 pieces (bed, sofa, table, …) | hardest |

A (family, seed) pair gives the same room every time. Seeds 0–999 are
training seeds, 1000–1099 held-out test seeds (`TRAIN_SEEDS`, `TEST_SEEDS`).
Pieces keep 0.6 m from each other and 0.8 m from doors, so a body can pass
between any two; the walkable region is still computed from the occupancy
grid (`Scene.walkable`), never assumed.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import trimesh

from motion_envs.scenes.furniture import PIECES, footprint
from motion_envs.scenes.labels import label_id
from motion_envs.scenes.scene import Scene, ScenePart

WALL_HEIGHT, WALL_THICKNESS, DOOR_WIDTH = 2.5, 0.1, 1.0
PIECE_GAP, DOOR_CLEARANCE = 0.6, 0.8
TRAIN_SEEDS, TEST_SEEDS = range(0, 1000), range(1000, 1100)

Rect = tuple[float, float, float, float]
"""x0, y0, x1, y1 (metres)."""


class _RoomBuilder:
    """Collects floor, walls (with door gaps) and furniture as labelled box meshes."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.parts: list[ScenePart] = []
        self.taken: list[Rect] = []  # furniture footprints grown by PIECE_GAP / 2, door keep-outs

    def box(self, centre: np.ndarray, size: np.ndarray, label: str, yaw: float = 0.0) -> None:
        transform = trimesh.transformations.rotation_matrix(yaw, (0, 0, 1))
        transform[:3, 3] = centre
        self.parts.append(ScenePart(trimesh.creation.box(extents=size, transform=transform), label_id(label)))

    def floor(self, rect: Rect) -> None:
        x0, y0, x1, y1 = rect
        vertices = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
        self.parts.append(ScenePart(trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], process=False), label_id("floor")))

    def wall(self, start: tuple[float, float], end: tuple[float, float], doors: tuple[float, ...] = ()) -> None:
        """An axis-aligned wall from `start` to `end` (xy), with 1 m door gaps centred `doors` metres from start."""
        start_, end_ = np.asarray(start, float), np.asarray(end, float)
        length = float(np.linalg.norm(end_ - start_))
        direction = (end_ - start_) / length
        cuts = [0.0]
        for door in sorted(doors):
            cuts += [door - DOOR_WIDTH / 2, door + DOOR_WIDTH / 2]
            centre = start_ + direction * door
            half = DOOR_CLEARANCE + DOOR_WIDTH / 2
            self.taken.append((centre[0] - half, centre[1] - half, centre[0] + half, centre[1] + half))
        cuts.append(length)
        for a, b in zip(cuts[::2], cuts[1::2]):
            if b - a < 1e-3:
                continue
            middle = start_ + direction * (a + b) / 2
            size = np.abs(direction) * (b - a) + np.abs(direction[::-1]) * WALL_THICKNESS
            self.box(np.array([*middle, WALL_HEIGHT / 2]), np.array([*size, WALL_HEIGHT]), "wall")

    def enclose(self, rect: Rect) -> None:
        """Floor and four walls around `rect`."""
        x0, y0, x1, y1 = rect
        self.floor(rect)
        for start, end in (((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)), ((x0, y1), (x0, y0))):
            self.wall(start, end)

    def place(self, kind: str, room: Rect, against_wall: bool, tries: int = 60) -> bool:
        """Put one `kind` piece in `room` (inside its walls) where it keeps its gaps; False when no spot is found."""
        boxes = PIECES[kind](self.rng)
        width, depth = footprint(boxes)
        x0, y0, x1, y1 = (room[0] + WALL_THICKNESS / 2, room[1] + WALL_THICKNESS / 2,
                          room[2] - WALL_THICKNESS / 2, room[3] - WALL_THICKNESS / 2)  # fmt: skip
        for _ in range(tries):
            quarter = int(self.rng.integers(4))  # back to the wall at y0, x1, y1, x0 (front faces inwards)
            yaw = quarter * np.pi / 2
            half = np.array([width, depth] if quarter % 2 == 0 else [depth, width]) / 2
            if np.any(2 * half > np.array([x1 - x0, y1 - y0]) - 0.05):
                return False
            centre = self.rng.uniform([x0 + half[0], y0 + half[1]], [x1 - half[0], y1 - half[1]])
            if against_wall:
                snapped = [(centre[0], y0 + half[1]), (x1 - half[0], centre[1]), (centre[0], y1 - half[1]), (x0 + half[0], centre[1])]
                centre = np.array(snapped[quarter])
            grown = (centre[0] - half[0] - PIECE_GAP / 2, centre[1] - half[1] - PIECE_GAP / 2,
                     centre[0] + half[0] + PIECE_GAP / 2, centre[1] + half[1] + PIECE_GAP / 2)  # fmt: skip
            if any(_overlap(grown, other) for other in self.taken):
                continue
            self.taken.append(grown)
            rotation = trimesh.transformations.rotation_matrix(yaw, (0, 0, 1))[:3, :3]
            for box in boxes:
                self.box(np.array([*centre, 0.0]) + rotation @ np.asarray(box.centre), np.asarray(box.size), kind, yaw)
            return True
        return False

    def furnish(self, room: Rect, kinds: list[str], against_wall: bool) -> None:
        for kind in kinds:
            self.place(kind, room, against_wall)


def _overlap(a: Rect, b: Rect) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _open(b: _RoomBuilder) -> None:
    room = (0.0, 0.0, b.rng.uniform(5, 7), b.rng.uniform(5, 7))
    b.enclose(room)
    b.furnish(room, list(b.rng.choice(["shelf", "cabinet", "sofa"], size=int(b.rng.integers(2, 4)))), against_wall=True)


def _corridor(b: _RoomBuilder) -> None:
    room = (0.0, 0.0, b.rng.uniform(2.0, 2.6), b.rng.uniform(8, 11))
    b.enclose(room)
    b.furnish(room, list(b.rng.choice(["shelf", "cabinet"], size=int(b.rng.integers(3, 6)))), against_wall=True)


def _living(b: _RoomBuilder) -> None:
    room = (0.0, 0.0, b.rng.uniform(6, 8), b.rng.uniform(5, 7))
    b.enclose(room)
    b.furnish(room, ["sofa", "shelf", "cabinet"], against_wall=True)
    b.furnish(room, ["table", "chair", "chair", *(["chair"] * int(b.rng.integers(0, 3))), "cabinet"], against_wall=False)


def _two_rooms(b: _RoomBuilder) -> None:
    width, depth = b.rng.uniform(8, 10), b.rng.uniform(4.5, 6)
    split = width / 2 + b.rng.uniform(-1, 1)
    b.enclose((0.0, 0.0, width, depth))
    b.wall((split, 0.0), (split, depth), doors=(b.rng.uniform(1.0, depth - 1.0),))
    for room in ((0.0, 0.0, split, depth), (split, 0.0, width, depth)):
        b.furnish(room, list(b.rng.choice(["shelf", "cabinet", "sofa", "table"], size=2)), against_wall=True)
        b.furnish(room, ["chair"], against_wall=False)


def _apartment(b: _RoomBuilder) -> None:
    width, depth = b.rng.uniform(9, 11), b.rng.uniform(7, 9)
    split_y = depth / 2 + b.rng.uniform(-0.8, 0.8)
    split_x = width / 2 + b.rng.uniform(-1.5, 1.5)
    b.enclose((0.0, 0.0, width, depth))
    b.wall((0.0, split_y), (width, split_y), doors=(b.rng.uniform(1.0, split_x - 1.0), b.rng.uniform(split_x + 1.0, width - 1.0)))
    b.wall((split_x, split_y), (split_x, depth), doors=(b.rng.uniform(1.0, depth - split_y - 1.0),))
    b.furnish((0.0, 0.0, width, split_y), ["sofa", "shelf", "cabinet"], against_wall=True)
    b.furnish((0.0, 0.0, width, split_y), ["table", "chair", "chair"], against_wall=False)
    b.furnish((0.0, split_y, split_x, depth), ["bed", "cabinet"], against_wall=True)
    b.furnish((split_x, split_y, width, depth), ["shelf", "table"], against_wall=True)


FAMILIES: dict[str, Callable[[_RoomBuilder], None]] = {
    "open": _open, "corridor": _corridor, "living": _living, "two_rooms": _two_rooms, "apartment": _apartment,
}  # fmt: skip
"""Layout family name -> builder, easiest to hardest."""


def families_of(choice: str) -> tuple[str, ...]:
    """The layout families an env's `choice` draws from: one family, or all of them for "mixed"."""
    return tuple(FAMILIES) if choice == "mixed" else (choice,)


def seeds_of(split: str, train_scenes: int, scene_seeds: tuple[int, ...] | None) -> tuple[int, ...]:
    """An env's room seeds: `scene_seeds` when given, else the first `train_scenes` training seeds ('train') or the
    held-out ones ('test')."""
    if scene_seeds is not None:
        return tuple(int(seed) for seed in scene_seeds)
    return tuple(TRAIN_SEEDS[:train_scenes]) if split == "train" else tuple(TEST_SEEDS)


def make_scene(family: str, seed: int) -> Scene:
    """The room of `family` for `seed` (deterministic)."""
    if family not in FAMILIES:
        raise ValueError(f"unknown scene family {family!r}; choose from {tuple(FAMILIES)}")
    builder = _RoomBuilder(np.random.default_rng([seed, list(FAMILIES).index(family)]))
    FAMILIES[family](builder)
    return Scene(builder.parts, name=f"{family}-{seed}")
