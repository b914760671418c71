"""Furniture as unions of boxes, in a local frame: footprint centred on the origin, standing on z = 0, front = +y.

Every piece is a list of `Box`es (solid, so collision and rendering agree);
sizes are drawn from ranges typical of real furniture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Box:
    """An axis-aligned box in the piece's frame: centre (3,) and size (3,) in metres."""

    centre: tuple[float, float, float]
    size: tuple[float, float, float]


def table(rng: np.random.Generator) -> list[Box]:
    width, depth, height = rng.uniform(1.0, 1.6), rng.uniform(0.7, 0.9), 0.75
    legs = [Box((sx * (width / 2 - 0.05), sy * (depth / 2 - 0.05), (height - 0.04) / 2), (0.05, 0.05, height - 0.04))
            for sx in (-1, 1) for sy in (-1, 1)]  # fmt: skip
    return [Box((0.0, 0.0, height - 0.02), (width, depth, 0.04)), *legs]


def chair(rng: np.random.Generator) -> list[Box]:
    width = rng.uniform(0.42, 0.5)
    seat = 0.45
    legs = [Box((sx * (width / 2 - 0.03), sy * (width / 2 - 0.03), (seat - 0.04) / 2), (0.04, 0.04, seat - 0.04))
            for sx in (-1, 1) for sy in (-1, 1)]  # fmt: skip
    return [Box((0.0, 0.0, seat - 0.02), (width, width, 0.04)), Box((0.0, -width / 2 + 0.02, seat + 0.22), (width, 0.04, 0.44)), *legs]


def sofa(rng: np.random.Generator) -> list[Box]:
    width, depth = rng.uniform(1.6, 2.2), rng.uniform(0.85, 0.95)
    return [
        Box((0.0, 0.0, 0.21), (width, depth, 0.42)),
        Box((0.0, -depth / 2 + 0.1, 0.63), (width, 0.2, 0.42)),
        *[Box((sx * (width / 2 - 0.08), 0.0, 0.52), (0.16, depth, 0.2)) for sx in (-1, 1)],
    ]


def bed(rng: np.random.Generator) -> list[Box]:
    width, depth = rng.uniform(1.4, 1.8), rng.uniform(1.95, 2.1)
    return [Box((0.0, 0.0, 0.25), (width, depth, 0.5)), Box((0.0, -depth / 2 + 0.04, 0.5), (width, 0.08, 1.0))]


def shelf(rng: np.random.Generator) -> list[Box]:
    width, height = rng.uniform(0.8, 1.2), rng.uniform(1.7, 2.0)
    return [Box((0.0, 0.0, height / 2), (width, 0.35, height))]


def cabinet(rng: np.random.Generator) -> list[Box]:
    width, height = rng.uniform(0.6, 1.0), rng.uniform(0.8, 1.0)
    return [Box((0.0, 0.0, height / 2), (width, 0.5, height))]


PIECES = {"table": table, "chair": chair, "sofa": sofa, "bed": bed, "shelf": shelf, "cabinet": cabinet}
"""Label -> builder `(rng) -> list[Box]`."""


def footprint(boxes: list[Box]) -> tuple[float, float]:
    """Width (x) and depth (y) of the piece's bounding rectangle."""
    low = np.min([np.subtract(b.centre, np.divide(b.size, 2)) for b in boxes], axis=0)
    high = np.max([np.add(b.centre, np.divide(b.size, 2)) for b in boxes], axis=0)
    return float(high[0] - low[0]), float(high[1] - low[1])
