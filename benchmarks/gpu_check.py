"""CUDA check (`motion-envs bench gpu`): the GAMMA rollout on the GPU agrees with the CPU, and how fast it runs.

1. Agreement: the same start bodies and the same latents (seeded on the CPU), stepped on the CPU and on CUDA in
   fp32 with TF32 off (cuDNN runs the GRU in TF32 by default: 1.4 mm after 20 GAMMA primitives on an H200, against
   0.012 mm without it). GAMMA: a free rollout of `PRIMITIVES` = 20 primitives (every marker and pelvis of their
   10-frame windows) within `TOLERANCE_M` (1e-4 m). WANDR: each of `WANDR_FRAMES` = 240 frames stepped on both
   devices from the same (CPU) state, within `TOLERANCE_M`; its free rollout is reported, not checked: WANDR's
   frame-by-frame recursion amplifies rounding (on the CPU alone, latents perturbed by 1e-6 end up 3.7 mm apart
   after 240 frames; CPU against an H200, 64 bodies: 0.5 um after one frame, 16 um after 40, 1 mm after 80 and
   up to 0.86 m after 240 in the 12 least stable bodies, median 0.19 mm), so no tolerance holds for it by
   construction. The GPU's matmuls reassociate sums differently, so the devices agree to float32 rounding, not bit
   for bit.
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
    core = wandr_core(device, latents.shape[0])
    state = core.sample_initial_state([np.random.default_rng(seed) for seed in range(latents.shape[1])])
    frames = []
    for z in latents:
        state, _ = core.step(state, z.to(device))
        frames.append(state.joints.cpu())
    return torch.stack(frames)


def wandr_core(device: str, frames: int):
    """A WandrReach core on `device` whose episodes last `frames` frames."""
    from motion_envs.envs.wandr_reach import WandrReachConfig, WandrReachCore

    return WandrReachCore(WandrReachConfig(device=device, max_frames=frames))


def wandr_step_agreement(latents: torch.Tensor, device: str = "cuda") -> float:
    """Largest joint distance (m) between one WANDR frame stepped on the CPU and on `device` from the same CPU
    state, over the T frames of the CPU's rollout with latents (T, N, 64)."""
    cpu, other = wandr_core("cpu", latents.shape[0]), wandr_core(device, latents.shape[0])
    state = cpu.sample_initial_state([np.random.default_rng(seed) for seed in range(latents.shape[1])])
    largest = 0.0
    for z in latents:
        elsewhere, _ = other.step(state.to(device), z.to(device))
        state, _ = cpu.step(state, z)
        largest = max(largest, float((state.joints - elsewhere.joints.cpu()).norm(dim=-1).max()))
    return largest


def distances(positions, latents: torch.Tensor) -> torch.Tensor:
    """(T,) largest CPU-CUDA distance (m) at each of the T steps of `positions(device, latents)`."""
    gap = (positions("cpu", latents) - positions("cuda", latents)).norm(dim=-1)
    return gap.flatten(1).amax(dim=1)


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
    gamma_latents = torch.randn(PRIMITIVES, BODIES, 128, generator=generator)
    wandr_latents = torch.randn(WANDR_FRAMES, BODIES, 64, generator=generator)
    tf32 = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = False
    try:
        gamma = float(distances(rollout_positions, gamma_latents).max())
        wandr = wandr_step_agreement(wandr_latents)
        wandr_free = distances(wandr_joints, wandr_latents)
    finally:
        torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = tf32
    distance = max(gamma, wandr)
    core = GammaReachCore(GammaReachConfig(device="cuda"))
    rows = [(count, precision, throughput(core, count, precision)) for count in BATCHES for precision in ("float32", "bfloat16")]
    jobs = end_to_end("cuda")
    verdict = "within" if distance <= TOLERANCE_M else "BEYOND"
    lines = [
        SECTION, "",
        f"Agreement: {BODIES} bodies, the same latents on the CPU and on {torch.cuda.get_device_name()} (fp32, TF32 "
        f"off): GAMMA, a free rollout of {PRIMITIVES} primitives, largest marker or pelvis distance "
        f"{gamma * 1000:.4f} mm; WANDR, each of {WANDR_FRAMES} frames stepped from the same state, largest joint "
        f"distance {wandr * 1000:.4f} mm; {verdict} the {TOLERANCE_M * 1000:g} mm tolerance. WANDR's free rollout "
        "(not checked: its recursion amplifies rounding, see `benchmarks/gpu_check.py`), largest joint distance after "
        + ", ".join(f"{frame} frame{'s' * (frame > 1)} {float(wandr_free[frame - 1]) * 1000:.4f} mm" for frame in (1, 40, 80, WANDR_FRAMES))
        + ".", "",
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
