"""GAMMA's heading calibration (`motion_envs.priors.gamma_heading`): measuring it, its file, the generator's use."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
import torch

from motion_envs.data.mirror import mirror
from motion_envs.data.primitives import MarkerClips
from motion_envs.envs.gamma_reach import GammaReachCore, GammaReachConfig
from motion_envs.priors.checkpoint import CheckpointMismatchError
from motion_envs.priors.gamma_generator import GammaGenerator
from motion_envs.priors.gamma_heading import (
    CALIBRATION_FILE,
    CALIBRATION_KIND,
    HeadingCalibration,
    measure_heading_calibration,
    network_fingerprints,
    rotate_about_centroids,
)
from motion_envs.priors.training import WEIGHTS_DIR, ship

GAMMA_FILES = ("gamma_predictor_1f.pt", "gamma_predictor_2f.pt", "gamma_regressor.pt", "gamma_pose_vae.pt")


def _networks(generator: GammaGenerator) -> dict[str, torch.nn.Module]:
    return {"predictor_1f": generator.predictor_1f, "predictor_2f": generator.predictor_2f, "regressor": generator.regressor}


def _weights_with_calibration(folder, calibration: HeadingCalibration, fingerprints: dict[str, str]):
    """A copy of the shipped GAMMA weights in `folder` with `calibration` beside them, claiming `fingerprints`."""
    for name in GAMMA_FILES:
        shutil.copy(WEIGHTS_DIR / name, folder / name)
    ship(calibration, folder / CALIBRATION_FILE, {"kind": CALIBRATION_KIND, "config": {}, "fingerprints": fingerprints})
    return folder


def test_rotation_about_centroids_turns_each_frame_rigidly_and_keeps_heights():
    points = torch.randn(3, 2, 67, 3)
    angles = torch.tensor([0.3, -1.0])
    turned = rotate_about_centroids(points, angles)
    assert torch.equal(turned[..., 2], points[..., 2])
    assert torch.allclose(turned[..., :2].mean(-2), points[..., :2].mean(-2), atol=1e-5)
    before, after = (value[:, :, 1, :2] - value[:, :, 0, :2] for value in (points, turned))
    turn = torch.atan2(after[..., 1], after[..., 0]) - torch.atan2(before[..., 1], before[..., 0])
    assert torch.allclose(torch.remainder(turn - angles + math.pi, 2 * math.pi) - math.pi, torch.zeros(3, 2), atol=1e-4)
    assert torch.allclose(rotate_about_centroids(turned, -angles), points, atol=1e-5)


def test_calibration_measured_on_windows_removes_most_of_their_heading_error(walking_motion_40fps, body):
    """On a real walk and its mirror image, the shipped predictors' mean heading error per predicted frame
    (through the regressor) is mostly gone once corrected by the calibration measured on the same windows."""
    generator = GammaGenerator.load()
    clips = MarkerClips.from_motions([walking_motion_40fps, mirror(walking_motion_40fps)], body)
    predictors = {"predictor_1f": generator.predictor_1f, "predictor_2f": generator.predictor_2f}
    calibration, figures = measure_heading_calibration(predictors, generator.regressor, body, clips, stride=8)
    for name, seed_frames in (("predictor_1f", 1), ("predictor_2f", 2)):
        before, after = (np.abs(figures[name][f"error_{when}_degrees"]) for when in ("before", "after"))
        assert len(before) == 10 - seed_frames == len(calibration.correction(name))
        assert after.max() <= 0.3 * before.max() + 0.05, (name, before, after)
        assert np.allclose(np.degrees(calibration.correction(name).numpy()), figures[name]["correction_degrees"], atol=0.01)


def test_generator_turns_each_predicted_frame_by_minus_its_correction(tmp_path):
    """With the calibration on, every predicted frame is the uncalibrated prediction turned about its centroid by
    minus the correction (seed frames untouched), for one- and two-frame seeds; off again, the raw prior."""
    shipped = GammaGenerator.load()
    calibration = HeadingCalibration()
    calibration.predictor_1f.copy_(torch.linspace(0.01, 0.09, 9))
    calibration.predictor_2f.copy_(torch.linspace(-0.02, 0.12, 8))
    folder = _weights_with_calibration(tmp_path, calibration, network_fingerprints(_networks(shipped)))
    generator = GammaGenerator.load(folder)
    core = GammaReachCore(GammaReachConfig(precision="float32"), generator)
    seed = core.initial_state(torch.arange(4), torch.zeros(4), torch.ones(4, 2)).seed
    z = torch.randn(4, generator.latent_size, generator=torch.Generator().manual_seed(0))
    for _ in range(2):  # first a one-frame seed, then a two-frame one
        raw, _ = generator.set_heading_calibration(False).step(seed, z)
        calibrated, next_seed = generator.set_heading_calibration(True).step(seed, z)
        new = raw.new_frames()[0]
        name = f"predictor_{int(seed.seed_frames[0])}f"
        correction = (calibration.predictor_1f if name == "predictor_1f" else calibration.predictor_2f).float()
        expected = rotate_about_centroids(raw.predicted_markers[:, new], -correction)
        assert torch.allclose(calibrated.predicted_markers[:, new], expected, atol=2e-4)
        assert torch.equal(calibrated.predicted_markers[:, ~new], raw.predicted_markers[:, ~new])
        seed = next_seed
    assert generator.set_heading_calibration(False).heading_calibration is None


def test_calibration_missing_or_measured_with_other_weights_is_refused(tmp_path):
    shipped = GammaGenerator.load()
    bare = GammaGenerator(shipped.predictor_1f, shipped.predictor_2f, shipped.regressor, shipped.pose_vae)
    with pytest.raises(FileNotFoundError, match="--stage heading"):
        GammaReachCore(GammaReachConfig(heading_calibration=True), bare)
    stale = {**network_fingerprints(_networks(shipped)), "regressor": "0" * 16}
    generator = GammaGenerator.load(_weights_with_calibration(tmp_path, HeadingCalibration(), stale))
    with pytest.raises(CheckpointMismatchError, match="regressor"):
        generator.set_heading_calibration(True)
