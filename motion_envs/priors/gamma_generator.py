"""GAMMA as a motion generator: latent codes in, bodies moving one primitive at a time out.

One `GammaGenerator.step` takes N bodies' motion seeds (world coordinates)
and N latent codes and, batched over bodies:

1. canonicalises each seed at its first seed frame (GAMMA's frame);
2. predicts the rest of the 10-frame primitive with the 1-frame model for
   bodies with a one-frame seed (episode starts) and the 2-frame model for
   the others;
3. regresses a body for every predicted frame and skins its markers
   (the re-projection);
4. blends: the primitive's markers are the average of predicted and
   re-projected markers (the paper's "ours-ro", release factor 0.5), so a
   body never drifts more than half the prediction error from its markers;
5. returns the primitive (world) and the next seed: its last two frames.

Seed frames are part of every primitive (frames 0..S-1), so a primitive always
has 10 frames; the 10 - S after the seed are new.

`precision="bfloat16"` runs the two networks (predictor and regressor, ~95% of
the FLOPs) under bf16 autocast and returns their outputs in fp32; the body
model, canonical frames and blending stay fp32, so positions do not lose
bf16's 3 significant digits far from the origin. Recent x86 CPUs (AMX,
AVX512-BF16) multiply bf16 matrices several times faster than fp32.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from motion_envs.batched import BatchedState
from motion_envs.body import BodyModel
from motion_envs.body.markers import marker_ids
from motion_envs.body.rotations import matrix_to_sixd, rotation_matrix
from motion_envs.data.primitives import PRIMITIVE_FRAMES
from motion_envs.priors.canonical import canonical_frame, goal_observation, to_canonical, to_world
from motion_envs.priors.gamma import MarkerCVAE, PoseVAE, goal_conditioned_seed
from motion_envs.priors.train_gamma import load_predictor
from motion_envs.priors.train_pose_prior import load_pose_vae
from motion_envs.priors.train_regressor import load_regressor
from motion_envs.priors.training import WEIGHTS_DIR

PRECISIONS = {"float32": torch.float32, "bfloat16": torch.bfloat16}

BLEND_FACTOR = 0.5
"""Weight of the re-projected markers in the blend (the release's reproj_factor)."""


@dataclasses.dataclass(frozen=True)
class GammaSeed(BatchedState):
    """The last two frames of N bodies, world coordinates.

    seed_frames: (N,) long, 1 or 2: how many of the two frames seed the next
        primitive. With 1 only frame index 1 counts (index 0 holds a copy).
    markers: (N, 2, 67, 3). joints: (N, 2, 22, 3). transl: (N, 2, 3) pelvis.
    global_orient: (N, 2, 6) and body_pose: (N, 2, 21, 6), 6-D rotations.
    """

    seed_frames: torch.Tensor
    markers: torch.Tensor
    joints: torch.Tensor
    transl: torch.Tensor
    global_orient: torch.Tensor
    body_pose: torch.Tensor


@dataclasses.dataclass(frozen=True)
class Primitive:
    """One generated primitive of N bodies, world coordinates, 10 frames.

    markers: (N, 10, 67, 3) blended markers. predicted_markers: same, before
    blending (seed frames: the seed's). reprojected_markers: same, skinned
    from the regressed bodies. joints: (N, 10, 22, 3). transl: (N, 10, 3).
    global_orient: (N, 10, 6). body_pose: (N, 10, 21, 6). seed_frames: (N,).
    """

    markers: torch.Tensor
    predicted_markers: torch.Tensor
    reprojected_markers: torch.Tensor
    joints: torch.Tensor
    transl: torch.Tensor
    global_orient: torch.Tensor
    body_pose: torch.Tensor
    seed_frames: torch.Tensor

    def new_frames(self) -> torch.Tensor:
        """(N, 10) bool: frames after the seed."""
        return torch.arange(PRIMITIVE_FRAMES, device=self.seed_frames.device) >= self.seed_frames[:, None]


class GammaGenerator(torch.nn.Module):
    """The trained GAMMA models (two predictors, regressor, pose VAE) and the body."""

    def __init__(
        self, predictor_1f: MarkerCVAE, predictor_2f: MarkerCVAE, regressor: torch.nn.Module, pose_vae: PoseVAE
    ) -> None:
        super().__init__()
        if predictor_1f.config.seed_frames != 1 or predictor_2f.config.seed_frames != 2:
            raise ValueError("predictor_1f must take 1 seed frame and predictor_2f 2")
        if predictor_1f.config.latent != predictor_2f.config.latent:
            raise ValueError("both predictors must share a latent size")
        self.predictor_1f, self.predictor_2f = predictor_1f, predictor_2f
        self.regressor, self.pose_vae = regressor, pose_vae
        self.body = BodyModel()
        self.register_buffer("marker_rows", self.body.skin_rows(marker_ids()), persistent=False)
        self.requires_grad_(False)
        self.eval()
        self.precision = "float32"

    def set_precision(self, precision: str) -> GammaGenerator:
        """"float32" (default) or "bfloat16" for the networks (see the module doc); returns self."""
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
        self.precision = precision
        return self

    def _networks(self):
        """Autocast context for the predictor and regressor passes."""
        return torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.precision == "bfloat16")

    @classmethod
    def load(cls, weights_dir: str | Path = WEIGHTS_DIR) -> GammaGenerator:
        """The shipped (or `weights_dir`'s) gamma_predictor_1f/2f, gamma_regressor and gamma_pose_vae."""
        weights_dir = Path(weights_dir)
        return cls(
            load_predictor(weights_dir / "gamma_predictor_1f.pt"),
            load_predictor(weights_dir / "gamma_predictor_2f.pt"),
            load_regressor(weights_dir / "gamma_regressor.pt"),
            load_pose_vae(weights_dir / "gamma_pose_vae.pt"),
        )

    @property
    def latent_size(self) -> int:
        return self.predictor_2f.config.latent

    @property
    def device(self) -> torch.device:
        return self.marker_rows.device

    def markers_of(self, transl: torch.Tensor, global_orient: torch.Tensor, body_pose: torch.Tensor):
        """Pose bodies (..., 3), (..., 6), (..., 21, 6) -> (joints (..., 22, 3), markers (..., 67, 3))."""
        posed = self.body(transl, global_orient, body_pose)
        return posed.joints, self.body.skin_with_rows(posed, self.marker_rows)

    def seed_from_bodies(self, transl: torch.Tensor, global_orient: torch.Tensor, body_pose: torch.Tensor) -> GammaSeed:
        """A one-frame seed from single poses: transl (N, 3), global_orient (N, 3|6), body_pose (N, 21, 3|6)."""
        orient = matrix_to_sixd(rotation_matrix(global_orient))
        pose = matrix_to_sixd(rotation_matrix(body_pose))
        joints, markers = self.markers_of(transl, orient, pose)

        def twice(value: torch.Tensor) -> torch.Tensor:
            return torch.stack([value, value], dim=1)

        count = torch.ones(len(transl), dtype=torch.long, device=transl.device)
        return GammaSeed(count, twice(markers), twice(joints), twice(transl), twice(orient), twice(pose))

    @torch.no_grad()
    def step(self, seed: GammaSeed, z: torch.Tensor, goal: torch.Tensor | None = None) -> tuple[Primitive, GammaSeed]:
        """Generate one primitive for every body. z: (N, latent). goal: (N, 3) world, needed (and only used)
        by a goal-conditioned predictor (the g-CVAE baseline)."""
        count = len(z)
        bodies = torch.arange(count, device=z.device)
        one = seed.seed_frames == 1
        first = seed.joints[bodies, 2 - seed.seed_frames]  # (N, 22, 3) first seed frame
        frame = canonical_frame(first)
        seed_markers = to_canonical(seed.markers.flatten(1, 2), frame).unflatten(1, (2, -1))  # (N, 2, 67, 3)

        predicted = torch.empty(count, PRIMITIVE_FRAMES, *seed_markers.shape[2:], dtype=z.dtype, device=z.device)
        for mask, model, frames in ((one, self.predictor_1f, 1), (~one, self.predictor_2f, 2)):
            if mask.any():  # two batched groups, not a loop over bodies
                group_seed = seed_markers[mask][:, 2 - frames :]
                condition = group_seed.flatten(2)
                if model.config.goal_features:
                    if goal is None:
                        raise ValueError("a goal-conditioned predictor needs the bodies' goals")
                    state = goal_observation(seed.markers[mask], first[mask], goal[mask])
                    condition = goal_conditioned_seed(state)[:, 2 - frames :]
                with self._networks():
                    future = model.decode(condition, z[mask]).float().unflatten(-1, (-1, 3))
                predicted[mask] = torch.cat([group_seed, future], dim=1)
        # frames 0 and 1 of a 2-frame seed, and frame 0 of a 1-frame seed, are the seed itself
        seed_slot = torch.stack([2 - seed.seed_frames, torch.ones_like(seed.seed_frames)], dim=1)  # (N, 2)

        with self._networks():
            regressed = {name: value.float() for name, value in self.regressor(predicted[:, 1:]).items()}  # frames 1..9
        rotation = frame.rotation[:, None]
        transl = to_world(regressed["transl"], frame)
        orient = matrix_to_sixd(rotation @ rotation_matrix(regressed["global_orient"]))
        pose = regressed["body_pose"]

        def with_seed(new: torch.Tensor, seed_value: torch.Tensor) -> torch.Tensor:
            """(N, 9, ...) regressed frames 1..9 + seed frames -> (N, 10, ...), seed where it is one."""
            gathered = seed_value[bodies[:, None], seed_slot]  # (N, 2, ...) seed frames in order
            full = torch.cat([gathered[:, :1], new], dim=1)
            keep = (torch.arange(PRIMITIVE_FRAMES, device=z.device) < seed.seed_frames[:, None]).reshape(
                count, PRIMITIVE_FRAMES, *([1] * (new.ndim - 2))
            )
            full[:, 1:2] = torch.where(keep[:, 1:2], gathered[:, 1:2], full[:, 1:2])
            return full

        transl, orient, pose = with_seed(transl, seed.transl), with_seed(orient, seed.global_orient), with_seed(pose, seed.body_pose)
        joints, reprojected = self.markers_of(transl, orient, pose)
        predicted_world = to_world(predicted.flatten(1, 2), frame).unflatten(1, (PRIMITIVE_FRAMES, -1))
        predicted_world = with_seed(predicted_world[:, 1:], seed.markers)
        blended = (1.0 - BLEND_FACTOR) * predicted_world + BLEND_FACTOR * reprojected
        is_seed = (torch.arange(PRIMITIVE_FRAMES, device=z.device) < seed.seed_frames[:, None])[..., None, None]
        markers = torch.where(is_seed, predicted_world, blended)  # seed frames were blended last primitive
        primitive = Primitive(markers, predicted_world, reprojected, joints, transl, orient, pose, seed.seed_frames)
        next_seed = GammaSeed(
            torch.full_like(seed.seed_frames, 2),
            markers[:, -2:], joints[:, -2:], transl[:, -2:], orient[:, -2:], pose[:, -2:],
        )  # fmt: skip
        return primitive, next_seed
