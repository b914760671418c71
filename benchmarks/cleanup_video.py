"""Side-by-side video of one clip before and after cleanup (`motion-envs bench cleanup-video`).

Left: the clip as retargeted (the uncleaned cache); right: the same clip after
contact labelling, floor levelling and foot locking. The trails are the paths
of the lowest sole point over the last second, one per stretch in which it
stays the same point (`footprints`), so a sliding stance foot draws a streak
and a planted one a dot. Written to
`docs/cleanup_<clip>.mp4` (30 fps, 960 x 360).
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import torch
from tqdm import tqdm

from motion_envs.atomic import atomic_path
from motion_envs.body import BodyModel
from motion_envs.body.markers import sole_vertex_ids
from motion_envs.data.build import build
from motion_envs.data.canonical import body_tensors
from motion_envs.data.dataset import MotionDataset
from motion_envs.data.paths import SHIPPED_SUBSETS
from motion_envs.render.camera import follow_camera
from motion_envs.render.third_person import ThirdPersonRenderer

DOCS = Path(__file__).resolve().parents[1] / "docs"


def clip_named(dataset: MotionDataset, name: str):
    names = [str(n) for n in dataset.arrays["clip_name"]]
    if name not in names:
        raise ValueError(f"no clip {name!r} in {dataset.path}; e.g. {names[:5]}")
    return dataset.clip(names.index(name))


def footprints(soles: np.ndarray, frame: int, fps: int) -> list[np.ndarray]:
    """Over the second up to `frame`, the path of the lowest sole point (soles (T, 4, 3)) while it stays the
    same point, one trail per such run: a planted foot leaves a dot, a sliding one a streak."""
    recent = soles[max(0, frame - fps) : frame + 1]
    lowest = recent[..., 2].argmin(-1)
    points = recent[np.arange(len(recent)), lowest]
    cuts = np.flatnonzero(np.diff(lowest)) + 1
    return [np.column_stack([run[:, :2], np.full(len(run), 0.005)]) for run in np.split(points, cuts) if len(run) > 1]


def main(clip: str = "cmu/08_11", mocap_dir: Path | None = None, cache_dir: Path | None = None) -> int:
    fps = 30
    cleaned = MotionDataset.load(build(mocap_dir, cache_dir, SHIPPED_SUBSETS, (fps,), progress=False).caches[fps])
    raw = MotionDataset.load(build(mocap_dir, cache_dir, SHIPPED_SUBSETS, (fps,), progress=False, cleanup=None).caches[fps])
    body = BodyModel()
    renderer = ThirdPersonRenderer(body)
    motions = [clip_named(raw, clip), clip_named(cleaned, clip)]
    frames = min(m.num_frames for m in motions)
    with torch.inference_mode():
        soles = [body.skin(body(*body_tensors(m)), sole_vertex_ids()).numpy() for m in motions]
        vertices = [renderer.vertices(*(t[:frames] for t in body_tensors(m))) for m in motions]
    destination = DOCS / f"cleanup_{clip.replace('/', '_')}.mp4"
    DOCS.mkdir(exist_ok=True)
    with atomic_path(destination) as partial, contextlib.closing(
        imageio.get_writer(str(partial), fps=fps, macro_block_size=8, format="FFMPEG")
    ) as writer:  # fmt: skip
        for frame in tqdm(range(frames), desc="render", unit="frame"):
            halves = []
            for index in range(2):
                pelvis = vertices[index][frame].mean(axis=0)
                camera = follow_camera(np.array([pelvis[0], pelvis[1], 0.5]), distance=3.0, height_above=1.0, azimuth=-0.3)
                halves.append(renderer.render(vertices[index][frame][None], camera, trail=footprints(soles[index], frame, fps)))
            writer.append_data(np.concatenate(halves, axis=1))
    print(f"wrote {destination} ({frames} frames: before cleanup left, after right)")
    return 0
