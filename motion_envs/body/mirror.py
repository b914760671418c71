"""Left/right mirror images of posed bodies and of marker offsets (batched torch), in a body-centred frame whose
x axis is the body's right (GAMMA's canonical frame).

Reflecting through the plane x = 0 maps a point (x, y, z) to (-x, y, z), a rotation R to S R S with
S = diag(-1, 1, 1) (the world's and SMPL-X's joint axes share the lateral x axis: `data.mirror`'s rule for
axis-angle), and swaps left and right joints. Markers are not mirrored by index: the SSM2 set is not
left/right symmetric (on the rest body, RBUSTLO's mirror image is 9.4 cm from the nearest marker, LBUST's 8.4,
RFRM2IN's 7.4, LIWR's 5.6; the median 1.3 cm), so a mirrored body's markers come from skinning it, and only small
offsets from a body's markers (the blend's) are carried over by `marker_partners`.
"""

from __future__ import annotations

from functools import lru_cache

import torch

from motion_envs.body.skeleton import MIRROR_JOINTS, rest_body

POSE_SWAP = torch.tensor([joint - 1 for joint in MIRROR_JOINTS[1:]])
"""(21,) the body_pose row of each joint's left/right counterpart."""


def mirror_points(points: torch.Tensor) -> torch.Tensor:
    """(..., 3) -> (..., 3) with x negated."""
    return points * points.new_tensor([-1.0, 1.0, 1.0])


def mirror_rotations(matrices: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) -> S R S: the entries with exactly one index 0 change sign."""
    return matrices * matrices.new_tensor([[1.0, -1.0, -1.0], [-1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]])


def mirror_body_pose(pose: torch.Tensor) -> torch.Tensor:
    """(..., 21, 3, 3) local joint rotations -> those of the mirror image (each joint takes its counterpart's)."""
    return mirror_rotations(pose[..., POSE_SWAP.to(pose.device), :, :])


@lru_cache(maxsize=1)
def marker_partners() -> torch.Tensor:
    """(67,) long: for each marker, the marker nearest to its mirror image on the rest body (module doc)."""
    from motion_envs.body.markers import marker_ids

    rest = torch.as_tensor(rest_body().vertices[marker_ids().numpy()], dtype=torch.float32)  # (67, 3)
    return torch.cdist(mirror_points(rest), rest).argmin(dim=1)


def mirror_marker_offsets(offsets: torch.Tensor) -> torch.Tensor:
    """(..., 67, 3) offsets from a body's markers -> the mirror image's, marker by marker (`marker_partners`)."""
    return mirror_points(offsets[..., marker_partners().to(offsets.device), :])
