"""Reading the built cache: clips of body motion by split."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_envs.data.build import CACHE_FORMAT
from motion_envs.data.mirror import mirror
from motion_envs.data.motion import BodyMotion


@dataclass(frozen=True)
class MotionDataset:
    """All clips of one cache file (one frame rate)."""

    path: Path
    arrays: dict[str, np.ndarray]

    @classmethod
    def load(cls, path: str | Path) -> MotionDataset:
        path = Path(path)
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
        if int(arrays.get("format", -1)) != CACHE_FORMAT:
            raise ValueError(f"{path} is a cache of another format; rebuild with 'motion-envs data build'")
        return cls(path, arrays)

    @property
    def fps(self) -> int:
        return int(self.arrays["fps"])

    def clip_ids(self, split: str | None = None) -> list[int]:
        splits = self.arrays["clip_split"]
        return [i for i in range(len(splits)) if split is None or splits[i] == split]

    def clip(self, index: int) -> BodyMotion:
        start, stop = self.arrays["clip_start"][index : index + 2]
        return BodyMotion(
            name=str(self.arrays["clip_name"][index]),
            subject=str(self.arrays["clip_subject"][index]),
            fps=float(self.fps),
            transl=self.arrays["transl"][start:stop],
            global_orient=self.arrays["global_orient"][start:stop],
            body_pose=self.arrays["body_pose"][start:stop],
            info={"split": str(self.arrays["clip_split"][index]), "contacts": self.arrays["contacts"][start:stop]},
        )

    def clips(self, split: str | None = None, mirrored: bool = False) -> list[BodyMotion]:
        """Clips of a split (all when None); with `mirrored`, each clip's mirror image follows it."""
        out: list[BodyMotion] = []
        for index in self.clip_ids(split):
            clip = self.clip(index)
            out += [clip, mirror(clip)] if mirrored else [clip]
        return out
