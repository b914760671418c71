"""Latent optimisation with WANDR's prior: the paper's "VAE + opt" row and its Sup. B.3 refinement.

The autoregressive generation is differentiable, so the latents of a whole
rollout (N, T, 64) can be optimised by gradient descent on

    L_opt = L_goal + λ L_norm,

L_goal the squared distance (m²) of the right wrist to the goal in the
final frame and L_norm = ½ mean z² the negative log-likelihood of the
latents under N(0, I) (up to a constant). The paper gives no λ, step count
or optimiser; we use Adam (lr 0.05), 20 steps and λ = 0.01.

* "VAE + opt" (Table 2): the prior without intention. We have no
  intention-free prior; ours sees an all-zero intention instead
  (`intentions=()`), which is the closest we can get without training
  another model. Starts from z ~ N(0, I).
* "WANDR + opt" (Sup. B.3): the full intention, started from the sampler's
  own latents, i.e. a WANDR motion refined towards the goal.

`optimise_latents` returns the latents; `LatentSequence` replays them in a
`WandrReachCore` (whose stepper must see the same intention) for scoring.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tqdm import tqdm

from motion_envs.envs.wandr_reach import WandrReachCore, WandrReachState
from motion_envs.priors.wandr import WandrStepper
from motion_envs.priors.wandr_features import RIGHT_WRIST


@dataclass(frozen=True)
class LatentOptimisationSettings:
    steps: int = 20
    learning_rate: float = 0.05
    norm_weight: float = 0.01
    chunk: int = 256
    """Bodies optimised together (memory: the graph of every frame is kept)."""


def optimise_latents(stepper: WandrStepper, start: WandrReachState, frames: int, initial: torch.Tensor,
                     settings: LatentOptimisationSettings = LatentOptimisationSettings(),
                     progress: bool = False) -> torch.Tensor:  # fmt: skip
    """Latents (N, frames, D) minimising L_goal + λ L_norm for bodies `start`, from `initial` (N, frames, D).

    The intention is computed as the stepper's prior was told (its `intentions`), towards each body's goal,
    with the env's countdown (frames left = deadline − frame, at least 1)."""
    if initial.shape[:2] != (start.num_bodies, frames):
        raise ValueError(f"initial latents must be ({start.num_bodies}, {frames}, D), got {tuple(initial.shape)}")
    trainable = [p for p in stepper.prior.parameters() if p.requires_grad]
    for parameter in trainable:  # gradients for the latents only
        parameter.requires_grad_(False)
    chunks = []
    bar = tqdm(total=settings.steps * ((start.num_bodies + settings.chunk - 1) // settings.chunk), desc="latent opt",
               leave=False, disable=not progress)  # fmt: skip
    for first in range(0, start.num_bodies, settings.chunk):
        rows = torch.arange(first, min(first + settings.chunk, start.num_bodies))
        part = start.index(rows)
        latents = initial[rows].clone().requires_grad_(True)
        optimiser = torch.optim.Adam([latents], lr=settings.learning_rate)
        for _ in range(settings.steps):
            optimiser.zero_grad()
            body = part.body
            for frame in range(frames):
                left = (part.deadline - frame).clamp_min(1)
                body, _ = stepper.step(body, latents[:, frame], part.goal, left)
            goal_loss = ((body.joints[:, RIGHT_WRIST] - part.goal) ** 2).sum(-1).mean()
            loss = goal_loss + settings.norm_weight * 0.5 * (latents**2).mean()
            loss.backward()
            optimiser.step()
            bar.update()
        chunks.append(latents.detach())
    bar.close()
    for parameter in trainable:
        parameter.requires_grad_(True)
    return torch.cat(chunks)


class LatentSequence:
    """Replays fixed latents (N, T, D): step t of a rollout gets latents[:, t]."""

    def __init__(self, latents: torch.Tensor) -> None:
        self.latents = latents
        self.frame = 0

    def __call__(self, core: WandrReachCore, state: WandrReachState) -> torch.Tensor:
        if core.config.frames_per_step != 1:
            raise ValueError("LatentSequence replays one latent per frame: use frames_per_step=1")
        z = self.latents[:, min(self.frame, self.latents.shape[1] - 1)]
        self.frame += 1
        return z
