"""A per-frame heading correction for GAMMA's marker predictors (ours, not the paper's).

Why: each trained predictor carries a small yaw bias of its own, of random sign, on the very windows it was
trained on, though the data (mirror images included) turn left and right alike: the shipped 2-frame
predictor's mean primitive, read through the regressor, turns +2.17° per primitive where the data turn +0.01°;
the same recipe with seeds 1 and 2 gives -1.32° and +1.15° (`motion-envs bench gamma-turns`, README). GAMMA
recomputes its canonical frame from the hips at every primitive, so the bias compounds: under z ~ N(0, I) 87% of
the shipped prior's bodies turn more than 30° left within 2-6 s. Heading losses in training were tried and trade
turning for the bias (the prior stops turning at all); training longer moves it about either way.

What: for predicted frame k of a predictor, the mean over the prior's training windows (every `stride`-th
frame, mirror images included) of the heading error (`rewards.facing_direction`: the hips, which the
canonical frame also reads) of the body the regressor makes of the predicted markers (z = 0) against the
data's own body. The generator (`GammaGenerator.set_heading_calibration`) turns each predicted frame's markers
about the vertical through their centroid by minus its correction, before the regressor; the blend and the next
seed use the turned markers. Two passes: the second measures what is left with the first correction applied and
adds it (the regressor does not follow a turn of its input one to one).

File: `gamma_heading_calibration.pt` beside the predictors (written by `motion-envs train gamma --stage
heading`), holding fingerprints of the predictors and regressor it was measured with; turning the calibration on
with other weights is refused (`CheckpointMismatchError`).
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import torch
from torch import nn

from motion_envs.body import BodyModel
from motion_envs.body.rotations import rotation_matrix, wrap_angle
from motion_envs.data.primitives import PRIMITIVE_FRAMES, MarkerClips
from motion_envs.priors.checkpoint import CheckpointMismatchError, load_checkpoint
from motion_envs.priors.gamma import MarkerCVAE
from motion_envs.rewards import facing_direction

CALIBRATION_FILE = "gamma_heading_calibration.pt"
CALIBRATION_KIND = "gamma_heading_calibration"
CALIBRATED_NETWORKS = ("predictor_1f", "predictor_2f", "regressor")
"""The generator's networks a calibration is measured with (their fingerprints are in its file)."""


class HeadingCalibration(nn.Module):
    """Per predicted frame heading corrections, radians (+ left): predictor_1f (9,), predictor_2f (8,)."""

    def __init__(self, config: dict | None = None) -> None:
        super().__init__()
        for seed_frames in (1, 2):
            self.register_buffer(f"predictor_{seed_frames}f", torch.zeros(PRIMITIVE_FRAMES - seed_frames))

    def correction(self, predictor: str) -> torch.Tensor:
        """(F,) radians of `predictor` ("predictor_1f" | "predictor_2f")."""
        return getattr(self, predictor)


def fingerprint(network: nn.Module) -> str:
    """A short hash of a network's weights rounded to float16 (as shipped files hold them), so that a run's
    weights and their shipped copy agree."""
    digest = hashlib.sha256()
    for name, value in sorted(network.state_dict().items()):
        digest.update(name.encode())
        digest.update((value.half() if value.is_floating_point() else value).cpu().numpy().tobytes())
    return digest.hexdigest()[:16]


def rotate_about_centroids(markers: torch.Tensor, angles: torch.Tensor) -> torch.Tensor:
    """(M, F, P, 3) points and (F,) angles (radians, + counter-clockwise seen from above) -> (M, F, P, 3): each
    frame's points turned about the vertical line through their centroid by its angle; heights unchanged."""
    cos, sin = angles.cos(), angles.sin()
    centroid = markers[..., :2].mean(dim=-2, keepdim=True)  # (M, F, 1, 2)
    x, y = (markers[..., :2] - centroid).unbind(-1)
    turned = torch.stack([cos[:, None] * x - sin[:, None] * y, sin[:, None] * x + cos[:, None] * y], dim=-1) + centroid
    return torch.cat([turned, markers[..., 2:]], dim=-1)


def facing_yaw(joints: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) joints -> (...) radians from +x of the body's forward on the ground (`rewards.facing_direction`)."""
    forward = facing_direction(joints)
    return torch.atan2(forward[..., 1], forward[..., 0])


def regressed_joints(regressor: nn.Module, body: BodyModel, markers: torch.Tensor) -> torch.Tensor:
    """(..., 67, 3) markers -> (..., 22, 3) joints of the body the regressor makes of them."""
    params = regressor(markers)
    return body.from_matrices(params["transl"], rotation_matrix(params["global_orient"]),
                              rotation_matrix(params["body_pose"])).joints  # fmt: skip


@torch.no_grad()
def heading_errors(predictor: MarkerCVAE, regressor: nn.Module, body: BodyModel, clips: MarkerClips, stride: int = 4,
                   correction: torch.Tensor | None = None, batch: int = 2048) -> torch.Tensor:  # fmt: skip
    """(F,) radians: the mean heading error (+ left) of each frame the predictor predicts (z = 0, seeded with each
    training window's first S frames, canonical as in training, each predicted frame turned by minus `correction`
    (F,) first), read through the regressor, against the data's body at that frame, over every 10-frame window of
    `clips` `stride` frames apart."""
    seed_frames = predictor.config.seed_frames
    starts = clips.window_starts(PRIMITIVE_FRAMES, stride)
    total = torch.zeros(PRIMITIVE_FRAMES - seed_frames, dtype=torch.float64)
    for chunk in starts.split(batch):  # bounded memory; one batched pass per chunk
        windows = clips.windows(chunk, PRIMITIVE_FRAMES)
        seed = windows.markers[:, :seed_frames].flatten(2)
        predicted = predictor.decode(seed, seed.new_zeros(len(seed), predictor.config.latent)).unflatten(-1, (-1, 3))
        if correction is not None:
            predicted = rotate_about_centroids(predicted, -correction)
        error = wrap_angle(facing_yaw(regressed_joints(regressor, body, predicted)) - facing_yaw(windows.joints[:, seed_frames:]))
        total += error.double().sum(dim=0)
    return (total / len(starts)).float()


def measure_heading_calibration(predictors: dict[str, MarkerCVAE], regressor: nn.Module, body: BodyModel,
                                clips: MarkerClips, stride: int = 4, passes: int = 2) -> tuple[HeadingCalibration, dict]:  # fmt: skip
    """The calibration of `predictors` ({"predictor_1f": ..., "predictor_2f": ...}) with `regressor` on `clips`
    (the prior's training split, mirrored), and its figures: per predictor the mean heading error per predicted
    frame in degrees before and after, rounded to 0.01°."""
    calibration, figures = HeadingCalibration(), {}
    for name, predictor in predictors.items():
        correction = torch.zeros(predictor.config.future_frames)
        before = None
        for _ in range(passes):
            residual = heading_errors(predictor, regressor, body, clips, stride, correction)
            before = residual if before is None else before
            correction = correction + residual
        after = heading_errors(predictor, regressor, body, clips, stride, correction)
        calibration.correction(name).copy_(correction)
        figures[name] = {f"{label}_degrees": [round(math.degrees(v), 2) for v in values.tolist()]
                         for label, values in (("correction", correction), ("error_before", before), ("error_after", after))}  # fmt: skip
    return calibration, figures


def network_fingerprints(networks: dict[str, nn.Module]) -> dict[str, str]:
    """{name: fingerprint} of `CALIBRATED_NETWORKS` in `networks`."""
    return {name: fingerprint(networks[name]) for name in CALIBRATED_NETWORKS}


def load_heading_calibration(path: str | Path, networks: dict[str, nn.Module]) -> HeadingCalibration:
    """The calibration in `path`, checked against the networks it will correct ({"predictor_1f", "predictor_2f",
    "regressor"}: modules).

    Raises:
        FileNotFoundError, CheckpointError: no readable calibration there.
        CheckpointMismatchError: it was measured with other weights (each differing network named).
    """
    payload = load_checkpoint(path, CALIBRATION_KIND)
    stored, ours = payload.get("fingerprints", {}), network_fingerprints(networks)
    differing = [name for name in CALIBRATED_NETWORKS if stored.get(name) != ours[name]]
    if differing:
        raise CheckpointMismatchError(f"{path} was measured with other {', '.join(differing)} weights than these; "
                                      "measure it anew: motion-envs train gamma --stage heading")  # fmt: skip
    calibration = HeadingCalibration()
    calibration.load_state_dict({name: value.float() for name, value in payload["model"].items()})
    return calibration
