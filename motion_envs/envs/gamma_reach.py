"""GammaReach-v0: steer a GAMMA body to a goal on the ground by choosing its latent codes.

## Description

GAMMA (Zhang & Tang, CVPR 2022) turns a latent code z into a 0.25 s motion
primitive of a human body. Here a body stands in the middle of a 20 × 20 m
ground and a goal lies somewhere on it; every step the agent picks z, the
prior generates the next primitive (10 frames at 40 fps: 1 or 2 seed frames
from the previous one, 9 or 8 new), and the body moves.

## Action Space

`Box(-4, 4, (128,), float32)`: the marker predictor's latent z, unscaled
(the prior is N(0, I), so the box holds all but 6e-5 of its mass per
coordinate). Actions outside the box are clipped to it, then scaled down to a
norm of `latent_radius` (16) where longer: N(0, I) latents (norm 11.3) and the
policies' are untouched, while uniform draws from the box (norm ~26) would
fold bodies to the floor. A wrong shape or a NaN/inf raises `ValueError`.

## Observation Space

`Box(-inf, inf, (804,), float32)`: the paper's state (Eq. 3) for the next
primitive, in its canonical frame (origin: pelvis of the first seed frame,
x: left-to-right hip, z: up): for each of 2 seed frames, 67 markers (x, y, z)
then 67 unit vectors from each marker to the goal (which lies on the
ground), i.e. `(2, 67, 6)` flattened. At an episode's start the seed is one
frame; it fills both slots.

## Rewards

GAMMA's Eq. 4 with the terms of `motion_envs.rewards` (each in [0, 1]),
weights from `RewardConfig` (`reward="paper"` default, or `"release"`, the
authors' code). Every term is in `info["reward_terms"]`. The last step of an
episode also settles r_goal (`goal_settlement`) so that the episode's goal
reward sums to Eq. 9's; with `terminate_on_goal` (default) a successful
step also earns the remaining primitives at the best per-step reward
(`goal_absorbing`; see `motion_envs.rewards`). Ours, off by default: `stooping`
per new frame and metre that the head is below `upright_head` (1.38 m), and
`skating` per new frame and m/s that the loaded heel or toe slides on the floor.

## Starting State

A start window from the validation data (`motion_envs/assets/start_poses.npz`,
standing or walking, `start_kind`), its last frame placed with the pelvis
over the centre, facing a uniformly random direction, its lowest foot point
snapped to the ground. The goal is uniform on
the ground, at least `min_goal_distance` from the start.

## Floor

With `ground_feet` (default) each new frame is moved vertically so that the body's lowest sole point (of the
soles' convex hulls) touches the ground, as WandrReach's rule: the prior's height drifts (random latents bury a
body or fly it metres up) and a walking body always has a foot down. The realism benchmarks also measure the
prior without it (`ground_feet=False`).

## Feet

With `lock_feet` (default) each body's legs are fitted so that its feet stand where the predicted markers put
them on the ground (their heights stay the regressor's), and a loaded foot is held where it touched down
(`GammaGenerator.step`, `motion_envs.body.foot_lock`): the body regressor recovers every frame on its own, and
its feet slide where the prediction holds them. Only the legs change; the next seed and so the motion are the
prior's (the shipped policies behave as without the rule, up to the floor rule's lift of the refitted bodies).
`lock_feet=False` shows the regressor's bodies.

## Episode End

Success: the pelvis (last frame of a primitive) within `goal_radius` (0.75 m)
of the goal on the ground; the episode terminates there when
`terminate_on_goal`. Truncation after `max_primitives` (60) primitives.

## Arguments

`gym.make("motion_envs/GammaReach-v0", **kwargs)` with any field of
`GammaReachConfig`; `reward` may be "paper", "release" or a `RewardConfig`.
`reset(options=...)` takes `goal` ((x, y) metres), `start_index` (row of the
start poses) and `facing` (radians: a turn of the stored start pose, which faces about
+y; the body then faces about `facing` + π/2 from +x).

## Batched core and state

`GammaReachCore` steps N bodies at once (the single env is N = 1; the
vector env is N = num_envs). The whole simulation state is one
`GammaReachState` (`motion_envs.batched.BatchedState`): `env.state` can be
cloned, indexed, repeated and assigned back, which the tree search uses.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
import roma
import torch

from motion_envs.allocator import keep_freed_memory
from motion_envs.batched import BatchedState
from motion_envs.body import BodyModel
from motion_envs.body.markers import foot_vertex_ids
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.data.start_poses import load_start_poses
from motion_envs.envs.core import CoreVectorEnv, check_actions, config_from_kwargs
from motion_envs.envs.options import check_known, index, number, point
from motion_envs.metrics import contact_score, loaded_slide, slowest_marker_speed
from motion_envs.precision import PRECISIONS, resolve_precision
from motion_envs.body.canonical_frame import (
    PELVIS,
    canonical_frame,
    canonical_goal_observation,
    goal_observation,
    to_canonical,
)
from motion_envs.body.mirror import mirror_points
from motion_envs.body.markers import MARKER_NAMES
from motion_envs.priors.gamma_generator import GammaGenerator, GammaSeed, Primitive
from motion_envs.render.env_view import EnvView, RenderInputs
from motion_envs.rewards import (
    UPRIGHT_HEAD,
    RewardConfig,
    contact_reward,
    goal_absorbing_reward,
    goal_reward,
    goal_settlement,
    head_drop,
    orientation_reward,
    path_reward,
    pose_prior_reward,
)

OBSERVATION_SIZE = 2 * 67 * 6
START_KINDS = ("any", "standing", "walking")
RESET_OPTIONS = ("goal", "start_index", "facing")
SOLE_MARKERS = [MARKER_NAMES.index(name) for name in ("LHEE", "LTOE", "RHEE", "RTOE")]
"""The heel and toe markers in `metrics.loaded_slide`'s sole-point order (left heel, left toe, right heel, right toe)."""


@dataclasses.dataclass(frozen=True)
class GammaReachConfig:
    """Everything that defines a GammaReach task (defaults: the paper's)."""

    reward: RewardConfig = dataclasses.field(default_factory=RewardConfig.paper)
    area: float = 20.0
    """Side of the square ground (m), centred on the start; goals are uniform on it."""
    goal_radius: float = 0.75
    min_goal_distance: float = 0.75
    max_primitives: int = 60
    start_kind: str = "any"
    latent_bound: float = 4.0
    """Each latent coordinate is clipped to ±latent_bound (the action space's box)."""
    latent_radius: float | None = 16.0
    """Then z is scaled down to this norm where it is longer (None: no cap). The prior was trained on z ~ N(0, I)
    (norm 11.3 ± 0.7 in 128 dimensions) and the policies act near the data's latents (norm ~4-6), but uniform
    in-range actions have a norm of ~26 (up to 45 in the box's corners), far outside anything the prior saw:
    they folded bodies to a pelvis 0.23 m high (`bench floor`). The cap leaves N(0, I) and every policy's
    actions as they are."""
    terminate_on_goal: bool = True
    weights_dir: str | None = None
    """Folder with the GAMMA weights (default: the shipped ones)."""
    device: str = "cpu"
    ground_feet: bool = True
    """The floor rule: each new frame is moved vertically so the body's lowest sole point is on the ground
    (`GammaGenerator.step`); False shows the raw prior, whose height drifts."""
    lock_feet: bool = True
    """The foot rule: legs fitted to the predicted feet, loaded feet held (`GammaGenerator.step`); False shows the
    regressor's bodies, whose feet slide."""
    precision: str = "auto"
    """The prior's networks: "float32", "bfloat16", or "auto": bf16 where the device multiplies it natively
    (`motion_envs.precision`; AMX / AVX512-BF16 CPUs, bf16 GPUs), else fp32. The core sets its generator's."""
    heading_calibration: bool = False
    """The prior's heading calibration (`motion_envs.priors.gamma_heading`): each predicted frame turned by minus
    its predictor's measured heading bias, which otherwise turns most random-latent bodies left. Off by default:
    the shipped policies were trained without it (with it on, the alpha = 1 policy reaches 0.28 instead of 0.91 of
    the goals 12 m to its left within 15 s: `motion-envs bench gamma-turns`); policies trained with it record it in
    their env options."""
    mirror_right_goals: bool = False
    """Bodies whose goal lies on their right at the start (canonical x > 0) live the episode in their mirror image:
    they see the mirror image's observation (`GammaGenerator.mirrored_seed_markers`, the goal reflected), and the
    prior makes the mirror image's primitives, mirrored back (`GammaGenerator.step`'s `mirror`). Decided once per
    episode: deciding per primitive made the alpha = 10 (cloned) policy, which approaches a goal holding it a
    little to one side, switch back and forth (per body 0.82 -> 0.71, 100 pairs x 8 bodies). Ours, not GAMMA's:
    the trained prior turns left far more readily than right (`bench gamma-turns`), so policies reach goals on
    the left (per body 0.99) and fail those on the right (0.64, `gamma_control_fp32.md`); the prior trains on
    every clip and its mirror image, so the mirror image's motion is as much the prior's own. Off by default:
    the shipped policies were trained without it (they need no retraining: they see left goals)."""
    stooping: float = 0.0
    """Per new frame and metre that the head is lower than `upright_head`, subtracted from the reward (ours, not
    GAMMA's; 0: off). GAMMA's reward has no posture term, and its policies walk hunched, the head hanging forward
    over bent knees (measured in held-out living rooms, the GammaReach alpha = 1 policy against the clean data's
    walking: head below 1.38 m in 60-80% of frames against 15-27%, `bench wander`; the trunk is as upright as the
    data's, the head hangs 0.12 m ahead of the neck against 0.04 m)."""
    upright_head: float = UPRIGHT_HEAD
    skating: float = 0.0
    """Per new frame and m/s that the loaded heel or toe marker slides faster than 0.2 m/s while on the floor
    (`metrics.loaded_slide` of the LHEE, LTOE, RHEE, RTOE markers skinned from the regressed body), subtracted
    from the reward (ours; 0: off). GAMMA's contact term (Eq. 7) scores only a primitive's single slowest
    marker, so a policy pays nothing for a planted foot that slides while the other one stands: fine-tuned with
    `stooping` alone, the alpha = 1 policy's FS rose from 0.69 to 0.79 (runs/reach_posture.py, 100 pairs x 8
    bodies)."""

    def __post_init__(self) -> None:
        if isinstance(self.reward, str):
            object.__setattr__(self, "reward", RewardConfig.named(self.reward))
        if min(self.stooping, self.upright_head, self.skating) < 0:
            raise ValueError(f"stooping, upright_head and skating must be >= 0, got {self.stooping}, {self.upright_head}, "
                             f"{self.skating}")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {self.precision!r}")
        if self.start_kind not in START_KINDS:
            raise ValueError(f"start_kind must be one of {START_KINDS}, got {self.start_kind!r}")
        if self.max_primitives < 1 or self.area <= 0 or self.goal_radius <= 0 or self.latent_bound <= 0:
            raise ValueError("max_primitives, area, goal_radius and latent_bound must be positive")
        if self.latent_radius is not None and self.latent_radius <= 0:
            raise ValueError(f"latent_radius must be positive or None, got {self.latent_radius}")


@dataclasses.dataclass(frozen=True)
class GammaReachState(BatchedState):
    """N bodies' simulation state. goal: (N, 3) on the ground. steps: (N,) primitives so far.
    closest: (N,) closest pelvis-goal ground distance so far (m). goal_paid: (N,) r_goal paid so far.
    mirrored: (N,) bool, bodies living their episode in their mirror image (`GammaReachConfig.mirror_right_goals`)."""

    seed: GammaSeed
    goal: torch.Tensor
    steps: torch.Tensor
    closest: torch.Tensor
    goal_paid: torch.Tensor
    mirrored: torch.Tensor


@dataclasses.dataclass(frozen=True)
class GammaStepResult:
    """What one step of N bodies produced; every tensor (N,) unless noted."""

    reward: torch.Tensor
    terms: dict[str, torch.Tensor]
    distance: torch.Tensor
    reached: torch.Tensor
    terminated: torch.Tensor
    truncated: torch.Tensor
    contact_score: torch.Tensor
    primitive: Primitive


class GammaReachCore:
    """The batched task: start states, one step for N bodies, observations. Stateless: states go in and out."""

    def __init__(self, config: GammaReachConfig, generator: GammaGenerator | None = None) -> None:
        keep_freed_memory()  # large step tensors reused, not page-faulted anew (`motion_envs.allocator`)
        self.config = config
        self.device = torch.device(config.device)
        loaded = generator or (GammaGenerator.load(config.weights_dir) if config.weights_dir else GammaGenerator.load())
        self.generator = loaded.to(self.device).set_precision(resolve_precision(config.precision, self.device))
        self.generator.set_heading_calibration(config.heading_calibration)
        starts = load_start_poses(GAMMA_FPS)
        keep = np.ones(len(starts["kind"]), dtype=bool) if config.start_kind == "any" else starts["kind"] == config.start_kind
        self.start_rows = np.flatnonzero(keep)

        def last_frame(name: str) -> torch.Tensor:
            return torch.as_tensor(starts[name][:, -1], dtype=torch.float32, device=self.device)

        self.start_transl, self.start_orient, self.start_pose = last_frame("transl"), last_frame("global_orient"), last_frame("body_pose")
        with torch.no_grad():  # snap each start body to the ground, as the paper does (the data's floor drifts a few cm)
            posed = self.generator.body(self.start_transl, self.start_orient, self.start_pose)
            lowest = self.generator.body.skin(posed, foot_vertex_ids())[..., 2].amin(dim=-1)
        self.start_transl[:, 2] -= lowest

    @property
    def num_starts(self) -> int:
        return len(self.start_transl)

    def initial_state(self, start_index: torch.Tensor, facing: torch.Tensor, goal_xy: torch.Tensor,
                      start_xy: torch.Tensor | None = None) -> GammaReachState:  # fmt: skip
        """Bodies from start rows (N,) turned by `facing` (N,) radians about the vertical through the pelvis, pelvis
        over `start_xy` (N, 2) (default (0, 0)); goals (N, 2) on the ground. The stored start poses face about +y
        (forward, `rewards.facing_direction`, at a median 91° from +x, 68-133° over the 48 rows), so a body faces
        about `facing` + π/2 (`benchmarks.gamma_turns.starts` aims goals by the measured forward)."""
        start_index, facing, goal_xy = (value.to(self.device) for value in (start_index, facing, goal_xy))
        if (start_index < 0).any() or (start_index >= self.num_starts).any():
            raise ValueError(f"start_index must lie in [0, {self.num_starts}), got {start_index.tolist()}")
        turn = roma.rotvec_to_rotmat(torch.stack([torch.zeros_like(facing), torch.zeros_like(facing), facing], -1))
        orient = roma.rotmat_to_rotvec(turn @ roma.rotvec_to_rotmat(self.start_orient[start_index]))
        transl = self.start_transl[start_index] * torch.tensor([0.0, 0.0, 1.0], device=self.device)
        if start_xy is not None:
            transl[:, :2] = start_xy.to(self.device, torch.float32)
        seed = self.generator.seed_from_bodies(transl, orient, self.start_pose[start_index])
        count = len(start_index)
        goal = torch.cat([goal_xy.to(torch.float32), torch.zeros(count, 1, device=self.device)], dim=1)
        distance = (goal_xy - transl[:, :2]).norm(dim=-1)
        steps = torch.zeros(count, dtype=torch.long, device=self.device)
        mirrored = torch.zeros(count, dtype=torch.bool, device=self.device)
        if self.config.mirror_right_goals:  # the goal on the body's right: canonical x > 0
            first = seed.joints[:, -1]  # a one-frame seed: both slots hold its frame
            mirrored = to_canonical(goal[:, None], canonical_frame(first))[:, 0, 0] > 0
        return GammaReachState(seed, goal, steps, distance, torch.zeros(count, device=self.device), mirrored)

    def sample_initial_state(self, rngs: list[np.random.Generator], options: dict[str, Any] | None = None) -> GammaReachState:
        """One random start per generator (the single env has one; the vector env one per body).

        `options` may fix `goal` ((x, y)), `start_index` and `facing` for every body."""
        options = check_known(options, RESET_OPTIONS)
        given_row, given_facing = index(options, "start_index", self.num_starts), number(options, "facing")
        given_goal = point(options, "goal", 2)
        rows, facings, goals = [], [], []
        half = self.config.area / 2.0
        for rng in rngs:  # a few scalar draws per body at reset, so each body's episode follows its own seed
            rows.append(given_row if given_row is not None else int(rng.choice(self.start_rows)))
            facings.append(given_facing if given_facing is not None else float(rng.uniform(-math.pi, math.pi)))
            if given_goal is not None:
                goals.append(given_goal)
                continue
            goal = rng.uniform(-half, half, size=2)
            while np.linalg.norm(goal) < self.config.min_goal_distance:
                goal = rng.uniform(-half, half, size=2)
            goals.append(goal)
        return self.initial_state(torch.tensor(rows), torch.tensor(facings, dtype=torch.float32),
                                  torch.as_tensor(np.stack(goals), dtype=torch.float32))  # fmt: skip

    @property
    def body(self) -> BodyModel:
        return self.generator.body

    @property
    def goal_marker(self) -> tuple[str, float]:
        """How renders draw the goal: a ring of the success radius on the ground."""
        return "ring", self.config.goal_radius

    def render_inputs(self, state: GammaReachState) -> RenderInputs:
        """The bodies as they stand at the last frame of their latest primitive, with their goals."""
        seed = state.seed
        return RenderInputs(seed.transl[:, -1], seed.global_orient[:, -1], seed.body_pose[:, -1], seed.joints[:, -1, PELVIS], state.goal)

    def observe(self, state: GammaReachState) -> torch.Tensor:
        """(N, 804): per seed frame, canonical markers and unit marker-to-goal vectors (Eq. 3); with
        `mirror_right_goals`, the mirror image's for bodies whose goal is on their right."""
        seed = state.seed
        bodies = torch.arange(seed.num_bodies, device=self.device)
        first = seed.joints[bodies, 2 - seed.seed_frames]
        observation = goal_observation(seed.markers, first, state.goal)
        if state.mirrored.any():
            rows = torch.nonzero(state.mirrored).flatten()
            frame = canonical_frame(first[rows])
            goal = mirror_points(to_canonical(state.goal[rows, None], frame))
            observation[rows] = canonical_goal_observation(self.generator.mirrored_seed_markers(seed.index(rows), frame), goal)
        return observation

    def step(self, state: GammaReachState, z: torch.Tensor) -> tuple[GammaReachState, GammaStepResult]:
        """Generate one primitive per body from latents z (N, 128) and score it."""
        config, weights = self.config, self.config.reward
        z = z.to(self.device, torch.float32).clamp(-config.latent_bound, config.latent_bound)
        if config.latent_radius is not None:
            z = z * (config.latent_radius / z.norm(dim=-1, keepdim=True).clamp_min(config.latent_radius))
        primitive, next_seed = self.generator.step(state.seed, z, state.goal, ground_feet=config.ground_feet,
                                                    lock_feet=config.lock_feet, mirror=state.mirrored)
        joints, goal = primitive.joints, state.goal
        pelvis_start, pelvis_end = joints[:, 0, PELVIS], joints[:, -1, PELVIS]
        distance = (pelvis_end[:, :2] - goal[:, :2]).norm(dim=-1)
        closest = torch.minimum(state.closest, distance)
        reached = closest <= config.goal_radius
        forward_slowest = slowest_marker_speed(primitive.markers, GAMMA_FPS)  # the contact score's (Eq. 11)
        slowest = slowest_marker_speed(primitive.markers, GAMMA_FPS, central=True) if weights.central_difference else forward_slowest
        with torch.no_grad():
            latent_mean = self.generator.pose_latent(primitive.body_pose[:, 2:])  # frames new to every body
        terms = {
            "path": path_reward(pelvis_start, pelvis_end, goal),
            "orientation": orientation_reward(joints[:, -1], goal),
            "contact": contact_reward(pelvis_start[:, 2], pelvis_end[:, 2], slowest, weights.contact_speed_power),
            "pose_prior": pose_prior_reward(latent_mean, weights.pose_prior_power),
            "goal": goal_reward(closest, weights.goal_scale, config.goal_radius),
        }
        steps = state.steps + 1
        terminated = reached if config.terminate_on_goal else torch.zeros_like(reached)
        truncated = (steps >= config.max_primitives) & ~terminated
        reward = sum(getattr(weights, name) * value for name, value in terms.items())
        paid = state.goal_paid + terms["goal"]
        ended = terminated | truncated
        terms["goal_settlement"] = torch.where(ended, goal_settlement(steps, terms["goal"], paid), torch.zeros_like(paid))
        remaining = (config.max_primitives - steps).to(reward.dtype)
        terms["goal_absorbing"] = goal_absorbing_reward(terminated, remaining, weights.best_step_reward)
        new = primitive.new_frames()
        terms["stooping"] = -(head_drop(joints, config.upright_head) * new).sum(dim=1)
        slide = loaded_slide(primitive.reprojected_markers[:, :, SOLE_MARKERS], GAMMA_FPS)  # (N, 9) transitions
        terms["skating"] = -(slide * new[:, 1:]).sum(dim=1)
        reward = (reward + weights.goal * terms["goal_settlement"] + terms["goal_absorbing"]
                  + config.stooping * terms["stooping"] + config.skating * terms["skating"])  # fmt: skip
        result = GammaStepResult(reward, terms, distance, reached, terminated, truncated,
                                 contact_score(primitive.markers, GAMMA_FPS, forward_slowest), primitive)  # fmt: skip
        return GammaReachState(next_seed, goal, steps, closest, paid, state.mirrored), result


def _step_info(result: GammaStepResult, state: GammaReachState, index: int) -> dict[str, Any]:
    info: dict[str, Any] = {
        "reward_terms": {name: float(value[index]) for name, value in result.terms.items()},
        "distance": float(result.distance[index]),
        "closest_distance": float(state.closest[index]),
        "reached": bool(result.reached[index]),
        "contact_score": float(result.contact_score[index]),
        "primitives": int(state.steps[index]),
    }
    if result.terminated[index] or result.truncated[index]:
        info["is_success"] = bool(result.reached[index])
    return info


class GammaReachEnv(gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}
    """One rendered frame per primitive (the last of its 8 new frames at 40 fps): 5 frames per second."""

    def __init__(self, generator: GammaGenerator | None = None, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.config = config_from_kwargs(GammaReachConfig, kwargs, "GammaReach-v0")
        self.core = GammaReachCore(self.config, generator)
        bound = self.config.latent_bound
        self.action_space = gym.spaces.Box(-bound, bound, (self.core.generator.latent_size,), np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float32)
        self.state: GammaReachState | None = None
        self.last_primitive: Primitive | None = None
        self.trail: list[np.ndarray] = []
        self._view: EnvView | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.state = self.core.sample_initial_state([self.np_random], options)
        self.last_primitive = None
        self.trail = [self._pelvis()]
        info = {"distance": float(self.state.closest[0]), "goal": self.state.goal[0].cpu().numpy()}
        return self._observation(), info

    def step(self, action: np.ndarray):
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        z = check_actions(action, self.action_space.shape, batch=None)
        self.state, result = self.core.step(self.state, torch.as_tensor(z)[None])
        self.last_primitive = result.primitive
        self.trail.append(self._pelvis())
        return (self._observation(), float(result.reward[0]), bool(result.terminated[0]), bool(result.truncated[0]),
                _step_info(result, self.state, 0))  # fmt: skip

    def render(self) -> np.ndarray | None:
        """rgb_array: the body now (last frame), its goal and pelvis trail, from a camera that follows it."""
        if self.render_mode is None or self.state is None:
            return None
        if self._view is None:
            self._view = EnvView(self.core.body, *self.core.goal_marker, max_bodies=1)
        return self._view.frame(self.core.render_inputs(self.state), [np.array(self.trail)])

    def _pelvis(self) -> np.ndarray:
        return self.state.seed.joints[0, -1, PELVIS].cpu().numpy()

    def _observation(self) -> np.ndarray:
        return self.core.observe(self.state)[0].cpu().numpy().astype(np.float32)


class GammaReachVectorEnv(CoreVectorEnv):
    """N bodies in one batched core; same-step autoreset (see `CoreVectorEnv`)."""

    def __init__(self, num_envs: int = 1, generator: GammaGenerator | None = None, render_mode: str | None = None,
                 render_bodies: int = 8, autoreset_mode: str = "same_step", **kwargs: Any) -> None:  # fmt: skip
        self.config = config_from_kwargs(GammaReachConfig, kwargs, "GammaReach-v0")
        core = GammaReachCore(self.config, generator)
        bound = self.config.latent_bound
        super().__init__(core, num_envs, gym.spaces.Box(-bound, bound, (core.generator.latent_size,), np.float32),
                         gym.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float32), render_mode, render_bodies, autoreset_mode)  # fmt: skip
        self.last_primitive: Primitive | None = None

    def _step_info(self, result: GammaStepResult) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        self.last_primitive = result.primitive
        info: dict[str, Any] = {name: value.cpu().numpy() for name, value in
                                (("distance", result.distance), ("reached", result.reached),
                                 ("contact_score", result.contact_score))}  # fmt: skip
        info["reward_terms"] = {name: value.cpu().numpy() for name, value in result.terms.items()}
        done = (result.terminated | result.truncated).cpu().numpy()
        return info, {"is_success": result.reached.cpu().numpy() & done}
