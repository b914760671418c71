"""Every env, shipped agent, trainer and the tree search run on one device end to end (`motion-envs bench gpu`).

Each row is one job on `device`: an env made with `device=` and the `gym.make` arguments its shipped policy was
trained for, stepped by that policy with its network on the same device, and rendered once; a tiny PPO and DQN
training run; a tree search with the α = 1 policy. A row records the steps taken, the wall time and whether every
reward was finite, or the exception that stopped it, so that one run on a GPU machine reports every failure at once.
`tests/test_package.py` runs it on the CPU.
"""

from __future__ import annotations

import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

import motion_envs  # noqa: F401  (registers the ids)
from motion_envs.priors.training import WEIGHTS_DIR

SHIPPED_POLICIES = ("ppo_gammareach_alpha1_paper.zip", "ppo_gammawander_alpha1_paper.zip",
                    "ppo_wandrreach_alpha1_default.zip", "dqn_clopsnav_open.zip")  # fmt: skip


@dataclass(frozen=True)
class JobResult:
    """One end-to-end job on the device: `steps` env steps (or training timesteps) in `seconds`; `error` is the
    exception's last line, empty when it ran."""

    job: str
    steps: int
    seconds: float
    finite: bool
    error: str = ""

    @property
    def ran(self) -> bool:
        return not self.error and self.finite


def load_policy(path: Path, device: str):
    """The SB3 model of a shipped policy file (PPOKL or the ClopsNav DQN) on `device`, and the file's description."""
    from agents.double_dqn import PrioritizedDoubleDQN
    from agents.policy_files import read_policy_file
    from agents.ppo_kl import PPOKL

    file = read_policy_file(path)
    model_class = PPOKL if file.kind == "ppo_policy" else PrioritizedDoubleDQN
    return model_class.load(path, device=device), file


def policy_episode(name: str, device: str, steps: int) -> tuple[int, bool]:
    """Step the env the shipped policy `name` was trained for (made on `device`) `steps` times with that policy's
    deterministic action, resetting when an episode ends; render one frame. Returns (steps, every reward finite)."""
    model, file = load_policy(WEIGHTS_DIR / name, device)
    env = gym.make(file.trained_for.env_id, render_mode="rgb_array", device=device, **file.trained_for.env_kwargs)
    observation, _ = env.reset(seed=0)
    finite = True
    for _ in range(steps):
        action, _ = model.predict(observation, deterministic=True)
        observation, reward, terminated, truncated, _ = env.step(action)
        finite &= bool(np.isfinite(reward))
        if terminated or truncated:
            observation, _ = env.reset()
    frame = env.render()
    env.close()
    return steps, finite and frame is not None and frame.ndim == 3


def finite_weights(path: Path) -> bool:
    """Whether every parameter of the policy saved at `path` is finite."""
    model, _ = load_policy(path, "cpu")
    return all(bool(torch.isfinite(parameter).all()) for parameter in model.policy.parameters())


def train_ppo_tiny(device: str, timesteps: int) -> tuple[int, bool]:
    """A PPO run on GammaReach from scratch (no mocap needed) for `timesteps` primitives on `device`."""
    from agents.train_ppo import PPOTrainConfig, train_ppo

    with tempfile.TemporaryDirectory() as folder:
        config = PPOTrainConfig(init="scratch", num_envs=8, n_steps=max(timesteps // 8, 1), batch_size=8, n_epochs=1,
                                total_timesteps=timesteps, device=device, run_dir=Path(folder) / "run",
                                weights=Path(folder) / "policy.zip")  # fmt: skip
        entry = train_ppo(config)
        return int(entry["timesteps"]), finite_weights(config.weights)


def train_dqn_tiny(device: str, timesteps: int) -> tuple[int, bool]:
    """A DQN run on ClopsNav for `timesteps` actions on `device` (its views are ray-cast on the CPU)."""
    from agents.train_dqn import DQNTrainConfig, train_dqn

    with tempfile.TemporaryDirectory() as folder:
        config = DQNTrainConfig(num_envs=2, total_timesteps=timesteps, learning_starts=timesteps // 2, batch_size=8,
                                buffer_size=500, target_update_interval=timesteps, device=device,
                                run_dir=Path(folder) / "run", weights=Path(folder) / "policy.zip")  # fmt: skip
        entry = train_dqn(config)
        return int(entry["timesteps"]), finite_weights(config.weights)


def tree_search(device: str, depth: int) -> tuple[int, bool]:
    """GAMMA's tree search (4 roots, 2 children, top-2) for 2 bodies on `device`, the α = 1 policy proposing."""
    from agents.controllers import PolicyLatent
    from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore
    from motion_envs.wrappers.tree_search import SearchSettings, beam_search

    core = GammaReachCore(GammaReachConfig(device=device, max_primitives=depth))
    start = core.sample_initial_state([np.random.default_rng(seed) for seed in range(2)])
    policy = PolicyLatent(WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip", device=device)
    found = beam_search(core, start, policy, SearchSettings(roots=4, children=2, keep=2, max_depth=depth))
    return depth, bool(torch.isfinite(found.cost).all())


def run_job(job: str, work: Callable[[], tuple[int, bool]]) -> JobResult:
    """`work()` timed; an exception becomes the row's error (its last line) and is printed in full."""
    began = time.perf_counter()
    try:
        steps, finite = work()
    except Exception as error:  # noqa: BLE001  (a row per failure: one GPU run reports every one)
        traceback.print_exc()
        return JobResult(job, 0, time.perf_counter() - began, False, f"{type(error).__name__}: {error}".splitlines()[0])
    return JobResult(job, steps, time.perf_counter() - began, finite)


def jobs(device: str, steps: int = 20, timesteps: int = 64) -> dict[str, Callable[[], tuple[int, bool]]]:
    """Every job on `device` by name: each shipped policy's env for `steps` steps, PPO and DQN for `timesteps`, a
    tree search of 3 primitives."""
    return {
        **{f"{name} in its env": (lambda name=name: policy_episode(name, device, steps)) for name in SHIPPED_POLICIES},
        "train ppo (GammaReach, from scratch)": lambda: train_ppo_tiny(device, timesteps),
        "train dqn (ClopsNav)": lambda: train_dqn_tiny(device, timesteps),
        "tree search (GammaReach, α = 1 policy)": lambda: tree_search(device, 3),
    }


def end_to_end(device: str, steps: int = 20, timesteps: int = 64) -> list[JobResult]:
    """Every job of `jobs`, run."""
    return [run_job(job, work) for job, work in jobs(device, steps, timesteps).items()]


def table(results: list[JobResult]) -> list[str]:
    """Markdown rows of `results`."""
    rows = ["| job | steps | seconds | ran |", "|---|---|---|---|"]
    for result in results:
        verdict = "yes" if result.ran else (f"no: {result.error}" if result.error else "no: a non-finite value")
        rows.append(f"| {result.job} | {result.steps:,} | {result.seconds:.1f} | {verdict} |")
    return rows
