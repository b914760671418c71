"""Marker-based motion windows for GAMMA: clips as markers, cut into canonical windows.

A window of L frames starting at frame s is expressed in GAMMA's canonical
frame of frame s (the first seed frame): primitives are 10-frame windows,
rollout training uses windows of several overlapping primitives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import roma
import torch

from motion_envs.body import BodyModel
from motion_envs.body.markers import marker_ids
from motion_envs.data.dataset import MotionDataset
from motion_envs.data.motion import BodyMotion
from motion_envs.body.canonical_frame import canonical_frame, to_canonical

PRIMITIVE_FRAMES = 10
GAMMA_FPS = 40


@dataclass(frozen=True)
class MarkerWindows:
    """Windows in their own canonical frame.

    markers: (B, L, 67, 3). joints: (B, L, 22, 3). transl: (B, L, 3).
    global_orient: (B, L, 3). body_pose: (B, L, 21, 3). contacts: (B, L, 4) bool sole contacts.
    """

    markers: torch.Tensor
    joints: torch.Tensor
    transl: torch.Tensor
    global_orient: torch.Tensor
    body_pose: torch.Tensor
    contacts: torch.Tensor


@dataclass(frozen=True)
class MarkerClips:
    """Every clip of one split with its markers and joints, frames concatenated.

    markers: (F, 67, 3). joints: (F, 22, 3). transl: (F, 3). global_orient: (F, 3).
    body_pose: (F, 21, 3). clip_start: (C + 1,) first frame of each clip. contacts: (F, 4) bool sole
    contacts (`SOLE_POINTS` order; all False for uncleaned data).
    """

    markers: torch.Tensor
    joints: torch.Tensor
    transl: torch.Tensor
    global_orient: torch.Tensor
    body_pose: torch.Tensor
    clip_start: torch.Tensor
    fps: int
    contacts: torch.Tensor

    @classmethod
    def from_dataset(cls, dataset: MotionDataset, split: str, body: BodyModel, mirrored: bool = False) -> MarkerClips:
        """Skin the split's clips (optionally with their mirror images) into markers."""
        if dataset.fps != GAMMA_FPS:
            raise ValueError(f"GAMMA primitives need the {GAMMA_FPS} fps cache, got {dataset.fps} fps")
        clips = dataset.clips(split, mirrored=mirrored)
        if not clips:
            raise ValueError(f"split {split!r} has no clips in {dataset.path}")
        return cls.from_motions(clips, body)

    @classmethod
    def from_motions(cls, clips: list[BodyMotion], body: BodyModel) -> MarkerClips:
        """Skin body motions (all at one frame rate) into markers."""
        if len({c.fps for c in clips}) != 1:
            raise ValueError(f"clips have different frame rates: {sorted({c.fps for c in clips})}")

        def cat(name: str) -> torch.Tensor:
            return torch.as_tensor(np.concatenate([getattr(c, name) for c in clips]), dtype=torch.float32)

        transl, orient, pose = cat("transl"), cat("global_orient"), cat("body_pose")
        with torch.no_grad():
            posed = body(transl, orient, pose)
            markers = body.skin(posed, marker_ids())
        starts = torch.cumsum(torch.tensor([0] + [c.num_frames for c in clips]), dim=0)
        contacts = torch.as_tensor(np.concatenate([c.info.get("contacts", np.zeros((c.num_frames, 4), bool)) for c in clips]))
        return cls(markers, posed.joints.contiguous(), transl, orient, pose, starts, int(clips[0].fps), contacts)

    def window_starts(self, length: int, stride: int = 1) -> torch.Tensor:
        """(W,) first frames of every window of `length` frames lying inside one clip."""
        starts = [torch.zeros(0, dtype=torch.long)]
        for begin, end in zip(self.clip_start[:-1].tolist(), self.clip_start[1:].tolist()):
            if end - begin >= length:  # clips shorter than a window give none
                starts.append(torch.arange(begin, end - length + 1, stride))
        return torch.cat(starts)

    def windows(self, starts: torch.Tensor, length: int) -> MarkerWindows:
        """The windows starting at `starts` (B,), each canonical at its first frame."""
        frames = starts[:, None] + torch.arange(length)  # (B, L)
        frame = canonical_frame(self.joints[starts])
        markers = to_canonical(self.markers[frames].flatten(1, 2), frame).unflatten(1, (length, -1))
        joints = to_canonical(self.joints[frames].flatten(1, 2), frame).unflatten(1, (length, -1))
        transl = to_canonical(self.transl[frames], frame)
        turn = frame.rotation.transpose(-1, -2)[:, None]  # world -> canonical
        orient = roma.rotmat_to_rotvec(turn @ roma.rotvec_to_rotmat(self.global_orient[frames]))
        return MarkerWindows(markers, joints, transl, orient, self.body_pose[frames], self.contacts[frames])
