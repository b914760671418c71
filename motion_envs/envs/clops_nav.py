"""ClopsNav-v0: find a red sphere in a furnished room by looking, and walk to it by choosing where the head goes.

## Description

CLOPS (Diomataris et al., "Moving by Looking") drives a head-target motion
prior (`motion_envs.priors.clops`) with a Q-network that sees only the
body's egocentric view. A body stands in a room of one layout family
(`motion_envs.scenes.layouts`); a goal sphere floats somewhere in the free
space of the same room (reachable), seen only through the goal-mask channel.
Every step the agent picks one of K head-pose deltas (k-means over the
mocap, stored with the prior); the prior generates frames (30 fps) until
the head reaches that target pose (20 cm on the ground, 20° of yaw) or
`max_chunk_frames` (30) have passed, and the body's new egocentric view is the
next observation. The policy acts about once a second, as the paper's.
After every frame the lowest foot vertex is kept on the floor (as in
WandrReach: our small-data prior's height drifts).

## Action Space

`Discrete(K)`, K = 16 with the shipped prior (`prior.actions`: rows of
dx, dy, dz in the head's yaw frame (m) and dyaw (rad)). Out-of-range or
non-integer actions raise `ValueError`.

## Observation Space

`Box(0, 255, (5, H, W), uint8)`, channel-first so that SB3's `CnnPolicy`
takes it (and scales it by 1/255): depth (0-255 over 0-`max_depth` m),
semantic colour (3, the fixed label palette), goal mask (0 or 255). With
`known_goal=True` (the paper's "CLOPS + known goal") the observation is a
`Dict` of that `image` and `goal`: `Box(-inf, inf, (3,), float32)`, the
goal relative to the head in the head's yaw frame (m) — SB3's
`MultiInputPolicy`. With `goal_memory=True` (ours) it is a `Dict` of the
`image` and a `memory` vector `Box(-inf, inf, (13,), float32)`, what the
body itself has seen so far (`ClopsNavCore.memory`): where the goal was
when last in view (x, y relative to the head, head's yaw frame, m; zeros if
never), whether it has been seen, the time since (fraction of the episode;
1 if never), which of 8 directions around the body its view has pointed at
(45° bins, from straight ahead counter-clockwise) and the elapsed fraction
of the episode.

## Rewards

`ClopsRewardConfig` (`motion_envs.rewards`), per action, every term in
`info["reward_terms"]`: −0.1 time, −1 collision (any body sphere deeper
than `collision_tolerance` in the scene at any checked frame of the chunk),
−0.5 stay-still (head moved < 10 cm and turned < 10°), +10 goal found (the
pelvis within `success_distance` of the goal on the ground and any goal
pixel in view), −5 for leaving the room (ours). The paper's constants and
its "X cm" were lost from its text; `success_distance` = 1 m is ours.

## Starting State

A scene seed drawn from the family's training seeds (the first
`train_scenes` of `TRAIN_SEEDS`) or its held-out `TEST_SEEDS`
(`split="test"`; with `family="mixed"` a family is drawn first, uniformly); a start and a goal drawn from its walkable region at
least `min_goal_distance` apart; the body is a shipped start pose turned to
a random heading; the goal sphere's centre at a height in `goal_height`.

## Episode End

Terminates when the goal is found, or (failed) when the pelvis has left
the room (`room_margin` outside the walkable rectangle; ours: the prior is
kinematic and walks through walls), or (failed) when the prior's next frame
would drop the pelvis below `fall_height` (0.3 m; ours: that frame is not
taken, the body stays at its last upright one); truncates after `max_seconds` (15 s =
450 frames) of generated motion. Collisions never end an episode (as the
paper).

## Arguments

`gym.make("motion_envs/ClopsNav-v0", **kwargs)` with any field of
`ClopsNavConfig` (e.g. `family="living"`, `split="test"`, `width=64`,
`known_goal=True`). `reset(options=...)` takes `scene_seed` (one seed, or
one per body for the vector env), `start` (x, y), `goal` (x, y, z),
`facing` (radians) and `start_index`.

## Batched core

`ClopsNavCore` steps N bodies at once (the single env is N = 1): frames are
decoded for all bodies together, collisions are one signed-distance lookup
per scene for all checked frames of the chunk, views one ray cast per scene.
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
from motion_envs.body.collision_spheres import spheres_of_joints
from motion_envs.body.head_camera import camera_from_head
from motion_envs.body.rotations import about_z, matrix_to_sixd
from motion_envs.counter_random import counter_normal
from motion_envs.envs.core import CoreVectorEnv, check_actions, config_from_kwargs
from motion_envs.envs.options import check_known, index, number, point, scene_seed_option
from motion_envs.envs.starts import DeltaPriorBodies, StartBodies
from motion_envs.metrics import lowest_foot, track_skating
from motion_envs.priors.clops import ClopsPrior, ClopsStepper, HeadPose, action_targets, head_pose, head_yaw, yaw_change
from motion_envs.priors.train_clops import load_clops
from motion_envs.priors.wandr_features import FPS, PELVIS, WandrState
from motion_envs.render.egocentric import EgocentricRenderer
from motion_envs.render.env_view import EnvView, RenderInputs
from motion_envs.rewards import ClopsRewardConfig, goal_found, stayed_still
from motion_envs.scenes.layouts import FAMILIES, TRAIN_SEEDS, families_of, make_scene, seeds_of
from motion_envs.scenes.scene import Scene

RESET_OPTIONS = ("scene_seed", "start", "goal", "facing", "start_index")
MIXED = "mixed"
LOOK_BINS = 8
MEMORY_SIZE = 5 + LOOK_BINS


def goal_in_view(view: torch.Tensor) -> torch.Tensor:
    """(N,) bool: any goal-mask pixel in views (N, 5, H, W)."""
    return (view[:, 4] > 0).flatten(1).any(-1)


def looked_bins(yaw: torch.Tensor, fov: float) -> torch.Tensor:
    """(N, LOOK_BINS) bool: the yaw bins (centres k · 2π / LOOK_BINS) within half the field of view `fov` (degrees)
    of views whose yaw is `yaw` (N,) radians."""
    centres = torch.arange(LOOK_BINS, device=yaw.device) * (2 * math.pi / LOOK_BINS)
    offset = torch.remainder(centres - yaw[:, None] + math.pi, 2 * math.pi) - math.pi
    return offset.abs() <= math.radians(fov) / 2


GOAL_CEILING = 3.0
"""Highest goal centre a `goal` reset option may ask for (m): the rooms' walls are lower."""


def check_start(scene: Scene, start: np.ndarray) -> np.ndarray:
    """`start` (2,), checked to lie inside the scene's room (its walkable rectangle). A start inside furniture is
    allowed (the body collides from the first action; a test uses it)."""
    x0, y0, x1, y1 = scene.walkable_bounds
    if not (x0 <= start[0] <= x1 and y0 <= start[1] <= y1):
        raise ValueError(f"option 'start' {start.tolist()} lies outside {scene.name}: x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f}")
    return start


def check_goal(scene: Scene, goal: np.ndarray) -> np.ndarray:
    """`goal` (3,), checked to lie inside the scene's room: over its walkable rectangle, 0..`GOAL_CEILING` m up."""
    x0, y0, x1, y1 = scene.walkable_bounds
    if not (x0 <= goal[0] <= x1 and y0 <= goal[1] <= y1 and 0.0 <= goal[2] <= GOAL_CEILING):
        raise ValueError(f"option 'goal' {goal.tolist()} lies outside {scene.name}: x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f}, "
                         f"z 0..{GOAL_CEILING:g}")  # fmt: skip
    return goal


@dataclasses.dataclass(frozen=True)
class ClopsNavConfig:
    """Everything that defines a ClopsNav task."""

    family: str = "open"
    """Scene layout family (`motion_envs.scenes.layouts.FAMILIES`), or "mixed": every episode draws one of them
    uniformly, then one of its seeds."""
    split: str = "train"
    """'train': the first `train_scenes` training seeds; 'test': the held-out seeds."""
    train_scenes: int = 64
    scene_seeds: tuple[int, ...] | None = None
    """Explicit seeds (overrides `split`)."""
    reward: ClopsRewardConfig = dataclasses.field(default_factory=ClopsRewardConfig)
    width: int = 64
    height: int = 64
    fov: float = 90.0
    """Horizontal field of view, degrees (square pixels)."""
    max_depth: float = 10.0
    goal_radius: float = 0.25
    goal_height: tuple[float, float] = (0.8, 1.5)
    min_goal_distance: float = 2.0
    success_distance: float = 1.0
    max_seconds: float = 15.0
    max_chunk_frames: int = 30
    """At most this many frames per action (1 s: the policy acts at least once a second, the paper's 1 Hz). With 45,
    most chunks ran to the limit (the head overshoots its target and wanders back); the shipped open-trained policy
    found 70% of the open test goals with 45 and 0.10 m / 10° reach, 77% with 30 and 0.2 m / 20°, unretrained."""
    reach_distance: float = 0.2
    reach_angle: float = math.radians(20.0)
    """When a head is at its action's target (`ClopsStepper.reached`), matched to the shipped prior's precision: after
    a 1-s forward walk from standing its head lands a median 12-16 cm from the target (0.10 m and 10° were reached by
    31-41% of forward walks within 45 frames, 0.2 m and 20° by 78-94%; 64 bodies, `open`)."""
    latent_scale: float = 0.0
    """z = latent_scale · ε, ε ~ N(0, I) every frame. The paper samples (1); we decode the prior's mean (0): with
    our small-data prior, sampling raised foot skating from 44% to 74% of frames and collisions from 23% to 32% of
    actions under random actions (64 bodies × 15 actions, `open`)."""
    lock_feet: bool = True
    """The foot rule, as WandrReach's: every frame is shown with a loaded foot held where it stood (`WandrStepper`);
    the prior, the views and the agents' episodes are the same with and without it. False: the prior's own legs."""
    collision_every: int = 3
    """Frames between collision checks within a chunk (and its last frame)."""
    collision_tolerance: float = 0.02
    """Penetration (m) below which a sphere does not count as colliding (the grid has 5 cm voxels)."""
    still_distance: float = 0.10
    still_angle: float = math.radians(10.0)
    room_margin: float = 0.5
    """An episode ends (terminated, failed, `ClopsRewardConfig.left_room` paid) once the pelvis is more than this (m)
    outside the walkable region's rectangle: the prior is kinematic, so walls stop nothing, and a body that walked
    out of the room would otherwise see only the void for the rest of its episode (collision-free, a place to hide).
    As a truncation (bootstrapped from the void's value, never learnt) it cost nothing: 10 of the open-trained
    policy's 30 failures on open test rooms were walks out of the room, most from starts facing a near wall."""
    fall_height: float = 0.3
    """An episode ends (terminated, failed, `ClopsRewardConfig.fallen` paid) when the prior's next frame would put
    the pelvis lower than this (m); that frame is not taken, so the body stays at its last upright frame and no
    shown frame has the pelvis below the issue's 0.3 m. The previous prior let bodies fall and stay down (under
    uniform random actions 16 of 128 bodies had the pelvis below 0.3 m within 15 actions, most after frame 300;
    with the shipped upright prior 2% of random-action episodes and 3-8% of the policies' end so, `bench clops`), and a
    body lying on the floor is no walk to learn from or to show, as Gymnasium's Humanoid ends an episode when its
    torso leaves its healthy height. 0: off (the raw prior, as `bench floor`'s sinking rows measure it)."""
    known_goal: bool = False
    goal_memory: bool = False
    """Observe a memory of what the view has shown (module doc; ours). The paper's CLOPS has none and names it its
    limit: "If, while looking at the goal, it makes a motion that puts the goal out of its field of view, then it
    needs to find it all over again" (frame stacking did not help it). The goal's remembered position is its true
    centre from the frame it was last in view: any goal pixel counts as a detection (an ideal detector; the sphere's
    radius is 0.25 m)."""
    weights: str | None = None
    """CLOPS prior weights (default: the shipped priors/weights/clops.pt)."""
    device: str = "cpu"

    def __post_init__(self) -> None:
        if isinstance(self.reward, str):
            object.__setattr__(self, "reward", ClopsRewardConfig.named(self.reward))
        if self.family not in (*FAMILIES, MIXED):
            raise ValueError(f"unknown scene family {self.family!r}; choose from {(*FAMILIES, MIXED)}")
        if self.split not in ("train", "test"):
            raise ValueError(f"split must be 'train' or 'test', got {self.split!r}")
        if self.width < 8 or self.height < 8 or not 0 < self.fov < 180:
            raise ValueError(f"need width, height >= 8 and 0 < fov < 180, got {self.width}, {self.height}, {self.fov}")
        if min(self.max_chunk_frames, self.max_seconds, self.collision_every, self.reach_distance, self.reach_angle) <= 0:
            raise ValueError("max_chunk_frames, max_seconds, collision_every, reach_distance and reach_angle must be positive")
        if self.fall_height < 0:
            raise ValueError(f"fall_height must be >= 0 (0: off), got {self.fall_height}")
        if not 1 <= self.train_scenes <= len(TRAIN_SEEDS):
            raise ValueError(f"train_scenes must lie in [1, {len(TRAIN_SEEDS)}], got {self.train_scenes}")
        if self.scene_seeds is not None and len(self.scene_seeds) == 0:
            raise ValueError("scene_seeds must name at least one seed")
        if self.known_goal and self.goal_memory:
            raise ValueError("known_goal and goal_memory exclude each other: a known goal needs no memory of it")

    @property
    def families(self) -> tuple[str, ...]:
        """The layout families episodes are drawn from."""
        return families_of(self.family)

    @property
    def seeds(self) -> tuple[int, ...]:
        return seeds_of(self.split, self.train_scenes, self.scene_seeds)

    @property
    def max_frames(self) -> int:
        return round(self.max_seconds * FPS)


@dataclasses.dataclass(frozen=True)
class ClopsNavState(DeltaPriorBodies):
    """N bodies' simulation state.

    body: the prior's state as tensors; goal: (N, 3); scene: (N,) index into the core's scene list;
    noise_key: (N,) int64 key of the body's latent draws; frame / actions / collided: (N,) frames so far,
    actions taken, actions that collided; lowest_id, lowest_xy: (N,), (N, 2) the lowest foot vertex and
    where it was; skated: (N,) skating frames; found: (N,) bool; view: (N, 5, H, W) uint8 the current view;
    seen_at: (N,) frame the goal was last in view (-1: never); looked: (N, LOOK_BINS) bool, the world yaw bins
    (centred on k · 2π / LOOK_BINS, `head_yaw`'s convention) a view has pointed at after an action or the reset.
    """

    goal: torch.Tensor
    scene: torch.Tensor
    noise_key: torch.Tensor
    frame: torch.Tensor
    actions: torch.Tensor
    collided: torch.Tensor
    lowest_id: torch.Tensor
    lowest_xy: torch.Tensor
    skated: torch.Tensor
    found: torch.Tensor
    view: torch.Tensor
    seen_at: torch.Tensor
    looked: torch.Tensor

    @property
    def distance(self) -> torch.Tensor:
        """(N,) pelvis-to-goal distance on the ground (m)."""
        return (self.joints[:, PELVIS, :2] - self.goal[:, :2]).norm(dim=-1)


@dataclasses.dataclass(frozen=True)
class ClopsStepResult:
    """What one action of N bodies produced; every tensor (N,)."""

    reward: torch.Tensor
    terms: dict[str, torch.Tensor]
    terminated: torch.Tensor
    truncated: torch.Tensor
    collided: torch.Tensor
    frames: torch.Tensor
    left_room: torch.Tensor
    fallen: torch.Tensor
    trajectory: list[WandrState] | None = None
    """With `keep_frames`: the bodies after every generated frame of the chunk (frozen bodies repeat)."""


class SceneSlot:
    """A scene with its egocentric renderer."""

    def __init__(self, scene: Scene, config: ClopsNavConfig) -> None:
        self.scene = scene
        self.eyes = EgocentricRenderer(scene, config.width, config.height, config.fov, config.max_depth)
        self.bounds = torch.as_tensor(scene.walkable_bounds, dtype=torch.float32)


class ClopsNavCore:
    """The batched task: start states, one action for N bodies, observations. Stateless: states go in and out."""

    def __init__(self, config: ClopsNavConfig, prior: ClopsPrior | None = None) -> None:
        keep_freed_memory()  # large step tensors reused, not page-faulted anew (`motion_envs.allocator`)
        self.config = config
        self.device = torch.device(config.device)
        self.prior = (prior or load_clops(config.weights)).to(self.device).eval()
        self.body = BodyModel().to(self.device)
        self.stepper = ClopsStepper(self.prior, self.body, reach_distance=config.reach_distance, reach_angle=config.reach_angle,
                                    lock_feet=config.lock_feet)  # fmt: skip
        self.starts = StartBodies(self.stepper, self.device)
        self.slots: list[SceneSlot] = []
        self._slot_of: dict[tuple[str, int], int] = {}
        self.bounds = torch.zeros(0, 4, device=self.device)
        """(S, 4) walkable rectangle (x0, y0, x1, y1) of every slot, indexed like `slots`."""

    @property
    def num_actions(self) -> int:
        return len(self.prior.actions)

    def slot(self, family: str, seed: int) -> int:
        """Index of the (family, seed) scene in `slots`, building it on first use."""
        key = (family, int(seed))
        if key not in self._slot_of:
            self._slot_of[key] = len(self.slots)
            self.slots.append(SceneSlot(make_scene(family, int(seed)), self.config))
            self.bounds = torch.cat([self.bounds, self.slots[-1].bounds.to(self.device)[None]])
        return self._slot_of[key]

    def sample_initial_state(self, rngs: list[np.random.Generator], options: dict[str, Any] | None = None) -> ClopsNavState:
        """One random episode per generator; `options` (see the module doc) apply to every body."""
        options = check_known(options, RESET_OPTIONS)
        config, seeds, families = self.config, self.config.seeds, self.config.families
        slots, starts, goals, facings, rows, keys = [], [], [], [], [], []
        given_seeds = scene_seed_option(options, len(rngs))
        given_start, given_goal = point(options, "start", 2), point(options, "goal", 3)
        given_facing, given_row = number(options, "facing"), index(options, "start_index", len(self.starts))
        for body_index, rng in enumerate(rngs):  # per-body draws from its own generator (a few numbers each)
            # a single family draws nothing, so its episodes stay those of the same seeds before `mixed` existed
            family = families[int(rng.integers(len(families)))] if len(families) > 1 else families[0]
            drawn = seeds[int(rng.integers(len(seeds)))]
            slots.append(self.slot(family, drawn if given_seeds is None else int(given_seeds[body_index])))
            scene = self.slots[slots[-1]].scene
            start, goal = scene.sample_start_goal(rng, config.min_goal_distance)
            height = rng.uniform(*config.goal_height)
            starts.append(start if given_start is None else check_start(scene, given_start))
            goals.append(np.array([*goal, height]) if given_goal is None else check_goal(scene, given_goal))
            facings.append(given_facing if given_facing is not None else float(rng.uniform(-math.pi, math.pi)))
            rows.append(given_row if given_row is not None else int(rng.integers(len(self.starts))))
            keys.append(int(rng.integers(1 << 62)))
        goal = torch.as_tensor(np.stack(goals), dtype=torch.float32, device=self.device)
        position = torch.as_tensor(np.stack(starts), dtype=torch.float32, device=self.device)
        body, feet = self.starts.place(torch.tensor(rows), torch.tensor(facings, dtype=torch.float32), position)
        count, zeros = len(rngs), torch.zeros(len(rngs), dtype=torch.long, device=self.device)
        lowest_id, lowest_xy = lowest_foot(feet)
        scene = torch.tensor(slots, device=self.device)
        state = ClopsNavState(
            *body, goal, scene, torch.tensor(keys, device=self.device), zeros, zeros, zeros, lowest_id, lowest_xy, zeros,
            torch.zeros(count, dtype=torch.bool, device=self.device), torch.zeros(count, 0, device=self.device),
            zeros - 1, torch.zeros(count, LOOK_BINS, dtype=torch.bool, device=self.device),
        )  # fmt: skip
        state = dataclasses.replace(state, view=self.views(state.body, goal, scene))
        return self.remember(state, goal_in_view(state.view), head_yaw(head_pose(state.body).rotation))

    def remember(self, state: ClopsNavState, visible: torch.Tensor, yaw: torch.Tensor) -> ClopsNavState:
        """The state with its current view remembered: `seen_at` where the goal is `visible` (N,) bool, the yaw bins
        `looked` of the views' yaw (N,) radians."""
        seen_at = torch.where(visible, state.frame, state.seen_at)
        return dataclasses.replace(state, seen_at=seen_at, looked=state.looked | looked_bins(yaw, self.config.fov))

    def views(self, body: WandrState, goal: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
        """(N, 5, H, W) uint8 egocentric views of bodies from their head cameras, one ray cast per scene."""
        head = head_pose(body)
        camera = camera_from_head(head.position, head.rotation)
        return self.views_from(camera.eye, camera.rotation, goal, scene)

    def views_from(self, eye: torch.Tensor, rotation: torch.Tensor, goal: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
        """(N, 5, H, W) uint8 views from cameras eye (N, 3), rotation (N, 3, 3) in the scenes (N,) with goals (N, 3)."""
        config = self.config
        views = np.empty((len(goal), 5, config.height, config.width), dtype=np.uint8)
        for index in torch.unique(scene).tolist():
            rows = torch.nonzero(scene == index).flatten()
            raw = self.slots[index].eyes.render(eye[rows], rotation[rows], goal[rows], config.goal_radius)
            raw[:, 0] /= config.max_depth
            views[rows.cpu().numpy()] = np.round(np.clip(raw, 0.0, 1.0) * 255.0).astype(np.uint8)
        return torch.as_tensor(views, device=self.device)

    def goal_visible(self, eye: torch.Tensor, rotation: torch.Tensor, goal: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
        """(N,) bool: any goal pixel in the view from cameras eye (N, 3), rotation (N, 3, 3)."""
        return goal_in_view(self.views_from(eye, rotation, goal, scene))

    def collisions(self, joints: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
        """(N,) bool: any collision sphere of bodies with joints (T, N, 22, 3) deeper than the tolerance in its scene."""
        centres, radii = spheres_of_joints(joints)
        hit = torch.zeros(joints.shape[1], dtype=torch.bool, device=self.device)
        for index in torch.unique(scene).tolist():
            rows = torch.nonzero(scene == index).flatten()
            depth = self.slots[index].scene.collisions(centres[:, rows], radii)
            hit[rows] = (depth > self.config.collision_tolerance).flatten(2).any(-1).any(0)
        return hit

    def left_room(self, state: ClopsNavState) -> torch.Tensor:
        """(N,) bool: the pelvis more than `room_margin` outside its scene's walkable rectangle."""
        bounds = self.bounds[state.scene]
        margin = self.config.room_margin
        pelvis = state.joints[:, PELVIS, :2]
        return ((pelvis < bounds[:, :2] - margin) | (pelvis > bounds[:, 2:] + margin)).any(-1)

    def goal_in_head_frame(self, state: ClopsNavState, head: HeadPose | None = None) -> torch.Tensor:
        """(N, 3) the goal relative to the head (`head`: the bodies' head pose when already computed), in the head's
        yaw frame (x right, y forward, z up)."""
        head = head_pose(state.body) if head is None else head
        return ((state.goal - head.position)[:, None] @ about_z(head_yaw(head.rotation))).squeeze(1)  # R_zᵀ (g − h)

    def memory(self, state: ClopsNavState) -> torch.Tensor:
        """(N, MEMORY_SIZE) float32: [remembered goal x, y (m, head's yaw frame; 0 if never seen), seen (0/1), time
        since last seen (fraction of the episode; 1 if never), LOOK_BINS directions looked at (relative to the head:
        bin j is j · 360° / LOOK_BINS counter-clockwise from ahead), elapsed fraction of the episode]."""
        seen = state.seen_at >= 0
        head = head_pose(state.body)
        goal = self.goal_in_head_frame(state, head)[:, :2] * seen[:, None]
        since = torch.where(seen, (state.frame - state.seen_at).float() / self.config.max_frames, 1.0)
        width = 2 * math.pi / LOOK_BINS
        yaw = head_yaw(head.rotation)
        relative = torch.arange(LOOK_BINS, device=self.device) * width
        world_bin = torch.round((yaw[:, None] + relative) / width).long() % LOOK_BINS
        looked = state.looked.gather(1, world_bin).float()
        elapsed = state.frame.float() / self.config.max_frames
        return torch.cat([goal, seen.float()[:, None], since[:, None], looked, elapsed[:, None]], dim=1)

    def observe(self, state: ClopsNavState) -> np.ndarray | dict[str, np.ndarray]:
        """(N, 5, H, W) uint8 views; with `known_goal` a dict of those (`image`) and the goal (`goal`, (N, 3)), with
        `goal_memory` of those and the memory (`memory`, (N, MEMORY_SIZE))."""
        image = state.view.cpu().numpy()
        if self.config.known_goal:
            return {"image": image, "goal": self.goal_in_head_frame(state).cpu().numpy().astype(np.float32)}
        if self.config.goal_memory:
            return {"image": image, "memory": self.memory(state).cpu().numpy().astype(np.float32)}
        return image

    def check_actions(self, actions: torch.Tensor) -> torch.Tensor:
        """(N,) long action indices from (N,) numbers. Raises ValueError naming the bad ones."""
        bad = (actions != torch.round(actions)) | (actions < 0) | (actions >= self.num_actions)
        if bad.any():
            raise ValueError(f"actions must be integers in [0, {self.num_actions}), got {actions[bad][:5].tolist()}")
        return actions.long().to(self.device)

    @torch.no_grad()
    def step(self, state: ClopsNavState, actions: torch.Tensor, keep_frames: bool = False) -> tuple[ClopsNavState, ClopsStepResult]:
        """One action per body (N,): frames towards the target head pose until reached (or the chunk's limit).
        `keep_frames`: the result also holds every generated frame (for videos and the viewer)."""
        config, scales = self.config, self.config.reward
        actions = self.check_actions(actions)
        count = state.num_bodies
        start_frame, start_head = state.frame, head_pose(state.body)
        target = action_targets(start_head, self.prior.actions[actions])
        body, frame, lowest_id, lowest_xy, skated = state.body, state.frame, state.lowest_id, state.lowest_xy, state.skated
        active = (frame < config.max_frames) & ~state.found
        fallen = torch.zeros_like(active)
        checked, trajectory = [], []
        latent = self.prior.config.latent
        noise = config.latent_scale * counter_normal(state.noise_key, start_frame, config.max_chunk_frames * latent)
        for index in range(config.max_chunk_frames):  # autoregressive: frame by frame, all bodies at once
            z = noise[:, index * latent : (index + 1) * latent]
            moved, feet = self.stepper.step_towards(body, z, target)
            if config.fall_height > 0:  # 0: off (a pelvis below the floor must not count then)
                fallen = fallen | (active & (moved.joints[:, PELVIS, 2] < config.fall_height))
                active = active & ~fallen  # the falling frame is not taken: the body stays at its last upright one
            body = WandrState(*(where_bodies(active, new, old) for new, old in zip(moved, body)))
            slid, lowest_id, lowest_xy = track_skating(feet, lowest_id, lowest_xy, active)
            skated = skated + slid.long()
            frame = frame + active.long()
            if keep_frames:
                trajectory.append(body)
            if index % config.collision_every == 0:
                checked.append(body.joints)
            active = active & ~self.stepper.reached(body, target) & (frame < config.max_frames)
            if not active.any():
                break
        checked.append(body.joints)
        collided = self.collisions(torch.stack(checked), state.scene)
        view = self.views(body, state.goal, state.scene)
        visible = goal_in_view(view)  # the goal in the field of view, not hidden by the scene
        end_head = head_pose(body)
        turned = yaw_change(start_head.rotation, end_head.rotation)
        moved_by = (end_head.position[:, :2] - start_head.position[:, :2]).norm(dim=-1)
        state = dataclasses.replace(state, **body._asdict(), frame=frame, actions=state.actions + 1,
                                    collided=state.collided + collided.long(), lowest_id=lowest_id, lowest_xy=lowest_xy,
                                    skated=skated, view=view)  # fmt: skip
        state = self.remember(state, visible, head_yaw(end_head.rotation))
        found = goal_found(state.distance, visible, config.success_distance)
        state = dataclasses.replace(state, found=found)
        left = self.left_room(state) & ~found
        fallen = fallen & ~found
        terms = {"time": torch.ones(count, device=self.device), "collision": collided.float(),
                 "still": stayed_still(moved_by, turned, config.still_distance, config.still_angle).float(),
                 "goal": found.float(), "left_room": left.float(), "fallen": fallen.float()}  # fmt: skip
        reward = (scales.goal * terms["goal"] - scales.time * terms["time"] - scales.collision * terms["collision"]
                  - scales.still * terms["still"] - scales.left_room * terms["left_room"]
                  - scales.fallen * terms["fallen"])  # fmt: skip
        terminated = found | left | fallen
        truncated = (frame >= config.max_frames) & ~terminated
        return state, ClopsStepResult(reward, terms, terminated, truncated, collided, frame - start_frame, left,
                                      fallen, trajectory if keep_frames else None)  # fmt: skip

    @property
    def goal_marker(self) -> tuple[str, float]:
        """How third-person renders draw the goal: the sphere the body has to find."""
        return "sphere", self.config.goal_radius

    def render_inputs(self, state: ClopsNavState) -> RenderInputs:
        return RenderInputs(state.transl, matrix_to_sixd(state.orient), matrix_to_sixd(state.shown_pose), state.joints[:, PELVIS], state.goal)

    def scene_spec(self, state: ClopsNavState) -> str:
        """The first body's room as "family:seed" (what rollouts record and `motion-envs view --scene` takes)."""
        return ":".join(self.render_scene(state).name.rsplit("-", 1))

    def render_scene(self, state: ClopsNavState) -> Scene:
        """The scene drawn behind the bodies (the first body's)."""
        return self.slots[int(state.scene[0])].scene


def _spaces(core: ClopsNavCore) -> tuple[gym.spaces.Discrete, gym.spaces.Space]:
    config = core.config
    observation = image = gym.spaces.Box(0, 255, (5, config.height, config.width), np.uint8)
    if config.known_goal:
        observation = gym.spaces.Dict({"image": image, "goal": gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)})
    elif config.goal_memory:
        observation = gym.spaces.Dict({"image": image, "memory": gym.spaces.Box(-np.inf, np.inf, (MEMORY_SIZE,), np.float32)})
    return gym.spaces.Discrete(core.num_actions), observation


def with_view_inset(frame: np.ndarray, view: np.ndarray, scale: int = 2) -> np.ndarray:
    """The third-person `frame` (H, W, 3) uint8 with an egocentric `view` (5, h, w) uint8 in its top-left corner:
    semantic colours, goal pixels red, `scale` times enlarged, with a white border."""
    colour = view[1:4].transpose(1, 2, 0).copy()
    colour[view[4] > 0] = (230, 30, 30)
    inset = colour.repeat(scale, axis=0).repeat(scale, axis=1)
    height, width = min(inset.shape[0], frame.shape[0] - 4), min(inset.shape[1], frame.shape[1] - 4)
    framed = frame.copy()
    framed[: height + 4, : width + 4] = 255
    framed[2 : height + 2, 2 : width + 2] = inset[:height, :width]
    return framed


class ClopsNavEnv(gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array"], "render_fps": FPS}

    def __init__(self, prior: ClopsPrior | None = None, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        self.config = config_from_kwargs(ClopsNavConfig, kwargs, "ClopsNav-v0")
        self.core = ClopsNavCore(self.config, prior)
        self.metadata = {**self.metadata, "render_fps": 1}  # one frame per action (about a second of motion)
        self.action_space, self.observation_space = _spaces(self.core)
        self.state: ClopsNavState | None = None
        self.trail: list[np.ndarray] = []
        self._view: EnvView | None = None
        self._view_scene: Scene | None = None
        self.keep_frames = False
        """Set True to keep every generated frame of the last action in `last_frames` (videos, the viewer)."""
        self.last_frames: list[WandrState] = []

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.state = self.core.sample_initial_state([self.np_random], options)
        self.trail = [self._pelvis()]
        scene = self.core.render_scene(self.state)
        return self._observation(), {"goal": self.state.goal[0].cpu().numpy(), "scene": scene.name,
                                     "distance": float(self.state.distance[0])}  # fmt: skip

    def step(self, action: int | np.ndarray):
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        index = check_actions(action, (), batch=None)
        self.state, result = self.core.step(self.state, torch.as_tensor(index).reshape(1), self.keep_frames)
        self.last_frames = result.trajectory or []
        self.trail.append(self._pelvis())
        return (self._observation(), float(result.reward[0]), bool(result.terminated[0]), bool(result.truncated[0]),
                _step_info(self.state, result, 0))  # fmt: skip

    def render(self) -> np.ndarray | None:
        """rgb_array: the body in its room with the goal sphere and the pelvis trail; the egocentric view inset."""
        if self.render_mode is None or self.state is None:
            return None
        return self.render_body(self.state.body, self.state.view[0].cpu().numpy(), np.array(self.trail))

    def render_body(self, body: WandrState, view: np.ndarray, trail: np.ndarray) -> np.ndarray:
        """A frame of `body` (one frame of the current episode, e.g. from `last_frames`) with an egocentric `view`
        (5, H, W) inset and a pelvis `trail` (T, 3)."""
        scene = self.core.render_scene(self.state)
        if self._view is None or self._view_scene is not scene:
            self._view, self._view_scene = EnvView(self.core.body, *self.core.goal_marker, max_bodies=1, scene=scene), scene
        inputs = RenderInputs(body.transl, matrix_to_sixd(body.orient), matrix_to_sixd(body.shown_pose), body.joints[:, PELVIS], self.state.goal)
        return with_view_inset(self._view.frame(inputs, [trail]), view)

    def _pelvis(self) -> np.ndarray:
        return self.state.joints[0, PELVIS].cpu().numpy()

    def _observation(self) -> np.ndarray | dict[str, np.ndarray]:
        observation = self.core.observe(self.state)
        if isinstance(observation, dict):
            return {key: value[0] for key, value in observation.items()}
        return observation[0]


def _step_info(state: ClopsNavState, result: ClopsStepResult, index: int) -> dict[str, Any]:
    actions = max(int(state.actions[index]), 1)
    info: dict[str, Any] = {
        "reward_terms": {name: float(value[index]) for name, value in result.terms.items()},
        "distance": float(state.distance[index]),
        "frames": int(state.frame[index]),
        "chunk_frames": int(result.frames[index]),
        "collided": bool(result.collided[index]),
        "left_room": bool(result.left_room[index]),
        "fallen": bool(result.fallen[index]),
        "collision_rate": float(state.collided[index]) / actions,
        "foot_skating": float(state.skated[index]) / max(int(state.frame[index]), 1),
    }
    if result.terminated[index] or result.truncated[index]:
        info["is_success"] = bool(state.found[index])
    return info


class ClopsNavVectorEnv(CoreVectorEnv):
    """N bodies in one batched core (each in its own room); same-step autoreset (see `CoreVectorEnv`).
    Renders draw the first `render_bodies` bodies (default 1) in the first body's room, with its view inset."""

    def __init__(self, num_envs: int = 1, prior: ClopsPrior | None = None, render_mode: str | None = None,
                 render_bodies: int = 1, autoreset_mode: str = "same_step", **kwargs: Any) -> None:  # fmt: skip
        self.config = config_from_kwargs(ClopsNavConfig, kwargs, "ClopsNav-v0")
        core = ClopsNavCore(self.config, prior)
        super().__init__(core, num_envs, *_spaces(core), render_mode, render_bodies, autoreset_mode)
        self.metadata = {**self.metadata, "render_fps": 1}

    def render(self) -> np.ndarray | None:
        frame = super().render()
        return None if frame is None else with_view_inset(frame, self.state.view[0].cpu().numpy())

    def _step_info(self, result: ClopsStepResult) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        state = self.state
        info = {"distance": state.distance.cpu().numpy(), "collided": result.collided.cpu().numpy(),
                "left_room": result.left_room.cpu().numpy(), "fallen": result.fallen.cpu().numpy(),
                "reward_terms": {name: value.cpu().numpy() for name, value in result.terms.items()}}  # fmt: skip
        done = (result.terminated | result.truncated).cpu().numpy()
        final = {"is_success": state.found.cpu().numpy() & done,
                 "collision_rate": (state.collided.float() / state.actions.clamp_min(1).float()).cpu().numpy(),
                 "foot_skating": (state.skated.float() / state.frame.clamp_min(1).float()).cpu().numpy(),
                 "frames": state.frame.cpu().numpy(), "actions": state.actions.cpu().numpy()}  # fmt: skip
        return info, final
