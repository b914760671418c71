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

How it is fast: joints are composed one depth level at a time (SMPL-X orders
joints by depth, so each level is a contiguous slice), in a planes layout:
rotations as (3, 3, joints, bodies), every 3 x 3 product written out as three
accumulated outer products over long contiguous runs (a (..., 3, 3) batch of
matmuls spends its time in per-matrix kernels and layout copies: for 8,192
bodies on one core `from_matrices` took 16 ms that way and takes 7.7 now). Every
joint position and every skinned vertex is then linear in the rotations'
columns plus the pelvis position (`BodyPose.frame_rows`), so each is one GEMM
with a fixed matrix: positions with the bone-offset chains, vertices with blend
weights times rest offsets folded through those chains.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch
from torch import nn

from motion_envs.body.frames import MANNEQUIN_TO_WORLD
from motion_envs.body.rotations import gram_schmidt_entries, planes_matmul, rodrigues_entries, rotation_matrix
from motion_envs.body.skeleton import NUM_BODY_POSE_JOINTS, NUM_JOINTS, PARENTS, rest_body

FRAME_ROWS = NUM_JOINTS * 3 + 1
"""Rows of `BodyPose.frame_rows`: (joint j, axis b) -> column b of joint j's rotation; last: the pelvis."""


class BodyPose(NamedTuple):
    """Posed skeleton.

    joints: (..., 22, 3) world joint positions.
    rotations: (..., 22, 3, 3) world joint rotations (identity at rest).
    frame_rows: (67, B * 3) the rotations and the pelvis position rearranged
        so that any point fixed to the skeleton is one matrix product away
        (B = batch size); used by `BodyModel.skin`.
    """

    joints: torch.Tensor
    rotations: torch.Tensor
    frame_rows: torch.Tensor


def _rotations_of_rows(rows: torch.Tensor, batch: torch.Size) -> torch.Tensor:
    """(..., 22, 3, 3) world rotations as a view of `BodyPose.frame_rows` (67, B * 3) (not contiguous)."""
    size = rows.shape[1] // 3
    return rows[:-1].view(NUM_JOINTS, 3, size, 3).permute(2, 0, 3, 1).reshape(*batch, NUM_JOINTS, 3, 3)  # [n, j, a, b]


def _depths(parents: tuple[int, ...]) -> list[int]:
    depth = [0] * len(parents)
    for joint in range(1, len(parents)):
        depth[joint] = depth[parents[joint]] + 1
    return depth


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
        self.register_buffer("axes_to_world", torch.as_tensor(MANNEQUIN_TO_WORLD, dtype=torch.float32))

        depth = _depths(PARENTS)
        if depth != sorted(depth):
            raise RuntimeError("body joints must be ordered by depth (SMPL-X's order is)")
        # joints of one depth are contiguous; their parents lie in the previous depth
        self._levels: list[tuple[int, int, slice | str]] = []
        for level in range(1, max(depth) + 1):
            start, stop = depth.index(level), len(depth) - depth[::-1].index(level)
            first = depth.index(level - 1)
            slots = [PARENTS[j] - first for j in range(start, stop)]
            if slots == list(range(slots[0], slots[-1] + 1)):
                self._levels.append((start, stop, slice(slots[0], slots[-1] + 1)))
            else:
                self.register_buffer(f"parent_slots_{level}", torch.tensor(slots), persistent=False)
                self._levels.append((start, stop, f"parent_slots_{level}"))

        # joint j = pelvis + sum over the bones i on its chain of R_parent(i) offset_i
        chains = torch.zeros(NUM_JOINTS, NUM_JOINTS, 3)  # [j, parent, b]
        for joint in range(1, NUM_JOINTS):
            bone = joint
            while bone > 0:
                chains[joint, PARENTS[bone]] += self.offsets[bone]
                bone = PARENTS[bone]
        chain_rows = torch.cat([chains.reshape(NUM_JOINTS, FRAME_ROWS - 1), torch.ones(NUM_JOINTS, 1)], dim=1)
        self.register_buffer("chain_rows", chain_rows, persistent=False)

        axes = np.asarray(MANNEQUIN_TO_WORLD)
        self._axis_permutation = [int(i) for i in np.abs(axes).argmax(axis=1)]
        self._axis_signs = [float(axes[i, j]) for i, j in enumerate(self._axis_permutation)]
        # (A R Aᵀ)[i, j] = s_i s_j R[p(i), p(j)] for the signed permutation A[i, p(i)] = s_i: picked and negated
        # entries instead of two broadcast matmuls (5.4 -> 1.5 ms for 172,032 rotations, 2 cores); back,
        # (Aᵀ L A)[i, j] = s_q(i) s_q(j) L[q(i), q(j)] with q = p⁻¹
        permutation, signs = self._axis_permutation, self._axis_signs
        inverse = [permutation.index(axis) for axis in range(3)]
        conjugate_entries = [3 * permutation[i] + permutation[j] for i in range(3) for j in range(3)]
        conjugate_signs = [[signs[i] * signs[j]] for i in range(3) for j in range(3)]  # (9, 1): per entry
        back_entries = [3 * inverse[i] + inverse[j] for i in range(3) for j in range(3)]
        back_signs = [signs[inverse[i]] * signs[inverse[j]] for i in range(3) for j in range(3)]
        for name, values in (("conjugate_entries", conjugate_entries), ("conjugate_signs", conjugate_signs)):
            self.register_buffer(name, torch.tensor(values), persistent=False)
        self._back_entries, self._back_signs = back_entries, back_signs

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
        size = int(np.prod(batch)) if batch else 1
        root = rotation_matrix(global_orient.reshape(size, global_orient.shape[-1]))
        local = self._local_planes(body_pose.reshape(size, NUM_BODY_POSE_JOINTS, body_pose.shape[-1]))
        return self._compose(transl, root, local, batch)

    def from_matrices(self, transl: torch.Tensor, orient: torch.Tensor, pose: torch.Tensor) -> BodyPose:
        """`forward` with rotation matrices: orient (..., 3, 3) pelvis rotations, pose (..., 21, 3, 3) SMPL-X local
        rotations (no 6-D round trip; what autoregressive priors integrate)."""
        batch = transl.shape[:-1]
        if orient.shape != (*batch, 3, 3) or pose.shape != (*batch, NUM_BODY_POSE_JOINTS, 3, 3):
            raise ValueError(f"need orient {(*batch, 3, 3)} and pose {(*batch, NUM_BODY_POSE_JOINTS, 3, 3)}, "
                             f"got {tuple(orient.shape)} and {tuple(pose.shape)}")  # fmt: skip
        size = int(np.prod(batch)) if batch else 1
        local = self._world_axes(pose.reshape(size, NUM_BODY_POSE_JOINTS, 9).permute(2, 1, 0))
        return self._compose(transl, orient.reshape(size, 3, 3), local, batch)

    def _compose(self, transl: torch.Tensor, root: torch.Tensor, local: torch.Tensor, batch: torch.Size) -> BodyPose:
        """Forward kinematics: root (B, 3, 3) world pelvis rotations, local (3, 3, 21, B) the other joints' local
        rotations in world axes (A R Aᵀ), planes layout ([a, b, joint, body] = R[a, b])."""
        size = root.shape[0]
        levels = [root.permute(1, 2, 0).unsqueeze(2)]  # (3, 3, 1, B)
        for start, stop, slots in self._levels:
            parents = levels[-1][:, :, slots] if isinstance(slots, slice) else levels[-1].index_select(2, getattr(self, slots))
            levels.append(planes_matmul(parents, local[:, :, start - 1 : stop - 1]))  # R_parent L
        world = torch.cat(levels, dim=2)  # (3, 3, 22, B)
        rows = world.new_empty(FRAME_ROWS, size, 3)
        rows[:-1].view(NUM_JOINTS, 3, size, 3).copy_(world.permute(2, 1, 3, 0))  # [j, b, n, a] = R_j[a, b]
        rows[-1].copy_(transl.reshape(size, 3))
        rows = rows.view(FRAME_ROWS, size * 3)
        return BodyPose(joints=self._joints_of_rows(rows, batch), rotations=_rotations_of_rows(rows, batch), frame_rows=rows)

    def with_world_rotations(self, pose: BodyPose, transl: torch.Tensor, joint_ids: torch.Tensor,
                             rotations: torch.Tensor) -> BodyPose:  # fmt: skip
        """`pose` with the world rotations of the joints `joint_ids` (J,) replaced by `rotations` (3, 3, ..., J), in
        the planes layout (components first, `leg_fit`'s), and the pelvis moved to `transl` (..., 3); the other
        joints keep their world rotations (no forward kinematics: for rotations solved in world axes, as
        `leg_fit.fit_legs`'s, whose joints have no other children) and every joint position is recomputed.

        Written into a copy of `pose.frame_rows`, whose rows hold the rotations component by component, so the
        planes go in with one strided copy; the returned rotations are a view of those rows (not contiguous)."""
        if rotations.shape != (3, 3, *pose.joints.shape[:-2], len(joint_ids)):
            raise ValueError(f"need rotations {(3, 3, *pose.joints.shape[:-2], len(joint_ids))}, "
                             f"got {tuple(rotations.shape)}")  # fmt: skip
        rows = pose.frame_rows.clone()
        size = rows.shape[1] // 3
        by_joint = rows[:-1].view(NUM_JOINTS, 3, size, 3)  # [j, b, n, a] = R_j[a, b]
        by_joint[joint_ids] = rotations.reshape(3, 3, size, len(joint_ids)).permute(3, 1, 2, 0)
        rows[-1] = transl.reshape(size * 3)
        batch = pose.joints.shape[:-2]
        return BodyPose(joints=self._joints_of_rows(rows, batch), rotations=_rotations_of_rows(rows, batch), frame_rows=rows)

    def _joints_of_rows(self, rows: torch.Tensor, batch: torch.Size) -> torch.Tensor:
        """(..., 22, 3) joint positions from `BodyPose.frame_rows` (67, B * 3): one matmul."""
        size = rows.shape[1] // 3
        joints = (self.chain_rows.to(rows.dtype) @ rows).reshape(NUM_JOINTS, size, 3).transpose(0, 1)
        return joints.reshape(*batch, NUM_JOINTS, 3)

    def _local_planes(self, body_pose: torch.Tensor) -> torch.Tensor:
        """(B, 21, 3|6) SMPL-X local rotations -> (3, 3, 21, B) in world axes, A R Aᵀ (A = `axes_to_world`), planes
        layout. The components are made contiguous planes (joint-major) first. Axis-angle: conjugating by the
        axes map rotates the rotation axis, a signed permutation of its components; 6-D: `_world_axes`."""
        planes = body_pose.permute(2, 1, 0).contiguous()  # (3 | 6, 21, B)
        if body_pose.shape[-1] == 3:
            x, y, z = (sign * planes[axis] for axis, sign in zip(self._axis_permutation, self._axis_signs))
            return torch.stack(rodrigues_entries(x, y, z)).view(3, 3, *planes.shape[1:])
        return self._world_axes(torch.stack(gram_schmidt_entries(*planes)))

    def _world_axes(self, entries: torch.Tensor) -> torch.Tensor:
        """(9, 21, B) SMPL-X local rotations' entries, row-major -> (3, 3, 21, B) A R Aᵀ in world axes: the entries
        picked and negated (`__init__`)."""
        picked = entries.index_select(0, self.conjugate_entries)
        return (picked * self.conjugate_signs.to(picked.dtype)[..., None]).view(3, 3, *entries.shape[1:])

    def smplx_local(self, local_world: torch.Tensor) -> torch.Tensor:
        """(3, 3, ...) local rotations in world axes (parentᵀ @ child of world rotations) in the planes layout
        (components first, `leg_fit`'s) -> (..., 3, 3) in SMPL-X's own joint axes, Aᵀ L A (`body_pose`'s
        convention): the signed permutation of `_local_planes` the other way, as picked planes stacked
        once into the matrices' layout."""
        entries = [local_world[entry // 3, entry % 3] for entry in self._back_entries]
        signed = [plane if sign > 0 else -plane for plane, sign in zip(entries, self._back_signs)]
        return torch.stack(signed, dim=-1).unflatten(-1, (3, 3))

    def skin(self, pose: BodyPose, vertex_ids: torch.Tensor) -> torch.Tensor:
        """Linear-blend skinning of a vertex subset of a pose from `forward`.

        A vertex is sum_k w_k (R_k o_k + t_k); with the joint positions t
        themselves linear in the rotation rows and the pelvis position, it is
        one (V, 67) matrix times `pose.frame_rows`.

        Args:
            pose: output of `forward` with batch shape (...).
            vertex_ids: (V,) long vertex ids of the wooden mesh.

        Returns:
            (..., V, 3) world vertex positions.
        """
        return self.skin_with_rows(pose, self.skin_rows(vertex_ids))

    def skin_with_rows(self, pose: BodyPose, reading: torch.Tensor) -> torch.Tensor:
        """`skin` with the (V, 67) matrix of `skin_rows` computed once by the caller -> (..., V, 3)."""
        rows = pose.frame_rows
        size = rows.shape[1] // 3
        vertices = (reading.to(rows.dtype) @ rows).reshape(len(reading), size, 3).transpose(0, 1)
        return vertices.reshape(*pose.joints.shape[:-2], len(reading), 3)

    def heights_with_rows(self, pose: BodyPose, reading: torch.Tensor) -> torch.Tensor:
        """The heights (z) of `skin_with_rows`' vertices -> (..., V): a third of its matmul and output."""
        rows = pose.frame_rows
        heights = reading.to(rows.dtype) @ rows.unflatten(1, (-1, 3))[..., 2]  # (V, size)
        return heights.transpose(0, 1).reshape(*pose.joints.shape[:-2], len(reading))

    def skin_rows(self, vertex_ids: torch.Tensor) -> torch.Tensor:
        """(V, 67) matrix taking `BodyPose.frame_rows` to vertex positions."""
        joints = self.skin_joints[vertex_ids]  # (V, K)
        weights = self.skin_weights[vertex_ids]  # (V, K)
        count = len(vertex_ids)
        vertex = torch.arange(count, device=joints.device)[:, None]
        rotated = torch.zeros(count, NUM_JOINTS, 3, dtype=weights.dtype, device=weights.device)
        rotated.index_put_((vertex, joints), self.skin_offsets[vertex_ids] * weights[..., None], accumulate=True)
        translated = torch.zeros(count, NUM_JOINTS, dtype=weights.dtype, device=weights.device)
        translated.index_put_((vertex, joints), weights, accumulate=True)
        rows = torch.cat([rotated.reshape(count, FRAME_ROWS - 1), torch.zeros_like(translated[:, :1])], dim=1)
        return rows + translated @ self.chain_rows
