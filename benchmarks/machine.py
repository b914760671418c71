"""Machine description recorded in every benchmark result."""

from __future__ import annotations

import os
import platform
import shlex
from pathlib import Path

import torch

from motion_envs import precision
from motion_envs.data.paths import SHIPPED_SUBSETS

ISA_LIMITS = ("ONEDNN_MAX_CPU_ISA", "ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS")
"""Environment variables that hold oneDNN, torch's own kernels and MKL below the CPU's instruction set (to
estimate an older CPU's speed on a newer one)."""


def bench_command(bench: str, options: dict[str, object], defaults: dict[str, object] | None = None) -> str:
    """The `motion-envs bench <bench>` command line that reruns a benchmark with `options` (CLI option names
    without dashes, in order): an option at its default (`defaults`, else None or False) is left out, True is a
    bare flag, a list is its items in a row (`nargs="+"`), a tuple the flag once per item (`action="append"`);
    values are quoted for a POSIX shell."""
    words = [f"motion-envs bench {bench}"]
    for name, value in options.items():
        if value is None or value is False or value in ([], ()) or (defaults and name in defaults and value == defaults[name]):
            continue
        if isinstance(value, tuple):
            words += [part for item in value for part in (f"--{name}", shlex.quote(str(item)))]
            continue
        words.append(f"--{name}")
        if value is not True:
            words += [shlex.quote(str(item)) for item in (value if isinstance(value, list) else [value])]
    return " ".join(words)


def data_options(mocap_dir: Path | None, subsets: tuple[str, ...]) -> dict[str, object]:
    """`bench_command` options of a bench that reads the mocap folder (`--mocap-dir`, `--subset`): the folder
    where one was given, and the subfolders read beyond the shipped ones."""
    return {"mocap-dir": mocap_dir, "subset": tuple(name for name in subsets if name not in SHIPPED_SUBSETS)}


def machine_line() -> str:
    """One Markdown line: CPU model, cores, ISA flags (and any ISA limit set), torch version and thread count."""
    limits = [f"{name}={os.environ[name]}" for name in ISA_LIMITS if os.environ.get(name)]
    limited = f"; kernels limited by {', '.join(limits)}" if limits else ""
    return (
        f"Machine: {precision.cpu_description()}{limited}; Python {platform.python_version()}; torch {torch.__version__}, "
        f"{torch.get_num_threads()} threads."
    )
