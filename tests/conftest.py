"""Shared fixtures: the body model and the motion-capture folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from motion_envs.body import BodyModel
from motion_envs.data.paths import default_mocap_dir


TEST_THREADS = max(1, torch.get_num_threads() // int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
"""Intra-op threads of each test process: torch's default (the cores this process may use) shared out among
pytest-xdist's workers. With the default in every worker the cores are oversubscribed, and an OpenMP team waiting on
a descheduled thread turns each small op into a time slice: the cleanup's 300-step IK on a 2.5-s clip took 26 s in
a 2-worker run on 2 cores and 1.5 s on its own. Not passed on as OMP_NUM_THREADS: Ray keeps that for its workers,
which then ran two threads each on the same two cores (the Ray half of the suite: 68 -> 183 s)."""


@pytest.fixture(autouse=True)
def _share_the_cores() -> None:
    """Every test starts with `TEST_THREADS` threads (a test may set others: a CLI's --threads, a benchmark)."""
    torch.set_num_threads(TEST_THREADS)


@pytest.fixture(scope="session")
def body() -> BodyModel:
    return BodyModel()


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """The shared mocap folder; skipped outside CI when absent, a failure under CI=true."""
    path = default_mocap_dir()
    if path is None or not path.is_dir():
        message = "motion-capture folder not found (set MOTION_ENVS_DATA or put shared/mocap beside the repo)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(message)
        pytest.skip(message)
    return path


@pytest.fixture
def generator() -> torch.Generator:
    return torch.Generator().manual_seed(0)


def _walking_motion(mocap_dir, body, fps: int):
    from motion_envs.data.build import find_sources, load_clip
    from motion_envs.data.retarget import RetargetConfig

    source = next(s for s in find_sources(mocap_dir) if s.relative == "cmu/07_01.bvh")
    return load_clip(source, fps, body, RetargetConfig(iterations=60))


@pytest.fixture(scope="session")
def walking_motion_40fps(mocap_dir, body):
    """One real CMU walking clip (07_01) as body motion at 40 fps (GAMMA's rate)."""
    return _walking_motion(mocap_dir, body, 40)


@pytest.fixture(scope="session")
def walking_clips(walking_motion_40fps, body):
    """The same clip as 40 fps markers."""
    from motion_envs.data.primitives import MarkerClips

    return MarkerClips.from_motions([walking_motion_40fps], body)


@pytest.fixture(scope="session")
def walking_motion_30fps(mocap_dir, body):
    """The same clip as body motion at 30 fps (WANDR's rate)."""
    return _walking_motion(mocap_dir, body, 30)
