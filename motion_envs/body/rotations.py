"""Rotation conversions used by the body model (thin wrappers over `roma`).

Six-D rotations follow Zhou et al. (CVPR 2019): the first two *columns* of
the rotation matrix, flattened column-major as (..., 6) = (c0, c1).
"""

from __future__ import annotations

import roma
import torch


def rotation_matrix(rotation: torch.Tensor) -> torch.Tensor:
    """Axis-angle (..., 3) or 6-D (..., 6) rotations -> (..., 3, 3) matrices."""
    if rotation.shape[-1] == 3:
        return roma.rotvec_to_rotmat(rotation)
    if rotation.shape[-1] == 6:
        return sixd_to_matrix(rotation)
    raise ValueError(
        f"rotations must end in 3 (axis-angle) or 6 (6-D), got shape {tuple(rotation.shape)}"
    )


def sixd_to_matrix(sixd: torch.Tensor) -> torch.Tensor:
    """(..., 6) first two columns -> (..., 3, 3) rotation via Gram-Schmidt."""
    columns = sixd.reshape(*sixd.shape[:-1], 2, 3).transpose(-1, -2)
    return roma.special_gramschmidt(columns)


def matrix_to_sixd(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation -> (..., 6) first two columns."""
    return matrix[..., :, :2].transpose(-1, -2).reshape(*matrix.shape[:-2], 6)


def matrix_to_axis_angle(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation -> (..., 3) axis-angle."""
    return roma.rotmat_to_rotvec(matrix)
