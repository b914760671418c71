"""Spheres that cover a posed body, for batched collision against a scene's signed distance.

Each bone (joint to parent) carries three spheres (at its two ends and its
middle) of the bone's radius: a capsule chain sampled at 3 points, enough at
a 5 cm voxel grid. Radii are typical adult limb and torso half-thicknesses.
"""

from __future__ import annotations

from functools import lru_cache

import torch

from motion_envs.body.kinematics import BodyPose
from motion_envs.body.skeleton import JOINT_NAMES, PARENTS

BONE_RADIUS = {
    "spine": 0.11, "pelvis": 0.11, "hip": 0.09, "neck": 0.06, "collar": 0.06, "head": 0.09,
    "knee": 0.06, "ankle": 0.045, "foot": 0.04, "shoulder": 0.05, "elbow": 0.045, "wrist": 0.04,
}  # fmt: skip
"""Radius (m) of the bone ending at a joint whose name contains the key."""


@lru_cache(maxsize=1)
def _bones() -> tuple[list[int], list[int], list[float]]:
    children = [j for j, parent in enumerate(PARENTS) if parent >= 0]
    radii = [next(r for key, r in BONE_RADIUS.items() if key in JOINT_NAMES[j]) for j in children]
    return children, [PARENTS[j] for j in children], radii


def collision_spheres(pose: BodyPose) -> tuple[torch.Tensor, torch.Tensor]:
    """Centres (..., 63, 3) and radii (63,) of 3 spheres on each of the 21 bones of the posed bodies."""
    return spheres_of_joints(pose.joints)


def spheres_of_joints(joints: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Centres (..., 63, 3) and radii (63,) of the collision spheres of bodies with joints (..., 22, 3)."""
    children, parents, radii = _bones()
    child, parent = joints[..., children, :], joints[..., parents, :]
    centres = torch.cat([child, 0.5 * (child + parent), parent], dim=-2)
    radius = torch.tensor(radii, dtype=joints.dtype, device=joints.device).repeat(3)
    return centres, radius
