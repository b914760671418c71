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
        return axis_angle_to_matrix(rotation)
    if rotation.shape[-1] == 6:
        return sixd_to_matrix(rotation)
    raise ValueError(
        f"rotations must end in 3 (axis-angle) or 6 (6-D), got shape {tuple(rotation.shape)}"
    )


def axis_angle_to_matrix(rotvec: torch.Tensor) -> torch.Tensor:
    """(..., 3) axis-angle -> (..., 3, 3) rotation (Rodrigues); see `rodrigues`."""
    x, y, z = rotvec.movedim(-1, 0)
    return rodrigues(x, y, z)


def about_z(angle: torch.Tensor) -> torch.Tensor:
    """(...,) radians -> (..., 3, 3) rotations about +z (counter-clockwise seen from above)."""
    zero = torch.zeros_like(angle)
    return rodrigues(zero, zero, angle)


def wrap_angle(angle: torch.Tensor) -> torch.Tensor:
    """Angles (...,) wrapped into (-π, π]."""
    return torch.atan2(torch.sin(angle), torch.cos(angle))


def rodrigues(x: torch.Tensor, y: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """Axis-angle given as three (...) component planes -> (..., 3, 3) rotations.

    Written over contiguous planes because it is the hottest conversion of
    forward kinematics: 3.8 ms against 8.7 ms for `roma.rotvec_to_rotmat` on
    86,016 rotations (4,096 poses x 21 joints, 2 cores, torch 2.13); the two
    agree to 1e-6 (tested). Near zero angle it uses the series
    sin(t)/t ~ 1 - t²/6 and (1 - cos t)/t² ~ 1/2 - t²/24, so gradients stay finite.
    """
    return torch.stack(rodrigues_entries(x, y, z), dim=-1).reshape(*x.shape, 3, 3)


def rodrigues_entries(x: torch.Tensor, y: torch.Tensor, z: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """`rodrigues` as its nine entries, row-major, each shaped as the component planes (the planes layout that
    `BodyModel` composes in)."""
    squared = x * x + y * y + z * z
    small = squared < 1e-8
    angle = torch.sqrt(torch.where(small, torch.ones_like(squared), squared))
    sine_ratio = torch.where(small, 1.0 - squared / 6.0, torch.sin(angle) / angle)
    cosine_ratio = torch.where(small, 0.5 - squared / 24.0, (1.0 - torch.cos(angle)) / (angle * angle))
    cosine = 1.0 - cosine_ratio * squared
    xs, ys, zs = x * sine_ratio, y * sine_ratio, z * sine_ratio
    xc, yc, zc = x * cosine_ratio, y * cosine_ratio, z * cosine_ratio
    xy, xz, yz = x * yc, x * zc, y * zc
    return (cosine + x * xc, xy - zs, xz + ys, xy + zs, cosine + y * yc, yz - xs, xz - ys, yz + xs, cosine + z * zc)


def sixd_to_matrix(sixd: torch.Tensor) -> torch.Tensor:
    """(..., 6) first two columns -> (..., 3, 3) rotation via Gram-Schmidt (as `roma.special_gramschmidt`).

    Written over the six component planes, like `rodrigues`: roma normalises a column of a (..., 3, 2) view, a
    reduction over a stride-2 axis that torch's CPU kernels run 30-65x slower than a contiguous one (30 ms for
    172,032 rotations inside a GAMMA step of 1,024 bodies, 2 cores); this takes 3.2 ms against roma's 6.8 ms on
    contiguous input and agrees with it to float32 rounding (tested). The planes are made contiguous first (one
    transpose copy): elementwise passes over stride-6 planes cost more (8,192 × 21 rotations: 7.2 -> 5.9 ms)."""
    entries = gram_schmidt_entries(*sixd.reshape(-1, 6).t().contiguous())
    return torch.stack(entries, dim=-1).reshape(*sixd.shape[:-1], 3, 3)


def gram_schmidt_entries(a0: torch.Tensor, a1: torch.Tensor, a2: torch.Tensor, b0: torch.Tensor, b1: torch.Tensor,
                         b2: torch.Tensor) -> tuple[torch.Tensor, ...]:  # fmt: skip
    """`sixd_to_matrix` over the six component planes (any one shape) -> the nine entries, row-major, shaped as
    the planes."""
    scale = torch.rsqrt((a0 * a0 + a1 * a1 + a2 * a2).clamp_min(1e-24))
    x0, x1, x2 = a0 * scale, a1 * scale, a2 * scale
    along = x0 * b0 + x1 * b1 + x2 * b2
    c0, c1, c2 = b0 - along * x0, b1 - along * x1, b2 - along * x2
    scale = torch.rsqrt((c0 * c0 + c1 * c1 + c2 * c2).clamp_min(1e-24))
    y0, y1, y2 = c0 * scale, c1 * scale, c2 * scale
    z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    return x0, y0, z0, x1, y1, z1, x2, y2, z2


def matrix_to_sixd(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation -> (..., 6) first two columns."""
    return matrix[..., :, :2].transpose(-1, -2).reshape(*matrix.shape[:-2], 6)


def matrix_to_axis_angle(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation -> (..., 3) axis-angle."""
    return roma.rotmat_to_rotvec(matrix)


def planes_matmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(3, 3, ...) @ (3, 3, ...) in the planes layout (components first): 27 elementwise products over the batch
    (six times faster than a batched matmul's 3 x 3 kernels at 16,384 matrices, and no layout copies), as three
    outer products of a column and a row accumulated in place (a (3, 3, 3, ...) product summed over its middle
    axis was 3x slower: 117 against 38 us at 16,384 matrices, 2 cores)."""
    product = a[:, :1] * b[None, 0]
    product.addcmul_(a[:, 1:2], b[None, 1])
    return product.addcmul_(a[:, 2:], b[None, 2])
