"""How far does each of CLOPS's actions carry the body? (`motion-envs bench clops-actions`)

Every ClopsNav action is a head-pose target one second of data away (k-means
over the mocap's one-second head motions, `priors.train_clops.fit_head_actions`);
the prior generates frames until the head gets there or `max_chunk_frames`
(30) have passed. A prior that keeps the data's pace reaches its targets; a
slow one times out short of them, and a 15-s episode covers less of the room.
This check gives each action to the same bodies `actions` times in a row
(held-out open rooms, one body per room and action) and reports, per action,
the target's ground distance and turn, and for each prior the head's ground
travel per action, the frames an action took and the share of actions that
ran out of frames.

What it showed (AMX Xeon, 8 rooms): the prior retrained on the cleaned data
(`priors/weights/clean/clops.pt`) moves the head 0.59 m per walking action
(targets more than 0.5 m away) of the 0.94 m they ask, and 64-98% of those
actions run out of frames; the default prior it was meant to replace 0.83 m
of 1.10 m. It is why ClopsNav DQNs trained on the clean prior learn less in
the same number of actions (README, ClopsNav). The shipped upright prior
(`clops_upright`, the replaced default's action set): 0.82 m of 1.10 m, its
short turning actions 16-20 frames against the replaced default's 13-20
(without its turn term 20-28; AVX-512 EPYC).
Writes `benchmarks/results/clops_actions.md`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from benchmarks.machine import bench_command, machine_line
from motion_envs.atomic import atomic_write
from motion_envs.envs.clops_nav import ClopsNavConfig, ClopsNavCore
from motion_envs.priors.clops import HEAD_JOINT

RESULTS = Path(__file__).resolve().parent / "results"


@torch.no_grad()
def action_travel(weights: Path, rooms: int, actions: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Per action k (K,): "targets" (K, 2) ground distance (m) and |turn| (°) of the action's head target; "travel" head
    ground travel per action (m), "frames" per action and "timed_out" share of actions that used every frame, over
    `rooms` bodies given action k `actions` times (bodies whose episode ended stop counting)."""
    config = ClopsNavConfig(family="open", split="test", weights=str(weights))
    core = ClopsNavCore(config)
    count = core.num_actions
    chosen = torch.arange(count).repeat(rooms)
    rngs = [np.random.default_rng([seed, body]) for body in range(len(chosen))]
    state = core.sample_initial_state(rngs, {"scene_seed": [core.config.seeds[body // count % len(core.config.seeds)]
                                                            for body in range(len(chosen))]})  # fmt: skip
    travel, frames, timed_out, counted = (torch.zeros(len(chosen)) for _ in range(4))
    alive = torch.ones(len(chosen), dtype=torch.bool)
    for _ in range(actions):
        head = state.joints[:, HEAD_JOINT, :2].clone()
        state, result = core.step(state, chosen)
        moved = (state.joints[:, HEAD_JOINT, :2] - head).norm(dim=-1)
        travel[alive] += moved[alive]
        frames[alive] += result.frames[alive].float()
        timed_out[alive] += (result.frames[alive] >= config.max_chunk_frames).float()
        counted[alive] += 1
        alive &= ~(result.terminated | result.truncated)
    per_action = {name: torch.zeros(count).index_add_(0, chosen, values) / torch.zeros(count).index_add_(0, chosen, counted)
                  for name, values in (("travel", travel), ("frames", frames), ("timed_out", timed_out))}  # fmt: skip
    targets = core.prior.actions.cpu()
    return {"targets": torch.stack([targets[:, :2].norm(dim=-1), targets[:, 3].abs() * 180 / math.pi], 1).numpy(),
            **{name: values.numpy() for name, values in per_action.items()}}


def main(weights: list[Path], rooms: int = 8, actions: int = 6) -> int:
    """Print and write the table for CLOPS priors `weights` (each with its own action set)."""
    lines = ["# How far CLOPS's actions carry the body", "",
             f"Each action given {actions} times in a row to {rooms} bodies (one per held-out open room). Per action: the "
             "target's ground distance and turn (the prior's own action set, k-means over the data's one-second head "
             "motions), the head's ground travel per action, the frames per action and the share of actions that used "
             "all 30 frames without reaching the target. "
             f"`{bench_command('clops-actions', {'weights': list(weights), 'rooms': rooms})}`.", machine_line(), ""]  # fmt: skip
    for path in weights:
        figures = action_travel(path, rooms, actions)
        order = np.argsort(-figures["targets"][:, 0])
        lines += [f"**{path}**", "", "| action | target (m) | target turn (°) | travel (m) | frames | timed out |",
                  "|---|---|---|---|---|---|"]  # fmt: skip
        for k in order:
            lines.append(f"| {k} | {figures['targets'][k, 0]:.2f} | {figures['targets'][k, 1]:.0f} | {figures['travel'][k]:.2f} | "
                         f"{figures['frames'][k]:.1f} | {figures['timed_out'][k]:.2f} |")  # fmt: skip
        walking = figures["targets"][:, 0] > 0.5
        lines += ["", f"Actions with targets > 0.5 m away: mean travel {figures['travel'][walking].mean():.2f} m against "
                      f"{figures['targets'][walking, 0].mean():.2f} m asked.", ""]  # fmt: skip
    text = "\n".join(lines) + "\n"
    print(text)
    atomic_write(RESULTS / "clops_actions.md", lambda file: file.write(text.encode()))
    return 0
