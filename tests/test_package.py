"""Package surface: env registration and the command line."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import pytest

import motion_envs


def test_register_envs_is_idempotent_and_registers_every_listed_id():
    before = {k for k in gym.registry if k.startswith("motion_envs/")}
    first = motion_envs.register_envs()
    second = motion_envs.register_envs()
    after = {k for k in gym.registry if k.startswith("motion_envs/")}
    assert first == second == sorted(motion_envs.ENV_SPECS)
    assert after == before == set(motion_envs.ENV_SPECS)


def test_every_env_has_a_native_vector_entry_point():
    assert "motion_envs/GammaReach-v0" in motion_envs.ENV_SPECS
    for env_id in motion_envs.ENV_SPECS:
        spec = gym.spec(env_id)
        assert spec.vector_entry_point is not None and spec.vector_entry_point.startswith("motion_envs.envs.")


def test_cli_help_lists_the_subcommands():
    result = subprocess.run(
        [sys.executable, "-m", "motion_envs.cli", "--help"], capture_output=True, text=True, check=True
    )
    for command in ("data", "train", "bench", "play"):
        assert command in result.stdout


def test_cli_reports_unknown_training_targets_clearly():
    result = subprocess.run(
        [sys.executable, "-m", "motion_envs.cli", "train", "clop"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2
    assert "invalid choice: 'clop'" in result.stderr and "dqn" in result.stderr


def test_rerun_rows_replace_their_lines_insert_new_ones_and_keep_the_rest(tmp_path):
    from benchmarks.sections import replace_rows

    path = tmp_path / "grid.md"
    path.write_text("# Grid\n\nMachine: A.\n\n| row | SR |\n|---|---|\n| sampler | 3 |\n| PPO (a) | 80 |\n| opt | 2 |\n| data | |\n")
    replace_rows(path, {"new": "| new | 1 |", "PPO (a)": "| PPO (a) | 85 |", "PPO (b)": "| PPO (b) | 90 |"}, "| data", "Rows rerun: B.")
    assert path.read_text() == ("# Grid\n\nMachine: A.\nRows rerun: B.\n\n| row | SR |\n|---|---|\n| sampler | 3 |\n"
                                "| PPO (a) | 85 |\n| PPO (b) | 90 |\n| opt | 2 |\n| new | 1 |\n| data | |\n")  # fmt: skip
    with pytest.raises(FileNotFoundError, match="run the whole benchmark once"):
        replace_rows(tmp_path / "missing.md", {}, "| data", "")


def test_bench_gpu_skips_cleanly_without_cuda(tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("a CUDA machine: `motion-envs bench gpu` measures here instead of skipping")
    result = subprocess.run([sys.executable, "-m", "motion_envs.cli", "bench", "gpu"], capture_output=True, text=True,
                            timeout=120, cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0 and "no CUDA device" in result.stdout and "Traceback" not in result.stderr


def test_the_gpu_checks_rollouts_run_on_the_cpu():
    """The CUDA agreement check's two rollouts, on the CPU here (what `bench gpu` compares with CUDA)."""
    import torch

    from benchmarks.gpu_check import rollout_positions, wandr_joints, wandr_step_agreement

    gamma = rollout_positions("cpu", torch.randn(2, 3, 128, generator=torch.Generator().manual_seed(0)))
    wandr = wandr_joints("cpu", torch.randn(4, 3, 64, generator=torch.Generator().manual_seed(0)))
    assert gamma.shape == (2, 3, 10, 68, 3) and wandr.shape == (4, 3, 22, 3)
    assert torch.isfinite(gamma).all() and torch.isfinite(wandr).all()
    assert (gamma[1, :, -1, -1] - gamma[0, :, 0, -1]).norm(dim=-1).max() > 0  # the pelvis moved
    # each frame stepped twice from the same state on one device, same shapes: equal by construction
    assert wandr_step_agreement(torch.randn(3, 2, 64, generator=torch.Generator().manual_seed(1)), device="cpu") == 0.0


def test_the_gpu_checks_end_to_end_jobs_run_on_the_cpu_and_report_failures():
    """`bench gpu`'s end-to-end jobs on the CPU here, at a few steps: a shipped policy in its env, PPO training and
    the tree search (the GammaReach, GammaWander and ClopsNav episodes and DQN training take the same paths as
    these, ~1 minute more on 2 cores); a job that raises becomes a row naming its error instead of stopping the rest."""
    from benchmarks.gpu_end_to_end import jobs, run_job, table

    work = jobs("cpu", steps=2, timesteps=16)
    assert len(work) == 7
    results = [run_job(name, work[name]) for name in ("ppo_wandrreach_alpha1_default.zip in its env",
                                                      "train ppo (GammaReach, from scratch)",
                                                      "tree search (GammaReach, α = 1 policy)")]  # fmt: skip
    assert all(result.ran and result.steps > 0 for result in results), table(results)

    def broken() -> tuple[int, bool]:
        raise RuntimeError("Expected all tensors to be on the same device\nmore detail")

    failed = run_job("broken", broken)
    assert not failed.ran and failed.error == "RuntimeError: Expected all tensors to be on the same device"
    assert "no: RuntimeError" in table([failed])[-1]


def test_machine_line_names_the_cpu_and_any_instruction_set_limit(monkeypatch):
    """Every benchmark's machine line: the CPU flags that decide the kernels, and an ISA limit where one is set (an
    estimate of an older CPU on a newer one must say so)."""
    from benchmarks.machine import machine_line
    from motion_envs import precision

    monkeypatch.setattr(precision, "cpu_flags", lambda: frozenset({"avx2", "fma"}))
    monkeypatch.delenv("ONEDNN_MAX_CPU_ISA", raising=False)
    line = machine_line()
    assert "CPU flags avx2, fma (bf16 emulated)" in line and "limited" not in line
    monkeypatch.setenv("ONEDNN_MAX_CPU_ISA", "AVX2")
    assert "kernels limited by ONEDNN_MAX_CPU_ISA=AVX2" in machine_line()
