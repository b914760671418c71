"""GAMMA's goal-reaching benchmark (`motion-envs bench gamma`), the paper's Table 1 protocol.

Fixed body-goal pairs (seeded): a shipped start pose facing a random way in
the middle of a 20 × 20 m ground, a goal uniform on it. Each pair is run
with `clones` copies for up to 60 primitives by each controller, all bodies
in one batch of the GammaReach core. Per controller:

* steps: primitives until the goal is reached (0.75 m), over successful bodies;
* success rate: bodies that reach the goal;
* avg. dist.: ground distance pelvis-goal when the episode ends (reached or not);
* contact score: GAMMA Eq. 11 over every generated primitive;
* FS: WANDR's foot skating at 40 fps with its 0.2 m/s threshold.

`--quick` (the README's main job) runs fewer pairs and clones. Writes
`benchmarks/results/gamma_control.md` (or `gamma_control_quick.md`) and a
top-down plot of one clone per pair.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from tqdm import tqdm  # noqa: E402

from agents.controllers import PolicyLatent  # noqa: E402
from baselines.latent_controllers import GreedyLatent, RandomLatent  # noqa: E402
from benchmarks.machine import machine_line  # noqa: E402
from motion_envs.atomic import atomic_write  # noqa: E402
from motion_envs.body.markers import foot_vertex_ids  # noqa: E402
from motion_envs.data.primitives import GAMMA_FPS  # noqa: E402
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore, GammaReachState  # noqa: E402
from motion_envs.metrics import foot_skating, skating_threshold  # noqa: E402
from motion_envs.priors.canonical import PELVIS  # noqa: E402
from motion_envs.priors.training import WEIGHTS_DIR  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
PAPER_ROWS = {  # GAMMA Table 1: steps, success rate, avg. dist., contact score
    "g-CVAE (paper)": (24.1, 0.91, 3.46, 0.80),
    "policy(10) (paper)": (33.9, 0.95, 3.32, 0.94),
    "policy(1) (paper)": (21.2, 1.0, 3.60, 0.93),
    "policy(10) & top1 (paper)": (26.5, 0.99, 0.04, 0.97),
    "policy(10) & top4 (paper)": (23.4, 0.96, 1.98, 0.96),
}
Controller = Callable[[GammaReachCore, GammaReachState], torch.Tensor]


def fixed_pairs(core: GammaReachCore, pairs: int, clones: int, seed: int) -> GammaReachState:
    """`pairs` seeded body-goal pairs, each repeated `clones` times (clones of a pair are adjacent)."""
    rngs = [np.random.default_rng([seed, pair]) for pair in range(pairs)]
    return core.sample_initial_state(rngs).repeat(clones)


@torch.no_grad()
def run_controller(core: GammaReachCore, state: GammaReachState, controller: Controller) -> dict:
    """Run every body to its episode end; finished bodies leave the batch."""
    count, horizon = state.num_bodies, core.config.max_primitives
    steps_taken = torch.zeros(count, dtype=torch.long)
    final_distance = torch.zeros(count)
    reached = torch.zeros(count, dtype=torch.bool)
    paths = torch.full((count, horizon + 1, 2), float("nan"))  # pelvis at the end of every primitive
    paths[:, 0] = state.seed.joints[:, -1, PELVIS, :2]
    contact, skating = [], []
    active = torch.arange(count)
    body, feet_ids = core.generator.body, foot_vertex_ids()
    for step in tqdm(range(horizon), desc="primitives", leave=False):
        state, result = core.step(state, controller(core, state))
        primitive = result.primitive
        contact.append(result.contact_score)
        feet = body.skin(body(primitive.transl, primitive.global_orient, primitive.body_pose), feet_ids)
        first = 0 if step == 0 else 1  # transitions from the last seed frame on (start pose: 1-frame seed)
        skating.append(foot_skating(feet[:, first:], skating_threshold(GAMMA_FPS)).float().flatten())
        paths[active, step + 1] = primitive.joints[:, -1, PELVIS, :2]
        done = result.terminated | result.truncated
        ended = active[done]
        steps_taken[ended], final_distance[ended], reached[ended] = state.steps[done], result.distance[done], result.reached[done]
        if done.all():
            break
        state, active = state.index(~done), active[~done]
    return {
        "steps": float(steps_taken[reached].float().mean()) if reached.any() else float("nan"),
        "success rate": float(reached.float().mean()),
        "avg. dist.": float(final_distance.mean()),
        "contact score": float(torch.cat(contact).mean()),
        "FS": float(torch.cat(skating).mean()),
        "paths": paths.numpy(),
    }


def main(pairs: int = 100, clones: int = 32, candidates: int = 16, seed: int = 0, quick: bool = False) -> int:
    if quick:
        pairs, clones, candidates = 20, 4, 8
    began = time.perf_counter()
    core = GammaReachCore(GammaReachConfig())
    controllers: dict[str, Controller] = {
        "random z": RandomLatent(seed),
        f"greedy best-of-{candidates} by reward": GreedyLatent(candidates, "reward", seed),
        f"greedy best-of-{candidates} by distance": GreedyLatent(candidates, "distance", seed),
    }
    for policy in sorted(WEIGHTS_DIR.glob("ppo_gammareach_*.zip")):  # every shipped GammaReach policy
        controllers[f"PPO {policy.stem.removeprefix('ppo_gammareach_')}"] = PolicyLatent(policy, seed=seed)
    start = fixed_pairs(core, pairs, clones, seed)
    rows: dict[str, dict] = {}
    seconds: dict[str, float] = {}
    for name, controller in controllers.items():
        tick = time.perf_counter()
        rows[name] = run_controller(core, start.clone(), controller)
        seconds[name] = time.perf_counter() - tick
        print(f"{name}: success {rows[name]['success rate']:.2f} in {seconds[name]:.0f} s")
    name_suffix = "_quick" if quick else ""
    lines = [
        f"# GAMMA goal reaching ({'quick: ' if quick else ''}{pairs} body-goal pairs × {clones} clones, up to 60 primitives)",
        "",
        "Reward config: paper. Steps: primitives to reach the goal (successful bodies); avg. dist.: pelvis-goal ground "
        "distance (m) when the episode ends; contact score: Eq. 11 per primitive; FS: WANDR's, 40 fps, 0.2 m/s.",
        "",
        "| controller | steps ↓ | success rate ↑ | avg. dist. ↓ | contact score ↑ | FS ↓ | seconds |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, row in rows.items():
        steps = "–" if np.isnan(row["steps"]) else f"{row['steps']:.1f}"  # no body reached its goal
        lines.append(f"| {name} | {steps} | {row['success rate']:.2f} | {row['avg. dist.']:.2f} | "
                     f"{row['contact score']:.3f} | {row['FS']:.3f} | {seconds[name]:.0f} |")  # fmt: skip
    for name, (steps, success, distance, score) in PAPER_ROWS.items():
        lines.append(f"| {name} | {steps} | {success} | {distance} | {score} | | |")
    lines += ["", machine_line(), f"Command: `motion-envs bench gamma{' --quick' if quick else ''}`; "
              f"{time.perf_counter() - began:.0f} s in all.", "", f"![paths](gamma_control{name_suffix}.png)", ""]  # fmt: skip
    text = "\n".join(lines)
    print(text)
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic_write(RESULTS / f"gamma_control{name_suffix}.md", lambda file: file.write(text.encode()))
    figure, axes = plt.subplots(1, len(rows), figsize=(5 * len(rows), 5), squeeze=False)
    goals = start.goal[::clones, :2].numpy()
    for axis, (name, row) in zip(axes[0], rows.items()):
        for pair in range(pairs):
            path = row["paths"][pair * clones]
            axis.plot(path[:, 0], path[:, 1], linewidth=0.8)  # NaN after the episode ends
        axis.scatter(goals[:, 0], goals[:, 1], marker="x", color="black", s=20)
        axis.set(title=f"{name}: success {row['success rate']:.2f}", xlim=(-10, 10), ylim=(-10, 10), aspect="equal")
    figure.tight_layout()
    atomic_write(RESULTS / f"gamma_control{name_suffix}.png", lambda file: figure.savefig(file, format="png", dpi=100))
    return 0
