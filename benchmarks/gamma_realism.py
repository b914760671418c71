"""GAMMA's realism check on random latents (`motion-envs bench gamma-realism`).

The paper samples z ~ N(0, I) and compares the motion's contact score
(Eq. 11) and foot skating with real motion (GAMMA FS 0.064 vs ground truth
0.067 in the WANDR paper's table). Here: every shipped start pose (validation
data) is rolled out `rollouts` times for `primitives` primitives with random
z, and the same figures are measured on the validation clips themselves.

FS follows WANDR's definition at the data's 40 fps with WANDR's speed
threshold (0.66 cm per frame at 30 fps = 0.2 m/s, i.e. 0.5 cm per frame
here); the contact-aware FS is `metrics.loaded_foot_skating`. The random
latents run on the raw prior, again with the envs' floor rule
(`ground_feet`) and again with both the floor and the foot rule
(`lock_feet`), as the envs run by default, so the rules hide nothing. Writes
`benchmarks/results/gamma_realism.md` and
`gamma_realism_paths.png` (top-down pelvis paths).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.machine import bench_command, data_options, machine_line
from motion_envs.plots import plt, save, top_down
from motion_envs.atomic import atomic_write
from motion_envs.body import BodyModel
from motion_envs.body.markers import foot_vertex_ids, marker_ids, sole_vertex_ids
from motion_envs.data.build import build
from motion_envs.data.dataset import MotionDataset
from motion_envs.data.primitives import GAMMA_FPS, PRIMITIVE_FRAMES
from motion_envs.data.start_poses import load_start_poses
from motion_envs.metrics import contact_score, foot_skating, loaded_foot_skating, skating_threshold
from motion_envs.body.canonical_frame import PELVIS
from motion_envs.priors.gamma_generator import GammaGenerator
from motion_envs.priors.training import WEIGHTS_DIR
from motion_envs.data.paths import SHIPPED_SUBSETS

RESULTS = Path(__file__).resolve().parent / "results"


def prior_lines() -> list[str]:
    """The shipped priors' validation figures, from `priors/weights/manifest.json`."""
    manifest = json.loads((WEIGHTS_DIR / "manifest.json").read_text())
    lines = ["## Shipped priors (validation split, from the weights manifest)", ""]
    for name in ("gamma_predictor_1f.pt", "gamma_predictor_2f.pt"):
        entry = manifest.get(name)
        if entry is None:
            continue
        errors = entry["validation_marker_error_cm_per_frame"]
        rollout = next(key for key in errors if key.startswith("rollout"))
        lines += [
            f"**{name}** ({entry['epochs']} single-primitive + {entry['rollout_epochs']} rollout epochs; "
            f"`{entry['command']}`): marker error (cm) per predicted frame, posterior mean z:",
            "",
            "| | " + " | ".join(str(i + 1) for i in range(len(errors["primitive"]))) + " | mean |",
            "|---|" + "---|" * (len(errors["primitive"]) + 1),
            "| one primitive | " + " | ".join(f"{e:.2f}" for e in errors["primitive"]) + f" | {np.mean(errors['primitive']):.2f} |",
            "",
            "8-primitive rollout (each seeded by the previous prediction), per frame: "
            + ", ".join(f"{e:.1f}" for e in errors[rollout]) + f"; mean {np.mean(errors[rollout]):.2f}.",
            "",
        ]
    for name in ("gamma_regressor.pt", "gamma_pose_vae.pt"):
        if name in manifest:
            lines += [f"**{name}** (`{manifest[name]['command']}`): {json.dumps(manifest[name]['validation'])}", ""]
    return lines


def motion_figures(markers: torch.Tensor, feet: torch.Tensor, soles: torch.Tensor, pelvis: torch.Tensor) -> dict[str, float]:
    """Figures of N sequences of T frames: markers (N, T, 67, 3), feet (N, T, V, 3), soles (N, T, 4, 3), pelvis
    (N, T, 3), 40 fps.

    Contact score is averaged over the 10-frame windows of each sequence (stride 8, as primitives overlap)."""
    starts = torch.arange(0, markers.shape[1] - PRIMITIVE_FRAMES + 1, PRIMITIVE_FRAMES - 2)
    windows = markers[:, starts[:, None] + torch.arange(PRIMITIVE_FRAMES)].flatten(0, 1)
    speed = (pelvis[:, 1:, :2] - pelvis[:, :-1, :2]).norm(dim=-1) * GAMMA_FPS
    return {
        "contact score (Eq. 11)": float(contact_score(windows, GAMMA_FPS).mean()),
        "FS": float(foot_skating(feet, skating_threshold(GAMMA_FPS)).float().mean()),
        "contact-aware FS": float(loaded_foot_skating(soles, GAMMA_FPS).float().mean()),
        "frames with the lowest foot vertex below -3 cm": float((feet[..., 2].amin(-1) < -0.03).float().mean()),
        "pelvis ground speed (m/s)": float(speed.mean()),
        "pelvis height (m)": float(pelvis[..., 2].mean()),
        "frames with pelvis below 0.6 m": float((pelvis[..., 2] < 0.6).float().mean()),
    }


@torch.no_grad()
def random_motion(gamma: GammaGenerator, rollouts: int, primitives: int, seed: int,
                  ground_feet: bool = False, lock_feet: bool = False) -> dict[str, torch.Tensor]:  # fmt: skip
    """Roll every start pose out `rollouts` times with z ~ N(0, I) (the raw prior, or with the envs' floor and foot
    rules); new frames only, concatenated."""
    starts = load_start_poses(GAMMA_FPS)

    def last(name: str) -> torch.Tensor:
        return torch.as_tensor(starts[name][:, -1], dtype=torch.float32).repeat_interleave(rollouts, dim=0)

    state = gamma.seed_from_bodies(last("transl"), last("global_orient"), last("body_pose"))
    generator = torch.Generator().manual_seed(seed)
    pieces: dict[str, list[torch.Tensor]] = {"markers": [], "transl": [], "global_orient": [], "body_pose": []}
    for step in range(primitives):
        z = torch.randn(state.num_bodies, gamma.latent_size, generator=generator)
        primitive, state = gamma.step(state, z, ground_feet=ground_feet, lock_feet=lock_feet)
        first_new = 0 if step == 0 else 2  # the first primitive's seed frame is the start pose itself
        for name in pieces:
            pieces[name].append(getattr(primitive, name)[:, first_new:])
    return {name: torch.cat(values, dim=1) for name, values in pieces.items()}


def main(mocap_dir: Path | None = None, cache_dir: Path | None = None, subsets: tuple[str, ...] = SHIPPED_SUBSETS,
         rollouts: int = 10, primitives: int = 20, seed: int = 0, weights_dir: Path | None = None,
         output: str = "gamma_realism") -> int:  # fmt: skip
    """`weights_dir`: the GAMMA weights to measure (default: the shipped ones); the table is `output`.md."""
    began = time.perf_counter()
    command = bench_command("gamma-realism", {**data_options(mocap_dir, subsets), "rollouts": rollouts, "weights-dir": weights_dir,
                                              "output": output, "primitives": primitives, "seed": seed})  # fmt: skip
    body, gamma = BodyModel(), GammaGenerator.load(weights_dir or WEIGHTS_DIR)
    feet_rows, sole_rows = body.skin_rows(foot_vertex_ids()), body.skin_rows(sole_vertex_ids())

    def feet_of(transl: torch.Tensor, orient: torch.Tensor, pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Foot vertices (..., V, 3), sole points (..., 4, 3) and pelvis (..., 3) of bodies with 6-D or axis-angle rotations."""
        posed = body(transl, orient, pose)
        return body.skin_with_rows(posed, feet_rows), body.skin_with_rows(posed, sole_rows), posed.joints[..., PELVIS, :]

    generation_began = time.perf_counter()
    generated = random_motion(gamma, rollouts, primitives, seed)
    generation_seconds = time.perf_counter() - generation_began
    grounded = random_motion(gamma, rollouts, primitives, seed, ground_feet=True)
    locked = random_motion(gamma, rollouts, primitives, seed, ground_feet=True, lock_feet=True)
    with torch.no_grad():
        feet, soles, pelvis = feet_of(generated["transl"], generated["global_orient"], generated["body_pose"])
        ours = motion_figures(generated["markers"], feet, soles, pelvis)
        ruled = motion_figures(grounded["markers"], *feet_of(grounded["transl"], grounded["global_orient"], grounded["body_pose"]))
        both = motion_figures(locked["markers"], *feet_of(locked["transl"], locked["global_orient"], locked["body_pose"]))

    report = build(mocap_dir=mocap_dir, cache_dir=cache_dir, subsets=subsets, fps_list=(GAMMA_FPS,))
    dataset = MotionDataset.load(report.caches[GAMMA_FPS])
    frames = generated["markers"].shape[1]
    per_clip, weights = [], []
    with torch.no_grad():
        for clip in dataset.clips("validation"):  # whole clips: most are shorter than a rollout
            tensors = [torch.as_tensor(getattr(clip, name), dtype=torch.float32)[None] for name in ("transl", "global_orient", "body_pose")]
            per_clip.append(motion_figures(body.skin(body(*tensors), marker_ids()), *feet_of(*tensors)))
            weights.append(clip.num_frames)
    data = {name: float(np.average([figures[name] for figures in per_clip], weights=weights)) for name in ours}

    bodies = generated["markers"].shape[0]
    lines = [
        "# GAMMA realism: random latents against the data",
        "",
        f"Random z ~ N(0, I): {bodies} rollouts ({len(load_start_poses(GAMMA_FPS)['kind'])} shipped start poses × {rollouts}), "
        f"{primitives} primitives each ({frames} new frames at 40 fps, {frames / GAMMA_FPS:.1f} s), seed {seed}. "
        f"Data: the {len(per_clip)} validation clips ({sum(weights)} frames), figures averaged over clips by length.",
        "",
        "| | generated (random z), raw prior | generated, with the envs' floor rule | with the floor and foot rules (the envs' default) | validation data | GAMMA paper: generated / data |",
        "|---|---|---|---|---|---|",
    ]
    paper = {"FS": "0.064 / 0.067 (WANDR Tab. 1)", "contact score (Eq. 11)": "plotted in Fig. 3 (values not in the text)"}
    for name in ours:
        lines.append(f"| {name} | {ours[name]:.3f} | {ruled[name]:.3f} | {both[name]:.3f} | {data[name]:.3f} | {paper.get(name, '')} |")
    lines += [
        "",
        f"Generation: {bodies * primitives / generation_seconds:,.0f} body-primitives/s "
        f"({generation_seconds:.1f} s for {bodies} bodies × {primitives} primitives, one batch).",
        "",
        *prior_lines(),
        machine_line(),
        f"Command: `{command}`; "
        f"{time.perf_counter() - began:.0f} s in all.",
        "",
        f"![pelvis paths]({output}_paths.png)",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    RESULTS.mkdir(parents=True, exist_ok=True)
    atomic_write(RESULTS / f"{output}.md", lambda file: file.write(text.encode()))
    figure, axis = plt.subplots(figsize=(5, 5))
    top_down(axis, pelvis[:: max(1, rollouts // 2), :, :2].numpy(), title=f"pelvis paths, random z, {frames / GAMMA_FPS:.1f} s")
    save(figure, RESULTS / f"{output}_paths.png", dpi=120)
    return 0
