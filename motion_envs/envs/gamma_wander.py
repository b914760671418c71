"""GammaWander-v0: walk a GAMMA body along waypoints, through a furnished room or over open ground.

## Description

GAMMA's title task ("The Wanderings of Odysseus in 3D Scenes"): a body
follows a path of waypoints, as the authors' release does with a path
planner's waypoints (REFERENCE_NOTES §1.8). Each episode places a body in a
room of `scene`'s layout family (`motion_envs.scenes.layouts`), plans a path
between two walkable places (`motion_envs.scenes.paths`: A* with clearance,
waypoints at most `waypoint_spacing` m apart) and asks the body to walk it.
`scene="flat"` gives DART-style waypoint paths on open ground instead:
`flat_legs` legs of `flat_leg_length` m, each turning up to `flat_turn`.

A new id rather than GammaReach options: the state gains waypoints, a scene
and collisions, and the episode ends on different radii; GammaReach stays the
paper's Table 1 task. The motion, action and observation are GammaReach's
(`GammaReachCore` does the stepping), so every GammaReach policy drives this
env unchanged: it sees the current waypoint as its goal, the paper's way.

## Action Space

`Box(-4, 4, (128,), float32)`: GammaReach's latent z.

## Observation Space

`Box(-inf, inf, (804,), float32)`: GammaReach's (Eq. 3) with the current waypoint as the goal.

## Rewards

GammaReach's terms (`motion_envs.rewards`, weights from `reward`) towards the current waypoint, minus
`collision_penalty` for a primitive in which a body sphere enters the scene more than `collision_tolerance`,
and `clearance_penalty` per metre that its deepest sphere comes inside `clearance_margin` of the scene, and
`speeding` per frame and m/s that the pelvis moves faster than `walk_speed` over the ground, `stooping` per
frame and metre that the head is lower than `upright_head`, and `skating` per frame and m/s that the loaded heel
or toe slides on the floor (GammaReach's; all 0 by default:
collisions are reported in `info`, not paid; the shipped policy's recipe sets them). When a waypoint is
passed the goal term's closest distance restarts from the next one. Arriving at the last waypoint also earns the remaining
primitives at the best per-step reward (GammaReach's `goal_absorbing`), so that ending early never pays less
than walking on.

## Starting State

A GammaReach start pose over the path's start, facing a uniformly random direction. Rooms: start and goal
uniform over the walkable region, at least `min_goal_distance` apart (`Scene.sample_start_goal`).

## Episode End

An intermediate waypoint is passed when the pelvis (last frame of a primitive) comes within
`waypoint_radius` (0.75 m, the release's) of it; the episode succeeds (terminated) when the pelvis comes
within `goal_radius` (0.3 m, DART's) of the last waypoint after the others. Truncation after `max_primitives`.

## Arguments

`gym.make("motion_envs/GammaWander-v0", **kwargs)` with any field of `GammaWanderConfig`.
`reset(options=...)` takes `scene_seed` (one seed, or one per body), `start` ((x, y)), `goal` ((x, y): a path is planned to it),
`waypoints` (K × (x, y), used as given; the last is the goal), `facing` (radians) and `start_index`.

## Info

`distance` (m left along the path: to the current waypoint, then waypoint to waypoint), `waypoint`
(index of the current one), `waypoints`, `collided` (this primitive), `penetration` (deepest sphere, m),
`collisions` (primitives that collided so far), `contact_score`, `reached`; `is_success` at the end.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from motion_envs.allocator import keep_freed_memory
from motion_envs.batched import BatchedState
from motion_envs.body.canonical_frame import PELVIS
from motion_envs.body.collision_spheres import spheres_of_joints
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.envs.core import CoreVectorEnv, check_actions, config_from_kwargs
from motion_envs.envs.gamma_reach import OBSERVATION_SIZE, GammaReachConfig, GammaReachCore, GammaReachState
from motion_envs.envs.options import check_known, index, number, point, scene_seed_option
from motion_envs.precision import PRECISIONS
from motion_envs.priors.gamma_generator import GammaGenerator, GammaSeed, Primitive
from motion_envs.render.env_view import RenderInputs
from motion_envs.rewards import DATA_WALK_SPEED, UPRIGHT_HEAD, RewardConfig, goal_absorbing_reward, overspeed
from motion_envs.scenes.layouts import FAMILIES, TRAIN_SEEDS, families_of, make_scene, seeds_of
from motion_envs.scenes.paths import cell_costs, plan_path, split_legs
from motion_envs.scenes.scene import Scene

FLAT, MIXED = "flat", "mixed"
MAX_WAYPOINTS = 64
"""Waypoints a path may have (padded to this in the state, so that bodies batch)."""
RESET_OPTIONS = ("scene_seed", "start", "goal", "waypoints", "facing", "start_index")
PERSONAL_SPACE = 0.6
"""Pelvis-to-pelvis distance (m) under which two bodies crowd each other (`GammaWanderStepResult.crowding`)."""


@dataclasses.dataclass(frozen=True)
class GammaWanderConfig:
    """Everything that defines a GammaWander task (radii: the release's 0.75 m and DART's 0.3 m)."""

    scene: str = "living"
    """A layout family (`FAMILIES`), "mixed" (every episode draws a family), or "flat" (open ground, random paths)."""
    split: str = "train"
    """'train': the first `train_scenes` training seeds; 'test': the held-out seeds."""
    train_scenes: int = 64
    scene_seeds: tuple[int, ...] | None = None
    """Explicit room seeds (overrides `split`)."""
    waypoint_spacing: float = 1.5
    waypoint_radius: float = 0.75
    goal_radius: float = 0.3
    min_goal_distance: float = 3.0
    flat_legs: tuple[int, int] = (4, 5)
    flat_leg_length: tuple[float, float] = (2.0, 4.0)
    flat_turn: float = math.pi
    """Largest turn (radians) between two legs of a flat path."""
    max_primitives: int = 160
    collision_tolerance: float = 0.02
    """Penetration (m) below which a sphere does not count as colliding (the grid has 5 cm voxels)."""
    collision_penalty: float = 0.0
    clearance_penalty: float = 0.0
    """Per metre that the deepest body sphere of a primitive comes inside `clearance_margin` of the scene (ours; 0: off).
    Dense where `collision_penalty` is a flat toll: a body 14 cm inside a sofa pays more than one grazing it, and
    one that brushes past within the margin pays a little before it collides."""
    clearance_margin: float = 0.1
    speeding: float = 0.0
    """Per frame and m/s that the pelvis moves over the ground faster than `walk_speed` (ours, as WandrReach's; 0:
    off). GAMMA's reward pays arriving early (`goal_absorbing`) and, with the scene penalties, every primitive
    spent in a room costs: without this term fine-tuned policies run through living rooms (measured: 32% of
    primitives above 2.1 m/s, a 90th percentile of 2.7 m/s)."""
    walk_speed: float = DATA_WALK_SPEED
    stooping: float = 0.0
    """Per frame and metre that the head is lower than `upright_head`: `GammaReachConfig.stooping` (0: off)."""
    upright_head: float = UPRIGHT_HEAD
    skating: float = 0.0
    """Per frame and m/s that the loaded heel or toe slides on the floor: `GammaReachConfig.skating` (0: off)."""
    heading_calibration: bool = False
    """The prior's heading calibration: `GammaReachConfig.heading_calibration` (off: the shipped policies')."""
    reward: RewardConfig = dataclasses.field(default_factory=RewardConfig.paper)
    start_kind: str = "any"
    latent_bound: float = 4.0
    weights_dir: str | None = None
    device: str = "cpu"
    ground_feet: bool = True
    lock_feet: bool = True
    precision: str = "auto"

    def __post_init__(self) -> None:
        if isinstance(self.reward, str):
            object.__setattr__(self, "reward", RewardConfig.named(self.reward))
        if self.scene not in (*FAMILIES, MIXED, FLAT):
            raise ValueError(f"unknown scene {self.scene!r}; choose from {(*FAMILIES, MIXED, FLAT)}")
        if self.split not in ("train", "test"):
            raise ValueError(f"split must be 'train' or 'test', got {self.split!r}")
        if not 1 <= self.train_scenes <= len(TRAIN_SEEDS):
            raise ValueError(f"train_scenes must lie in [1, {len(TRAIN_SEEDS)}], got {self.train_scenes}")
        if self.scene_seeds is not None and len(self.scene_seeds) == 0:
            raise ValueError("scene_seeds must name at least one seed")
        penalties = {"collision_penalty": self.collision_penalty, "clearance_penalty": self.clearance_penalty,
                     "clearance_margin": self.clearance_margin, "speeding": self.speeding, "stooping": self.stooping,
                     "upright_head": self.upright_head, "skating": self.skating}  # fmt: skip
        negative = {name: value for name, value in penalties.items() if value < 0}
        if negative:
            raise ValueError(f"{', '.join(negative)} must be >= 0, got {negative}")
        if self.walk_speed <= 0:
            raise ValueError(f"walk_speed must be positive, got {self.walk_speed}")
        if min(self.waypoint_spacing, self.waypoint_radius, self.goal_radius, self.max_primitives) <= 0:
            raise ValueError("waypoint_spacing, waypoint_radius, goal_radius and max_primitives must be positive")
        if not 1 <= self.flat_legs[0] <= self.flat_legs[1] or not 0 < self.flat_leg_length[0] <= self.flat_leg_length[1]:
            raise ValueError(f"flat_legs and flat_leg_length must be (low, high) with 0 < low <= high, got "
                             f"{self.flat_legs}, {self.flat_leg_length}")  # fmt: skip
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {self.precision!r}")

    @property
    def families(self) -> tuple[str, ...]:
        """The layout families episodes are drawn from."""
        return families_of(self.scene)

    @property
    def seeds(self) -> tuple[int, ...]:
        return seeds_of(self.split, self.train_scenes, self.scene_seeds)

    def reach_config(self) -> GammaReachConfig:
        """The GammaReach task that steps the bodies: the waypoint radius for its goal reward, no ending of its own."""
        return GammaReachConfig(reward=self.reward, goal_radius=self.waypoint_radius, max_primitives=2**62,
                                start_kind=self.start_kind, latent_bound=self.latent_bound, terminate_on_goal=False,
                                weights_dir=self.weights_dir, device=self.device, ground_feet=self.ground_feet,
                                lock_feet=self.lock_feet, precision=self.precision, stooping=self.stooping,
                                heading_calibration=self.heading_calibration,
                                upright_head=self.upright_head, skating=self.skating)  # fmt: skip


@dataclasses.dataclass(frozen=True)
class GammaWanderState(BatchedState):
    """N bodies: reach: the GammaReach state (its goal is the current waypoint, on the ground).
    waypoints: (N, MAX_WAYPOINTS, 2), padded with the last one. count: (N,) waypoints in the path. current: (N,)
    index of the current one. scene: (N,) index into the core's scenes (-1: open ground). neighbours: (N, M, 2)
    other bodies' pelvis positions to keep clear of (M = 0 unless a crowd sets them). collisions: (N,)
    primitives that collided so far."""

    reach: GammaReachState
    waypoints: torch.Tensor
    count: torch.Tensor
    current: torch.Tensor
    scene: torch.Tensor
    neighbours: torch.Tensor
    collisions: torch.Tensor

    @property
    def goal(self) -> torch.Tensor:
        """(N, 3) the current waypoint on the ground."""
        return self.reach.goal

    @property
    def steps(self) -> torch.Tensor:
        return self.reach.steps

    @property
    def seed(self) -> GammaSeed:
        """The GAMMA seed (the last frames so far), as a GammaReach state has it."""
        return self.reach.seed

    @property
    def pelvis(self) -> torch.Tensor:
        """(N, 3) the pelvis at the last frame so far."""
        return self.reach.seed.joints[:, -1, PELVIS]

    def distance_left(self, pelvis_xy: torch.Tensor) -> torch.Tensor:
        """(N,) metres from `pelvis_xy` (N, 2) to the current waypoint, then along the rest of the path."""
        return distance_along_path(self.waypoints, self.current, pelvis_xy)


@dataclasses.dataclass(frozen=True)
class GammaWanderStepResult:
    """One step of N bodies; every tensor (N,). distance: metres left along the path. reached: the last waypoint
    reached. clearance: the least signed distance (m) of a body sphere's surface to the scene over the primitive's
    frames (negative inside; +inf on open ground); penetration: the deepest sphere, max(-clearance, 0); collided:
    deeper than the tolerance. crowding: how far (m) the pelvis came inside `PERSONAL_SPACE` of a neighbour."""

    reward: torch.Tensor
    terms: dict[str, torch.Tensor]
    distance: torch.Tensor
    waypoint_distance: torch.Tensor
    reached: torch.Tensor
    terminated: torch.Tensor
    truncated: torch.Tensor
    clearance: torch.Tensor
    collided: torch.Tensor
    crowding: torch.Tensor
    contact_score: torch.Tensor
    primitive: Primitive

    @property
    def penetration(self) -> torch.Tensor:
        """(N,) the deepest body sphere inside the scene (m, 0 when clear)."""
        return (-self.clearance).clamp(min=0.0)


class GammaWanderCore:
    """The batched task over `GammaReachCore`: paths, waypoint switching, scene collisions. Stateless."""

    def __init__(self, config: GammaWanderConfig, generator: GammaGenerator | None = None) -> None:
        keep_freed_memory()  # large step tensors reused, not page-faulted anew (`motion_envs.allocator`)
        self.config = config
        self.reach = GammaReachCore(config.reach_config(), generator)
        self.device = self.reach.device
        self.scenes: list[Scene] = []
        self._costs: list[np.ndarray] = []
        self._slot_of: dict[tuple[str, int], int] = {}

    @property
    def generator(self) -> GammaGenerator:
        return self.reach.generator

    @property
    def body(self):
        return self.reach.body

    @property
    def goal_marker(self) -> tuple[str, float]:
        return "ring", self.config.goal_radius

    def add_scene(self, scene: Scene) -> int:
        """Index of `scene` in `scenes` (any scene, e.g. from `load_scene`), adding it on first use."""
        for slot, known in enumerate(self.scenes):
            if known is scene:
                return slot
        self.scenes.append(scene)
        self._costs.append(cell_costs(scene))
        return len(self.scenes) - 1

    def slot(self, family: str, seed: int) -> int:
        """Index of the (family, seed) room in `scenes`, building it on first use."""
        key = (family, int(seed))
        if key not in self._slot_of:
            self._slot_of[key] = self.add_scene(make_scene(family, int(seed)))
        return self._slot_of[key]

    def plan(self, slot: int, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """(W, 2) waypoints from `start` to `goal` in scene `slot` (`UnreachableGoal` when none joins them)."""
        return plan_path(self.scenes[slot], start, goal, self.config.waypoint_spacing, costs=self._costs[slot]).waypoints

    def flat_path(self, rng: np.random.Generator) -> np.ndarray:
        """(W, 2) waypoints of a random open-ground path from the origin: 4-5 legs, each turning up to `flat_turn`."""
        config = self.config
        legs = int(rng.integers(config.flat_legs[0], config.flat_legs[1] + 1))
        heading = rng.uniform(-math.pi, math.pi) + np.concatenate([[0.0], np.cumsum(rng.uniform(-1, 1, legs - 1) * config.flat_turn)])
        steps = rng.uniform(*config.flat_leg_length, size=legs)[:, None] * np.stack([np.cos(heading), np.sin(heading)], -1)
        corners = np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
        return split_legs(corners, config.waypoint_spacing)

    def sample_initial_state(self, rngs: list[np.random.Generator], options: dict[str, Any] | None = None) -> GammaWanderState:
        """One random episode per generator; `options` (module doc) apply to every body."""
        options = check_known(options, RESET_OPTIONS)
        config = self.config
        given_start, given_goal = point(options, "start", 2), point(options, "goal", 2)
        given_waypoints = point(options, "waypoints", 2, many=True)
        given_facing, given_row = number(options, "facing"), index(options, "start_index", self.reach.num_starts)
        given_seeds = scene_seed_option(options, len(rngs))
        slots, starts, paths, facings, rows = [], [], [], [], []
        for body, rng in enumerate(rngs):  # a few draws per body (and a path plan), so each body's episode follows its own seed
            slot = -1
            if config.scene != FLAT:
                family = config.families[int(rng.integers(len(config.families)))] if len(config.families) > 1 else config.families[0]
                drawn = config.seeds[int(rng.integers(len(config.seeds)))] if given_seeds is None else int(given_seeds[body])
                slot = self.slot(family, drawn)
            start, path = self._start_and_path(slot, rng, given_start, given_goal, given_waypoints)
            slots.append(slot), starts.append(start), paths.append(path)
            facings.append(given_facing if given_facing is not None else float(rng.uniform(-math.pi, math.pi)))
            rows.append(given_row if given_row is not None else int(rng.choice(self.reach.start_rows)))
        return self.initial_state(torch.tensor(rows), torch.tensor(facings, dtype=torch.float32),
                                  np.stack(starts), paths, torch.tensor(slots))  # fmt: skip

    def _start_and_path(self, slot: int, rng: np.random.Generator, start: np.ndarray | None, goal: np.ndarray | None,
                        waypoints: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """(2,) start and (W, 2) waypoints of one body: given, planned to a given goal, or drawn."""
        if slot < 0:
            start = np.zeros(2) if start is None else start
            if waypoints is not None:
                return start, waypoints
            return start, (split_legs(np.stack([start, goal]), self.config.waypoint_spacing) if goal is not None
                           else start + self.flat_path(rng))  # fmt: skip
        scene = self.scenes[slot]
        if start is None or (goal is None and waypoints is None):
            drawn_start, drawn_goal = scene.sample_start_goal(rng, self.config.min_goal_distance)
            start = drawn_start if start is None else start
            goal = drawn_goal if goal is None else goal
        return start, waypoints if waypoints is not None else self.plan(slot, start, goal)

    def initial_state(self, start_index: torch.Tensor, facing: torch.Tensor, start_xy: np.ndarray,
                      paths: list[np.ndarray], scene: torch.Tensor) -> GammaWanderState:  # fmt: skip
        """Bodies from start rows (N,) facing (N,) radians at `start_xy` (N, 2), each with its path (W_i, 2)
        in scene slot (N,) (-1: open ground)."""
        waypoints, lengths = self._padded(paths)
        reach = self.reach.initial_state(start_index, facing, waypoints[:, 0], torch.as_tensor(start_xy, dtype=torch.float32))
        count = len(paths)
        zeros = torch.zeros(count, dtype=torch.long, device=self.device)
        return GammaWanderState(reach, waypoints, lengths, zeros, scene.to(self.device), torch.zeros(count, 0, 2, device=self.device), zeros)

    def with_paths(self, state: GammaWanderState, rows: torch.Tensor, paths: list[np.ndarray]) -> GammaWanderState:
        """`state` with the bodies `rows` (K,) walking new paths (K × (W_i, 2)) from where they stand."""
        waypoints, lengths = self._padded(paths)
        rows = rows.to(self.device)
        reach = state.reach
        goal, closest, paid = reach.goal.clone(), reach.closest.clone(), reach.goal_paid.clone()
        goal[rows, :2] = waypoints[:, 0]
        closest[rows] = (state.pelvis[rows, :2] - waypoints[:, 0]).norm(dim=-1)
        paid[rows] = 0.0
        changes = {"waypoints": state.waypoints.clone(), "count": state.count.clone(), "current": state.current.clone()}
        changes["waypoints"][rows], changes["count"][rows], changes["current"][rows] = waypoints, lengths, 0
        return dataclasses.replace(state, reach=dataclasses.replace(reach, goal=goal, closest=closest, goal_paid=paid), **changes)

    def _padded(self, paths: list[np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
        """(K, MAX_WAYPOINTS, 2) the paths (W_i, 2) padded with their last waypoint, and (K,) their lengths."""
        if any(len(path) > MAX_WAYPOINTS or len(path) == 0 for path in paths):
            raise ValueError(f"paths must have 1 to {MAX_WAYPOINTS} waypoints, got {[len(p) for p in paths]} "
                             f"(raise waypoint_spacing or shorten the path)")  # fmt: skip
        padded = np.stack([np.concatenate([path, np.repeat(path[-1:], MAX_WAYPOINTS - len(path), axis=0)]) for path in paths])
        lengths = torch.tensor([len(path) for path in paths], device=self.device)
        return torch.as_tensor(padded, dtype=torch.float32, device=self.device), lengths

    def observe(self, state: GammaWanderState) -> torch.Tensor:
        """(N, 804): GammaReach's observation towards the current waypoint."""
        return self.reach.observe(state.reach)

    def step(self, state: GammaWanderState, z: torch.Tensor) -> tuple[GammaWanderState, GammaWanderStepResult]:
        """One primitive per body from latents z (N, 128): move, switch waypoints, check collisions, score."""
        config = self.config
        reach, moved = self.reach.step(state.reach, z)
        pelvis = moved.primitive.joints[:, -1, PELVIS, :2]
        last = state.current >= state.count - 1
        reached = last & (moved.distance <= config.goal_radius)
        advance = ~last & (moved.distance <= config.waypoint_radius)
        current = state.current + advance.long()
        goal_xy = state.waypoints.gather(1, current[:, None, None].expand(-1, 1, 2))[:, 0]
        waypoint_distance = (pelvis - goal_xy).norm(dim=-1)
        reach = dataclasses.replace(reach, goal=torch.cat([goal_xy, torch.zeros_like(goal_xy[:, :1])], dim=1),
                                    closest=torch.where(advance, waypoint_distance, reach.closest),
                                    goal_paid=torch.where(advance, torch.zeros_like(reach.goal_paid), reach.goal_paid))  # fmt: skip
        clearance = self.clearance(moved.primitive.joints, state.scene)
        collided = -clearance > config.collision_tolerance
        crowding = crowding_depth(moved.primitive.joints[:, :, PELVIS, :2], state.neighbours)
        remaining = (config.max_primitives - reach.steps).to(moved.reward.dtype)
        pelvis_path = moved.primitive.joints[:, :, PELVIS]  # (N, 10, 3); the steps into new frames are paid
        speeding = overspeed(pelvis_path[:, :-1], pelvis_path[:, 1:], GAMMA_FPS, config.walk_speed)
        terms = {**moved.terms, "collision": -collided.float(),
                 "clearance": -(config.clearance_margin - clearance).clamp(min=0.0),
                 "speeding": -(speeding * moved.primitive.new_frames()[:, 1:]).sum(dim=1),
                 "goal_absorbing": goal_absorbing_reward(reached, remaining, config.reward.best_step_reward)}  # fmt: skip
        reward = (moved.reward + config.collision_penalty * terms["collision"] + config.clearance_penalty * terms["clearance"]
                  + config.speeding * terms["speeding"] + terms["goal_absorbing"])  # fmt: skip
        truncated = (reach.steps >= config.max_primitives) & ~reached
        next_state = dataclasses.replace(state, reach=reach, current=current, collisions=state.collisions + collided.long())
        result = GammaWanderStepResult(reward, terms, next_state.distance_left(pelvis), waypoint_distance, reached, reached,
                                       truncated, clearance, collided, crowding, moved.contact_score, moved.primitive)  # fmt: skip
        return next_state, result

    def clearance(self, joints: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
        """(N,) least signed distance (m; negative: inside) from the collision spheres of bodies with joints
        (N, T, 22, 3) to their scenes over all T frames, +inf on open ground; one signed-distance lookup per scene."""
        centres, radii = spheres_of_joints(joints)
        clearance = torch.full((len(joints),), float("inf"), device=joints.device)
        for slot in torch.unique(scene).tolist():
            if slot < 0:
                continue
            rows = torch.nonzero(scene == slot).flatten()
            clearance[rows] = self.scenes[slot].clearance(centres[rows], radii).flatten(1).amin(dim=1)
        return clearance

    def render_inputs(self, state: GammaWanderState) -> RenderInputs:
        return self.reach.render_inputs(state.reach)

    def render_scene(self, state: GammaWanderState) -> Scene | None:
        """The first body's scene (None on open ground): what a vector env's render draws."""
        slot = int(state.scene[0])
        return None if slot < 0 else self.scenes[slot]

    def scene_spec(self, state: GammaWanderState) -> str:
        """The first body's room as "family:seed" ("" on open ground or in a loaded scene): what rollouts record."""
        slot = int(state.scene[0])
        return next((f"{family}:{seed}" for (family, seed), known in self._slot_of.items() if known == slot), "")

    def render_paths(self, state: GammaWanderState) -> list[np.ndarray]:
        """Per body, (W, 3) the waypoints still ahead, on the ground."""
        paths = []
        for waypoints, current, count in zip(state.waypoints.cpu().numpy(), state.current.tolist(), state.count.tolist()):
            ahead = waypoints[current:count]
            paths.append(np.concatenate([ahead, np.zeros((len(ahead), 1))], axis=1))
        return paths


def distance_along_path(waypoints: torch.Tensor, current: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
    """(N,) metres from points `xy` (N, 2) to waypoint `current` (N,) of paths `waypoints` (N, W, 2), then along the
    rest of each path; paths shorter than W are padded with their last waypoint (0-length legs)."""
    legs = (waypoints[:, 1:] - waypoints[:, :-1]).norm(dim=-1)
    after = torch.cat([legs.flip(1).cumsum(1).flip(1), torch.zeros_like(legs[:, :1])], dim=1)
    target = waypoints.gather(1, current[:, None, None].expand(-1, 1, 2))[:, 0]
    return (xy - target).norm(dim=-1) + after.gather(1, current[:, None])[:, 0]


def crowding_depth(pelvis: torch.Tensor, neighbours: torch.Tensor) -> torch.Tensor:
    """(N,) how far (m) pelvis paths (N, T, 2) came inside `PERSONAL_SPACE` of any neighbour (N, M, 2); 0 with none."""
    if neighbours.shape[1] == 0:
        return torch.zeros(len(pelvis), device=pelvis.device)
    gaps = torch.cdist(pelvis, neighbours).amin(dim=(1, 2))
    return (PERSONAL_SPACE - gaps).clamp(min=0.0)


def _step_info(result: GammaWanderStepResult, state: GammaWanderState, row: int) -> dict[str, Any]:
    info: dict[str, Any] = {
        "reward_terms": {name: float(value[row]) for name, value in result.terms.items()},
        "distance": float(result.distance[row]),
        "waypoint_distance": float(result.waypoint_distance[row]),
        "waypoint": int(state.current[row]),
        "waypoints": int(state.count[row]),
        "reached": bool(result.reached[row]),
        "collided": bool(result.collided[row]),
        "penetration": float(result.penetration[row]),
        "collisions": int(state.collisions[row]),
        "contact_score": float(result.contact_score[row]),
        "primitives": int(state.steps[row]),
    }
    if result.terminated[row] or result.truncated[row]:
        info["is_success"] = bool(result.reached[row])
    return info


def _spaces(core: GammaWanderCore) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    bound = core.config.latent_bound
    return (gym.spaces.Box(-bound, bound, (core.generator.latent_size,), np.float32),
            gym.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float32))  # fmt: skip


class GammaWanderEnv(gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}

    def __init__(self, generator: GammaGenerator | None = None, render_mode: str | None = None, **kwargs: Any) -> None:
        self.vector = GammaWanderVectorEnv(1, generator, render_mode, render_bodies=1, **kwargs)
        self.core, self.config, self.render_mode = self.vector.core, self.vector.config, render_mode
        self.action_space, self.observation_space = self.vector.single_action_space, self.vector.single_observation_space
        self.last_primitive: Primitive | None = None
        """The primitive the last step generated (what `motion-envs play` records and renders frame by frame)."""

    @property
    def state(self) -> GammaWanderState | None:
        return self.vector.state

    @state.setter
    def state(self, value: GammaWanderState) -> None:
        self.vector.state = value

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.vector.rngs = [self.np_random]
        observation, _ = self.vector.reset(options=options)
        state = self.vector.state
        return observation[0], {"distance": float(state.distance_left(state.pelvis[:, :2])[0]),
                                "waypoints": state.waypoints[0, : int(state.count[0])].cpu().numpy()}  # fmt: skip

    def step(self, action: np.ndarray):
        if self.vector.state is None:
            raise RuntimeError("call reset() before step()")
        z = check_actions(action, self.action_space.shape, batch=None)
        state, result = self.core.step(self.vector.state, torch.as_tensor(z)[None])
        self.vector.state, self.last_primitive = state, result.primitive
        self.vector.record_trails(torch.zeros(1, dtype=torch.bool))
        return (self.core.observe(state)[0].cpu().numpy().astype(np.float32), float(result.reward[0]),
                bool(result.terminated[0]), bool(result.truncated[0]), _step_info(result, state, 0))  # fmt: skip

    def render(self) -> np.ndarray | None:
        """rgb_array: the body, its room (walls cut away), the path ahead and the pelvis trail."""
        return self.vector.render()


class GammaWanderVectorEnv(CoreVectorEnv):
    """N bodies in one batched core (each in its own room); same-step autoreset (see `CoreVectorEnv`)."""

    def __init__(self, num_envs: int = 1, generator: GammaGenerator | None = None, render_mode: str | None = None,
                 render_bodies: int = 8, autoreset_mode: str = "same_step", **kwargs: Any) -> None:  # fmt: skip
        self.config = config_from_kwargs(GammaWanderConfig, kwargs, "GammaWander-v0")
        core = GammaWanderCore(self.config, generator)
        super().__init__(core, num_envs, *_spaces(core), render_mode, render_bodies, autoreset_mode)

    def _step_info(self, result: GammaWanderStepResult) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        info: dict[str, Any] = {name: getattr(result, name).cpu().numpy() for name in
                                ("distance", "waypoint_distance", "reached", "collided", "penetration", "contact_score")}  # fmt: skip
        info["waypoint"] = self.state.current.cpu().numpy()
        info["reward_terms"] = {name: value.cpu().numpy() for name, value in result.terms.items()}
        done = (result.terminated | result.truncated).cpu().numpy()
        return info, {"is_success": result.reached.cpu().numpy() & done, "collisions": self.state.collisions.cpu().numpy()}
