"""Training GAMMA's marker predictor (`motion-envs train gamma --stage predictor`).

Reads top to bottom: data -> model -> (resume) -> single-primitive epochs ->
rollout epochs (8 primitives, each seeded by the previous prediction moved
into the next primitive's ground-truth canonical frame, as in the paper) ->
validation -> weights + manifest. Checkpoints go to `run_dir` every few
minutes and after every epoch; rerunning the same command resumes.
"""

from __future__ import annotations

import json
import random
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from motion_envs.atomic import atomic_write
from motion_envs.data.primitives import PRIMITIVE_FRAMES, MarkerClips, MarkerWindows
from motion_envs.priors.canonical import canonical_frame, to_canonical, to_world
from motion_envs.priors.checkpoint import load_checkpoint, save_checkpoint
from motion_envs.priors.gamma import MarkerCVAE, MarkerCVAEConfig, predictor_loss

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
PREDICTOR_KIND = "gamma_predictor"


@dataclass
class PredictorTrainConfig:
    """Settings of one predictor training run (the paper: 200 epochs, then rollout fine-tuning)."""

    model: MarkerCVAEConfig = field(default_factory=MarkerCVAEConfig)
    epochs: int = 30
    rollout_epochs: int = 5
    rollout_primitives: int = 8
    batch_size: int = 128
    learning_rate: float = 5e-4
    window_stride: int = 2
    checkpoint_minutes: float = 3.0
    seed: int = 0
    run_dir: Path = Path("runs/gamma_predictor")
    weights: Path | None = None
    data_hash: str = ""
    command: str = ""

    def rollout_frames(self) -> int:
        seed = self.model.seed_frames
        return seed + self.rollout_primitives * (PRIMITIVE_FRAMES - seed)


def rollout_loss(
    model: MarkerCVAE, windows: MarkerWindows, primitives: int, sample: bool = True
) -> dict[str, torch.Tensor]:
    """Eq. 1 averaged over `primitives` chained primitives; also returns per-frame errors (m).

    With `sample` false the posterior mean is decoded (validation)."""
    seed_frames = model.config.seed_frames
    step = PRIMITIVE_FRAMES - seed_frames
    markers, joints = windows.markers, windows.joints
    total: dict[str, torch.Tensor] = {}
    errors = []
    previous_world = None
    for k in range(primitives):
        start = k * step
        frame = canonical_frame(joints[:, start])
        truth = to_canonical(markers[:, start : start + PRIMITIVE_FRAMES].flatten(1, 2), frame)
        truth = truth.unflatten(1, (PRIMITIVE_FRAMES, -1)).flatten(2)  # (B, 10, 201)
        if previous_world is None:
            seed = truth[:, :seed_frames]
        else:
            seed = to_canonical(previous_world.flatten(1, 2), frame).unflatten(1, (seed_frames, -1)).flatten(2)
        mean, log_variance = model.encode(seed, truth[:, seed_frames:])
        z = mean + torch.randn_like(mean) * torch.exp(0.5 * log_variance) if sample else mean
        reconstruction = model.decode(seed, z)
        for name, value in predictor_loss(seed, truth[:, seed_frames:], reconstruction, mean, log_variance).items():
            total[name] = total.get(name, 0.0) + value / primitives
        predicted = reconstruction.unflatten(-1, (-1, 3))  # (B, step, 67, 3)
        errors.append((predicted - truth[:, seed_frames:].unflatten(-1, (-1, 3))).norm(dim=-1).mean(dim=(0, 2)))
        previous_world = to_world(predicted.flatten(1, 2), frame).unflatten(1, (step, -1))[:, -seed_frames:]
    total["frame_error"] = torch.cat(errors)
    return total


def _batches(starts: torch.Tensor, batch_size: int, generator: torch.Generator) -> list[torch.Tensor]:
    order = starts[torch.randperm(len(starts), generator=generator)]
    return [order[i : i + batch_size] for i in range(0, len(order) - batch_size + 1, batch_size)] or [order]


@torch.no_grad()
def validate(model: MarkerCVAE, clips: MarkerClips, primitives: int, max_windows: int = 512) -> dict[str, list[float]]:
    """Per-frame marker error (cm) of one primitive and of a `primitives`-long rollout, posterior mean z."""
    model.eval()
    seed_frames = model.config.seed_frames
    frames_needed = seed_frames + primitives * (PRIMITIVE_FRAMES - seed_frames)
    result: dict[str, list[float]] = {}
    for name, count, length in (("primitive", 1, PRIMITIVE_FRAMES), (f"rollout_{primitives}", primitives, frames_needed)):
        starts = clips.window_starts(length, stride=max(1, len(clips.markers) // max_windows // 2))[:max_windows]
        if len(starts) == 0:
            continue
        errors = rollout_loss(model, clips.windows(starts, length), count, sample=False)["frame_error"]
        result[name] = [round(float(e) * 100, 2) for e in errors]
    model.train()
    return result


def train_predictor(config: PredictorTrainConfig, train: MarkerClips, validation: MarkerClips) -> dict:
    """Train (or resume) a marker predictor; returns the manifest entry it writes."""
    torch.manual_seed(config.seed)
    random.seed(config.seed)
    np.random.seed(config.seed)
    model = MarkerCVAE(config.model)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    checkpoint_path = config.run_dir / "checkpoint.pt"
    start_epoch = 0
    history: list[float] = []
    if checkpoint_path.exists():
        state = load_checkpoint(checkpoint_path, PREDICTOR_KIND + "_run", asdict(config.model))
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        start_epoch = state["epoch"]
        history = list(state["history"])
        print(f"resuming {checkpoint_path} at epoch {start_epoch}", file=sys.stderr)
    writer = SummaryWriter(str(config.run_dir / "tensorboard"))
    generator = torch.Generator().manual_seed(config.seed + start_epoch)
    total_epochs = config.epochs + config.rollout_epochs
    last_save = time.monotonic()

    def save(epoch: int) -> None:
        save_checkpoint(checkpoint_path, {"kind": PREDICTOR_KIND + "_run", "config": asdict(config.model),
                                          "model": model.state_dict(), "optimiser": optimiser.state_dict(),
                                          "epoch": epoch, "history": history[:epoch]})  # fmt: skip

    for epoch in range(start_epoch, total_epochs):
        rollout = epoch >= config.epochs
        length = config.rollout_frames() if rollout else PRIMITIVE_FRAMES
        primitives = config.rollout_primitives if rollout else 1
        batches = _batches(train.window_starts(length, config.window_stride), config.batch_size, generator)
        sums: dict[str, float] = {}
        progress = tqdm(batches, desc=f"epoch {epoch + 1}/{total_epochs}{' rollout' if rollout else ''}", leave=False)
        for starts in progress:
            optimiser.zero_grad()
            terms = rollout_loss(model, train.windows(starts, length), primitives)
            terms["total"].backward()
            optimiser.step()
            for name in ("total", "reconstruction", "difference", "kl"):
                sums[name] = sums.get(name, 0.0) + float(terms[name].detach()) / len(batches)
            progress.set_postfix(loss=f"{terms['total'].item():.4f}")
            if time.monotonic() - last_save > 60 * config.checkpoint_minutes:
                save(epoch)  # mid-epoch: the epoch restarts on resume
                last_save = time.monotonic()
        for name, value in sums.items():
            writer.add_scalar(f"train/{name}", value, epoch)
        history.append(sums["total"])
        save(epoch + 1)
        last_save = time.monotonic()
    writer.close()

    figures = validate(model, validation, config.rollout_primitives)
    weights = config.weights or WEIGHTS_DIR / f"gamma_predictor_{config.model.seed_frames}f.pt"
    entry = {
        "kind": PREDICTOR_KIND,
        "config": asdict(config.model),
        "data_hash": config.data_hash,
        "command": config.command,
        "epochs": config.epochs,
        "rollout_epochs": config.rollout_epochs,
        "train_loss_by_epoch": [round(v, 5) for v in history],
        "validation_marker_error_cm_per_frame": figures,
        "torch": str(torch.__version__),
    }
    half = {name: value.half() for name, value in model.state_dict().items()}  # halves the shipped size
    save_checkpoint(weights, {**entry, "model": half})
    _update_manifest(weights, entry)
    return entry


def load_predictor(path: str | Path) -> MarkerCVAE:
    """A trained predictor from shipped weights (float16 on disk, float32 in memory)."""
    state = load_checkpoint(path, PREDICTOR_KIND)
    model = MarkerCVAE(MarkerCVAEConfig(**state["config"]))
    model.load_state_dict({name: value.float() for name, value in state["model"].items()})
    return model.eval()


def _update_manifest(weights: Path, entry: dict) -> None:
    manifest_path = weights.parent / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    manifest[weights.name] = {k: v for k, v in entry.items() if k != "model"}
    text = json.dumps(manifest, indent=2) + "\n"
    atomic_write(manifest_path, lambda file: file.write(text.encode()))
