"""What every environment shares: checked actions, configs built from `gym.make` kwargs, and the native
vector env over a batched core."""

from __future__ import annotations

import dataclasses
import os
import types
import typing
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


def _single_threaded_after_fork() -> None:
    """A forked child of a process whose torch thread pool has run deadlocks in its first parallel region (measured:
    `gym.make_vec(..., vectorization_mode="async")`, whose default on Linux is fork, hung in `reset` for every env;
    its spaces come from an env built in the parent). A forked child runs torch on one thread: one env per process
    is what async vector envs are for. The spawn context needs nothing."""
    torch.set_num_threads(1)


os.register_at_fork(after_in_child=_single_threaded_after_fork)


def check_actions(actions: Any, shape: tuple[int, ...], batch: int | None) -> np.ndarray:
    """Actions as float32, checked: real numbers (numpy, lists, Python numbers or torch tensors, detached), `shape`
    for one body (batch None) or (batch, *shape); all finite.

    Raises:
        ValueError: naming the expected and received shape, a non-numeric type (None, strings, complex, bool) or the
        non-finite entries.
    """
    if actions is None:
        raise ValueError(f"action is None; expected real numbers of shape {tuple(shape) if batch is None else (batch, *shape)}")
    if isinstance(actions, torch.Tensor):
        actions = actions.detach().cpu().numpy()
    try:
        raw = np.asarray(actions)
    except ValueError as error:  # ragged sequences
        raise ValueError(f"action must be a regular array of numbers, got {actions!r}") from error
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"action must hold real numbers, got {type(actions).__name__} of dtype {raw.dtype}: {actions!r}"[:300])
    with np.errstate(over="ignore"):  # beyond float32's range becomes inf, refused below
        array = raw.astype(np.float32)
    expected = tuple(shape) if batch is None else (batch, *shape)
    if array.shape != expected:
        raise ValueError(f"action must have shape {expected}, got {array.shape}")
    if not np.isfinite(array).all():
        bad = np.argwhere(~np.isfinite(array))[:5].tolist()
        raise ValueError(f"action contains NaN or inf, or values beyond float32's range (first at indices {bad})")
    return array


def config_from_kwargs(config_type: type[Config], kwargs: dict[str, Any], env_name: str) -> Config:
    """`config_type(**kwargs)`, with unknown keys reported by name next to the valid ones and values of the wrong
    type (`check_field_type`) by name, with the type expected."""
    valid = {field.name for field in dataclasses.fields(config_type)}
    unknown = sorted(set(kwargs) - valid)
    if unknown:
        raise TypeError(f"{env_name} got unknown arguments {unknown}; valid: {sorted(valid)}")
    hints = typing.get_type_hints(config_type)
    for name, value in kwargs.items():
        if not check_field_type(value, hints[name]):
            raise TypeError(f"{env_name} argument {name!r} must be {_type_name(hints[name])}, got {value!r} ({type(value).__name__})")
    return config_type(**kwargs)


def check_field_type(value: Any, hint: Any) -> bool:
    """Whether `value` fits a config field's type: int (not bool, no float), float (a real number, not NaN), bool,
    str, None, unions, tuples (fixed or `...`) and dicts of those; other types (reward configs, which also take
    their names as strings) are left to the config's own checks."""
    origin, arguments = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(check_field_type(value, argument) for argument in arguments)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, (bool, np.bool_))
    if hint is int:
        return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if hint is float:
        real = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
        return real and not np.isnan(value)
    if hint is str:
        return isinstance(value, str)
    if origin is tuple:
        if not isinstance(value, (tuple, list)):
            return False
        if len(arguments) == 2 and arguments[1] is Ellipsis:
            return all(check_field_type(item, arguments[0]) for item in value)
        return len(value) == len(arguments) and all(check_field_type(item, kind) for item, kind in zip(value, arguments))
    if origin is dict or hint is dict:
        return isinstance(value, dict)
    return True


def _type_name(hint: Any) -> str:
    """'int', 'tuple[float, float]', 'str | None'."""
    plain = typing.get_origin(hint) is None and hasattr(hint, "__name__")
    return hint.__name__ if plain else str(hint).replace("typing.", "").replace("NoneType", "None")


AUTORESET_MODES = {"same_step": AutoresetMode.SAME_STEP, "next_step": AutoresetMode.NEXT_STEP}
"""The vector envs' autoreset modes by name (the `AutoresetMode` values themselves are taken too)."""

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
    """N bodies of one batched core. Same-step autoreset by default (ended bodies restart at once, without
    options, as Gymnasium's own vector envs do; their last observation and info are in `info["final_obs"]` /
    `info["final_info"]`; SB3's adapter `agents.vec_env.NativeVecEnv` needs it). `autoreset_mode="next_step"`
    (Gymnasium's default mode, which its vector `NormalizeObservation` requires): the step that ends a body returns
    its last observation and info; its next step ignores its action and returns its new start (reward 0, neither
    terminated nor truncated). Subclasses build the core and say what goes into `info` (`_step_info`).

    `render_mode="rgb_array"`: `render()` draws the first `render_bodies` bodies in one image (camera on
    their mean pelvis), each with its goal and pelvis trail, in the core's `render_scene(state)` where the
    core has one."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"]}

    def __init__(self, core: BatchedCore, num_envs: int, single_action_space: gym.spaces.Box,
                 single_observation_space: gym.spaces.Box, render_mode: str | None = None,
                 render_bodies: int = 8, autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP) -> None:  # fmt: skip
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        mode = autoreset_mode if isinstance(autoreset_mode, AutoresetMode) else AUTORESET_MODES.get(autoreset_mode)
        if mode not in AUTORESET_MODES.values():
            raise ValueError(f"autoreset_mode must be one of {sorted(AUTORESET_MODES)}, got {autoreset_mode!r}")
        self.metadata = {**self.metadata, "autoreset_mode": mode}
        self._restart_next = torch.zeros(num_envs, dtype=torch.bool)
        """NEXT_STEP mode: bodies that ended in the last step and restart in the next one."""
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
        self._restart_next[:] = False
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
        reward = result.reward.cpu().numpy().astype(np.float64)
        terminated, truncated = result.terminated.cpu().numpy(), result.truncated.cpu().numpy()
        observation = as_numpy(self.core.observe(self.state))
        info, final = self._step_info(result)
        if self.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP:
            restarted = self._restart_next  # ended last step: this step only restarts them (its motion is dropped)
            done = done & ~restarted
            self._restart_next = done
            reward[restarted.numpy()] = 0.0
            terminated[restarted.numpy()] = truncated[restarted.numpy()] = False
            if done.any():  # Gymnasium's next-step convention: the ending step's info holds the episode's figures
                info.update({**final, **{f"_{name}": done.numpy() for name in final}})
        else:
            restarted = done
            if done.any():
                info["final_obs"] = np.empty(self.num_envs, dtype=object)  # one observation per ended body, None elsewhere
                for i in torch.nonzero(done).flatten().tolist():
                    info["final_obs"][i] = _rows(observation, i)
                info["final_info"] = {**final, **{f"_{name}": done.numpy() for name in final}}
                info["_final_obs"] = info["_final_info"] = done.numpy()
        if restarted.any():
            self._restart(restarted, observation)
        self.record_trails(restarted)
        return observation, reward, terminated, truncated, info

    def record_trails(self, restarted: torch.Tensor) -> None:
        """With a render mode, add the drawn bodies' pelvis to their trails; bodies `restarted` (N,) bool begin anew."""
        if self.render_mode is not None:
            for trail, pelvis, new in zip(self.trails, self._drawn_pelvis(), restarted.tolist()):
                trail[:] = [pelvis] if new else [*trail, pelvis]

    def _restart(self, rows: torch.Tensor, observation: Observation) -> None:
        """Start new episodes for the bodies where `rows` (N,) bool is true, writing their observations in place."""
        ended = torch.nonzero(rows).flatten()
        fresh = self.core.sample_initial_state([self.rngs[i] for i in ended.tolist()])
        order = torch.zeros(self.num_envs, dtype=torch.long)
        order[ended] = torch.arange(len(ended))  # fresh body k goes to row ended[k]; other rows are masked
        self.state = self.state.replace_bodies(rows.to(self.core.device), fresh.index(order.to(self.core.device)))
        _set_rows(observation, ended.numpy(), as_numpy(self.core.observe(fresh)))  # only the new bodies are observed

    def render(self) -> np.ndarray | None:
        """rgb_array: (H, W, 3) uint8 of the first `render_bodies` bodies (None without a render mode)."""
        if self.render_mode is None or self.state is None:
            return None
        scene = self.core.render_scene(self.state) if hasattr(self.core, "render_scene") else None  # cores with a scene
        if self._view is None or self._view_scene is not scene:
            self._view = EnvView(self.core.body, *self.core.goal_marker, max_bodies=self.render_bodies, scene=scene)
            self._view_scene = scene
        paths = self.core.render_paths(self.state) if hasattr(self.core, "render_paths") else None  # cores with routes
        return self._view.frame(self.core.render_inputs(self.state), [np.array(trail) for trail in self.trails], paths)

    def _drawn_pelvis(self) -> np.ndarray:
        """(min(N, render_bodies), 3) pelvis positions of the bodies a render draws."""
        return self.core.render_inputs(self.state).pelvis[: self.render_bodies].detach().cpu().numpy()
