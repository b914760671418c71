"""Stable-Baselines3 `VecEnv` over a native batched Gymnasium `VectorEnv` (no subprocesses).

One process steps all bodies in one batched call; SB3's `VecNormalize`,
`VecMonitor` and every on/off-policy algorithm work on top:

    from agents.vec_env import NativeVecEnv
    venv = VecMonitor(NativeVecEnv.make("motion_envs/GammaReach-v0", num_envs=256))
    PPO("MlpPolicy", venv).learn(1_000_000)

The wrapped env must autoreset in the same step (`AutoresetMode.SAME_STEP`,
like every motion_envs vector env), which is SB3's own convention: the ended
episode's last observation goes to `infos[i]["terminal_observation"]` and
time-limit ends are flagged with `infos[i]["TimeLimit.truncated"]`.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvStepReturn


class NativeVecEnv(VecEnv):
    """SB3 view of a same-step-autoreset `VectorEnv` (e.g. `GammaReachVectorEnv`).

    `bootstrap_truncation=False` reports time-limit ends as true ends (no `TimeLimit.truncated`), so
    SB3 does not add γ·V(last observation) to the last reward. Use it for fixed-horizon tasks whose
    observation does not show the time left, as GAMMA's (Monte-Carlo returns over 60 primitives):
    there V of a state at the time limit is the value of the same state with the whole episode ahead,
    and bootstrapping it pays more for running out of time than reaching the goal does (measured on
    GammaReach: every PPO run drifted from 0.3-0.5 success down to 0.1-0.2 once its critic fitted; with
    Monte-Carlo returns the α = 1 run rose steadily from 0.29 to 0.73 over 2.1M steps)."""

    def __init__(self, vector_env: VectorEnv, bootstrap_truncation: bool = True) -> None:
        mode = vector_env.metadata.get("autoreset_mode")
        if mode != AutoresetMode.SAME_STEP:
            raise ValueError(f"NativeVecEnv needs a same-step autoreset vector env, got autoreset_mode={mode!r}")
        self.vector_env = vector_env
        self.bootstrap_truncation = bootstrap_truncation
        super().__init__(vector_env.num_envs, vector_env.single_observation_space, vector_env.single_action_space)
        self._actions: np.ndarray | None = None

    @classmethod
    def make(cls, env_id: str, num_envs: int, bootstrap_truncation: bool = True, **kwargs: Any) -> NativeVecEnv:
        """`gym.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point", **kwargs)` wrapped."""
        vector_env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
        return cls(vector_env, bootstrap_truncation)

    def reset(self) -> np.ndarray:
        """Resets every body; seeds from `seed()` (body i: seed + i) and options from `set_options()`
        (the native env takes one options dict for all bodies: the first one's)."""
        seeds = None if all(seed is None for seed in self._seeds) else [int(seed) for seed in self._seeds]
        observations, _ = self.vector_env.reset(seed=seeds, options=self._options[0] or None)
        self._reset_seeds()
        self._reset_options()
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        observations, rewards, terminated, truncated, info = self.vector_env.step(self._actions)
        dones = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for index in np.flatnonzero(dones):  # only ended episodes carry information SB3 reads
            infos[index]["terminal_observation"] = info["final_obs"][index]
            infos[index]["TimeLimit.truncated"] = self.bootstrap_truncation and bool(truncated[index] and not terminated[index])
            final = info.get("final_info", {})
            for name, values in final.items():  # is_success, and e.g. GammaWander's episode collisions
                if not name.startswith("_"):
                    infos[index][name] = values[index].item()
        return observations, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.vector_env.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        value = getattr(self.vector_env.unwrapped, attr_name)
        return [value] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.vector_env.unwrapped, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        result = getattr(self.vector_env.unwrapped, method_name)(*method_args, **method_kwargs)
        return [result] * len(self._get_indices(indices))

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: Any = None) -> list[bool]:
        return [False] * len(self._get_indices(indices))
