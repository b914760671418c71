"""A latent policy's first guess from the data: regress its mean onto the latents that made real motion.

For each goal window (`motion_envs.data.goal_windows`) the marker predictor's
posterior mean z is the latent that reproduces what the person did next while
heading for that goal. Regressing an SB3 policy's action mean onto it, from
the environment's own observation, gives PPO a start that already walks
towards goals. Deviation from GAMMA, which trains PPO from a random policy:
our prior, trained on ~30 minutes of mostly non-locomotion CMU capture, walks
under a small part of N(0, I) (posterior means have an rms of ~0.35, and
z ~ N(0, I) mostly stands), so a random policy almost never reaches a goal
(0.6% after 0.76M steps of PPO from scratch) and PPO has nothing to
reinforce. Only the actor is fitted; the critic and the log-std keep their
initial values.
"""

from __future__ import annotations

import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from tqdm import tqdm

from motion_envs.data.goal_windows import GoalWindows
from motion_envs.priors.gamma import MarkerCVAE


@torch.no_grad()
def posterior_latents(predictor: MarkerCVAE, windows: GoalWindows, batch_size: int = 4096) -> torch.Tensor:
    """(B, latent) posterior means of the 2-frame predictor for every window."""
    if predictor.config.seed_frames != 2:
        raise ValueError("posterior latents come from the 2-frame predictor (the env's state has two seed frames)")
    means = [predictor.encode(seed.flatten(2), future.flatten(2))[0]
             for seed, future in zip(windows.seed.split(batch_size), windows.future.split(batch_size))]  # fmt: skip
    return torch.cat(means)


def clone_latents(policy: ActorCriticPolicy, observation: torch.Tensor, latents: torch.Tensor, epochs: int = 40,
                  batch_size: int = 256, learning_rate: float = 1e-3, validation_share: float = 0.1,
                  seed: int = 0) -> dict[str, float]:  # fmt: skip
    """Fit the policy's action mean to `latents` (B, A) from `observation` (B, obs) by mean squared error.

    Returns the final train and validation MSE and the latents' variance (what predicting their mean
    would score), validation on a random `validation_share` of the examples."""
    if observation.ndim != 2 or latents.ndim != 2 or len(observation) != len(latents):
        raise ValueError(f"observation (B, obs) and latents (B, A) must pair up, got {tuple(observation.shape)} "
                         f"and {tuple(latents.shape)}")  # fmt: skip
    generator = torch.Generator().manual_seed(seed)
    order = torch.randperm(len(observation), generator=generator)
    held = max(1, int(validation_share * len(order)))
    validation, train = order[:held], order[held:]
    actor = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters()]
    optimiser = torch.optim.Adam(actor, lr=learning_rate)

    def loss_of(rows: torch.Tensor) -> torch.Tensor:
        mean = policy.get_distribution(observation[rows]).distribution.mean
        return (mean - latents[rows]).pow(2).mean()

    policy.train()
    for _ in tqdm(range(epochs), desc="cloning data latents", unit="epoch"):
        for rows in train[torch.randperm(len(train), generator=generator)].split(batch_size):
            loss = loss_of(rows)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    policy.eval()
    with torch.no_grad():
        return {"train_mse": float(loss_of(train)), "validation_mse": float(loss_of(validation)),
                "latent_variance": float(latents[validation].var(dim=0).mean())}  # fmt: skip
