"""Wandering in scenes: the path planner, GammaWander-v0, collision-aware tree search, crowds and the room view."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import torch
import trimesh
from gymnasium.utils.env_checker import check_env

import motion_envs  # noqa: F401  (registers the ids)
from baselines.latent_controllers import RandomLatent
from motion_envs.body.markers import MARKER_NAMES
from motion_envs.body.skeleton import joint_index
from motion_envs.envs.gamma_wander import GammaWanderConfig, GammaWanderCore, GammaWanderEnv
from motion_envs.metrics import loaded_slide
from motion_envs.priors.gamma_generator import GammaGenerator
from motion_envs.scenes import FAMILIES, TEST_SEEDS, Scene, ScenePart, make_scene
from motion_envs.scenes.labels import label_id
from motion_envs.scenes.paths import UnreachableGoal, nearest_walkable, plan_path
from motion_envs.wrappers.tree_search import SearchCost, SearchSettings, beam_search

ENV_ID = "motion_envs/GammaWander-v0"


@pytest.fixture(scope="module")
def gamma() -> GammaGenerator:
    return GammaGenerator.load()


def _walkable_at(scene: Scene, points: np.ndarray) -> np.ndarray:
    cells = np.floor((points - scene.grid.origin[:2]) / scene.grid.pitch).astype(int)
    return scene.walkable[cells[:, 0], cells[:, 1]]


@pytest.mark.parametrize("family", list(FAMILIES))
def test_planned_paths_stay_in_free_space_and_join_start_and_goal(family):
    scene = make_scene(family, TEST_SEEDS[3])
    rng = np.random.default_rng(0)
    for _ in range(3):
        start, goal = scene.sample_start_goal(rng, 3.0)
        path = plan_path(scene, start, goal, spacing=1.5)
        route = np.concatenate([start[None], path.waypoints])
        np.testing.assert_allclose(route[-1], goal)
        legs = np.linalg.norm(np.diff(route, axis=0), axis=1)
        assert legs.max() <= 1.5 + 1e-6 and path.length >= np.linalg.norm(goal - start) - 1e-6
        dense = np.concatenate([a + np.outer(np.linspace(0, 1, 40), b - a) for a, b in zip(route[:-1], route[1:])])
        assert _walkable_at(scene, dense).all()  # every point of every leg keeps the body's 0.25 m clearance
        clearance = scene.grid.query(torch.as_tensor(np.c_[dense, np.full(len(dense), 1.0)], dtype=torch.float32))
        assert float(clearance.min()) >= 0.25 - scene.grid.pitch


def test_a_goal_inside_furniture_or_a_sealed_room_raises():
    scene = make_scene("living", TEST_SEEDS[0])
    table = next(part.mesh for part in scene.parts if part.label == label_id("table"))
    start = scene.sample_free(np.random.default_rng(1), 1)[0]
    with pytest.raises(UnreachableGoal, match="not on the walkable floor"):
        plan_path(scene, start, table.bounds[:, :2].mean(axis=0))
    walls = [trimesh.creation.box(extents=(0.1, 4.0, 2.5), transform=trimesh.transformations.translation_matrix((x, 2.0, 1.25)))
             for x in (0.0, 2.0, 4.0, 7.0)] + [trimesh.creation.box(extents=(7.0, 0.1, 2.5),  # fmt: skip
             transform=trimesh.transformations.translation_matrix((3.5, y, 1.25))) for y in (0.0, 4.0)]
    sealed = Scene([ScenePart(wall, label_id("wall")) for wall in walls], "sealed rooms")
    with pytest.raises(UnreachableGoal, match="sealed rooms"):  # the 2 x 4 m room is not the largest one
        plan_path(sealed, np.array([5.5, 2.0]), np.array([1.0, 2.0]))
    inside, in_wall = nearest_walkable(sealed, np.array([[5.5, 2.0], [4.0, 2.0]]))
    assert np.linalg.norm(inside - [5.5, 2.0]) <= 0.71 * sealed.pitch  # a walkable point stays (its cell's centre)
    assert _walkable_at(sealed, in_wall[None])[0] and 0.25 <= in_wall[0] - 4.0 <= 0.25 + 2 * sealed.pitch


def test_waypoints_advance_within_075_m_and_the_last_counts_within_03_m(gamma):
    """At every step of a walk along 5 waypoints, the current waypoint advances exactly when the pelvis ends the
    primitive within 0.75 m of it, and the episode succeeds exactly when it ends within 0.3 m of the last (the
    shipped GammaReach policy, deterministic, passes 2 of the 4 turns within 60 primitives here)."""
    from agents.controllers import PolicyLatent
    from motion_envs.priors.training import WEIGHTS_DIR

    policy = PolicyLatent(WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip", deterministic=True)
    env = GammaWanderEnv(generator=gamma, scene="flat", max_primitives=60)
    waypoints = np.array([[1.5, 0.0], [3.0, 0.0], [3.0, 1.5], [1.5, 1.5], [1.5, 3.0]])
    env.reset(seed=0, options={"start": [0.0, 0.0], "waypoints": waypoints, "start_index": 0})
    current, advanced, terminated, truncated = 0, 0, False, False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(policy(env.core, env.state)[0].numpy())
        gap = float(np.linalg.norm(env.state.pelvis[0, :2].numpy() - waypoints[current]))
        if current < len(waypoints) - 1:
            assert (info["waypoint"] == current + 1) == (gap <= 0.75) and not terminated
            advanced += info["waypoint"] - current
        else:
            assert terminated == (gap <= 0.3) and info["waypoint"] == current
        current = info["waypoint"]
    assert advanced >= 2 and truncated != terminated  # the shipped GammaReach policy follows waypoints (slowly)


def test_env_checker_vector_equals_single_and_renders_the_room_and_path(gamma):
    for scene in ("flat", "living"):
        check_env(GammaWanderEnv(generator=gamma, scene=scene), skip_render_check=True)
    vector = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", generator=gamma, scene="mixed")
    observations, _ = vector.reset(seed=5)
    latents = np.random.default_rng(6).standard_normal((2, 128)).astype(np.float32)
    vector_step = vector.step(latents)
    for i in range(2):
        single = GammaWanderEnv(generator=gamma, scene="mixed", render_mode="rgb_array")
        observation, info = single.reset(seed=5 + i)
        np.testing.assert_allclose(observation, observations[i], atol=1e-5)
        np.testing.assert_array_equal(info["waypoints"], vector.unwrapped.state.waypoints[i, : len(info["waypoints"])].numpy())
        _, reward, _, _, step_info = single.step(latents[i])
        assert reward == pytest.approx(float(vector_step[1][i]), rel=1e-4, abs=1e-6)
        assert step_info["distance"] == pytest.approx(float(vector_step[4]["distance"][i]), abs=1e-4)
    image = single.render()
    assert image.shape == (360, 480, 3) and image.std() > 10
    path_blue = (image[..., 2] > 200) & (image[..., 0] < 80)
    assert path_blue.sum() > 5  # the planned route is drawn


def _table_scene() -> Scene:
    """A room 8 x 6 m with one long table across its middle (from wall to 1 m short of the far wall)."""
    room = [((4.0, 0.0), (8.0, 0.1)), ((4.0, 6.0), (8.0, 0.1)), ((0.0, 3.0), (0.1, 6.0)), ((8.0, 3.0), (0.1, 6.0))]
    parts = [ScenePart(trimesh.creation.box(extents=(*size, 2.5), transform=trimesh.transformations.translation_matrix((*centre, 1.25))),
                       label_id("wall")) for centre, size in room]  # fmt: skip
    table = trimesh.creation.box(extents=(0.8, 4.5, 0.75), transform=trimesh.transformations.translation_matrix((4.0, 2.25, 0.375)))
    floor = trimesh.Trimesh([[0, 0, 0], [8, 0, 0], [8, 6, 0], [0, 6, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    return Scene([*parts, ScenePart(table, label_id("table")), ScenePart(floor, label_id("floor"))], "table room")


def test_the_search_prunes_branches_that_walk_into_a_table(gamma):
    """The goal lies straight across a table. Half of each node's children follow the GammaReach policy (which walks
    straight at it, through the table), half are random latents: with the scene terms the chosen branches avoid the
    table; ranked by distance alone (no collision or clearance term) they walk into it. Collisions are counted on the
    branches as searched (`found.collisions`): a replay one body at a time is not guaranteed to be bit-identical to
    the search in a batch of 64 (bf16 kernels on AMX CPUs may sum in another order per batch size)."""
    from agents.controllers import PolicyLatent
    from motion_envs.priors.training import WEIGHTS_DIR

    core = GammaWanderCore(GammaWanderConfig(scene="flat"), gamma)
    slot = core.add_scene(_table_scene())
    start = core.initial_state(torch.tensor([0]), torch.tensor([0.0]), np.array([[3.0, 2.0]]),
                               [np.array([[5.4, 2.0]])], torch.tensor([slot]))  # fmt: skip
    policy = PolicyLatent(WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip", deterministic=True)
    collisions = {}
    for scene_terms in (True, False):
        collisions[scene_terms] = 0
        for seed in range(8):
            random = RandomLatent(seed)

            def half_policy(core, state):
                straight, other = policy(core, state), random(core, state)
                return torch.where((torch.arange(len(straight)) % 2 == 0)[:, None], straight, other)

            cost = SearchCost.distance_only()
            if not scene_terms:
                cost = dataclasses.replace(cost, collision=0.0, clearance=0.0)
            found = beam_search(core, start, half_policy, SearchSettings(roots=16, children=4, keep=4, max_depth=8, cost=cost))
            collisions[scene_terms] += int(found.collisions[0])
    # measured (8 searches of 8 primitives, AMX Xeon, bf16): with the scene terms 0; without 13 with the foot rule,
    # 17 without it (the upright policy of f7e59dd; 30-31 with the policy before it)
    assert collisions[False] >= 8 and collisions[True] <= collisions[False] / 4, collisions


def test_collision_clearance_speeding_stooping_and_skating_penalties_are_paid_in_proportion(gamma):
    """A body walking straight through a table: the same latents with and without the penalties move it alike (the
    reward does not feed back into the motion), and the rewards differ by exactly collision_penalty per colliding
    primitive, clearance_penalty per metre inside the margin, speeding per frame and m/s that the pelvis is
    faster than walk_speed (0.5 m/s here, so that an ordinary walk pays it), stooping per frame and metre that
    the head is lower than upright_head (1.6 m here, for the same reason) and skating per frame and m/s that the
    loaded heel or toe marker slides beyond 0.2 m/s."""
    from agents.controllers import PolicyLatent
    from motion_envs.priors.training import WEIGHTS_DIR

    policy = PolicyLatent(WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip", deterministic=True)
    rewards, results = {}, {}
    for paid in (False, True):
        config = GammaWanderConfig(scene="flat", collision_penalty=4.0 * paid, clearance_penalty=10.0 * paid,
                                   speeding=2.0 * paid, walk_speed=0.5, stooping=3.0 * paid, upright_head=1.6,
                                   skating=5.0 * paid, precision="float32")  # fmt: skip
        core = GammaWanderCore(config, gamma)
        slot = core.add_scene(_table_scene())
        state = core.initial_state(torch.tensor([0]), torch.tensor([0.0]), np.array([[3.3, 2.0]]),
                                   [np.array([[5.4, 2.0]])], torch.tensor([slot]))  # fmt: skip
        rewards[paid], results[paid] = [], []
        # the body starts 30 cm from the table's edge, so that it collides however the shipped policy walks: measured
        # (fp32, policy of 116f67a) in 17 of the 18 primitives, faster than 0.5 m/s in 13, head below 1.6 m in all,
        # a loaded marker sliding in 17 (from 3.0 m it dawdled and turned away, colliding in none)
        for _ in range(18):
            state, result = core.step(state, policy(core, state))
            rewards[paid].append(result.reward)
            results[paid].append(result)
    clearance = torch.cat([result.clearance for result in results[True]])
    collided = torch.cat([result.collided for result in results[True]])
    assert torch.equal(clearance, torch.cat([result.clearance for result in results[False]]))
    assert collided.sum() >= 2 and torch.isfinite(clearance).all()
    over, low, slid = [], [], []
    for result in results[True]:
        pelvis = result.primitive.joints[:, :, 0, :2].double()
        speed = (pelvis[:, 1:] - pelvis[:, :-1]).norm(dim=-1) * 40.0
        new = torch.arange(1, pelvis.shape[1]) >= result.primitive.seed_frames[:, None]
        over.append(((speed - 0.5).clamp(min=0.0) * new).sum(dim=1).float())
        head = result.primitive.joints[:, :, joint_index("head"), 2].double()
        low.append(((1.6 - head).clamp(min=0.0) * result.primitive.new_frames()).sum(dim=1).float())
        soles = result.primitive.reprojected_markers[:, :, [MARKER_NAMES.index(name) for name in ("LHEE", "LTOE", "RHEE", "RTOE")]]
        slid.append((loaded_slide(soles, 40.0) * result.primitive.new_frames()[:, 1:]).sum(dim=1))
    over, low, slid = torch.cat(over), torch.cat(low), torch.cat(slid)
    assert (over > 0).sum() >= 6, over  # the body walks faster than 0.5 m/s in most primitives
    assert (low > 0).sum() >= 6, low  # and its head is lower than 1.6 m
    assert (slid > 0).sum() >= 3, slid  # and a planted foot slides now and then
    expected = 4.0 * collided.float() + 10.0 * (0.1 - clearance).clamp(min=0.0) + 2.0 * over + 3.0 * low + 5.0 * slid
    assert torch.allclose(torch.cat(rewards[False]) - torch.cat(rewards[True]), expected, atol=1e-3)
    with pytest.raises(ValueError, match="clearance_penalty"):
        GammaWanderConfig(clearance_penalty=-1.0)
    with pytest.raises(ValueError, match="walk_speed"):
        GammaWanderConfig(walk_speed=0.0)
    with pytest.raises(ValueError, match="stooping"):
        GammaWanderConfig(stooping=-1.0)


def test_populate_end_to_end_writes_a_rollout_a_video_and_views_from_above(tmp_path):
    import subprocess
    import sys

    from motion_envs.rollout import Rollout
    from motion_envs.viewer import CUTAWAY_HEIGHT, opening_camera

    command = [sys.executable, "-m", "motion_envs.cli", "populate", "--scene", "living:1003", "--bodies", "3", "--seconds", "1",
               "--video", str(tmp_path / "crowd.mp4"), "--save-rollout", str(tmp_path / "crowd.npz")]  # fmt: skip
    printed = subprocess.run(command, capture_output=True, text=True, timeout=300, check=True).stdout
    assert "3 bodies, 1.0 s of motion" in printed and "arrivals" in printed
    rollout = Rollout.load(tmp_path / "crowd.npz")
    assert rollout.bodies == 3 and rollout.frames >= 4 * 8 and rollout.scene == "living:1003"
    assert (tmp_path / "crowd.mp4").stat().st_size > 10_000
    scene = make_scene("living", 1003)
    pelvis = rollout.transl[0]
    eye, look = (np.array(v) for v in opening_camera(pelvis, in_scene=True))
    cut = trimesh.util.concatenate([part.mesh for part in scene.cutaway(CUTAWAY_HEIGHT)])
    head = pelvis + [0.0, 0.0, 0.7]
    directions = (head - eye) / np.linalg.norm(head - eye, axis=1, keepdims=True)
    hits = [np.linalg.norm(cut.ray.intersects_location([eye], [d])[0] - eye, axis=1) for d in directions]
    assert all(len(h) == 0 or h.min() > np.linalg.norm(p - eye) for h, p in zip(hits, head))  # every head in view
    assert eye[2] > 2.5 and np.linalg.norm(look[:2] - pelvis[:, :2].mean(axis=0)) < 0.1  # above the walls, on the bodies


def test_live_episodes_feed_the_viewer_gamma_wander_primitives_in_one_room():
    """`motion-envs view --env motion_envs/GammaWander-v0` plays GammaWander (not GammaReach) in one held-out
    room that every chunk names, across the end of an episode."""
    from motion_envs.play import LiveEpisodes

    live = LiveEpisodes("motion_envs/GammaWander-v0", seed=0, env_kwargs={"scene": "living", "max_primitives": 3})
    assert isinstance(live.env, GammaWanderEnv)
    chunks = [live.more() for _ in range(3)]  # 5 primitives (8 new frames each) a chunk: episodes end inside chunks
    assert all(len(chunk.transl) >= 40 for chunk in chunks)  # about a second of 40 fps frames each
    assert {chunk.scene for chunk in chunks} == {f"living:{TEST_SEEDS[0]}"}
    assert live.seed >= 2  # later episodes began, in the same room
