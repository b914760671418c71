"""Grounding and canonicalisation of body motion (the papers' canonical frames)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import roma
import torch

from motion_envs.body import BodyModel, joint_index
from motion_envs.body.markers import foot_vertex_ids
from motion_envs.data.motion import BodyMotion


def body_tensors(motion: BodyMotion) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(T, 3), (T, 3), (T, 21, 3) float32 tensors of a body motion."""
    return (
        torch.as_tensor(motion.transl, dtype=torch.float32),
        torch.as_tensor(motion.global_orient, dtype=torch.float32),
        torch.as_tensor(motion.body_pose, dtype=torch.float32),
    )


def lowest_foot_points(motion: BodyMotion, body: BodyModel) -> np.ndarray:
    """(T, 3) the lowest foot vertex of each frame."""
    with torch.no_grad():
        feet = body.skin(body(*body_tensors(motion)), foot_vertex_ids())
    lowest = feet[..., 2].argmin(dim=-1)
    return feet[torch.arange(len(feet)), lowest].numpy()


def facing_angle(joints: np.ndarray) -> np.ndarray:
    """(...,) heading angle about +z of the body forward z × (right hip − left hip), from +y."""
    across = joints[..., joint_index("right_hip"), :] - joints[..., joint_index("left_hip"), :]
    forward = np.stack([-across[..., 1], across[..., 0]], axis=-1)  # z × across, in xy
    return np.arctan2(-forward[..., 0], forward[..., 1])


def canonicalise(motion: BodyMotion, body: BodyModel, ground_first_frame: bool = True) -> BodyMotion:
    """First-frame pelvis at the xy origin, facing +y (GAMMA's canonical frame: x = right hip − left hip, z up),
    and with `ground_first_frame` the first frame's lowest foot point on z = 0 (for motion whose floor is
    unknown; cleaned motion already has its floor at z = 0 and keeps its height)."""
    with torch.no_grad():
        first = body(*(t[:1] for t in body_tensors(motion))).joints[0].numpy()
    angle = facing_angle(first)
    turn = roma.rotvec_to_rotmat(torch.tensor([0.0, 0.0, -angle], dtype=torch.float64)).numpy()
    origin = np.array([first[0, 0], first[0, 1], 0.0])
    transl = (motion.transl - origin) @ turn.T
    orient = roma.rotmat_to_rotvec(
        torch.as_tensor(turn) @ roma.rotvec_to_rotmat(torch.as_tensor(motion.global_orient, dtype=torch.float64))
    ).numpy()
    turned = replace(motion, transl=transl, global_orient=orient)
    if not ground_first_frame:
        return turned
    first_frame = replace(turned, transl=transl[:1], global_orient=orient[:1], body_pose=motion.body_pose[:1])
    ground = lowest_foot_points(first_frame, body)[0, 2]
    return replace(turned, transl=transl - np.array([0.0, 0.0, ground]))
