"""CLOPS's scene matrix (`motion-envs bench clops`): the paper's protocol (Sec. 4.1-4.2) on our room families.

Every shipped ClopsNav policy (`priors/weights/dqn_clopsnav_<family>.zip`,
trained on one layout family, or on all five mixed: `mixed`) is evaluated on the held-out test seeds of
every family (`TEST_SEEDS`: one episode per seed, `episodes` seeds per
family, the same starts and goals for every row). Per row and family:

* SR: % of episodes that reached a state with the goal within
  `success_distance` (1 m) on the ground and in view (any goal pixel);
* Col: % of actions (about 1 s of motion each) during which any collision
  sphere penetrated the scene by more than 2 cm;
* FS: % of frames whose lowest foot vertex slid more than 0.66 cm (WANDR's
  measure, the same authors');
* how episodes end: % found, left the room, fallen, out of time (15 s).

Rows beside the DQN policies: uniformly random actions; the non-visual
GAMMA navigator told the goal (EgoGen-like, `baselines.gamma_navigator`);
the known-goal DQN policy (`dqn_clopsnav_<family>_known_goal.zip`) and the
goal-memory one (`dqn_clopsnav_<family>_memory.zip`, ours) where shipped.
The paper's numbers go beside (its Table 1 matrix on Replica S1-S5 and its
Table 2). Writes `benchmarks/results/clops_matrix.md`, and
`clops_matrix.png`: the egocentric frames of one episode (semantic colours,
goal pixels red) over its top-down path, and the SR matrix.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from agents.policy_files import OBSERVATION_FLAGS, read_policy_file
from agents.train_dqn import OBSERVATION_OPTIONS
from benchmarks.fanout import group_seed, run_grouped, spans
from benchmarks.machine import bench_command, machine_line
from benchmarks.sections import replace_section
from motion_envs.atomic import atomic_write
from motion_envs.envs.clops_nav import ClopsNavConfig, ClopsNavCore, ClopsNavState
from motion_envs.plots import plt, save, top_down
from motion_envs.priors.training import WEIGHTS_DIR
from motion_envs.priors.wandr_features import PELVIS
from motion_envs.scenes.layouts import FAMILIES, TEST_SEEDS

RESULTS = Path(__file__).resolve().parent / "results"
PAPER_TABLE2 = {  # SR %, Col %, FS %
    "EgoGen, known goal (paper)": (48, 31, 40),
    "CLOPS, vision only (paper)": (68, 27, 27),
    "CLOPS + known goal (paper)": (100, 36, 26),
}
PAPER_SR_MATRIX = [[93, 84, 96, 78, 85], [78, 87, 93, 73, 78], [81, 72, 84, 72, 72], [90, 84, 94, 78, 73], [87, 78, 90, 66, 68]]
PAPER_COL_MATRIX = [[26, 16, 35, 42, 40], [42, 10, 35, 43, 43], [40, 20, 19, 45, 38], [39, 20, 35, 38, 38], [39, 17, 36, 40, 27]]
GAMMA_POLICY = WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip"
OBSERVATIONS = {  # policy-name suffix -> (row-label suffix, e.g. " + known goal", the env's observation options)
    suffix: ("".join(f" + {name.replace('_', ' ')}" for name in options), options) for suffix, options in OBSERVATION_OPTIONS.items()
}

Controller = Callable[[ClopsNavCore, ClopsNavState], torch.Tensor]


@dataclass(frozen=True)
class Scores:
    """One row on one family: SR, Col, FS, episodes ended by a fall (`ClopsNavConfig.fall_height`), by leaving the
    room and by the 15-s limit (the last three NaN for the GAMMA navigator, whose bodies are GAMMA's and whose
    episodes end otherwise) in %, and the pelvis paths (N, T, 2) and views of episode 0."""

    success: float
    collision: float
    skating: float
    fallen: float
    left: float
    timed_out: float
    seconds: float
    paths: np.ndarray
    views: list[np.ndarray]


def random_actions(seed: int) -> Controller:
    generator = torch.Generator().manual_seed(seed)

    def act(core: ClopsNavCore, state: ClopsNavState) -> torch.Tensor:
        return torch.randint(core.num_actions, (state.num_bodies,), generator=generator)

    return act


def policy_actions(path: Path) -> Controller:
    from agents.double_dqn import PrioritizedDoubleDQN

    model = PrioritizedDoubleDQN.load(path, device="cpu")

    def act(core: ClopsNavCore, state: ClopsNavState) -> torch.Tensor:
        actions, _ = model.predict(core.observe(state), deterministic=True)
        return torch.as_tensor(actions)

    return act


def episodes(core: ClopsNavCore, count: int | range) -> ClopsNavState:
    """The family's first `count` test seeds, or those numbered in a range, one episode each (episode seed = scene
    seed; episode i is the same either way)."""
    seeds = list(TEST_SEEDS)[:count] if isinstance(count, int) else [TEST_SEEDS[index] for index in count]
    return core.sample_initial_state([np.random.default_rng(seed) for seed in seeds], {"scene_seed": seeds})


EPISODES_PER_TASK = 25
"""Episodes per task: a row runs each family as groups of this many episodes, one after another in this process
or as Ray tasks (`benchmarks.fanout`); random actions are seeded per group, so the numbers do not depend on where
a group ran."""
CONTROLLERS = ("random", "gamma", "dqn")


@dataclass(frozen=True)
class ClopsRow:
    """A row as a task rebuilds it: "random" actions, the "gamma" navigator, or a "dqn" policy; the env's
    observation options (names of `OBSERVATION_FLAGS` set true)."""

    controller: str
    policy: Path | None = None
    options: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {CONTROLLERS}, got {self.controller!r}")


@functools.lru_cache(maxsize=8)
def cached_core(family: str, options: tuple[str, ...]) -> ClopsNavCore:
    """One test-split core per process, family and observation (its rooms are built once)."""
    return ClopsNavCore(ClopsNavConfig(family=family, split="test", **{name: True for name in options}))


def run_shard(row: ClopsRow, family: str, first: int, last: int, seed: int) -> dict:
    """Episodes [first, last) of `family` under the row's controller: `run`'s (or `gamma_row`'s) counts."""
    core = cached_core(family, row.options)
    state = episodes(core, range(first, last))
    if row.controller == "gamma":
        return gamma_row(core, state)
    controller = random_actions(group_seed(seed, first)) if row.controller == "random" else policy_actions(row.policy)
    return run(core, state, controller)


def scores_of(parts: list[dict]) -> Scores:
    """A row's scores on one family from its groups in order (paths and views: the first group's)."""
    found = np.concatenate([part["found"] for part in parts])
    collided, skated = (tuple(map(sum, zip(*(part[key] for part in parts)))) for key in ("collided", "skated"))
    fallen, left, timed_out = (np.concatenate([part[key] for part in parts]) for key in ("fallen", "left", "timed out"))
    return Scores(100 * float(found.mean()), 100 * collided[0] / max(collided[1], 1), 100 * skated[0] / max(skated[1], 1),
                  100 * float(fallen.mean()), 100 * float(left.mean()), 100 * float(timed_out.mean()),
                  float(np.concatenate([part["seconds"] for part in parts]).mean()),
                  parts[0]["paths"], parts[0]["views"])  # fmt: skip


def run(core: ClopsNavCore, state: ClopsNavState, controller: Controller) -> dict:
    """Step every episode to its end (found, left the room, fallen or 15 s); the core steps every body until the
    last ends, and what a body does after its own end is not counted (one that left the room or fell could walk
    on to the goal). Returns the counts `scores_of` merges: found, fallen, left (the room) and timed out (N,) each,
    (collided, actions) and (skated, frames) sums, seconds (N,), the pelvis paths (N, T, 2) and episode 0's views."""
    count = state.num_bodies
    alive = torch.ones(count, dtype=torch.bool)
    actions, collided = torch.zeros(count), torch.zeros(count)
    found, fallen, left = (torch.zeros(count, dtype=torch.bool) for _ in range(3))
    skated, frames = torch.zeros(count), torch.zeros(count)
    paths, views = [state.joints[:, PELVIS, :2].numpy()], [state.view[0].numpy()]
    while alive.any():
        state, result = core.step(state, controller(core, state))
        actions += alive.float()
        collided += (result.collided & alive).float()
        found |= state.found & alive
        fallen |= result.fallen & alive
        left |= result.left_room & alive
        skated, frames = (torch.where(alive, now.float(), then) for now, then in ((state.skated, skated), (state.frame, frames)))
        paths.append(np.where(alive[:, None].numpy(), state.joints[:, PELVIS, :2].numpy(), np.nan))
        if alive[0]:
            views.append(state.view[0].numpy())
        alive &= ~(result.terminated | result.truncated)
    return {"found": found.numpy(), "fallen": fallen.numpy(), "left": left.numpy(), "timed out": (~(found | fallen | left)).numpy(),
            "collided": (float(collided.sum()), float(actions.sum())),
            "skated": (float(skated.sum()), float(frames.sum())), "seconds": frames.numpy() / 30,
            "paths": np.stack(paths, 1), "views": views}  # fmt: skip


def gamma_row(core: ClopsNavCore, state: ClopsNavState) -> dict:
    """The GAMMA navigator's counts, as `run`'s (collisions per second of motion; no views)."""
    from agents.ppo_kl import PPOKL
    from baselines.gamma_navigator import gamma_navigate

    stats = gamma_navigate(core, state, PPOKL.load(GAMMA_POLICY, device="cpu"))
    unknown = np.full(len(stats.found), np.nan)
    return {"found": np.asarray(stats.found), "fallen": unknown, "left": unknown, "timed out": unknown,
            "collided": (float(stats.collided_seconds.sum()), float(stats.seconds.sum())),
            "skated": (float(stats.skated.sum()), float(stats.frames.sum())), "seconds": np.asarray(stats.seconds, dtype=float),
            "paths": stats.paths, "views": []}  # fmt: skip


def matrix_rows(policies: dict[str, Path]) -> dict[str, ClopsRow]:
    """Every row ({label: ClopsRow}): random actions, the GAMMA navigator, and each DQN policy with its observation."""
    rows = {"random actions": ClopsRow("random"), "GAMMA navigator, known goal (EgoGen-like)": ClopsRow("gamma")}
    for suffix, (label_suffix, options) in OBSERVATIONS.items():
        for name, path in policies.items():
            if observation_of(path) == suffix:
                rows[f"CLOPS DQN trained on {name.removesuffix(suffix)}{label_suffix}"] = ClopsRow("dqn", path, tuple(options))
    return rows


def main(episodes_per_family: int = 100, families: tuple[str, ...] = tuple(FAMILIES), seed: int = 0,
         ray_address: str | None = None) -> int:  # fmt: skip
    """Every row on every family's test seeds; `ray_address`: fan the episode groups out over Ray ("local" or a
    cluster's address)."""
    torch.manual_seed(seed)
    policies = {path.stem.removeprefix("dqn_clopsnav_"): path for path in sorted(WEIGHTS_DIR.glob("dqn_clopsnav_*.zip"))}
    tasks = [((label, family), (row, family, first, last, seed)) for family in families
             for label, row in matrix_rows(policies).items() for first, last in spans(episodes_per_family, EPISODES_PER_TASK)]  # fmt: skip
    started = time.perf_counter()
    rows: dict[str, dict[str, Scores]] = {}
    for (label, family), parts in run_grouped(run_shard, tasks, ray_address, "clops episode groups").items():
        rows.setdefault(label, {})[family] = scores = scores_of(parts)
        print(f"{label} on {family}: SR {scores.success:.0f}%  Col {scores.collision:.0f}%  FS {scores.skating:.0f}%")
    command = bench_command("clops", {"episodes": episodes_per_family, "families": ",".join(families), "seed": seed, "ray": ray_address})
    write_results(rows, families, episodes_per_family, time.perf_counter() - started, command, ray_address)
    throughput_section(ClopsNavCore(ClopsNavConfig(family=families[0], split="test")), bodies=64, actions=3)
    return 0


def observation_of(path: Path) -> str:
    """The `OBSERVATIONS` suffix of the observation options the policy at `path` was trained with (what the file
    says, `agents.policy_files`): "_known_goal", "_memory" or ""."""
    trained = read_policy_file(path).trained_for
    flags = {} if trained is None else {flag: True for flag in OBSERVATION_FLAGS if trained.env_kwargs.get(flag)}
    return next(suffix for suffix, options in OBSERVATION_OPTIONS.items() if options == flags)


def trained_on(label: str) -> str | None:
    """The family a DQN row's policy was trained on ("CLOPS DQN trained on living + known goal" -> "living")."""
    prefix = "CLOPS DQN trained on "
    if not label.startswith(prefix):
        return None
    family = label.removeprefix(prefix)
    for label_suffix, _ in OBSERVATIONS.values():
        family = family.removesuffix(label_suffix)
    return family


def write_results(rows: dict[str, dict[str, Scores]], families: tuple[str, ...], count: int, wall: float, command: str,
                  ray_address: str | None = None) -> None:  # fmt: skip
    lines = [
        "# CLOPS scene matrix", "",
        f"{count} episodes per family (its held-out test seeds {TEST_SEEDS.start}-{TEST_SEEDS.start + count - 1}, one each), "
        f"15 s each, the same episodes for every row, in groups of {EPISODES_PER_TASK} (`benchmarks.fanout`) run "
        + ("in this process" if ray_address is None else f"as Ray tasks ({ray_address})")
        + f". `{command}` ({wall / 60:.0f} min).",
        machine_line(), "",
        "SR: goal within 1 m and in view (%); Col: actions with a collision (%); FS: frames whose lowest foot vertex slid > 0.66 cm (%); "
        f"falls: episodes ended by the pelvis falling below {ClopsNavConfig.fall_height} m (%, `ClopsNavConfig.fall_height`; the GAMMA "
        "navigator's bodies are GAMMA's: –).",
        "Home SR: on the held-out rooms of the family a policy was trained on; elsewhere: mean SR over the other families "
        "(the issue's targets: ≥ 80% and ≥ 60%, collisions ≤ 20%).",
        "", "| row | " + " | ".join(f"{f} SR / Col / FS" for f in families) + " | mean SR | mean Col | mean FS | falls | home SR | SR elsewhere |",
        "|---|" + "---|" * (len(families) + 6),
    ]  # fmt: skip
    for label, by_family in rows.items():
        cells = [f"{s.success:.0f} / {s.collision:.0f} / {s.skating:.0f}" for s in (by_family[f] for f in families if f in by_family)]
        means = [np.mean([getattr(s, name) for s in by_family.values()]) for name in ("success", "collision", "skating", "fallen")]
        home = trained_on(label)
        split = (f"{by_family[home].success:.0f} | {np.mean([s.success for f, s in by_family.items() if f != home]):.0f}"
                 if home in by_family and len(by_family) > 1 else " | ")  # fmt: skip
        lines.append(f"| {label} | " + " | ".join(cells) + " | " + " | ".join("–" if np.isnan(m) else f"{m:.0f}" for m in means) + f" | {split} |")
    lines += ["", "How episodes end, per family (%): goal found / left the room / fell / 15 s up (the GAMMA navigator's: found only).", "",
              "| row | " + " | ".join(families) + " |", "|---|" + "---|" * len(families)]
    for label, by_family in rows.items():
        ends = [" / ".join("–" if np.isnan(value) else f"{value:.0f}" for value in (s.success, s.left, s.fallen, s.timed_out))
                for s in (by_family[f] for f in families if f in by_family)]  # fmt: skip
        lines.append(f"| {label} | " + " | ".join(ends) + " |")
    lines += ["", "The paper (Replica scenes, its own X cm; Table 2 trains and tests on S1):", "", "| row | SR | Col | FS |", "|---|---|---|---|"]
    lines += [f"| {label} | {sr} | {col} | {fs} |" for label, (sr, col, fs) in PAPER_TABLE2.items()]
    lines += ["", "The paper's Table 1 (rows: train scene, columns: test scene S1-S5), SR / Col %:", ""]
    lines += ["| train \\ test | S1 | S2 | S3 | S4 | S5 |", "|---|---|---|---|---|---|"]
    lines += [f"| S{i + 1} | " + " | ".join(f"{a} / {b}" for a, b in zip(sr, col)) + " |"
              for i, (sr, col) in enumerate(zip(PAPER_SR_MATRIX, PAPER_COL_MATRIX))]  # fmt: skip
    text = "\n".join(lines) + "\n"
    atomic_write(RESULTS / "clops_matrix.md", lambda file: file.write(text.encode()))
    print(text)
    figure_of(rows, families)


def figure_of(rows: dict[str, dict[str, Scores]], families: tuple[str, ...]) -> None:
    """Egocentric frames of one DQN episode over its top-down path, and the SR matrix."""
    learnt = [label for label in rows if label.startswith("CLOPS DQN") and "known" not in label]
    label = learnt[0] if learnt else next(iter(rows))
    family = families[0]
    scores = rows[label][family]
    frames = scores.views[:8]
    figure = plt.figure(figsize=(2 * max(len(frames), 4), 6.5))
    for index, view in enumerate(frames):
        axis = figure.add_subplot(2, max(len(frames), 4), index + 1)
        colour = view[1:4].transpose(1, 2, 0).copy()
        colour[view[4] > 0] = (230, 30, 30)
        axis.imshow(colour)
        axis.set_title(f"action {index}", fontsize=8)
        axis.axis("off")
    core = ClopsNavCore(ClopsNavConfig(family=family, split="test"))
    scene = core.slots[core.slot(family, TEST_SEEDS.start)].scene
    path_axis = figure.add_subplot(2, 2, 3)
    state = episodes(core, 1)
    top_down(path_axis, scores.paths[:1], state.goal[:, :2].numpy(), scene, title=f"{label}, {family} test seed {TEST_SEEDS.start}")
    matrix_axis = figure.add_subplot(2, 2, 4)
    table = np.array([[rows[name][f].success if f in rows[name] else np.nan for f in families] for name in rows])
    matrix_axis.imshow(table, vmin=0, vmax=100, cmap="viridis")
    matrix_axis.set(xticks=range(len(families)), xticklabels=families, yticks=range(len(rows)), yticklabels=list(rows))
    for (i, j), value in np.ndenumerate(table):
        matrix_axis.text(j, i, f"{value:.0f}", ha="center", va="center", color="white", fontsize=8)
    matrix_axis.set_title("SR (%) on held-out seeds")
    save(figure, RESULTS / "clops_matrix.png")


def stepping_rate(core: ClopsNavCore, bodies: int, actions: int) -> tuple[float, float]:
    """(actions/s, body-frames/s) of `bodies` held-out episodes stepped `actions` random actions each."""
    state = episodes(core, bodies)
    controller = random_actions(0)
    tick = time.perf_counter()
    frames_before = state.frame.sum()
    for _ in range(actions):
        state, _ = core.step(state, controller(core, state))
    seconds = time.perf_counter() - tick
    return bodies * actions / seconds, int(state.frame.sum() - frames_before) / seconds


def throughput_section(core: ClopsNavCore, bodies: int, actions: int) -> None:
    """Measured ClopsNav stepping rate into `throughput.md`."""
    per_action, per_frame = stepping_rate(core, bodies, actions)
    text = (f"ClopsNav-v0 ({core.config.family}, {core.config.width}×{core.config.height} views), {bodies} bodies, "
            f"{actions} random actions each: {per_action:.0f} actions/s, {per_frame:.0f} "
            f"body-frames/s (decode, collisions, views). {machine_line()}")  # fmt: skip
    replace_section(RESULTS / "throughput.md", f"## ClopsNav stepping\n\n{text}\n")
