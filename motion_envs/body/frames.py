"""The one place where mannequin-x's Y-up frame becomes the suite's Z-up world.

mannequin-x (like SMPL-X) builds its rest body Y up, facing +Z, with the body's
left on +X. The suite's world is Z up with the rest body facing +Y (the
canonical frame of GAMMA and WANDR), so its right is +X and its left is -X.
`MANNEQUIN_TO_WORLD` is the proper rotation taking mannequin coordinates to
world coordinates: (x, y, z) -> (-x, z, y).
"""

from __future__ import annotations

import numpy as np

Y_UP_TO_Z_UP = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]], dtype=np.float64)
"""(3, 3) rotation, det +1: takes a Y-up frame whose figures face +Z to Z up facing +Y."""

MANNEQUIN_TO_WORLD = Y_UP_TO_Z_UP
"""world = MANNEQUIN_TO_WORLD @ mannequin (also used for Y-up mocap, which shares the axes)."""
