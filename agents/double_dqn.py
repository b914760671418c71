"""Double DQN with prioritised experience replay on top of Stable-Baselines3's DQN (CLOPS's agent, Sec. 4).

`PrioritizedDoubleDQN` is SB3's `DQN` with two changes in `train`:

* double Q-learning (van Hasselt et al., 2016): the online network picks
  the next action, the target network values it,
  y = r + γ (1 − done) Q_target(s', argmax_a Q_online(s', a));
* prioritised replay (Schaul et al., 2015): batches come from
  `PrioritizedReplayBuffer` (or its dict twin), the Huber loss is weighted
  by the importance weights, the batch's TD errors become its new
  priorities, and β rises linearly from `beta_start` to `beta_end` over
  training.

Everything else is SB3's: `learn`, `predict`, `save`/`load`, callbacks,
ε-greedy exploration, target updates, `CnnPolicy` / `MultiInputPolicy`.

    from agents.double_dqn import PrioritizedDoubleDQN
    model = PrioritizedDoubleDQN("CnnPolicy", venv, buffer_size=50_000, learning_starts=2_000)
    model.learn(200_000)
    model.save("dqn_clops.zip"); PrioritizedDoubleDQN.load("dqn_clops.zip")
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3 import DQN

from agents.prioritized_replay import PrioritizedDictReplayBuffer, PrioritizedReplayBuffer


class PrioritizedDoubleDQN(DQN):
    """SB3 DQN with double-Q targets and prioritised replay (see the module doc).

    Args (beyond DQN's):
        alpha: priority exponent (0: uniform replay).
        beta_start, beta_end: importance-weight exponent at the start and end of `learn`.
        prioritized: False gives uniform replay (SB3's own buffer) with the double-Q target.
    """

    def __init__(self, policy: Any, env: Any, alpha: float = 0.6, beta_start: float = 0.4, beta_end: float = 1.0,
                 prioritized: bool = True, **kwargs: Any) -> None:  # fmt: skip
        self.alpha, self.beta_start, self.beta_end, self.prioritized = alpha, beta_start, beta_end, prioritized
        if prioritized and kwargs.get("replay_buffer_class") is None and env is not None:
            observation_space = env.observation_space if not isinstance(env, str) else None
            dict_space = isinstance(observation_space, spaces.Dict)
            kwargs["replay_buffer_class"] = PrioritizedDictReplayBuffer if dict_space else PrioritizedReplayBuffer
            kwargs["replay_buffer_kwargs"] = {"alpha": alpha, "beta": beta_start, **(kwargs.get("replay_buffer_kwargs") or {})}
        super().__init__(policy, env, **kwargs)

    def _beta(self) -> float:
        done = 1.0 - self._current_progress_remaining
        return self.beta_start + (self.beta_end - self.beta_start) * done

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        prioritized = hasattr(self.replay_buffer, "update_priorities")
        if prioritized:
            self.replay_buffer.beta = self._beta()
        losses, values = [], []
        for _ in range(gradient_steps):
            batch = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)
            discounts = batch.discounts if batch.discounts is not None else self.gamma
            with torch.no_grad():
                next_actions = self.q_net(batch.next_observations).argmax(dim=1, keepdim=True)  # online net picks
                next_values = self.q_net_target(batch.next_observations).gather(1, next_actions)  # target net values
                targets = batch.rewards + (1 - batch.dones) * discounts * next_values
            values_now = self.q_net(batch.observations).gather(1, batch.actions.long())
            per_sample = F.smooth_l1_loss(values_now, targets, reduction="none")
            weights = batch.weights if prioritized else torch.ones_like(per_sample)
            loss = (weights * per_sample).mean()
            self.policy.optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
            if prioritized:
                self.replay_buffer.update_priorities(batch, (targets - values_now).detach().cpu().numpy())
            losses.append(loss.item())
            values.append(values_now.mean().item())
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", float(np.mean(losses)))
        self.logger.record("train/mean_q", float(np.mean(values)))
        if prioritized:
            self.logger.record("train/per_beta", self.replay_buffer.beta)
