"""WANDR's own inference as a controller, and batched episodes of WandrReach bodies.

`WandrSampler` is the paper's generation (Sec. 3.5): a fresh z ~ N(0, σ² I)
every frame (σ = 1, the release's sigma_mult), the intention recomputed
from the goal by the environment core. `roll_out` plays N bodies of a
`WandrReachCore` until every one has reached its goal (bodies that arrive
stop and stay, as "stop on success") or run out of frames.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from tqdm import tqdm

from motion_envs.counter_random import BodyNoise
from motion_envs.envs.wandr_reach import WandrReachCore, WandrReachState

Controller = Callable[[WandrReachCore, WandrReachState], torch.Tensor]
"""(core, state) -> latents (N, 64)."""


class WandrSampler:
    """z ~ N(0, σ² I) for every body and step; a body's draws depend only on the seed and its index in `bodies`
    (`motion_envs.counter_random.BodyNoise`), so shards of a batch draw what the whole batch would."""

    def __init__(self, sigma: float = 1.0, seed: int = 0, bodies: torch.Tensor | None = None) -> None:
        if not sigma >= 0:
            raise ValueError(f"sigma must be non-negative, got {sigma}")
        self.sigma = sigma
        self.noise = BodyNoise(seed, bodies)

    def __call__(self, core: WandrReachCore, state: WandrReachState) -> torch.Tensor:
        return self.sigma * self.noise(state.num_bodies, core.prior.config.latent)


def roll_out(core: WandrReachCore, state: WandrReachState, controller: Controller, progress: bool = False,
             on_step: Callable[[WandrReachState], None] | None = None) -> WandrReachState:  # fmt: skip
    """Step every body with `controller` until all have ended; returns the final state.

    on_step: called with the state after every step (e.g. to record frames).
    """
    steps = tqdm(range(core.config.max_steps), desc="rollout", leave=False, disable=not progress, mininterval=2.0)
    for _ in steps:
        state, result = core.step(state, controller(core, state))
        if on_step is not None:
            on_step(state)
        if bool((result.terminated | result.truncated).all()):
            break
    return state
