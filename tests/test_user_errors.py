"""What a new user or a hostile tester hits first: policies for the wrong env, commands that fail, bad files.

Each test names the defect it guards against (issue "What a user hits first")."""

from __future__ import annotations

import subprocess
import sys
import zipfile

import numpy as np
import pytest

from agents.policy_files import PolicyFileError, expect_policy, read_policy_file
from motion_envs.play import CLOPS_ID, GAMMA_ID, WANDR_ID, LiveEpisodes, play
from motion_envs.priors.training import WEIGHTS_DIR

MEMORY_POLICY = WEIGHTS_DIR / "dqn_clopsnav_open_memory.zip"
KNOWN_GOAL_POLICY = WEIGHTS_DIR / "dqn_clopsnav_open_known_goal.zip"
GAMMA_POLICY = WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip"
WANDR_POLICY = WEIGHTS_DIR / "ppo_wandrreach_alpha1_default.zip"


def _cli(*words: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "motion_envs.cli", *words], capture_output=True, text=True, timeout=timeout)


def test_play_builds_the_env_each_clops_policy_was_trained_for():
    """`play ClopsNav-v0 --policy <memory or known-goal policy>` crashed inside SB3: the env lacked the options."""
    assert read_policy_file(MEMORY_POLICY).trained_for.env_kwargs["goal_memory"] is True
    assert read_policy_file(KNOWN_GOAL_POLICY).trained_for.env_kwargs["known_goal"] is True
    for policy in (MEMORY_POLICY, KNOWN_GOAL_POLICY):
        (summary,) = play(CLOPS_ID, policy, seed=0, max_seconds=3.0)  # an env option on top of the policy's own
        assert summary["frames"] <= 90 and isinstance(summary["success"], bool)
    live = LiveEpisodes(CLOPS_ID, MEMORY_POLICY)
    assert live.env.config.goal_memory and live.more().frames >= 30


def test_a_policy_for_another_env_or_of_another_kind_fails_before_the_first_step(tmp_path):
    """Wrong policies failed deep inside SB3 or torch, some only after the episode had started."""
    with pytest.raises(PolicyFileError, match="trained for motion_envs/WandrReach-v0.*not motion_envs/GammaReach-v0"):
        play(GAMMA_ID, WANDR_POLICY)
    with pytest.raises(PolicyFileError, match="holds a PPO latent policy.*needs a ClopsNav DQN policy"):
        play(CLOPS_ID, GAMMA_POLICY)
    with pytest.raises(PolicyFileError, match="holds a ClopsNav DQN policy"):
        play(WANDR_ID, MEMORY_POLICY)
    with pytest.raises(PolicyFileError, match="expects the observation space Dict"):
        play(CLOPS_ID, MEMORY_POLICY, goal_memory=False)  # overriding what it was trained for
    with pytest.raises(FileNotFoundError, match=r"nope\.zip$"):  # SB3 alone looks for nope.zip.zip
        expect_policy(tmp_path / "nope.zip", "ppo_policy", GAMMA_ID)
    garbage = tmp_path / "garbage.zip"
    garbage.write_bytes(b"not a zip at all")
    with pytest.raises(PolicyFileError, match="garbage.zip is not a saved Stable-Baselines3 policy"):
        read_policy_file(garbage)
    empty = tmp_path / "empty.zip"
    with zipfile.ZipFile(empty, "w") as archive:
        archive.writestr("data", "{}")
    with pytest.raises(PolicyFileError, match="empty.zip"):
        read_policy_file(empty)


def test_cli_errors_are_one_line_with_a_nonzero_exit_and_debug_shows_the_traceback():
    """Every CLI error was a raw traceback."""
    failed = _cli("play", CLOPS_ID, "--policy", str(GAMMA_POLICY))
    assert failed.returncode == 1 and "Traceback" not in failed.stderr
    (line,) = failed.stderr.strip().splitlines()
    assert line.startswith("motion-envs play: error:") and "needs a ClopsNav DQN policy" in line
    debug = _cli("play", CLOPS_ID, "--policy", str(GAMMA_POLICY), "--debug")
    assert debug.returncode == 1 and "Traceback" in debug.stderr and "PolicyFileError" in debug.stderr


def test_a_write_killed_midway_leaves_a_temporary_file_that_the_next_write_removes(tmp_path):
    """A SIGKILL during a checkpoint save left an orphan `.checkpoint.pt.*.tmp` that nothing ever cleaned."""
    target = tmp_path / "checkpoint.pt"
    killed = subprocess.run([sys.executable, "-c", (
        "import os, signal, sys\nfrom motion_envs.atomic import atomic_write\n"
        "def write(file):\n    file.write(b'half')\n    file.flush()\n    os.kill(os.getpid(), signal.SIGKILL)\n"
        f"atomic_write({str(target)!r}, write)\n")], timeout=60)  # fmt: skip
    assert killed.returncode == -9
    orphans = list(tmp_path.glob(".checkpoint.pt.*.tmp*"))
    assert len(orphans) == 1 and not target.exists()
    from motion_envs.atomic import atomic_write

    atomic_write(target, lambda file: file.write(b"whole"))
    assert target.read_bytes() == b"whole" and list(tmp_path.glob(".checkpoint.pt.*")) == []


def test_a_failed_video_leaves_no_file_behind(tmp_path, monkeypatch):
    """`play --video` wrote the mp4 in place: a failed run left a truncated video. The failure is injected after a
    real episode has written its frames (the one stand-in here: checked inputs leave no public way to make an
    episode fail midway)."""
    import motion_envs.play as playing

    real_episode = playing._episode

    def episode_then_failure(*args, **kwargs):
        real_episode(*args, **kwargs)
        raise RuntimeError("stopped after the first episode")

    monkeypatch.setattr(playing, "_episode", episode_then_failure)
    video = tmp_path / "out.mp4"
    with pytest.raises(RuntimeError, match="stopped"):
        play(GAMMA_ID, video=video, max_primitives=1, every=4)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(playing, "_episode", real_episode)
    play(GAMMA_ID, video=video, max_primitives=1, every=4)
    assert video.stat().st_size > 1000 and [path.name for path in tmp_path.iterdir()] == ["out.mp4"]


ENV_IDS = (GAMMA_ID, WANDR_ID, CLOPS_ID)
SMALL = {GAMMA_ID: {}, WANDR_ID: {}, CLOPS_ID: {"scene_seeds": (1000,)}}


@pytest.fixture(scope="module")
def envs():
    import gymnasium as gym

    return {env_id: gym.make(env_id, **SMALL[env_id]).unwrapped for env_id in ENV_IDS}


def test_nan_inf_and_mistyped_reset_options_are_refused_by_name(envs):
    """NaN or inf goals and facings gave NaN observations (on ClopsNav behind finite views), starts and goals
    outside the room were accepted, and 120.9, "120", "far" or a 2-vector were cast or failed without a name."""
    cases = {
        GAMMA_ID: [("goal", (float("nan"), 1.0)), ("goal", (1.0, float("inf"))), ("facing", float("nan")), ("goal", "far"),
                   ("start_index", 120.9), ("start_index", "1"), ("start_index", 10**6), ("goal", (1.0, 2.0, 3.0))],
        WANDR_ID: [("goal", (1.0, float("nan"), 1.0)), ("facing", float("inf")), ("start_index", 10**6), ("goal", "far"),
                   ("goal_velocity", (1.0, 2.0)), ("goal_time", 120.9), ("goal_time", "120"), ("goals", [])],
        CLOPS_ID: [("start", (float("nan"), 1.0)), ("facing", float("inf")), ("goal", (1.0, 1.0, float("nan"))),
                   ("start", (100.0, 0.0)), ("goal", (1.0, 1.0, 9.0)), ("scene_seed", 1.5), ("start_index", True)],
    }  # fmt: skip
    for env_id, bad in cases.items():
        for name, value in bad:
            with pytest.raises(ValueError, match=f"'{name}'"):
                envs[env_id].reset(seed=0, options={name: value})
    observation, _ = envs[WANDR_ID].reset(seed=0, options={"goal_time": 120.0, "goal": (0.5, 2.0, 1.2)})  # integral: fine
    assert np.isfinite(observation).all()


def test_mistyped_env_arguments_are_refused_by_name():
    import gymnasium as gym

    for env_id, name, value in ((GAMMA_ID, "max_primitives", "abc"), (GAMMA_ID, "max_primitives", 2.5),
                                (GAMMA_ID, "area", float("nan")), (CLOPS_ID, "width", "64"), (CLOPS_ID, "goal_height", (0.8,)),
                                (WANDR_ID, "frames_per_step", None)):  # fmt: skip
        with pytest.raises(TypeError, match=f"argument '{name}' must be"):
            gym.make(env_id, **{name: value})


def test_actions_of_the_wrong_type_are_refused_by_name_and_torch_actions_work(envs):
    """ClopsNav's None said "contains NaN or inf", complex and numeric-string actions were taken silently, and a
    torch action that requires grad crashed in `.numpy()`."""
    import torch

    for env_id, env in envs.items():
        env.reset(seed=0)
        for bad in (None, "3", 1 + 2j, True, [[1.0], [1.0, 2.0]]):
            with pytest.raises(ValueError, match="action"):
                env.step(bad)
    gamma = envs[GAMMA_ID]
    _, reward, *_ = gamma.step(torch.zeros(128, requires_grad=True))
    assert np.isfinite(reward)


def _random_value(rng: np.random.Generator):
    kinds = [None, "x", "12", 1 + 1j, True, float("nan"), float("inf"), -float("inf"), 1e300, -5, 0, 3, 2.5, (), [],
             [1.0], [1.0, 2.0], [1.0, 2.0, 3.0], [[1.0, 2.0, 3.0]], [float("nan")] * 3, {"a": 1}, np.zeros((2, 2))]  # fmt: skip
    value = kinds[int(rng.integers(len(kinds)))]
    return np.asarray(value) * rng.uniform(-3, 3) if isinstance(value, list) and value and rng.random() < 0.3 else value


OPTIONS = {GAMMA_ID: ("goal", "start_index", "facing"),
           WANDR_ID: ("goal", "goal_time", "goals", "goal_velocity", "start_index", "facing"),
           CLOPS_ID: ("scene_seed", "start", "goal", "facing", "start_index")}  # fmt: skip


def _finite(observation) -> bool:
    if isinstance(observation, dict):
        return all(np.isfinite(value).all() for value in observation.values())
    return bool(np.isfinite(observation).all())


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_fuzzed_reset_options_and_actions_give_a_named_error_or_finite_results(envs, env_id):
    """Random types, shapes, NaN/inf and out-of-range values for every reset option and for the action: either a
    ValueError/TypeError that names the option (or says "action"), or finite observations and rewards."""
    env, rng = envs[env_id], np.random.default_rng(7)
    accepted = refused = 0
    for trial in range(60):
        name = OPTIONS[env_id][int(rng.integers(len(OPTIONS[env_id])))]
        value = _random_value(rng)
        try:
            observation, _ = env.reset(seed=trial, options={name: value})
        except (ValueError, TypeError) as error:
            assert repr(name) in str(error) or "give either" in str(error), f"{name}={value!r}: {error}"
            refused += 1
            continue
        accepted += 1
        assert _finite(observation), f"{name}={value!r} gave a non-finite observation"
        action = env.action_space.sample()
        _, reward, *_ = env.step(action)
        assert np.isfinite(reward), f"{name}={value!r} gave reward {reward}"
    env.reset(seed=0)
    for trial in range(20):
        value = _random_value(rng)
        try:
            _, reward, *_ = env.step(value)
        except ValueError as error:
            assert "action" in str(error)
            continue
        assert np.isfinite(reward)
    assert refused > 0 and accepted > 0


def test_clops_envs_pickle_deep_copy_and_run_in_async_vector_envs():
    """embreex's scene made ClopsNav envs unpicklable after reset, and async vector envs hung in their workers. This
    process has cast rays by the time the vector env starts, so its workers are spawned: a forked one would refuse
    (`test_a_child_forked_after_casting_refuses_to_cast_instead_of_hanging`)."""
    import copy
    import pickle

    import gymnasium as gym

    env = gym.make(CLOPS_ID, scene_seeds=(1000,))
    env.reset(seed=0)
    twins = [copy.deepcopy(env), pickle.loads(pickle.dumps(env))]
    observation, reward, *_ = env.step(3)
    for twin in twins:
        again, twin_reward, *_ = twin.step(3)
        assert np.array_equal(observation, again) and twin_reward == reward  # same process, same bodies: same bits
    vector = gym.make_vec(CLOPS_ID, num_envs=2, vectorization_mode="async", vector_kwargs={"context": "spawn"},
                          scene_seeds=(1000,))  # fmt: skip
    try:
        views, _ = vector.reset(seed=0)
        _, rewards, *_ = vector.step(np.array([0, 3]))
        assert views.shape == (2, 5, 64, 64) and np.isfinite(rewards).all()
    finally:
        vector.close()


def _cast_in_child(results) -> None:
    """Child of the fork test below: cast one ray and report what happened."""
    from motion_envs.render.raycast import RayCaster

    try:
        RayCaster(np.eye(3), np.array([[0, 1, 2]])).cast(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]))
        results.put("cast")
    except RuntimeError as error:
        results.put(str(error))


def test_a_child_forked_after_casting_refuses_to_cast_instead_of_hanging():
    """A child forked from a process whose embree thread pool had run deadlocked in its first scene build (the async
    vector env test hung the suite); it now raises, naming the fix."""
    import multiprocessing

    from motion_envs.render.raycast import RayCaster

    hit, distance = RayCaster(np.eye(3), np.array([[0, 1, 2]])).cast(np.full((1, 3), 0.2), np.array([[0.0, 0.0, 1.0]]))
    assert hit[0] == 0 and np.isclose(distance[0], 0.4, atol=1e-5)  # the plane x + y + z = 1, 0.4 above (0.2, 0.2, 0.2)
    context = multiprocessing.get_context("fork")
    results = context.Queue()
    child = context.Process(target=_cast_in_child, args=(results,))
    child.start()
    try:
        message = results.get(timeout=60)
    finally:
        child.join(timeout=10)
        if child.is_alive():  # a child that hung in embree (the guard gone) is not left behind
            child.kill()
    assert "forked" in message and "spawn" in message


def test_next_step_autoreset_works_under_gymnasiums_normalize_observation():
    """Gymnasium's vector NormalizeObservation refused our vector envs (same-step autoreset only)."""
    import gymnasium as gym
    from gymnasium.wrappers.vector import NormalizeObservation

    vector = NormalizeObservation(gym.make_vec(GAMMA_ID, num_envs=2, vectorization_mode="vector_entry_point",
                                               autoreset_mode="next_step", max_primitives=2))  # fmt: skip
    vector.reset(seed=0)
    zeros = np.zeros((2, 128), dtype=np.float32)
    vector.step(zeros)
    _, _, terminated, truncated, info = vector.step(zeros)
    assert (terminated | truncated).all() and info["_is_success"].all() and "final_obs" not in info
    observation, reward, terminated, truncated, _ = vector.step(zeros)  # the restart step: action ignored
    assert (reward == 0).all() and not (terminated | truncated).any() and np.isfinite(observation).all()
    assert vector.unwrapped.state.steps.tolist() == [0, 0]
    with pytest.raises(ValueError, match="autoreset_mode"):
        gym.make_vec(GAMMA_ID, num_envs=2, vectorization_mode="vector_entry_point", autoreset_mode="sometimes")


def test_train_defaults_follow_the_env_and_mocap_dir_means_the_clips_folder(tmp_path):
    """`train ppo --env WandrReach-v0` failed without `--reward default`; `train` wanted a cmu/ subfolder that
    `data build` did not; `data build` then read the whole folder (HDM05 too) where `train` reads the shipped
    subfolders, so a user who built first retargeted again when training."""
    from agents.train_ppo import PPOTrainConfig
    from motion_envs.cli import _subsets, parser

    assert PPOTrainConfig(env_id=WANDR_ID).reward == "default" and PPOTrainConfig().reward == "paper"
    (tmp_path / "cmu").mkdir()
    (tmp_path / "hdm05").mkdir()
    with_cmu = parser().parse_args(["train", "wandr", "--mocap-dir", str(tmp_path), "--subset", "hdm05"])
    assert _subsets(with_cmu) == ("cmu", "hdm05")
    flat = tmp_path / "flat"
    flat.mkdir()
    assert _subsets(parser().parse_args(["train", "gamma", "--mocap-dir", str(flat)])) == ()  # the whole folder
    for command in (["data", "build"], ["train", "gamma"], ["bench", "data"]):  # one cache for all of them
        assert _subsets(parser().parse_args([*command, "--mocap-dir", str(tmp_path)])) == ("cmu",)
    assert _subsets(parser().parse_args(["data", "build", "--mocap-dir", str(flat)])) == ()


def test_train_threads_below_one_is_refused_before_anything_runs(capsys):
    """`train --threads` sets torch's threads for the run; 0 or less names the option instead of training."""
    from motion_envs.cli import main

    assert main(["train", "ppo", "--threads", "0", "--timesteps", "1"]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("motion-envs train: error:") and "--threads must be at least 1, got 0" in line


def test_broken_prior_checkpoints_name_the_file_and_never_suggest_unsafe_loading(tmp_path):
    """A truncated checkpoint gave `OSError: [Errno 22] Invalid argument` without a file name, a garbage one torch's
    advice to set weights_only=False."""
    from motion_envs.priors.checkpoint import CheckpointError
    from motion_envs.priors.train_wandr import load_wandr

    whole = (WEIGHTS_DIR / "wandr.pt").read_bytes()
    for name, content in (("truncated.pt", whole[: len(whole) // 2]), ("garbage.pt", b"garbage" * 100), ("empty.pt", b"")):
        (tmp_path / name).write_bytes(content)
        with pytest.raises(CheckpointError, match=f"{name}.*not a readable checkpoint") as error:
            load_wandr(tmp_path / name)
        assert "weights_only" not in str(error.value)


def test_bench_gamma_labels_a_policy_by_what_its_file_holds_not_by_its_name(tmp_path):
    """`bench gamma --policies` labelled a renamed policy from its file name ("policy(a1), warm_617k reward")."""
    import shutil

    from benchmarks.gamma_control import CLONED_CENTRE, MIRRORED_RIGHT_GOALS, policy_label

    renamed = tmp_path / "my_finetune.zip"
    shutil.copy(WEIGHTS_DIR / "ppo_gammareach_alpha10_paper_cloned.zip", renamed)
    assert policy_label(renamed) == "policy(10)" + CLONED_CENTRE + MIRRORED_RIGHT_GOALS
    assert policy_label(WEIGHTS_DIR / "ppo_gammareach_alpha10_release.zip") == "policy(10), release reward"

    assert read_policy_file(GAMMA_POLICY).alpha == 1.0 and read_policy_file(MEMORY_POLICY).alpha is None


def test_bench_results_record_the_command_that_reruns_them():
    """A results file from `bench gamma --seed 1 --clones 16 --policies ...` named only `--policies ...`, so a rerun
    from its Command line measured other pairs with twice the clones (`bench wander` left out --paths, --rooms and
    --seed the same way; the other benches their counts and seeds)."""
    import shlex
    from pathlib import Path

    from benchmarks.machine import bench_command, data_options
    from motion_envs.cli import parser

    policies = [Path("runs/old.zip"), Path("new.zip")]
    defaults = {"pairs": 100, "clones": 32, "seed": 0, "precision": "auto"}
    options = {"quick": False, "pairs": 50, "clones": 16, "seed": 1, "precision": "float32", "ray": None,
               "mirror-right-goals": True, "policies": policies}  # fmt: skip
    args = parser().parse_args(shlex.split(bench_command("gamma", options, defaults))[1:])
    assert (args.pairs, args.clones, args.seed, args.precision) == (50, 16, 1, "float32")
    assert args.mirror_right_goals and args.policies == policies and not args.quick and args.ray is None
    assert bench_command("gamma", {"quick": False, "pairs": 100, "seed": 0}, defaults) == "motion-envs bench gamma"
    wander = parser().parse_args(shlex.split(bench_command("wander", {"paths": 30, "rooms": 100, "seed": 2, "quick": True}, {"rooms": 100}))[1:])
    assert (wander.paths, wander.rooms, wander.seed, wander.quick) == (30, 100, 2, True)
    label = "WANDR sampler, paced t_G = 1 s"  # bench wandr --only: a row label, spaces and all
    wandr = parser().parse_args(shlex.split(bench_command("wandr", {"seed": 0, "no-timing": True, "only": label}))[1:])
    assert (wandr.seed, wandr.no_timing, wandr.only, wandr.quick) == (0, True, label, False)
    realism = bench_command("gamma-realism", {**data_options(Path("my mocap"), ("cmu", "hdm05", "extra")), "seed": 3})
    realism = parser().parse_args(shlex.split(realism)[1:])
    assert (realism.mocap_dir, realism.subset, realism.seed) == (Path("my mocap"), ["hdm05", "extra"], 3)
