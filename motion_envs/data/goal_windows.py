"""Goal-reaching examples cut from the data: a primitive, and a goal the body walked to later.

GAMMA's g-CVAE baseline is trained "on goals taken from the data"; the same
examples give a policy its first idea of which latent walks where
(`agents.behaviour_cloning`). For every 10-frame window (stride 1) of a clip,
the goal is the pelvis, dropped to the ground, at a random later frame of the
same clip (`horizon_frames` after the window's end, clipped to the clip's
end). Windows whose goal lies closer than `min_goal_distance` to the body are
dropped: most of the data stands still, and the environment's goals are
metres away.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from motion_envs.data.primitives import PRIMITIVE_FRAMES, MarkerClips
from motion_envs.body.canonical_frame import PELVIS, canonical_frame, goal_observation, to_canonical


@dataclass(frozen=True)
class GoalWindowSettings:
    horizon_frames: tuple[int, int] = (20, 240)
    """A goal lies this many frames (40 fps: 0.5-6 s) after its window, at most at the clip's end."""
    min_goal_distance: float = 1.0
    """Metres on the ground between the window's last pelvis and its goal."""
    goals_per_window: int = 3
    seed: int = 0


@dataclass(frozen=True)
class GoalWindows:
    """observation: (B, 804) the environment's state (Eq. 3) at the window's start. seed: (B, 2, 67, 3) and
    future: (B, 8, 67, 3) canonical markers of the window. goal: (B, 3) canonical goal on the ground."""

    observation: torch.Tensor
    seed: torch.Tensor
    future: torch.Tensor
    goal: torch.Tensor

    def __len__(self) -> int:
        return len(self.observation)


def goal_windows(clips: MarkerClips, settings: GoalWindowSettings = GoalWindowSettings()) -> GoalWindows:
    """Every window of `clips` with `goals_per_window` goals each, those too near dropped."""
    starts = clips.window_starts(PRIMITIVE_FRAMES)
    if len(starts) == 0:
        raise ValueError("no clip is long enough for one primitive")
    clip_end = clips.clip_start[torch.searchsorted(clips.clip_start, starts, right=True)]
    generator = torch.Generator().manual_seed(settings.seed)
    low, high = settings.horizon_frames
    reached_from = clips.joints[starts + PRIMITIVE_FRAMES - 1, PELVIS, :2]
    chosen, goals = [], []
    for _ in range(settings.goals_per_window):
        later = torch.randint(low, high + 1, (len(starts),), generator=generator)
        goal = clips.joints[torch.minimum(starts + PRIMITIVE_FRAMES - 1 + later, clip_end - 1), PELVIS].clone()
        goal[:, 2] = 0.0
        far = (goal[:, :2] - reached_from).norm(dim=-1) >= settings.min_goal_distance
        chosen.append(starts[far])
        goals.append(goal[far])
    starts, goal = torch.cat(chosen), torch.cat(goals)
    if len(starts) == 0:
        raise ValueError(f"no window has a goal at least {settings.min_goal_distance} m away")
    windows = clips.windows(starts, PRIMITIVE_FRAMES)
    first = clips.joints[starts]
    observation = goal_observation(clips.markers[starts[:, None] + torch.arange(2)], first, goal)
    canonical_goal = to_canonical(goal[:, None], canonical_frame(first))[:, 0]
    return GoalWindows(observation, windows.markers[:, :2], windows.markers[:, 2:], canonical_goal)
