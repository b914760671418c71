"""Which float precision the priors' networks run in: bf16 only where the hardware multiplies bf16 natively.

On a CPU that means the AMX or AVX512-BF16 instructions (Intel Sapphire Rapids and later, AMD Zen 4 and later);
without them torch emulates bf16 matrix products in software, 7x slower than fp32 on an AVX2-only EPYC (GAMMA
rollout, 1,024 bodies: 278 against 1,987 body-primitives/s). On CUDA it is `torch.cuda.is_bf16_supported()`.
An explicit precision ("float32" or "bfloat16") always wins over "auto".
"""

from __future__ import annotations

import functools
import os
import platform
from pathlib import Path

import torch

PRECISIONS = ("auto", "float32", "bfloat16")
NATIVE_BF16_FLAGS = ("amx_bf16", "avx512_bf16")
"""CPU flags (as /proc/cpuinfo names them) of native bf16 matrix arithmetic."""
ISA_FLAGS = ("avx2", "fma", "avx512f", "avx512_bf16", "avx512_fp16", "amx_tile", "amx_bf16")
"""The instruction-set flags that decide torch's CPU kernels (and whether bf16 is native), as /proc/cpuinfo names them."""


def _cpuinfo(*keys: str) -> str:
    """The value of the first /proc/cpuinfo line starting with one of `keys` ('' where there is none, e.g. macOS)."""
    info = Path("/proc/cpuinfo")
    if info.is_file():
        for line in info.read_text(errors="replace").splitlines():
            if line.startswith(keys):
                return line.split(":", 1)[1].strip()
    return ""


@functools.cache
def cpu_flags() -> frozenset[str]:
    """The flags of this machine's first CPU (x86 "flags", Arm "Features")."""
    return frozenset(_cpuinfo("flags", "Features").split())


def cpu_model() -> str:
    """The CPU's model name ('' where /proc/cpuinfo has none)."""
    return _cpuinfo("model name")


def native_bf16(device: str | torch.device = "cpu", flags: frozenset[str] | None = None) -> bool:
    """Whether `device` multiplies bf16 matrices natively (`flags`: the CPU flags to judge, default this CPU's)."""
    device = torch.device(device)
    if device.type == "cuda":
        return torch.cuda.is_available() and torch.cuda.is_bf16_supported()
    if device.type != "cpu":
        return False
    return any(flag in (cpu_flags() if flags is None else flags) for flag in NATIVE_BF16_FLAGS)


def resolve_precision(precision: str, device: str | torch.device = "cpu") -> str:
    """"float32" or "bfloat16": `precision` itself, or for "auto" bf16 where `native_bf16(device)`, else fp32."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if precision != "auto":
        return precision
    return "bfloat16" if native_bf16(device) else "float32"


def cpu_description() -> str:
    """The CPU model, its core count and its ISA flags that matter to torch, e.g. "AMD EPYC, 2 cores; CPU flags
    avx2, fma (bf16 emulated)": what benchmarks and training records say they ran on."""
    cpu = cpu_model() or platform.processor() or platform.machine()
    flags = [flag for flag in ISA_FLAGS if flag in cpu_flags()]
    native = "native bf16" if native_bf16() else "bf16 emulated"
    return f"{cpu}, {os.cpu_count()} cores; CPU flags {', '.join(flags) or 'none of ' + ', '.join(ISA_FLAGS)} ({native})"
