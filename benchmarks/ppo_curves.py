"""Learning curves of the shipped PPO policies (`python -m benchmarks.ppo_curves`), from their manifest entries.

Each `motion-envs train ppo` run records, every few minutes, the success rate
of the training episodes that ended since the last record (per body, sampled
latents). This plots them against env steps and wall time and tabulates the
shipped checkpoint -> `benchmarks/results/ppo_curves.md` and `.png`. A policy
trained in stages (each `--init` the last one's policy: the record's `stages`)
shows the curve of its first stage, the one that learnt the task from the data
or from scratch, where the record keeps it, else its last stage's; the last
column says which.
"""

from __future__ import annotations

import json
from pathlib import Path

from motion_envs.atomic import atomic_write
from motion_envs.plots import learning_curves, plt, save
from motion_envs.priors.training import WEIGHTS_DIR

RESULTS = Path(__file__).resolve().parent / "results"


def learning_run(entry: dict) -> dict:
    """The run whose curve a policy's row shows: the first of its `stages` where that stage's curve was kept, else
    the record's own run (with all stages' commands); with its command, curve, timesteps, machine and which run of
    how many it is."""
    stages = entry.get("stages", [])
    runs = len(stages) + 1
    if stages and stages[0].get("curve"):
        first = stages[0]
        return {"command": first["command"], "curve": first["curve"], "timesteps": first["timesteps"],
                "machine": first.get("machine"), "shown": f"first of {runs} runs"}  # fmt: skip
    return {"command": entry.get("repeat", entry["config"]["command"]), "curve": entry["curve"], "timesteps": entry["timesteps"],
            "machine": entry.get("machine"), "shown": f"last of {runs} runs" if stages else "its only run"}  # fmt: skip


TARGET = 0.9
"""Per-body training success whose first window the table times."""


def main() -> int:
    manifest = json.loads((WEIGHTS_DIR / "manifest.json").read_text())
    runs = {name: learning_run(entry) for name, entry in sorted(manifest.items()) if entry.get("kind") == "ppo_policy" and entry["curve"]}
    if not runs:
        print("no shipped PPO policy with a learning curve")
        return 1
    figure, (by_steps, by_time) = plt.subplots(1, 2, figsize=(10, 4))
    lines = ["# PPO learning curves (shipped policies)", "",
             "Per-body success of training episodes (sampled latents), recorded every 3 minutes; the shipped "
             "checkpoint is the best window. GammaReach policies start from the data's cloned latents, the WandrReach "
             "policy from WANDR's sampler (mean 0, σ = 1). One thread per run.", "",
             f"\"≥ {TARGET:.1f} at\": the minutes to the first window at or above {TARGET:.1f} (the issue's GammaReach target: "
             "within 60 minutes on 2 cores).", "",
             f"| policy | command | first window | best window | at steps | at minutes | ≥ {TARGET:.1f} at (minutes) | "
             "env steps in all | machine | curve |",
             "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for name, entry in runs.items():
        curve = entry["curve"]
        rates = [point["success_rate"] for point in curve]
        label = Path(name).stem.removeprefix("ppo_")
        best = max(curve, key=lambda point: point["success_rate"])
        reached = next((f"{point['wall_seconds'] / 60:.0f}" for point in curve if point["success_rate"] >= TARGET), "never")
        lines.append(f"| {label} | `{entry['command']}` | {rates[0]:.2f} | {best['success_rate']:.2f} | "
                     f"{best['timesteps']:,} | {best['wall_seconds'] / 60:.0f} | {reached} | {entry['timesteps']:,} | "
                     f"{entry.get('machine') or 'not recorded'} | {entry['shown']} |")  # fmt: skip
    curves = {Path(name).stem.removeprefix("ppo_"): entry["curve"] for name, entry in runs.items()}
    learning_curves(by_steps, by_time, curves, steps_label="env steps (GammaReach: primitives; WandrReach: frames)")
    by_steps.set(ylabel="success rate (per body)", ylim=(0, 1))
    by_time.set(ylim=(0, 1))
    lines += ["", "![curves](ppo_curves.png)", ""]
    text = "\n".join(lines)
    print(text)
    atomic_write(RESULTS / "ppo_curves.md", lambda file: file.write(text.encode()))
    save(figure, RESULTS / "ppo_curves.png", dpi=90)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
