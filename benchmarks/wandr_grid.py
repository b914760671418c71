"""WANDR's goal-reaching benchmark (`motion-envs bench wandr`): the paper's protocol (Sec. 4.2-4.3).

Goals on a cylinder around each start body: 5 angles equally spaced over
360° (from the body's forward), 5 heights in 0-1.8 m, 5 ground distances in
0.5-5 m from the pelvis; 6 start poses (evenly spread over the shipped
30 fps validation start windows, each facing +y); 5 samples each:
3,750 rollouts of at most 8 s (240 frames), in batches of `SHARD`. Per row:

* SR: the right wrist came within 10 cm of the goal (the rollout stops there);
* FS: frames whose lowest foot vertex slid more than 0.66 cm (WANDR's
  threshold at 30 fps), % of all frames generated;
* DTG: the closest the wrist came to the goal, cm, mean over rollouts.

The paper gives every goal the same deadline, the episode's 8 s (t_G in the
wrist intention I^w = (G − W) / (t_G − i)). Our prior, trained on 17 min of
CMU, follows I^w only at a walking pace: told to take 8 s to a goal 0.5 m
away it stands, and to one 5 m away it dawdles (median 3.8 m still to go
after 4 s), then cannot catch up when t_G nears. So the table also has the
"paced" sampler, whose t_G is the goal's distance at a walking pace,
t_G = 1 s + d / (1.2 m/s) (capped at 8 s); the paper's inference otherwise
(the user supplies t_G, Sec. 3.5). On 250 rollouts, other paces gave 54%
(1.5 s + d / 1 m/s), 45% (2 s + d / 0.8 m/s) and 64% (1 s + d / 1.4 m/s).
Every ablation / data variant gets a paced row too.

Sampling every frame's z from N(0, I) makes the feet slide: the paced
sampler's FS is 79%, the test clips' 64%. Two more paced rows lower the
sampling temperature (z ~ N(0, σ² I)): σ = 0.25, and σ = 0, the prior's
mean (what ClopsNav decodes, `ClopsNavConfig.latent_scale`). On the full
grid σ = 0.5 gave 60.3% / 70.9% (SR / FS), and slower paces at σ = 1 lower
FS less than SR (1 s + d / 0.9 m/s: 57.9% / 76.5%).

Attempts to make the 8-s sampler work, each fine-tuned from the shipped
prior (`train wandr --prior-init`) and scored on 500 rollouts (2 poses ×
2 samples; 8-s SR / FS, then paced SR / FS; shipped: 2.8 / 71.6,
63.2 / 80.9): KL weight β = 1 for 8 epochs 4.4 / 93.7, 43.8 / 93.4;
β = 0.3: 3.6 / 87.7, 58.2 / 87.9; 10 more epochs as shipped
2.6 / 77.2, 62.2 / 83.6; every training goal ≥ 1.5 m away (the release)
3.4 / 70.3, 63.8 / 81.8; the clips time-warped to 0.6× and 0.8× pace as
well (not kept) 3.6 / 67.1, 62.8 / 79.3; 30-frame training rollouts
3.6 / 70.3, 65.8 / 83.7, and with β = 0.3 4.8 / 74.8, 72.4 / 84.2; a
learned conditional prior p(z | c) in place of N(0, I) (`--learned-prior`,
10 epochs) 2.6 / 84.3, 56.8 / 88.3, and trained from scratch with it
(40 epochs) 0.8 / 69.0, 72.0 / 76.0 (z = 0 paced: 63.6 / 65.1). Trained from scratch with the shipped
recipe but every goal ≥ 1.5 m away: 3.2 / 65.6, 65.0 / 79.8.
`benchmarks.wandr_pace` shows why: the prior lags its own intention on
the windows it was trained on.

On the shipped prior (cleaned data, pace and upright terms) the lag is gone
(`wandr_pace.md`: 0.33 m left after 6 s, the data 0.30) and the 8-s sampler
misses at the deadline instead: on 500 rollouts (2 poses × 2 samples, seed 0)
its pelvis is a median 0.3 m from the goal at 8 s, as the data's at t_G, but
the wrist ends 0.22-0.30 m off (goals at 0.9 / 1.35 m: 20% / 19% reached);
paced goals leave time after t_G, where I^w is large, to home in. The reach
term (`train wandr --reach-weight R --end-goal-probability P`,
`train_wandr.free_run_terms`), 4 epochs of the `wandr_upright` stage's
fine-tune from the shipped prior (pace 0.03, upright 1.0, lr 1e-4), scored
the same way (8-s SR / FS, paced SR / FS, then the head over the last second
of 15-s walks towards a goal 15 m ahead, `benchmarks.floor`'s sinking row
with 16 episodes from seed 100; shipped: 8.4 / 19.8, 60.2 / 50.1, 1.46 m):
R = 0.1, P = 0.5: 17.6 / 22.2, 75.2 / 53.4, 1.44 m; R = 0.3: 20.2 / 25.1,
70.0 / 57.1 (8 walks: 1.36 m); R = 1: 24.6 / 21.7, 67.6 / 56.0, 1.42 m
(goals at 0.9 / 1.35 m 51% / 71%, at 1.8 m 1%, at 0 and 0.45 m none);
R = 1 at lr 5e-5: 14.0 / 23.8, 70.2 / 55.9, 1.42 m; R = 0.3, P = 1:
24.8 / 25.4, 69.2 / 57.9, 1.33 m; upright 3 with R = 1 / R = 3 (P = 0.8):
20.0 / 22.0% at the 8 s, 8 walks 1.26 / 1.28 m. Each of these costs the
15-s walk its head height (target 1.45 m). With 150-frame free runs instead
of 90 (`--pace-frames 150`, R = 1, P = 0.5; 36 min beside another job):
27.6 / 15.6, 72.2 / 50.4, head 1.48 m (lowest 1.24, shipped 1.10): better
than the shipped prior on every figure, 4 points under the paper's 32%, and
the candidate for the next shipped prior; on the full grid (3,750 rollouts a
row, seed 0) 8-s 29.4% / FS 14.1% / DTG 29.9 cm, paced 71.7% / 49.1%. Not shipped yet: the WandrReach
PPO policy, trained on the shipped prior, drops on it (500 rollouts, mean
latent / sampled: 90.4 / 96.6% -> 79.2 / 85.4%; on the R = 0.1 prior
87.6 / 91.6%); fine-tuned on it with the shipped policy's last stage
(`train ppo ... --env-option weights=<prior> --timesteps 2000000`, 8.5 min)
it gives 91.2 / 97.6% (FS 10.4 / 14.1%). It ships with that fine-tune and
every WANDR table rerun. The figures of this paragraph and the two
above were measured on the previous shipped prior (uncleaned CMU data); the
shipped prior is now the one retrained on the cleaned data (CMU + ACCAD,
contact loss, rollouts of up to 60 frames), and the previous one is a
variant row when its weights are at hand (`git show
6f9e93a:motion_envs/priors/weights/wandr.pt > runs/wandr_weights/wandr_uncleaned.pt`).

Two speed columns show whether a row walks or runs: the share of every
half-second span of pelvis ground motion (before the rollout ends) faster
than the data's fastest walk (`WALK_SPEED`, 2.1 m/s), and the median over
rollouts of each one's fastest half second; the data's own distribution is
printed below the table.

Rows: the WANDR sampler (z ~ N(0, I) every frame) on the shipped prior and
on every ablation / data variant whose weights are in `runs/wandr_weights/`
(`--variants-dir`; they are trained with `motion-envs train wandr
--intentions ... --weights runs/wandr_weights/NAME.pt` and not shipped); the sampler and the paced sampler without the env's foot
rule (`lock_feet`), and the shipped prior without it and without `ground_feet` (the prior alone);
latent optimisation (`baselines.latent_optimisation`: "VAE + opt" with a
zero intention from random latents, "WANDR + opt" refining the sampler's
latents) on 2 start poses × 1 sample (250 rollouts: it backpropagates
through 240 frames, ~5 min a row on 2 cores); every shipped WandrReach PPO policy, twice: with
sampled latents (the policy's σ ≈ 0.96, held near N(0, I) by the α·KL term, as GAMMA's protocol) and
with its mean latent (SB3's deterministic evaluation), which slides far less; and
the data's own FS (test clips, when the mocap cache can be built). Writes
`benchmarks/results/wandr_grid.md`, `wandr_grid.png` (the paper's Figure 5:
SR by height, angle and distance) and the prior's decode throughput into
`benchmarks/results/throughput.md`.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from baselines.latent_optimisation import LatentSequence, optimise_latents
from baselines.wandr_sampler import Controller, WandrSampler, roll_out
from benchmarks.fanout import run_grouped, spans
from benchmarks.machine import bench_command, machine_line
from benchmarks.sections import replace_rows, replace_section
from motion_envs.atomic import atomic_write
from motion_envs.counter_random import BodyNoise
from motion_envs.data.dataset import MotionDataset
from motion_envs.envs.wandr_reach import WandrReachConfig, WandrReachCore, WandrReachState
from motion_envs.priors.train_wandr import WandrClips, load_wandr
from motion_envs.priors.training import WEIGHTS_DIR
from motion_envs.priors.wandr import WandrStepper
from motion_envs.metrics import window_speeds
from motion_envs.priors.wandr_features import FPS, PELVIS
from motion_envs.rewards import WandrRewardConfig
from motion_envs.plots import plt, save, success_by
from motion_envs.data.paths import SHIPPED_SUBSETS

RESULTS = Path(__file__).resolve().parent / "results"
ANGLES, HEIGHTS, DISTANCES = 5, 5, 5
HEIGHT_RANGE, DISTANCE_RANGE = (0.0, 1.8), (0.5, 5.0)
PACED_START_S, PACED_SPEED = 1.0, 1.2
"""The paced sampler's deadline: t_G = PACED_START_S + d / PACED_SPEED seconds for a goal d metres away."""
PACED_LABEL = f"WANDR sampler, paced t_G = {PACED_START_S:g} s + d / {PACED_SPEED:g} m/s (ours)"
WALK_SPEED = WandrRewardConfig.walk_speed
"""m/s: the data's fastest walk (the speed columns count half-second windows faster than it)."""
COLD_SIGMAS = {0.25: "σ = 0.25", 0.0: "z = 0, the prior's mean"}
"""Extra paced rows at a lower sampling temperature (z ~ N(0, σ² I)): sampling raises foot skating."""
PAPER_ROWS = {  # WANDR Tables 1 and 2: SR %, FS %, DTG cm
    "WANDR (paper)": (32, 16, 24.8),
    "WANDR, I^w only (paper)": (15, 13, 62.9),
    "WANDR, I^w + I^p (paper)": (18, 17, 44.9),
    "WANDR, I^w + I^r (paper)": (19, 19, 36.0),
    "VAE + opt (paper)": (3, 4, 217.0),
    "WANDR trained on AMASS only (paper)": (16, 19, 48.0),
}
VARIANTS_DIR = Path("runs/wandr_weights")
VARIANTS = {  # weights file -> row label
    "wandr_wrist.pt": "WANDR sampler, I^w only",
    "wandr_wrist_pelvis.pt": "WANDR sampler, I^w + I^p",
    "wandr_wrist_orientation.pt": "WANDR sampler, I^w + I^r",
    "wandr_cmu_hdm05.pt": "WANDR sampler, trained on cmu + hdm05",
    "wandr_uncleaned.pt": "WANDR sampler, the previous prior (uncleaned CMU data, no contact loss)",
}


def grid_values() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The paper's 5 angles (rad), 5 heights (m) and 5 distances (m)."""
    angles = torch.arange(ANGLES) * (2 * math.pi / ANGLES)
    return angles, torch.linspace(*HEIGHT_RANGE, HEIGHTS), torch.linspace(*DISTANCE_RANGE, DISTANCES)


def grid_cells(poses: int, samples: int) -> torch.Tensor:
    """(B, 5) every (pose, angle, height, distance, sample) index of the grid, in rollout order."""
    return torch.cartesian_prod(torch.arange(poses), torch.arange(ANGLES), torch.arange(HEIGHTS), torch.arange(DISTANCES),
                                torch.arange(samples))  # fmt: skip


def cell_axes(cells: torch.Tensor) -> dict[str, torch.Tensor]:
    """Each rollout's angle, height and distance index."""
    return {"angle": cells[:, 1], "height": cells[:, 2], "distance": cells[:, 3]}


def grid_start(core: WandrReachCore, poses: int, samples: int, paced: bool = False) -> tuple[WandrReachState, dict[str, torch.Tensor]]:
    """Every (pose, angle, height, distance, sample) as one batch; returns the state and each body's grid cell.
    paced: each goal is due at a walking pace (`PACED_START_S`, `PACED_SPEED`), not at the episode's end."""
    angles, heights, distances = grid_values()
    pose_rows = torch.linspace(0, core.num_starts - 1, poses).round().long()
    cells = grid_cells(poses, samples)
    start_index, facing = pose_rows[cells[:, 0]], torch.zeros(len(cells))
    goals = core.cylinder_goals(start_index, facing, angles[cells[:, 1]], heights[cells[:, 2]], distances[cells[:, 3]])
    due = (PACED_START_S + distances[cells[:, 3]] / PACED_SPEED) * FPS
    goal_time = due.round().long().clamp(max=core.config.max_frames) if paced else None
    state = core.initial_state(start_index, facing, goals[:, None], goal_time=goal_time)
    return state, cell_axes(cells)


SHARD = 250
"""Rollouts per task: every row runs as shards of this many bodies, one after another in this process or as Ray
tasks (`benchmarks.fanout`), so its numbers do not depend on where it ran (the full grid: 15 tasks a row)."""
CONTROLLERS = ("sampler", "policy", "policy-mean", "vae-opt", "wandr-opt")


@dataclass(frozen=True)
class GridRow:
    """A table row as a task rebuilds it: the prior's weights, the controller, the goals' deadlines and the grid.

    controller: "sampler" (`WandrSampler(sigma)`), "policy" / "policy-mean" (`PolicyLatent(policy)`, sampled or
    mean latents), "vae-opt" / "wandr-opt" (latent optimisation with a zero / the prior's own intention)."""

    prior: Path
    controller: str = "sampler"
    sigma: float = 1.0
    policy: Path | None = None
    paced: bool = False
    ground_feet: bool = True
    lock_feet: bool = True
    poses: int = 6
    samples: int = 5

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {CONTROLLERS}, got {self.controller!r}")

    def shards(self) -> list[tuple[int, int]]:
        """[first, last) rollout ranges of `SHARD` rollouts."""
        return spans(self.poses * ANGLES * HEIGHTS * DISTANCES * self.samples, SHARD)


@functools.lru_cache(maxsize=8)
def cached_prior(path: Path) -> torch.nn.Module:
    """A prior loaded once per process (a task's network is read-only; latent optimisation freezes and restores it)."""
    return load_wandr(path)


def run_shard(row: GridRow, first: int, last: int, seed: int) -> dict:
    """Rollouts [first, last) of the row's grid: per-rollout reached, skated frames, frames, closest distance,
    half-second windows of pelvis ground speed (how many, how many faster than `WALK_SPEED`, the fastest; numpy),
    and the task's seconds. A pure function of its arguments (per-body noise: `BodyNoise`)."""
    from agents.controllers import PolicyLatent

    torch.manual_seed(seed)
    core = WandrReachCore(WandrReachConfig(ground_feet=row.ground_feet, lock_feet=row.lock_feet), prior=cached_prior(row.prior))
    bodies = torch.arange(first, last)
    start = grid_start(core, row.poses, row.samples, row.paced)[0].index(bodies)
    began = time.perf_counter()
    if row.controller == "sampler":
        controller: Controller = WandrSampler(row.sigma, seed=seed, bodies=bodies)
    elif row.controller in ("policy", "policy-mean"):
        controller = PolicyLatent(row.policy, deterministic=row.controller == "policy-mean", seed=seed, bodies=bodies)
    else:
        intentions = () if row.controller == "vae-opt" else None
        core.stepper = WandrStepper(core.prior, core.body, core.config.ground_feet, intentions, core.config.lock_feet)
        frames, noise = core.config.max_frames, BodyNoise(seed, bodies)
        initial = torch.stack([noise(len(bodies), core.prior.config.latent) for _ in range(frames)], dim=1)
        controller = LatentSequence(optimise_latents(core.stepper, start, frames, initial))
    track = [start.joints[:, PELVIS, :2]]
    final = roll_out(core, start, controller, on_step=lambda state: track.append(state.joints[:, PELVIS, :2]))
    speeds, inside = window_speeds(torch.stack(track, dim=1), final.frame, FPS)
    peak = torch.where(inside, speeds, 0.0).amax(1) if speeds.shape[1] else torch.zeros(len(speeds))
    return {"reached": final.reached.numpy(), "skated": final.skated.numpy(), "frames": final.frame.numpy(),
            "closest": final.closest.numpy(), "windows": inside.sum(1).numpy(),
            "fast": ((speeds > WALK_SPEED) & inside).sum(1).numpy(), "peak": peak.numpy(),
            "seconds": time.perf_counter() - began}  # fmt: skip


def merge_shards(parts: list[dict]) -> dict:
    """One row's SR, FS and DTG (as `evaluate`) from its shards in order; fast: % of half-second windows faster
    than `WALK_SPEED`; peak: median over rollouts of the fastest half-second; seconds: their sum."""
    reached = torch.as_tensor(np.concatenate([part["reached"] for part in parts]))
    skated = float(np.concatenate([part["skated"] for part in parts]).sum())
    frames = int(np.concatenate([part["frames"] for part in parts]).sum())
    closest = np.concatenate([part["closest"] for part in parts])
    windows, fast = (sum(int(part[key].sum()) for part in parts) for key in ("windows", "fast"))
    return {"SR": 100 * float(reached.float().mean()), "FS": 100 * skated / frames, "DTG": 100 * float(closest.mean()),
            "fast": 100 * fast / max(windows, 1), "peak": float(np.median(np.concatenate([part["peak"] for part in parts]))),
            "reached": reached, "seconds": sum(part["seconds"] for part in parts), "frames": frames}  # fmt: skip


def run_rows(rows: dict[str, GridRow], seed: int, ray_address: str | None = None) -> dict[str, dict]:
    """Every row's figures ({label: merge_shards(...)}), its shards run in this process or over Ray."""
    tasks = [(label, (row, first, last, seed)) for label, row in rows.items() for first, last in row.shards()]
    return {label: merge_shards(parts) for label, parts in run_grouped(run_shard, tasks, ray_address, "wandr grid shards").items()}


OPTIMISATION_POSES = 2
"""Latent optimisation rows: 2 start poses × 1 sample (250 rollouts; it backpropagates through 240 frames)."""


def motion_30fps(subsets: tuple[str, ...] = SHIPPED_SUBSETS) -> MotionDataset | None:
    """The 30 fps `MotionDataset`, or None (said why) when the mocap cache cannot be built here."""
    from motion_envs.data.build import build

    try:
        return MotionDataset.load(build(subsets=subsets, fps_list=(FPS,)).caches[FPS])
    except (FileNotFoundError, OSError) as error:
        print(f"no mocap: {error}")
        return None


def training_clips() -> WandrClips | None:
    """The shipped prior's training clips (CMU, mirrored included), or None without the mocap."""
    from motion_envs.body import BodyModel

    dataset = motion_30fps()
    return None if dataset is None else WandrClips.from_dataset(dataset, "train", BodyModel(), mirrored=True)


def data_figures(subsets: tuple[str, ...] = SHIPPED_SUBSETS) -> dict[str, float] | None:
    """The test clips at 30 fps: FS (%), % of half-second windows faster than `WALK_SPEED` and the half-second
    pelvis ground speeds' median, 95th percentile and maximum (m/s), or None when the mocap cache cannot be built here."""
    from motion_envs.body import BodyModel
    from motion_envs.body.markers import foot_vertex_ids
    from motion_envs.data.canonical import body_tensors
    from motion_envs.metrics import foot_skating

    dataset = motion_30fps(subsets)
    if dataset is None:
        return None
    body, ids, skated, frames, speeds = BodyModel(), foot_vertex_ids(), 0.0, 0, []
    with torch.no_grad():
        for clip in dataset.clips("test"):
            tensors = body_tensors(clip)
            flags = foot_skating(body.skin(body(*tensors), ids))
            skated, frames = skated + float(flags.sum()), frames + len(flags)
            clip_speeds, _ = window_speeds(tensors[0][None, :, :2], torch.tensor([len(flags)]), FPS)
            speeds.append(clip_speeds.flatten())
    speeds = torch.cat(speeds)
    quantiles = torch.quantile(speeds, torch.tensor([0.5, 0.95, 1.0])).tolist()
    return {"FS": 100 * skated / max(frames, 1), "fast": 100 * float((speeds > WALK_SPEED).float().mean()),
            **dict(zip(("median", "p95", "max"), quantiles))}


@torch.no_grad()
def decode_throughput(core: WandrReachCore, batch: int = 1024, frames: int = 30) -> dict[str, float]:
    """Body-frames/s of the prior's step alone (decode, integrate, FK) and of the env core's step at `batch`."""
    rows = torch.arange(batch) % core.num_starts
    state = core.initial_state(rows, torch.zeros(batch), torch.zeros(batch, 1, 3) + torch.tensor([0.0, 3.0, 1.0]))
    z = torch.randn(batch, core.prior.config.latent, generator=torch.Generator().manual_seed(0))
    body = state.body
    core.stepper.step(body, z, state.goal, state.frames_left)  # warm-up
    began = time.perf_counter()
    for _ in range(frames):
        body, _ = core.stepper.step(body, z, state.goal, state.frames_left)
    prior_rate = batch * frames / (time.perf_counter() - began)
    began = time.perf_counter()
    for _ in range(frames):
        state, _ = core.step(state, z)
    return {"prior": prior_rate, "env": batch * frames / (time.perf_counter() - began)}


def success_by_cell(reached: torch.Tensor, cells: dict[str, torch.Tensor]) -> dict[str, np.ndarray]:
    """SR (%) per grid value of each axis."""
    sizes = {"angle": ANGLES, "height": HEIGHTS, "distance": DISTANCES}
    return {axis: np.array([100 * float(reached[cells[axis] == v].float().mean()) for v in range(size)])
            for axis, size in sizes.items()}  # fmt: skip


def figure(by_cell: dict[str, dict[str, np.ndarray]], path: Path, title: str) -> None:
    """The paper's Figure 5: SR by height, angle and distance, one bar series per row in `by_cell` ({row: rates})."""
    angles, heights, distances = grid_values()
    figure_, axes = plt.subplots(1, 3, figsize=(11, 3.2), sharey=True)
    success_by(axes, {
        "goal height (m)": ([f"{h:.2f}" for h in heights.tolist()], {label: c["height"] for label, c in by_cell.items()}),
        "goal angle from the body's forward": ([f"{math.degrees(a):.0f}°" for a in angles.tolist()],
                                               {label: c["angle"] for label, c in by_cell.items()}),
        "goal distance (m)": ([f"{d:.2f}" for d in distances.tolist()], {label: c["distance"] for label, c in by_cell.items()}),
    })  # fmt: skip
    figure_.suptitle(title)
    save(figure_, path, dpi=110)


def table_row(label: str, row: dict) -> str:
    return (f"| {label} | {row['SR']:.1f} | {row['FS']:.1f} | {row['DTG']:.1f} | {row['fast']:.1f} | {row['peak']:.2f} "
            f"| {row['seconds']:.0f} |")


def grid_rows(quick: bool = False, weights_dir: Path | None = None, policies: list[Path] | None = None,
              optimisation: bool = True, variants_dir: Path = VARIANTS_DIR, only: str | None = None) -> dict[str, GridRow]:  # fmt: skip
    """The benchmark's rows ({label: GridRow}) for the weights at hand (see `main`)."""
    poses, samples = (2, 1) if quick else (6, 5)
    weights_dir = weights_dir or WEIGHTS_DIR
    shipped = weights_dir / "wandr.pt"
    grid = {"poses": poses, "samples": samples}
    runs: dict[str, GridRow] = {}
    if shipped.exists():
        runs["WANDR sampler"] = GridRow(shipped, **grid)
        runs[PACED_LABEL] = GridRow(shipped, paced=True, **grid)
        for sigma, name in COLD_SIGMAS.items():
            runs[f"{PACED_LABEL}, {name}"] = GridRow(shipped, sigma=sigma, paced=True, **grid)
    for name, label in VARIANTS.items():
        if (variants_dir / name).exists():
            runs[label] = GridRow(variants_dir / name, **grid)
            runs[f"{label}, paced"] = GridRow(variants_dir / name, paced=True, **grid)
    for policy in policies if policies is not None else sorted(weights_dir.glob("ppo_wandrreach*.zip")):
        runs[f"PPO ({policy.stem})"] = GridRow(shipped, "policy", policy=policy, **grid)
        runs[f"PPO ({policy.stem}), mean latent"] = GridRow(shipped, "policy-mean", policy=policy, **grid)
    if only is not None:
        runs = {label: run for label, run in runs.items() if only in label}
    if not runs:
        raise FileNotFoundError(f"no WANDR weights in {weights_dir}" + (f" for rows matching {only!r}" if only else ""))
    if only is None and shipped.exists():
        runs["WANDR sampler, without the foot rule (lock_feet)"] = GridRow(shipped, lock_feet=False, **grid)
        runs[f"{PACED_LABEL}, without the foot rule"] = GridRow(shipped, paced=True, lock_feet=False, **grid)
        runs["WANDR sampler, prior alone (no ground_feet, no lock_feet)"] = GridRow(shipped, ground_feet=False, lock_feet=False, **grid)
        if optimisation:
            few = {"poses": OPTIMISATION_POSES, "samples": 1}
            runs[f"VAE + opt (zero intention; {OPTIMISATION_POSES} poses × 1 sample)"] = GridRow(shipped, "vae-opt", **few)
            runs[f"WANDR + opt ({OPTIMISATION_POSES} poses × 1 sample)"] = GridRow(shipped, "wandr-opt", **few)
    return runs


def main(quick: bool = False, seed: int = 0, weights_dir: Path | None = None, policies: list[Path] | None = None,
         data_fs: bool = True, optimisation: bool = True, variants_dir: Path = VARIANTS_DIR, only: str | None = None,
         ray_address: str | None = None, timing: bool = True) -> int:  # fmt: skip
    """Run every row, print the table, write the result files.

    only: rerun just the grid rows whose label contains this text and rewrite those rows of the existing
    table (e.g. a new policy, when the ablation weights of the last full run are not at hand).
    ray_address: fan the rows' shards out over Ray (`benchmarks.fanout`: "local" or a cluster's address).
    timing: measure the prior's decode throughput (off on a busy machine; rows' seconds are printed either way)."""
    poses, samples = (2, 1) if quick else (6, 5)
    runs = grid_rows(quick, weights_dir, policies, optimisation, variants_dir, only)
    began = time.perf_counter()
    rows = run_rows(runs, seed, ray_address)
    wall = time.perf_counter() - began
    for label, row in rows.items():
        print(f"{label}: SR {row['SR']:.1f}%  FS {row['FS']:.1f}%  DTG {row['DTG']:.1f} cm  ({row['seconds']:.0f} s)")
    cells = cell_axes(grid_cells(poses, samples))
    grid_labels = [label for label in runs if runs[label].poses == poses]
    by_cell = {label: success_by_cell(rows[label]["reached"], cells)
               for label in grid_labels if label == grid_labels[0] or label == PACED_LABEL}  # fmt: skip
    where = ("in this process" if ray_address is None else
             f"as {sum(len(row.shards()) for row in runs.values())} Ray tasks of ≤ {SHARD} rollouts ({ray_address})")  # fmt: skip
    name = "wandr_grid_quick" if quick else "wandr_grid"
    command = bench_command("wandr", {"quick": quick, "seed": seed, "no-data-fs": not data_fs, "no-optimisation": not optimisation,
                                      "no-timing": not timing, "variants-dir": variants_dir, "only": only, "ray": ray_address},
                            {"variants-dir": VARIANTS_DIR})  # fmt: skip
    if only is not None:
        replace_rows(RESULTS / f"{name}.md", {label: table_row(label, row) for label, row in rows.items()}, "| data",
                     f"Rows containing '{only}' rerun by `{command}`: {machine_line()}")  # fmt: skip
        return 0
    main_label = next(iter(by_cell))
    data = data_figures() if data_fs else None
    throughput = decode_throughput(WandrReachCore(WandrReachConfig(), prior=load_wandr(runs[main_label].prior))) if timing else None

    count = len(rows[main_label]["reached"])
    lines = [f"# WANDR goal reaching{' (quick)' if quick else ''}", "",
             f"{count} rollouts: {ANGLES} angles × {HEIGHTS} heights ({HEIGHT_RANGE[0]}-{HEIGHT_RANGE[1]} m) × "
             f"{DISTANCES} distances ({DISTANCE_RANGE[0]}-{DISTANCE_RANGE[1]} m) × {poses} start poses × {samples} samples, "
             f"≤ 240 frames (8 s) each, in batches of {SHARD} (`benchmarks.fanout`), run {where}: {wall:.0f} s in all. "
             f"`{command}`. Time per row: its batches' seconds, summed.",
             machine_line(), "", f"| row | SR (%) | FS (%) | DTG (cm) | ½-s windows > {WALK_SPEED:g} m/s (%) "
             "| fastest ½ s, median (m/s) | time (s) |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for label, row in rows.items():
        lines.append(table_row(label, row))
    if data is not None:
        lines.append(f"| data (test clips) | | {data['FS']:.1f} | | {data['fast']:.1f} | | |")
    for label, (sr, fs, dtg) in PAPER_ROWS.items():
        lines.append(f"| {label} | {sr} | {fs} | {dtg} | | | |")
    angles, heights, distances = grid_values()
    for label, cell_rates in by_cell.items():
        lines += ["", f"SR (%) of '{label}' by goal height (m), angle and distance (m), as the paper's Figure 5:", ""]
        for axis, values in (("height", heights), ("angle (°)", torch.rad2deg(angles)), ("distance", distances)):
            key = axis.split()[0]
            lines.append(f"- {axis}: " + ", ".join(f"{v:.2f}: {s:.0f}" for v, s in zip(values.tolist(), cell_rates[key])))
    if data is not None:
        lines += ["", f"Pelvis ground speed over half-second windows of the test clips: median {data['median']:.2f} m/s, "
                  f"95th percentile {data['p95']:.2f}, fastest {data['max']:.2f}; they include ACCAD's runs (the issue measured "
                  f"CMU's test walks never passing {WALK_SPEED:g} m/s). The speed columns are over every half-second "
                  "span of a rollout before it ends."]
    if throughput is not None:
        lines += ["", f"Prior decode throughput at batch 1,024: {throughput['prior']:,.0f} body-frames/s (decode, integrate, FK); "
                  f"env core step {throughput['env']:,.0f} body-frames/s (adds feet, rewards, goals)."]  # fmt: skip
    else:
        lines += ["", "Run with --no-timing (a busy machine): no throughput measured; the rows' seconds are not speed figures."]
    lines.append("")
    text = "\n".join(lines)
    print(text)
    RESULTS.mkdir(exist_ok=True)
    atomic_write(RESULTS / f"{name}.md", lambda file: file.write(text.encode()))
    figure(by_cell, RESULTS / f"{name}.png", f"WANDR sampler: success by goal position ({count} rollouts)")
    if not quick and throughput is not None:
        replace_section(RESULTS / "throughput.md", "\n".join([
            "## WANDR prior decode", "", machine_line(), "",
            "| batch | prior step (body-frames/s) | env core step (body-frames/s) | target |", "|---|---|---|---|",
            f"| 1,024 | {throughput['prior']:,.0f} | {throughput['env']:,.0f} | ≥ 20,000 |", "",
            f"Whole grid ({count} rollouts of ≤ 240 frames, batches of {SHARD}), sampler row: {rows[main_label]['seconds']:.0f} s "
            f"({rows[main_label]['frames'] / rows[main_label]['seconds']:,.0f} body-frames/s).", ""]))  # fmt: skip
    return 0
