"""Rendering speed (`motion-envs bench render`): third-person frames/s at 480 × 360 and egocentric
frames/s at 64 × 64 on this machine.

Third person: real poses (the shipped start poses) with a following camera,
goal sphere and trail, one and eight bodies per image, on the bare ground and
inside a procedural room (`living`, seed 0). Egocentric: the CLOPS
observation (depth, semantic colours, goal mask) from head cameras at free
positions of the same room, batches of 1 to 256 bodies. Writes the
"Third-person rendering" and "Egocentric views" sections of
`benchmarks/results/throughput.md` (other sections are kept).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from benchmarks.machine import machine_line
from benchmarks.sections import replace_section
from benchmarks.throughput import command_line
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.data.start_poses import load_start_poses
from motion_envs.render.camera import follow_camera
from motion_envs.render.egocentric import EgocentricRenderer
from motion_envs.render.third_person import ThirdPersonRenderer
from motion_envs.scenes import make_scene

RESULTS = Path(__file__).resolve().parent / "results"
THIRD_PERSON, EGOCENTRIC = "## Third-person rendering", "## Egocentric views"
SCENE = ("living", 0)


def median_seconds(run: Callable[[int], None], repeats: int) -> float:
    """Median wall time of `run(i)` over `repeats` calls, after one warm-up call."""
    run(0)
    seconds = []
    for index in range(repeats):
        began = time.perf_counter()
        run(index)
        seconds.append(time.perf_counter() - began)
    return float(np.median(seconds))


def third_person_fps(renderer: ThirdPersonRenderer, vertices: np.ndarray, centre: np.ndarray, frames: int = 40) -> float:
    """Frames/s rendering `vertices` (B, V, 3) with a camera that moves every frame."""
    trail = centre + np.stack([np.linspace(-2, 0, 30), np.zeros(30), np.zeros(30)], axis=1)
    goal = centre + np.array([1.0, 1.0, 0.3])

    def frame(index: int) -> None:
        shift = np.array([0.02 * index, 0.0, 0.0])
        renderer.render(vertices + shift, follow_camera(centre + shift), goal=goal, goal_radius=0.1, trail=trail, goal_shape="sphere")

    return 1.0 / median_seconds(frame, frames)


def egocentric_fps(renderer: EgocentricRenderer, bodies: int, repeats: int = 10) -> float:
    """Body-frames/s of `bodies` head cameras at free positions, random headings, a goal in the room."""
    rng = np.random.default_rng(0)
    eye = torch.tensor(np.c_[renderer.scene.sample_free(rng, bodies), np.full(bodies, 1.6)], dtype=torch.float32)
    yaw = torch.tensor(rng.uniform(0, 2 * np.pi, bodies), dtype=torch.float32)
    rotation = torch.zeros(bodies, 3, 3)
    rotation[:, 0, 0], rotation[:, 1, 0], rotation[:, 0, 1], rotation[:, 1, 1], rotation[:, 2, 2] = yaw.cos(), yaw.sin(), -yaw.sin(), yaw.cos(), 1
    goal = torch.tensor(np.c_[renderer.scene.sample_free(rng, bodies), np.full(bodies, 1.0)], dtype=torch.float32)
    return bodies / median_seconds(lambda _: renderer.render(eye, rotation, goal), repeats)


def main(output: str = "throughput") -> int:
    """Writes the two sections into `benchmarks/results/<output>.md` (other sections are kept)."""
    began = time.perf_counter()
    starts = load_start_poses(GAMMA_FPS)
    scene = make_scene(*SCENE)
    centre = np.array([*scene.sample_free(np.random.default_rng(1), 1)[0], 0.9])
    bare, furnished = ThirdPersonRenderer(), ThirdPersonRenderer(scene=scene)

    def bodies(count: int) -> np.ndarray:
        rows = np.arange(count) * 5 % len(starts["kind"])
        vertices = bare.vertices(*(torch.as_tensor(starts[name][rows, -1]) for name in ("transl", "global_orient", "body_pose")))
        vertices[..., 2] -= vertices[..., 2].min(axis=1, keepdims=True)  # on the ground
        vertices[..., :2] -= vertices[..., :2].mean(axis=1, keepdims=True)
        vertices[..., 0] += np.linspace(-1.5, 1.5, count)[:, None] if count > 1 else 0.0  # side by side
        vertices[..., :2] += centre[:2]
        return vertices

    rows = [(where, count, third_person_fps(renderer, bodies(count), centre))
            for where, renderer in (("bare ground", bare), (f"room ({SCENE[0]}, seed {SCENE[1]})", furnished)) for count in (1, 8)]  # fmt: skip
    lines = [THIRD_PERSON, "", f"480 × 360, body mesh at {len(bare.mesh.faces):,} triangles per body ({len(bare.crowd_mesh.faces):,} with several "
             "bodies in the image; vertex-clustered LODs of "
             "mannequin-x's wooden mesh, rebuilt in embree every frame), the room's walls and furniture cut away at 1.2 m, "
             "analytic ground, goal sphere and trail; median of 40 frames with a moving camera. Target (issue 7): ≥ 20 frames/s.",
             "", "| where | bodies per image | frames/s |", "|---|---|---|"]  # fmt: skip
    lines += [f"| {where} | {count} | {fps:.1f} |" for where, count, fps in rows]
    lines += ["", machine_line(), f"Command: `{command_line('render', output)}`.", ""]
    third = "\n".join(lines)

    ego_rows = []
    for size in (64, 128):
        renderer = EgocentricRenderer(scene, width=size, height=size)
        ego_rows += [(size, count, egocentric_fps(renderer, count)) for count in ((1, 16, 64, 256) if size == 64 else (64,))]
    lines = [EGOCENTRIC, "", f"The CLOPS observation (depth, semantic RGB, goal mask; 90° field of view) from head cameras in "
             f"`{SCENE[0]}` seed {SCENE[1]} ({len(scene.faces):,} triangles): one embree cast per thread for all bodies' rays, "
             "the goal sphere analytic. Median of 10 batches. Target (issue 7): ≥ 1,000 frames/s at 64 × 64.", "",
             "| resolution | bodies per call | body-frames/s | rays/s |", "|---|---|---|---|"]  # fmt: skip
    lines += [f"| {size} × {size} | {count} | {fps:,.0f} | {fps * size * size / 1e6:.1f} M |" for size, count, fps in ego_rows]
    lines += ["", machine_line(), f"Command: `{command_line('render', output)}`; {time.perf_counter() - began:.0f} s for both sections.", ""]
    ego = "\n".join(lines)
    print(third + "\n" + ego)
    replace_section(RESULTS / f"{output}.md", third)
    replace_section(RESULTS / f"{output}.md", ego)
    return 0
