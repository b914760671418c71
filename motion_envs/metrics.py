"""Motion metrics shared by benchmarks and environments (batched torch)."""

from __future__ import annotations

import torch

WANDR_SKATING_THRESHOLD = 2.0 / 3.0 * 0.01
"""WANDR's FS threshold: 0.66 cm between consecutive frames at 30 fps (0.2 m/s)."""


def foot_skating(feet: torch.Tensor, threshold: float = WANDR_SKATING_THRESHOLD) -> torch.Tensor:
    """WANDR's foot skating per frame transition.

    The lowest foot vertex of frame t skates if that same vertex moves more
    than `threshold` metres horizontally by frame t + 1 (no height gating, as
    in the WANDR release).

    Args:
        feet: (..., T, V, 3) foot vertex positions (see `body.markers.foot_vertex_ids`).

    Returns:
        (..., T - 1) bool, True where the frame skates. FS is its mean.
    """
    lowest = feet[..., :-1, :, 2].argmin(dim=-1, keepdim=True)  # (..., T-1, 1)
    index = lowest[..., None].expand(*lowest.shape, 2)
    now = torch.gather(feet[..., :-1, :, :2], -2, index)
    then = torch.gather(feet[..., 1:, :, :2], -2, index)
    return (then - now).norm(dim=-1).squeeze(-1) > threshold
