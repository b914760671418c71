"""A static triangle mesh in an embree scene (through embreex), cast once per batch of rays.

Fork: embree runs its scene builds on TBB's worker pool, whose locks a forked child inherits in whatever state the
parent's workers left them; a child forked from a process that had cast rays deadlocked in its first scene build
(seen: `rtcCommitScene` waiting on TBB's market lock in a ClopsNav `gym.make_vec(..., vectorization_mode="async")`
worker, the default fork context on Linux, test suite hung). Such a child refuses to cast with a `RuntimeError`
saying what to do (the "spawn" or "forkserver" context); a child forked before any cast is unaffected.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache

import numpy as np
import torch
from embreex import rtcore, rtcore_scene
from embreex.mesh_construction import TriangleMesh

_DEVICE = None
_HAS_CAST = False
"""Whether this process has cast rays (embree's TBB pool has run)."""
_FORKED_AFTER_CASTING = False
"""Whether this process was forked from one that had cast rays (see the module doc)."""
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
        origins = np.ascontiguousarray(origins, dtype=np.float32)  # once: the threads' parts are views of it
        directions = np.ascontiguousarray(directions, dtype=np.float32)
        threads = min(torch.get_num_threads(), len(origins) // PARALLEL_RAYS + 1) if parallel else 1
        if threads <= 1:
            return self._cast(origins, directions)
        bounds = np.linspace(0, len(origins), threads + 1).astype(int)
        parts = [slice(start, stop) for start, stop in zip(bounds[:-1], bounds[1:])]
        results = list(thread_pool(threads).map(lambda part: self._cast(origins[part], directions[part]), parts))
        return np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results])

    def _cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        global _HAS_CAST
        if _FORKED_AFTER_CASTING:
            raise RuntimeError("this process was forked after its parent cast rays with embree, whose thread pool "
                               "does not survive fork (the first scene build deadlocks); start worker processes "
                               "with the 'spawn' or 'forkserver' context, e.g. gym.make_vec(..., "
                               "vectorization_mode='async', vector_kwargs={'context': 'spawn'})")  # fmt: skip
        _HAS_CAST = True
        result = self._scene.run(np.ascontiguousarray(origins, dtype=np.float32),
                                 np.ascontiguousarray(directions, dtype=np.float32), output=1)  # fmt: skip
        triangle = result["primID"].astype(np.int64)
        distance = result["tfar"]  # float32, written by this call alone
        distance[triangle < 0] = np.inf
        return triangle, distance


@lru_cache(maxsize=4)
def thread_pool(threads: int) -> ThreadPoolExecutor:
    """A process-wide pool of `threads` workers for ray casting and shading."""
    return ThreadPoolExecutor(threads, thread_name_prefix="raycast")


def _after_fork_in_child() -> None:
    """Mark a child forked after casting (module doc) and forget the parent's ray-casting threads, which a child
    does not have."""
    global _FORKED_AFTER_CASTING
    _FORKED_AFTER_CASTING = _HAS_CAST
    thread_pool.cache_clear()


os.register_at_fork(after_in_child=_after_fork_in_child)
