"""What every environment shares: checked actions, configs built from `gym.make` kwargs, and the native
vector env over a batched core."""

from __future__ import annotations

import dataclasses
from typing import Any, Protocol, TypeVar

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv

from motion_envs.batched import BatchedState
from motion_envs.body import BodyModel
from motion_envs.render.env_view import EnvView, RenderInputs
from motion_envs.scenes.scene import Scene

Config = TypeVar("Config")


def check_actions(actions: Any, shape: tuple[int, ...], batch: int | None) -> np.ndarray:
    """Actions as float32, checked: `shape` for one body (batch None) or (batch, *shape); all finite.

    Raises:
        ValueError: naming the expected and received shape, or the non-finite entries.
    """
    array = np.asarray(actions, dtype=np.float32)
    expected = tuple(shape) if batch is None else (batch, *shape)
    if array.shape != expected:
        raise ValueError(f"action must have shape {expected}, got {array.shape}")
    if not np.isfinite(array).all():
        bad = np.argwhere(~np.isfinite(array))[:5].tolist()
        raise ValueError(f"action contains NaN or inf (first at indices {bad})")
    return array


def config_from_kwargs(config_type: type[Config], kwargs: dict[str, Any], env_name: str) -> Config:
    """`config_type(**kwargs)`, with unknown keys reported by name next to the valid ones."""
    valid = {field.name for field in dataclasses.fields(config_type)}
    unknown = sorted(set(kwargs) - valid)
    if unknown:
        raise TypeError(f"{env_name} got unknown arguments {unknown}; valid: {sorted(valid)}")
    return config_type(**kwargs)


Observation = Any
"""A batch of observations: an array (N, ...) or a dict of them."""


def as_numpy(observation: torch.Tensor | np.ndarray | dict) -> Observation:
    """Tensors (and dicts of them) as numpy arrays."""
    if isinstance(observation, dict):
        return {key: as_numpy(value) for key, value in observation.items()}
    return observation.cpu().numpy() if isinstance(observation, torch.Tensor) else observation


def _rows(observation: Observation, rows: Any) -> Observation:
    if isinstance(observation, dict):
        return {key: value[rows] for key, value in observation.items()}
    return observation[rows]


def _set_rows(observation: Observation, rows: np.ndarray, values: Observation) -> None:
    if isinstance(observation, dict):
        for key in observation:
            observation[key][rows] = values[key]
    else:
        observation[rows] = values


class BatchedCore(Protocol):
    """What `CoreVectorEnv` needs of an environment's batched core."""

    device: torch.device

    def sample_initial_state(self, rngs: list[np.random.Generator], options: dict[str, Any] | None = None) -> Any: ...

    def observe(self, state: Any) -> torch.Tensor | np.ndarray | dict[str, np.ndarray]: ...

    def step(self, state: Any, z: torch.Tensor) -> tuple[Any, Any]: ...

    body: BodyModel
    goal_marker: tuple[str, float]

    def render_inputs(self, state: Any) -> RenderInputs: ...


class CoreVectorEnv(VectorEnv):
    """N bodies of one batched core; same-step autoreset (ended bodies restart at once, without options,
    as Gymnasium's own vector envs do; their last observation and info are in `info["final_obs"]` /
    `info["final_info"]`). Subclasses build the core and say what goes into `info` (`_step_info`).

    `render_mode="rgb_array"`: `render()` draws the first `render_bodies` bodies in one image (camera on
    their mean pelvis), each with its goal and pelvis trail, in the core's `render_scene(state)` where the
    core has one."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"]}

    def __init__(self, core: BatchedCore, num_envs: int, single_action_space: gym.spaces.Box,
                 single_observation_space: gym.spaces.Box, render_mode: str | None = None,
                 render_bodies: int = 8) -> None:  # fmt: skip
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode, self.render_bodies = render_mode, render_bodies
        self._view: EnvView | None = None
        self._view_scene: Scene | None = None
        self.trails: list[list[np.ndarray]] = []
        self.core = core
        self.num_envs = num_envs
        self.single_action_space, self.single_observation_space = single_action_space, single_observation_space
        self.action_space = gym.vector.utils.batch_space(single_action_space, num_envs)
        self.observation_space = gym.vector.utils.batch_space(single_observation_space, num_envs)
        self.rngs = [np.random.default_rng() for _ in range(num_envs)]
        self.state: BatchedState | None = None

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        if seed is not None:
            seeds = seed if isinstance(seed, list) else [seed + i for i in range(self.num_envs)]
            self.rngs = [np.random.default_rng(s) for s in seeds]  # body i follows the single env reset with seed + i
        self.state = self.core.sample_initial_state(self.rngs, options)
        if self.render_mode is not None:
            self.trails = [[pelvis] for pelvis in self._drawn_pelvis()]
        return as_numpy(self.core.observe(self.state)), {}

    def _step_info(self, result: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """(info of every body, final info of the bodies that ended: arrays over all bodies, with is_success)."""
        raise NotImplementedError

    def step(self, actions: np.ndarray):
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        z = check_actions(actions, self.single_action_space.shape, batch=self.num_envs)
        self.state, result = self.core.step(self.state, torch.as_tensor(z))
        done = (result.terminated | result.truncated).cpu()
        observation = as_numpy(self.core.observe(self.state))
        info, final = self._step_info(result)
        if done.any():
            ended = torch.nonzero(done).flatten()
            info["final_obs"] = np.empty(self.num_envs, dtype=object)  # one observation per ended body, None elsewhere
            for i in ended.tolist():
                info["final_obs"][i] = _rows(observation, i)
            info["final_info"] = {**final, **{f"_{name}": done.numpy() for name in final}}
            info["_final_obs"] = info["_final_info"] = done.numpy()
            fresh = self.core.sample_initial_state([self.rngs[i] for i in ended.tolist()])
            order = torch.zeros(self.num_envs, dtype=torch.long)
            order[ended] = torch.arange(len(ended))  # fresh body k goes to row ended[k]; other rows are masked
            self.state = self.state.replace_bodies(done.to(self.core.device), fresh.index(order.to(self.core.device)))
            _set_rows(observation, ended.numpy(), as_numpy(self.core.observe(fresh)))  # only the new bodies are observed
        if self.render_mode is not None:
            for trail, pelvis, restarted in zip(self.trails, self._drawn_pelvis(), done.tolist()):
                trail[:] = [pelvis] if restarted else [*trail, pelvis]
        return (observation, result.reward.cpu().numpy().astype(np.float64), result.terminated.cpu().numpy(),
                result.truncated.cpu().numpy(), info)  # fmt: skip

    def render(self) -> np.ndarray | None:
        """rgb_array: (H, W, 3) uint8 of the first `render_bodies` bodies (None without a render mode)."""
        if self.render_mode is None or self.state is None:
            return None
        scene = self.core.render_scene(self.state) if hasattr(self.core, "render_scene") else None  # cores with a scene
        if self._view is None or self._view_scene is not scene:
            self._view = EnvView(self.core.body, *self.core.goal_marker, max_bodies=self.render_bodies, scene=scene)
            self._view_scene = scene
        return self._view.frame(self.core.render_inputs(self.state), [np.array(trail) for trail in self.trails])

    def _drawn_pelvis(self) -> np.ndarray:
        """(min(N, render_bodies), 3) pelvis positions of the bodies a render draws."""
        return self.core.render_inputs(self.state).pelvis[: self.render_bodies].detach().cpu().numpy()
