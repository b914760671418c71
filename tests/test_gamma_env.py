"""GammaReach-v0 on the shipped GAMMA weights: spaces, checker, state clone/restore, blending, bad input."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

import motion_envs  # noqa: F401  (registers the ids)
from motion_envs.body.markers import MARKER_NAMES, marker_ids
from motion_envs.body.skeleton import joint_index
from motion_envs.envs.gamma_reach import OBSERVATION_SIZE, GammaReachEnv
from motion_envs.metrics import loaded_slide
from motion_envs.priors.checkpoint import CheckpointMismatchError
from motion_envs.priors.gamma_generator import GammaGenerator
from motion_envs.priors.train_gamma import load_predictor
from motion_envs.priors.training import WEIGHTS_DIR

ENV_ID = "motion_envs/GammaReach-v0"


@pytest.fixture(scope="module")
def gamma() -> GammaGenerator:
    return GammaGenerator.load()


@pytest.fixture
def env(gamma) -> GammaReachEnv:
    return GammaReachEnv(generator=gamma)


def _latents(count: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal((count, 128)).astype(np.float32)


def test_spaces_and_env_checker(env):
    assert env.action_space.shape == (128,) and env.action_space.dtype == np.float32
    assert env.observation_space.shape == (OBSERVATION_SIZE,) and env.observation_space.dtype == np.float32
    check_env(env, skip_render_check=True)
    observation, info = env.reset(seed=3)
    assert observation.dtype == np.float32 and env.observation_space.contains(observation)
    assert info["distance"] >= env.config.min_goal_distance


def test_gym_make_and_kwargs():
    env = gym.make(ENV_ID, reward="release", max_primitives=5)
    assert env.unwrapped.config.reward.orientation == 0.5 and env.unwrapped.config.max_primitives == 5
    with pytest.raises(TypeError, match=r"unknown arguments \['max_steps'\]"):
        gym.make(ENV_ID, max_steps=5)
    with pytest.raises(ValueError, match="start_kind"):
        gym.make(ENV_ID, start_kind="running")


def test_observation_is_the_papers_state(env):
    observation, _ = env.reset(seed=0, options={"goal": (0.0, 5.0), "facing": 0.0, "start_index": 0})
    state = observation.reshape(2, 67, 6)
    assert np.allclose(state[0], state[1])  # one-frame seed fills both slots
    assert np.allclose(np.linalg.norm(state[..., 3:], axis=-1), 1.0, atol=1e-5)
    assert np.abs(state[0, :, :2]).max() < 1.2  # markers around the canonical pelvis


def test_reward_terms_lie_in_unit_interval_and_sum_to_the_reward(gamma):
    """GAMMA's five terms lie in [0, 1]; the reward is their weighted sum plus the settlement, the absorbing payment,
    `stooping` times minus the metres the head is below `upright_head` over the new frames (1.7 m here, so that
    every frame pays; the start bodies' heads are at about 1.5 m) and `skating` times minus the m/s the loaded heel
    or toe marker slides beyond 0.2 m/s (random latents skate on the regressor's bodies; the foot rule would hold
    them, `tests/test_foot_lock.py`)."""
    env = GammaReachEnv(generator=gamma, stooping=2.0, upright_head=1.7, skating=0.5, precision="float32", lock_feet=False)
    slid = 0.0
    env.reset(seed=1)
    weights = env.config.reward
    for z in _latents(6, 1):
        _, reward, terminated, _, info = env.step(z)
        terms = info["reward_terms"]
        for name in ("path", "orientation", "contact", "pose_prior", "goal"):
            assert 0.0 <= terms[name] <= 1.0, name
        primitive = env.last_primitive
        head = primitive.joints[0, :, joint_index("head"), 2].double()
        drop = ((1.7 - head) * primitive.new_frames()[0]).sum().item()
        assert drop > 0.5 and terms["stooping"] == pytest.approx(-drop, rel=1e-4)
        soles = primitive.reprojected_markers[0][:, [MARKER_NAMES.index(name) for name in ("LHEE", "LTOE", "RHEE", "RTOE")]]
        slide = loaded_slide(soles, 40.0) * primitive.new_frames()[0, 1:]
        assert terms["skating"] == pytest.approx(-slide.sum().item(), rel=1e-4, abs=1e-6)
        slid += slide.sum().item()
        expected = sum(getattr(weights, name) * terms[name] for name in ("path", "orientation", "contact", "pose_prior", "goal"))
        expected += weights.goal * terms["goal_settlement"] + terms["goal_absorbing"] + 2.0 * terms["stooping"] + 0.5 * terms["skating"]
        assert reward == pytest.approx(expected, rel=1e-5)
        assert 0.0 < info["contact_score"] <= 1.0
    assert slid > 0.1, slid
    with pytest.raises(ValueError, match="stooping"):
        GammaReachEnv(generator=gamma, stooping=-1.0)


def test_clone_and_restore_give_identical_next_steps(env):
    env.reset(seed=2)
    for z in _latents(3, 2):
        env.step(z)
    saved = env.state.clone()
    following = _latents(3, 3)
    first = [env.step(z) for z in following]
    env.state = saved
    second = [env.step(z) for z in following]
    for (obs_a, reward_a, *_), (obs_b, reward_b, *_) in zip(first, second):
        assert np.array_equal(obs_a, obs_b) and reward_a == reward_b


def test_state_repeats_into_clones_that_step_together(gamma):
    env = GammaReachEnv(generator=gamma)
    env.reset(seed=4)
    clones = env.state.repeat(8)
    assert clones.num_bodies == 8 and torch.equal(clones.index(torch.tensor([5])).goal, env.state.goal)
    next_state, result = env.core.step(clones, torch.as_tensor(_latents(8, 4)))
    assert result.reward.shape == (8,) and next_state.steps.tolist() == [1] * 8
    assert len({round(float(d), 4) for d in result.distance}) > 1  # different latents, different motion


def test_markers_are_the_blend_of_prediction_and_the_regressed_body(gamma, body):
    """Without the foot rule the bodies are the regressor's, and the markers their blend with the prediction (with
    it the blend is the same, `tests/test_foot_lock.py`)."""
    env = GammaReachEnv(generator=gamma, lock_feet=False)
    env.reset(seed=5)
    for z in _latents(3, 5):
        env.step(z)
    primitive = env.last_primitive
    posed = body(primitive.transl, primitive.global_orient, primitive.body_pose)
    skinned = body.skin(posed, marker_ids())
    new = primitive.new_frames()[0]
    assert torch.allclose(skinned[0, new], primitive.reprojected_markers[0, new], atol=1e-4)
    gap = (primitive.markers - skinned)[0, new].norm(dim=-1)
    half_prediction_gap = 0.5 * (primitive.predicted_markers - skinned)[0, new].norm(dim=-1)
    assert torch.allclose(gap, half_prediction_gap, atol=1e-4)
    assert gap.mean() < 0.05  # the regressed body stays within a few cm of its markers


def test_latents_longer_than_latent_radius_are_scaled_to_it_and_shorter_ones_kept(gamma):
    """A box corner (norm 45) steps as the same direction at norm 16 (`latent_radius`); z ~ N(0, I) (norm ~11)
    steps exactly as with no cap (the scale is exactly 1 there)."""
    import dataclasses

    capped = GammaReachEnv(generator=gamma)
    capped.reset(seed=6)
    free = GammaReachEnv(generator=gamma, latent_radius=None)
    corner = torch.where(torch.as_tensor(_latents(1, 6)) > 0, 4.0, -4.0)
    normal = torch.as_tensor(_latents(1, 7))
    start = capped.state.repeat(2)
    _, cornered = capped.core.step(start, torch.cat([corner, corner * (16.0 / corner.norm())]))
    assert torch.allclose(cornered.primitive.joints[0], cornered.primitive.joints[1], atol=1e-4)
    _, with_cap = capped.core.step(start.index(torch.tensor([0])), normal)
    _, without = free.core.step(start.index(torch.tensor([0])), normal)
    assert torch.equal(with_cap.primitive.joints, without.primitive.joints)
    _, uncapped_corner = free.core.step(start.index(torch.tensor([0])), corner)
    assert not torch.allclose(uncapped_corner.primitive.joints, cornered.primitive.joints[:1], atol=1e-2)
    with pytest.raises(ValueError, match="latent_radius"):
        dataclasses.replace(capped.config, latent_radius=0.0)


def test_bad_actions_raise_clear_errors(env):
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(128,\)"):
        env.step(np.zeros(64, dtype=np.float32))
    bad = np.zeros(128, dtype=np.float32)
    bad[7] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(bad)
    bad[7] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(bad)


def test_a_reached_goal_terminates_with_success_and_pays_the_remaining_steps(gamma):
    env = GammaReachEnv(generator=gamma, goal_radius=3.0, max_primitives=10)
    env.reset(seed=0, options={"goal": (0.0, 1.0), "start_index": 0, "facing": 0.0})
    _, reward, terminated, truncated, info = env.step(np.zeros(128, dtype=np.float32))
    assert terminated and not truncated and info["is_success"] and info["reward_terms"]["goal"] == 1.0
    assert info["reward_terms"]["goal_absorbing"] == pytest.approx(9 * env.config.reward.best_step_reward)
    far = GammaReachEnv(generator=gamma, max_primitives=2, terminate_on_goal=False)
    far.reset(seed=0, options={"goal": (9.0, 9.0)})
    far.step(np.zeros(128, dtype=np.float32))
    _, _, terminated, truncated, info = far.step(np.zeros(128, dtype=np.float32))
    assert truncated and not terminated and info["is_success"] is False


def test_vector_env_matches_single_envs_with_the_same_seeds(gamma):
    vector = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", generator=gamma)
    observations, _ = vector.reset(seed=10)
    latents = _latents(3, 11)
    vector_step = vector.step(latents)
    for i in range(3):
        single = GammaReachEnv(generator=gamma)
        observation, _ = single.reset(seed=10 + i)
        assert np.allclose(observation, observations[i], atol=1e-5)
        _, reward, *_ = single.step(latents[i])
        assert reward == pytest.approx(float(vector_step[1][i]), rel=1e-4)


def test_vector_env_resets_finished_bodies_in_the_same_step(gamma):
    vector = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", generator=gamma, max_primitives=2)
    vector.reset(seed=0)
    vector.step(_latents(2, 0))
    _, _, terminated, truncated, info = vector.step(_latents(2, 1))
    assert (terminated | truncated).all()
    assert info["_final_obs"].all() and info["final_obs"][0].shape == (OBSERVATION_SIZE,)
    assert info["final_obs"][0].dtype == np.float32
    assert vector.unwrapped.state.steps.tolist() == [0, 0]


def test_weights_of_another_model_fail_clearly():
    with pytest.raises(CheckpointMismatchError, match="expected 'gamma_predictor'"):
        load_predictor(WEIGHTS_DIR / "gamma_regressor.pt")
    one = load_predictor(WEIGHTS_DIR / "gamma_predictor_1f.pt")
    with pytest.raises(ValueError, match="predictor_1f must take 1 seed frame"):
        GammaGenerator(one, one, None, None)


def test_stable_baselines3_ppo_runs_on_the_env(gamma):
    from stable_baselines3 import PPO

    env = GammaReachEnv(generator=gamma, max_primitives=8)
    model = PPO("MlpPolicy", env, n_steps=16, batch_size=16, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=32)
    observation, _ = env.reset(seed=0)
    action, _ = model.predict(observation, deterministic=True)
    assert action.shape == (128,) and env.action_space.contains(action)


def test_generator_steps_mixed_one_and_two_frame_seeds_as_separate_batches(gamma):
    env = GammaReachEnv(generator=gamma)
    env.reset(seed=6)
    started = env.state.seed  # one-frame seed
    _, moving = gamma.step(started, torch.as_tensor(_latents(1, 6)))  # two-frame seed
    mixed = type(started).cat([started, moving])
    z = torch.as_tensor(_latents(2, 7))
    together, _ = gamma.step(mixed, z)
    alone_one, _ = gamma.step(started, z[:1])
    alone_two, _ = gamma.step(moving, z[1:])
    assert torch.allclose(together.markers[0], alone_one.markers[0], atol=1e-5)
    assert torch.allclose(together.markers[1], alone_two.markers[0], atol=1e-5)
    assert together.new_frames().sum(dim=1).tolist() == [9, 8]


def test_floor_rule_puts_every_new_frames_lowest_sole_point_on_the_ground_and_moves_only_height(gamma, body):
    """`ground_feet` shifts each new frame vertically and nothing else, so that the soles' rims touch the floor and
    no foot vertex is below it (the rims stand in for the whole foot's hull); without it the raw prior drifts."""
    from motion_envs.body.markers import foot_vertex_ids
    from motion_envs.body.soles import sole_hull_vertex_ids

    env = GammaReachEnv(generator=gamma, precision="float32")
    env.reset(seed=8)
    seed = env.state.seed
    z = 3.0 * torch.as_tensor(_latents(1, 8))  # far latents: the raw prior leaves the floor
    raw, _ = gamma.step(seed, z)
    grounded, _ = gamma.step(seed, z, ground_feet=True)
    new = grounded.new_frames()[0]

    def lowest(primitive, vertex_ids):
        posed = body(primitive.transl[0], primitive.global_orient[0], primitive.body_pose[0])
        return body.skin(posed, vertex_ids)[..., 2].amin(-1)  # (10,)

    assert torch.allclose(lowest(grounded, sole_hull_vertex_ids())[new], torch.zeros(int(new.sum())), atol=1e-5)
    assert lowest(grounded, foot_vertex_ids())[new].min() > -0.005
    assert lowest(raw, sole_hull_vertex_ids())[new].abs().max() > 0.01  # the rule had something to do
    shift = grounded.joints - raw.joints
    assert torch.allclose(shift[..., :2], torch.zeros_like(shift[..., :2]), atol=1e-5)
    assert torch.allclose(shift[..., 2], shift[..., :1, 2].expand_as(shift[..., 2]), atol=1e-5)  # one height a frame
    assert torch.equal(grounded.body_pose, raw.body_pose)


def test_start_bodies_stand_on_the_ground(env, body):
    from motion_envs.body.markers import foot_vertex_ids

    core = env.core
    posed = body(core.start_transl, core.start_orient, core.start_pose)
    lowest = body.skin(posed, foot_vertex_ids())[..., 2].amin(dim=-1)
    assert lowest.abs().max() < 1e-4


def test_an_episodes_goal_reward_sums_to_the_papers(gamma):
    env = GammaReachEnv(generator=gamma, max_primitives=4, terminate_on_goal=False)
    env.reset(seed=8)
    paid = 0.0
    for z in _latents(4, 8):
        _, _, _, truncated, info = env.step(z)
        paid += info["reward_terms"]["goal"] + info["reward_terms"]["goal_settlement"]
    assert truncated
    assert paid == pytest.approx(4 * info["reward_terms"]["goal"], rel=1e-5)  # T · r_goal(closest of the episode)


def test_bf16_is_chosen_only_where_the_cpu_has_it_and_agrees_with_fp32(gamma, monkeypatch):
    from motion_envs import precision

    monkeypatch.setattr(precision, "cpu_flags", lambda: frozenset({"avx2", "fma"}))  # an AVX2-only EPYC
    assert GammaReachEnv(generator=gamma).core.generator.precision == "float32"
    assert GammaReachEnv(generator=gamma, precision="bfloat16").core.generator.precision == "bfloat16"  # explicit wins
    monkeypatch.setattr(precision, "cpu_flags", lambda: frozenset({"avx2", "avx512f", "avx512_bf16", "amx_bf16"}))
    assert GammaReachEnv(generator=gamma).core.generator.precision == "bfloat16"
    assert GammaReachEnv(generator=gamma, precision="float32").core.generator.precision == "float32"
    with pytest.raises(ValueError, match="precision"):
        GammaReachEnv(generator=gamma, precision="fp8")
    monkeypatch.undo()  # the comparison runs on this machine's real CPU (bf16 emulated where it has no bf16 units)
    pelvis = {}
    for name in ("float32", "bfloat16"):  # one primitive from the same start: bf16's 3 digits move it by millimetres
        env = GammaReachEnv(generator=gamma, precision=name)
        env.reset(seed=3)
        env.step(_latents(1, 5)[0])
        pelvis[name] = env.state.seed.joints[0, -1, 0]
    assert 0 < (pelvis["float32"] - pelvis["bfloat16"]).norm() < 0.02


def test_body_mirror_is_the_training_datas_mirror_image(body):
    """`body.mirror` mirrors a pose as `data.mirror` mirrors the training clips (the prior learnt both), and
    mirroring twice gives the pose back."""
    from motion_envs.body.mirror import mirror_body_pose, mirror_points, mirror_rotations
    from motion_envs.body.rotations import rotation_matrix
    from motion_envs.data.mirror import mirror
    from motion_envs.data.motion import BodyMotion

    rng = np.random.default_rng(0)
    motion = BodyMotion(name="clip", subject="s", fps=40.0, transl=rng.normal(size=(3, 3)), global_orient=rng.normal(size=(3, 3)) * 0.5,
                        body_pose=rng.normal(size=(3, 21, 3)) * 0.3)  # fmt: skip
    mirrored = mirror(motion)
    pose = rotation_matrix(torch.as_tensor(motion.body_pose, dtype=torch.float32))
    orient = rotation_matrix(torch.as_tensor(motion.global_orient, dtype=torch.float32))
    expected = rotation_matrix(torch.as_tensor(mirrored.body_pose, dtype=torch.float32))
    assert torch.allclose(mirror_body_pose(pose), expected, atol=1e-5)
    assert torch.allclose(mirror_rotations(orient), rotation_matrix(torch.as_tensor(mirrored.global_orient, dtype=torch.float32)), atol=1e-5)
    assert torch.allclose(mirror_points(torch.as_tensor(motion.transl)), torch.as_tensor(mirrored.transl))
    assert torch.allclose(mirror_body_pose(mirror_body_pose(pose)), pose)


def test_a_mirrored_primitive_is_the_mirror_image_of_the_mirror_images_own(gamma):
    """`step(..., mirror=...)` makes the primitive of the seed's mirror image and mirrors it back: a body seeded with
    a start pose and mirrored moves as the mirror image of the same latent's primitive from the mirrored start
    pose (to the skeleton's own left/right asymmetry, which moves the canonical frame by a fraction of a degree)."""
    from motion_envs.body.mirror import mirror_body_pose, mirror_points, mirror_rotations
    from motion_envs.body.rotations import matrix_to_sixd, rotation_matrix
    from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore

    core = GammaReachCore(GammaReachConfig(), gamma)
    count = 8
    orient = rotation_matrix(core.start_orient[:count])
    pose = rotation_matrix(core.start_pose[:count])
    transl = core.start_transl[:count] * torch.tensor([0.0, 0.0, 1.0])
    seed = gamma.seed_from_bodies(transl, matrix_to_sixd(orient), matrix_to_sixd(pose))
    twin = gamma.seed_from_bodies(mirror_points(transl), matrix_to_sixd(mirror_rotations(orient)), matrix_to_sixd(mirror_body_pose(pose)))
    z = torch.as_tensor(_latents(count, 3))
    mirrored, _ = gamma.step(seed, z, mirror=torch.ones(count, dtype=torch.bool))
    plain, _ = gamma.step(twin, z)
    # pelvis paths in the world (both start at the origin facing their own way; the twin is the reflection in x = 0)
    path, twin_path = mirrored.joints[:, :, 0] - mirrored.joints[:, :1, 0], plain.joints[:, :, 0] - plain.joints[:, :1, 0]
    assert (path - mirror_points(twin_path)).norm(dim=-1).max() < 0.03
    assert twin_path[:, -1].norm(dim=-1).max() > 0.05  # the primitives move
    wrong_way = (path - twin_path).norm(dim=-1).max()
    assert wrong_way > 2 * (path - mirror_points(twin_path)).norm(dim=-1).max()


def test_mirroring_right_goals_lets_the_shipped_policy_turn_right(gamma):
    """The shipped alpha = 1 policy turns left far more readily than right (the prior's bias); goals 100° to the
    right and 6 m away, 24 bodies, 30 primitives (6 s): with `mirror_right_goals` they live in their mirror image,
    where the goal is on the left, and many more of them arrive."""
    from agents.controllers import PolicyLatent
    from benchmarks.gamma_turns import starts
    from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore

    policy = WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip"
    arrived = {}
    for on in (False, True):
        core = GammaReachCore(GammaReachConfig(mirror_right_goals=on), gamma)
        state = starts(core, 24, seed=0, bearing=torch.full((24,), -math.radians(100.0)), distance=torch.full((24,), 6.0))
        assert bool(state.mirrored.all()) is on
        act, reached = PolicyLatent(policy, seed=0), torch.zeros(24, dtype=torch.bool)
        for _ in range(30):
            state, result = core.step(state, act(core, state))
            reached |= result.reached
        arrived[on] = reached.float().mean().item()
    assert arrived[True] >= 0.4 and arrived[True] > arrived[False] + 0.3  # measured on an AVX2 EPYC: 0.71 against 0.0
