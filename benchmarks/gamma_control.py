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
* FS: WANDR's foot skating at 40 fps with its 0.2 m/s threshold;
* contact-aware FS: the loaded sole point slides faster than 0.2 m/s while on
  the floor (`metrics.loaded_foot_skating`; the clean data 0.08-0.16);
* head low: the share of generated frames whose head is lower than 1.38 m
  (`rewards.UPRIGHT_HEAD`: a stooping or crouching body; the clean data's
  walking frames 15% in the test split, 27% in training).

Tree-search rows ("& topK", `motion_envs.wrappers.tree_search`) run one
search per pair (16 roots, 4 children per node, K kept); their "clones" are
the K kept nodes: avg. dist. is the kept nodes' mean when the search ends,
and contact score and FS are those of the chosen branch, replayed.

Rows: random z, the g-CVAE (`baselines.g_cvae`, z ~ N(0, I)), each shipped
GammaReach policy (sampled latents, as the paper), the α = 10 and α = 1
paper-reward policies with top-1 and top-4 search (the release's node cost
and distance alone), random z with top-4 search, and with `--bf16` (or when the CPU has native bf16) the
α = 10 policy with the prior's networks in bf16 (`GammaGenerator.set_precision`).
Per body: GAMMA's any-of-32 hides single bodies that fail, so every policy
row also runs each clone on its own (`run_bodies`: no clone stops another;
each goes on until it reaches the goal or 60 primitives) and a second table
gives per-body success by the goal's direction from the start body's facing
(`DIRECTIONS`: ahead < 60°, side, behind > 120°; side goals also left and right) and by its distance
(`DISTANCES`). `--quick` (the README's main job) runs fewer pairs and clones. Writes
`benchmarks/results/gamma_control.md` (or `gamma_control_quick.md`) and a
top-down plot of the first clone (or chosen branch) per pair.
"""

from __future__ import annotations

import functools
import itertools
import time
from dataclasses import dataclass
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from agents.controllers import PolicyLatent
from agents.policy_files import read_policy_file
from baselines.g_cvae import G_CVAE_WEIGHTS, goal_cvae_generator
from baselines.latent_controllers import RandomLatent
from benchmarks.fanout import group_seed, run_grouped, spans
from benchmarks.machine import bench_command, machine_line
from motion_envs.plots import grid_of_axes, save, top_down
from motion_envs.atomic import atomic_write
from motion_envs.body.markers import foot_vertex_ids, sole_vertex_ids
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore, GammaReachState, GammaStepResult
from motion_envs.metrics import foot_skating, loaded_foot_skating, skating_threshold
from motion_envs.rewards import UPRIGHT_HEAD, head_drop
from motion_envs.body.canonical_frame import PELVIS
from motion_envs.priors.training import WEIGHTS_DIR
from motion_envs.rewards import facing_direction
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


def fixed_pairs(core: GammaReachCore, pairs: int | range, seed: int) -> GammaReachState:
    """Seeded body-goal pairs: the first `pairs`, or those numbered in a range (pair i is the same either way)."""
    rngs = [np.random.default_rng([seed, pair]) for pair in (range(pairs) if isinstance(pairs, int) else pairs)]
    return core.sample_initial_state(rngs)


class Recorder:
    """Contact score, foot skating (WANDR's and contact-aware), frames with the head low and the pelvis path of the
    primitives a row generates."""

    def __init__(self, core: GammaReachCore, start: GammaReachState, horizon: int) -> None:
        self.body, self.feet_ids, self.sole_ids = core.generator.body, foot_vertex_ids(), sole_vertex_ids()
        self.contact: list[torch.Tensor] = []
        self.skating: list[torch.Tensor] = []
        self.loaded_skating: list[torch.Tensor] = []
        self.stooped: list[tuple[float, int]] = []
        self.paths = torch.full((start.num_bodies, horizon + 1, 2), float("nan"))  # pelvis after every primitive
        self.paths[:, 0] = start.seed.joints[:, -1, PELVIS, :2]

    def add(self, step: int, result: GammaStepResult, rows: torch.Tensor, every: int = 1) -> None:
        """The primitives of `step`; every `every`-th body's path goes to path `rows`."""
        primitive = result.primitive
        self.contact.append(result.contact_score)
        posed = self.body(primitive.transl, primitive.global_orient, primitive.body_pose)
        feet, soles = self.body.skin(posed, self.feet_ids), self.body.skin(posed, self.sole_ids)
        first = 0 if step == 0 else 1  # transitions from the last seed frame on (start pose: 1-frame seed)
        self.skating.append(foot_skating(feet[:, first:], skating_threshold(GAMMA_FPS)).float().flatten())
        self.loaded_skating.append(loaded_foot_skating(soles[:, first:], GAMMA_FPS).float().flatten())
        new, low = primitive.new_frames(), head_drop(primitive.joints, UPRIGHT_HEAD) > 0
        self.stooped.append((float((low & new).sum()), int(new.sum())))
        self.paths[rows, step + 1] = primitive.joints[::every, -1, PELVIS, :2].cpu()

    def row(self, steps: torch.Tensor, reached: torch.Tensor, distance: torch.Tensor) -> dict:
        """The pairs' figures as `summarise` merges them: per pair (steps, reached, distance, paths) and the
        per-primitive contact scores, skating flags and head-low frames as sums and counts."""
        contact, skating, loaded = torch.cat(self.contact), torch.cat(self.skating), torch.cat(self.loaded_skating)
        return {"steps": steps.numpy(), "reached": reached.numpy(), "distance": distance.numpy(), "paths": self.paths.numpy(),
                "contact": (float(contact.sum()), len(contact)), "skating": (float(skating.sum()), len(skating)),
                "loaded skating": (float(loaded.sum()), len(loaded)), "stooped": tuple(map(sum, zip(*self.stooped)))}  # fmt: skip


def summarise(parts: list[dict]) -> dict:
    """A row's figures from its shards' `Recorder.row`s, in pair order."""
    steps, reached = np.concatenate([part["steps"] for part in parts]), np.concatenate([part["reached"] for part in parts])
    contact, skating, loaded, stooped = (tuple(map(sum, zip(*(part[key] for part in parts))))
                                         for key in ("contact", "skating", "loaded skating", "stooped"))  # fmt: skip
    return {
        "steps": float(steps[reached].mean()) if reached.any() else float("nan"),
        "success rate": float(reached.mean()),
        "avg. dist.": float(np.concatenate([part["distance"] for part in parts]).mean()),
        "contact score": contact[0] / contact[1],
        "FS": skating[0] / skating[1],
        "contact-aware FS": loaded[0] / loaded[1],
        "head low": stooped[0] / stooped[1],
        "paths": np.concatenate([part["paths"] for part in parts]),
        "seconds": sum(part.get("seconds", 0.0) for part in parts),
        **({"per body": np.concatenate([part["per body"] for part in parts])} if "per body" in parts[0] else {}),
    }


@torch.no_grad()
def run_clones(core: GammaReachCore, start: GammaReachState, controller: Controller, clones: int,
               recorder_type: type[Recorder] = Recorder) -> dict:  # fmt: skip
    """The paper's protocol: `clones` copies of every pair move together until one reaches the goal."""
    pairs, horizon = start.num_bodies, core.config.max_primitives
    state = start.repeat(clones)  # clones of a pair are adjacent rows
    recorder = recorder_type(core, start, horizon)
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
def run_search(core: GammaReachCore, start: GammaReachState, proposal: Controller, settings: SearchSettings,
               recorder_type: type[Recorder] = Recorder) -> dict:  # fmt: skip
    """One tree search per pair; the chosen branches replayed for contact score, FS and paths."""
    found = beam_search(core, start, proposal, settings)
    recorder = recorder_type(core, start, core.config.max_primitives)
    state, live = start, torch.arange(start.num_bodies)
    for level in range(found.latents.shape[1]):
        state, result = core.step(state, found.latents[live, level])
        recorder.add(level, result, live)
        going = found.length[live] > level + 1
        state, live = state.index(going.to(state.steps.device)), live[going]
    return recorder.row(found.length, found.reached, found.spread)


def run_bodies(core: GammaReachCore, start: GammaReachState, controller: Controller, clones: int) -> np.ndarray:
    """Per-body success: `clones` copies of every pair, each on its own until it reaches the goal or the horizon
    (`run_clones` with every copy a pair of one clone, so no clone's arrival stops another). Returns (pairs, clones)
    bool."""
    return run_clones(core, start.repeat(clones), controller, 1)["reached"].reshape(start.num_bodies, clones)


DIRECTIONS = {"ahead (< 60°)": (0.0, 60.0), "side (60–120°)": (60.0, 120.0), "behind (> 120°)": (120.0, 180.01)}
"""Goal direction bins: the angle between the start body's facing and the ground direction to its goal."""
DISTANCES = {"< 4 m": (0.0, 4.0), "4–8 m": (4.0, 8.0), "≥ 8 m": (8.0, float("inf"))}
"""Goal distance bins: pelvis to goal on the ground at the start."""


def goal_bearings(start: GammaReachState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pairs,) the angle (degrees, 0–180) between each start body's facing and the ground direction to its goal,
    (pairs,) the goal's ground distance from the pelvis (m) and (pairs,) bool whether the goal is on the body's left."""
    joints = start.seed.joints[:, -1]
    to_goal = start.goal[:, :2] - joints[:, PELVIS, :2]
    distance = to_goal.norm(dim=-1)
    facing = facing_direction(joints)
    cosine = (facing * to_goal / distance[:, None].clamp_min(1e-6)).sum(-1).clamp(-1.0, 1.0)
    left = facing[:, 0] * to_goal[:, 1] - facing[:, 1] * to_goal[:, 0] > 0
    return torch.rad2deg(torch.arccos(cosine)).cpu().numpy(), distance.cpu().numpy(), left.cpu().numpy()


def per_body_table(rows: dict[str, dict], start: GammaReachState) -> list[str]:
    """Per-body success of the rows that ran `run_bodies`, by goal direction (side goals also by side: the prior
    turns left more readily, `gamma_turns.md`) and distance (pairs in each bin)."""
    angle, distance, left = goal_bearings(start)
    directions = {name: (angle >= low) & (angle < high) for name, (low, high) in DIRECTIONS.items()}
    side = directions["side (60–120°)"]
    bins = {**directions, "side, left": side & left, "side, right": side & ~left,
            **{name: (distance >= low) & (distance < high) for name, (low, high) in DISTANCES.items()}}  # fmt: skip
    header = " | ".join(f"{name} ({int(mask.sum())})" for name, mask in bins.items())
    lines = [f"| controller | any clone (paper's) | per body | {header} |", "|---" * (len(bins) + 3) + "|"]
    for name, row in rows.items():
        if "per body" not in row:
            continue
        bodies = row["per body"]
        cells = " | ".join(f"{bodies[mask].mean():.2f}" if mask.any() else "–" for mask in bins.values())
        lines.append(f"| {name} | {row['success rate']:.2f} | {bodies.mean():.2f} | {cells} |")
    return lines


CLONED_CENTRE = ", KL to N(cloned, I)"
"""Label suffix of policies trained with `--kl-mean cloned` (`*_cloned.zip`)."""
CALIBRATED_PRIOR = ", heading-calibrated prior"
"""Label suffix of policies trained on the prior with its heading calibration (`--env-option heading_calibration=true`)."""
MIRRORED_RIGHT_GOALS = ", trained with right goals mirrored"
"""Label suffix of policies trained with `--env-option mirror_right_goals=true`."""


def policy_label(path: Path) -> str:
    """A GammaReach PPO policy's row label from what its file holds (α, the regulariser's centre, the reward it was
    trained on), whatever its name: "policy(10)"; another reward is named: "policy(10), release reward"; a
    regulariser centred on the cloned policy: "policy(10), KL to N(cloned, I)"."""
    policy = read_policy_file(path)
    reward = (policy.trained_for.env_kwargs if policy.trained_for else {}).get("reward", "paper")
    return (f"policy({policy.alpha:g})" + ("" if reward == "paper" else f", {reward} reward")
            + (CLONED_CENTRE if policy.kl_mean == "cloned" else "")
            + (CALIBRATED_PRIOR if trained_with(path, "heading_calibration") else "")
            + (MIRRORED_RIGHT_GOALS if trained_with(path, "mirror_right_goals") else ""))  # fmt: skip


def trained_with(path: Path, option: str) -> bool:
    """Whether the policy in `path` was trained with the boolean GammaReach env option `option` on."""
    trained = read_policy_file(path).trained_for
    return bool(trained and trained.env_kwargs.get(option))


BF16_CHECK = (20, 8)
"""Pairs and clones of the bf16 check (the networks run ~10x slower in bf16 on CPUs without bf16 units)."""


PAIRS_PER_TASK = 25
"""Pairs per task: every row runs as groups of this many pairs (× clones), one after another in this process
or as Ray tasks (`benchmarks.fanout`), each group's latents seeded by the group, so a row's numbers do not
depend on where it ran."""
CONTROLLERS = ("random", "g-cvae", "policy")


@dataclass(frozen=True)
class GammaRow:
    """A table row as a task rebuilds it. controller: "random" (z ~ N(0, I)), "g-cvae" (the same through the
    goal-conditioned CVAE) or "policy" (`PolicyLatent(policy)`); keep: None for the clones protocol, K for
    a tree search keeping K nodes with `cost` ("release" or "distance")."""

    controller: str
    policy: Path | None = None
    keep: int | None = None
    cost: str = "release"
    clones: int = 32
    precision: str = "auto"
    weights_dir: str | None = None
    """The prior's folder (None: the shipped one)."""
    heading_calibration: bool = False
    """The prior's heading calibration on (`GammaReachConfig.heading_calibration`): as the policy was trained."""
    mirror_right_goals: bool = False
    """Bodies whose goal starts on their right live in their mirror image (`GammaReachConfig.mirror_right_goals`)."""

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {CONTROLLERS}, got {self.controller!r}")


@functools.lru_cache(maxsize=4)
def cached_core(precision: str, goal_cvae: bool, weights_dir: str | None = None, heading_calibration: bool = False,
                mirror_right_goals: bool = False) -> GammaReachCore:  # fmt: skip
    """One env core per process and setting (cores are stateless between rollouts; loading the prior is not free)."""
    core = GammaReachCore(GammaReachConfig(precision=precision, weights_dir=weights_dir, heading_calibration=heading_calibration,
                                           mirror_right_goals=mirror_right_goals))  # fmt: skip
    if not goal_cvae:
        return core
    return GammaReachCore(GammaReachConfig(weights_dir=weights_dir), goal_cvae_generator(g_cvae_weights(weights_dir), core.generator))


def g_cvae_weights(weights_dir: str | None) -> Path:
    """The g-CVAE baseline's weights in `weights_dir` (None: the shipped ones)."""
    return G_CVAE_WEIGHTS if weights_dir is None else Path(weights_dir) / G_CVAE_WEIGHTS.name


def run_shard(row: GammaRow, first: int, last: int, seed: int) -> dict:
    """Pairs [first, last) of the row (`Recorder.row`'s figures, plus the task's seconds)."""
    began = time.perf_counter()
    core = cached_core(row.precision, row.controller == "g-cvae", row.weights_dir, row.heading_calibration, row.mirror_right_goals)
    start = fixed_pairs(core, range(first, last), seed)
    shard_seed = group_seed(seed, first)
    proposal = PolicyLatent(row.policy, seed=shard_seed) if row.controller == "policy" else RandomLatent(shard_seed)
    if row.keep is None:
        result = run_clones(core, start, proposal, row.clones)
        if row.controller == "policy":
            bodies = PolicyLatent(row.policy, seed=shard_seed + 1)
            result["per body"] = run_bodies(core, start, bodies, row.clones)
    else:
        cost = SearchCost() if row.cost == "release" else SearchCost.distance_only()
        result = run_search(core, start, proposal, SearchSettings(keep=row.keep, cost=cost))
    return {**result, "seconds": time.perf_counter() - began}


def run_rows(rows: dict[str, GammaRow], pairs: int, seed: int, ray_address: str | None = None) -> dict[str, dict]:
    """Every row's figures (`summarise`), its pair groups run in this process or over Ray."""
    tasks = [(label, (row, first, last, seed)) for label, row in rows.items() for first, last in spans(pairs, PAIRS_PER_TASK)]
    merged = {label: summarise(parts) for label, parts in run_grouped(run_shard, tasks, ray_address, "gamma pair groups").items()}
    for label, row in merged.items():
        print(f"{label}: success {row['success rate']:.2f} in {row['seconds']:.0f} s")
    return merged


def table(rows: dict[str, dict], paper: dict[str, tuple] | None = None) -> list[str]:
    lines = ["| controller | steps ↓ | success rate ↑ | avg. dist. ↓ | contact score ↑ | FS ↓ | contact-aware FS ↓ | head low ↓ | seconds |",
             "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for name, row in rows.items():
        steps = "–" if np.isnan(row["steps"]) else f"{row['steps']:.1f}"  # no pair reached its goal
        lines.append(f"| {name} | {steps} | {row['success rate']:.2f} | {row['avg. dist.']:.2f} | "
                     f"{row['contact score']:.3f} | {row['FS']:.3f} | {row['contact-aware FS']:.3f} | {row['head low']:.0%} | "
                     f"{row['seconds']:.0f} |")  # fmt: skip
    for name, (steps, success, distance, score) in (paper or {}).items():
        lines.append(f"| {name} | {steps} | {success} | {distance} | {score} | | | | |")
    return lines


def main(pairs: int = 100, clones: int = 32, seed: int = 0, quick: bool = False, bf16: bool = False,
         precision: str = "auto", output: str | None = None, ray_address: str | None = None,
         policies: list[Path] | None = None, weights_dir: Path | None = None, mirror_right_goals: bool = False) -> int:  # fmt: skip
    """`precision`: the prior's networks for the main table; `output`: the results' file stem (default
    gamma_control[_quick]); `ray_address`: fan the pair groups out over Ray ("local" or a cluster's address);
    `policies`: GammaReach policy files to evaluate in place of the shipped ones (e.g. one trained on RLlib);
    `weights_dir`: a folder holding a GAMMA prior and its policies, used for both (default: the shipped ones);
    `mirror_right_goals`: every row but the g-CVAE's (whose goal features are not mirrored) with bodies whose goal
    starts on their right living in their mirror image (`GammaReachConfig.mirror_right_goals`; a policy trained
    with it runs so in any case, as one trained with the heading calibration runs on the calibrated prior)."""
    command = bench_command("gamma", {"quick": quick, "pairs": pairs, "clones": clones, "seed": seed, "bf16": bf16,
                                      "precision": precision, "output": output, "ray": ray_address,
                                      "weights-dir": weights_dir, "mirror-right-goals": mirror_right_goals,
                                      "policies": policies},
                            {"pairs": 100, "clones": 32, "seed": 0, "precision": "auto"})  # fmt: skip
    if quick:
        pairs, clones = 20, 8
    began = time.perf_counter()
    folder = None if weights_dir is None else str(weights_dir)
    core = cached_core(precision, False, folder)
    start = fixed_pairs(core, pairs, seed)
    precision = core.generator.precision  # "auto" resolved here: every task, on whatever CPU, runs the same networks
    row = functools.partial(GammaRow, precision=precision, weights_dir=folder, mirror_right_goals=mirror_right_goals)
    runs: dict[str, GammaRow] = {"random z": row("random", clones=clones)}
    if g_cvae_weights(folder).exists():
        runs["g-CVAE"] = row("g-cvae", clones=clones, mirror_right_goals=False)
    shipped = sorted(Path(weights_dir or WEIGHTS_DIR).glob("ppo_gammareach_*.zip"))
    evaluated = ({policy_label(path): path for path in shipped} if policies is None
                 else {f"{policy_label(path)} ({path})": path for path in policies})  # fmt: skip
    options = {path: {"heading_calibration": trained_with(path, "heading_calibration"),  # the env the policy knows
                      "mirror_right_goals": mirror_right_goals or trained_with(path, "mirror_right_goals")}
               for path in evaluated.values()}  # fmt: skip
    for label, path in evaluated.items():
        runs[label] = row("policy", path, clones=clones, **options[path])
    searched = ("policy(10)", "policy(1)", "policy(10)" + CLONED_CENTRE)
    searchers = {label: path for label, path in evaluated.items() if label.removesuffix(MIRRORED_RIGHT_GOALS).removesuffix(CALIBRATED_PRIOR) in searched}
    costs = (("", "release"), (", distance cost", "distance"))
    for (label, path), keep, (cost_name, cost) in itertools.product(searchers.items(), (1, 4), costs):
        runs[f"{label} & top{keep}{cost_name}"] = row("policy", path, keep=keep, cost=cost, **options[path])
    searcher = searchers.get("policy(10)")
    runs["random z & top4"] = row("random", keep=4)
    rows = run_rows(runs, pairs, seed, ray_address)
    stem = output or "gamma_control" + ("_mirror" if mirror_right_goals else "") + ("_quick" if quick else "")
    lines = [
        f"# GAMMA goal reaching ({'quick: ' if quick else ''}{pairs} body-goal pairs × {clones} clones, up to 60 primitives)",
        "",
        "The paper's protocol (Sec. 4.2): a pair succeeds when any clone reaches the goal (0.75 m), and ends there. "
        "Steps: primitives to the first arrival (successful pairs); avg. dist.: pelvis-goal ground distance (m) of all "
        "clones when the pair ends (search rows: of the kept nodes); contact score: Eq. 11 per primitive; FS: WANDR's, "
        "40 fps, 0.2 m/s; contact-aware FS: the loaded sole point slides while on the floor (`metrics.loaded_foot_skating`; "
        "the clean data 0.08-0.16); head low: share of generated frames with the head below 1.38 m (`rewards.UPRIGHT_HEAD`; the "
        "clean data's walking 15% test, 27% training). Search rows: 16 roots, 4 children per node, top-K kept, the release's node cost (contact + "
        "0.1 × orientation + 0.1 × distance) or distance alone (`SearchCost.distance_only`). Policies sample their latents. "
        "Bodies as the env makes them: the floor and foot rules on (`ground_feet`, `lock_feet`; `gamma_feet.md` compares). "
        f"Pairs run in groups of {PAIRS_PER_TASK} (`benchmarks.fanout`), "
        + ("in this process" if ray_address is None else f"as Ray tasks ({ray_address})") + "; seconds: a row's groups, summed.",
        *(["", "Bodies whose goal starts on their right live the episode in their mirror image "
            "(`GammaReachConfig.mirror_right_goals`, ours): every row but the g-CVAE's (its goal features are not "
            "mirrored)."] if mirror_right_goals else []),
        "", *table(rows, PAPER_ROWS), "",
        f"Per body: each policy row again with its {clones} clones of every pair on their own (none stops another), "
        "success by the goal's direction from the start body's facing and by its distance (pairs per bin in brackets); "
        "the first column is the table's any-of-clones figure. A policy row's seconds include this run.",
        "", *per_body_table(rows, start),
    ]  # fmt: skip
    lines += ["", f"The prior's networks ran in {core.generator.precision} (`precision=\"auto\"`: bf16 only on a CPU with "
              f"native bf16, `motion_envs.precision`). Prior: {weights_dir or 'the shipped one'}"
              f"{', heading-calibrated in the rows that say so' if any(CALIBRATED_PRIOR in label for label in runs) else ''}; "
              f"policies: {'the files named in the rows' if policies else weights_dir or 'the shipped ones'}."]  # fmt: skip
    if (bf16 or core.generator.precision == "bfloat16") and searcher is not None:
        check_pairs, check_clones = BF16_CHECK
        subset = start.index(torch.arange(min(check_pairs, pairs)))
        cores = {name: GammaReachCore(GammaReachConfig(precision=name, weights_dir=folder)) for name in ("float32", "bfloat16")}
        checks = {}
        for name, check_core in cores.items():
            tick = time.perf_counter()
            part = run_clones(check_core, subset, PolicyLatent(searcher, seed=seed), check_clones)
            checks[f"policy(10), {name} prior"] = summarise([{**part, "seconds": time.perf_counter() - tick}])
        lines += ["", f"bf16 check: the first {subset.num_bodies} pairs × {check_clones} clones, the prior's networks in fp32 "
                  "and in bf16 (`GammaReachConfig.precision`), same policy and seed.", "", *table(checks)]  # fmt: skip
    lines += ["", machine_line(), f"Command: `{command}`; {time.perf_counter() - began:.0f} s in all.", "",
              f"![paths]({stem}.png)", ""]  # fmt: skip
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
