"""Learning curves of the shipped PPO policies (`python -m benchmarks.ppo_curves`), from their manifest entries.

Each `motion-envs train ppo` run records, every few minutes, the success rate
of the training episodes that ended since the last record (per body, sampled
latents). This plots them against env steps and wall time and tabulates the
shipped checkpoint -> `benchmarks/results/ppo_curves.md` and `.png`.
"""

from __future__ import annotations

import json
from pathlib import Path

from motion_envs.atomic import atomic_write
from motion_envs.plots import learning_curves, plt, save
from motion_envs.priors.training import WEIGHTS_DIR

RESULTS = Path(__file__).resolve().parent / "results"


def main() -> int:
    manifest = json.loads((WEIGHTS_DIR / "manifest.json").read_text())
    runs = {name: entry for name, entry in sorted(manifest.items()) if entry.get("kind") == "ppo_policy" and entry["curve"]}
    if not runs:
        print("no shipped PPO policy with a learning curve")
        return 1
    figure, (by_steps, by_time) = plt.subplots(1, 2, figsize=(10, 4))
    lines = ["# PPO learning curves (shipped policies)", "",
             "Per-body success of training episodes (sampled latents), recorded every 3 minutes; the shipped "
             "checkpoint is the best window. GammaReach policies start from the data's cloned latents, the WandrReach "
             "policy from WANDR's sampler (mean 0, σ = 1). One thread per run.", "",
             "| policy | command | first window | best window | at steps | at minutes | env steps in all | machine |",
             "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for name, entry in runs.items():
        curve = entry["curve"]
        rates = [point["success_rate"] for point in curve]
        label = Path(name).stem.removeprefix("ppo_")
        best = max(curve, key=lambda point: point["success_rate"])
        lines.append(f"| {label} | `{entry.get('repeat', entry['config']['command'])}` | {rates[0]:.2f} | {best['success_rate']:.2f} | "
                     f"{best['timesteps']:,} | {best['wall_seconds'] / 60:.0f} | {entry['timesteps']:,} | "
                     f"{entry.get('machine', 'not recorded')} |")  # fmt: skip
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
