"""Training GAMMA's body regressor (`motion-envs train gamma --stage regressor`).

Samples are the frames of 10-frame windows, each window in its own
canonical frame, so inputs cover every offset a primitive's frames have from
its canonical origin. Loss (GAMMA Eq. 2, our body): the L1 distance between
the markers skinned from the regressed body and the true markers, plus
`pose_weight` times the mean squared deviation of the joint rotations from
rest. The paper's α|θ_h|² regularises hand pose, which our fixed hands do
not have; the rest-pose term plays its part for joints the markers leave
loosely determined (twists of the forearms and neck).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import torch

from motion_envs.body import BodyModel
from motion_envs.body.markers import marker_ids
from motion_envs.body.rotations import rotation_matrix
from motion_envs.data.primitives import PRIMITIVE_FRAMES, MarkerClips
from motion_envs.priors.gamma import BodyRegressor, BodyRegressorConfig
from motion_envs.priors.training import WEIGHTS_DIR, TrainRun, fit, load_shipped, minibatches, seed_everything, ship

REGRESSOR_KIND = "gamma_regressor"


@dataclass
class RegressorTrainConfig(TrainRun):
    """Settings of one regressor training run (release: lr 3e-4, batch 16, 100 epochs). Batches count
    windows (of 10 frames each)."""

    model: BodyRegressorConfig = field(default_factory=BodyRegressorConfig)
    batch_size: int = 16
    learning_rate: float = 3e-4
    pose_weight: float = 1e-3
    window_stride: int = 4
    run_dir: Path = Path("runs/gamma_regressor")


def regressor_loss(
    model: BodyRegressor, body: BodyModel, markers: torch.Tensor, pose_weight: float
) -> dict[str, torch.Tensor]:
    """Markers (B, 67, 3) -> marker L1 of the regressed bodies (m) + pose_weight · rest-pose deviation."""
    params = model(markers)
    posed = body(params["transl"], params["global_orient"], params["body_pose"])
    skinned = body.skin(posed, marker_ids())
    rotations = rotation_matrix(params["body_pose"])
    terms = {
        "markers": (skinned - markers).abs().mean(),
        "pose": (rotations - torch.eye(3)).pow(2).sum(dim=(-1, -2)).mean(),
        "marker_error": (skinned - markers).norm(dim=-1).mean().detach(),
    }
    terms["total"] = terms["markers"] + pose_weight * terms["pose"]
    return terms


@torch.no_grad()
def validate_regressor(model: BodyRegressor, body: BodyModel, clips: MarkerClips, max_windows: int = 512) -> dict:
    """Mean marker and joint error (cm) of the regressed bodies on windows of `clips`."""
    starts = clips.window_starts(PRIMITIVE_FRAMES, stride=PRIMITIVE_FRAMES)[:max_windows]
    windows = clips.windows(starts, PRIMITIVE_FRAMES)
    params = model(windows.markers)
    posed = body(params["transl"], params["global_orient"], params["body_pose"])
    marker_error = (body.skin(posed, marker_ids()) - windows.markers).norm(dim=-1).mean()
    joint_error = (posed.joints - windows.joints).norm(dim=-1).mean()
    return {"marker_error_cm": round(float(marker_error) * 100, 2), "joint_error_cm": round(float(joint_error) * 100, 2)}


def train_regressor(config: RegressorTrainConfig, train: MarkerClips, validation: MarkerClips) -> dict:
    """Train (or resume) the body regressor; returns the manifest entry it writes."""
    seed_everything(config.seed)
    body = BodyModel()
    model = BodyRegressor(config.model)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    settings = config.fit_settings(REGRESSOR_KIND)

    def epoch_batches(epoch: int, generator: torch.Generator) -> list[torch.Tensor]:
        return minibatches(train.window_starts(PRIMITIVE_FRAMES, config.window_stride), config.batch_size, generator)

    def loss_terms(epoch: int, starts: torch.Tensor) -> dict[str, torch.Tensor]:
        markers = train.windows(starts, PRIMITIVE_FRAMES).markers.flatten(0, 1)
        return regressor_loss(model, body, markers, config.pose_weight)

    history = fit(model, optimiser, settings, epoch_batches, loss_terms)
    figures = validate_regressor(model, body, validation)
    print(f"validation: {figures}", file=sys.stderr)
    entry = config.entry(REGRESSOR_KIND, config.model, history, validation=figures)
    return ship(model, config.output("gamma_regressor.pt"), entry)


def load_regressor(path: str | Path = WEIGHTS_DIR / "gamma_regressor.pt") -> BodyRegressor:
    """The trained body regressor from shipped weights."""
    return load_shipped(path, REGRESSOR_KIND, lambda config: BodyRegressor(BodyRegressorConfig(**config)))
