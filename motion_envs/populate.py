"""`motion-envs populate`: fill a room with bodies walking between random reachable places (GAMMA's Figure 1).

Every body starts at a free place (at least `SPACING` m from the others) and
walks a planned path (`motion_envs.scenes.paths`) to a random walkable goal;
on arrival (pelvis within 0.3 m) it gets a new goal and a new path from
where it stands. All bodies step together in one `GammaWanderCore`. With
`search` (the default), each primitive is chosen by a short tree search per
body (receding horizon: `SearchSettings(max_depth=2)` by default, its first
primitive played) whose node cost prunes collisions with the room and keeps
bodies out of each other's way: the other bodies' pelvis positions at the
start of the step are the `neighbours` of the search (`SearchCost.crowd`).
Without search the proposal's latent is played as is.

Figures (`CrowdResult`): arrivals per minute of motion, collisions (share of
body-primitives with a sphere more than 2 cm into the room), interpenetration
(share of body-primitive ends at which a body's spheres overlap another
body's by more than 2 cm) and wall-clock time.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from motion_envs.body.collision_spheres import spheres_of_joints
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.envs.gamma_wander import GammaWanderConfig, GammaWanderCore, GammaWanderState
from motion_envs.rollout import Rollout, RolloutRecorder
from motion_envs.scenes.paths import nearest_walkable
from motion_envs.scenes.scene import Scene
from motion_envs.wrappers.tree_search import SearchSettings, beam_search

SPACING = 1.0
"""Least distance (m) between two bodies' start places."""
OVERLAP_TOLERANCE = 0.02
PRIMITIVE_SECONDS = 0.25
Proposal = Callable[[object, GammaWanderState], torch.Tensor]


@dataclass(frozen=True)
class CrowdResult:
    """rollout: every frame of every body (40 fps). arrivals: goals reached. collided / overlapping: shares of
    body-primitives (see the module doc). wall_seconds: time to generate. primitives: per body."""

    rollout: Rollout
    arrivals: int
    collided: float
    overlapping: float
    wall_seconds: float
    primitives: int
    bodies: int

    @property
    def motion_seconds(self) -> float:
        return self.primitives * PRIMITIVE_SECONDS

    @property
    def arrivals_per_minute(self) -> float:
        return 60.0 * self.arrivals / self.motion_seconds

    @property
    def realtime_factor(self) -> float:
        """Seconds of motion (of all bodies at once) generated per wall-clock second."""
        return self.motion_seconds / self.wall_seconds


def populate(scene: Scene, proposal: Proposal, bodies: int = 16, seconds: float = 30.0, seed: int = 0,
             search: SearchSettings | None = SearchSettings(roots=8, children=4, keep=2, max_depth=2),
             scene_spec: str = "", core: GammaWanderCore | None = None, progress: bool = True) -> CrowdResult:  # fmt: skip
    """Generate `seconds` of `bodies` bodies wandering in `scene` (see the module doc).

    `scene_spec` ("family:seed") goes into the rollout so that `motion-envs view` rebuilds the room."""
    if bodies < 1 or seconds <= 0:
        raise ValueError(f"need at least one body and a positive duration, got {bodies} bodies, {seconds} s")
    core = core or GammaWanderCore(GammaWanderConfig(max_primitives=2**62))
    slot = core.add_scene(scene)
    rng = np.random.default_rng(seed)
    starts = _spread_starts(scene, rng, bodies)
    paths = [core.plan(slot, start, _goal(scene, rng, start)) for start in starts]
    state = core.initial_state(torch.as_tensor(rng.choice(core.reach.start_rows, size=bodies)),
                               torch.as_tensor(rng.uniform(-math.pi, math.pi, size=bodies), dtype=torch.float32),
                               starts, paths, torch.full((bodies,), slot))  # fmt: skip
    recorder = RolloutRecorder(GAMMA_FPS, *core.goal_marker, env_id="motion_envs/GammaWander-v0", scene=scene_spec)
    steps = max(1, round(seconds / PRIMITIVE_SECONDS))
    arrivals, collided, overlapping = 0, 0, 0
    began = time.perf_counter()
    for _ in tqdm(range(steps), desc="populate", unit="primitive", disable=not progress):
        state = dataclasses.replace(state, neighbours=_others(state.pelvis[:, :2]))
        z = proposal(core, state) if search is None else beam_search(core, state, proposal, search).latents[:, 0]
        state, result = core.step(state, z)
        primitive = result.primitive
        for frame in torch.nonzero(primitive.new_frames()[0]).flatten().tolist():
            recorder.add(primitive.transl[:, frame], primitive.global_orient[:, frame], primitive.body_pose[:, frame], state.goal)
        collided += int(result.collided.sum())
        overlapping += int(_overlapping(primitive.joints[:, -1]).sum())
        arrived = torch.nonzero(result.reached).flatten().tolist()
        arrivals += len(arrived)
        if arrived:
            here = nearest_walkable(scene, state.pelvis[arrived, :2].cpu().numpy())
            state = core.with_paths(state, torch.tensor(arrived), [core.plan(slot, start, _goal(scene, rng, start)) for start in here])
    wall = time.perf_counter() - began
    return CrowdResult(recorder.rollout(), arrivals, collided / (steps * bodies), overlapping / (steps * bodies), wall, steps, bodies)


class CrowdView:
    """Frames of a crowd rollout in its room (walls cut away) from a fixed camera that frames the whole room."""

    def __init__(self, scene: Scene, width: int = 640, height: int = 480) -> None:
        from motion_envs.render.camera import follow_camera
        from motion_envs.render.third_person import ThirdPersonRenderer

        self.renderer = ThirdPersonRenderer(width=width, height=height, scene=scene)
        x0, y0, x1, y1 = scene.walkable_bounds
        size = max(x1 - x0, y1 - y0)
        self.camera = follow_camera(np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0]), width, height, distance=0.9 * size,
                                    height_above=0.8 * size)  # fmt: skip

    def frame(self, rollout: Rollout, index: int) -> np.ndarray:
        """(H, W, 3) uint8: every body at frame `index`, with its current goal."""
        rotations = torch.as_tensor(rollout.rotations[index])
        vertices = self.renderer.vertices(torch.as_tensor(rollout.transl[index]), rotations[:, 0], rotations[:, 1:])
        return self.renderer.render(vertices, self.camera, goal=rollout.goal[index], goal_radius=0.3)


def write_video(result: CrowdResult, scene: Scene, path: str | Path, every: int = 2, width: int = 640, height: int = 480) -> Path:
    """An mp4 of the crowd (every `every`-th frame; `CrowdView`)."""
    import imageio.v2 as imageio

    from motion_envs.atomic import atomic_path

    view, rollout = CrowdView(scene, width, height), result.rollout
    with atomic_path(path) as partial, imageio.get_writer(str(partial), fps=rollout.fps / every, macro_block_size=8) as writer:
        for index in tqdm(range(0, rollout.frames, every), desc="video", unit="frame"):
            writer.append_data(view.frame(rollout, index))
    return Path(path)


def _spread_starts(scene: Scene, rng: np.random.Generator, bodies: int, tries: int = 200) -> np.ndarray:
    """(bodies, 2) walkable places at least `SPACING` apart where the room has space (else the best of `tries`)."""
    chosen: list[np.ndarray] = []
    for _ in range(bodies):
        candidates = scene.sample_free(rng, tries)
        if chosen:
            gaps = np.linalg.norm(candidates[:, None] - np.stack(chosen)[None], axis=-1).min(axis=1)
            fits = np.nonzero(gaps >= SPACING)[0]
            candidates = candidates[fits[:1]] if len(fits) else candidates[np.argmax(gaps)][None]
        chosen.append(candidates[0])
    return np.stack(chosen)


def _goal(scene: Scene, rng: np.random.Generator, start: np.ndarray, min_distance: float = 3.0, tries: int = 100) -> np.ndarray:
    """(2,) a walkable goal at least `min_distance` from `start` (the farthest of `tries` when none is)."""
    candidates = scene.sample_free(rng, tries)
    distance = np.linalg.norm(candidates - start, axis=1)
    far = np.nonzero(distance >= min_distance)[0]
    return candidates[far[0] if len(far) else int(np.argmax(distance))]


def _others(pelvis: torch.Tensor) -> torch.Tensor:
    """(N, N - 1, 2): for each body, the other bodies' positions (N, 2)."""
    count = len(pelvis)
    others = ~torch.eye(count, dtype=torch.bool, device=pelvis.device)
    return pelvis[None].expand(count, -1, -1)[others].reshape(count, count - 1, 2)


def _overlapping(joints: torch.Tensor) -> torch.Tensor:
    """(N,) bool: bodies (joints (N, 22, 3)) whose collision spheres overlap another body's by > 2 cm."""
    centres, radii = spheres_of_joints(joints)  # (N, S, 3), (S,)
    count, spheres = centres.shape[:2]
    gaps = torch.cdist(centres.reshape(-1, 3), centres.reshape(-1, 3)) - (radii.repeat(count)[:, None] + radii.repeat(count)[None])
    owner = torch.arange(count, device=joints.device).repeat_interleave(spheres)
    gaps = gaps.masked_fill(owner[:, None] == owner[None], math.inf)
    return (gaps < -OVERLAP_TOLERANCE).reshape(count, spheres, -1).any(-1).any(-1)
