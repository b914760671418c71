"""Non-learned controllers for GAMMA-style environments: they pick latent codes for N bodies.

* `RandomLatent`: z ~ N(0, I) every primitive (the paper's "random" row).
* `GreedyLatent`: for every body, try `candidates` random latents on clones of
  its state (the batched clone API of `GammaReachCore`), keep the best by
  `score`: "reward" (the env's reward) or "distance" (closest to the goal
  after the primitive). A depth-1 search with no learning: a floor any
  trained policy should clear.

Both are called as `controller(core, state) -> z (N, latent)`.
"""

from __future__ import annotations

import torch

from motion_envs.envs.gamma_reach import GammaReachCore, GammaReachState


class RandomLatent:
    def __init__(self, seed: int = 0) -> None:
        self.generator = torch.Generator().manual_seed(seed)

    def __call__(self, core: GammaReachCore, state: GammaReachState) -> torch.Tensor:
        return torch.randn(state.num_bodies, core.generator.latent_size, generator=self.generator)


class GreedyLatent:
    SCORES = ("reward", "distance")

    def __init__(self, candidates: int = 16, score: str = "reward", seed: int = 0) -> None:
        if candidates < 1:
            raise ValueError(f"candidates must be positive, got {candidates}")
        if score not in self.SCORES:
            raise ValueError(f"score must be one of {self.SCORES}, got {score!r}")
        self.candidates, self.score = candidates, score
        self.generator = torch.Generator().manual_seed(seed)

    def __call__(self, core: GammaReachCore, state: GammaReachState) -> torch.Tensor:
        count = state.num_bodies
        z = torch.randn(count * self.candidates, core.generator.latent_size, generator=self.generator)
        _, result = core.step(state.repeat(self.candidates), z)  # body i's candidates are rows i*K .. i*K+K-1
        value = result.reward if self.score == "reward" else -result.distance
        best = value.reshape(count, self.candidates).argmax(dim=1)
        return z.reshape(count, self.candidates, -1)[torch.arange(count), best]
