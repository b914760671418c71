"""WandrReach-v0: walk and put the right wrist on a 3-D goal by choosing WANDR's latent codes.

## Description

WANDR (Diomataris et al., CVPR 2024) generates human motion one frame at a
time (30 fps) from a latent z ∈ R^64, conditioned on the body's state and
its *intention* towards a goal (`motion_envs.priors.wandr_features`). Here a
body starts in a pose from the validation data and a goal for its right
wrist floats somewhere around it; every step the agent picks z and the prior
generates the next `frames_per_step` frames with it. After every frame the
body is moved vertically so that its lowest foot vertex touches the floor
(`ground_feet`, see `WandrStepper`: our small-data prior's height drifts),
and a foot that bore the weight in the previous frame is held where it stood
(`lock_feet`: the legs refitted, `motion_envs.body.foot_lock`).

## Action Space

`Box(-4, 4, (64,), float32)`: the prior's latent z, unscaled (the prior is
N(0, I), so z ~ N(0, I) is WANDR's own sampler and the box holds all but
6e-5 of its mass per coordinate). Actions outside the box are clipped to
it; a wrong shape or a NaN/inf raises `ValueError`.

## Observation Space

`Box(-inf, inf, (281,), float32)`:

| slice | size | what |
|---|---|---|
| 0:133 | 133 | pose: pelvis height, pelvis rotation without heading (6-D), 21 local joint rotations (6-D) |
| 133:268 | 135 | the previous frame's delta (translation in the heading frame, rotation steps as 6-D) |
| 268:277 | 9 | intention: wrist velocity needed (3), saturated pelvis-to-goal (3), heading change to the goal (3) |
| 277:280 | 3 | the goal relative to the pelvis, in the heading frame (m) |
| 280 | 1 | frames left until the goal's deadline / `max_frames` |

The first 277 are the prior's condition, z-scored with the prior's own
training statistics (so they are O(1)); the last four are raw.

## Rewards

`WandrRewardConfig` (`motion_envs.rewards`), every term per step in
`info["reward_terms"]`: `progress` (metres the wrist came closer, × 10),
`success` (10 on reaching), `skating` (−0.1 per frame whose lowest foot
vertex slides more than WANDR's 0.66 cm FS threshold), `speeding`
(−1 per frame and m/s by which the pelvis moves over the ground faster than
2.1 m/s, the data's fastest walk: ours, against running to far goals),
`lying` (per frame and metre by which the pelvis is lower than 0.3 m;
weight 0 by default: ours, against folding flat to reach the floor),
`latent` (−0.01 · mean z²).

## Starting State

A start window from the validation data (`motion_envs/assets/start_poses.npz`,
30 fps; its last two frames give the pose and the delta into it), the
pelvis over the origin, facing a uniformly random direction, the lowest foot
point on the ground. The goal is drawn in cylindrical coordinates around the
body (as the paper's evaluation): angle from the body's forward in
`goal_angle`, height in `goal_height`, ground distance from the pelvis in
`goal_distance`.

## Episode End

Success: the right wrist within `success_radius` (10 cm) of the (last)
goal; the episode terminates there when `terminate_on_success`. Truncation
after `max_frames` frames (240 = 8 s).

## Arguments

`gym.make("motion_envs/WandrReach-v0", **kwargs)` with any field of
`WandrReachConfig`; `reward` may be a `WandrRewardConfig` or a spec such as
"default:success=5". `reset(options=...)` takes:

* `goal`: (x, y, z) world goal; `goal_time`: frames until it is due (the
  wrist intention's t_G; default: the episode's end). After the deadline the
  prior is told one frame is left.
* `goals`: a list of (x, y, z) reached in turn (each new goal is due
  `goal_time` frames after the previous one is reached, default the
  episode's end); success is reaching the last.
* `goal_velocity`: (vx, vy, vz) m/s, a moving goal.
* `start_index`, `facing` (radians).

## Batched core and state

`WandrReachCore` steps N bodies at once (the single env is N = 1, the
vector env N = num_envs); the state is one `WandrReachState`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from motion_envs.allocator import keep_freed_memory
from motion_envs.batched import where_bodies
from motion_envs.body import BodyModel
from motion_envs.body.rotations import matrix_to_sixd
from motion_envs.envs.core import CoreVectorEnv, check_actions, config_from_kwargs
from motion_envs.envs.options import check_known, index, number, point
from motion_envs.envs.starts import DeltaPriorBodies, StartBodies
from motion_envs.metrics import lowest_foot, track_skating
from motion_envs.priors.train_wandr import load_wandr
from motion_envs.priors.wandr import WandrPrior, WandrStepper
from motion_envs.priors.wandr_features import FPS, PELVIS, RIGHT_WRIST, WandrState, heading
from motion_envs.render.env_view import EnvView, RenderInputs
from motion_envs.rewards import WandrRewardConfig, latent_cost, overspeed, pelvis_drop, wrist_progress

OBSERVATION_SIZE = 281
RESET_OPTIONS = ("goal", "goal_time", "goals", "goal_velocity", "start_index", "facing")


@dataclasses.dataclass(frozen=True)
class WandrReachConfig:
    """Everything that defines a WandrReach task (goal ranges: the paper's evaluation)."""

    reward: WandrRewardConfig = dataclasses.field(default_factory=WandrRewardConfig)
    frames_per_step: int = 1
    max_frames: int = 240
    success_radius: float = 0.10
    goal_angle: tuple[float, float] = (-math.pi, math.pi)
    """Radians from the body's forward, counter-clockwise (left) positive."""
    goal_height: tuple[float, float] = (0.0, 1.8)
    goal_distance: tuple[float, float] = (0.5, 5.0)
    latent_bound: float = 4.0
    terminate_on_success: bool = True
    ground_feet: bool = True
    """Keep the lowest foot vertex on the floor after every frame (`WandrStepper`); off: the prior alone."""
    lock_feet: bool = True
    """The foot rule: every frame is shown with a loaded foot held where it stood (`WandrStepper`,
    `WandrState.shown_pose`); the prior goes on from its own pose, so success is the same with and without it.
    On the 3,750-rollout grid (`bench wandr`) it takes WANDR's FS of the PPO policy's mean latent from 55.6% to
    34.4% (SR 90.3% either way), of the 8-s sampler from 66.5% to 32.3%. (Fed back to the prior, the held legs
    folded a 15-s walk: head over the last second 0.69 m against 1.12 m.) False: the prior's own legs."""
    weights: str | None = None
    """WANDR prior weights (default: the shipped priors/weights/wandr.pt)."""
    device: str = "cpu"

    def __post_init__(self) -> None:
        if isinstance(self.reward, str):
            object.__setattr__(self, "reward", WandrRewardConfig.named(self.reward))
        if self.frames_per_step < 1 or self.max_frames < self.frames_per_step:
            raise ValueError(f"need 1 <= frames_per_step <= max_frames, got {self.frames_per_step}, {self.max_frames}")
        if self.success_radius <= 0 or self.latent_bound <= 0:
            raise ValueError("success_radius and latent_bound must be positive")
        for name in ("goal_angle", "goal_height", "goal_distance"):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f"{name} must be (low, high) with low <= high, got {(low, high)}")

    @property
    def max_steps(self) -> int:
        return math.ceil(self.max_frames / self.frames_per_step)


@dataclasses.dataclass(frozen=True)
class WandrReachState(DeltaPriorBodies):
    """N bodies' simulation state.

    body: the prior's state (pose, previous delta, joints) as tensors; goals: (N, G, 3) the goal list
    (one row for a single goal); goal_index / goal_count: (N,) the current goal and how many;
    goal_velocity: (N, 3) m/s; goal_time: (N,) frames each new goal gets (-1: until the episode's end);
    deadline: (N,) frame the current goal is due; frame: (N,) frames so far; distance / closest: (N,)
    wrist-to-goal now and closest so far (m); lowest_id, lowest_xy: (N,), (N, 2) the lowest foot vertex
    and where it was; skated: (N,) skating frames so far; reached: (N,) bool, the last goal reached.
    """

    goals: torch.Tensor
    goal_index: torch.Tensor
    goal_count: torch.Tensor
    goal_velocity: torch.Tensor
    goal_time: torch.Tensor
    deadline: torch.Tensor
    frame: torch.Tensor
    distance: torch.Tensor
    closest: torch.Tensor
    lowest_id: torch.Tensor
    lowest_xy: torch.Tensor
    skated: torch.Tensor
    reached: torch.Tensor

    @property
    def goal(self) -> torch.Tensor:
        """(N, 3) the current goal."""
        return self.goals[torch.arange(len(self.goals), device=self.goals.device), self.goal_index]

    @property
    def frames_left(self) -> torch.Tensor:
        """(N,) frames until the current goal is due, at least 1 (what the prior is told)."""
        return (self.deadline - self.frame).clamp_min(1)


@dataclasses.dataclass(frozen=True)
class WandrStepResult:
    """What one step of N bodies produced; every tensor (N,)."""

    reward: torch.Tensor
    terms: dict[str, torch.Tensor]
    terminated: torch.Tensor
    truncated: torch.Tensor


class WandrReachCore:
    """The batched task: start states, one step for N bodies, observations. Stateless: states go in and out."""

    def __init__(self, config: WandrReachConfig, prior: WandrPrior | None = None) -> None:
        keep_freed_memory()  # large step tensors reused, not page-faulted anew (`motion_envs.allocator`)
        self.config = config
        self.device = torch.device(config.device)
        self.prior = (prior or load_wandr(config.weights)).to(self.device).eval()
        self.body = BodyModel().to(self.device)
        self.stepper = WandrStepper(self.prior, self.body, config.ground_feet, lock_feet=config.lock_feet)
        self.starts = StartBodies(self.stepper, self.device)

    @property
    def num_starts(self) -> int:
        return len(self.starts)

    def initial_state(self, start_index: torch.Tensor, facing: torch.Tensor, goals: torch.Tensor,
                      goal_count: torch.Tensor | None = None, goal_time: torch.Tensor | None = None,
                      goal_velocity: torch.Tensor | None = None) -> WandrReachState:  # fmt: skip
        """Bodies from start rows (N,) turned to `facing` (N,) radians, pelvis over the origin.

        goals: (N, G, 3) world goals (the first G' = goal_count of them used, in order);
        goal_time: (N,) frames each goal gets (-1 / None: until the episode's end); goal_velocity: (N, 3) m/s.
        """
        goals = goals.to(self.device, torch.float32)
        count = len(start_index)
        body, feet = self.starts.place(start_index, facing)
        lowest_id, lowest_xy = lowest_foot(feet)
        goal_count = torch.ones(count, dtype=torch.long, device=self.device) if goal_count is None else goal_count.to(self.device)
        goal_time = torch.full((count,), -1, dtype=torch.long, device=self.device) if goal_time is None else goal_time.to(self.device)
        velocity = torch.zeros(count, 3, device=self.device) if goal_velocity is None else goal_velocity.to(self.device, torch.float32)
        zeros = torch.zeros(count, dtype=torch.long, device=self.device)
        distance = (body.joints[:, RIGHT_WRIST] - goals[:, 0]).norm(dim=-1)
        return WandrReachState(
            *body, goals, zeros, goal_count, velocity, goal_time, self._deadline(zeros, goal_time), zeros, distance, distance,
            lowest_id, lowest_xy, zeros, (distance <= self.config.success_radius) & (goal_count == 1),
        )  # fmt: skip

    def _deadline(self, frame: torch.Tensor, goal_time: torch.Tensor) -> torch.Tensor:
        return torch.where(goal_time >= 0, frame + goal_time, torch.full_like(frame, self.config.max_frames))

    def cylinder_goals(self, start_index: torch.Tensor, facing: torch.Tensor, angle: torch.Tensor, height: torch.Tensor,
                       distance: torch.Tensor) -> torch.Tensor:  # fmt: skip
        """(N, 3) goals at `angle` from the body's forward (N,), `height` (N,), ground `distance` (N,) from
        the pelvis, for bodies placed by `initial_state(start_index, facing, ...)` (pelvis over the origin)."""
        forward = self.starts.forward(start_index, facing)
        forward = forward / forward.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        cosine, sine = torch.cos(angle.to(self.device)), torch.sin(angle.to(self.device))
        direction = torch.stack([cosine * forward[:, 0] - sine * forward[:, 1], sine * forward[:, 0] + cosine * forward[:, 1]], -1)
        ground = direction * distance.to(self.device)[:, None]
        return torch.cat([ground, height.to(self.device)[:, None]], dim=1)

    def sample_initial_state(self, rngs: list[np.random.Generator], options: dict[str, Any] | None = None) -> WandrReachState:
        """One random start per generator; `options` (see the module doc) apply to every body."""
        options = check_known(options, RESET_OPTIONS)
        if "goal" in options and "goals" in options:
            raise ValueError("give either 'goal' or 'goals', not both")
        config = self.config
        given_row, given_facing = index(options, "start_index", self.num_starts), number(options, "facing")
        rows = [given_row if given_row is not None else int(rng.integers(self.num_starts)) for rng in rngs]
        facings = [given_facing if given_facing is not None else float(rng.uniform(-math.pi, math.pi)) for rng in rngs]
        draws = np.array([[rng.uniform(*config.goal_angle), rng.uniform(*config.goal_height), rng.uniform(*config.goal_distance)]
                          for rng in rngs])  # fmt: skip
        start_index, facing = torch.tensor(rows), torch.tensor(facings, dtype=torch.float32)
        count = len(rngs)
        given = point(options, "goals", 3, many=True) if "goals" in options else point(options, "goal", 3)
        if given is not None:
            goals = torch.as_tensor(given.reshape(-1, 3), dtype=torch.float32).expand(count, -1, -1)
        else:
            goals = self.cylinder_goals(start_index, facing, *torch.as_tensor(draws.T, dtype=torch.float32))[:, None]
        due = index(options, "goal_time", np.iinfo(np.int64).max, low=1)
        goal_time = torch.full((count,), -1 if due is None else due, dtype=torch.long)
        velocity = point(options, "goal_velocity", 3)
        velocity = torch.zeros(1, 3) if velocity is None else torch.as_tensor(velocity, dtype=torch.float32).reshape(1, 3)
        return self.initial_state(start_index, facing, goals, torch.full((count,), goals.shape[1]), goal_time,
                                  velocity.expand(count, 3))  # fmt: skip

    @property
    def goal_marker(self) -> tuple[str, float]:
        """How renders draw the goal: a sphere of the success radius (with its ring on the ground below)."""
        return "sphere", self.config.success_radius

    def render_inputs(self, state: WandrReachState) -> RenderInputs:
        """The bodies now (rotations as 6-D), with their current goals."""
        return RenderInputs(state.transl, matrix_to_sixd(state.orient), matrix_to_sixd(state.shown_pose), state.joints[:, PELVIS], state.goal)

    def observe(self, state: WandrReachState) -> torch.Tensor:
        """(N, 281): the normalised condition, the goal in the heading frame, frames left / max_frames."""
        with torch.no_grad():
            condition = self.stepper.condition(state.body, state.goal, state.frames_left)
        to_goal = ((state.goal - state.transl)[:, None] @ heading(state.orient)).squeeze(1)
        left = ((state.deadline - state.frame).clamp_min(0).float() / self.config.max_frames)[:, None]
        return torch.cat([condition, to_goal, left], dim=1)

    @torch.no_grad()
    def step(self, state: WandrReachState, z: torch.Tensor) -> tuple[WandrReachState, WandrStepResult]:
        """`frames_per_step` frames per body from latents z (N, 64), scored."""
        config, scales = self.config, self.config.reward
        z = z.to(self.device, torch.float32).clamp(-config.latent_bound, config.latent_bound)
        terms = {name: torch.zeros(state.num_bodies, device=self.device) for name in ("progress", "success", "skating", "speeding", "lying")}
        rows = torch.arange(state.num_bodies, device=self.device)
        for _ in range(config.frames_per_step):  # WANDR is autoregressive: frame by frame
            active = ~state.reached if config.terminate_on_success else torch.ones_like(state.reached)
            body, feet = self.stepper.step(state.body, z, state.goal, state.frames_left)
            frame = state.frame + 1
            goals = state.goals.clone()
            goals[rows, state.goal_index] += state.goal_velocity / FPS
            distance = (body.joints[:, RIGHT_WRIST] - goals[rows, state.goal_index]).norm(dim=-1)
            skated, lowest_id, lowest_xy = track_skating(feet, state.lowest_id, state.lowest_xy, active)
            arrived = (distance <= config.success_radius) & active
            last = state.goal_index >= state.goal_count - 1
            advance = arrived & ~last
            goal_index = state.goal_index + advance.long()
            terms["progress"] += torch.where(active, wrist_progress(state.distance, distance), torch.zeros_like(distance))
            terms["success"] += (arrived & last).float()
            terms["skating"] += skated.float()
            speeding = overspeed(state.joints[:, PELVIS], body.joints[:, PELVIS], FPS, scales.walk_speed)
            terms["speeding"] += torch.where(active, speeding, torch.zeros_like(speeding))
            lying = pelvis_drop(body.joints[:, PELVIS], scales.pelvis_floor)
            terms["lying"] += torch.where(active, lying, torch.zeros_like(lying))
            distance_now = (body.joints[:, RIGHT_WRIST] - goals[rows, goal_index]).norm(dim=-1)
            moved = WandrState(*(where_bodies(active, new, old) for new, old in zip(body, state.body)))  # done bodies stay
            state = dataclasses.replace(
                state, **moved._asdict(), goals=goals, goal_index=goal_index,
                deadline=torch.where(advance, self._deadline(frame, state.goal_time), state.deadline),
                frame=where_bodies(active, frame, state.frame),
                distance=where_bodies(active, distance_now, state.distance),
                closest=torch.where(advance, distance_now, where_bodies(active, torch.minimum(state.closest, distance_now), state.closest)),
                lowest_id=lowest_id, lowest_xy=lowest_xy,
                skated=state.skated + skated.long(), reached=state.reached | (arrived & last),
            )  # fmt: skip
        terms["latent"] = latent_cost(z)
        reward = (scales.progress * terms["progress"] + scales.success * terms["success"]
                  - scales.skating * terms["skating"] - scales.speeding * terms["speeding"]
                  - scales.lying * terms["lying"] - scales.latent * terms["latent"])  # fmt: skip
        terminated = state.reached if config.terminate_on_success else torch.zeros_like(state.reached)
        truncated = (state.frame >= config.max_frames) & ~terminated
        return state, WandrStepResult(reward, terms, terminated, truncated)


def _step_info(state: WandrReachState, result: WandrStepResult, index: int) -> dict[str, Any]:
    frames = int(state.frame[index])
    info: dict[str, Any] = {
        "reward_terms": {name: float(value[index]) for name, value in result.terms.items()},
        "distance": float(state.distance[index]),
        "closest_distance": float(state.closest[index]),
        "frames": frames,
        "goal_index": int(state.goal_index[index]),
        "foot_skating": float(state.skated[index]) / max(frames, 1),
    }
    if result.terminated[index] or result.truncated[index]:
        info["is_success"] = bool(state.reached[index])
    return info


def _spaces(core: WandrReachCore) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    bound = core.config.latent_bound
    return (gym.spaces.Box(-bound, bound, (core.prior.config.latent,), np.float32),
            gym.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float32))  # fmt: skip


class WandrReachEnv(gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array"], "render_fps": FPS}

    def __init__(self, prior: WandrPrior | None = None, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.config = config_from_kwargs(WandrReachConfig, kwargs, "WandrReach-v0")
        self.core = WandrReachCore(self.config, prior)
        self.metadata = {**self.metadata, "render_fps": FPS / self.config.frames_per_step}
        self.action_space, self.observation_space = _spaces(self.core)
        self.state: WandrReachState | None = None
        self.trail: list[np.ndarray] = []
        self._view: EnvView | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.state = self.core.sample_initial_state([self.np_random], options)
        self.trail = [self._pelvis()]
        return self._observation(), {"distance": float(self.state.distance[0]), "goal": self.state.goal[0].cpu().numpy()}

    def step(self, action: np.ndarray):
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        z = check_actions(action, self.action_space.shape, batch=None)
        self.state, result = self.core.step(self.state, torch.as_tensor(z)[None])
        self.trail.append(self._pelvis())
        return (self._observation(), float(result.reward[0]), bool(result.terminated[0]), bool(result.truncated[0]),
                _step_info(self.state, result, 0))  # fmt: skip

    def render(self) -> np.ndarray | None:
        """rgb_array: the body now, the goal (a sphere of the success radius) and the pelvis trail."""
        if self.render_mode is None or self.state is None:
            return None
        if self._view is None:
            self._view = EnvView(self.core.body, *self.core.goal_marker, max_bodies=1)
        return self._view.frame(self.core.render_inputs(self.state), [np.array(self.trail)])

    def _pelvis(self) -> np.ndarray:
        return self.state.joints[0, PELVIS].cpu().numpy()

    def _observation(self) -> np.ndarray:
        return self.core.observe(self.state)[0].cpu().numpy().astype(np.float32)


class WandrReachVectorEnv(CoreVectorEnv):
    """N bodies in one batched core; same-step autoreset (see `CoreVectorEnv`)."""

    def __init__(self, num_envs: int = 1, prior: WandrPrior | None = None, render_mode: str | None = None,
                 render_bodies: int = 8, autoreset_mode: str = "same_step", **kwargs: Any) -> None:  # fmt: skip
        self.config = config_from_kwargs(WandrReachConfig, kwargs, "WandrReach-v0")
        core = WandrReachCore(self.config, prior)
        super().__init__(core, num_envs, *_spaces(core), render_mode, render_bodies, autoreset_mode)
        self.metadata = {**self.metadata, "render_fps": FPS / self.config.frames_per_step}

    def _step_info(self, result: WandrStepResult) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        state = self.state
        info = {"distance": state.distance.cpu().numpy(), "closest_distance": state.closest.cpu().numpy(),
                "reward_terms": {name: value.cpu().numpy() for name, value in result.terms.items()}}  # fmt: skip
        done = (result.terminated | result.truncated).cpu().numpy()
        skating = (state.skated.float() / state.frame.clamp_min(1).float()).cpu().numpy()
        return info, {"is_success": state.reached.cpu().numpy() & done, "foot_skating": skating}
