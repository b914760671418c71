"""Machine description recorded in every benchmark result."""

from __future__ import annotations

import os
import platform

import torch

from motion_envs import precision

ISA_LIMITS = ("ONEDNN_MAX_CPU_ISA", "ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS")
"""Environment variables that hold oneDNN, torch's own kernels and MKL below the CPU's instruction set (to
estimate an older CPU's speed on a newer one)."""


def bench_command(bench: str, options: dict[str, object], defaults: dict[str, object] | None = None) -> str:
    """The `motion-envs bench <bench>` command line that reruns a benchmark with `options` (CLI option names
    without dashes, in order): an option at its default (`defaults`, else None or False) is left out, True is a
    bare flag, a list is its items in a row."""
    words = [f"motion-envs bench {bench}"]
    for name, value in options.items():
        if value is None or value is False or value == [] or (defaults and name in defaults and value == defaults[name]):
            continue
        words.append(f"--{name}")
        if value is not True:
            words += map(str, value) if isinstance(value, list) else [str(value)]
    return " ".join(words)


def machine_line() -> str:
    """One Markdown line: CPU model, cores, ISA flags (and any ISA limit set), torch version and thread count."""
    limits = [f"{name}={os.environ[name]}" for name in ISA_LIMITS if os.environ.get(name)]
    limited = f"; kernels limited by {', '.join(limits)}" if limits else ""
    return (
        f"Machine: {precision.cpu_description()}{limited}; Python {platform.python_version()}; torch {torch.__version__}, "
        f"{torch.get_num_threads()} threads."
    )
