"""Third-person `rgb_array` frames of an environment's bodies, shared by every single and vector env.

A core says what to draw (`RenderInputs`: the bodies' parameters, pelvis
and goal); `EnvView` poses the first `max_bodies` bodies, follows their mean
pelvis with the camera, and draws each body's goal and pelvis trail.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from motion_envs.body import BodyModel
from motion_envs.render.camera import follow_camera
from motion_envs.render.third_person import ThirdPersonRenderer
from motion_envs.scenes.scene import Scene


ROOM_CAMERA = {"distance": 4.0, "height_above": 4.2}
"""In a room the camera looks down at about 45 degrees, so that the ground near the (cut) walls stays in view."""


class RenderInputs(NamedTuple):
    """What to draw of N bodies. transl: (N, 3); global_orient: (N, 3) axis-angle or (N, 6);
    body_pose: (N, 21, 3) or (N, 21, 6); pelvis: (N, 3); goal: (N, 3)."""

    transl: torch.Tensor
    global_orient: torch.Tensor
    body_pose: torch.Tensor
    pelvis: torch.Tensor
    goal: torch.Tensor


class EnvView:
    """Frames of up to `max_bodies` bodies with their goals (`goal_shape` "ring" or "sphere" of `goal_radius`)."""

    def __init__(self, body: BodyModel, goal_shape: str, goal_radius: float, max_bodies: int = 8, width: int = 480,
                 height: int = 360, scene: Scene | None = None) -> None:  # fmt: skip
        if max_bodies < 1:
            raise ValueError(f"max_bodies must be >= 1, got {max_bodies}")
        self.renderer = ThirdPersonRenderer(body, width, height, scene=scene)
        self.goal_shape, self.goal_radius, self.max_bodies = goal_shape, goal_radius, max_bodies

    def frame(self, inputs: RenderInputs, trails: list[np.ndarray] | None = None, paths: list[np.ndarray] | None = None) -> np.ndarray:
        """(H, W, 3) uint8 of the first `max_bodies` bodies; trails: one (T, 3) pelvis path per drawn body; paths:
        one (W, 3) planned route per body (drawn as waypoint dots joined by a line)."""
        count = min(self.max_bodies, len(inputs.transl))
        cpu = RenderInputs(*(tensor[:count].detach().cpu() for tensor in inputs))
        vertices = self.renderer.vertices(cpu.transl, cpu.global_orient, cpu.body_pose)
        camera = follow_camera(cpu.pelvis.mean(dim=0).numpy().astype(np.float64), self.renderer.width, self.renderer.height,
                               **(ROOM_CAMERA if self.renderer.scene is not None else {}))  # fmt: skip
        return self.renderer.render(vertices, camera, goal=cpu.goal.numpy(), goal_radius=self.goal_radius,
                                    trail=None if trails is None else trails[:count], goal_shape=self.goal_shape,
                                    routes=None if paths is None else paths[:count])  # fmt: skip
