"""A non-visual navigator for ClopsNav episodes: GAMMA's goal-reaching policy told where the goal is (EgoGen-like).

EgoGen (the CLOPS paper's Table 2 baseline) steers a motion prior with PPO
towards a known goal. Our stand-in is the shipped GammaReach PPO policy: it
sees the goal position, not the room, so it walks straight at the goal and
collides with whatever stands in between. The episode is the ClopsNav
episode (same room, start, heading and goal); every 0.25 s primitive is
scored like a ClopsNav action:

* success: the pelvis within `success_distance` of the goal on the ground
  and any goal pixel in the head camera's view (the same ray-cast mask);
  the body stops there;
* collision: per second of motion (4 primitives, about one CLOPS action),
  any collision sphere deeper than the tolerance in the scene at any new
  frame;
* foot skating: WANDR's measure with its 0.66 cm per 1/30 s threshold
  scaled to 40 fps (0.495 cm per frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from motion_envs.body.head_camera import head_camera
from motion_envs.body.markers import foot_vertex_ids
from motion_envs.envs.clops_nav import ClopsNavCore, ClopsNavState
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore
from motion_envs.metrics import foot_skating, skating_threshold
from motion_envs.priors.clops import head_yaw

PRIMITIVES_PER_SECOND = 4
GAMMA_FPS = 40


@dataclass(frozen=True)
class NavigationStats:
    """Per body: found (N,) bool, seconds (N,) of motion, collided_seconds (N,), skated (N,) frames, frames (N,),
    paths (N, T, 2) pelvis positions after every action or second (NaN after the end)."""

    found: np.ndarray
    seconds: np.ndarray
    collided_seconds: np.ndarray
    skated: np.ndarray
    frames: np.ndarray
    paths: np.ndarray


def gamma_navigate(clops: ClopsNavCore, episodes: ClopsNavState, policy, max_seconds: float = 15.0) -> NavigationStats:
    """Run `policy` (an SB3 model over GammaReach observations) on the ClopsNav `episodes` (their rooms, starts,
    headings and goals)."""
    gamma = GammaReachCore(GammaReachConfig(terminate_on_goal=False))
    count = episodes.num_bodies
    start = episodes.joints[:, 0, :2].clone()  # pelvis
    offset = torch.cat([start, torch.zeros(count, 1)], dim=1)
    rows = torch.arange(count) % gamma.num_starts
    own_yaw = head_yaw(_rotations(gamma, rows))
    wanted_yaw = head_yaw(episodes.orient)
    state = gamma.initial_state(rows, wanted_yaw - own_yaw, episodes.goal[:, :2] - start)
    feet_ids = foot_vertex_ids()
    threshold = skating_threshold(GAMMA_FPS)
    found = torch.zeros(count, dtype=torch.bool)
    seconds = torch.zeros(count, dtype=torch.long)
    collided_seconds = torch.zeros(count, dtype=torch.long)
    skated = torch.zeros(count, dtype=torch.long)
    frames = torch.zeros(count, dtype=torch.long)
    window_hit = torch.zeros(count, dtype=torch.bool)
    last_feet = None
    paths = [start.numpy().copy()]
    for step in range(round(max_seconds * PRIMITIVES_PER_SECOND)):
        alive = ~found
        with torch.no_grad():
            actions, _ = policy.predict(gamma.observe(state).numpy(), deterministic=True)
            state, result = gamma.step(state, torch.as_tensor(actions))
        primitive = result.primitive
        new = primitive.new_frames()[0]  # every body has the same seed length after the first step
        joints = primitive.joints[:, new] + offset[:, None, None]
        window_hit |= clops.collisions(joints.transpose(0, 1), episodes.scene) & alive
        posed = gamma.body(primitive.transl[:, new], primitive.global_orient[:, new], primitive.body_pose[:, new])
        feet = gamma.body.skin(posed, feet_ids)  # (N, F, V, 3)
        chain = feet if last_feet is None else torch.cat([last_feet[:, None], feet], dim=1)
        slid = foot_skating(chain, threshold)  # (N, F or F - 1)
        skated += (slid.sum(1) * alive).long()
        frames += (slid.shape[1] * alive).long()
        last_feet = feet[:, -1]
        last = posed.joints[:, -1, 0, :2] + start
        camera = head_camera(posed)
        visible = clops.goal_visible(camera.eye[:, -1] + offset, camera.rotation[:, -1], episodes.goal, episodes.scene)
        near = (last - episodes.goal[:, :2]).norm(dim=-1) <= clops.config.success_distance
        found |= near & visible & alive
        if (step + 1) % PRIMITIVES_PER_SECOND == 0:
            seconds += alive.long()
            collided_seconds += window_hit.long()
            window_hit[:] = False
            paths.append(np.where(alive[:, None].numpy(), last.numpy(), np.nan))
        if found.all():
            break
    return NavigationStats(found.numpy(), seconds.numpy(), collided_seconds.numpy(), skated.numpy(), frames.numpy(),
                           np.stack(paths, axis=1))  # fmt: skip


def _rotations(gamma: GammaReachCore, rows: torch.Tensor) -> torch.Tensor:
    """(N, 3, 3) pelvis rotations of GammaReach start rows."""
    posed = gamma.body(gamma.start_transl[rows], gamma.start_orient[rows], gamma.start_pose[rows])
    return posed.rotations[:, 0]
