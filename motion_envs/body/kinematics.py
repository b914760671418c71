"""Batched, differentiable forward kinematics and linear-blend skinning in torch.

Parameter convention (documented once here, used everywhere):

* `transl` (..., 3): world position of the pelvis joint (Z up, metres). This
  differs from SMPL-X, whose `transl` is added to the rest pelvis; convert an
  SMPL-X/AMASS translation with `transl = trans + J_pelvis_rest`.
* `global_orient` (..., 3 | 6): world rotation of the pelvis; zero is the rest
  body standing upright facing +Y. (An AMASS `root_orient` R_a, which also
  lifts SMPL's Y-up body into Z up, is R_a = R_go @ MANNEQUIN_TO_WORLD.)
* `body_pose` (..., 21, 3 | 6): SMPL-X local joint rotations of joints 1..21,
  in SMPL-X's own (Y-up) joint axes, so SMPL-X/AMASS body poses carry over
  unchanged.

Returned rotations are world rotations of each joint frame, identity at rest.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch
from torch import nn

from motion_envs.body.frames import MANNEQUIN_TO_WORLD
from motion_envs.body.rotations import rotation_matrix
from motion_envs.body.skeleton import NUM_BODY_POSE_JOINTS, NUM_JOINTS, PARENTS, rest_body


class BodyPose(NamedTuple):
    """Posed skeleton.

    joints: (..., 22, 3) world joint positions.
    rotations: (..., 22, 3, 3) world joint rotations (identity at rest).
    """

    joints: torch.Tensor
    rotations: torch.Tensor


def _levels(parents: tuple[int, ...]) -> list[list[int]]:
    depth = [0] * len(parents)
    for joint in range(1, len(parents)):
        depth[joint] = depth[parents[joint]] + 1
    return [[j for j in range(len(parents)) if depth[j] == d] for d in range(max(depth) + 1)]


class BodyModel(nn.Module):
    """The mannequin-x body as a torch module (22 joints, any device, differentiable).

    Args:
        shape: SMPL-X shape coefficients (10); zeros is the neutral body.
    """

    def __init__(self, shape: tuple[float, ...] = (0.0,) * 10) -> None:
        super().__init__()
        rest = rest_body(tuple(float(b) for b in shape))
        self.shape_coefficients = tuple(float(b) for b in shape)
        self.register_buffer("offsets", torch.as_tensor(rest.offsets, dtype=torch.float32))
        self.register_buffer("rest_joints", torch.as_tensor(rest.rest_joints, dtype=torch.float32))
        self.register_buffer("skin_joints", torch.as_tensor(rest.skin_joints, dtype=torch.long))
        self.register_buffer("skin_offsets", torch.as_tensor(rest.skin_offsets, dtype=torch.float32))
        self.register_buffer("skin_weights", torch.as_tensor(rest.skin_weights, dtype=torch.float32))
        self.register_buffer(
            "axes_to_world", torch.as_tensor(MANNEQUIN_TO_WORLD, dtype=torch.float32)
        )
        levels = _levels(PARENTS)
        order = [j for level in levels for j in level]  # joints grouped by depth
        self._level_bounds = [(order.index(level[0]), order.index(level[0]) + len(level)) for level in levels]
        # parents of depth-d joints all have depth d-1: index them within that level
        for depth in range(1, len(levels)):
            slots = torch.tensor([levels[depth - 1].index(PARENTS[j]) for j in levels[depth]])
            self.register_buffer(f"parent_slots_{depth}", slots, persistent=False)
        self.register_buffer("level_offsets", self.offsets[order], persistent=False)
        self.register_buffer("pose_order", torch.tensor([j - 1 for j in order[1:]]), persistent=False)
        self.register_buffer("joint_slot", torch.tensor([order.index(j) for j in range(NUM_JOINTS)]), persistent=False)

    @property
    def num_vertices(self) -> int:
        return int(self.skin_joints.shape[0])

    def forward(
        self,
        transl: torch.Tensor,
        global_orient: torch.Tensor,
        body_pose: torch.Tensor,
    ) -> BodyPose:
        """Pose the skeleton.

        Args:
            transl: (..., 3) pelvis position.
            global_orient: (..., 3) axis-angle or (..., 6) 6-D pelvis rotation.
            body_pose: (..., 21, 3) or (..., 21, 6) local joint rotations.

        Returns:
            BodyPose with joints (..., 22, 3) and rotations (..., 22, 3, 3).
        """
        batch = transl.shape[:-1]
        if transl.shape[-1:] != (3,):
            raise ValueError(f"transl must end in 3, got {tuple(transl.shape)}")
        if global_orient.shape[:-1] != batch or global_orient.shape[-1] not in (3, 6):
            raise ValueError(
                f"global_orient must be {(*batch, 3)} or {(*batch, 6)}, got {tuple(global_orient.shape)}"
            )
        if body_pose.shape[:-1] != (*batch, NUM_BODY_POSE_JOINTS) or body_pose.shape[-1] not in (3, 6):
            raise ValueError(
                f"body_pose must be {(*batch, NUM_BODY_POSE_JOINTS, 3)} or "
                f"{(*batch, NUM_BODY_POSE_JOINTS, 6)}, got {tuple(body_pose.shape)}"
            )
        root = rotation_matrix(global_orient).reshape(-1, 1, 3, 3)
        pose = body_pose.reshape(-1, NUM_BODY_POSE_JOINTS, body_pose.shape[-1])
        local = self._local_rotations_in_world_axes(pose.index_select(1, self.pose_order))
        rotations = [root]
        positions = [transl.reshape(-1, 1, 3)]
        for depth, (start, stop) in enumerate(self._level_bounds[1:], start=1):
            slots = getattr(self, f"parent_slots_{depth}")
            parent_rot = rotations[-1].index_select(1, slots)
            rotations.append(torch.einsum("bkij,bkjl->bkil", parent_rot, local[:, start - 1 : stop - 1]))
            offsets = self.level_offsets[start:stop]
            positions.append(positions[-1].index_select(1, slots) + torch.einsum("bkij,kj->bki", parent_rot, offsets))
        joint_rot = torch.cat(rotations, dim=1).index_select(1, self.joint_slot)
        joint_pos = torch.cat(positions, dim=1).index_select(1, self.joint_slot)
        return BodyPose(
            joints=joint_pos.reshape(*batch, NUM_JOINTS, 3),
            rotations=joint_rot.reshape(*batch, NUM_JOINTS, 3, 3),
        )

    def _local_rotations_in_world_axes(self, body_pose: torch.Tensor) -> torch.Tensor:
        """(B, 21, 3|6) SMPL-X local rotations -> (B, 21, 3, 3) conjugated into world axes."""
        axes = self.axes_to_world.to(body_pose.dtype)
        if body_pose.shape[-1] == 3:
            return rotation_matrix(body_pose @ axes.T)  # a rotated axis is the conjugated rotation
        return axes @ rotation_matrix(body_pose) @ axes.T

    def skin(self, pose: BodyPose, vertex_ids: torch.Tensor) -> torch.Tensor:
        """Linear-blend skinning of a vertex subset.

        Each vertex is sum_k w_k (R_k o_k + t_k); stacking every joint's
        [R | t] as a (3, 22 * 4) matrix turns the whole subset into one matmul
        with a (22 * 4, V) coefficient matrix of weights times [o_k; 1].

        Args:
            pose: output of `forward` with batch shape (...).
            vertex_ids: (V,) long vertex ids of the wooden mesh.

        Returns:
            (..., V, 3) world vertex positions.
        """
        dtype = pose.joints.dtype
        coefficients = self.skin_coefficients(vertex_ids).to(dtype)  # (22 * 4, V)
        transforms = torch.cat([pose.rotations, pose.joints[..., None]], dim=-1)  # (..., 22, 3, 4)
        stacked = transforms.transpose(-3, -2).reshape(*transforms.shape[:-3], 3, NUM_JOINTS * 4)
        return (stacked @ coefficients).transpose(-1, -2)

    def skin_coefficients(self, vertex_ids: torch.Tensor) -> torch.Tensor:
        """(22 * 4, V) matrix: entry (4 j + b, v) = sum over v's influences on joint j of w * [o; 1][b]."""
        joints = self.skin_joints[vertex_ids]  # (V, K)
        homogeneous = torch.cat([self.skin_offsets[vertex_ids], torch.ones_like(self.skin_weights[vertex_ids, :, None])], -1)
        weighted = homogeneous * self.skin_weights[vertex_ids, :, None]  # (V, K, 4)
        coefficients = torch.zeros(len(vertex_ids), NUM_JOINTS, 4, dtype=weighted.dtype, device=weighted.device)
        coefficients.index_put_((torch.arange(len(vertex_ids), device=joints.device)[:, None], joints), weighted, accumulate=True)
        return coefficients.reshape(len(vertex_ids), NUM_JOINTS * 4).T
