"""The head camera: eye position and gaze of a posed body, for egocentric views."""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np
import torch

from motion_envs.body.kinematics import BodyPose
from motion_envs.body.skeleton import JOINT_NAMES, rest_body

HEAD = JOINT_NAMES.index("head")
EYE_HEIGHT_ABOVE_HEAD_JOINT = 0.07
"""Eyes sit about 7 cm above SMPL-X's head joint (the skull base)."""


class CameraFrame(NamedTuple):
    """eye: (..., 3) position. rotation: (..., 3, 3), columns = right, gaze, up (world)."""

    eye: torch.Tensor
    rotation: torch.Tensor

    @property
    def gaze(self) -> torch.Tensor:
        """(..., 3) unit viewing direction."""
        return self.rotation[..., :, 1]


@lru_cache(maxsize=1)
def eye_offset() -> tuple[float, float, float]:
    """Eye point in the head joint's rest frame: on the face's midline, 1 cm inside the surface."""
    rest = rest_body()
    head = rest.rest_joints[HEAD]
    relative = rest.vertices - head
    face = (np.abs(relative[:, 0]) < 0.03) & (np.abs(relative[:, 2] - EYE_HEIGHT_ABOVE_HEAD_JOINT) < 0.02)
    front = float(relative[face, 1].max()) - 0.01
    return (0.0, front, EYE_HEIGHT_ABOVE_HEAD_JOINT)


def head_camera(pose: BodyPose) -> CameraFrame:
    """Camera frame of each posed body: eye on the face, gaze along the head's forward (+y)."""
    return camera_from_head(pose.joints[..., HEAD, :], pose.rotations[..., HEAD, :, :])


def camera_from_head(position: torch.Tensor, rotation: torch.Tensor) -> CameraFrame:
    """Camera frame from head joint positions (..., 3) and world rotations (..., 3, 3)."""
    offset = torch.tensor(eye_offset(), dtype=rotation.dtype, device=rotation.device)
    return CameraFrame(eye=position + rotation @ offset, rotation=rotation)
