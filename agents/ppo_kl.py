"""PPO with GAMMA's latent regulariser (Eq. 10) as a Stable-Baselines3 algorithm.

    L = L_PPO + E[(R_t - V(s_t))²] + α Ψ(KL(π(z|s) ‖ N(0, I))),   Ψ(s) = sqrt(1 + s²) - 1,

the KL averaged over latent dimensions and the minibatch (the authors'
release, REFERENCE_NOTES §1.6). The regulariser keeps the policy's latents
where the motion prior was trained, so the motion stays natural.

`prior_mean="cloned"` (ours) keeps Ψ and α but centres the unit Gaussian on
the cloned policy's mean for the same observation, N(μ_cloned(s), I): the
data's own walking latents given the goal. On our CMU-trained prior z = 0
stands still (random z ~ N(0, I) moves the pelvis at 0.23 m/s, the data at
1.32), so the paper's form at α = 10 pulls the policy towards standing; the
paper means the term to keep motion realistic, which the data's latents are.

How it joins SB3's loss without copying `PPO.train`: `LatentPriorPolicy`
keeps the action distribution of its latest forward pass, and during
`train()` the optimiser's `zero_grad` is followed by the backward pass of
α Ψ(KL) of that distribution (the minibatch just evaluated). SB3 then adds
the PPO loss's gradient and steps, so the update is exactly the gradient of
the sum above (gradient clipping included). Everything else is SB3's PPO:
`learn`, `save`/`load`, callbacks, `predict`, tensorboard (`train/prior_kl`).

Paper defaults differ from SB3's: `gae_lambda=1` (the paper's Monte-Carlo
returns), `target_kl=0.02 / 1.5` (SB3 stops at 1.5 × target_kl; the release
stops at an approximate KL of 0.02), `clip_range=0.2`, `gamma=0.99`.
"""

from __future__ import annotations

import copy
from typing import Any

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy

from motion_envs.priors.gamma import kl_to_standard_normal, robust_kl

PAPER_SETTINGS: dict[str, Any] = {"gamma": 0.99, "gae_lambda": 1.0, "clip_range": 0.2, "target_kl": 0.02 / 1.5,
                                  "normalize_advantage": True}  # fmt: skip


class LatentPriorPolicy(ActorCriticPolicy):
    """SB3's actor-critic policy that remembers the Gaussian (and observations) of its latest forward pass.

    `anchored=True` keeps a frozen copy of the actor's mean network, set by `set_anchor()` (e.g. after
    cloning the data's latents), for `anchor_kl`."""

    last_distribution: DiagGaussianDistribution | None = None
    last_observation: torch.Tensor | None = None

    def __init__(self, *args: Any, anchored: bool = False, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.anchor = copy.deepcopy(self._actor_mean()).requires_grad_(False) if anchored else None  # not optimised

    def _actor_mean(self) -> torch.nn.Sequential:
        """The actor's mean network, features -> action mean (views of the live modules)."""
        return torch.nn.Sequential(self.mlp_extractor.policy_net, self.action_net)

    def set_anchor(self) -> None:
        """Freeze the actor's current mean network as the anchor."""
        if self.anchor is None:
            raise RuntimeError("this policy was built without an anchor (anchored=False)")
        self.anchor.load_state_dict(self._actor_mean().state_dict())

    def evaluate_actions(self, obs: torch.Tensor, actions: torch.Tensor):
        self.last_observation = obs
        return super().evaluate_actions(obs, actions)

    def _get_action_dist_from_latent(self, latent_pi: torch.Tensor):
        distribution = super()._get_action_dist_from_latent(latent_pi)
        if not isinstance(distribution, DiagGaussianDistribution):
            raise TypeError(f"PPOKL needs a diagonal Gaussian policy over a Box action space, got {type(distribution).__name__}")
        self.last_distribution = distribution
        return distribution

    def prior_kl(self, centred_on_anchor: bool = False) -> torch.Tensor:
        """Mean over dims and batch of KL(π(z|s) ‖ N(0, I)) for the latest forward pass; `centred_on_anchor`:
        KL(π(z|s) ‖ N(μ_anchor(s), I)) for the latest `evaluate_actions`."""
        normal = self.last_distribution.distribution
        mean = normal.loc - self.anchor_mean() if centred_on_anchor else normal.loc
        return kl_to_standard_normal(mean, 2.0 * normal.scale.log()).mean()

    def anchor_kl(self) -> torch.Tensor:
        """Mean over dims and batch of KL(π(z|s) ‖ N(μ_anchor(s), σ²)) for the latest `evaluate_actions`."""
        normal = self.last_distribution.distribution
        return ((normal.loc - self.anchor_mean()).pow(2) / (2.0 * normal.scale.detach().pow(2))).mean()

    def anchor_mean(self) -> torch.Tensor:
        """(batch, latent) the frozen anchor's mean for the observations of the latest `evaluate_actions`."""
        with torch.no_grad():
            return self.anchor(self.extract_features(self.last_observation, self.pi_features_extractor))


PRIOR_MEANS = ("zero", "cloned")


class PPOKL(PPO):
    """PPO + α Ψ(KL(π ‖ N(0, I))) [+ β KL(π ‖ anchor)]. `kl_prior_coef` is α (paper: 1 or 10); `anchor_coef`
    is β (0: the paper's loss; > 0 also holds the actor near its anchor, see `LatentPriorPolicy.set_anchor`);
    `prior_mean` "zero" (the paper's N(0, I)) or "cloned" (N(μ_anchor(s), I), see the module docstring; the
    anchor is set after cloning); other arguments are SB3's PPO's, with the paper's settings
    (`PAPER_SETTINGS`) where not given."""

    policy_aliases = {"MlpPolicy": LatentPriorPolicy}

    def __init__(self, policy: str | type[LatentPriorPolicy], env: Any, kl_prior_coef: float = 10.0,
                 anchor_coef: float = 0.0, prior_mean: str = "zero", **kwargs: Any) -> None:  # fmt: skip
        if kl_prior_coef < 0 or anchor_coef < 0:
            raise ValueError(f"kl_prior_coef and anchor_coef must be >= 0, got {kl_prior_coef} and {anchor_coef}")
        if prior_mean not in PRIOR_MEANS:
            raise ValueError(f"prior_mean must be one of {PRIOR_MEANS}, got {prior_mean!r}")
        self.kl_prior_coef, self.anchor_coef, self.prior_mean = kl_prior_coef, anchor_coef, prior_mean
        if anchor_coef > 0 or prior_mean == "cloned":
            kwargs["policy_kwargs"] = {**kwargs.get("policy_kwargs", {}), "anchored": True}
        super().__init__(policy, env, **{**PAPER_SETTINGS, **kwargs})

    def train(self) -> None:
        optimiser = self.policy.optimizer
        plain_zero_grad = optimiser.zero_grad
        values: list[float] = []
        anchored: list[float] = []

        def zero_grad_then_regularise(set_to_none: bool = True) -> None:
            plain_zero_grad(set_to_none=set_to_none)
            kl = self.policy.prior_kl(centred_on_anchor=self.prior_mean == "cloned")
            values.append(float(kl.detach()))
            regulariser = self.kl_prior_coef * robust_kl(kl)
            if self.anchor_coef > 0:
                anchor = self.policy.anchor_kl()
                anchored.append(float(anchor.detach()))
                regulariser = regulariser + self.anchor_coef * anchor
            regulariser.backward(retain_graph=True)  # the PPO loss shares this graph

        optimiser.zero_grad = zero_grad_then_regularise
        try:
            super().train()
        finally:
            optimiser.zero_grad = plain_zero_grad
        if values:
            self.logger.record("train/prior_kl", sum(values) / len(values))
        if anchored:
            self.logger.record("train/anchor_kl", sum(anchored) / len(anchored))
