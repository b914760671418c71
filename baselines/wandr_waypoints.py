"""WANDR following waypoints with pelvis goals: the paper's C.3 extension done at inference time.

WANDR's supplement (C.3) extends its wrist intention to other joints "by replacing the wrist position with the
joint of interest in the definition of I^w", which needs a prior trained that way. The shipped prior was trained
on the wrist, so here the pelvis goal is handed to it as the wrist goal that asks for the same displacement: every
frame the goal is the current waypoint shifted by the body's own wrist-from-pelvis offset, so that the wrist
intention I^w equals the pelvis's path to the waypoint, and the pelvis and orientation intentions point at the
waypoint as they would (to within that offset). The deadline asks for one pace all along: the current waypoint
is due in d / `pace` seconds (d: the pelvis's ground distance to it), recomputed every frame (WANDR's multi-goal
reaching, Fig. S.2, also recomputes the intention every frame). Waypoints switch when the pelvis comes within
`waypoint_radius` (GAMMA's release, 0.75 m); the path is walked when the pelvis comes within `goal_radius`
(DART's 0.3 m) of the last one after the others.
"""

from __future__ import annotations

import dataclasses

import torch

from baselines.wandr_sampler import Controller
from motion_envs.batched import where_bodies
from motion_envs.envs.gamma_wander import distance_along_path
from motion_envs.envs.wandr_reach import WandrReachCore
from motion_envs.metrics import track_skating
from motion_envs.priors.wandr_features import FPS, PELVIS, RIGHT_WRIST, WandrState
from motion_envs.rewards import UPRIGHT_HEAD, head_drop

ASKED_PACE = 1.2
"""m/s the deadline asks for: a walking pace, the paced sampler's in `bench wandr`. The shipped prior keeps the
pace its intention asks (`bench wandr-pace`); on `bench wander`'s 100 open-ground paths (one body each, seed 0,
the sampler, same seed) asking 1.2 / 2 / 3 m/s walks 95 / 100 / 100% of them in 19.0 / 11.7 / 8.2 s,
with FS 0.34 / 0.48 / 0.62: a faster ask buys the last 5% with skating feet. The prior before the pelvis-tilt
fix walked at about half the asked pace, and this row asked 3 m/s (23 / 74 / 99% then)."""


@dataclasses.dataclass(frozen=True)
class WaypointWalk:
    """N bodies' waypoint walks. reached: (N,) bool; frames: (N,) frames walked (to arrival, or all); skated:
    (N,) frames whose lowest foot vertex slid (WANDR's FS); distance: (N,) metres left along the path at the end
    (at most `goal_radius` for the bodies that arrived); stooped: (N,) frames with the head lower than `UPRIGHT_HEAD`."""

    reached: torch.Tensor
    frames: torch.Tensor
    skated: torch.Tensor
    distance: torch.Tensor
    stooped: torch.Tensor


def pelvis_goal_as_wrist_goal(state: WandrState, waypoint: torch.Tensor) -> torch.Tensor:
    """(N, 3) the wrist goal that asks bodies `state` for the pelvis's ground path to `waypoint` (N, 2): the
    waypoint shifted by each body's wrist-from-pelvis ground offset, at the wrist's height."""
    wrist, pelvis = state.joints[:, RIGHT_WRIST], state.joints[:, PELVIS]
    return torch.cat([waypoint + wrist[:, :2] - pelvis[:, :2], wrist[:, 2:]], dim=1)


@torch.no_grad()
def follow_waypoints(core: WandrReachCore, start_index: torch.Tensor, facing: torch.Tensor, waypoints: torch.Tensor,
                     count: torch.Tensor, controller: Controller, max_frames: int, waypoint_radius: float = 0.75,
                     goal_radius: float = 0.3, pace: float = ASKED_PACE) -> WaypointWalk:  # fmt: skip
    """Walk N bodies from start rows (N,) facing (N,) radians (pelvis over the origin) along waypoints
    (N, W, 2) (the first `count` (N,) of each row, padded with its last, as `GammaWanderState` has them) with
    `controller`'s latents, for at most
    `max_frames` frames (30 fps); bodies stop where they arrive."""
    device = core.device
    waypoints, count = waypoints.to(device), count.to(device)
    rows = torch.arange(len(waypoints), device=device)
    state = core.initial_state(start_index, facing, torch.zeros(len(waypoints), 1, 3))
    body, current = state.body, torch.zeros_like(count)
    lowest_id, lowest_xy = state.lowest_id, state.lowest_xy
    active = torch.ones_like(count, dtype=torch.bool)
    frames, skated, stooped = torch.zeros_like(count), torch.zeros_like(count), torch.zeros_like(count)
    for _ in range(max_frames):
        if not active.any():
            break
        waypoint = waypoints[rows, current]
        distance = (waypoint - body.joints[:, PELVIS, :2]).norm(dim=-1)
        frames_left = (distance / pace * FPS).ceil().long().clamp_min(1)
        z = controller(core, dataclasses.replace(state, **body._asdict()))
        moved, feet = core.stepper.step(body, z, pelvis_goal_as_wrist_goal(body, waypoint), frames_left)
        slid, lowest_id, lowest_xy = track_skating(feet, lowest_id, lowest_xy, active)
        body = WandrState(*(where_bodies(active, new, old) for new, old in zip(moved, body)))
        low = head_drop(body.joints, UPRIGHT_HEAD) > 0
        frames, skated, stooped = frames + active.long(), skated + slid.long(), stooped + (low & active).long()
        distance = (waypoint - body.joints[:, PELVIS, :2]).norm(dim=-1)
        last = current >= count - 1
        arrived = active & last & (distance <= goal_radius)
        current = current + (active & ~last & (distance <= waypoint_radius)).long()
        active = active & ~arrived
    left = distance_along_path(waypoints, current, body.joints[:, PELVIS, :2])
    return WaypointWalk((~active).cpu(), frames.cpu(), skated.cpu(), left.cpu(), stooped.cpu())
