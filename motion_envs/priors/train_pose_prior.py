"""Training the pose VAE that stands in for VPoser (`motion-envs train gamma --stage pose-vae`).

Samples are single body poses (21 joint rotations) of the training clips and
their mirror images. Validation reports the mean joint-angle error of the
reconstruction through the posterior mean and the mean |μ|² of validation
poses, the quantity r_vposer (GAMMA Eq. 8) turns into a reward.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import torch

from motion_envs.body.rotations import rotation_matrix
from motion_envs.priors.gamma import PoseVAE, PoseVAEConfig, pose_vae_loss
from motion_envs.priors.training import WEIGHTS_DIR, TrainRun, fit, load_shipped, minibatches, seed_everything, ship

POSE_VAE_KIND = "gamma_pose_vae"


@dataclass
class PoseVAETrainConfig(TrainRun):
    model: PoseVAEConfig = field(default_factory=PoseVAEConfig)
    epochs: int = 30
    batch_size: int = 256
    kl_weight: float = 5e-3
    run_dir: Path = Path("runs/gamma_pose_vae")


@torch.no_grad()
def validate_pose_vae(model: PoseVAE, body_pose: torch.Tensor) -> dict[str, float]:
    """Mean joint-angle error (degrees) through the posterior mean and mean |μ|² over poses (F, 21, 3)."""
    mean, _ = model.encode(body_pose)
    relative = model.decode(mean).transpose(-1, -2) @ rotation_matrix(body_pose)
    cosine = ((relative.diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0).clamp(-1.0, 1.0)
    return {
        "joint_angle_error_deg": round(float(torch.rad2deg(torch.acos(cosine)).mean()), 2),
        "mean_squared_norm_mu": round(float(mean.pow(2).sum(-1).mean()), 3),
    }


def train_pose_vae(config: PoseVAETrainConfig, train_poses: torch.Tensor, validation_poses: torch.Tensor) -> dict:
    """Train (or resume) the pose VAE on (F, 21, 3) axis-angle poses; returns the manifest entry it writes."""
    seed_everything(config.seed)
    model = PoseVAE(config.model)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    settings = config.fit_settings(POSE_VAE_KIND)

    def epoch_batches(epoch: int, generator: torch.Generator) -> list[torch.Tensor]:
        return minibatches(torch.arange(len(train_poses)), config.batch_size, generator)

    def loss_terms(epoch: int, indices: torch.Tensor) -> dict[str, torch.Tensor]:
        return pose_vae_loss(model, train_poses[indices], config.kl_weight)

    history = fit(model, optimiser, settings, epoch_batches, loss_terms)
    figures = validate_pose_vae(model, validation_poses)
    print(f"validation: {figures}", file=sys.stderr)
    entry = config.entry(POSE_VAE_KIND, config.model, history, kl_weight=config.kl_weight, validation=figures)
    return ship(model, config.output("gamma_pose_vae.pt"), entry)


def load_pose_vae(path: str | Path = WEIGHTS_DIR / "gamma_pose_vae.pt") -> PoseVAE:
    """The trained pose VAE from shipped weights."""
    return load_shipped(path, POSE_VAE_KIND, lambda config: PoseVAE(PoseVAEConfig(**config)))
