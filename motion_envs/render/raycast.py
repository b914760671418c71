"""A static triangle mesh in an embree scene (through embreex), cast once per batch of rays."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache

import numpy as np
import torch
from embreex import rtcore, rtcore_scene
from embreex.mesh_construction import TriangleMesh

_DEVICE = None
PARALLEL_RAYS = 8192
"""Fewer rays than this are cast on the calling thread."""


def device() -> rtcore.EmbreeDevice:
    """One embree device per process (creating one per scene costs a thread pool)."""
    global _DEVICE
    if _DEVICE is None:
        _DEVICE = rtcore.EmbreeDevice()
    return _DEVICE


class RayCaster:
    """Closest hits of rays against fixed triangles. vertices: (V, 3), faces: (F, 3)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float32)
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)
        self._scene = rtcore_scene.EmbreeScene(device())
        TriangleMesh(self._scene, self.vertices, self.faces)

    def __getstate__(self) -> dict:
        """Pickled (and deep-copied) without the embree scene, which cannot be; `__setstate__` rebuilds it."""
        return {"vertices": self.vertices, "faces": self.faces}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["vertices"], state["faces"])

    def cast(self, origins: np.ndarray, directions: np.ndarray, parallel: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """origins, directions: (R, 3) (directions unit). Returns the hit triangle (R,) int (-1: none) and the
        distance along the ray (R,) float32 (+inf where nothing is hit).

        With `parallel`, above `PARALLEL_RAYS` rays the batch is split over torch's thread count (embree frees
        the GIL); callers already running on `thread_pool` pass False."""
        threads = min(torch.get_num_threads(), len(origins) // PARALLEL_RAYS + 1) if parallel else 1
        if threads <= 1:
            return self._cast(origins, directions)
        chunks = np.array_split(np.arange(len(origins)), threads)
        results = list(thread_pool(threads).map(lambda rows: self._cast(origins[rows], directions[rows]), chunks))
        return np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results])

    def _cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        result = self._scene.run(np.ascontiguousarray(origins, dtype=np.float32),
                                 np.ascontiguousarray(directions, dtype=np.float32), output=1)  # fmt: skip
        triangle = result["primID"].astype(np.int64)
        distance = np.where(triangle >= 0, result["tfar"], np.inf).astype(np.float32)
        return triangle, distance


@lru_cache(maxsize=4)
def thread_pool(threads: int) -> ThreadPoolExecutor:
    """A process-wide pool of `threads` workers for ray casting and shading."""
    return ThreadPoolExecutor(threads, thread_name_prefix="raycast")
