"""Machine description recorded in every benchmark result."""

from __future__ import annotations

import os
import platform

import torch

from motion_envs import precision

ISA_LIMITS = ("ONEDNN_MAX_CPU_ISA", "ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS")
"""Environment variables that hold oneDNN, torch's own kernels and MKL below the CPU's instruction set (to
estimate an older CPU's speed on a newer one)."""


def machine_line() -> str:
    """One Markdown line: CPU model, cores, ISA flags (and any ISA limit set), torch version and thread count."""
    limits = [f"{name}={os.environ[name]}" for name in ISA_LIMITS if os.environ.get(name)]
    limited = f"; kernels limited by {', '.join(limits)}" if limits else ""
    return (
        f"Machine: {precision.cpu_description()}{limited}; Python {platform.python_version()}; torch {torch.__version__}, "
        f"{torch.get_num_threads()} threads."
    )
