"""motion_envs ids as RLlib environments: one native batched env per env runner, episode success as a metric.

RLlib's `SingleAgentEnvRunner` calls `gym.make_vec(name, num_envs=N, vectorization_mode=...)`. Registered here
(`register_rllib_env`), `name` resolves to our native vector env (`vectorization_mode="vector_entry_point"`):
N bodies in one batched call inside the runner's process, no per-body subprocesses, so one runner drives
hundreds of bodies and more runners (local or on other nodes of the cluster) scale out. RLlib expects
Gymnasium's next-step autoreset, which our vector envs take as `autoreset_mode="next_step"`.

Time-limit ends: with `bootstrap_truncation=False` (the GAMMA default of `train ppo`, see
`agents.vec_env.NativeVecEnv`) the wrapper reports them as terminations, so RLlib's GAE adds no γ·V at the end
and the returns are the paper's Monte-Carlo ones.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import VectorEnv, VectorWrapper
from ray.rllib.callbacks.callbacks import RLlibCallback
from ray.tune.registry import register_env

SUCCESSES, ENDED = "motion_envs_successes", "motion_envs_episodes_ended"
"""Per-iteration sums the env runners report: episodes that ended with `is_success`, and episodes that ended."""


class TimeLimitAsTermination(VectorWrapper):
    """Truncated bodies reported as terminated: no value bootstrap at the time limit (Monte-Carlo returns)."""

    def step(self, actions: np.ndarray):
        observation, reward, terminated, truncated, info = self.env.step(actions)
        return observation, reward, terminated | truncated, np.zeros_like(truncated), info


def make_env(env_id: str, bootstrap_truncation: bool, context: dict[str, Any]) -> gym.Env | VectorEnv:
    """The env RLlib asks for: a single env, or (with "num_envs" in `context`, RLlib's vector entry point) the
    native vector env in next-step autoreset mode. `context` (RLlib's `EnvContext`) holds the `gym.make`
    arguments."""
    import motion_envs  # noqa: F401  registers the ids in this (possibly remote) process

    kwargs = dict(context)
    num_envs = kwargs.pop("num_envs", None)
    if num_envs is None:
        return gym.make(env_id, **kwargs)
    vector_env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                              autoreset_mode="next_step", **kwargs)  # fmt: skip
    return vector_env if bootstrap_truncation else TimeLimitAsTermination(vector_env)


def rllib_env_name(env_id: str, bootstrap_truncation: bool = True) -> str:
    """The name `register_rllib_env` registers `env_id` under."""
    return f"{env_id}@rllib" + ("" if bootstrap_truncation else "-monte-carlo")


def register_rllib_env(env_id: str, bootstrap_truncation: bool = True) -> str:
    """Register `env_id` with Ray's registry (call after `ray.init`; remote runners read it from the cluster).

    Returns:
        The name to pass to `AlgorithmConfig.environment(env=...)`.

    Raises:
        ValueError: `env_id` is not a motion_envs id.
    """
    import motion_envs

    if env_id not in motion_envs.ENV_SPECS:
        raise ValueError(f"{env_id!r} is not a motion_envs id; known: {sorted(motion_envs.ENV_SPECS)}")
    name = rllib_env_name(env_id, bootstrap_truncation)
    register_env(name, lambda context: make_env(env_id, bootstrap_truncation, context))
    return name


class EpisodeSuccess(RLlibCallback):
    """Counts ended episodes and those whose last info says `is_success` (summed per training iteration)."""

    def on_episode_end(self, *, episode: Any, metrics_logger: Any = None, **kwargs: Any) -> None:
        info = episode.get_infos(-1)
        metrics_logger.log_value(ENDED, 1, reduce="sum")
        metrics_logger.log_value(SUCCESSES, float(bool(info.get("is_success", False))), reduce="sum")
