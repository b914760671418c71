"""`motion_envs.allocator`: a GAMMA step's large tensors come back from the heap instead of fresh kernel pages."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

STEP_FAULTS = """
import resource, torch
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore
from benchmarks.throughput import walking_state
torch.set_num_threads(1)
core = GammaReachCore(GammaReachConfig(precision="float32"))
state = walking_state(core, 1024)
z = torch.zeros(1024, core.generator.latent_size)
for _ in range(2):
    core.step(state, z)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(3):
    core.step(state, z)
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 3)
"""


def step_faults(keep: bool) -> float:
    """Minor page faults per GAMMA step of 1,024 bodies in a fresh process (the setting is process-wide)."""
    env = {**os.environ, "MOTION_ENVS_KEEP_FREED_MEMORY": "1" if keep else "0"}
    done = subprocess.run([sys.executable, "-c", STEP_FAULTS], env=env, capture_output=True, text=True, check=True,
                          cwd=Path(__file__).resolve().parents[1])  # fmt: skip
    return float(done.stdout.split()[-1])


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc", reason="glibc's malloc only")
def test_the_envs_keep_freed_memory_so_a_step_does_not_page_fault_its_tensors_anew():
    """Opted out, glibc maps and zero-fills most of a step's multi-MB tensors afresh (measured: 13,900-15,900 faults
    a step, ~60 MB); with the thresholds the cores set, they are reused (measured: 0-670)."""
    kept, default = step_faults(keep=True), step_faults(keep=False)
    assert kept < 0.2 * default, (kept, default)
