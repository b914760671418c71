"""Semantic labels of scene surfaces and their fixed colours (the egocentric semantic channels)."""

from __future__ import annotations

import numpy as np

LABELS: tuple[str, ...] = ("void", "floor", "wall", "table", "chair", "sofa", "bed", "shelf", "cabinet", "other")
"""Label ids are indices into this tuple; "void" is what a ray that hits nothing sees."""

PALETTE = np.array(
    [
        (0, 0, 0),  # void
        (186, 176, 156),  # floor
        (222, 222, 214),  # wall
        (150, 96, 52),  # table
        (214, 148, 40),  # chair
        (64, 110, 178),  # sofa
        (170, 60, 120),  # bed
        (90, 160, 70),  # shelf
        (120, 120, 150),  # cabinet
        (240, 120, 110),  # other
    ],
    dtype=np.uint8,
)
"""(len(LABELS), 3) uint8 RGB per label id."""


def label_id(name: str) -> int:
    """Id of a label name; a clear error for an unknown one."""
    if name not in LABELS:
        raise ValueError(f"unknown scene label {name!r}; known: {LABELS}")
    return LABELS.index(name)


def label_from_name(node_name: str) -> int:
    """Label of a mesh node named like 'chair', 'chair_2' or 'Sofa.001' ("other" when no label is in the name)."""
    lowered = node_name.lower()
    for index, name in enumerate(LABELS[1:], start=1):
        if name in lowered:
            return index
    return LABELS.index("other")
