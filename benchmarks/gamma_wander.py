"""Wandering (`motion-envs bench wander`): GAMMA bodies following waypoints on open ground, through rooms, in crowds.

1. **Waypoint paths** (DART's protocol on paths of our own): `paths` fixed open-ground paths of 4-5 legs of
   2-4 m (up to 20 m), each leg turning up to 180°, waypoints at most 1.5 m apart
   (`GammaWanderCore.flat_path`). A path succeeds when the pelvis ends a primitive within 0.3 m of the last
   waypoint after passing the others in order (0.75 m). Every path runs twice: 32 clones moving together
   (GAMMA's Table 1 protocol: success when any clone arrives) and `repeats` single bodies (per-body success).
   The WANDR row walks the same paths with WANDR's sampler (z ~ N(0, I) every frame) on the shipped WANDR
   prior, the pelvis goal handed over as a wrist goal (`baselines.wandr_waypoints`: the paper's C.3 extension
   at inference time, each waypoint asked for at a walking pace, 1.2 m/s: `ASKED_PACE`), one body per path and
   repeat, for as long as the GAMMA rows get (40 s).
2. **Rooms**: `rooms` held-out rooms per layout family (`TEST_SEEDS`), start and goal at the far ends of the
   walkable region (`scenes.paths.far_ends`), one body per room. Collisions: share of primitives in which a
   body sphere is more than 2 cm inside furniture or a wall, and per second of motion. The "straight at the
   goal" row gives the policy the goal alone (no planned path); the search rows (the policy's proposals with
   either cost, random z with the distance cost) follow the planned path.
3. **Crowd**: 16 bodies for 30 s in `living:1003` (`motion_envs.populate`).

Time to arrive: seconds of motion to success (successful paths). Contact score: GAMMA Eq. 11; FS: WANDR's
(40 fps, 0.2 m/s). Head low: share of generated frames with the head lower than 1.38 m (`rewards.UPRIGHT_HEAD`; a stooping or
crouching body; the clean data's walking frames: 15% in the test split, 27% in training). Floor distance is not reported: the env's floor rule (`ground_feet`) puts the lowest sole
point of every frame on the ground, by construction. Search rows: 16 roots, 4 children per node, the top 1 or
4 nodes kept per level (the release keeps 4), the node cost with the scene's collision and clearance terms
(`SearchCost`: a branch that touched furniture is pruned while another is left), and distance alone or the
release's contact cost.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from agents.controllers import PolicyLatent
from baselines.latent_controllers import RandomLatent
from baselines.wandr_sampler import WandrSampler
from baselines.wandr_waypoints import follow_waypoints
from benchmarks.gamma_control import Recorder, run_clones, run_search
from benchmarks.machine import bench_command, machine_line
from motion_envs.atomic import atomic_write
from motion_envs.envs.gamma_wander import GammaWanderConfig, GammaWanderCore, GammaWanderState
from motion_envs.envs.wandr_reach import WandrReachConfig, WandrReachCore
from motion_envs.plots import grid_of_axes, save, top_down
from motion_envs.priors.wandr_features import FPS as WANDR_FPS
from motion_envs.populate import PRIMITIVE_SECONDS, populate
from motion_envs.priors.training import WEIGHTS_DIR
from motion_envs.scenes.layouts import FAMILIES, TEST_SEEDS, make_scene
from motion_envs.scenes.paths import far_ends
from motion_envs.wrappers.tree_search import SearchCost, SearchSettings

RESULTS = Path(__file__).resolve().parent / "results"
POLICY = WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip"
WANDER_POLICY = WEIGHTS_DIR / "ppo_gammawander_alpha1_paper.zip"
COSTS = {"distance": SearchCost.distance_only(), "release": SearchCost()}


class WanderRecorder(Recorder):
    """`Recorder` plus the share of primitives that collided with the scene."""

    def __init__(self, core: GammaWanderCore, start: GammaWanderState, horizon: int) -> None:
        super().__init__(core, start, horizon)
        self.collided: list[torch.Tensor] = []

    def add(self, step: int, result, rows: torch.Tensor, every: int = 1) -> None:
        super().add(step, result, rows, every)
        self.collided.append(result.collided.float().cpu())

    def row(self, steps: torch.Tensor, reached: torch.Tensor, distance: torch.Tensor) -> dict:
        collided = torch.cat(self.collided)
        return {**super().row(steps, reached, distance), "collided": (float(collided.sum()), len(collided))}


def figures(row: dict, seconds: float) -> dict:
    """A table row from `WanderRecorder.row`."""
    reached = row["reached"]
    return {
        "success": float(reached.mean()),
        "time": float(row["steps"][reached].mean() * PRIMITIVE_SECONDS) if reached.any() else float("nan"),
        "left": float(row["distance"].mean()),
        "collisions": row["collided"][0] / row["collided"][1],
        "collisions per s": row["collided"][0] / (row["collided"][1] * PRIMITIVE_SECONDS),
        "contact": row["contact"][0] / row["contact"][1],
        "FS": row["skating"][0] / row["skating"][1],
        "stooped": row["stooped"][0] / row["stooped"][1],
        "seconds": seconds,
        "paths": row["paths"],
    }


def policy_label(path: Path) -> str:
    """ppo_gammareach_alpha1_paper.zip -> "policy(1)"; ppo_gammawander_alpha1_paper.zip -> "wander policy(1)"."""
    env, _, rest = path.stem.removeprefix("ppo_").partition("_alpha")
    return ("wander " if env == "gammawander" else "") + f"policy({rest.split('_')[0]})"


def run_row(core: GammaWanderCore, start: GammaWanderState, row: str, seed: int, clones: int = 1,
            policy: Path = POLICY) -> dict:  # fmt: skip
    """One row on the bodies of `start`: "policy" (the `policy` file), "random z" (+ " & topK <cost>": a search)."""
    began = time.perf_counter()
    proposal = RandomLatent(seed) if row.startswith("random") else PolicyLatent(policy, seed=seed)
    if "top" not in row:
        recorded = run_clones(core, start, proposal, clones, WanderRecorder)
    else:
        keep = int(row.split("top")[1].split()[0])
        settings = SearchSettings(keep=keep, cost=COSTS[row.rsplit(" ", 1)[1]])
        recorded = run_search(core, start, proposal, settings, WanderRecorder)
    return figures(recorded, time.perf_counter() - began)


def wandr_row(start: GammaWanderState, max_primitives: int, seed: int) -> dict:
    """WANDR's sampler walking the waypoints of `start` (open ground), one body each, from random start rows and
    headings, for as many seconds as `max_primitives` GAMMA primitives last."""
    began = time.perf_counter()
    core = WandrReachCore(WandrReachConfig())
    rng = np.random.default_rng([seed, start.num_bodies])
    rows = torch.as_tensor(rng.integers(core.num_starts, size=start.num_bodies))
    facing = torch.as_tensor(rng.uniform(-np.pi, np.pi, start.num_bodies), dtype=torch.float32)
    walk = follow_waypoints(core, rows, facing, start.waypoints, start.count, WandrSampler(1.0, seed),
                            max_frames=round(max_primitives * PRIMITIVE_SECONDS * WANDR_FPS))  # fmt: skip
    reached = walk.reached
    return {"success": float(reached.float().mean()), "time": float(walk.frames[reached].float().mean() / WANDR_FPS)
            if reached.any() else float("nan"), "left": float(walk.distance.mean()), "contact": float("nan"),
            "FS": float(walk.skated.sum() / walk.frames.sum()),
            "stooped": float(walk.stooped.sum() / walk.frames.sum()), "seconds": time.perf_counter() - began}  # fmt: skip


def flat_paths(core: GammaWanderCore, count: int, seed: int) -> GammaWanderState:
    """The fixed open-ground paths (path i is the same for any `count`)."""
    return core.sample_initial_state([np.random.default_rng([seed, path]) for path in range(count)])


def room_starts(core: GammaWanderCore, rooms: int, seed: int, straight: bool) -> GammaWanderState:
    """One body per held-out room of the core's family, start and goal at the region's far ends; `straight`: the
    goal alone."""
    states = []
    for room in TEST_SEEDS[:rooms]:
        rng = np.random.default_rng([seed, room])
        start, goal = far_ends(core.scenes[core.slot(core.config.scene, room)], rng)
        options = {"scene_seed": room, "start": start, **({"waypoints": goal[None]} if straight else {"goal": goal})}
        states.append(core.sample_initial_state([rng], options))
    return GammaWanderState.cat(states)


def table(rows: dict[str, dict], columns: tuple[str, ...]) -> list[str]:
    header = {"success": "success ↑", "time": "time (s) ↓", "left": "m left ↓", "collisions": "collided primitives ↓",
              "collisions per s": "collisions / s ↓", "contact": "contact ↑", "FS": "FS ↓", "stooped": "head low ↓", "seconds": "seconds"}  # fmt: skip
    lines = ["| row | " + " | ".join(header[name] for name in columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for name, row in rows.items():
        cells = ["–" if np.isnan(row[c]) else f"{row[c]:.0f}" if c == "seconds" else f"{row[c]:.3f}" for c in columns]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def main(paths: int = 100, clones: int = 32, repeats: int = 4, rooms: int = 100, crowd_seconds: float = 30.0,
         seed: int = 0, quick: bool = False, policies: list[Path] | None = None, output: str | None = None) -> int:  # fmt: skip
    """`policies`: GammaReach/GammaWander PPO files to compare (default: the shipped wander policy where there is
    one, and GammaReach's α = 1 policy); the first one also drives the search rows and the crowd."""
    command = bench_command("wander", {"paths": paths, "rooms": rooms, "seed": seed, "quick": quick, "policies": policies,
                                       "output": output}, {"paths": 100, "rooms": 100, "seed": 0})  # fmt: skip
    if quick:
        paths, clones, repeats, rooms, crowd_seconds = 20, 8, 2, 10, 10.0
    policies = policies or [path for path in (WANDER_POLICY, POLICY) if path.exists()]
    labels = {policy_label(path): path for path in policies}
    main_label, main_policy = next(iter(labels.items()))
    began = time.perf_counter()
    flat_core = GammaWanderCore(GammaWanderConfig(scene="flat", max_primitives=160))
    start = flat_paths(flat_core, paths, seed)
    flat: dict[str, dict] = {}
    for label, policy in labels.items():
        for name, body_clones in ((f"{label}, any of {clones} clones", clones), (f"{label}, one body", 1)):
            bodies = start if body_clones > 1 else start.repeat(repeats)
            flat[name] = run_row(flat_core, bodies, "policy", seed, body_clones, policy)
    for row in (f"{main_label} & top1 distance", f"{main_label} & top1 release", "random z & top4 distance"):
        flat[row] = run_row(flat_core, start, row, seed, policy=main_policy)
    flat["WANDR sampler, pelvis goals (ours), one body"] = wandr_row(start.repeat(repeats), flat_core.config.max_primitives, seed)
    flat_columns = ("success", "time", "left", "contact", "FS", "stooped", "seconds")

    room_cores = {family: GammaWanderCore(GammaWanderConfig(scene=family, max_primitives=160), flat_core.generator)
                  for family in FAMILIES}  # fmt: skip
    rooms_rows: dict[str, dict[str, dict]] = {}
    for family, room_core in tqdm(room_cores.items(), desc="room families"):
        planned, straight = room_starts(room_core, rooms, seed, False), room_starts(room_core, rooms, seed, True)
        rooms_rows[family] = {}
        for label, policy in labels.items():
            rooms_rows[family][f"{label}, planned path"] = run_row(room_core, planned, "policy", seed, policy=policy)
            rooms_rows[family][f"{label}, straight at the goal"] = run_row(room_core, straight, "policy", seed, policy=policy)
        for row in ("policy & top1 distance", "policy & top4 distance", "policy & top1 release", "random z & top4 distance"):
            name = row.replace("policy", main_label) + ", planned path"
            rooms_rows[family][name] = run_row(room_core, planned, row, seed, policy=main_policy)
    room_columns = ("success", "time", "left", "collisions", "collisions per s", "FS", "stooped", "seconds")

    crowd = populate(make_scene("living", 1003), PolicyLatent(main_policy, seed=seed), 16, crowd_seconds, seed,
                     scene_spec="living:1003", core=room_cores["living"], progress=False)  # fmt: skip
    stem = output or "gamma_wander" + ("_quick" if quick else "")
    lines = [f"# Wandering: waypoints, rooms and crowds ({'quick' if quick else 'full'})", "", __doc__.split("\n\n", 1)[1].strip(), "",
             f"## 1. Waypoint paths on open ground ({paths} paths; one-body rows: {repeats} bodies per path)", "",
             *table(flat, flat_columns), "", f"## 2. Rooms ({rooms} held-out rooms per family, one body each)", ""]  # fmt: skip
    for family, rows in rooms_rows.items():
        lines += [f"**{family}**", "", *table(rows, room_columns), ""]
    lines += [f"## 3. Crowd ({main_label}, search: 8 roots, 4 children, 2 kept, 2 primitives ahead)", "", "| bodies | seconds of motion | arrivals / min | collided primitives | overlapping another body "
              "| wall s | × real time |", "|---|---|---|---|---|---|---|",
              f"| {crowd.bodies} | {crowd.motion_seconds:.0f} | {crowd.arrivals_per_minute:.1f} | {crowd.collided:.3f} | "
              f"{crowd.overlapping:.3f} | {crowd.wall_seconds:.0f} | {crowd.realtime_factor:.2f} |", "",
              machine_line(), f"Command: `{command}`; "
              f"{time.perf_counter() - began:.0f} s in all.", "", f"![paths]({stem}.png)", ""]  # fmt: skip
    text = "\n".join(lines)
    print(text)
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic_write(RESULTS / f"{stem}.md", lambda file: file.write(text.encode()))
    _figure(flat, start, rooms_rows, room_cores, seed, rooms, main_label, RESULTS / f"{stem}.png")
    return 0


def _figure(flat: dict, start: GammaWanderState, rooms_rows: dict, room_cores: dict[str, GammaWanderCore], seed: int,
            rooms: int, label: str, path: Path) -> None:  # fmt: skip
    """Top-down: the first open-ground paths (waypoints as crosses) and one room per family with its body's path."""
    figure, axes = grid_of_axes(1 + len(rooms_rows), columns=3, size=4.5)
    count = min(8, start.num_bodies)
    waypoints = torch.cat([start.waypoints[i, : int(start.count[i])] for i in range(count)]).numpy()
    row = next(iter(flat.values()))
    top_down(axes[0], row["paths"][:count], waypoints, title=f"open ground: {row['success']:.2f}", extent=12.0)
    for axis, (family, rows) in zip(axes[1:], rooms_rows.items()):
        state = room_starts(room_cores[family], 1, seed, False)
        scene = room_cores[family].scenes[int(state.scene[0])]
        planned = rows[f"{label}, planned path"]
        top_down(axis, planned["paths"][:1], state.waypoints[0, : int(state.count[0])].numpy(), scene,
                 title=f"{family}: {planned['success']:.2f} of {rooms}")  # fmt: skip
    save(figure, path, dpi=80)
