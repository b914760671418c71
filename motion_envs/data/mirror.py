"""Left/right mirroring of body motion (augmentation).

Reflecting through the body's sagittal plane x = 0 maps a rotation R to
S R S with S = diag(-1, 1, 1); for axis-angle that is (a_x, -a_y, -a_z).
Our world and SMPL-X's joint axes share the lateral x axis, so the same rule
applies to global_orient and body_pose, and left/right joints swap.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from motion_envs.body.skeleton import MIRROR_JOINTS
from motion_envs.data.motion import BodyMotion

_FLIP = np.array([1.0, -1.0, -1.0])


def mirror(motion: BodyMotion) -> BodyMotion:
    """The mirrored motion (mirroring twice gives the original back exactly); sole contacts (`info["contacts"]`,
    `SOLE_POINTS` order: left heel, left toe, right heel, right toe) swap sides too."""
    pose = motion.body_pose[:, [j - 1 for j in MIRROR_JOINTS[1:]]] * _FLIP
    info = dict(motion.info)
    if "contacts" in info:
        info["contacts"] = info["contacts"][:, [2, 3, 0, 1]]
    return replace(
        motion,
        info=info,
        name=f"{motion.name}_mirrored",
        transl=motion.transl * np.array([-1.0, 1.0, 1.0]),
        global_orient=motion.global_orient * _FLIP,
        body_pose=pose,
    )
