"""What the 30 fps delta-prior environments (WandrReach, ClopsNav) share: the bodies' part of their batched state
and the shipped start windows placed in the world."""

from __future__ import annotations

import dataclasses

import roma
import torch

from motion_envs.batched import BatchedState
from motion_envs.body.rotations import about_z
from motion_envs.data.start_poses import load_start_poses
from motion_envs.priors.wandr import WandrStepper
from motion_envs.priors.wandr_features import FPS, WandrState, make_state, pose_delta


@dataclasses.dataclass(frozen=True)
class DeltaPriorBodies(BatchedState):
    """The first fields of a delta-prior env's state: the prior's `WandrState` of N bodies, as tensors."""

    transl: torch.Tensor
    orient: torch.Tensor
    pose: torch.Tensor
    previous_delta: torch.Tensor
    joints: torch.Tensor
    shown_pose: torch.Tensor

    @property
    def body(self) -> WandrState:
        return WandrState(self.transl, self.orient, self.pose, self.previous_delta, self.joints, self.shown_pose)


class StartBodies:
    """The last two frames of each shipped start window (`motion_envs/assets/start_poses.npz`, 30 fps): the pose
    and the delta into it."""

    def __init__(self, stepper: WandrStepper, device: torch.device) -> None:
        self.stepper, self.device = stepper, device
        starts = load_start_poses(FPS)
        self.transl, self.orient, self.pose = (
            torch.as_tensor(starts[name][:, -2:], dtype=torch.float32, device=device)
            for name in ("transl", "global_orient", "body_pose")
        )  # (S, 2, ...): the frame before the start and the start

    def __len__(self) -> int:
        return len(self.transl)

    def place(self, start_index: torch.Tensor, facing: torch.Tensor,
              position: torch.Tensor | None = None) -> tuple[WandrState, torch.Tensor]:  # fmt: skip
        """Start rows (N,) turned by `facing` (N,) radians about +z, the pelvis over `position` (N, 2) (default the
        origin), the lowest foot point on the ground. Returns the states and their foot vertices (N, V, 3).

        Raises:
            ValueError: a start row outside [0, len(self)).
        """
        start_index, facing = start_index.to(self.device), facing.to(self.device)
        if (start_index < 0).any() or (start_index >= len(self)).any():
            raise ValueError(f"start_index must lie in [0, {len(self)}), got {start_index.tolist()}")
        turn = about_z(facing)
        origin = self.transl[start_index, -1] * torch.tensor([1.0, 1.0, 0.0], device=self.device)
        transl = ((self.transl[start_index] - origin[:, None])[..., None, :] @ turn[:, None].transpose(-1, -2)).squeeze(-2)
        if position is not None:
            transl = transl + torch.cat([position.to(self.device, torch.float32), torch.zeros_like(position[:, :1])], 1)[:, None]
        orient = turn[:, None] @ roma.rotvec_to_rotmat(self.orient[start_index])
        pose = roma.rotvec_to_rotmat(self.pose[start_index])
        delta = pose_delta(transl[:, 0], orient[:, 0], pose[:, 0], transl[:, 1], orient[:, 1], pose[:, 1])
        _, posed = make_state(self.stepper.body, transl[:, 1], orient[:, 1], pose[:, 1], delta)
        lowest = self.stepper.feet(posed)[..., 2].amin(dim=-1)  # snap the lowest foot point to the ground
        grounded = transl[:, 1] - torch.stack([torch.zeros_like(lowest), torch.zeros_like(lowest), lowest], -1)
        body, posed = make_state(self.stepper.body, grounded, orient[:, 1], pose[:, 1], delta)
        return body, self.stepper.feet(posed)

    def forward(self, start_index: torch.Tensor, facing: torch.Tensor) -> torch.Tensor:
        """(N, 2) ground forward of the start rows turned by `facing` (radians)."""
        return (about_z(facing.to(self.device)) @ roma.rotvec_to_rotmat(self.orient[start_index.to(self.device), -1]))[:, :2, 1]
