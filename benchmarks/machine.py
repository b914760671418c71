"""Machine description recorded in every benchmark result."""

from __future__ import annotations

import os
import platform

import torch

from motion_envs.precision import cpu_flags, cpu_model, native_bf16

ISA_FLAGS = ("avx2", "fma", "avx512f", "avx512_bf16", "avx512_fp16", "amx_tile", "amx_bf16")
"""The instruction-set flags that decide torch's CPU kernels (and whether bf16 is native), as /proc/cpuinfo names them."""


def machine_line() -> str:
    """One Markdown line: CPU model, cores, ISA flags, torch version and thread count."""
    cpu = cpu_model() or platform.processor() or platform.machine()
    flags = [flag for flag in ISA_FLAGS if flag in cpu_flags()]
    native = "native bf16" if native_bf16() else "no native bf16 (emulated)"
    return (
        f"Machine: {cpu}, {os.cpu_count()} cores; CPU flags {', '.join(flags) or 'none of ' + ', '.join(ISA_FLAGS)} "
        f"({native}); Python {platform.python_version()}; torch {torch.__version__}, {torch.get_num_threads()} threads."
    )
