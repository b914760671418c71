"""RLlib PPO (new API stack) with the same networks and loss as `agents.ppo_kl.PPOKL`.

`SB3PolicyModule` is an RLlib `RLModule` whose networks *are* a Stable-Baselines3
actor-critic policy (`LatentPriorPolicy` for the latent-action envs, SB3's CNN /
multi-input policies for ClopsNav's images): RLlib samples and updates it, and
the trained weights load unchanged into a PPOKL model (`agents.train_rllib`),
so a policy trained on a Ray cluster is shipped, played and benchmarked by
exactly the code that reads SB3-trained ones, and cloning the data's latents
(`agents.behaviour_cloning`) works on it as it is.

`LatentPriorPPOLearner` is RLlib's torch PPO learner plus GAMMA's latent
regulariser α Ψ(KL(π(z|s) ‖ N(0, I))) (Eq. 10, as `PPOKL`), with α from
`config.learner_config_dict["kl_prior_coef"]`. RLlib's own KL penalty to the
old policy is off (`use_kl_loss=False`), as in the paper's PPO; RLlib has no
early stop at a target KL, which SB3's path has.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis import ValueFunctionAPI
from ray.rllib.core.rl_module.torch import TorchRLModule
from stable_baselines3.common.policies import ActorCriticCnnPolicy, ActorCriticPolicy, MultiInputActorCriticPolicy

from agents.ppo_kl import LatentPriorPolicy
from motion_envs.priors.gamma import kl_to_standard_normal, robust_kl

PRIOR_KL_METRIC = "prior_kl"


def sb3_policy_class(observation_space: gym.Space, action_space: gym.Space) -> type[ActorCriticPolicy]:
    """The SB3 policy class PPO uses for these spaces: `LatentPriorPolicy` for latent (Box) actions, SB3's CNN
    policy for image observations, its multi-input policy for dict observations."""
    if isinstance(action_space, gym.spaces.Box):
        return LatentPriorPolicy
    if isinstance(observation_space, gym.spaces.Dict):
        return MultiInputActorCriticPolicy
    if isinstance(observation_space, gym.spaces.Box) and len(observation_space.shape) == 3:
        return ActorCriticCnnPolicy
    return ActorCriticPolicy


def build_sb3_policy(observation_space: gym.Space, action_space: gym.Space, net_width: int = 256,
                     log_std_init: float = -1.0) -> ActorCriticPolicy:  # fmt: skip
    """The actor-critic policy `agents.train_ppo` builds: two hidden layers of `net_width` for actor and critic."""
    kwargs: dict[str, Any] = {"net_arch": {"pi": [net_width, net_width], "vf": [net_width, net_width]}}
    if isinstance(action_space, gym.spaces.Box):
        kwargs["log_std_init"] = log_std_init
    return sb3_policy_class(observation_space, action_space)(observation_space, action_space, lambda _: 0.0, **kwargs)


class SB3PolicyModule(TorchRLModule, ValueFunctionAPI):
    """RLlib view of an SB3 actor-critic policy (`self.policy`).

    model_config: {"net_width": int, "log_std_init": float}. Action-distribution inputs: for Box actions the
    Gaussian's mean and log σ concatenated, (B, 2A) (RLlib's `TorchDiagGaussian`); for Discrete actions the
    logits, (B, K). Embeddings are the critic's last hidden layer, (B, net_width)."""

    def setup(self) -> None:
        config = self.model_config or {}
        self.policy = build_sb3_policy(self.observation_space, self.action_space, int(config.get("net_width", 256)),
                                       float(config.get("log_std_init", -1.0)))  # fmt: skip
        self.policy.optimizer = None  # RLlib's learner owns the optimiser

    def _latents(self, batch: dict[str, Any]) -> tuple[torch.Tensor, torch.Tensor]:
        features = self.policy.extract_features(batch[Columns.OBS], self.policy.features_extractor)
        return self.policy.mlp_extractor(features)

    def _distribution_inputs(self, latent_pi: torch.Tensor) -> torch.Tensor:
        head = self.policy.action_net(latent_pi)
        if isinstance(self.action_space, gym.spaces.Box):
            return torch.cat([head, self.policy.log_std.expand_as(head)], dim=-1)
        return head

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, torch.Tensor]:
        latent_pi, _ = self._latents(batch)
        return {Columns.ACTION_DIST_INPUTS: self._distribution_inputs(latent_pi)}

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, torch.Tensor]:
        latent_pi, latent_vf = self._latents(batch)
        return {Columns.ACTION_DIST_INPUTS: self._distribution_inputs(latent_pi), Columns.EMBEDDINGS: latent_vf}

    def compute_values(self, batch: dict[str, Any], embeddings: torch.Tensor | None = None) -> torch.Tensor:
        """(B,) state values."""
        if embeddings is None:
            _, embeddings = self._latents(batch)
        return self.policy.value_net(embeddings).squeeze(-1)


class LatentPriorPPOLearner(PPOTorchLearner):
    """RLlib's PPO loss + α Ψ(mean KL(π ‖ N(0, I))) for Gaussian policies (α: `learner_config_dict`)."""

    def compute_loss_for_module(self, *, module_id: str, config: Any, batch: dict[str, Any],
                                fwd_out: dict[str, torch.Tensor]) -> torch.Tensor:  # fmt: skip
        loss = super().compute_loss_for_module(module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)
        alpha = float(config.learner_config_dict.get("kl_prior_coef", 0.0))
        if alpha == 0.0 or not isinstance(self.module[module_id].unwrapped().action_space, gym.spaces.Box):
            return loss
        mean, log_std = fwd_out[Columns.ACTION_DIST_INPUTS].chunk(2, dim=-1)
        per_row = kl_to_standard_normal(mean, 2.0 * log_std)
        if Columns.LOSS_MASK in batch:  # RLlib pads episodes with an artificial step for its value bootstrap
            mask = batch[Columns.LOSS_MASK]
            kl = per_row[mask].mean()
        else:
            kl = per_row.mean()
        self.metrics.log_value((module_id, PRIOR_KL_METRIC), float(kl.detach()), window=1)
        return loss + alpha * robust_kl(kl)
