"""Body-surface marker set (GAMMA's SSM2 names), foot vertices and the head camera.

GAMMA represents the body by 67 markers of the SSM2 set on the SMPL-X mesh.
Our body is the mannequin-x wooden mesh, so the SMPL-X vertex ids do not
apply: each marker is placed where its name says by `MARKER_PLACEMENT` (an
anchor on the rest skeleton and an outward direction in the body frame:
right +x, forward +y, up +z) and the chosen vertex ids are frozen in
`MARKER_VERTICES`, so that trained priors stay valid. `python -m
motion_envs.body.markers` re-runs the placement and prints the table; a test
checks that it still gives the frozen ids on the installed mannequin-x.

Names whose meaning is not obvious: BUST(LO) (lower) chest, NWST side of the
waist, FWT/BWT front/back waist, FRM2(IN) back (inner) side of the forearm,
IWR/OWR thumb/little-finger side of the wrist, MT1/MT5 first/fifth metatarsal
head, RSTBEEF sole under the ball of the foot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from motion_envs.body.skeleton import JOINT_NAMES, RestBody, rest_body

MARKER_NAMES: tuple[str, ...] = (
    "C7", "CLAV", "LANK", "LFWT", "LBAK", "LBCEP", "LBSH", "LBUM", "LBUST", "LCHEECK",
    "LELB", "LELBIN", "LFIN", "LFRM2", "LFTHI", "LFTHIIN", "LHEE", "LIWR", "LKNE", "LKNI",
    "LMT1", "LMT5", "LNWST", "LOWR", "LBWT", "LRSTBEEF", "LSHO", "LTHI", "LTHMB", "LTIB",
    "LTOE", "MBLLY", "RANK", "RFWT", "RBAK", "RBCEP", "RBSH", "RBUM", "RBUSTLO", "RCHEECK",
    "RELB", "RELBIN", "RFIN", "RFRM2", "RFRM2IN", "RFTHI", "RFTHIIN", "RHEE", "RKNE", "RKNI",
    "RMT1", "RMT5", "RNWST", "ROWR", "RBWT", "RRSTBEEF", "RSHO", "RTHI", "RTHMB", "RTIB",
    "RTOE", "STRN", "T8", "LFHD", "LBHD", "RFHD", "RBHD",
)  # fmt: skip
"""The 67 SSM2 marker names in GAMMA's order (201-d marker vector = 67 x 3)."""

FOOT_MARKERS: tuple[str, ...] = ("RHEE", "RTOE", "RRSTBEEF", "LHEE", "LTOE", "LRSTBEEF")
"""EgoGen/GAMMA's foot markers, used for contact and skating terms."""


@dataclass(frozen=True)
class Placement:
    """Where a marker goes: the skin point farthest along `direction` near `anchor`.

    anchor: joint weights (name -> weight, summing to 1) plus `offset` (m).
    direction: outward direction in the body frame (right +x, forward +y, up +z).
    radius: only vertices this close to the anchor, and on the marker's side
        of the body (x < 0 left, x > 0 right; either for midline markers), are
        candidates.
    """

    anchor: tuple[tuple[str, float], ...]
    offset: tuple[float, float, float]
    direction: tuple[float, float, float]
    radius: float = 0.2
    side: int = 0


# Left-side placements: lateral is -x. Right-side ones mirror x.
_SIDED: dict[str, Placement] = {
    "ANK": Placement((("ankle", 1.0),), (0, 0, 0), (-1, 0, 0)),
    "FWT": Placement((("pelvis", 0.4), ("hip", 0.6)), (-0.04, 0, 0.09), (-0.3, 1, 0)),
    "BAK": Placement((("spine3", 0.5), ("collar", 0.5)), (-0.04, 0, -0.08), (-0.2, -1, 0)),
    "BCEP": Placement((("shoulder", 0.5), ("elbow", 0.5)), (0, 0, 0), (0, 1, 0.2)),
    "BSH": Placement((("shoulder", 1.0),), (0.02, 0, 0), (0, -1, 0.5)),
    "BUM": Placement((("hip", 1.0),), (0, 0, -0.05), (-0.2, -1, 0)),
    "BUST": Placement((("spine3", 1.0),), (-0.09, 0, -0.04), (0, 1, 0)),
    "BUSTLO": Placement((("spine3", 1.0),), (-0.09, 0, -0.12), (0, 1, 0)),
    "CHEECK": Placement((("head", 1.0),), (-0.04, 0, 0.03), (-0.5, 1, 0)),
    "ELB": Placement((("elbow", 1.0),), (0, 0, 0), (0, -1, 0.2)),
    "ELBIN": Placement((("elbow", 1.0),), (0, 0, 0), (0, 1, -0.2)),
    "FIN": Placement((("wrist", 1.0),), (-0.12, 0, 0), (-1, 0, -0.2), radius=0.25),
    "FRM2": Placement((("elbow", 0.4), ("wrist", 0.6)), (0, 0, 0), (0, 0, 1)),
    "FRM2IN": Placement((("elbow", 0.4), ("wrist", 0.6)), (0, 0, 0), (0, 0, -1)),
    "FTHI": Placement((("hip", 0.5), ("knee", 0.5)), (0, 0, 0), (0, 1, 0)),
    "FTHIIN": Placement((("hip", 0.4), ("knee", 0.6)), (0, 0, 0), (0.7, 1, 0)),
    "HEE": Placement((("ankle", 1.0),), (0, 0, -0.04), (0, -1, -0.3)),
    "IWR": Placement((("wrist", 1.0),), (0, 0, 0), (0, 1, 0), radius=0.06),
    "OWR": Placement((("wrist", 1.0),), (0, 0, 0), (0, -1, 0), radius=0.06),
    "KNE": Placement((("knee", 1.0),), (0, 0, 0), (-1, 0, 0)),
    "KNI": Placement((("knee", 1.0),), (0, 0, 0), (1, 0, 0)),
    "MT1": Placement((("foot", 1.0),), (0, -0.03, -0.01), (1, 0.2, 0), radius=0.08),
    "MT5": Placement((("foot", 1.0),), (0, -0.03, -0.01), (-1, 0.2, 0), radius=0.08),
    "NWST": Placement((("pelvis", 0.5), ("spine1", 0.5)), (0, 0, 0), (-1, 0.3, 0)),
    "BWT": Placement((("pelvis", 1.0),), (-0.06, 0, 0.05), (-0.2, -1, 0)),
    "RSTBEEF": Placement((("foot", 1.0),), (0, -0.02, 0), (0, 0, -1), radius=0.06),
    "SHO": Placement((("shoulder", 1.0),), (0, 0, 0), (0, 0, 1)),
    "THI": Placement((("hip", 0.5), ("knee", 0.5)), (0, 0, 0), (-1, 0, 0)),
    "THMB": Placement((("wrist", 1.0),), (-0.05, 0.03, 0), (-0.5, 1, -0.3), radius=0.2),
    "TIB": Placement((("knee", 0.5), ("ankle", 0.5)), (0, 0, 0), (0, 1, 0)),
    "TOE": Placement((("foot", 1.0),), (0, 0, 0), (0, 1, -0.2), radius=0.12),
    "FHD": Placement((("head", 1.0),), (-0.04, 0, 0.09), (-0.4, 1, 0.4)),
    "BHD": Placement((("head", 1.0),), (-0.04, 0, 0.09), (-0.4, -1, 0.4)),
}
_MIDLINE: dict[str, Placement] = {
    "C7": Placement((("neck", 1.0),), (0, 0, -0.03), (0, -1, 0.2)),
    "CLAV": Placement((("neck", 1.0),), (0, 0, -0.06), (0, 1, 0)),
    "MBLLY": Placement((("spine1", 1.0),), (0, 0, 0), (0, 1, 0)),
    "STRN": Placement((("spine3", 1.0),), (0, 0, 0.0), (0, 1, 0)),
    "T8": Placement((("spine2", 0.5), ("spine3", 0.5)), (0, 0, 0), (0, -1, 0)),
}
_SIDED_JOINTS = {"ankle", "hip", "collar", "shoulder", "elbow", "wrist", "knee", "foot"}


def marker_placement(name: str) -> Placement:
    """The placement rule of one SSM2 marker, resolved to joint names and side."""
    if name in _MIDLINE:
        return _MIDLINE[name]
    side, part = name[0], name[1:]
    if side not in "LR" or part not in _SIDED:
        raise KeyError(f"no placement for marker {name!r}")
    rule = _SIDED[part]
    prefix = "left_" if side == "L" else "right_"
    sign = -1.0 if side == "R" else 1.0
    anchor = tuple((prefix + j if j in _SIDED_JOINTS else j, w) for j, w in rule.anchor)
    mirror = np.array([sign, 1.0, 1.0])
    return Placement(
        anchor,
        tuple(np.asarray(rule.offset) * mirror),
        tuple(np.asarray(rule.direction) * mirror),
        rule.radius,
        side=-1 if side == "L" else 1,
    )


def place_marker(rest: RestBody, rule: Placement) -> int:
    """Vertex id farthest along `rule.direction` from the anchor, penalising sideways drift."""
    anchor = sum(w * rest.rest_joints[JOINT_NAMES.index(j)] for j, w in rule.anchor)
    anchor = anchor + np.asarray(rule.offset)
    direction = np.asarray(rule.direction, dtype=np.float64)
    direction /= np.linalg.norm(direction)
    relative = rest.vertices - anchor
    along = relative @ direction
    across = np.linalg.norm(relative - along[:, None] * direction, axis=1)
    candidate = (np.linalg.norm(relative, axis=1) <= rule.radius) & (rest.vertices[:, 0] * rule.side >= 0)
    score = np.where(candidate, along - 2.0 * across, -np.inf)
    return int(np.argmax(score))


def place_all(rest: RestBody | None = None) -> dict[str, int]:
    """Run the placement for every SSM2 marker on the rest body."""
    rest = rest_body() if rest is None else rest
    return {name: place_marker(rest, marker_placement(name)) for name in MARKER_NAMES}


MARKER_VERTICES: dict[str, int] = {
    "C7": 782, "CLAV": 816, "LANK": 19942, "LFWT": 4026, "LBAK": 1188, "LBCEP": 4868,
    "LBSH": 1597, "LBUM": 22089, "LBUST": 1395, "LCHEECK": 14795, "LELB": 11778, "LELBIN": 11972,
    "LFIN": 6885, "LFRM2": 5998, "LFTHI": 22096, "LFTHIIN": 22404, "LHEE": 20111, "LIWR": 22999,
    "LKNE": 22509, "LKNI": 22460, "LMT1": 20459, "LMT5": 20692, "LNWST": 4402, "LOWR": 7406,
    "LBWT": 3931, "LRSTBEEF": 20523, "LSHO": 4651, "LTHI": 22389, "LTHMB": 7382, "LTIB": 20770,
    "LTOE": 20237, "MBLLY": 2249, "RANK": 18791, "RFWT": 3234, "RBAK": 31, "RBCEP": 8419,
    "RBSH": 433, "RBUM": 17180, "RBUSTLO": 2366, "RCHEECK": 15601, "RELB": 8286, "RELBIN": 13356,
    "RFIN": 10439, "RFRM2": 9554, "RFRM2IN": 9162, "RFTHI": 17103, "RFTHIIN": 17162, "RHEE": 18912,
    "RKNE": 17230, "RKNI": 16473, "RMT1": 18479, "RMT5": 19494, "RNWST": 3722, "ROWR": 10961,
    "RBWT": 3251, "RRSTBEEF": 19318, "RSHO": 8204, "RTHI": 17147, "RTHMB": 10937, "RTIB": 17404,
    "RTOE": 19035, "STRN": 1154, "T8": 1121, "LFHD": 14650, "LBHD": 14746, "RFHD": 15331,
    "RBHD": 15309,
}  # fmt: skip
"""Frozen vertex id of each SSM2 marker on the mannequin-x wooden mesh."""


def marker_ids(names: tuple[str, ...] = MARKER_NAMES) -> torch.Tensor:
    """(M,) long vertex ids of the named markers, in the given order."""
    return torch.tensor([MARKER_VERTICES[n] for n in names], dtype=torch.long)


def foot_vertex_ids(rest: RestBody | None = None) -> torch.Tensor:
    """(F,) vertex ids whose minimum height is the body's lowest foot point.

    The skin around each ankle and toe joint moves almost rigidly with that
    joint, and the lowest point of a rigid point set lies on its convex hull,
    so the hull vertices of each of the four foot parts stand in for the whole
    foot in "lowest vertex" metrics such as WANDR's FS. Only hull vertices
    below their joint can be lowest while the foot is on or near the ground;
    they are thinned to one per 1 cm cell (about two hundred ids in all).
    """
    from scipy.spatial import ConvexHull

    rest = rest_body() if rest is None else rest
    dominant = rest.skin_joints[np.arange(len(rest.vertices)), rest.skin_weights.argmax(axis=1)]
    ids: list[np.ndarray] = []
    for joint in ("left_ankle", "right_ankle", "left_foot", "right_foot"):
        part = np.flatnonzero(dominant == JOINT_NAMES.index(joint))
        on_hull = part[ConvexHull(rest.vertices[part]).vertices]
        below = on_hull[rest.vertices[on_hull, 2] < rest.rest_joints[JOINT_NAMES.index(joint), 2]]
        _, first = np.unique(np.floor(rest.vertices[below] / 0.01), axis=0, return_index=True)
        ids.append(below[first])
    return torch.as_tensor(np.sort(np.concatenate(ids)), dtype=torch.long)


SOLE_POINTS: tuple[str, ...] = ("left_heel", "left_toe", "right_heel", "right_toe")
"""The four contact points of `sole_vertex_ids`, in its order."""


def sole_vertex_ids(rest: RestBody | None = None) -> torch.Tensor:
    """(4,) vertex ids of the heel and the toe of each foot's sole (`SOLE_POINTS` order).

    Of each part's sole (its vertices within 1.5 cm of its lowest point at rest), heel: the lowest vertex of the
    ankle part's rearmost 3 cm; toe: the lowest of the toe part's foremost 3 cm. Both touch the floor (within
    about 1 cm) when the foot stands flat; a rolling foot loads the heel first and the toe last, so contact is
    labelled (and locked) for each point on its own.
    """
    rest = rest_body() if rest is None else rest
    dominant = rest.skin_joints[np.arange(len(rest.vertices)), rest.skin_weights.argmax(axis=1)]
    ids = []
    for side in ("left", "right"):
        for joint, forward in ((f"{side}_ankle", -1.0), (f"{side}_foot", 1.0)):
            part = np.flatnonzero(dominant == JOINT_NAMES.index(joint))
            sole = part[rest.vertices[part, 2] < rest.vertices[part, 2].min() + 0.015]
            along = forward * rest.vertices[sole, 1]
            end = sole[along > along.max() - 0.03]
            ids.append(int(end[np.argmin(rest.vertices[end, 2])]))
    return torch.tensor(ids, dtype=torch.long)


if __name__ == "__main__":
    placed = list(place_all().items())
    for start in range(0, len(placed), 6):
        print("    " + " ".join(f'"{name}": {vertex},' for name, vertex in placed[start : start + 6]))
