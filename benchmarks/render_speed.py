"""Third-person rendering speed (`motion-envs bench render`): frames/s at 480 × 360 on this machine.

Renders real poses (the shipped start poses) with a following camera, goal
and trail, one body and eight bodies per image; writes the "Third-person
rendering" section of `benchmarks/results/throughput.md` (other sections of
that file are kept).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.machine import machine_line
from benchmarks.sections import replace_section
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.data.start_poses import load_start_poses
from motion_envs.render.camera import follow_camera
from motion_envs.render.third_person import ThirdPersonRenderer

RESULTS = Path(__file__).resolve().parent / "results"
SECTION = "## Third-person rendering"


def frames_per_second(renderer: ThirdPersonRenderer, vertices: np.ndarray, frames: int = 40) -> float:
    """Median-of-runs frames/s rendering `vertices` (B, V, 3) with a camera that moves every frame."""
    trail = np.stack([np.linspace(0, 2, 30), np.linspace(-3, 0, 30), np.full(30, 0.9)], axis=1)
    renderer.render(vertices, follow_camera(np.array([0.0, 0.0, 0.9])), goal=np.array([3.0, 2.0, 0.0]), trail=trail)
    seconds = []
    for frame in range(frames):
        camera = follow_camera(np.array([0.02 * frame, 0.0, 0.9]))
        began = time.perf_counter()
        renderer.render(vertices + np.array([0.02 * frame, 0.0, 0.0]), camera, goal=np.array([3.0, 2.0, 0.0]), trail=trail)
        seconds.append(time.perf_counter() - began)
    return 1.0 / float(np.median(seconds))


def main() -> int:
    starts = load_start_poses(GAMMA_FPS)
    renderer = ThirdPersonRenderer()

    def bodies(count: int) -> np.ndarray:
        rows = np.arange(count) * 5 % len(starts["kind"])
        vertices = renderer.vertices(*(torch.as_tensor(starts[name][rows, -1]) for name in ("transl", "global_orient", "body_pose")))
        vertices[..., 2] -= vertices[..., 2].min(axis=1, keepdims=True)  # on the ground
        vertices[..., 0] += np.linspace(-1.5, 1.5, count)[:, None]  # side by side
        return vertices

    rows = [(count, frames_per_second(renderer, bodies(count))) for count in (1, 8)]
    lines = [SECTION, "", f"480 × 360, body mesh at {len(renderer.mesh.faces):,} triangles per body (vertex-clustered "
             "LOD of mannequin-x's wooden mesh), embree ray casting of the bodies' screen box + analytic ground, "
             "median of 40 frames with a moving camera. Target (issue 7): ≥ 20 frames/s.", "",
             "| bodies per image | frames/s |", "|---|---|"]  # fmt: skip
    lines += [f"| {count} | {fps:.1f} |" for count, fps in rows]
    lines += ["", machine_line(), "Command: `motion-envs bench render`.", ""]
    section = "\n".join(lines)
    print(section)
    replace_section(RESULTS / "throughput.md", section)
    return 0
