"""The soles' hull vertices that GammaReach's floor rule grounds.

Beside `markers.py` rather than in it: that module is part of the data cache's key (`data.build.CACHE_CODE`, for
the contact points the cleanup uses), and this one is not data code.
"""

from __future__ import annotations

import numpy as np
import torch

from motion_envs.body.skeleton import JOINT_NAMES, RestBody, rest_body


def sole_hull_vertex_ids(cell: float = 0.04, rest: RestBody | None = None) -> torch.Tensor:
    """(F,) vertex ids of the soles (F = 50 at 4 cm): a cheap stand-in for `foot_vertex_ids` in a floor rule, whose
    lowest point is within millimetres of the lowest foot point for a foot that stands, rolls or tips.

    Each of the four foot parts (ankle and toe of each foot) moves almost rigidly, and the lowest point of a rigid
    point set lies on its convex hull. Of each part, the hull of its sole (its vertices within 3 cm of its lowest
    point at rest) is kept, one vertex per `cell` × `cell` square of the ground plan (the lowest at rest). Measured
    on GAMMA primitives of uniform latents in [-4, 4]: the lowest of these is at most 6.6 mm (median 0.9 mm) above
    the lowest of `foot_vertex_ids`' 484 vertices; the soles' 2-D rims alone miss the rounded bottom by ~1 cm.
    """
    from scipy.spatial import ConvexHull

    rest = rest_body() if rest is None else rest
    dominant = rest.skin_joints[np.arange(len(rest.vertices)), rest.skin_weights.argmax(axis=1)]
    ids: list[np.ndarray] = []
    for joint in ("left_ankle", "left_foot", "right_ankle", "right_foot"):
        part = np.flatnonzero(dominant == JOINT_NAMES.index(joint))
        sole = part[rest.vertices[part, 2] < rest.vertices[part, 2].min() + 0.03]
        hull = sole[ConvexHull(rest.vertices[sole]).vertices]
        lowest_first = hull[np.argsort(rest.vertices[hull, 2], kind="stable")]
        _, first = np.unique(np.floor(rest.vertices[lowest_first, :2] / cell), axis=0, return_index=True)
        ids.append(np.sort(lowest_first[first]))
    return torch.as_tensor(np.concatenate(ids), dtype=torch.long)
