"""Trained policies as batched controllers: `controller(core, state) -> z (N, latent)`.

The same call shape as `baselines.latent_controllers` and
`baselines.wandr_sampler`, so benchmarks and the tree search run learned and
non-learned controllers alike, on any env core with `observe(state)`
(GammaReach, WandrReach).
"""

from __future__ import annotations

from pathlib import Path

import torch

from agents.policy_files import PolicyFileError, expect_policy
from agents.ppo_kl import PPOKL
from motion_envs.batched import BatchedState
from motion_envs.counter_random import BodyNoise
from motion_envs.envs.core import BatchedCore


class PolicyLatent:
    """A saved PPOKL policy. Sampled latents by default, as the paper (its release does not use the mean); a body's
    noise depends only on the seed and its index in `bodies` (`BodyNoise`). `file` says what it was trained for (`agents.policy_files`); a file of another kind fails here, by name. The network runs on `device`; latents
    come back on the CPU."""

    def __init__(self, path: str | Path, deterministic: bool = False, seed: int = 0, bodies: torch.Tensor | None = None,
                 device: str = "cpu") -> None:  # fmt: skip
        self.file = expect_policy(path, "ppo_policy")
        self.model = PPOKL.load(path, device=device)
        self.deterministic = deterministic
        self.noise = BodyNoise(seed, bodies)

    @torch.no_grad()
    def __call__(self, core: BatchedCore, state: BatchedState) -> torch.Tensor:
        observations = core.observe(state).to(self.model.device)
        expected = self.model.observation_space.shape
        if tuple(observations.shape[1:]) != tuple(expected):
            raise PolicyFileError(f"{self.file.path} expects observations of shape {expected}, the env gives "
                                  f"{tuple(observations.shape[1:])}")  # fmt: skip
        distribution = self.model.policy.get_distribution(observations).distribution
        if self.deterministic:
            return distribution.loc.cpu()
        noise = self.noise(*distribution.loc.shape)
        return (distribution.loc + distribution.scale * noise.to(distribution.loc.device)).cpu()
