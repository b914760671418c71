"""Machine description recorded in every benchmark result."""

from __future__ import annotations

import os
import platform

import torch

from motion_envs import precision

ISA_FLAGS = ("avx2", "fma", "avx512f", "avx512_bf16", "avx512_fp16", "amx_tile", "amx_bf16")
"""The instruction-set flags that decide torch's CPU kernels (and whether bf16 is native), as /proc/cpuinfo names them."""


ISA_LIMITS = ("ONEDNN_MAX_CPU_ISA", "ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS")
"""Environment variables that hold oneDNN, torch's own kernels and MKL below the CPU's instruction set (to
estimate an older CPU's speed on a newer one)."""


def machine_line() -> str:
    """One Markdown line: CPU model, cores, ISA flags (and any ISA limit set), torch version and thread count."""
    cpu = precision.cpu_model() or platform.processor() or platform.machine()
    flags = [flag for flag in ISA_FLAGS if flag in precision.cpu_flags()]
    native = "native bf16" if precision.native_bf16() else "no native bf16 (emulated)"
    limits = [f"{name}={os.environ[name]}" for name in ISA_LIMITS if os.environ.get(name)]
    limited = f"; kernels limited by {', '.join(limits)}" if limits else ""
    return (
        f"Machine: {cpu}, {os.cpu_count()} cores; CPU flags {', '.join(flags) or 'none of ' + ', '.join(ISA_FLAGS)} "
        f"({native}){limited}; Python {platform.python_version()}; torch {torch.__version__}, "
        f"{torch.get_num_threads()} threads."
    )
