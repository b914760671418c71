"""GAMMA rollout speed (`motion-envs bench speed`): the paper's Table S3 on this machine.

For batches of 64 to 4,096 bodies: seconds per primitive (one
`GammaReachCore.step`: both predictors, body regression, skinning, blending,
the floor and foot rules, markers and the reward; at 1,024 bodies also without
the foot rule) and body-primitives per second, in fp32 and with the
prior's networks in bf16 (`GammaGenerator.set_precision`). Beside them: the
FLOPs of one body-primitive (counted by `torch.utils.flop_counter`), this
machine's own matmul FLOP/s in fp32 and bf16 (measured in the same run), and
the share of it a rollout achieves. Then the same for `env.step` through the
SB3 adapter (`NativeVecEnv` over `GammaReachVectorEnv`: observations, numpy
conversion, auto-reset) against the raw core step. Writes the "GAMMA rollout"
section of `benchmarks/results/throughput.md`.
"""

from __future__ import annotations

import dataclasses
import math
import resource
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode, register_flop_formula

from agents.vec_env import NativeVecEnv
from benchmarks.machine import bench_command, machine_line
from benchmarks.sections import replace_section
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore, GammaReachState, GammaReachVectorEnv
from motion_envs.precision import native_bf16, resolve_precision
from motion_envs.priors.gamma_generator import GammaGenerator
from motion_envs.priors.inference_linear import ONEDNN_LINEAR, linear

RESULTS = Path(__file__).resolve().parent / "results"
SECTION = "## GAMMA rollout"
PAPER_SECONDS_1024 = 0.85
"""Table S3: seconds per primitive for 1,024 bodies on a Quadro RTX 6000 (≈ 1,205 body-primitives/s)."""
TARGETS = {"float32": 5_000, "bfloat16": 10_000}
"""Body-primitives/s at 1,024 bodies on 2 cores (issue "Speed and portability"); bf16 only where it is native."""


def command_line(bench: str, output: str) -> str:
    """The `motion-envs bench` command that wrote a throughput section to `output` (a results file stem)."""
    return bench_command(bench, {"output": output}, {"output": "throughput"})


def best_seconds(run: Callable[[], object], repeats: int) -> float:
    """Fastest of `repeats` timed calls after one warm-up call."""
    return interleaved_best_seconds([run], repeats)[0]


def interleaved_best_seconds(runs: list[Callable[[], object]], repeats: int) -> list[float]:
    """Fastest of `repeats` timed calls of each of `runs`, called in turn (a, b, a, b, ...) after one warm-up call
    each, so that a shared machine's drift affects all of them alike."""
    for run in runs:
        run()
    times = [[] for _ in runs]
    for _ in range(repeats):
        for run, seen in zip(runs, times):
            tick = time.perf_counter()
            run()
            seen.append(time.perf_counter() - tick)
    return [min(seen) for seen in times]


@torch.no_grad()
def matmul_flops(dtype: torch.dtype, size: int = 1024) -> float:
    """FLOP/s of a square fp32/bf16 matmul on this machine (all torch threads), through the path the priors' linears
    take at inference (`inference_linear.linear`: oneDNN on the CPU)."""
    a, b = torch.randn(size, size, dtype=dtype), torch.randn(size, size, dtype=dtype)
    repeats = 10 if dtype == torch.float32 else 2
    return 2 * size**3 * repeats / best_seconds(lambda: [linear(a, b) for _ in range(repeats)], 3)


if ONEDNN_LINEAR is not None:

    @register_flop_formula(ONEDNN_LINEAR)
    def _onednn_linear_flops(x_shape, second_shape, third_shape, *args, **kwargs) -> int:
        """oneDNN's fused linear: (x (..., in), weight (out, in), bias, ...) or, with a fused sum (`.binary`),
        (x, summand (..., out), weight, ...): the matmul's FLOPs, as torch counts `addmm`'s."""
        w_shape = third_shape if third_shape is not None and len(third_shape) == 2 else second_shape
        return 2 * math.prod(x_shape[:-1]) * w_shape[0] * w_shape[1]


def walking_state(core: GammaReachCore, count: int) -> GammaReachState:
    """`count` bodies after one primitive (2-frame seeds: the steady state of a rollout)."""
    start = core.sample_initial_state([np.random.default_rng(i) for i in range(count)])
    state, _ = core.step(start, torch.zeros(count, core.generator.latent_size))
    return state


def page_faults_per_step(core: GammaReachCore, state: GammaReachState, z: torch.Tensor, steps: int = 3) -> float:
    """Minor page faults of this process per core step (memory the kernel maps and zero-fills; `motion_envs.allocator`)."""
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(steps):
        core.step(state, z)
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / steps


def step_flops(core: GammaReachCore, state: GammaReachState) -> float:
    """FLOPs of one core step per body (matmuls and convolutions, as counted by torch)."""
    z = torch.zeros(state.num_bodies, core.generator.latent_size)
    with FlopCounterMode(display=False) as counter:
        core.step(state, z)
    return counter.get_total_flops() / state.num_bodies


def main(batches: tuple[int, ...] = (64, 128, 256, 512, 1024, 4096), bf16_batches: tuple[int, ...] = (64, 256, 1024),
         env_batches: tuple[int, ...] = (64, 256, 1024), output: str = "throughput") -> int:  # fmt: skip
    """Writes the "GAMMA rollout" and "Other envs' stepping" sections of `benchmarks/results/<output>.md`."""
    began = time.perf_counter()
    generator = GammaGenerator.load()
    core = GammaReachCore(GammaReachConfig(), generator)
    flops = {"fp32": matmul_flops(torch.float32), "bf16": matmul_flops(torch.bfloat16)}
    per_body = step_flops(core, walking_state(core, 64))
    rows = []
    for precision, sizes in (("float32", batches), ("bfloat16", bf16_batches)):
        generator.set_precision(precision)
        for count in sizes:
            state = walking_state(core, count)
            z = torch.randn(count, generator.latent_size, generator=torch.Generator().manual_seed(0))
            seconds = best_seconds(lambda: core.step(state, z), 5 if count <= 1024 else 1)
            rows.append((precision, count, seconds, count / seconds))
            print(f"{precision} {count}: {seconds:.3f} s per primitive, {count / seconds:,.0f} body-primitives/s")
    faults = page_faults_per_step(core, state, z)  # the last timed: 1,024 bodies (bf16 where listed)
    rule_free = GammaReachCore(dataclasses.replace(core.config, lock_feet=False), generator)
    rule_costs = {}
    for precision in ("float32", "bfloat16"):  # the foot rule's cost at 1,024 bodies, with and without it in turn
        generator.set_precision(precision)
        states = walking_state(core, 1024), walking_state(rule_free, 1024)
        z = torch.randn(1024, generator.latent_size, generator=torch.Generator().manual_seed(0))
        with_rule, seconds = interleaved_best_seconds([lambda: core.step(states[0], z), lambda: rule_free.step(states[1], z)], 5)
        rule_costs[precision] = with_rule / seconds - 1
        rows.append((f"{precision}, no foot rule", 1024, seconds, 1024 / seconds))
        print(f"{precision} 1024 without the foot rule: {seconds:.3f} s per primitive (with it, in turn: {with_rule:.3f} s)")
    generator.set_precision("float32")
    env_rows = []
    for count in env_batches:
        venv = NativeVecEnv(GammaReachVectorEnv(num_envs=count, generator=generator, precision="float32"))
        venv.seed(0)
        venv.reset()
        actions = np.random.default_rng(0).standard_normal((count, generator.latent_size)).astype(np.float32)

        def env_step() -> None:
            venv.step_async(actions)
            venv.step_wait()

        state = walking_state(core, count)
        raw = best_seconds(lambda: core.step(state, torch.as_tensor(actions)), 3)
        wrapped = best_seconds(env_step, 3)
        env_rows.append((count, raw, wrapped))
        print(f"env {count}: raw {raw:.3f} s, SB3 adapter {wrapped:.3f} s ({wrapped / raw - 1:+.0%})")
    chosen = resolve_precision("auto")
    at_1024 = {precision: rate for precision, count, _, rate in rows if count == 1024}  # the rule-free rows named apart
    verdicts = [f"{name} {at_1024[name]:,.0f} (target ≥ {target:,})" for name, target in TARGETS.items()
                if name in at_1024 and (name == "float32" or native_bf16())]  # fmt: skip
    lines = [
        SECTION, "",
        "One primitive (10 frames at 40 fps, 8 new) for every body: both marker predictors, body regression and skinning of the 8 new "
        "frames, blending, the envs' floor and foot rules (`ground_feet`, `lock_feet`: the defaults), markers and the reward "
        "(`GammaReachCore.step`), best of 5; the last rows without the foot rule, each timed in turn with the rule's "
        f"step so that the machine's drift cancels: the rule costs {rule_costs['float32']:+.0%} of an fp32 step and "
        f"{rule_costs['bfloat16']:+.0%} of a bf16 step at 1,024 bodies. The paper's Table S3: "
        f"{PAPER_SECONDS_1024} s per primitive for 1,024 bodies on a Quadro RTX 6000 GPU ≈ "
        f"{1024 / PAPER_SECONDS_1024:,.0f} body-primitives/s. One body-primitive costs {per_body / 1e6:.1f} MFLOP "
        f"(torch's FLOP counter). This machine's matmul (1024², same run, through oneDNN as the priors' layers): "
        f"fp32 {flops['fp32'] / 1e9:.0f} GFLOP/s, "
        f"bf16 {flops['bf16'] / 1e9:.1f} GFLOP/s. Freed memory stays in the process's heap (`motion_envs.allocator`, "
        f"which every core sets): {faults:,.0f} minor page faults per step of the last row timed above ({rows[-1][1]:,} "
        "bodies; without it 13,900-15,900 a step at 1,024 bodies, 8-13% slower on the AMX Xeon).", "",
        f"At 1,024 bodies: {'; '.join(verdicts)}. `precision=\"auto\"` picks {chosen} on this CPU "
        f"({'native bf16' if native_bf16() else 'no native bf16'}).", "",
        "| networks | bodies | s per primitive | body-primitives/s | vs paper's GPU | share of matmul FLOP/s |",
        "|---|---|---|---|---|---|",
    ]  # fmt: skip
    for precision, count, seconds, rate in rows:
        share = rate * per_body / flops["fp32" if precision.startswith("float32") else "bf16"]
        shown = f"{share:.0%}" if share <= 1 else "– (see below the table)"
        lines.append(f"| {precision} | {count:,} | {seconds:.3f} | {rate:,.0f} | {rate / (1024 / PAPER_SECONDS_1024):.2f}× "
                     f"| {shown} |")  # fmt: skip
    if any(rate * per_body > flops["fp32" if precision.startswith("float32") else "bf16"] for precision, _, _, rate in rows):
        lines += ["", "Shares over 100% are not shown: the square matmul measured slower in this run than the networks' "
                  "own layers ran (the reference is the best of 3 short timings and varies between runs on a shared "
                  "machine), so it is no ceiling for them here."]  # fmt: skip
    if flops["bf16"] < flops["fp32"]:
        lines += ["", f"This CPU multiplies bf16 matrices {flops['fp32'] / flops['bf16']:.0f}× slower than fp32 (no bf16 "
                  "units: torch converts in software), so the bf16 mode is for CPUs with AMX/AVX512-BF16 and for "
                  "GPUs; its share of the square bf16 matmul rate is not meaningful here (the networks' small matmuls "
                  "take faster paths)."]  # fmt: skip
    lines += ["", "`env.step` through the SB3 adapter (`NativeVecEnv` over `GammaReachVectorEnv`, fp32) against the "
              "raw core step on the same bodies:", "",
              "| bodies | raw step (s) | SB3 env.step (s) | overhead |", "|---|---|---|---|"]  # fmt: skip
    lines += [f"| {count:,} | {raw:.3f} | {wrapped:.3f} | {wrapped / raw - 1:+.0%} |" for count, raw, wrapped in env_rows]
    lines += ["", machine_line(), f"Command: `{command_line('speed', output)}`; {time.perf_counter() - began:.0f} s in all.", ""]
    section = "\n".join(lines)
    print(section)
    replace_section(RESULTS / f"{output}.md", section)
    other = other_envs_section(command=command_line("speed", output))
    print(other)
    replace_section(RESULTS / f"{output}.md", other)
    return 0


def other_envs_section(bodies: int = 64, actions: int = 3, command: str = "motion-envs bench speed") -> str:
    """WANDR's decode at 1,024 bodies and ClopsNav's step at `bodies` (random actions), measured on the same machine
    line as the GAMMA rollout (these priors run in fp32 on every CPU: they have no bf16 mode)."""
    from benchmarks.clops_matrix import stepping_rate
    from benchmarks.wandr_grid import decode_throughput
    from motion_envs.envs.clops_nav import ClopsNavConfig, ClopsNavCore
    from motion_envs.envs.wandr_reach import WandrReachConfig, WandrReachCore

    wandr = decode_throughput(WandrReachCore(WandrReachConfig()))
    per_action, per_frame = stepping_rate(ClopsNavCore(ClopsNavConfig(family="open", split="test")), bodies, actions)
    return "\n".join([
        "## Other envs' stepping (bench speed)", "",
        "| env | bodies | rate | target |", "|---|---|---|---|",
        f"| WandrReach-v0, prior step (decode, integrate, FK) | 1,024 | {wandr['prior']:,.0f} body-frames/s | ≥ 20,000 |",
        f"| WandrReach-v0, env core step | 1,024 | {wandr['env']:,.0f} body-frames/s | |",
        f"| ClopsNav-v0 (open, 64 × 64 views), random actions | {bodies} | {per_action:,.0f} actions/s ({per_frame:,.0f} "
        "body-frames/s: decode, collisions, views) | |",
        "", machine_line(), f"Command: `{command}`.", "",
    ])  # fmt: skip
