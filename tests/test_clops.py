"""CLOPS: head-target prior and action clusters, ClopsNav-v0, double DQN with prioritised replay."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

import motion_envs  # noqa: F401  (registers the ids)
from agents.double_dqn import PrioritizedDoubleDQN
from agents.prioritized_replay import PriorityLedger
from motion_envs.envs.clops_nav import LOOK_BINS, MEMORY_SIZE, ClopsNavConfig, ClopsNavCore, goal_in_view
from motion_envs.priors.clops import HeadPose, action_targets, head_deltas, head_pose, head_rotation
from motion_envs.priors.train_clops import ClopsTrainConfig, fit_head_actions, load_clops, train_clops
from motion_envs.priors.train_wandr import WandrClips
from motion_envs.priors.wandr_features import PELVIS
from motion_envs.rewards import ClopsRewardConfig, goal_found, stayed_still
from motion_envs.scenes.labels import LABELS

ENV_ID = "motion_envs/ClopsNav-v0"
SEEDS = (1000,)  # one held-out open room keeps the tests' scene builds to one


@pytest.fixture(scope="module")
def core() -> ClopsNavCore:
    return ClopsNavCore(ClopsNavConfig(scene_seeds=SEEDS))


def test_head_rotation_matches_forward_kinematics(body, generator):
    import roma

    orient, pose = roma.random_rotmat(3, generator=generator), roma.random_rotmat((3, 21), generator=generator)
    posed = body.from_matrices(torch.zeros(3, 3), orient, pose)
    assert torch.allclose(head_rotation(orient, pose), posed.rotations[:, 15], atol=1e-5)


def test_action_targets_invert_head_deltas(generator):
    import roma

    yaw = torch.tensor([0.3, -2.0])
    rotation = roma.rotvec_to_rotmat(torch.stack([torch.zeros(2), torch.zeros(2), yaw], 1))
    head = HeadPose(torch.randn(2, 3, generator=generator), rotation)
    deltas = torch.tensor([[0.2, 1.0, 0.0, 0.4], [-0.5, 0.1, 0.05, -1.0]])
    assert torch.allclose(head_deltas(head, action_targets(head, deltas)), deltas, atol=1e-5)


def test_kmeans_actions_are_reproducible_for_a_seed(walking_motion_30fps, body):
    clips = WandrClips.from_motions([walking_motion_30fps], body)
    first, again = fit_head_actions(clips, 30, 6, seed=3), fit_head_actions(clips, 30, 6, seed=3)
    assert first.shape == (6, 4) and np.array_equal(first, again)
    assert first[0, 1] == first[:, 1].max()  # sorted: the most forward first
    assert first[0, 1] > 0.5  # a walking clip: the head travels over half a metre a second


def test_a_free_run_heads_for_one_action_target_after_another(walking_motion_30fps, body):
    """CLOPS's free-running terms re-target every horizon, as ClopsNav's actions do: with a 10-frame horizon a
    50-frame run heads for the data's head 10, 20, ..., 50 frames after its start, a 15-frame run for 10 and then
    its last frame."""
    from motion_envs.priors.train_clops import HeadTargets

    targets, starts = HeadTargets(WandrClips.from_motions([walking_motion_30fps], body), 10), torch.tensor([0, 7])
    fixed = targets.goal_frames(starts, 50)
    heading_for = [targets.free_run_goal_frames(starts, step, 50, fixed) - starts for step in range(50)]
    assert [int(frames[0]) for frames in heading_for] == [10 * (step // 10 + 1) for step in range(50)]
    assert torch.equal(heading_for[49], torch.tensor([50, 50]))
    assert [int(targets.free_run_goal_frames(starts, step, 15, fixed)[1]) for step in (0, 9, 10, 14)] == [17, 17, 22, 22]


def test_a_tiny_clops_training_run_lowers_its_loss(walking_motion_30fps, body, tmp_path):
    clips = WandrClips.from_motions([walking_motion_30fps], body)
    config = ClopsTrainConfig(epochs=5, batch_size=16, window_stride=1, max_rollout=1, init=None, run_dir=tmp_path / "run",
                              weights=tmp_path / "clops.pt")  # fmt: skip
    config.model = dataclasses.replace(config.model, layers=3, max_width=64, actions=4)
    entry = train_clops(config, clips, clips)
    assert entry["train_loss_by_epoch"][-1] < entry["train_loss_by_epoch"][0]
    prior = load_clops(tmp_path / "clops.pt")
    assert prior.actions.shape == (4, 4) and prior.actions.abs().sum() > 0  # the action set travels with the weights
    checkpoint = torch.load(tmp_path / "clops.pt", weights_only=False)
    checkpoint["model"]["actions"] = checkpoint["model"]["actions"] * 2  # an action set no fit gives
    torch.save(checkpoint, tmp_path / "doubled.pt")
    kept = dataclasses.replace(config, epochs=1, actions_from=tmp_path / "doubled.pt", run_dir=tmp_path / "kept",
                               weights=tmp_path / "kept.pt")  # fmt: skip
    train_clops(kept, clips, clips)
    assert torch.equal(load_clops(tmp_path / "kept.pt").actions, prior.actions * 2)  # kept, not refitted


def test_the_prior_moves_the_head_towards_a_target_half_a_metre_ahead(core):
    count = len(core.starts)  # every shipped start pose, each facing a random way
    state = core.sample_initial_state([np.random.default_rng(seed) for seed in range(count)])
    head = head_pose(state.body)
    target = action_targets(head, torch.tensor([[0.0, 0.5, 0.0, 0.0]]).expand(count, 4))
    body = state.body
    with torch.no_grad():
        for _ in range(45):  # 1.5 s, the env's chunk limit
            body, _ = core.stepper.step_towards(body, torch.zeros(count, 64), target)
    distance = (head_pose(body).position[:, :2] - target.position[:, :2]).norm(dim=-1)
    assert (distance < 0.5).float().mean() >= 0.9, "the head should come closer to its target for nearly every start"
    assert distance.median() < 0.25, f"median head-to-target distance {distance.median():.2f} m after 1.5 s (from 0.5 m)"


def test_the_foot_rule_changes_only_the_shown_legs_and_their_skating(core):
    """ClopsNav's foot rule (`lock_feet`, the default) is shown, not fed back: the same actions give the same
    bodies, heads and episodes with and without it, and the shown feet slide in fewer frames (16 bodies, 4
    random actions)."""
    runs = {}
    for lock in (True, False):
        env = ClopsNavCore(dataclasses.replace(core.config, lock_feet=lock), prior=core.prior)
        state = env.sample_initial_state([np.random.default_rng(seed) for seed in range(16)])
        actions = np.random.default_rng(0).integers(env.num_actions, size=(4, 16))
        for step in actions:
            state, _ = env.step(state, torch.as_tensor(step))
        runs[lock] = state
    with_rule, without = runs[True], runs[False]
    assert torch.allclose(with_rule.joints, without.joints, atol=1e-4)
    assert torch.equal(with_rule.frame, without.frame) and torch.equal(with_rule.found, without.found)
    assert not torch.allclose(with_rule.shown_pose, with_rule.pose, atol=1e-3)  # the legs were fitted
    assert with_rule.skated.sum() < 0.8 * without.skated.sum(), (with_rule.skated.sum(), without.skated.sum())  # 242 vs 561


def test_spaces_and_check_env():
    env = gym.make(ENV_ID, scene_seeds=SEEDS)
    check_env(env.unwrapped, skip_render_check=True)
    assert isinstance(env.action_space, gym.spaces.Discrete) and env.action_space.n == 16
    assert env.observation_space.shape == (5, 64, 64) and env.observation_space.dtype == np.uint8
    known = gym.make(ENV_ID, scene_seeds=SEEDS, known_goal=True)
    observation, _ = known.reset(seed=0)
    assert set(observation) == {"image", "goal"} and observation["goal"].shape == (3,)
    check_env(known.unwrapped, skip_render_check=True)
    remembering = gym.make(ENV_ID, scene_seeds=SEEDS, goal_memory=True)
    observation, _ = remembering.reset(seed=0)
    assert set(observation) == {"image", "memory"} and observation["memory"].shape == (MEMORY_SIZE,)
    check_env(remembering.unwrapped, skip_render_check=True)
    with pytest.raises(ValueError, match="known_goal and goal_memory exclude each other"):
        gym.make(ENV_ID, scene_seeds=SEEDS, known_goal=True, goal_memory=True)


def test_reward_term_functions_on_hand_computed_cases():
    moved, turned = torch.tensor([0.05, 0.3, 0.05]), torch.tensor([0.0, 0.0, 0.5])
    assert stayed_still(moved, turned, 0.1, math.radians(10)).tolist() == [True, False, False]
    assert goal_found(torch.tensor([0.5, 0.5, 2.0]), torch.tensor([True, False, True]), 1.0).tolist() == [True, False, False]
    assert ClopsRewardConfig.named("default:collision=2").collision == 2.0


def _least_moving_action(core: ClopsNavCore) -> int:
    actions = core.prior.actions
    return int((actions[:, :2].norm(dim=1) + actions[:, 3].abs()).argmin())


def test_goal_in_view_pays_and_goal_behind_does_not(core):
    state = core.sample_initial_state([np.random.default_rng(1)])
    head = head_pose(state.body)
    rest = _least_moving_action(core)
    found = {}
    for name, ahead in (("front", 0.7), ("behind", -0.7)):
        goal = action_targets(head, torch.tensor([[0.0, ahead, 0.0, 0.0]])).position
        placed = dataclasses.replace(state, goal=goal)
        _, result = core.step(placed, torch.tensor([rest]))
        found[name] = (bool(result.terminated[0]), float(result.terms["goal"][0]), float(result.reward[0]))
    assert found["front"][:2] == (True, 1.0)
    assert found["behind"][:2] == (False, 0.0)
    terms_front = found["front"][2] - found["behind"][2]
    assert terms_front == pytest.approx(10.0, abs=1e-4)  # the same action, only the goal term differs


def test_the_goal_memory_keeps_a_goal_seen_and_then_turned_away_from(core):
    drawn = core.sample_initial_state([np.random.default_rng(1)])
    head = head_pose(drawn.body)
    states = {}
    for name, ahead in (("front", 1.5), ("behind", -1.5)):
        goal = action_targets(head, torch.tensor([[0.0, ahead, 0.0, 0.0]])).position[0]
        states[name] = core.sample_initial_state([np.random.default_rng(1)], {"goal": goal.tolist()})  # the same start
    behind, front = core.memory(states["behind"])[0], core.memory(states["front"])[0]
    assert behind[:4].tolist() == [0.0, 0.0, 0.0, 1.0]  # never seen: no position, time since = the whole episode
    assert front[2:4].tolist() == [1.0, 0.0] and front[:2].tolist() == pytest.approx([0.0, 1.5], abs=1e-4)
    looked = front[4 : 4 + LOOK_BINS]
    assert looked[0] == 1 and looked[LOOK_BINS // 2] == 0 and front[-1] == 0  # ahead looked at, behind not, t = 0
    turn, state = int(core.prior.actions[:, 3].abs().argmax()), states["front"]
    for _ in range(6):  # turn until the goal is out of view
        state, _ = core.step(state, torch.tensor([turn]))
        if not goal_in_view(state.view)[0]:
            break
    memory = core.memory(state)[0]
    assert not goal_in_view(state.view)[0] and memory[2] == 1.0
    assert float(memory[3]) == pytest.approx(float(state.frame[0] - state.seen_at[0]) / core.config.max_frames)
    assert memory[3] > 0 and memory[-1] == pytest.approx(float(state.frame[0]) / core.config.max_frames)
    assert memory[:2].tolist() == pytest.approx(core.goal_in_head_frame(state)[0, :2].tolist(), abs=1e-4)
    assert memory[4 : 4 + LOOK_BINS].sum() > looked.sum()  # turning looked at new directions


def test_a_body_inside_furniture_collides_and_pays_for_it(core):
    scene = core.slots[core.slot("open", SEEDS[0])].scene
    piece = next(p for p in scene.parts if LABELS[p.label] not in ("floor", "wall"))
    centre = piece.mesh.bounds.mean(axis=0)
    rest = _least_moving_action(core)
    inside = core.sample_initial_state([np.random.default_rng(2)], {"start": centre[:2].tolist()})
    free = core.sample_initial_state([np.random.default_rng(2)])
    _, hit = core.step(inside, torch.tensor([rest]))
    _, clear = core.step(free, torch.tensor([rest]))
    assert bool(hit.collided[0]) and not bool(clear.collided[0])
    scales = core.config.reward
    expected = -scales.time - scales.collision - scales.still * float(hit.terms["still"][0])
    assert float(hit.reward[0]) == pytest.approx(expected, abs=1e-5)


def test_walking_out_of_the_room_ends_the_episode_and_pays_for_it(core):
    x0, y0, x1, y1 = core.slots[core.slot("open", SEEDS[0])].bounds.tolist()
    forward = int(core.prior.actions[:, 1].argmax())
    start_forward = core.starts.forward(torch.tensor([0]), torch.zeros(1))[0]
    facing = math.pi - math.atan2(float(start_forward[1]), float(start_forward[0]))  # turns the start pose to face -x
    state = core.sample_initial_state([np.random.default_rng(3)], {
        "start": [x0 + 0.3, (y0 + y1) / 2], "facing": facing, "start_index": 0, "goal": [x1 - 0.5, (y0 + y1) / 2, 1.0]})
    for _ in range(6):
        state, result = core.step(state, torch.tensor([forward]))
        if result.terminated[0] or result.truncated[0]:
            break
    assert bool(result.left_room[0]) and bool(result.terminated[0]) and not bool(result.truncated[0])
    assert float(state.joints[0, PELVIS, 0]) < x0 - core.config.room_margin and not bool(state.found[0])
    scales, terms = core.config.reward, {name: float(value[0]) for name, value in result.terms.items()}
    expected = -scales.time - scales.collision * terms["collision"] - scales.still * terms["still"] - scales.left_room
    assert terms["left_room"] == 1.0 and float(result.reward[0]) == pytest.approx(expected, abs=1e-5)


def test_a_body_whose_pelvis_falls_below_fall_height_ends_its_episode_frozen_and_pays_for_it(core):
    """fall_height set above a standing pelvis (1.5 m): the first frame counts as a fall, so it is not taken (the
    body stays at its start, the last upright frame) and the episode ends with `fallen` paid; the same start and
    action with the rule off (0) go on. A real fall is rare and late (after ~300 frames of random actions), so the
    threshold stands in for it."""
    import dataclasses

    forward = int(core.prior.actions[:, 1].argmax())
    high = ClopsNavCore(dataclasses.replace(core.config, fall_height=1.5), core.prior)
    off = ClopsNavCore(dataclasses.replace(core.config, fall_height=0.0), core.prior)
    start = high.sample_initial_state([np.random.default_rng(5)])
    after, fell = high.step(start, torch.tensor([forward]))
    _, walked = off.step(off.sample_initial_state([np.random.default_rng(5)]), torch.tensor([forward]))
    assert bool(fell.fallen[0]) and bool(fell.terminated[0]) and not bool(fell.truncated[0]) and int(fell.frames[0]) == 0
    assert torch.equal(after.joints, start.joints) and torch.equal(after.transl, start.transl)
    assert not bool(walked.fallen[0]) and not bool(walked.terminated[0]) and int(walked.frames[0]) > 1
    scales, terms = core.config.reward, {name: float(value[0]) for name, value in fell.terms.items()}
    expected = -scales.time - scales.collision * terms["collision"] - scales.still * terms["still"] - scales.fallen
    assert terms["fallen"] == 1.0 and float(fell.reward[0]) == pytest.approx(expected, abs=1e-5)
    with pytest.raises(ValueError, match="fall_height"):
        ClopsNavConfig(fall_height=-0.1)


def test_mixed_family_draws_rooms_of_every_family():
    core = ClopsNavCore(ClopsNavConfig(family="mixed", train_scenes=2))
    state = core.sample_initial_state([np.random.default_rng(seed) for seed in range(24)])
    families = {core.slots[int(index)].scene.name.rsplit("-", 1)[0] for index in state.scene}
    assert families == set(core.config.families) and len(families) == 5
    with pytest.raises(ValueError, match="unknown scene family 'attic'.*mixed"):
        ClopsNavConfig(family="attic")


def assert_views_agree(single: np.ndarray, batched: np.ndarray) -> None:
    """A single env's (5, H, W) uint8 view against the same body's view in a batch.

    Not bit-equal by construction: the prior's Linear layers run as one matmul over the batch, and oneDNN/MKL pick
    other kernels (other summation orders) for 1 and N rows and for AVX2 and AVX-512/AMX, so the bodies agree to
    about 3e-7 m after a 30-frame chunk (asserted by the caller within 1e-5 m). Depth is quantised to
    `max_depth` / 255 = 3.9 cm a level, so such a difference moves a pixel by at most one level, and only a pixel
    whose depth lies on a rounding boundary (measured on an AMX Xeon: 1 of 4,096 pixels, by 1 level); a silhouette
    (semantic or goal pixel) changes only where a ray grazes an edge within that distance. Allowed: depth within one
    level, at most 1% of the pixels different in any channel."""
    difference = np.abs(single.astype(np.int16) - batched.astype(np.int16))
    assert difference[0].max() <= 1, f"depth differs by {difference[0].max()} levels"
    changed = (difference > 0).reshape(len(difference), -1).mean(-1)
    assert changed.max() <= 0.01, f"share of pixels that differ per channel: {changed.tolist()}"


def test_vector_env_equals_single_envs_and_renders():
    single = [gym.make(ENV_ID, scene_seeds=SEEDS) for _ in range(2)]
    vector = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", scene_seeds=SEEDS, render_mode="rgb_array")
    batch, _ = vector.reset(seed=5)
    for index, env in enumerate(single):
        observation, _ = env.reset(seed=5 + index)
        assert_views_agree(observation, batch[index])
    actions = np.array([0, 7])
    batch, rewards, *_ = vector.step(actions)
    for index, env in enumerate(single):
        observation, reward, *_ = env.step(int(actions[index]))
        alone, together = env.unwrapped.state, vector.unwrapped.state
        assert int(alone.frame[0]) == int(together.frame[index])  # the same chunk length: the same reach decisions
        assert torch.allclose(alone.joints[0], together.joints[index], atol=1e-5)
        assert_views_agree(observation, batch[index])
        assert reward == pytest.approx(rewards[index], abs=1e-5)
    frame = vector.render()
    assert frame.dtype == np.uint8 and frame.shape == (360, 480, 3)


def test_out_of_range_actions_raise_clear_errors():
    env = gym.make(ENV_ID, scene_seeds=SEEDS)
    env.reset(seed=0)
    for bad in (16, -1, 2.5, float("nan")):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)
    with pytest.raises(TypeError, match="unknown arguments"):
        gym.make(ENV_ID, resolution=32)


def test_prioritised_replay_samples_high_priority_transitions_more_often():
    ledger = PriorityLedger(buffer_size=100, n_envs=1, alpha=0.6)
    for row in range(100):
        ledger.added(row)
    ledger.update(np.arange(100), np.zeros(100, dtype=int), np.full(100, 0.1))
    ledger.update(np.array([7]), np.array([0]), np.array([10.0]))  # one transition with a large TD error
    rng = np.random.default_rng(0)
    rows, _, weights = ledger.sample(20_000, 100, beta=0.4, rng=rng)
    share = np.mean(rows == 7)
    expected = 10.0**0.6 / (10.0**0.6 + 99 * 0.1**0.6)  # P(i) = p_i^α / Σ p^α
    assert share == pytest.approx(expected, rel=0.1) and share > 10 / 100
    assert weights[rows == 7].max() < weights[rows != 7].min()  # importance weights undo the over-sampling


class _TwoArmedBandit(gym.Env):
    """Action 1 pays 1, action 0 pays 0; one-step episodes on a constant image."""

    observation_space = gym.spaces.Box(0, 255, (5, 36, 36), np.uint8)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.full((5, 36, 36), 128, dtype=np.uint8), {}

    def step(self, action):
        return np.full((5, 36, 36), 128, dtype=np.uint8), float(action), True, False, {}


def test_a_tiny_dqn_run_learns_the_better_arm_and_saves(tmp_path):
    model = PrioritizedDoubleDQN("CnnPolicy", _TwoArmedBandit(), learning_starts=20, buffer_size=500, batch_size=16,
                                 train_freq=1, gradient_steps=1, target_update_interval=20, exploration_fraction=0.5,
                                 learning_rate=1e-3, seed=0, device="cpu")  # fmt: skip
    model.learn(300)
    observation = np.full((1, 5, 36, 36), 128, dtype=np.uint8)
    q_values = model.q_net(torch.as_tensor(observation)).detach()[0]
    assert q_values[1] > q_values[0] + 0.3
    model.save(tmp_path / "dqn.zip")
    loaded = PrioritizedDoubleDQN.load(tmp_path / "dqn.zip", device="cpu")
    assert loaded.predict(observation[0], deterministic=True)[0] == 1
    assert type(loaded.replay_buffer).__name__ == "PrioritizedReplayBuffer"


def test_a_tiny_dqn_run_on_clops_nav(tmp_path):
    from agents.vec_env import NativeVecEnv

    venv = NativeVecEnv.make(ENV_ID, num_envs=2, scene_seeds=SEEDS, max_seconds=3.0)
    model = PrioritizedDoubleDQN("CnnPolicy", venv, learning_starts=8, buffer_size=100, batch_size=8, train_freq=1,
                                 gradient_steps=1, seed=0, device="cpu")  # fmt: skip
    model.learn(24)
    assert model.num_timesteps >= 24 and model.replay_buffer.size() >= 12
    actions, _ = model.predict(venv.reset(), deterministic=True)
    assert actions.shape == (2,) and ((0 <= actions) & (actions < 16)).all()


def test_a_dqn_fine_tune_starts_from_the_policy_file_and_rejects_one_for_other_observations(tmp_path):
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.train_dqn import DQNTrainConfig, fine_tuned_model
    from agents.vec_env import NativeVecEnv
    from motion_envs.priors.training import WEIGHTS_DIR

    shipped = WEIGHTS_DIR / "dqn_clopsnav_open.zip"
    config = DQNTrainConfig(num_envs=2, run_dir=tmp_path, init=shipped, init_exploration=0.3)
    venv = VecMonitor(NativeVecEnv.make(ENV_ID, num_envs=2, scene_seeds=SEEDS, max_seconds=3.0))
    model = fine_tuned_model(config, venv)
    observation = torch.as_tensor(venv.reset())
    expected = PrioritizedDoubleDQN.load(shipped, device="cpu").q_net(observation)
    assert torch.equal(model.q_net(observation), expected) and torch.equal(model.q_net_target(observation), expected)
    assert model.num_timesteps == 0 and model.exploration_schedule(1.0) == pytest.approx(0.3)
    memory = DQNTrainConfig(num_envs=2, run_dir=tmp_path, init=WEIGHTS_DIR / "dqn_clopsnav_open_memory.zip")
    with pytest.raises(ValueError, match="does not fit this run's env"):
        fine_tuned_model(memory, venv)
    with pytest.raises(ValueError, match="init must be an existing policy file"):
        DQNTrainConfig(init=tmp_path / "missing.zip")


def test_play_writes_every_frame_of_a_clops_episode(tmp_path):
    import imageio.v2 as imageio

    from motion_envs.play import play
    from motion_envs.rollout import Rollout

    video, rollout = tmp_path / "clops.mp4", tmp_path / "clops.npz"
    summary = play(ENV_ID, video=video, every=1, save_rollout=rollout, scene_seeds=SEEDS, max_seconds=2.0)[0]
    assert set(summary) >= {"success", "frames", "collision_rate", "foot_skating"}
    saved = Rollout.load(rollout)
    assert saved.scene == f"open:{SEEDS[0]}" and len(saved.transl) == summary["frames"]
    frames = imageio.get_reader(str(video)).count_frames()
    assert summary["frames"] - 1 <= frames <= summary["frames"]  # every generated frame (the writer may drop one)


def test_live_episodes_feed_the_viewer_clops_frames_in_one_room():
    from motion_envs.play import LiveEpisodes

    live = LiveEpisodes(ENV_ID, seed=0)
    first, second = live.more(), live.more()
    assert len(first.transl) >= 30 and len(second.transl) >= 30  # about a second of 30 fps frames each
    assert first.scene == second.scene == "open:1000"


def test_clops_actions_bench_measures_travel_per_action():
    """`bench clops-actions` on one room: the longest target moves the head further than the standing ones, frames
    per action lie in 1..max_chunk_frames, and only actions that used every frame count as timed out."""
    from benchmarks.clops_actions import action_travel
    from motion_envs.priors.training import WEIGHTS_DIR

    figures = action_travel(WEIGHTS_DIR / "clops.pt", rooms=1, actions=2)
    targets, travel, frames = figures["targets"], figures["travel"], figures["frames"]
    assert targets.shape == (16, 2) and travel.shape == frames.shape == figures["timed_out"].shape == (16,)
    farthest, nearest = int(targets[:, 0].argmax()), int(targets[:, 0].argmin())
    assert travel[farthest] > 0.3 and travel[farthest] > 5 * travel[nearest]
    assert ((frames >= 1) & (frames <= 30)).all() and ((figures["timed_out"] > 0) <= (frames > 1)).all()
