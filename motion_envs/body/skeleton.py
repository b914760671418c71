"""The 22-joint body skeleton taken from mannequin-x, expressed in the Z-up world.

Joint order and parents are SMPL-X's body joints (pelvis + 21). Hands are
fixed in mannequin-x's relaxed neutral pose, so every hand and finger joint
moves rigidly with its wrist: `rest_body()` folds them into the wrist for
skinning, and forward kinematics only ever sees 22 joints.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from motion_envs.body.frames import MANNEQUIN_TO_WORLD

JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
    "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
    "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist",
)  # fmt: skip
"""SMPL-X body joint names; `left_foot`/`right_foot` are the toe-base joints."""

PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)
NUM_JOINTS = len(JOINT_NAMES)
NUM_BODY_POSE_JOINTS = NUM_JOINTS - 1

MIRROR_JOINTS: tuple[int, ...] = tuple(
    JOINT_NAMES.index(
        name.replace("left_", "@").replace("right_", "left_").replace("@", "right_")
    )
    for name in JOINT_NAMES
)
"""Index of each joint's left/right counterpart (itself for the spine)."""


def joint_index(name: str) -> int:
    """Index of a joint by its SMPL-X name; raises a ValueError listing the names."""
    if name not in JOINT_NAMES:
        raise ValueError(f"unknown joint {name!r}; joints are {', '.join(JOINT_NAMES)}")
    return JOINT_NAMES.index(name)


@dataclass(frozen=True)
class RestBody:
    """Rest skeleton and skin of one mannequin-x body shape, in world axes (Z up).

    Attributes:
        offsets: (22, 3) joint offset from its parent at rest; row 0 is the
            pelvis position relative to mannequin-x's origin (unused by our FK,
            whose `transl` is the pelvis position).
        rest_joints: (22, 3) rest joint positions with the pelvis at the origin.
        vertices: (V, 3) rest skin vertices, pelvis at the origin.
        skin_joints: (V, 4) body joint index of each skin influence (hand and
            finger influences folded into the wrist).
        skin_offsets: (V, 4, 3) the vertex in each influence joint's rest frame
            (world axes), i.e. what the joint's rotation acts on.
        skin_weights: (V, 4) blend weights, rows summing to 1.
        faces: (F, 3) triangle vertex ids of the wooden mesh.
    """

    offsets: np.ndarray
    rest_joints: np.ndarray
    vertices: np.ndarray
    skin_joints: np.ndarray
    skin_offsets: np.ndarray
    skin_weights: np.ndarray
    faces: np.ndarray


@lru_cache(maxsize=4)
def rest_body(shape: tuple[float, ...] = (0.0,) * 10) -> RestBody:
    """Rest body of the mannequin-x wooden mannequin for SMPL-X `shape` (10 betas)."""
    import mannequin  # imported lazily: it loads mesh assets

    model = mannequin.Mannequin("wooden", shape=np.asarray(shape, dtype=np.float32))
    to_world = MANNEQUIN_TO_WORLD
    names = model.joint_names
    parents = model.parents
    identity = model._identity  # mannequin-x keeps its shaped skin here (0.3.x)
    local_offsets = np.asarray(identity["local_joint_offsets"], dtype=np.float64)
    if list(parents[:NUM_JOINTS]) != list(PARENTS):
        raise RuntimeError("mannequin-x joint hierarchy changed; motion_envs needs mannequin-x 0.3.x")

    rest_pose = model.rest_pose()
    transforms = model.joint_transforms(rest_pose).astype(np.float64)  # (54, 4, 4), mannequin frame
    pelvis = transforms[0, :3, 3]
    wrist_of = {}
    for joint in range(NUM_JOINTS, len(names)):
        ancestor = joint
        while ancestor >= NUM_JOINTS:
            ancestor = parents[ancestor]
        wrist_of[joint] = ancestor

    skin_joints = model._skin_joint_indices.copy()
    skin_weights = model._skin_weights.astype(np.float64)
    bind = identity["skin_bind_positions"].astype(np.float64)
    skin_vertices = identity["skin_vertices"].astype(np.float64)
    # vertex in each influence joint's frame (rest rotations are identity except
    # in the posed hand, whose fixed transform we fold into the wrist)
    relative = skin_vertices[:, None, :] - bind[skin_joints]
    rotation = transforms[skin_joints, :3, :3]
    translation = transforms[skin_joints, :3, 3]
    posed = np.einsum("vkij,vkj->vki", rotation, relative) + translation
    folded = np.vectorize(lambda j: wrist_of.get(j, j))(skin_joints)
    skin_offsets = posed - transforms[folded, :3, 3]  # body joints have identity rest rotation
    vertices = np.sum(posed * skin_weights[..., None], axis=1) - pelvis

    rest_joints = transforms[:NUM_JOINTS, :3, 3] - pelvis
    return RestBody(
        offsets=local_offsets[:NUM_JOINTS] @ to_world.T,
        rest_joints=rest_joints @ to_world.T,
        vertices=vertices @ to_world.T,
        skin_joints=folded,
        skin_offsets=skin_offsets @ to_world.T,
        skin_weights=skin_weights,
        faces=np.asarray(model.faces),
    )
