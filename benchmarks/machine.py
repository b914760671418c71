"""Machine description recorded in every benchmark result."""

from __future__ import annotations

import os
import platform

import torch


def machine_line() -> str:
    """One Markdown line: CPU, cores, torch version and thread count."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as info:
            cpu = next(line.split(":", 1)[1].strip() for line in info if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return (
        f"Machine: {cpu}, {os.cpu_count()} cores; Python {platform.python_version()}; "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads."
    )
