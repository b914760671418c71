"""Shared fixtures: the body model and the motion-capture folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from motion_envs.body import BodyModel
from motion_envs.data.paths import default_mocap_dir


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
