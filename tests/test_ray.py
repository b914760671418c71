"""RLlib training and benchmarks fanned out over Ray (the `ray` extra; skipped without it).

One local Ray bound to 127.0.0.1 with 2 CPUs serves the whole module (`xdist_group`: one pytest worker)."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

ray = pytest.importorskip("ray")

import motion_envs  # noqa: E402
from agents.ppo_kl import PPOKL  # noqa: E402
from agents.train_ppo import PPOTrainConfig, train_ppo  # noqa: E402
from agents.train_rllib import export_model  # noqa: E402
from benchmarks import wandr_grid  # noqa: E402
from benchmarks.fanout import run_tasks  # noqa: E402
from motion_envs.priors.training import WEIGHTS_DIR  # noqa: E402

pytestmark = [pytest.mark.ray, pytest.mark.xdist_group("ray")]


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
    yield
    ray.shutdown()


def tiny_config(env_id: str, folder: Path, **changes) -> PPOTrainConfig:
    settings = {"env_id": env_id, "engine": "rllib", "num_envs": 4, "n_steps": 8, "batch_size": 16, "n_epochs": 1,
                "total_timesteps": 32, "init": "scratch", "run_dir": folder / "run", "weights": folder / "policy.zip",
                "net_width": 16, "checkpoint_minutes": 0.0}  # fmt: skip
    return PPOTrainConfig(**{**settings, **changes})


@pytest.mark.parametrize("env_id", sorted(motion_envs.ENV_SPECS))
def test_rllib_ppo_trains_every_id_on_an_env_runner_and_ships_an_sb3_policy(local_ray, tmp_path, env_id):
    from stable_baselines3 import PPO

    config = tiny_config(env_id, tmp_path, env_runners=1)
    entry = train_ppo(config)
    assert entry["timesteps"] >= config.total_timesteps and entry["engine"] == "rllib"
    assert (config.run_dir / "rllib").is_dir() and not (config.run_dir / "rllib.tmp").exists()
    model = (PPOKL if "ClopsNav" not in env_id else PPO).load(config.weights, device="cpu")
    assert model.trained_for["env_id"] == env_id
    initial = tiny_config(env_id, tmp_path / "untrained")
    untrained = export_model(initial)
    changed = [not torch.equal(mine, theirs) for mine, theirs in
               zip(model.policy.state_dict().values(), untrained.policy.state_dict().values())]  # fmt: skip
    assert any(changed), "the shipped weights are the untrained network's"


def test_rllib_dqn_trains_clopsnav_and_ships_a_policy_the_scene_matrix_reads(local_ray, tmp_path):
    from agents.double_dqn import PrioritizedDoubleDQN
    from agents.rllib_dqn import build_sb3_q_policy
    from agents.train_dqn import DQNTrainConfig, train_dqn
    from benchmarks.clops_matrix import cached_core, episodes, policy_actions

    config = DQNTrainConfig(engine="rllib", env_runners=1, num_envs=2, total_timesteps=24, buffer_size=200,
                            learning_starts=8, batch_size=8, gradient_steps=1, target_update_interval=8,
                            checkpoint_minutes=0.0, run_dir=tmp_path / "run", weights=tmp_path / "dqn.zip")  # fmt: skip
    entry = train_dqn(config)
    assert entry["timesteps"] >= 24 and entry["engine"] == "rllib"
    trained = PrioritizedDoubleDQN.load(config.weights, device="cpu").policy.q_net.state_dict()
    assert set(trained) == set(build_sb3_q_policy(*_clops_spaces()).q_net.state_dict())
    core = cached_core("open", ())
    actions = policy_actions(config.weights)(core, episodes(core, 3))
    assert actions.shape == (3,) and int(actions.max()) < core.num_actions


def _clops_spaces():
    import gymnasium as gym

    env = gym.make("motion_envs/ClopsNav-v0")
    return env.observation_space, env.action_space


def test_the_prior_kl_term_pulls_a_narrow_policy_towards_n01(local_ray, tmp_path):
    """α Ψ(KL(π ‖ N(0, I))) dominates a tiny PPO update at α = 100: log σ starts at −2 and must rise."""
    config = tiny_config("motion_envs/GammaReach-v0", tmp_path, alpha=100.0, log_std_init=-2.0, learning_rate=1e-2,
                         n_epochs=4, total_timesteps=96)  # fmt: skip
    train_ppo(config)
    log_std = PPOKL.load(config.weights, device="cpu").policy.log_std
    rise = float(log_std.detach().mean()) + 2.0
    assert rise > 0.1, f"log σ rose by only {rise:.3f}"


def test_exported_policy_computes_what_the_rllib_module_computes(local_ray, tmp_path):
    from ray.rllib.core.columns import Columns

    from agents.rllib_envs import register_rllib_env
    from agents.train_rllib import algorithm_config, module_weights

    config = tiny_config("motion_envs/GammaReach-v0", tmp_path)
    register_rllib_env(config.env_id, config.bootstrap_truncation)
    algorithm = algorithm_config(config).build_algo()
    try:
        algorithm.train()
        model = export_model(config)
        model.policy.load_state_dict(module_weights(algorithm))
        observations = torch.as_tensor(np.random.default_rng(0).normal(size=(5, 804)), dtype=torch.float32)
        with torch.no_grad():
            inputs = algorithm.get_module().forward_inference({Columns.OBS: observations})[Columns.ACTION_DIST_INPUTS]
            distribution = model.policy.get_distribution(observations).distribution
        mean, log_std = inputs.chunk(2, dim=-1)
        torch.testing.assert_close(mean, distribution.loc)
        torch.testing.assert_close(log_std.exp(), distribution.scale)
    finally:
        algorithm.stop()


def test_a_stopped_rllib_run_resumes_from_its_checkpoint(local_ray, tmp_path, capsys):
    train_ppo(tiny_config("motion_envs/WandrReach-v0", tmp_path))
    first = (tmp_path / "run" / "rllib" / "motion_envs_progress.json").read_text()
    entry = train_ppo(tiny_config("motion_envs/WandrReach-v0", tmp_path, total_timesteps=64))
    assert "resuming" in capsys.readouterr().err
    assert '"timesteps": 32' in first and entry["timesteps"] >= 64


def small_rows() -> dict[str, wandr_grid.GridRow]:
    """Two rows of one start pose × one sample (125 rollouts each): the sampler and the shipped PPO policy."""
    rows = {"sampler": wandr_grid.GridRow(WEIGHTS_DIR / "wandr.pt", poses=1, samples=1)}
    policy = WEIGHTS_DIR / "ppo_wandrreach_alpha1_default.zip"
    if policy.exists():
        rows["policy"] = wandr_grid.GridRow(WEIGHTS_DIR / "wandr.pt", "policy", policy=policy, poses=1, samples=1)
    return rows


def single_threaded_rows(rows: dict) -> dict:
    """The rows in this process with one torch thread, as a Ray task has (float reductions can depend on it)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return wandr_grid.run_rows(rows, seed=0)
    finally:
        torch.set_num_threads(threads)


def assert_same_rows(theirs: dict, ours: dict) -> None:
    assert theirs.keys() == ours.keys()
    for label in ours:
        assert torch.equal(theirs[label]["reached"], ours[label]["reached"]), label
        for figure in ("SR", "FS", "DTG", "fast", "peak", "frames"):
            assert theirs[label][figure] == ours[label][figure], (label, figure)


def test_a_wandr_benchmark_split_over_ray_tasks_equals_the_single_process_run(local_ray, monkeypatch):
    monkeypatch.setattr(wandr_grid, "SHARD", 50)  # 125 rollouts a row: 3 tasks of 50, 50 and 25
    rows = small_rows()
    assert all(len(row.shards()) == 3 for row in rows.values())
    assert_same_rows(wandr_grid.run_rows(rows, seed=0, ray_address="local"), single_threaded_rows(rows))


class KillFirstAttempt:
    """Runs `function`, except that the first attempt of the task numbered `victim` kills its own worker process
    (SIGKILL, as the OOM killer or a lost node would). Pickled by value: Ray workers cannot import this module."""

    def __init__(self, function, marker: Path, victim: int) -> None:
        self.function, self.marker, self.victim = function, marker, victim
        self.__name__ = "KillFirstAttempt"

    def __call__(self, index: int, *arguments):
        if index == self.victim and not self.marker.exists():
            self.marker.write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)
        return self.function(*arguments)


def test_a_worker_killed_mid_benchmark_is_retried_and_the_table_is_complete(local_ray, tmp_path, monkeypatch):
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    monkeypatch.setattr(wandr_grid, "SHARD", 50)
    row = small_rows()["sampler"]
    tasks = [(index, row, first, last, 0) for index, (first, last) in enumerate(row.shards())]
    killer = KillFirstAttempt(wandr_grid.run_shard, tmp_path / "killed", victim=1)
    parts = run_tasks(killer, tasks, ray_address="local")
    assert (tmp_path / "killed").exists(), "no worker was killed"
    merged = wandr_grid.merge_shards(parts)
    expected = single_threaded_rows({"sampler": row})["sampler"]
    assert len(merged["reached"]) == 125
    assert_same_rows({"sampler": merged}, {"sampler": expected})


def test_gamma_and_clops_benchmarks_split_over_ray_equal_the_single_process_run(local_ray, monkeypatch):
    from benchmarks import clops_matrix, gamma_control

    monkeypatch.setattr(gamma_control, "PAIRS_PER_TASK", 2)
    monkeypatch.setattr(clops_matrix, "EPISODES_PER_TASK", 2)
    gamma_rows = {"random z": gamma_control.GammaRow("random", clones=2, precision="float32")}
    clops_row = clops_matrix.ClopsRow("random")
    tasks = [(clops_row, "open", first, first + 2, 0) for first in (0, 2)]
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as a Ray task has
    try:
        gamma_here = gamma_control.run_rows(gamma_rows, pairs=4, seed=0)
        clops_here = clops_matrix.scores_of(run_tasks(clops_matrix.run_shard, tasks))
    finally:
        torch.set_num_threads(threads)
    gamma_there = gamma_control.run_rows(gamma_rows, pairs=4, seed=0, ray_address="local")
    clops_there = clops_matrix.scores_of(run_tasks(clops_matrix.run_shard, tasks, ray_address="local"))
    for figure in ("steps", "success rate", "avg. dist.", "contact score", "FS"):
        assert gamma_here["random z"][figure] == gamma_there["random z"][figure] or np.isnan(gamma_here["random z"][figure])
    np.testing.assert_array_equal(gamma_here["random z"]["paths"], gamma_there["random z"]["paths"])
    figures = ("success", "collision", "skating", "fallen", "left", "timed_out")
    assert [getattr(clops_here, name) for name in figures] == [getattr(clops_there, name) for name in figures]
    np.testing.assert_array_equal(clops_here.paths, clops_there.paths)
