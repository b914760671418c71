"""What every prior's training shares: the resumable epoch loop and shipped weights.

`fit` runs epochs of minibatches with a progress bar and tensorboard, saves
a run checkpoint (model, optimiser, epoch, history) every few minutes and
after every epoch, and resumes from it when rerun. `ship` writes float16
weights plus an entry in the `manifest.json` beside them; `load_shipped`
reads them back as float32 modules. A run writes its weights into its own run
folder (`weights_destination`); only an explicit `ship=True` (`motion-envs
train ... --ship`) writes into the package's `priors/weights/`, and says what it
replaces.
"""

from __future__ import annotations

import json
import random
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import torch
from torch import nn
from torch.utils.tensorboard import SummaryWriter
from tqdm import tqdm

from motion_envs.atomic import atomic_write
from motion_envs.precision import cpu_description
from motion_envs.priors.checkpoint import load_checkpoint, save_checkpoint

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
PACKAGE_PARENT = WEIGHTS_DIR.parents[2]
"""The folder that holds the `motion_envs` package (a checkout's root, or site-packages)."""
CLEAN_WEIGHTS_DIR = WEIGHTS_DIR / "clean"
"""Priors retrained on the cleaned data (issue "Clean motion"), shipped beside the defaults until the agents are
retrained on them: every shipped policy was trained on the defaults, and a policy acts in its own prior's latent
space (the WandrReach PPO policy reaches 6.7% on the retrained WANDR prior against 88.9% on its own). Envs take
them by path (`weights_dir=` / `weights=`)."""

Batch = TypeVar("Batch")


@dataclass
class FitSettings:
    """Where and how often a training run checkpoints."""

    kind: str
    run_dir: Path
    epochs: int
    seed: int = 0
    checkpoint_minutes: float = 3.0


@dataclass
class TrainRun:
    """Settings every prior's training run shares; each prior's config extends it."""

    epochs: int = 10
    batch_size: int = 64
    learning_rate: float = 1e-3
    checkpoint_minutes: float = 3.0
    seed: int = 0
    run_dir: Path = Path("runs/prior")
    weights: Path | None = None
    """Output file (default: `weights_destination`: the prior's name in `run_dir`, or in priors/weights/ with `ship`)."""
    ship: bool = False
    """Write the weights into the package (priors/weights/ + its manifest), replacing the shipped ones."""
    data_hash: str = ""
    command: str = ""

    def output(self, name: str) -> Path:
        """Where this run writes weights called `name` (`weights_destination`)."""
        return weights_destination(name, self.run_dir, self.weights, self.ship)

    def fit_settings(self, kind: str, epochs: int | None = None) -> FitSettings:
        return FitSettings(kind, self.run_dir, self.epochs if epochs is None else epochs, self.seed, self.checkpoint_minutes)

    def entry(self, kind: str, model_config: Any, history: list[float], **figures: Any) -> dict[str, Any]:
        """The manifest entry of a finished run: what, from which data and command, and how well."""
        return {"kind": kind, "config": asdict(model_config), "data_hash": self.data_hash, "command": self.command,
                "epochs": self.epochs, "train_loss_by_epoch": [round(v, 5) for v in history], **figures}  # fmt: skip


def weights_destination(name: str, run_dir: Path, weights: Path | None = None, ship: bool = False) -> Path:
    """Where a training run writes its weights: `weights` when given; else priors/weights/`name` when `ship` (the
    explicit act that replaces the package's weights); else `run_dir`/`name`, beside the run's checkpoints."""
    if weights is not None:
        return Path(weights)
    return (WEIGHTS_DIR if ship else Path(run_dir)) / name


def announce_replacement(weights: Path) -> None:
    """Say on stderr which shipped weights (and the manifest's record of them) a write to `weights` replaces."""
    weights = Path(weights)
    if not weights.exists() or not in_package(weights):
        return
    manifest_path = WEIGHTS_DIR / "manifest.json"
    record = json.loads(manifest_path.read_text()).get(weights.name, {}) if manifest_path.exists() else {}
    figures = {key: value for key, value in record.items() if key.startswith("validation") and not isinstance(value, (list, dict))}
    if record.get("curve"):  # a policy: its last success-rate window
        figures["last success rate"] = round(record["curve"][-1]["success_rate"], 3)
    command = record.get("command") or record.get("config", {}).get("command") or "unknown"  # priors / policies
    print(f"replacing the shipped {weights} (made by: {command}; {figures or 'no figures'})", file=sys.stderr)


def seed_everything(seed: int) -> None:
    torch.manual_seed(seed)
    random.seed(seed)
    np.random.seed(seed)


def fit(
    model: nn.Module,
    optimiser: torch.optim.Optimizer,
    settings: FitSettings,
    epoch_batches: Callable[[int, torch.Generator], Sequence[Batch]],
    loss_terms: Callable[[int, Batch], dict[str, torch.Tensor]],
    describe: Callable[[int], str] = lambda epoch: "",
) -> list[float]:
    """Train `model` for `settings.epochs` epochs (resuming a run checkpoint); returns mean loss per epoch.

    Args:
        epoch_batches: (epoch, generator) -> the minibatches of that epoch.
        loss_terms: (epoch, batch) -> named scalar losses including "total", which is minimised.
        describe: epoch -> a word for the progress bar (e.g. "rollout").
    """
    checkpoint_path = settings.run_dir / "checkpoint.pt"
    config = asdict(model.config) if hasattr(model, "config") else {}
    start_epoch, history = 0, []
    if checkpoint_path.exists():
        state = load_checkpoint(checkpoint_path, settings.kind + "_run", config)
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        start_epoch, history = state["epoch"], list(state["history"])
        print(f"resuming {checkpoint_path} at epoch {start_epoch}", file=sys.stderr)

    def save(epoch: int) -> None:
        save_checkpoint(checkpoint_path, {"kind": settings.kind + "_run", "config": config, "model": model.state_dict(),
                                          "optimiser": optimiser.state_dict(), "epoch": epoch,
                                          "history": history[:epoch]})  # fmt: skip

    writer = SummaryWriter(str(settings.run_dir / "tensorboard"))
    generator = torch.Generator().manual_seed(settings.seed + start_epoch)
    last_save = time.monotonic()
    model.train()
    for epoch in range(start_epoch, settings.epochs):
        batches = epoch_batches(epoch, generator)
        sums: dict[str, float] = {}
        label = f"epoch {epoch + 1}/{settings.epochs} {describe(epoch)}".rstrip()
        progress = tqdm(batches, desc=label, leave=False, mininterval=2.0)
        for batch in progress:
            optimiser.zero_grad()
            terms = loss_terms(epoch, batch)
            terms["total"].backward()
            optimiser.step()
            for name, value in terms.items():
                if value.ndim == 0:
                    sums[name] = sums.get(name, 0.0) + float(value.detach()) / len(batches)
            progress.set_postfix(loss=f"{terms['total'].item():.4f}")
            if time.monotonic() - last_save > 60 * settings.checkpoint_minutes:
                save(epoch)  # mid-epoch: that epoch restarts on resume
                last_save = time.monotonic()
        for name, value in sums.items():
            writer.add_scalar(f"train/{name}", value, epoch)
        history.append(sums["total"])
        save(epoch + 1)
        last_save = time.monotonic()
        print(f"{label}: loss {sums['total']:.5f}", file=sys.stderr)
    writer.close()
    model.eval()
    return history


def ship(model: nn.Module, weights: Path, entry: dict[str, Any]) -> dict[str, Any]:
    """Write float16 weights with `entry` (kind, config, figures; torch and the machine added) and record `entry`
    in the manifest."""
    half = {name: value.half() if value.is_floating_point() else value for name, value in model.state_dict().items()}
    entry = {**entry, "torch": str(torch.__version__), "machine": cpu_description()}
    announce_replacement(weights)
    save_checkpoint(weights, {**entry, "model": half})
    record_in_manifest(weights, entry)
    print(f"weights {weights} (manifest: {Path(weights).parent / 'manifest.json'})", file=sys.stderr)
    return entry


def ship_trained(weights: Path, folder: Path | None = None, name: str | None = None, contents: bytes | None = None,
                 notes: dict[str, str] | None = None) -> Path:  # fmt: skip
    """Copy finished weights of a run folder (and their record in the manifest beside them) into the package's
    priors/weights/ (or `folder`, with its own manifest) as `name` (default: the file's own), naming what they
    replace; returns the shipped path.

    The record keeps the history of the one it replaces (`with_history`). `contents`: the bytes to ship instead of
    the file's (a policy whose saved env options were edited, `agents.policy_files.without_env_options`); `notes`:
    entries added to the record (e.g. "note", "promoted")."""
    weights = Path(weights)
    manifest_path = weights.parent / "manifest.json"
    record = json.loads(manifest_path.read_text()).get(weights.name) if manifest_path.exists() else None
    if record is None:
        raise FileNotFoundError(f"{weights} has no record in {manifest_path}; ship only what a train command wrote")
    shipped = Path(folder or WEIGHTS_DIR) / (name or weights.name)
    if shipped.resolve() == weights.resolve():
        raise ValueError(f"{weights} is already the shipped file")
    shipped.parent.mkdir(parents=True, exist_ok=True)
    announce_replacement(shipped)
    data = weights.read_bytes() if contents is None else contents
    atomic_write(shipped, lambda file: file.write(data))
    record_in_manifest(shipped, {**record, **(notes or {})}, history=True)
    print(f"shipped {weights} as {shipped}", file=sys.stderr)
    return shipped


def command_of(record: dict[str, Any]) -> str | None:
    """The command that made a manifest record's weights (priors keep it at the top, policies in their config)."""
    config = record.get("config")
    return record.get("command") or (config.get("command") if isinstance(config, dict) else None)


def with_history(record: dict[str, Any], replaced: dict[str, Any] | None, shipped: Path) -> dict[str, Any]:
    """`record` of weights about to replace the shipped `replaced` at `shipped`, with the history a reader needs to
    repeat them. A fine-tune of the shipped weights (its config's `init` is `shipped`) goes on from them:
    `stages` is the replaced record's stages and its own last stage (command, steps, curve, machine), and
    `repeat` chains the commands. Anything else starts afresh and names what it replaces (`replaces`)."""
    if replaced is None:
        return record
    config = record.get("config") if isinstance(record.get("config"), dict) else {}
    init = config.get("init")
    if init and resolve_weights(init).resolve() == shipped.resolve():
        stage = {"command": command_of(replaced), "timesteps": replaced.get("timesteps"), "shipped": replaced.get("shipped"),
                 "curve": replaced.get("curve", []), "machine": replaced.get("machine")}  # fmt: skip
        if replaced.get("curve"):
            stage["last_window"] = replaced["curve"][-1]
        repeat = f"{replaced.get('repeat') or command_of(replaced)} && {command_of(record)}"
        return {**record, "stages": [*replaced.get("stages", []), stage], "repeat": repeat}
    summary = {key: replaced[key] for key in ("timesteps", "shipped", "data_hash") if key in replaced}
    if replaced.get("curve"):
        summary["last_window"] = replaced["curve"][-1]
    return {**record, "replaces": {"command": command_of(replaced), **summary}}


def in_package(weights: Path) -> bool:
    """Whether `weights` is in the package's weights folder (what `--ship` writes)."""
    return Path(weights).resolve().parent == WEIGHTS_DIR.resolve()


def record_in_manifest(weights: Path, entry: dict[str, Any], history: bool | None = None) -> None:
    """Set `entry` as the record of `weights` in the `manifest.json` beside it (written atomically). With `history`
    (default: for weights in the package, which replace shipped ones) the entry keeps the history of the record it
    replaces (`with_history`)."""
    weights = Path(weights)
    manifest_path = weights.parent / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    keep_history = in_package(weights) if history is None else history
    manifest[weights.name] = with_history(entry, manifest.get(weights.name), weights) if keep_history else entry
    text = json.dumps(manifest, indent=2) + "\n"
    atomic_write(manifest_path, lambda file: file.write(text.encode()))


Module = TypeVar("Module", bound=nn.Module)


def resolve_weights(path: str | Path) -> Path:
    """`path`, or where a relative path that is not found from the working directory lies under the folder that
    holds the package (policy files name their priors as `motion_envs/priors/weights/...`, relative to it)."""
    path = Path(path)
    beside_package = PACKAGE_PARENT / path
    return beside_package if not path.is_absolute() and not path.exists() and beside_package.exists() else path


def load_shipped(path: str | Path, kind: str, build: Callable[[dict[str, Any]], Module]) -> Module:
    """A module from `ship`'s weights (float16 on disk, float32 in memory), in eval mode.

    `build` makes the untrained module from the stored config dict.
    """
    state = load_checkpoint(resolve_weights(path), kind)
    model = build(state["config"])
    model.load_state_dict({name: value.float() if value.is_floating_point() else value
                           for name, value in state["model"].items()})  # fmt: skip
    return model.eval()


def minibatches(indices: torch.Tensor, batch_size: int, generator: torch.Generator) -> list[torch.Tensor]:
    """Shuffled full minibatches of `indices` (one short batch if there are fewer than `batch_size`)."""
    order = indices[torch.randperm(len(indices), generator=generator)]
    return [order[i : i + batch_size] for i in range(0, len(order) - batch_size + 1, batch_size)] or [order]
