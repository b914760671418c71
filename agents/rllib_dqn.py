"""RLlib DQN (new API stack) whose Q-network is the SB3 DQN policy `agents.train_dqn` trains.

`SB3QModule` is RLlib's default DQN module with its networks replaced by an SB3 `DQNPolicy` (NatureCNN on
ClopsNav's views; SB3's multi-input extractor with the known goal or the goal memory): RLlib's DQN
(double-Q targets and prioritised episode replay, as CLOPS's agent) trains `policy.q_net` and updates
`policy.q_net_target` as its target network, so the trained weights load unchanged into a
`PrioritizedDoubleDQN` file (`agents.train_rllib.train_rllib_dqn`), which `bench clops`, `play` and `view`
read as any other ClopsNav policy. Plain Q-values only: no dueling heads, one atom.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from ray.rllib.algorithms.dqn.default_dqn_rl_module import QF_PREDS
from ray.rllib.algorithms.dqn.torch.default_dqn_torch_rl_module import DefaultDQNTorchRLModule
from ray.rllib.core.columns import Columns
from ray.rllib.utils.schedules.scheduler import Scheduler
from stable_baselines3.dqn.policies import CnnPolicy, DQNPolicy, MultiInputPolicy


def build_sb3_q_policy(observation_space: gym.Space, action_space: gym.Space) -> DQNPolicy:
    """The SB3 DQN policy `agents.train_dqn.make_model` builds for these spaces (SB3's defaults)."""
    policy_class = MultiInputPolicy if isinstance(observation_space, gym.spaces.Dict) else CnnPolicy
    return policy_class(observation_space, action_space, lambda _: 0.0)


class SB3QModule(DefaultDQNTorchRLModule):
    """RLlib's DQN module over an SB3 `DQNPolicy` (`self.policy`): Q-values (B, K) from `policy.q_net`, targets
    from `policy.q_net_target`."""

    def setup(self) -> None:
        self.uses_dueling, self.uses_double_q, self.num_atoms = False, bool(self.model_config.get("double_q", True)), 1
        self.epsilon_schedule = Scheduler(fixed_value_or_schedule=self.model_config["epsilon"], framework="torch")
        self.policy = build_sb3_q_policy(self.observation_space, self.action_space)
        self.policy.optimizer = None  # RLlib's learner owns the optimiser

    def get_non_inference_attributes(self) -> list[str]:
        return []

    def make_target_networks(self) -> None:
        self.policy.q_net_target.load_state_dict(self.policy.q_net.state_dict())
        self.policy.q_net_target.requires_grad_(False)

    def get_target_network_pairs(self) -> list[tuple[torch.nn.Module, torch.nn.Module]]:
        return [(self.policy.q_net, self.policy.q_net_target)]

    def compute_q_values(self, batch: dict[str, Any]) -> dict[str, torch.Tensor]:
        return {QF_PREDS: self.policy.q_net(batch[Columns.OBS])}

    def forward_target(self, batch: dict[str, Any]) -> dict[str, torch.Tensor]:
        return {QF_PREDS: self.policy.q_net_target(batch[Columns.OBS])}

    def get_initial_state(self) -> dict:
        return {}
