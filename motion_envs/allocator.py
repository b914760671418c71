"""Keep freed memory in the process's heap (glibc), so that large torch CPU tensors are not zero-filled anew each step.

torch's CPU tensors come from glibc's malloc. A block above its mmap threshold (128 KB at first, rising with what
is freed) is mapped fresh from the kernel on every allocation and unmapped when freed, and the kernel zero-fills
each of its pages on first touch; freed memory at the top of the heap beyond the trim threshold goes back too. A
batched step allocates and frees the same few MB-sized tensors every call (a GAMMA step of 1,024 bodies: markers
(1,024, 10, 67, 3) are 8 MB), so it pays those page faults every step. `keep_freed_memory` raises the mmap threshold
to glibc's largest (32 MB on 64-bit) and the trim threshold to 1 GB, as `GLIBC_TUNABLES` would at start-up: freed
blocks are reused. Measured on the AMX Xeon (2 cores, `motion-envs bench speed`'s GAMMA step, 1,024 bodies, bf16):
8,093-8,433 -> 9,058-9,307 body-primitives/s with the tunables set.

The cost: a process keeps its peak heap (what a training or benchmark process touches anyway) instead of handing
memory back between steps. The environments and the CLI call it; `MOTION_ENVS_KEEP_FREED_MEMORY=0` leaves malloc
as it is. Elsewhere than glibc (macOS, musl, Windows) it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
"""glibc's mallopt parameters (malloc.h)."""
MMAP_THRESHOLD = 32 * 1024 * 1024
"""glibc's largest mmap threshold on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX): blocks up to this come from the heap."""
TRIM_THRESHOLD = 1024 * 1024 * 1024
"""Free memory at the top of the heap kept before glibc returns it to the kernel."""
OPT_OUT = "MOTION_ENVS_KEEP_FREED_MEMORY"


@functools.cache
def keep_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds once per process (module doc); True where they were set."""
    if os.environ.get(OPT_OUT, "1") == "0":
        return False
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
        libc.gnu_get_libc_version  # glibc only: musl and macOS have no such symbol
    except (OSError, AttributeError, TypeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
