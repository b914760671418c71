"""CUDA check (`motion-envs bench gpu`): the GAMMA rollout on the GPU agrees with the CPU, and how fast it runs.

1. Agreement: the same start bodies and the same latents (seeded on the CPU), stepped on the CPU and on CUDA in
   fp32: GAMMA for `PRIMITIVES` = 20 primitives (every marker and pelvis of their 10-frame windows), WANDR for
   `WANDR_FRAMES` = 240 frames (every joint). The largest distance must stay within `TOLERANCE_M` (1e-4 m). The
   GPU's matmuls reassociate sums differently, so the two agree to float32 rounding, not bit for bit, and the
   autoregressive rollouts let that grow; 1e-4 m is a tenth of a millimetre.
2. Throughput: body-primitives/s at 1,024 to 16,384 bodies in fp32 and bf16 (`GammaReachConfig.precision`).
3. End to end: every env with its shipped policy, PPO and DQN training and the tree search on CUDA
   (`benchmarks.gpu_end_to_end`).

Writes the "GAMMA on CUDA" section of `benchmarks/results/throughput.md`. Without CUDA it says so and returns 0
without writing anything (`main` returns 0 so that `bench gpu` on a laptop is not an error).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.gpu_end_to_end import end_to_end, table
from benchmarks.machine import machine_line
from benchmarks.sections import replace_section
from benchmarks.throughput import best_seconds, walking_state
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore

RESULTS = Path(__file__).resolve().parent / "results"
SECTION = "## GAMMA on CUDA"
PRIMITIVES = 20
WANDR_FRAMES = 240
BODIES = 64
TOLERANCE_M = 1e-4
BATCHES = (1_024, 4_096, 16_384)


def rollout_positions(device: str, latents: torch.Tensor) -> torch.Tensor:
    """(P, N, 10, 67 + 1, 3) markers and pelvis of every primitive of N = latents.shape[1] bodies stepped with
    latents (P, N, 128) on `device` (fp32), from the same seeded starts; returned on the CPU."""
    core = GammaReachCore(GammaReachConfig(device=device, precision="float32"))
    state = core.sample_initial_state([np.random.default_rng(seed) for seed in range(latents.shape[1])])
    frames = []
    for z in latents:
        state, result = core.step(state, z.to(device))
        primitive = result.primitive
        frames.append(torch.cat([primitive.markers, primitive.joints[:, :, :1]], dim=2).cpu())
    return torch.stack(frames)


def wandr_joints(device: str, latents: torch.Tensor) -> torch.Tensor:
    """(T, N, 22, 3) joints of N bodies after each of T = latents.shape[0] WANDR frames (latents (T, N, 64))."""
    from motion_envs.envs.wandr_reach import WandrReachConfig, WandrReachCore

    core = WandrReachCore(WandrReachConfig(device=device, max_frames=latents.shape[0]))
    state = core.sample_initial_state([np.random.default_rng(seed) for seed in range(latents.shape[1])])
    frames = []
    for z in latents:
        state, _ = core.step(state, z.to(device))
        frames.append(state.joints.cpu())
    return torch.stack(frames)


def agreement(positions, latents: torch.Tensor) -> float:
    """Largest CPU-CUDA distance (m) of any position `positions(device, latents)` returns."""
    return float((positions("cpu", latents) - positions("cuda", latents)).norm(dim=-1).max())


def throughput(core: GammaReachCore, count: int, precision: str) -> float:
    """Body-primitives/s of one step of `count` walking bodies on the CUDA `core` with its networks in `precision`
    (best of 3 after a warm-up, each call waited for)."""
    core.generator.set_precision(precision)
    state = walking_state(core, count)
    z = torch.randn(count, core.generator.latent_size, device=core.device)

    def step() -> None:
        core.step(state, z)
        torch.cuda.synchronize()

    return count / best_seconds(step, 3)


def main() -> int:
    if not torch.cuda.is_available():
        print("bench gpu: no CUDA device here (torch.cuda.is_available() is False); nothing measured, nothing written")
        return 0
    began = time.perf_counter()
    generator = torch.Generator().manual_seed(0)
    gamma = agreement(rollout_positions, torch.randn(PRIMITIVES, BODIES, 128, generator=generator))
    wandr = agreement(wandr_joints, torch.randn(WANDR_FRAMES, BODIES, 64, generator=generator))
    distance = max(gamma, wandr)
    core = GammaReachCore(GammaReachConfig(device="cuda"))
    rows = [(count, precision, throughput(core, count, precision)) for count in BATCHES for precision in ("float32", "bfloat16")]
    jobs = end_to_end("cuda")
    verdict = "within" if distance <= TOLERANCE_M else "BEYOND"
    lines = [
        SECTION, "",
        f"Agreement: {BODIES} bodies, the same latents on the CPU and on {torch.cuda.get_device_name()} (fp32): "
        f"GAMMA, {PRIMITIVES} primitives, largest marker or pelvis distance {gamma * 1000:.4f} mm; WANDR, "
        f"{WANDR_FRAMES} frames, largest joint distance {wandr * 1000:.4f} mm; {verdict} the {TOLERANCE_M * 1000:g} mm "
        "tolerance.", "",
        "| bodies | networks | body-primitives/s |", "|---|---|---|",
        *[f"| {count:,} | {precision} | {rate:,.0f} |" for count, precision, rate in rows],
        "", "End to end on CUDA (`benchmarks/gpu_end_to_end.py`): each shipped policy in its env, with the env's prior "
        "and the policy's network on the GPU, deterministic actions, one frame rendered; tiny PPO and DQN runs; the "
        "tree search.", "", *table(jobs),
        "", machine_line(), f"Command: `motion-envs bench gpu`; {time.perf_counter() - began:.0f} s in all.", "",
    ]  # fmt: skip
    section = "\n".join(lines)
    print(section)
    replace_section(RESULTS / "throughput.md", section)
    return 0 if distance <= TOLERANCE_M and all(job.ran for job in jobs) else 1
