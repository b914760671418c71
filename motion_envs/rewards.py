"""Reward terms as named pure functions over batched tensors, and their weights.

GAMMA (Zhang & Tang, CVPR 2022, Eq. 4-9) scores every primitive with

    r = r_path + β1 r_ori + β2 r_contact + β3 r_vposer + β4 r_goal,

each term in [0, 1]. The paper does not print its β; `RewardConfig.paper()`
weighs every term 1. The authors' released code computes a different reward
(REFERENCE_NOTES §1.7): `RewardConfig.release()` reproduces it (facing
weight 0.5, contact with the unsquared central-difference speed, pose prior
on the unsquared latent norm, goal term over a 10 m scale).

Deviation, both configs: Eq. 9's r_goal is "added to all primitives of the
sequence according to the closest distance of any primitive", which needs
the future. An environment must pay as it goes, so r_goal here uses the
closest distance *so far*, and the episode's last step pays the rest
(`goal_settlement`): T · r_goal(closest of the episode) minus what was paid,
so an episode's goal reward sums to the paper's (undiscounted). Without the
settlement, getting close late earns almost nothing, and a policy learns to
walk towards the goal slowly without reaching it. When the environment ends an episode on success, the
remaining primitives are paid at the best per-step reward
(`goal_absorbing_reward`), as if the body stayed at the goal: without it,
ending an episode early would lose reward, and a policy would learn to
avoid the goal.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import TypeVar

import torch

from motion_envs.body.canonical_frame import LEFT_HIP, PELVIS, RIGHT_HIP
from motion_envs.body.skeleton import joint_index

HEAD = joint_index("head")

DATA_WALK_SPEED = 2.1
"""m/s: the data's fastest walking (no half-second window of the CMU test walks is faster); the speeding terms'
default limit."""
UPRIGHT_HEAD = 1.38
"""m: the neutral body's head height that the clean data's walking (pelvis ground speed 0.5-2.1 m/s) stays above in
85% of the test split's frames and 73% of the training split's (medians 1.42-1.43 m; the standing start poses
1.49 m); the stooping terms' default."""


@dataclass(frozen=True)
class RewardConfig:
    """Weights (β) and shapes of GAMMA's reward terms."""

    path: float = 1.0
    orientation: float = 1.0
    contact: float = 1.0
    pose_prior: float = 1.0
    goal: float = 1.0
    goal_scale: float = 20.0
    """L of Eq. 9, metres: the size of the activity area (release: 10)."""
    contact_speed_power: float = 2.0
    """Eq. 7 uses exp(-|v*|²); the release exp(-|v*|)."""
    central_difference: bool = False
    """Marker speed by central (release) or forward (paper's metric) difference."""
    pose_prior_power: float = 2.0
    """Eq. 8 uses exp(-|μ|²); the release exp(-|μ|) (both on the latent rms here, see `pose_prior_reward`)."""

    @classmethod
    def paper(cls) -> RewardConfig:
        return cls()

    @classmethod
    def release(cls) -> RewardConfig:
        return cls(orientation=0.5, goal_scale=10.0, contact_speed_power=1.0, central_difference=True, pose_prior_power=1.0)

    @classmethod
    def named(cls, spec: str) -> RewardConfig:
        """'paper' or 'release', optionally with fields changed: 'paper:goal=5,orientation=0.5'."""
        return named_config(spec, {"paper": cls.paper, "release": cls.release})

    @property
    def best_step_reward(self) -> float:
        """The largest reward one primitive can earn (every term 1)."""
        return self.path + self.orientation + self.contact + self.pose_prior + self.goal


Config = TypeVar("Config")


def named_config(spec: str, presets: dict[str, Callable[[], Config]]) -> Config:
    """A preset by name with fields changed after a colon: 'name:field=value,field=value'."""
    name, _, changes = spec.partition(":")
    if name not in presets:
        raise ValueError(f"unknown reward config {name!r}; choose from {sorted(presets)} (then :field=value,...)")
    config = presets[name]()
    names = [f.name for f in fields(config)]
    for change in filter(None, changes.split(",")):
        field, _, value = change.partition("=")
        if field not in names or not value:
            raise ValueError(f"bad reward change {change!r} in {spec!r}; fields: {names}")
        kind = type(getattr(config, field))
        config = replace(config, **{field: value.lower() in ("1", "true") if kind is bool else kind(value)})
    return config


def _unit(vectors: torch.Tensor) -> torch.Tensor:
    return vectors / vectors.norm(dim=-1, keepdim=True).clamp_min(1e-8)


def path_reward(pelvis_start: torch.Tensor, pelvis_end: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """Eq. 5: (⟨unit(p_T - p_0), unit(g - p_0)⟩ + 1) / 2 on the ground plane. Inputs (N, 2|3) -> (N,)."""
    moved = _unit(pelvis_end[..., :2] - pelvis_start[..., :2])
    wanted = _unit(goal[..., :2] - pelvis_start[..., :2])
    return ((moved * wanted).sum(-1) + 1.0) / 2.0


def facing_direction(joints: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) -> (..., 2) unit forward on the ground: up × (right hip − left hip)."""
    across = joints[..., RIGHT_HIP, :2] - joints[..., LEFT_HIP, :2]
    return _unit(torch.stack([-across[..., 1], across[..., 0]], dim=-1))


def orientation_reward(joints_end: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """Eq. 6: (⟨o_T, unit(g - p_T)⟩ + 1) / 2, facing at the last frame. joints_end (N, 22, 3), goal (N, 2|3)."""
    wanted = _unit(goal[..., :2] - joints_end[..., PELVIS, :2])
    return ((facing_direction(joints_end) * wanted).sum(-1) + 1.0) / 2.0


def contact_reward(pelvis_z_start: torch.Tensor, pelvis_z_end: torch.Tensor, min_speed: torch.Tensor,
                   speed_power: float = 2.0) -> torch.Tensor:  # fmt: skip
    """Eq. 7: exp(-|p_z,T - p_z,0|) · exp(-|v*|^power), v* the slowest marker speed of the primitive. (N,) -> (N,)."""
    return torch.exp(-(pelvis_z_end - pelvis_z_start).abs()) * torch.exp(-min_speed.pow(speed_power))


def pose_prior_reward(latent_mean: torch.Tensor, power: float = 2.0) -> torch.Tensor:
    """Eq. 8 on the latent's root mean square: exp(-mean over frames of rms(μ(θ))^power). (N, T, D) -> (N,).

    Deviation: Eq. 8 has |μ|^2. Our pose VAE puts validation poses at a mean
    |μ|² of 17.5 over its 32 dimensions, where exp(-|μ|²) is ~0 for every real
    pose and the term would teach nothing; rms = |μ| / sqrt(D) keeps the paper's
    shape on a scale where real poses score ~0.6 and odd ones less."""
    rms = latent_mean.norm(dim=-1) / latent_mean.shape[-1] ** 0.5
    return torch.exp(-rms.pow(power).mean(dim=-1))


def goal_reward(closest_distance: torch.Tensor, scale: float, tolerance: float) -> torch.Tensor:
    """Eq. 9 on the closest pelvis-goal ground distance so far (N,): 1 within `tolerance`, else ((L - d) / L)+."""
    return torch.where(closest_distance <= tolerance, torch.ones_like(closest_distance),
                       ((scale - closest_distance) / scale).clamp_min(0.0))  # fmt: skip


def goal_settlement(steps: torch.Tensor, final_goal_reward: torch.Tensor, paid: torch.Tensor) -> torch.Tensor:
    """Episode end: what makes the r_goal paid over `steps` (N,) primitives sum to steps · r_goal(closest),
    given the last r_goal (N,) (of the episode's closest distance) and the sum `paid` (N,) so far."""
    return steps.to(paid.dtype) * final_goal_reward - paid


def goal_absorbing_reward(succeeded: torch.Tensor, remaining_steps: torch.Tensor, best_step_reward: float) -> torch.Tensor:
    """On success (N,) bool, the remaining primitives (N,) paid at `best_step_reward` each (see module doc)."""
    return succeeded.to(remaining_steps.dtype) * remaining_steps * best_step_reward


@dataclass(frozen=True)
class WandrRewardConfig:
    """Scales of WandrReach's reward terms (ours: the WANDR paper trains no policy and has no reward).

    r = progress · wrist_progress + success · reached − skating · skated − speeding · overspeed − lying · pelvis_drop
        − latent · latent_cost
    """

    progress: float = 10.0
    """Per metre the right wrist comes closer to the goal (a 5 m reach earns about 50)."""
    success: float = 10.0
    """Once, on the frame the wrist first comes within the success radius."""
    skating: float = 0.1
    """Per frame whose lowest foot vertex slides more than WANDR's FS threshold."""
    speeding: float = 1.0
    """Per frame, times the m/s by which the pelvis moves over the ground faster than `walk_speed` (`overspeed`).
    Ours: without it the policy reached far goals by running (median peak pelvis speed 3.8 m/s for goals 5–6 m
    away), because discounting pays arriving sooner; the task is walking and reaching."""
    walk_speed: float = DATA_WALK_SPEED
    lying: float = 0.0
    """Per frame, times the metres by which the pelvis is lower than `pelvis_floor` (`pelvis_drop`). Ours: a
    policy without it folds flat to put the wrist on a goal at the floor (pelvis down to 0.1 m, `bench floor`)
    where a person squats."""
    pelvis_floor: float = 0.3
    latent: float = 0.01
    """Times the mean square of z: keeps actions where the prior was trained (N(0, I))."""

    @classmethod
    def named(cls, spec: str) -> WandrRewardConfig:
        """'default', optionally with fields changed: 'default:success=5,skating=0.5'."""
        return named_config(spec, {"default": cls})


def wrist_progress(previous_distance: torch.Tensor, distance: torch.Tensor) -> torch.Tensor:
    """(N,) metres the wrist came closer to the goal this step (negative when it moved away)."""
    return previous_distance - distance


def overspeed(previous_pelvis: torch.Tensor, pelvis: torch.Tensor, fps: float, limit: float) -> torch.Tensor:
    """(...) m/s by which the pelvis moved over the ground faster than `limit` this frame (0 when slower);
    previous_pelvis, pelvis: (..., 3) positions one frame (1 / fps s) apart."""
    return ((pelvis - previous_pelvis)[..., :2].norm(dim=-1) * fps - limit).clamp_min(0.0)


def pelvis_drop(pelvis: torch.Tensor, height: float) -> torch.Tensor:
    """(...) metres by which pelvis positions (..., 3) are lower than `height` above the ground (0 when higher)."""
    return (height - pelvis[..., 2]).clamp_min(0.0)


def head_drop(joints: torch.Tensor, height: float) -> torch.Tensor:
    """(...) metres by which the head of bodies with joints (..., 22, 3) is lower than `height` above the ground (0
    when higher): a bent trunk, bent knees and a hanging head all lower it."""
    return (height - joints[..., HEAD, 2]).clamp_min(0.0)


def latent_cost(z: torch.Tensor) -> torch.Tensor:
    """(N, D) latents -> (N,) mean square, 1 for typical draws from N(0, I)."""
    return (z**2).mean(dim=-1)


@dataclass(frozen=True)
class ClopsRewardConfig:
    """Scales of CLOPS's reward (Eq. 5), paid per action; the paper's constants were lost from its text, these are ours.

    r = −time − collision · collided − still · stayed + goal · found − left_room · left − fallen · fell
    """

    time: float = 0.1
    """Every action (pushes towards reaching the goal sooner)."""
    collision: float = 1.0
    """An action during which any body sphere penetrates the scene (`ClopsNavConfig.collision_tolerance`)."""
    still: float = 0.5
    """An action after which the head has neither moved nor turned (`ClopsNavConfig.still_distance`, `still_angle`)."""
    goal: float = 10.0
    """The action that ends with the goal near (`success_distance`) and in view (any goal-mask pixel)."""
    left_room: float = 5.0
    """Ours, not the paper's (its Replica rooms are closed): the action after which the pelvis is out of the room
    (`ClopsNavConfig.room_margin`); the episode ends there."""
    fallen: float = 5.0
    """Ours: the action during which the pelvis fell below `ClopsNavConfig.fall_height`; the episode ends there."""

    @classmethod
    def named(cls, spec: str) -> ClopsRewardConfig:
        """'default', optionally with fields changed: 'default:collision=0.5'."""
        return named_config(spec, {"default": cls})


def stayed_still(moved: torch.Tensor, turned: torch.Tensor, distance: float, angle: float) -> torch.Tensor:
    """(N,) bool: a head moved less than `distance` metres (moved, (N,)) and turned less than `angle` radians (turned, (N,))."""
    return (moved < distance) & (turned.abs() < angle)


def goal_found(distance: torch.Tensor, visible: torch.Tensor, success_distance: float) -> torch.Tensor:
    """(N,) bool: the goal within `success_distance` (distance, (N,), metres on the ground) and visible ((N,) bool)."""
    return (distance <= success_distance) & visible
