"""PPO throughput on GammaReach-v0: RLlib's env runners against the SB3 path, same bodies, same update
(`motion-envs bench rllib`; needs `pip install -e ".[ray]"`).

Each engine trains PPO with α = 10 (the paper's reward) from the same 256-unit actor-critic on `bodies` bodies
× 60 primitives per update (the SB3 path's defaults, `agents.train_ppo.PPOTrainConfig`), for one warm-up update
and `updates` timed ones. Rows: SB3 (`agents.vec_env.NativeVecEnv`, one process), RLlib with the driver
sampling (0 env runners) and RLlib with 1 env-runner actor. Columns: env steps (primitives) per second of
sampling, and per second of the whole update (sampling + learning). Timing ratios are within this run. A Ray
actor's torch runs as many threads as it has CPUs (`--cpus-per-env-runner`).
Writes `benchmarks/results/rllib.md` (section "PPO throughput").
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from benchmarks.machine import bench_command, machine_line
from benchmarks.sections import replace_section

RESULTS = Path(__file__).resolve().parent / "results"
ENV_ID = "motion_envs/GammaReach-v0"


def sb3_rates(bodies: int, updates: int) -> tuple[float, float]:
    """(sampling steps/s, whole-update steps/s) of the SB3 path."""
    from stable_baselines3.common.vec_env import VecMonitor

    from agents.train_ppo import PPOTrainConfig, new_model
    from agents.vec_env import NativeVecEnv

    with tempfile.TemporaryDirectory() as folder:
        config = PPOTrainConfig(env_id=ENV_ID, num_envs=bodies, init="scratch", run_dir=Path(folder))
        model = new_model(config, VecMonitor(NativeVecEnv.make(ENV_ID, num_envs=bodies, reward=config.reward)))
        model.learn(bodies * config.n_steps)  # warm-up update
        sampling = [0.0]
        collect = model.collect_rollouts

        def timed_collect(*args, **kwargs):
            began = time.perf_counter()
            result = collect(*args, **kwargs)
            sampling[0] += time.perf_counter() - began
            return result

        model.collect_rollouts = timed_collect
        began = time.perf_counter()
        model.learn(updates * bodies * config.n_steps, reset_num_timesteps=False)
        whole = time.perf_counter() - began
    steps = updates * bodies * config.n_steps
    return steps / sampling[0], steps / whole


def rllib_rates(bodies: int, updates: int, env_runners: int, cpus: int = 1) -> tuple[float, float]:
    """(sampling steps/s, whole-update steps/s) of RLlib's PPO with `env_runners` actors of `cpus` CPUs each (0:
    the driver samples)."""
    from agents.rllib_envs import register_rllib_env
    from agents.train_ppo import PPOTrainConfig
    from agents.train_rllib import algorithm_config, start_ray

    config = PPOTrainConfig(env_id=ENV_ID, num_envs=bodies, init="scratch", engine="rllib", env_runners=env_runners,
                            cpus_per_env_runner=cpus)  # fmt: skip
    start_ray(None)
    register_rllib_env(ENV_ID, config.bootstrap_truncation)
    algorithm = algorithm_config(config).build_algo()
    algorithm.train()  # warm-up update
    steps = sampling = whole = 0.0
    for _ in range(updates):
        began = time.perf_counter()
        result = algorithm.train()
        whole += time.perf_counter() - began
        steps += result["env_runners"]["num_env_steps_sampled"]
        sampling += result["timers"]["env_runner_sampling_timer"]
    algorithm.stop()
    return steps / sampling, steps / whole


def curve_section(run_dir: Path) -> str:
    """The learning curve of a `train ppo --engine rllib` run (its `curve.json` and manifest entry) as a section,
    the plot copied beside the results."""
    import json
    import shutil

    curve = json.loads((run_dir / "curve.json").read_text())
    manifest = run_dir / "manifest.json"
    entry = next(iter(json.loads(manifest.read_text()).values()), {}) if manifest.exists() else {}
    command = entry.get("config", {}).get("command", "")
    shutil.copyfile(run_dir / "curve.png", RESULTS / "rllib_curve.png")
    lines = ["## RLlib PPO training on GammaReach-v0", "", machine_line(), "",
             f"`{command}` ({run_dir}): per-body success of the training episodes that ended in each window "
             "(sampled latents), as `train ppo` records it on either engine.", "",
             "| env steps | training minutes | success rate | episodes |", "|---|---|---|---|"]  # fmt: skip
    lines += [f"| {point['timesteps']:,} | {point['wall_seconds'] / 60:.1f} | {point['success_rate']:.3f} | {point['episodes']:,} |"
              for point in curve]  # fmt: skip
    lines += ["", f"Shipped checkpoint: {entry.get('shipped', '?')}.", "", "![curve](rllib_curve.png)", ""]
    return "\n".join(lines)


def main(bodies: int = 256, updates: int = 2, curve_from: Path | None = None) -> int:
    """Time the engines (`bodies` per update), or with `curve_from` (a run folder) write that run's curve."""
    if curve_from is not None:
        section = curve_section(curve_from)
        print(section)
        replace_section(RESULTS / "rllib.md", section, title="# Ray and RLlib")
        return 0
    rows = {"SB3 (NativeVecEnv, one process)": sb3_rates(bodies, updates)}
    rows["RLlib, 0 env runners (the driver samples)"] = rllib_rates(bodies, updates, 0)
    for cpus in (1, 2):
        rows[f"RLlib, 1 env runner of {cpus} CPU{'s' if cpus > 1 else ''}"] = rllib_rates(bodies, updates, 1, cpus)
    base_sampling, base_whole = next(iter(rows.values()))
    lines = ["## PPO throughput", "", machine_line(), "",
             f"GammaReach-v0, {bodies} bodies × 60 primitives per update, α = 10, 256-unit actor-critic, "
             f"{updates} timed updates after a warm-up one. `{bench_command('rllib', {'bodies': bodies})}`.", "",
             "| engine | sampling (steps/s) | whole update (steps/s) | sampling vs SB3 | update vs SB3 |",
             "|---|---|---|---|---|"]  # fmt: skip
    for label, (sampling, whole) in rows.items():
        lines.append(f"| {label} | {sampling:,.0f} | {whole:,.0f} | {sampling / base_sampling:.2f}× | {whole / base_whole:.2f}× |")
    section = "\n".join(lines) + "\n"
    print(section)
    RESULTS.mkdir(exist_ok=True)
    replace_section(RESULTS / "rllib.md", section, title="# Ray and RLlib")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
