"""Left and right turns of GAMMA's prior and of the shipped policy (`motion-envs bench gamma-turns`).

The prior is trained on every clip and its mirror image (`MarkerClips.from_dataset(..., mirrored=True)`), so
it should turn left as often as right (`mirror` turns a left turn into a right one: tested). Three measurements,
bodies from the env's start poses (1,024 for the prior, a quarter of that per policy row):

- the prior under z ~ N(0, I): each body's heading change (`rewards.facing_direction`, + left) over the first
  2 s and over the next 4 s, with the share turning more than 30° / 90° either way;
- one primitive of the prior's mean (z = 0) seeded with held-out data windows and with their mirror images,
  against how the data goes on (`one_primitive_turns`), and the same over every training window of the prior,
  each stage on its own (`training_window_turns`; needs the mocap folder);
- the shipped alpha = 1 policy (sampled latents) towards a goal 90° to the body's left or right, 4 or 12 m away:
  the heading change over the first 6 s (a body that turns the long way round shows about +270° for a goal on
  its right) and the share that reached the goal by 6 s and by 15 s (60 primitives).

Each measurement of the prior is made as trained and with its heading calibration (`motion_envs.priors.
gamma_heading`) when the weights have one; the policy rows run on the prior the policy was trained on (its env
options) and, for comparison, on the other one.

Writes `benchmarks/results/gamma_turns.md`.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import torch

from agents.controllers import PolicyLatent
from benchmarks.machine import bench_command, machine_line
from motion_envs.atomic import atomic_write
from motion_envs.body.rotations import matrix_to_sixd, rotation_matrix, wrap_angle
from motion_envs.data.build import build
from motion_envs.data.dataset import MotionDataset
from motion_envs.data.paths import SHIPPED_SUBSETS, default_mocap_dir
from motion_envs.data.mirror import mirror
from motion_envs.data.motion import BodyMotion
from motion_envs.data.primitives import GAMMA_FPS, PRIMITIVE_FRAMES, MarkerClips
from motion_envs.data.start_poses import load_start_poses
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore, GammaReachState
from motion_envs.priors.gamma_generator import GammaGenerator, GammaSeed
from motion_envs.priors.gamma_heading import facing_yaw, regressed_joints, rotate_about_centroids
from motion_envs.priors.training import WEIGHTS_DIR

RESULTS = Path(__file__).resolve().parent / "results"
POLICY = WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip"
PRIMITIVES_PER_SECOND = 4


def heading(state: GammaReachState) -> torch.Tensor:
    """(N,) radians: the facing direction at the last frame of the latest primitive."""
    return facing_yaw(state.seed.joints[:, -1])


def starts(core: GammaReachCore, count: int, seed: int, bearing: torch.Tensor | None = None,
           distance: torch.Tensor | None = None) -> GammaReachState:  # fmt: skip
    """`count` bodies from random start poses and facings; goals at `bearing` (N,) radians from each body's
    measured facing (+ left) and `distance` (N,) m, or 50 m ahead when not given."""
    rng = np.random.default_rng(seed)
    facing = torch.as_tensor(rng.uniform(-math.pi, math.pi, count), dtype=torch.float32)
    rows = torch.as_tensor(rng.integers(0, core.num_starts, count))
    placed = core.initial_state(rows, facing, torch.zeros(count, 2))
    bearing = torch.zeros(count) if bearing is None else bearing
    distance = torch.full((count,), 50.0) if distance is None else distance
    direction = heading(placed) + bearing
    pelvis = placed.seed.joints[:, -1, 0, :2]
    goal = pelvis + distance[:, None] * torch.stack([direction.cos(), direction.sin()], dim=1)
    return core.initial_state(rows, facing, goal)


def turned(core: GammaReachCore, state: GammaReachState, act, primitives: int) -> tuple[torch.Tensor, torch.Tensor, GammaReachState]:
    """Heading change (N,) radians (+ left) and reached flags (N,) over `primitives` steps of `act(state)`."""
    previous, total = heading(state), torch.zeros(state.num_bodies)
    reached = torch.zeros(state.num_bodies, dtype=torch.bool)
    for _ in range(primitives):
        state, result = core.step(state, act(state))
        now = heading(state)
        total += wrap_angle(now - previous)
        previous, reached = now, reached | result.reached.cpu()
    return total, reached, state


def start_windows() -> list[BodyMotion]:
    """The env's start windows (10 frames of held-out data each) as motions."""
    poses = load_start_poses(GAMMA_FPS)
    return [BodyMotion("start", "data", GAMMA_FPS, *(poses[name][row] for name in ("transl", "global_orient", "body_pose")))
            for row in range(len(poses["transl"]))]  # fmt: skip


def one_primitive_turns(generator: GammaGenerator, windows: list[BodyMotion]) -> tuple[float, float]:
    """Mean heading change (degrees, + left) from the second to the last frame of `windows` (10 frames each), as
    the data goes on and as the prior's mean primitive (z = 0, seeded with the windows' first two frames, no
    floor or foot rule) goes on."""
    transl, orient, pose = (torch.as_tensor(np.stack([getattr(w, name) for w in windows]), dtype=torch.float32)
                            for name in ("transl", "global_orient", "body_pose"))  # fmt: skip
    orient, pose = matrix_to_sixd(rotation_matrix(orient)), matrix_to_sixd(rotation_matrix(pose))
    joints, markers = generator.markers_of(transl, orient, pose)  # (W, 10, ...)
    count = len(transl)
    seed = GammaSeed(torch.full((count,), 2), markers[:, :2], markers[:, :2], joints[:, :2], transl[:, :2], orient[:, :2],
                     pose[:, :2])  # fmt: skip
    primitive, _ = generator.step(seed, torch.zeros(count, generator.latent_size))

    def change(end: torch.Tensor) -> float:
        return math.degrees(float(wrap_angle(facing_yaw(end) - facing_yaw(joints[:, 1])).mean()))

    return change(joints[:, -1]), change(primitive.joints[:, -1])


def training_window_turns(generator: GammaGenerator, clips: MarkerClips, stride: int = 4) -> list[tuple[str, torch.Tensor]]:
    """Heading changes (W,) degrees (+ left) from the second to the last frame of every 10-frame training window
    (`stride` apart; canonical, as the predictor trains on them): the data's; the bodies the regressor makes of
    the data's own markers (the regressor alone); the 2-frame predictor's mean primitive (z = 0) from the data's
    first two frames, read as the generator reads it, through the regressor (predictor and regressor), and the same
    heading-calibrated when the generator's calibration is on."""
    windows = clips.windows(clips.window_starts(PRIMITIVE_FRAMES, stride), PRIMITIVE_FRAMES)

    def change(new_joints: torch.Tensor) -> torch.Tensor:  # (W, 8, 22, 3) -> (W,)
        return torch.rad2deg(wrap_angle(facing_yaw(new_joints[:, -1]) - facing_yaw(windows.joints[:, 1])))

    def regressed(markers: torch.Tensor) -> torch.Tensor:  # (W, 8, 67, 3) -> joints (W, 8, 22, 3)
        return regressed_joints(generator.regressor, generator.body, markers)

    seed = windows.markers[:, :2].flatten(2)
    predicted = generator.predictor_2f.decode(seed, seed.new_zeros(len(seed), generator.latent_size)).unflatten(-1, (-1, 3))
    rows = [("the data", change(windows.joints[:, 2:])), ("the regressor, from the data's markers", change(regressed(windows.markers[:, 2:]))),
            ("the predictor (z = 0) and the regressor", change(regressed(predicted)))]  # fmt: skip
    if generator.heading_calibration is not None:
        calibrated = rotate_about_centroids(predicted, -generator.heading_calibration.correction("predictor_2f"))
        rows.append(("the same, heading-calibrated", change(regressed(calibrated))))
    return rows


def training_window_lines(generator: GammaGenerator) -> list[str]:
    """The table of `training_window_turns` on the shipped data's training split (mirror images included,
    as the prior trains), or a line saying why there is none."""
    mocap = default_mocap_dir()
    if mocap is None:
        return ["No mocap folder (`MOTION_ENVS_DATA` or `../shared/mocap`): the training-window rows are skipped."]
    dataset = MotionDataset.load(build(mocap, subsets=SHIPPED_SUBSETS, fps_list=(GAMMA_FPS,), progress=False).caches[GAMMA_FPS])
    clips = MarkerClips.from_dataset(dataset, "train", generator.body, mirrored=True)
    turns = training_window_turns(generator, clips)
    lines = [f"Every 10-frame window of the prior's training split ({len(turns[0][1]):,}, every 4th frame, "
             f"`{dataset.path.stem}`, mirror images included): the heading change from the second to the last frame, "
             "each stage of the generator on its own (`training_window_turns`). The data turn left and right alike; "
             "a bias here is the network's, on windows it was trained on.", "",
             "| heading change of | mean (+ left) | left > 10° | right > 10° |", "|---|---|---|---|"]  # fmt: skip
    for label, degrees in turns:
        lines.append(f"| {label} | {degrees.mean():+.2f}° | {(degrees > 10).float().mean():.3f} | {(degrees < -10).float().mean():.3f} |")
    return lines


def shares(degrees: np.ndarray) -> str:
    """Table cells: median, left > 30°, right > 30°, left > 90°, right > 90°."""
    return (f"{np.median(degrees):+.0f}° | {np.mean(degrees > 30):.2f} | {np.mean(degrees < -30):.2f} "
            f"| {np.mean(degrees > 90):.2f} | {np.mean(degrees < -90):.2f}")  # fmt: skip


def calibration_settings(generator: GammaGenerator) -> list[tuple[str, bool]]:
    """(label, on) for the prior as trained and, where its weights have one, with its heading calibration."""
    try:
        generator.set_heading_calibration(True)
    except FileNotFoundError:
        return [("as trained", False)]
    finally:
        generator.set_heading_calibration(False)
    return [("as trained", False), ("heading-calibrated", True)]


def prior_lines(core: GammaReachCore, settings: list[tuple[str, bool]], bodies: int, seed: int) -> list[str]:
    """The z ~ N(0, I) table and the held-out one-primitive table, one row per calibration setting."""
    def normal(state: GammaReachState) -> torch.Tensor:
        return torch.randn(state.num_bodies, core.generator.latent_size)

    latent_rows, window_rows = [], []
    for label, on in settings:
        core.generator.set_heading_calibration(on)
        torch.manual_seed(seed)
        first, _, state = turned(core, starts(core, bodies, seed), normal, 2 * PRIMITIVES_PER_SECOND)
        later, _, _ = turned(core, state, normal, 4 * PRIMITIVES_PER_SECOND)
        latent_rows += [f"| z ~ N(0, I), {label} | 0-2 | {shares(np.degrees(first.numpy()))} |",
                        f"| z ~ N(0, I), {label} | 2-6 | {shares(np.degrees(later.numpy()))} |"]  # fmt: skip
        windows = start_windows()
        for kind, seeds in (("held-out windows", windows), ("their mirror images", [mirror(w) for w in windows])):
            data, prior = one_primitive_turns(core.generator, seeds)
            window_rows.append(f"| {kind}, {label} | {data:+.2f}° | {prior:+.2f}° | {prior - data:+.2f}° |")
    core.generator.set_heading_calibration(False)
    return ["| latents, prior | seconds | median heading change (+ left) | left > 30° | right > 30° | left > 90° | right > 90° |",
            "|---|---|---|---|---|---|---|", *latent_rows, "",
            "One primitive (8 new frames, 0.2 s) of the prior's mean (z = 0) from the 48 held-out start windows' first "
            "two frames, against how the data goes on, and the same for the windows' mirror images: a prior that "
            "treats left and right alike turns the mirrored seeds by minus what it turns the originals.", "",
            "| seeds, prior | data's turn (+ left) | prior's turn, z = 0 | prior minus data |", "|---|---|---|---|", *window_rows]  # fmt: skip


def policy_lines(core: GammaReachCore, settings: list[tuple[str, bool]], bodies: int, seed: int) -> list[str]:
    """The alpha = 1 policy's rows towards goals 90° left and right, on each prior setting."""
    policy = PolicyLatent(POLICY, seed=seed)
    trained = policy.file.trained_for
    trained_on = bool(trained and trained.env_kwargs.get("heading_calibration"))
    lines = ["| policy, prior, goal | bodies | heading change over 6 s (+ left) | left > 30° | right > 30° | left > 90° | "
             "right > 90° | reached by 6 s | reached by 15 s |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for label, on in sorted(settings, key=lambda setting: setting[1] != trained_on):
        core.generator.set_heading_calibration(on)
        prior = f"{label}{' (its own)' if on == trained_on else ''}"
        for side, sign in (("left", 1.0), ("right", -1.0)):
            for distance in (4.0, 12.0):
                count = bodies // 4
                state = starts(core, count, seed + 1, torch.full((count,), sign * math.pi / 2), torch.full((count,), distance))
                change, early, state = turned(core, state, lambda s: policy(core, s), 6 * PRIMITIVES_PER_SECOND)
                _, late, _ = turned(core, state, lambda s: policy(core, s), 9 * PRIMITIVES_PER_SECOND)
                lines.append(f"| alpha = 1, {prior}, 90° {side}, {distance:.0f} m | {count} | "
                             f"{shares(np.degrees(change.numpy()))} | {early.float().mean():.2f} | {(early | late).float().mean():.2f} |")  # fmt: skip
    core.generator.set_heading_calibration(False)
    return lines


def main(bodies: int = 1024, seed: int = 0) -> int:
    began = time.perf_counter()
    core = GammaReachCore(GammaReachConfig(terminate_on_goal=False))
    settings = calibration_settings(core.generator)
    lines = ["# GAMMA's turns, left and right", "", "\n\n".join(__doc__.split("\n\n")[1:4]).strip(), "",
             *prior_lines(core, settings, bodies, seed), ""]  # fmt: skip
    core.generator.set_heading_calibration(len(settings) > 1)
    lines += [*training_window_lines(core.generator), ""]
    core.generator.set_heading_calibration(False)
    lines += policy_lines(core, settings, bodies, seed)
    lines += ["", machine_line(), f"Command: `{bench_command('gamma-turns', {'bodies': bodies, 'seed': seed})}`; "
              f"{time.perf_counter() - began:.0f} s.", ""]
    text = "\n".join(lines)
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic_write(RESULTS / "gamma_turns.md", lambda file: file.write(text.encode()))
    print(text)
    return 0
