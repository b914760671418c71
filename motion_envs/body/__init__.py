"""The embedded body: mannequin-x's SMPL-X skeleton and skin, batched in torch, Z up."""

from motion_envs.body.kinematics import BodyModel, BodyPose
from motion_envs.body.skeleton import JOINT_NAMES, MIRROR_JOINTS, NUM_JOINTS, PARENTS, joint_index

__all__ = ["JOINT_NAMES", "MIRROR_JOINTS", "NUM_JOINTS", "PARENTS", "BodyModel", "BodyPose", "joint_index"]
