"""GAMMA's goal-reaching benchmark (`motion-envs bench gamma`): the paper's Table 1 protocol.

Fixed body-goal pairs (seeded): a shipped start pose facing a random way in
the middle of a 20 × 20 m ground, a goal uniform on it. As in the paper
(Sec. 4.2), each pair's body is cloned `clones` times and all clones move at
once; a pair's simulation ends when any clone reaches the goal (0.75 m) or
after 60 primitives. Per row:

* steps: primitives until the first clone reached the goal (successful pairs);
* success rate: pairs where any clone reached the goal;
* avg. dist.: pelvis-goal ground distance of all clones when the pair ends;
* contact score: GAMMA Eq. 11 over every generated primitive;
* FS: WANDR's foot skating at 40 fps with its 0.2 m/s threshold.

Tree-search rows ("& topK", `motion_envs.wrappers.tree_search`) run one
search per pair (16 roots, 4 children per node, K kept); their "clones" are
the K kept nodes: avg. dist. is the kept nodes' mean when the search ends,
and contact score and FS are those of the chosen branch, replayed.

Rows: random z, the g-CVAE (`baselines.g_cvae`, z ~ N(0, I)), each shipped
GammaReach policy (sampled latents, as the paper), the α = 10 and α = 1
paper-reward policies with top-1 and top-4 search (the release's node cost
and distance alone), random z with top-4 search, and with `--bf16` (or when the CPU has native bf16) the
α = 10 policy with the prior's networks in bf16 (`GammaGenerator.set_precision`).
`--quick` (the README's main job) runs fewer pairs and clones. Writes
`benchmarks/results/gamma_control.md` (or `gamma_control_quick.md`) and a
top-down plot of the first clone (or chosen branch) per pair.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from agents.controllers import PolicyLatent
from baselines.g_cvae import G_CVAE_WEIGHTS, goal_cvae_generator
from baselines.latent_controllers import RandomLatent
from benchmarks.machine import machine_line
from motion_envs.plots import grid_of_axes, save, top_down
from motion_envs.atomic import atomic_write
from motion_envs.body.markers import foot_vertex_ids
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore, GammaReachState, GammaStepResult
from motion_envs.metrics import foot_skating, skating_threshold
from motion_envs.body.canonical_frame import PELVIS
from motion_envs.priors.training import WEIGHTS_DIR
from motion_envs.wrappers.tree_search import SearchCost, SearchSettings, beam_search

RESULTS = Path(__file__).resolve().parent / "results"
PAPER_ROWS = {  # GAMMA Table 1: steps, success rate, avg. dist., contact score
    "g-CVAE (paper)": (24.1, 0.91, 3.46, 0.80),
    "policy(10) (paper)": (33.9, 0.95, 3.32, 0.94),
    "policy(1) (paper)": (21.2, 1.0, 3.60, 0.93),
    "policy(10) & top1 (paper)": (26.5, 0.99, 0.04, 0.97),
    "policy(10) & top4 (paper)": (23.4, 0.96, 1.98, 0.96),
}
Controller = Callable[[GammaReachCore, GammaReachState], torch.Tensor]


def fixed_pairs(core: GammaReachCore, pairs: int, seed: int) -> GammaReachState:
    """`pairs` seeded body-goal pairs."""
    rngs = [np.random.default_rng([seed, pair]) for pair in range(pairs)]
    return core.sample_initial_state(rngs)


class Recorder:
    """Contact score, foot skating and the pelvis path of the primitives a row generates."""

    def __init__(self, core: GammaReachCore, start: GammaReachState, horizon: int) -> None:
        self.body, self.feet_ids = core.generator.body, foot_vertex_ids()
        self.contact: list[torch.Tensor] = []
        self.skating: list[torch.Tensor] = []
        self.paths = torch.full((start.num_bodies, horizon + 1, 2), float("nan"))  # pelvis after every primitive
        self.paths[:, 0] = start.seed.joints[:, -1, PELVIS, :2]

    def add(self, step: int, result: GammaStepResult, rows: torch.Tensor, every: int = 1) -> None:
        """The primitives of `step`; every `every`-th body's path goes to path `rows`."""
        primitive = result.primitive
        self.contact.append(result.contact_score)
        feet = self.body.skin(self.body(primitive.transl, primitive.global_orient, primitive.body_pose), self.feet_ids)
        first = 0 if step == 0 else 1  # transitions from the last seed frame on (start pose: 1-frame seed)
        self.skating.append(foot_skating(feet[:, first:], skating_threshold(GAMMA_FPS)).float().flatten())
        self.paths[rows, step + 1] = primitive.joints[::every, -1, PELVIS, :2].cpu()

    def row(self, steps: torch.Tensor, reached: torch.Tensor, distance: torch.Tensor) -> dict:
        return {
            "steps": float(steps[reached].float().mean()) if reached.any() else float("nan"),
            "success rate": float(reached.float().mean()),
            "avg. dist.": float(distance.mean()),
            "contact score": float(torch.cat(self.contact).mean()),
            "FS": float(torch.cat(self.skating).mean()),
            "paths": self.paths.numpy(),
        }


@torch.no_grad()
def run_clones(core: GammaReachCore, start: GammaReachState, controller: Controller, clones: int) -> dict:
    """The paper's protocol: `clones` copies of every pair move together until one reaches the goal."""
    pairs, horizon = start.num_bodies, core.config.max_primitives
    state = start.repeat(clones)  # clones of a pair are adjacent rows
    recorder = Recorder(core, start, horizon)
    steps, reached, distance = torch.zeros(pairs, dtype=torch.long), torch.zeros(pairs, dtype=torch.bool), torch.zeros(pairs)
    live = torch.arange(pairs)
    for step in tqdm(range(horizon), desc="primitives", leave=False):
        state, result = core.step(state, controller(core, state))
        recorder.add(step, result, live, every=clones)
        arrived = result.reached.reshape(len(live), clones).any(dim=1).cpu()
        over = arrived | (step == horizon - 1)
        ended = live[over]
        steps[ended], reached[ended] = step + 1, arrived[over]
        distance[ended] = result.distance.reshape(len(live), clones).mean(dim=1).cpu()[over]
        if over.all():
            break
        keep = (~over).repeat_interleave(clones)
        state, live = state.index(keep.to(state.steps.device)), live[~over]
    return recorder.row(steps, reached, distance)


@torch.no_grad()
def run_search(core: GammaReachCore, start: GammaReachState, proposal: Controller, settings: SearchSettings) -> dict:
    """One tree search per pair; the chosen branches replayed for contact score, FS and paths."""
    found = beam_search(core, start, proposal, settings)
    recorder = Recorder(core, start, core.config.max_primitives)
    state, live = start, torch.arange(start.num_bodies)
    for level in range(found.latents.shape[1]):
        state, result = core.step(state, found.latents[live, level])
        recorder.add(level, result, live)
        going = found.length[live] > level + 1
        state, live = state.index(going.to(state.steps.device)), live[going]
    return recorder.row(found.length, found.reached, found.spread)


def policy_label(path: Path) -> str:
    """ppo_gammareach_alpha10_paper.zip -> "policy(10)"; another reward is named: "policy(10), release reward"."""
    alpha, _, reward = path.stem.removeprefix("ppo_gammareach_alpha").partition("_")
    return f"policy({alpha})" + ("" if reward == "paper" else f", {reward} reward")


BF16_CHECK = (20, 8)
"""Pairs and clones of the bf16 check (the networks run ~10x slower in bf16 on CPUs without bf16 units)."""


def timed_rows(runs: dict[str, Callable[[], dict]]) -> tuple[dict[str, dict], dict[str, float]]:
    rows, seconds = {}, {}
    for name, run in runs.items():
        tick = time.perf_counter()
        rows[name] = run()
        seconds[name] = time.perf_counter() - tick
        print(f"{name}: success {rows[name]['success rate']:.2f} in {seconds[name]:.0f} s")
    return rows, seconds


def table(rows: dict[str, dict], seconds: dict[str, float], paper: dict[str, tuple] | None = None) -> list[str]:
    lines = ["| controller | steps ↓ | success rate ↑ | avg. dist. ↓ | contact score ↑ | FS ↓ | seconds |",
             "|---|---|---|---|---|---|---|"]  # fmt: skip
    for name, row in rows.items():
        steps = "–" if np.isnan(row["steps"]) else f"{row['steps']:.1f}"  # no pair reached its goal
        lines.append(f"| {name} | {steps} | {row['success rate']:.2f} | {row['avg. dist.']:.2f} | "
                     f"{row['contact score']:.3f} | {row['FS']:.3f} | {seconds[name]:.0f} |")  # fmt: skip
    for name, (steps, success, distance, score) in (paper or {}).items():
        lines.append(f"| {name} | {steps} | {success} | {distance} | {score} | | |")
    return lines


def main(pairs: int = 100, clones: int = 32, seed: int = 0, quick: bool = False, bf16: bool = False,
         precision: str = "auto", output: str | None = None) -> int:  # fmt: skip
    """`precision`: the prior's networks for the main table; `output`: the results' file stem (default
    gamma_control[_quick])."""
    if quick:
        pairs, clones = 20, 8
    began = time.perf_counter()
    core = GammaReachCore(GammaReachConfig(precision=precision))
    start = fixed_pairs(core, pairs, seed)
    runs: dict[str, Callable[[], dict]] = {"random z": lambda: run_clones(core, start, RandomLatent(seed), clones)}
    if G_CVAE_WEIGHTS.exists():
        goal_core = GammaReachCore(GammaReachConfig(), goal_cvae_generator(base=core.generator))
        runs["g-CVAE"] = lambda: run_clones(goal_core, start, RandomLatent(seed), clones)
    policies = {policy_label(path): path for path in sorted(WEIGHTS_DIR.glob("ppo_gammareach_*.zip"))}
    for label, path in policies.items():
        runs[label] = lambda path=path: run_clones(core, start, PolicyLatent(path, seed=seed), clones)
    searchers = {label: path for label, path in policies.items() if label in ("policy(10)", "policy(1)")}
    costs = (("", SearchCost()), (", distance cost", SearchCost.distance_only()))
    for (label, path), keep, (cost_name, cost) in itertools.product(searchers.items(), (1, 4), costs):
        runs[f"{label} & top{keep}{cost_name}"] = lambda path=path, keep=keep, cost=cost: run_search(
            core, start, PolicyLatent(path, seed=seed), SearchSettings(keep=keep, cost=cost))  # fmt: skip
    searcher = searchers.get("policy(10)")
    runs["random z & top4"] = lambda: run_search(core, start, RandomLatent(seed), SearchSettings(keep=4))
    rows, seconds = timed_rows(runs)
    stem = output or "gamma_control" + ("_quick" if quick else "")
    lines = [
        f"# GAMMA goal reaching ({'quick: ' if quick else ''}{pairs} body-goal pairs × {clones} clones, up to 60 primitives)",
        "",
        "The paper's protocol (Sec. 4.2): a pair succeeds when any clone reaches the goal (0.75 m), and ends there. "
        "Steps: primitives to the first arrival (successful pairs); avg. dist.: pelvis-goal ground distance (m) of all "
        "clones when the pair ends (search rows: of the kept nodes); contact score: Eq. 11 per primitive; FS: WANDR's, "
        "40 fps, 0.2 m/s. Search rows: 16 roots, 4 children per node, top-K kept, the release's node cost (contact + "
        "0.1 × orientation + 0.1 × distance) or distance alone (`SearchCost.distance_only`). Policies sample their latents.",
        "", *table(rows, seconds, PAPER_ROWS),
    ]  # fmt: skip
    lines += ["", f"The prior's networks ran in {core.generator.precision} (`precision=\"auto\"`: bf16 only on a CPU with "
              "native bf16, `motion_envs.precision`)."]  # fmt: skip
    if (bf16 or core.generator.precision == "bfloat16") and searcher is not None:
        check_pairs, check_clones = BF16_CHECK
        subset = start.index(torch.arange(min(check_pairs, pairs)))
        cores = {name: GammaReachCore(GammaReachConfig(precision=name)) for name in ("float32", "bfloat16")}
        checks, check_seconds = timed_rows({
            f"policy(10), {name} prior": lambda name=name: run_clones(cores[name], subset, PolicyLatent(searcher, seed=seed), check_clones)
            for name in cores
        })  # fmt: skip
        lines += ["", f"bf16 check: the first {subset.num_bodies} pairs × {check_clones} clones, the prior's networks in fp32 "
                  "and in bf16 (`GammaReachConfig.precision`), same policy and seed.", "", *table(checks, check_seconds)]  # fmt: skip
    lines += ["", machine_line(), f"Command: `motion-envs bench gamma{' --quick' if quick else ''}{' --bf16' if bf16 else ''}"
              f"{'' if precision == 'auto' else ' --precision ' + precision}{' --output ' + output if output else ''}`; "
              f"{time.perf_counter() - began:.0f} s in all.", "", f"![paths]({stem}.png)", ""]  # fmt: skip
    text = "\n".join(lines)
    print(text)
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic_write(RESULTS / f"{stem}.md", lambda file: file.write(text.encode()))
    figure, axes = grid_of_axes(len(rows))
    goals = start.goal[:, :2].numpy()
    for axis, (name, row) in zip(axes, rows.items()):
        top_down(axis, row["paths"], goals, title=f"{name}: {row['success rate']:.2f}", extent=10.0)  # NaN after a pair ends
    save(figure, RESULTS / f"{stem}.png", dpi=80)
    return 0
