"""Retargeting captured motion onto the body.

1. Scale: the source is scaled uniformly so its rest height (head joint above
   the ankles) equals the body's.
2. Rotation transfer with rest-pose correction: each mapped body joint takes
   the world rotation of its source joint relative to the source's rest, times
   a fixed rotation A_j that turns the body's rest bone (joint -> its mapped
   child) onto the source's rest bone. This absorbs different rest poses
   (e.g. Acclaim's legs spread 20°) and gives twist and end-joint orientation.
3. Position refinement: Adam on 6-D rotations and the pelvis position, batched
   over all frames, pulls the body's joints onto the scaled source joints,
   with a pull towards step 2's rotations that keeps what positions cannot
   see (twist, head and hand orientation). The two skeletons place their
   joints differently (hips, collars, spine) and have different proportions,
   so each target is the scaled source joint plus a constant placement
   offset, measured with both skeletons in the source's rest pose and riding
   with the body parent's transferred rotation.

The reported error is the per-joint distance between the body's joints and
these targets, averaged over the mapped joints; the raw distance to the
scaled source joints is reported beside it.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import roma
import torch

from motion_envs.body import BodyModel
from motion_envs.body.frames import Y_UP_TO_Z_UP
from motion_envs.body.rotations import matrix_to_sixd, rotation_matrix
from motion_envs.body.skeleton import JOINT_NAMES, PARENTS
from motion_envs.data.motion import BodyMotion, SourceMotion
from motion_envs.data.skeleton_maps import SkeletonMap


@dataclass(frozen=True)
class RetargetConfig:
    """iterations/learning_rate: the position refinement. rotation_prior: weight of
    the pull towards transferred rotations (m² per unit 6-D distance)."""

    iterations: int = 150
    learning_rate: float = 0.01
    rotation_prior: float = 1e-4


@dataclass(frozen=True)
class RetargetResult:
    motion: BodyMotion
    joint_error: np.ndarray  # (T, 22) metres; NaN for unmapped joints
    source_positions: np.ndarray  # (T, J, 3) scaled source joints in the body's world (for plots)


def _align(source_dir: np.ndarray, target_dir: np.ndarray) -> np.ndarray:
    """(3, 3) smallest rotation taking unit direction `source_dir` onto `target_dir`."""
    a = source_dir / np.linalg.norm(source_dir)
    b = target_dir / np.linalg.norm(target_dir)
    axis = np.cross(a, b)
    angle = np.arctan2(np.linalg.norm(axis), a @ b)
    if np.linalg.norm(axis) < 1e-9:
        return np.eye(3)
    return roma.rotvec_to_rotmat(torch.as_tensor(axis / np.linalg.norm(axis) * angle)).numpy()


def retarget(
    source: SourceMotion,
    mapping: SkeletonMap,
    body: BodyModel,
    name: str,
    subject: str,
    config: RetargetConfig = RetargetConfig(),
) -> RetargetResult:
    """Retarget `source` onto `body` (see the module docstring)."""
    to_z = Y_UP_TO_Z_UP
    names = source.skeleton.names
    src = np.array([names.index(mapping.joints[j]) if mapping.joints[j] else -1 for j in JOINT_NAMES])
    mapped = src >= 0
    positions, rotations = source.global_transforms()
    positions = positions @ to_z.T
    rotations = to_z @ rotations @ to_z.T
    rest = source.skeleton.rest_positions() @ to_z.T
    body_rest = body.rest_joints.double().numpy()

    ankles = [JOINT_NAMES.index("left_ankle"), JOINT_NAMES.index("right_ankle")]

    def height(points: np.ndarray, joint_ids: np.ndarray) -> float:
        """Rest height: head joint above the mean ankle."""
        return float(points[joint_ids[JOINT_NAMES.index("head")], 2] - points[joint_ids[ankles], 2].mean())

    scale = height(body_rest, np.arange(22)) / height(rest, src)
    positions = positions * scale
    rest = (rest - rest[src[0]]) * scale

    aligned = np.empty((22, 3, 3))  # A_j: body rest bone onto the source rest bone
    for j, parent in enumerate(PARENTS):
        children = [c for c, p in enumerate(PARENTS) if p == j and mapped[c]]
        aligned[j] = np.eye(3) if mapped[j] else aligned[parent]
        if mapped[j] and len(children) == 1:
            c = children[0]
            aligned[j] = _align(body_rest[c] - body_rest[j], rest[src[c]] - rest[src[j]])
    transferred = rotations[:, np.where(mapped, src, 0)] @ aligned  # (T, 22, 3, 3)
    for j, parent in enumerate(PARENTS):  # unmapped joints keep their parent's rotation
        if not mapped[j]:
            transferred[:, j] = transferred[:, parent]

    # the body posed in the source's rest pose, and where each body joint sits
    # relative to its source joint there, in the body parent's frame
    reference = np.zeros((22, 3))
    for j, parent in enumerate(PARENTS[1:], start=1):
        reference[j] = reference[parent] + aligned[parent] @ (body_rest[j] - body_rest[parent])
    placement = reference - rest[np.where(mapped, src, 0)]
    frame = [0] + list(PARENTS[1:])
    placement = np.einsum("jba,jb->ja", aligned[frame], placement)
    targets = positions[:, np.where(mapped, src, 0)] + np.einsum(
        "tjab,jb->tja", transferred[:, frame], placement
    )
    parent_rot = transferred[:, [max(p, 0) for p in PARENTS[1:]]]
    local = np.swapaxes(parent_rot, -1, -2) @ transferred[:, 1:]
    axes = torch.as_tensor(body.axes_to_world, dtype=torch.float64)
    local_smplx = axes.T @ torch.as_tensor(local) @ axes  # world axes -> SMPL-X axes

    weights = torch.as_tensor(mapped, dtype=torch.float64)
    target = torch.as_tensor(targets)
    init_orient = matrix_to_sixd(torch.as_tensor(transferred[:, 0]))
    init_pose = matrix_to_sixd(local_smplx)
    orient = init_orient.clone().requires_grad_(True)
    pose = init_pose.clone().requires_grad_(True)
    transl = target[:, 0].clone().requires_grad_(True)
    model = copy.deepcopy(body).double()  # refine in float64; the caller's body stays as it is
    optimiser = torch.optim.Adam([orient, pose, transl], lr=config.learning_rate)
    for _ in range(config.iterations):
        optimiser.zero_grad()
        joints = model(transl, orient, pose).joints
        fit = (((joints - target) ** 2).sum(-1) * weights).sum(-1).mean()
        prior = ((orient - init_orient) ** 2).sum(-1).mean() + ((pose - init_pose) ** 2).sum((-1, -2)).mean()
        (fit + config.rotation_prior * prior).backward()
        optimiser.step()
    with torch.no_grad():
        joints = model(transl, orient, pose).joints
        error = (joints - target).norm(dim=-1).numpy()
        global_orient = roma.rotmat_to_rotvec(rotation_matrix(orient)).numpy()
        body_pose = roma.rotmat_to_rotvec(rotation_matrix(pose)).numpy()
    error[:, ~mapped] = np.nan
    motion = BodyMotion(
        name=name,
        subject=subject,
        fps=source.fps,
        transl=transl.detach().numpy(),
        global_orient=global_orient,
        body_pose=body_pose,
        info={"skeleton": mapping.name, "scale": scale},
    )
    return RetargetResult(motion, error, positions)
