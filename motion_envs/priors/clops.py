"""CLOPS's head-target motion prior (Diomataris et al., "Moving by Looking") and its discrete actions.

The prior (Sec. 3.1) is WANDR's per-frame delta c-VAE (`WandrPrior`, same
representation and state features, `wandr_features`) whose 9 intention
features are replaced by a target head pose N frames ahead:

* translation (3): R_zᵀ (h* − h), the target head position minus the current one in the pelvis heading frame;
* orientation (6): 6-D of H_headᵀ H*, the target head rotation relative to the current head rotation.

No time is given: at inference the prior generates frames until the head
reaches the target (`ClopsStepper.reached`: within `reach_distance` and
`reach_angle`) or the environment's `max_chunk_frames` frames have passed.

Actions (Sec. 3.2): head-pose deltas over N frames measured in the data,
clustered with k-means into K rows of (dx, dy, dz, dyaw): the head's
displacement in its own yaw frame (x right, y forward, z up, metres) and its
yaw change (radians, left positive). Action k turns into a target head pose:
position h + R_z(ψ) (dx, dy, dz), rotation R_z(dyaw) H (the current head
rotation turned about +z). The paper's N and K were lost from its text; we
use N = 30 frames (1 s at 30 fps: the policy acts at 1 Hz, REFERENCE_NOTES
§5) and K = 16 (`ClopsConfig`). The k-means centres live in the checkpoint
(`ClopsPrior.actions`) so a prior carries its own action set.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch

from motion_envs.body import BodyModel
from motion_envs.body.frames import MANNEQUIN_TO_WORLD
from motion_envs.body.rotations import about_z, matrix_to_sixd, wrap_angle
from motion_envs.priors.wandr import WandrPrior, WandrStepper
from motion_envs.priors.wandr_features import WandrState, condition, heading

HEAD_CHAIN = (2, 5, 8, 11, 14)
"""`body_pose` rows of spine1, spine2, spine3, neck and head: the head's rotation is orient @ these in order."""
HEAD_JOINT = 15


@dataclass(frozen=True)
class ClopsConfig:
    latent: int = 64
    layers: int = 8
    max_width: int = 512
    dropout: float = 0.03
    horizon: int = 30
    """N: frames between a head pose and its target in training and in the action clusters (1 s)."""
    actions: int = 16
    """K: k-means clusters of head-pose deltas (the discrete action set)."""

    def __post_init__(self) -> None:
        if self.layers < 2 or self.horizon < 1 or self.actions < 1:
            raise ValueError(f"need layers >= 2, horizon >= 1, actions >= 1; got {self.layers}, {self.horizon}, {self.actions}")


class ClopsPrior(WandrPrior):
    """WANDR's c-VAE with head-target features in the intention slot, plus the K action deltas (K, 4)."""

    def __init__(self, config: ClopsConfig = ClopsConfig()) -> None:
        super().__init__(config)  # type: ignore[arg-type]  # same network fields as WandrConfig
        self.register_buffer("actions", torch.zeros(config.actions, 4))

    def set_actions(self, deltas: np.ndarray | torch.Tensor) -> None:
        """deltas: (K, 4) rows of (dx, dy, dz, dyaw), see the module doc."""
        deltas = torch.as_tensor(deltas, dtype=torch.float32)
        if deltas.shape != self.actions.shape:
            raise ValueError(f"need {tuple(self.actions.shape)} action deltas, got {tuple(deltas.shape)}")
        self.actions.copy_(deltas)


class HeadPose(NamedTuple):
    """position: (B, 3) head joint positions; rotation: (B, 3, 3) head joint world rotations."""

    position: torch.Tensor
    rotation: torch.Tensor


def head_rotation(orient: torch.Tensor, pose: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) world rotation of the head joint (as `BodyModel`'s) from pelvis rotations (..., 3, 3) and
    SMPL-X local poses (..., 21, 3, 3), whose axes `MANNEQUIN_TO_WORLD` (symmetric) maps to the world's."""
    chain = pose[..., HEAD_CHAIN[0], :, :]
    for row in HEAD_CHAIN[1:]:
        chain = chain @ pose[..., row, :, :]
    axes = torch.as_tensor(MANNEQUIN_TO_WORLD, dtype=orient.dtype, device=orient.device)
    return orient @ axes @ chain @ axes


def head_pose(state: WandrState) -> HeadPose:
    return HeadPose(state.joints[:, HEAD_JOINT], head_rotation(state.orient, state.pose))


def head_target_features(state: WandrState, target: HeadPose) -> torch.Tensor:
    """(B, 9): the target head pose relative to the bodies' current heads (see the module doc)."""
    head = head_pose(state)
    offset = ((target.position - head.position)[:, None] @ heading(state.orient)).squeeze(1)
    return torch.cat([offset, matrix_to_sixd(head.rotation.transpose(-1, -2) @ target.rotation)], dim=1)


def head_yaw(rotation: torch.Tensor) -> torch.Tensor:
    """(...,) yaw (radians, from +y, counter-clockwise) of the forward (+y) axis of rotations (..., 3, 3)."""
    return torch.atan2(-rotation[..., 0, 1], rotation[..., 1, 1])


def yaw_change(start: torch.Tensor, end: torch.Tensor) -> torch.Tensor:
    """(...,) yaw (radians, left positive, in (-π, π]) from rotations `start` to `end` (..., 3, 3)."""
    return wrap_angle(head_yaw(end) - head_yaw(start))


def head_deltas(start: HeadPose, end: HeadPose) -> torch.Tensor:
    """(B, 4) (dx, dy, dz, dyaw) of head poses `end` relative to `start`, in the start head's yaw frame."""
    yaw = head_yaw(start.rotation)
    local = ((end.position - start.position)[:, None] @ about_z(yaw)).squeeze(1)
    return torch.cat([local, yaw_change(start.rotation, end.rotation)[:, None]], dim=1)


def action_targets(head: HeadPose, deltas: torch.Tensor) -> HeadPose:
    """Target head poses of action deltas (B, 4) from current heads: the inverse of `head_deltas`."""
    yaw = head_yaw(head.rotation)
    position = head.position + (about_z(yaw) @ deltas[:, :3, None]).squeeze(-1)
    return HeadPose(position, about_z(deltas[:, 3]) @ head.rotation)


class ClopsStepper(WandrStepper):
    """Rolls bodies towards target head poses with a trained `ClopsPrior` (feet kept on the floor, as WANDR's)."""

    def __init__(self, prior: ClopsPrior, body: BodyModel | None = None, ground_feet: bool = True, *,
                 reach_distance: float, reach_angle: float, lock_feet: bool = False) -> None:  # fmt: skip
        """reach_distance (m, on the ground) and reach_angle (rad, yaw): when a head counts as at its target
        (`ClopsNavConfig` holds the defaults and their measurements)."""
        super().__init__(prior, body, ground_feet, intentions=(), lock_feet=lock_feet)  # the intention slot: the head target
        self.reach_distance, self.reach_angle = reach_distance, reach_angle

    def head_condition(self, state: WandrState, target: HeadPose) -> torch.Tensor:
        """(B, 277) the normalised condition of bodies towards target head poses."""
        return self.prior.normalise_condition(condition(state, head_target_features(state, target)))

    def step_towards(self, state: WandrState, z: torch.Tensor, target: HeadPose) -> tuple[WandrState, torch.Tensor]:
        """The next frame of bodies decoded with latents z (B, latent), and its foot vertices (B, V, 3)."""
        delta = self.prior.denormalise_delta(self.prior.generate(z, self.head_condition(state, target)))
        return self.advance(state, delta)

    def reached(self, state: WandrState, target: HeadPose) -> torch.Tensor:
        """(B,) bool: the head within `reach_distance` (on the ground plane) and `reach_angle` (yaw) of its target."""
        head = head_pose(state)
        near = (head.position[:, :2] - target.position[:, :2]).norm(dim=-1) <= self.reach_distance
        return near & (yaw_change(target.rotation, head.rotation).abs() <= self.reach_angle)
