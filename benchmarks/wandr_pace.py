"""Does WANDR's prior keep the pace its wrist intention asks for? (`motion-envs bench wandr-pace`)

The grid's 8-s sampler fails (3.5% SR) because the body falls behind the
deadline and cannot catch up (`benchmarks.wandr_grid`). This check removes
every out-of-distribution factor: it takes the prior's own *training*
windows (CMU, 30 fps) in which the pelvis travels more than `min_travel`
in `horizon` frames, gives the prior the data's start state and, as the
goal, the right wrist at the window's last frame due at that frame (I^w's
t_G), and rolls out the intention loop (`WandrStepper`, as WandrReach) with
z ~ N(0, I) and with z = 0. Per second it prints the median ground distance
from the pelvis to the goal for the data and for each prior: a prior that
follows its intention tracks the data's column.

Writes `benchmarks/results/wandr_pace.md`. What it showed (165 windows,
> 2 m in 6 s): the shipped prior falls behind from the third second on
(median 2.17 m left after 4 s where the data has 1.29 m; with z = 0,
2.57 m) and reaches the wrist goal at the deadline in 1% of the windows,
on the data it was trained on. It walks too slowly rather than astray: by
4 s its pelvis has walked 1.15 m where the data walked 2.78 m (the first
second matches). Raising the KL weight to β = 1 (8 epochs fine-tuned from
the shipped prior) halves the lag in the middle seconds (1.54 m left after
4 s) but averages the motion (FS 94% against 72% on 500 grid rollouts).
Neither ten more epochs, time-warped copies of the clips (0.6× and 0.8×
pace), goals only ≥ 1.5 m away (the release; also from scratch: 2.06 m
left after 4 s), 30-frame training rollouts nor a learned conditional
prior p(z | c) (Sohn et al.'s prior network, `WandrConfig.learned_prior`;
from scratch: 2.07 m left after 4 s) moved the lag (`wandr_grid`'s module doc has
their grid figures). A pace term in training does (`train wandr
--pace-weight`, `priors/train_wandr.py`: 0.80 -> 0.44 / 0.37 m left after
6 s at weights 0.01 / 0.03, the data 0.34), at the cost of 15-s walks that
sink more unless an upright term comes with it (0.43 m; the recipe's
`wandr_paced` stage, which `wandr_upright` fine-tunes further); the table in
`results/wandr_pace.md` compares them.
"""

from __future__ import annotations

from pathlib import Path

import torch

from benchmarks.machine import bench_command, machine_line
from motion_envs.atomic import atomic_write
from motion_envs.body import BodyModel
from motion_envs.priors.train_wandr import WandrClips, load_wandr
from motion_envs.priors.wandr import WandrStepper
from motion_envs.priors.wandr_features import FPS, PELVIS, RIGHT_WRIST

RESULTS = Path(__file__).resolve().parent / "results"


def far_windows(clips: WandrClips, horizon: int, min_travel: float, stride: int = 5) -> torch.Tensor:
    """(W,) window starts whose pelvis moves more than `min_travel` m on the ground over `horizon` frames."""
    starts = clips.window_starts(horizon, stride)
    travel = (clips.joints[starts + horizon, PELVIS, :2] - clips.joints[starts, PELVIS, :2]).norm(dim=-1)
    return starts[travel > min_travel]


def left_and_walked(pelvis: torch.Tensor, goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Pelvis ground tracks (W, F + 1, 2) from frame 0 -> at the end of every second (F // FPS, W): the distance
    left to the goals' ground points (W, 2) and the path walked so far, metres."""
    seconds = torch.arange(FPS, pelvis.shape[1], FPS)
    walked = torch.cat([pelvis.new_zeros(len(pelvis), 1), (pelvis[:, 1:] - pelvis[:, :-1]).norm(dim=-1).cumsum(1)], 1)
    return (pelvis[:, seconds] - goal[:, None]).norm(dim=-1).T, walked[:, seconds].T


@torch.no_grad()
def pace(stepper: WandrStepper, clips: WandrClips, starts: torch.Tensor, horizon: int, sigma: float,
         seed: int = 0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:  # fmt: skip
    """Roll the prior out from the data at `starts` (W,) towards the wrist at `starts + horizon`, due then.

    Returns `left_and_walked` of its pelvis (each (horizon // FPS, W)) and the final wrist-to-goal distance
    (W,), metres.
    """
    goal_frames = starts + horizon
    goal = clips.joints[goal_frames, RIGHT_WRIST]
    generator = torch.Generator().manual_seed(seed)
    state = clips.state(starts)
    track = [state.joints[:, PELVIS, :2]]
    for frame in range(1, horizon + 1):
        z = sigma * torch.randn(len(starts), stepper.prior.config.latent, generator=generator)
        state, _ = stepper.step(state, z, goal, goal_frames - (starts + frame - 1))
        track.append(state.joints[:, PELVIS, :2])
    return *left_and_walked(torch.stack(track, 1), goal[:, :2]), (state.joints[:, RIGHT_WRIST] - goal).norm(dim=-1)


def prior_labels(weights: list[Path]) -> list[str]:
    """Each prior's column name: its file's stem, with its folder where another prior shares the stem (every
    prior is saved as wandr.pt, and columns of the same name would overwrite each other)."""
    stems = [path.stem for path in weights]
    return [f"{path.parent.name}/{path.stem}" if stems.count(path.stem) > 1 else path.stem for path in weights]


def main(weights: list[Path], horizon_s: int = 6, min_travel: float = 2.0) -> int:
    """Print and write the pace table for each prior in `weights` (default: the shipped one)."""
    from benchmarks.wandr_grid import training_clips

    clips = training_clips()
    if clips is None:
        return 1
    horizon = horizon_s * FPS
    starts = far_windows(clips, horizon, min_travel)
    if len(starts) == 0:
        raise ValueError(f"no training window travels more than {min_travel} m in {horizon_s} s")
    data = left_and_walked(clips.joints[starts[:, None] + torch.arange(horizon + 1), PELVIS, :2],
                           clips.joints[starts + horizon, RIGHT_WRIST, :2])  # fmt: skip
    columns = {"data": tuple(values.median(1).values for values in data)}
    reached = {}
    body = BodyModel()
    for path, prior_label in zip(weights, prior_labels(weights)):
        stepper = WandrStepper(load_wandr(path).eval(), body)
        for sigma, name in ((1.0, "z ~ N(0, I)"), (0.0, "z = 0")):
            left, walked, wrist = pace(stepper, clips, starts, horizon, sigma)
            label = f"{prior_label}, {name}"
            columns[label] = (left.median(1).values, walked.median(1).values)
            reached[label] = 100 * float((wrist < 0.1).float().mean())
    lines = ["# WANDR pace on the prior's own training windows", "",
             f"{len(starts)} CMU training windows (mirrored included) whose pelvis travels > {min_travel} m in {horizon_s} s; "
             f"goal: the right wrist at the window's end, due then. Medians at the end of each second: pelvis-to-goal ground "
             f"distance (m), and in brackets the ground path the pelvis has walked (m). "
             f"`{bench_command('wandr-pace', {'weights': list(weights)})}`.", machine_line(), "",
             "| s | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]  # fmt: skip
    for second in range(horizon_s):
        lines.append(f"| {second + 1} | " + " | ".join(f"{left[second]:.2f} ({walked[second]:.2f})" for left, walked in columns.values()) + " |")
    lines += ["", "Wrist within 10 cm of the goal at the deadline: "
              + ", ".join(f"{label} {rate:.0f}%" for label, rate in reached.items()) + ".", ""]  # fmt: skip
    text = "\n".join(lines)
    print(text)
    RESULTS.mkdir(exist_ok=True)
    atomic_write(RESULTS / "wandr_pace.md", lambda file: file.write(text.encode()))
    return 0
