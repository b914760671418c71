"""Counter-based random numbers: the same (key, counter) gives the same draws on any batch, in one batched op.

The environments draw per-body noise inside a batched step; a body's draws
must not depend on which other bodies share its batch (a vector env equals
its single envs for the same seeds). Each body keeps a key from its own
seeded generator, and draw i of step t is a pure function of (key, t, i):
splitmix64 hashing, then Box-Muller.
"""

from __future__ import annotations

import math

import torch

_GOLDEN, _MIX1, _MIX2 = (c - (1 << 64) for c in (0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB))


def _shift(x: torch.Tensor, bits: int) -> torch.Tensor:
    """Logical right shift of int64 (torch shifts arithmetically)."""
    return (x >> bits) & ((1 << (64 - bits)) - 1)


def _splitmix(x: torch.Tensor) -> torch.Tensor:
    x = x + _GOLDEN
    x = (x ^ _shift(x, 30)) * _MIX1
    x = (x ^ _shift(x, 27)) * _MIX2
    return x ^ _shift(x, 31)


def _uniform(x: torch.Tensor) -> torch.Tensor:
    """int64 hashes -> float64 in (0, 1)."""
    return (_shift(x, 11).double() + 0.5) / float(1 << 53)


def counter_normal(keys: torch.Tensor, counters: torch.Tensor, size: int) -> torch.Tensor:
    """(N, size) float32 standard normal draws for int64 keys (N,) at counters (N,)."""
    index = torch.arange(size, device=keys.device)
    base = _splitmix(_splitmix(keys)[:, None] ^ (counters[:, None] * (2 * size) + 2 * index))
    first, second = _uniform(_splitmix(base)), _uniform(_splitmix(base + 1))
    return (torch.sqrt(-2.0 * torch.log(first)) * torch.cos(2.0 * math.pi * second)).float()


class BodyNoise:
    """Standard normal draws for a batch of bodies that do not depend on which other bodies share the batch.

    Body b's draws at call t are `counter_normal(seed · 2³² + b, t)`; `bodies` (N,) int64 gives the bodies'
    global indices (default 0..N-1 on each call), so a batch split into shards (e.g. a benchmark fanned out
    over Ray tasks) draws exactly what the whole batch would."""

    def __init__(self, seed: int = 0, bodies: torch.Tensor | None = None) -> None:
        self.seed, self.bodies, self.calls = int(seed), bodies, 0

    def __call__(self, num_bodies: int, size: int) -> torch.Tensor:
        """(num_bodies, size) float32 draws; the next call gives the next ones."""
        bodies = torch.arange(num_bodies) if self.bodies is None else self.bodies
        if len(bodies) != num_bodies:
            raise ValueError(f"this noise is for {len(bodies)} bodies, asked for {num_bodies}")
        keys = (self.seed << 32) + bodies.long()
        draws = counter_normal(keys, torch.full_like(keys, self.calls), size)
        self.calls += 1
        return draws
