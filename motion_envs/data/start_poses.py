"""The shipped start poses: short standing and walking windows from validation clips.

`motion_envs/assets/start_poses.npz` lets the environments and the main job
run without the mocap folder. Per frame rate it holds S windows of
`WINDOW` frames, each canonicalised (first frame: pelvis over the origin,
facing +y, lowest foot point on z = 0). Derived from the CMU Graphics Lab
Motion Capture Database (mocap.cs.cmu.edu; acknowledgement in
`motion_envs/assets/ACKNOWLEDGEMENT.md`).
"""

from __future__ import annotations

from dataclasses import replace
from importlib.resources import files
from pathlib import Path

import numpy as np

from motion_envs.atomic import atomic_write
from motion_envs.body import BodyModel
from motion_envs.data.build import DEFAULT_FPS, build
from motion_envs.data.canonical import canonicalise
from motion_envs.data.dataset import MotionDataset
from motion_envs.data.motion import BodyMotion
from motion_envs.data.paths import SHIPPED_SUBSETS

WINDOW = 10
PER_KIND = 24
STANDING_SPEED = (0.0, 0.25)
WALKING_SPEED = (0.7, 1.8)
"""Pelvis ground speed (m/s) over a window for each kind. Standing is rare in the
validation clips (mostly the first frames of walks), so its windows are searched
frame by frame; walking windows every half second."""


def _windows(clip: BodyMotion, speed: tuple[float, float], stride: int) -> list[int]:
    starts = np.arange(0, clip.num_frames - WINDOW, stride)
    travel = np.linalg.norm(clip.transl[starts + WINDOW - 1, :2] - clip.transl[starts, :2], axis=1)
    velocity = travel / ((WINDOW - 1) / clip.fps)
    return [int(s) for s, v in zip(starts, velocity) if speed[0] <= v < speed[1]]


def select_start_poses(dataset: MotionDataset, body: BodyModel) -> dict[str, np.ndarray]:
    """PER_KIND standing + PER_KIND walking windows, spread over the validation clips."""
    clips = dataset.clips("validation")
    chosen: dict[str, list] = {key: [] for key in ("transl", "global_orient", "body_pose", "kind", "clip", "frame")}
    for kind, speed in (("standing", STANDING_SPEED), ("walking", WALKING_SPEED)):
        stride = 1 if kind == "standing" else dataset.fps // 2
        candidates = [(clip, start) for clip in clips for start in _windows(clip, speed, stride)]
        if not candidates:
            raise RuntimeError(f"no {kind} windows in the validation clips")
        picks = np.linspace(0, len(candidates) - 1, min(PER_KIND, len(candidates))).round().astype(int)
        for clip, start in (candidates[i] for i in picks):
            window = replace(
                clip,
                transl=clip.transl[start : start + WINDOW],
                global_orient=clip.global_orient[start : start + WINDOW],
                body_pose=clip.body_pose[start : start + WINDOW],
            )
            window = canonicalise(window, body)
            for key in ("transl", "global_orient", "body_pose"):
                chosen[key].append(getattr(window, key).astype(np.float32))
            chosen["kind"].append(kind)
            chosen["clip"].append(clip.name)
            chosen["frame"].append(start)
    return {key: np.asarray(value) for key, value in chosen.items()}


def write_start_poses(
    mocap_dir: Path | None = None,
    cache_dir: Path | None = None,
    subsets: tuple[str, ...] = SHIPPED_SUBSETS,
    destination: Path | None = None,
) -> Path:
    """Build (or reuse) the cache and write the start poses for every default frame rate."""
    report = build(mocap_dir=mocap_dir, cache_dir=cache_dir, subsets=subsets, fps_list=DEFAULT_FPS)
    body = BodyModel()
    arrays: dict[str, np.ndarray] = {}
    for fps, path in report.caches.items():
        for key, value in select_start_poses(MotionDataset.load(path), body).items():
            arrays[f"{fps}fps_{key}"] = value
    destination = destination or Path(str(files("motion_envs") / "assets" / "start_poses.npz"))
    return atomic_write(destination, lambda file: np.savez_compressed(file, **arrays))


def load_start_poses(fps: int) -> dict[str, np.ndarray]:
    """The shipped start windows at `fps`: transl (S, W, 3), global_orient (S, W, 3),
    body_pose (S, W, 21, 3), kind (S,), clip (S,), frame (S,)."""
    resource = files("motion_envs") / "assets" / "start_poses.npz"
    with resource.open("rb") as handle, np.load(handle, allow_pickle=False) as data:
        prefix = f"{fps}fps_"
        arrays = {key[len(prefix) :]: data[key] for key in data.files if key.startswith(prefix)}
    if not arrays:
        raise ValueError(f"no shipped start poses at {fps} fps; available: {sorted(DEFAULT_FPS)}")
    return arrays
