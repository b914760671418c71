"""Checkpoints: plain dicts written atomically, checked for kind and architecture on load."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from motion_envs.atomic import atomic_write


class CheckpointError(ValueError):
    """A file that is not a readable checkpoint."""


class CheckpointMismatchError(CheckpointError):
    """A checkpoint made for another model or architecture."""


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> Path:
    """torch.save to a temporary file beside `path`, then rename (never half-written)."""
    return atomic_write(path, lambda file: torch.save(payload, file))


def load_checkpoint(path: str | Path, kind: str, config: dict[str, Any] | None = None) -> dict[str, Any]:
    """Load a checkpoint written by `save_checkpoint` and check what it holds.

    Raises:
        FileNotFoundError: no such file.
        CheckpointError: not a readable checkpoint (truncated, garbage, or holding objects beyond tensors and
            plain containers, which are never unpickled), with the file named.
        CheckpointMismatchError: its `kind` or `config` differ from the expected ones.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises OSError, RuntimeError, UnpicklingError, EOFError ... for broken files
        # torch's own text advises weights_only=False, which would run arbitrary code from the file: not repeated
        raise CheckpointError(f"{path} ({path.stat().st_size:,} bytes) is not a readable checkpoint: truncated, corrupt "
                              f"or not written by motion_envs ({type(error).__name__})") from error  # fmt: skip
    if not isinstance(payload, dict) or payload.get("kind") != kind:
        found = payload.get("kind") if isinstance(payload, dict) else type(payload).__name__
        raise CheckpointMismatchError(f"{path} holds a {found!r} checkpoint, expected {kind!r}")
    if config is not None and payload.get("config") != config:
        raise CheckpointMismatchError(f"{path} was made for config {payload.get('config')}, expected {config}")
    return payload
