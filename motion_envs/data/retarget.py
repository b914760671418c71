"""Retargeting captured motion onto the body.

1. Scale: the source is scaled uniformly so its standing height equals the
   body's, measured along the bones (leg: hip -> knee -> ankle; trunk: pelvis
   -> ... -> head over the joints both skeletons have), so that it does not
   depend on the rest pose (ACCAD's rest pose bends the trunk 90° forward).
2. Rotation transfer with rest-pose correction: each mapped body joint takes
   the world rotation of its source joint relative to the source's rest, times
   a fixed rotation A_j that turns the body's rest bones onto the source's rest
   bones: towards its one mapped child (the smallest rotation), or, for a joint
   whose first mapped descendants are several (the pelvis: hips and spine; the
   chest: neck and collars), the rotation that best aligns all those bones
   (`roma.rigid_vectors_registration`). This absorbs different rest poses
   (Acclaim's legs spread 20°, ACCAD's bent trunk, a source facing +X) and
   gives twist and end-joint orientation.
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


def _first_mapped_descendants(joint: int, mapped: np.ndarray) -> list[int]:
    """Body joints below `joint` that are mapped and have no mapped joint between them and it."""
    found: list[int] = []
    for child in (c for c, p in enumerate(PARENTS) if p == joint):
        found += [child] if mapped[child] else _first_mapped_descendants(child, mapped)
    return found


def standing_height(points: np.ndarray, joint_ids: np.ndarray, mapped: np.ndarray) -> float:
    """Leg length (hip -> knee -> ankle, mean of both legs) plus the trunk's length (pelvis -> ... -> head over
    the mapped joints), along the bones of a skeleton whose body joint j sits at `points[joint_ids[j]]`."""

    def path(names: tuple[str, ...]) -> float:
        chain = points[[joint_ids[JOINT_NAMES.index(n)] for n in names if mapped[JOINT_NAMES.index(n)]]]
        return float(np.linalg.norm(np.diff(chain, axis=0), axis=-1).sum())

    legs = [path((f"{side}_hip", f"{side}_knee", f"{side}_ankle")) for side in ("left", "right")]
    return float(np.mean(legs)) + path(("pelvis", "spine1", "spine2", "spine3", "neck", "head"))


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

    scale = standing_height(body_rest, np.arange(22), mapped) / standing_height(rest, src, mapped)
    positions = positions * scale
    rest = (rest - rest[src[0]]) * scale

    aligned = np.empty((22, 3, 3))  # A_j: body rest bones onto the source rest bones
    for j, parent in enumerate(PARENTS):
        descendants = _first_mapped_descendants(j, mapped)
        aligned[j] = np.eye(3) if mapped[j] else aligned[parent]
        body_bones = body_rest[descendants] - body_rest[j]
        source_bones = rest[src[descendants]] - rest[src[j]]
        lengths = np.minimum(np.linalg.norm(body_bones, axis=-1), np.linalg.norm(source_bones, axis=-1))
        body_bones, source_bones = body_bones[lengths > 1e-6], source_bones[lengths > 1e-6]  # Max: collar at chest
        if mapped[j] and len(body_bones) == 1:
            aligned[j] = _align(body_bones[0], source_bones[0])
        elif mapped[j] and len(body_bones) > 1:
            unit = lambda v: torch.as_tensor(v / np.linalg.norm(v, axis=-1, keepdims=True))  # noqa: E731
            aligned[j] = roma.rigid_vectors_registration(unit(body_bones), unit(source_bones)).numpy()
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
