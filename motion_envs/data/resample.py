"""Resampling motion to a new frame rate: slerp for rotations, lerp for positions."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import roma
import torch

from motion_envs.data.motion import BodyMotion, SourceMotion


def resample_times(num_frames: int, fps_in: float, fps_out: float) -> np.ndarray:
    """Source frame positions (fractional) of the output frames; keeps the clip's duration.

    The output has floor((T - 1) / fps_in * fps_out) + 1 frames, starting at frame 0.
    """
    if num_frames < 2:
        raise ValueError("resampling needs at least two frames")
    duration = (num_frames - 1) / fps_in
    count = int(np.floor(duration * fps_out + 1e-9)) + 1
    return np.minimum(np.arange(count) * (fps_in / fps_out), num_frames - 1)


def slerp_rotations(rotations: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(T, ..., 3, 3) rotations sampled at fractional frame `times` (N,) -> (N, ..., 3, 3)."""
    start = np.minimum(np.floor(times).astype(int), len(rotations) - 2)
    weight = torch.as_tensor(times - start).reshape(-1, *([1] * (rotations.ndim - 3)))
    r0 = torch.as_tensor(rotations[start])
    r1 = torch.as_tensor(rotations[start + 1])
    step = roma.rotmat_to_rotvec(r0.transpose(-1, -2) @ r1)  # shortest arc, angle <= pi
    return (r0 @ roma.rotvec_to_rotmat(step * weight[..., None])).numpy()


def lerp(values: np.ndarray, times: np.ndarray) -> np.ndarray:
    """(T, ...) values linearly interpolated at fractional frame `times` (N,)."""
    start = np.minimum(np.floor(times).astype(int), len(values) - 2)
    weight = (times - start).reshape(-1, *([1] * (values.ndim - 1)))
    return values[start] * (1 - weight) + values[start + 1] * weight


def resample_source(motion: SourceMotion, fps: float) -> SourceMotion:
    """The source motion at `fps`."""
    times = resample_times(motion.num_frames, motion.fps, fps)
    return replace(
        motion,
        fps=float(fps),
        root_positions=lerp(motion.root_positions, times),
        local_rotations=slerp_rotations(motion.local_rotations, times),
    )


def resample_body(motion: BodyMotion, fps: float) -> BodyMotion:
    """The body motion at `fps` (axis-angle slerped through rotation matrices)."""
    times = resample_times(motion.num_frames, motion.fps, fps)
    rotations = roma.rotvec_to_rotmat(
        torch.as_tensor(np.concatenate([motion.global_orient[:, None], motion.body_pose], axis=1))
    ).numpy()
    resampled = roma.rotmat_to_rotvec(torch.as_tensor(slerp_rotations(rotations, times))).numpy()
    return replace(
        motion,
        fps=float(fps),
        transl=lerp(motion.transl, times),
        global_orient=resampled[:, 0],
        body_pose=resampled[:, 1:],
    )
