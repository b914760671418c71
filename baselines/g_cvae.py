"""GAMMA's g-CVAE baseline: the marker predictor with the goal features of Eq. 3 as an extra condition.

Trained like the 2-frame predictor (Eq. 1: marker and velocity L1 + robust
KL), on goal windows from the data (`motion_envs.data.goal_windows`: every
primitive with the pelvis position of a later frame of its clip as the goal).
At test time z ~ N(0, I) and the goal steers the motion: `goal_cvae_generator`
puts it in place of the 2-frame predictor, so the environment, benchmarks
and tree search run it unchanged (`RandomLatent` picks z).

Deviation: the paper conditions both its models on the goal; here the
episode's first primitive (a one-frame seed) still comes from the plain
1-frame predictor, because the goal windows are cut with two seed frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import torch

from motion_envs.data.goal_windows import GoalWindows
from motion_envs.priors.gamma import MarkerCVAE, MarkerCVAEConfig, goal_conditioned_seed, predictor_loss
from motion_envs.priors.gamma_generator import GammaGenerator
from motion_envs.priors.train_gamma import PREDICTOR_KIND, load_predictor
from motion_envs.priors.training import WEIGHTS_DIR, TrainRun, fit, minibatches, seed_everything, ship

G_CVAE_WEIGHTS = WEIGHTS_DIR / "gamma_g_cvae_2f.pt"


@dataclass
class GoalCVAETrainConfig(TrainRun):
    model: MarkerCVAEConfig = field(default_factory=lambda: MarkerCVAEConfig(seed_frames=2, goal_features=True))
    epochs: int = 12
    batch_size: int = 128
    learning_rate: float = 5e-4
    run_dir: Path = Path("runs/gamma_g_cvae")


def _loss(model: MarkerCVAE, windows: GoalWindows, rows: torch.Tensor) -> dict[str, torch.Tensor]:
    """Eq. 1 on the windows `rows`, z drawn from the posterior."""
    seed = goal_conditioned_seed(windows.observation[rows])
    future = windows.future[rows].flatten(2)
    mean, log_variance = model.encode(seed, future)
    z = mean + torch.randn_like(mean) * torch.exp(0.5 * log_variance)
    return predictor_loss(windows.seed[rows].flatten(2), future, model.decode(seed, z), mean, log_variance)


@torch.no_grad()
def validation_error_cm(model: MarkerCVAE, windows: GoalWindows, max_windows: int = 2048) -> float:
    """Mean marker error (cm) of the predicted frames, decoding the posterior mean."""
    rows = torch.arange(min(max_windows, len(windows)))
    seed = goal_conditioned_seed(windows.observation[rows])
    mean, _ = model.encode(seed, windows.future[rows].flatten(2))
    predicted = model.decode(seed, mean).unflatten(-1, (-1, 3))
    return float((predicted - windows.future[rows]).norm(dim=-1).mean() * 100)


def train_goal_cvae(config: GoalCVAETrainConfig, train: GoalWindows, validation: GoalWindows) -> dict:
    """Train (or resume) the g-CVAE; returns the manifest entry it writes."""
    if not config.model.goal_features or config.model.seed_frames != 2:
        raise ValueError("the g-CVAE is a 2-frame predictor with goal features")
    seed_everything(config.seed)
    model = MarkerCVAE(config.model)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.learning_rate)

    def epoch_batches(epoch: int, generator: torch.Generator) -> list[torch.Tensor]:
        return minibatches(torch.arange(len(train)), config.batch_size, generator)

    def loss_terms(epoch: int, rows: torch.Tensor) -> dict[str, torch.Tensor]:
        return _loss(model, train, rows)

    history = fit(model, optimiser, config.fit_settings(PREDICTOR_KIND, config.epochs), epoch_batches, loss_terms)
    model.eval()
    entry = config.entry(PREDICTOR_KIND, config.model, history, baseline="g-CVAE", training_windows=len(train),
                         validation_marker_error_cm=round(validation_error_cm(model, validation), 2))  # fmt: skip
    return ship(model, config.output(G_CVAE_WEIGHTS.name), entry)


def goal_cvae_generator(path: str | Path = G_CVAE_WEIGHTS, base: GammaGenerator | None = None) -> GammaGenerator:
    """The shipped GAMMA generator with the g-CVAE as its 2-frame predictor."""
    base = base or GammaGenerator.load()
    predictor = load_predictor(path)
    if not predictor.config.goal_features:
        raise ValueError(f"{path} is not a goal-conditioned predictor")
    return GammaGenerator(base.predictor_1f, predictor, base.regressor, base.pose_vae)
