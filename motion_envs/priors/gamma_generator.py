"""GAMMA as a motion generator: latent codes in, bodies moving one primitive at a time out.

One `GammaGenerator.step` takes N bodies' motion seeds (world coordinates)
and N latent codes and, batched over bodies:

1. canonicalises each seed at its first seed frame (GAMMA's frame);
2. predicts the rest of the 10-frame primitive with the 1-frame model for
   bodies with a one-frame seed (episode starts) and the 2-frame model for
   the others;
3. regresses a body for every predicted (new) frame and skins its markers
   (the re-projection); the seed frames keep the seed's own bodies and
   markers, so nothing is regressed or skinned twice;
4. blends: the primitive's markers are the average of predicted and
   re-projected markers (the paper's "ours-ro", release factor 0.5), so a
   body never drifts more than half the prediction error from its markers;
5. with `lock_feet` (the envs' foot rule), fits each body's legs to the
   predicted feet and holds a loaded foot where it touched down
   (`motion_envs.body.foot_lock`, `motion_envs.body.leg_fit`): the regressor
   recovers every frame on its own, so its feet jitter by ~1 cm from frame to
   frame and slide where the prediction holds them still. Only the feet's
   horizontal positions follow the prediction; their heights stay the
   regressor's (the predicted feet sit ~2 cm higher under the pelvis, and
   with the floor rule that sank random-latent bodies by 1.8 cm). Only the
   bodies change (legs below the hips; pelvis, spine, arms and head are the
   regressor's): the blend and so the next seed use the regressor's own
   re-projection, so the prior's motion, and every policy trained on it,
   goes where it went without the rule. Off in `step` alone, the raw prior;
6. with `ground_feet` (the envs' floor rule, as WANDR's stepper), lifts or
   lowers each new frame so that its body's lowest sole point (the soles'
   convex hulls, `sole_hull_vertex_ids`: 50 vertices, heights only)
   is on the floor (grounding the lowest foot marker instead left 0.3-0.7% of
   frames with the mesh more than 3 cm below the floor, tipped feet): our
   small-data prior's height drifts (random latents bury a body or fly it
   metres up), and a walking body always has a foot down (GAMMA generates
   walking; a jump would be pulled down); the seed frames are the previous
   primitive's, already grounded. Off by default: `step` alone is the raw
   prior, which the realism benchmarks measure too;
7. returns the primitive (world) and the next seed: its last two frames.

With `set_heading_calibration(True)` each predicted frame's markers are first turned about their centroid by
minus the predictor's measured heading bias at that frame (`motion_envs.priors.gamma_heading`: each trained
predictor turns its bodies 1-2° per primitive one way, and the hip-based canonical frame compounds it into
whole turns). Off by default: every shipped policy was trained on the uncorrected prior.

With `mirror` (per body) the prior makes the primitive of the seed's mirror image (`mirrored_seed_markers`:
the seed bodies mirrored pose by pose, as the training data's mirror images are, skinned, plus the blend's offsets
carried marker to marker), and the regressed bodies are mirrored back pose by pose; the prediction comes back as
its offsets from their markers (the SSM2 marker set is not left/right symmetric, so markers do not mirror by
index). GammaReach's `mirror_right_goals` uses it: the trained predictors turn left far more readily than right.

Seed frames are part of every primitive (frames 0..S-1), so a primitive always
has 10 frames; the 10 - S after the seed are new.

`precision="bfloat16"` runs the networks (predictor, regressor and the pose
VAE of the pose-prior reward, ~95% of the FLOPs) as bf16 copies and returns
their outputs in fp32; the body model, canonical frames and blending stay
fp32, so positions do not lose bf16's 3 significant digits far from the
origin. Recent x86 CPUs (AMX, AVX512-BF16) multiply bf16 matrices several
times faster than fp32; `motion_envs.precision` picks bf16 only where the CPU
has it natively.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
from pathlib import Path

import torch

from motion_envs.batched import BatchedState
from motion_envs.body import BodyModel
from motion_envs.body.foot_lock import locked_feet
from motion_envs.body.leg_fit import CONTACT_POINTS, LEG_POSE_ROWS, fit_legs, leg_fit_marker_slots
from motion_envs.body.markers import marker_ids
from motion_envs.body.mirror import mirror_body_pose, mirror_marker_offsets, mirror_points, mirror_rotations
from motion_envs.body.soles import sole_hull_vertex_ids
from motion_envs.body.rotations import matrix_to_sixd, rotation_matrix
from motion_envs.data.primitives import GAMMA_FPS, PRIMITIVE_FRAMES
from motion_envs.body.canonical_frame import (
    CanonicalFrame,
    canonical_frame,
    goal_observation,
    to_canonical,
    to_world,
    vectors_to_canonical,
    vectors_to_world,
)
from motion_envs.priors.gamma import MarkerCVAE, PoseVAE, goal_conditioned_seed
from motion_envs.priors.gamma_heading import CALIBRATION_FILE, HeadingCalibration, load_heading_calibration, rotate_about_centroids
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
    markers: (N, 2, 67, 3) what the predictor is seeded with (the blend, step 4).
    body_markers: (N, 2, 67, 3) the same markers skinned on the bodies. joints: (N, 2, 22, 3). transl: (N, 2, 3) pelvis.
    global_orient: (N, 2, 6) and body_pose: (N, 2, 21, 6), 6-D rotations (orthonormal columns).
    """

    seed_frames: torch.Tensor
    markers: torch.Tensor
    body_markers: torch.Tensor
    joints: torch.Tensor
    transl: torch.Tensor
    global_orient: torch.Tensor
    body_pose: torch.Tensor


@dataclasses.dataclass(frozen=True)
class Primitive:
    """One generated primitive of N bodies, world coordinates, 10 frames.

    markers: (N, 10, 67, 3) blended markers (the next seed's). predicted_markers: same, the predictor's.
    reprojected_markers: same, skinned on the bodies (with `lock_feet`, the bodies after foot locking; otherwise
    GAMMA's re-projection, whose blend with the prediction `markers` is). Seed frames (`~new_frames()`) hold the
    seed's blended markers in the first two and its bodies' in the third. joints: (N, 10, 22, 3).
    transl: (N, 10, 3). global_orient: (N, 10, 6). body_pose: (N, 10, 21, 6), orthonormal 6-D rotations.
    seed_frames: (N,).
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
        self.register_buffer("sole_rows", self.body.skin_rows(sole_hull_vertex_ids()), persistent=False)
        self.requires_grad_(False)
        self.eval()
        self.precision = "float32"
        self.register_buffer("leg_fit_slots", leg_fit_marker_slots(), persistent=False)
        self._copies: dict[tuple[str, int, torch.device], torch.nn.Module] = {}
        self.calibration_path: Path | None = None
        """The heading calibration file found beside the weights (`load`), read when it is turned on."""
        self.heading_calibration: HeadingCalibration | None = None

    def set_heading_calibration(self, on: bool) -> GammaGenerator:
        """Turn the predictors' heading calibration (module doc) on or off; returns self.

        Raises:
            FileNotFoundError: on, and no calibration was found beside the weights (`load`).
            CheckpointMismatchError: on, and the calibration was measured with other predictors or regressor.
        """
        if not on:
            self.heading_calibration = None
            return self
        if self.calibration_path is None or not self.calibration_path.is_file():
            raise FileNotFoundError(f"no heading calibration ({CALIBRATION_FILE}) beside these GAMMA weights; measure "
                                    "one with: motion-envs train gamma --stage heading")  # fmt: skip
        networks = {"predictor_1f": self.predictor_1f, "predictor_2f": self.predictor_2f, "regressor": self.regressor}
        self.heading_calibration = load_heading_calibration(self.calibration_path, networks).to(self.device)
        return self

    def set_precision(self, precision: str) -> GammaGenerator:
        """"float32" (default) or "bfloat16" for the networks (see the module doc); returns self."""
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
        self.precision = precision
        return self

    def _network(self, name: str) -> torch.nn.Module:
        """The network `name` at the current precision: itself in fp32; in bf16 a bf16 copy made once per network
        object and device (a network assigned anew gets a new copy).
        Not autocast: it casts every weight again at every call when the weights need no gradient (ours), 278
        casts and ~10 ms of a 1,024-body bf16 step."""
        network = getattr(self, name)
        if self.precision == "float32":
            return network
        key = (name, id(network), self.device)
        if key not in self._copies:
            self._copies[key] = copy.deepcopy(network).to(PRECISIONS[self.precision])
        return self._copies[key]

    def pose_latent(self, body_pose: torch.Tensor) -> torch.Tensor:
        """(..., 21, 6) orthonormal 6-D poses (a `Primitive`'s or `GammaSeed`'s body_pose; the regressor's own
        output is not orthonormal, `rotation_matrix` makes it so) -> (..., latent) the pose VAE's mean (the
        pose-prior reward's input), in fp32."""
        return self._network("pose_vae").encode_sixd(body_pose.to(PRECISIONS[self.precision]))[0].float()

    @classmethod
    def load(cls, weights_dir: str | Path = WEIGHTS_DIR) -> GammaGenerator:
        """The shipped (or `weights_dir`'s) gamma_predictor_1f/2f, gamma_regressor and gamma_pose_vae."""
        weights_dir = Path(weights_dir)
        generator = cls(
            load_predictor(weights_dir / "gamma_predictor_1f.pt"),
            load_predictor(weights_dir / "gamma_predictor_2f.pt"),
            load_regressor(weights_dir / "gamma_regressor.pt"),
            load_pose_vae(weights_dir / "gamma_pose_vae.pt"),
        )
        generator.calibration_path = weights_dir / CALIBRATION_FILE
        return generator

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
        return GammaSeed(count, twice(markers), twice(markers), twice(joints), twice(transl), twice(orient), twice(pose))

    def mirrored_seed_markers(self, seed: GammaSeed, frame: CanonicalFrame) -> torch.Tensor:
        """(N, 2, 67, 3): the seed's markers as its mirror image has them, in the canonical `frame` (batch (N,)) of
        the first seed frame (whose mirror image has the same frame): the mirrored bodies' own markers (a body
        mirrored pose by pose, as the training data's mirror images are) plus the seed markers' offsets from
        their bodies' (the blend's), each carried to the mirror image's marker (`body.mirror`)."""
        return self._mirrored_markers({name: getattr(seed, name) for name in SEED_FIELDS}, frame)

    def _mirrored_markers(self, seed: dict[str, torch.Tensor], frame: CanonicalFrame) -> torch.Tensor:
        """`mirrored_seed_markers` of seed fields (M, S, ...) -> (M, S, 67, 3)."""
        frames = seed["transl"].shape[1]
        offsets = vectors_to_canonical((seed["markers"] - seed["body_markers"]).flatten(1, 2), frame).unflatten(1, (frames, -1))
        transl = to_canonical(seed["transl"], frame)
        orient = frame.rotation.mT[:, None] @ rotation_matrix(seed["global_orient"])
        posed = self.body.from_matrices(mirror_points(transl), mirror_rotations(orient),
                                        mirror_body_pose(rotation_matrix(seed["body_pose"])))  # fmt: skip
        body_markers = self.body.skin_with_rows(posed, self.marker_rows)
        return body_markers + mirror_marker_offsets(offsets)

    @torch.no_grad()
    def step(self, seed: GammaSeed, z: torch.Tensor, goal: torch.Tensor | None = None,
             ground_feet: bool = False, lock_feet: bool = False, mirror: torch.Tensor | None = None) -> tuple[Primitive, GammaSeed]:  # fmt: skip
        """Generate one primitive for every body. z: (N, latent). goal: (N, 3) world, needed (and only used)
        by a goal-conditioned predictor (the g-CVAE baseline). `ground_feet`: the floor rule (module doc, 6).
        `lock_feet`: the foot rule, loaded feet held still (module doc, 5). `mirror`: (N,) bool, bodies whose
        primitive the prior makes for their mirror image (`mirrored_seed_markers`), mirrored back."""
        count = len(z)
        bodies = torch.arange(count, device=z.device)
        first = seed.joints[bodies, 2 - seed.seed_frames]  # (N, 22, 3) first seed frame
        frame = canonical_frame(first)
        seed_slot = torch.stack([2 - seed.seed_frames, torch.ones_like(seed.seed_frames)], dim=1)  # (N, 2) in order
        mirrored = torch.zeros(count, dtype=torch.bool, device=z.device) if mirror is None else mirror.to(z.device)
        if mirrored.any() and self.predictor_2f.config.goal_features:
            raise ValueError("mirror needs a predictor without goal features (the g-CVAE's are not mirrored)")
        parts = []
        for (frames, model), flip in itertools.product(((1, "predictor_1f"), (2, "predictor_2f")), (False, True)):
            rows = torch.nonzero((seed.seed_frames == frames) & (mirrored == flip)).flatten()
            if len(rows):  # up to four batched groups, not a loop over bodies
                group_frame = CanonicalFrame(frame.origin[rows], frame.rotation[rows])
                parts.append((rows, self._group(seed, rows, seed_slot[rows, 2 - frames :], group_frame, model, z[rows],
                                                None if goal is None else goal[rows], first[rows], lock_feet, flip)))  # fmt: skip
        fields = _merge(parts, count)
        lowest_sole = fields.pop("lowest_sole")
        if ground_feet:
            _ground(fields, lowest_sole, seed.seed_frames)
        primitive = Primitive(**fields, seed_frames=seed.seed_frames)
        next_seed = GammaSeed(
            torch.full_like(seed.seed_frames, 2), primitive.markers[:, -2:], primitive.reprojected_markers[:, -2:],
            primitive.joints[:, -2:], primitive.transl[:, -2:], primitive.global_orient[:, -2:],
            primitive.body_pose[:, -2:],
        )  # fmt: skip
        return primitive, next_seed

    def _group(self, seed: GammaSeed, rows: torch.Tensor, slots: torch.Tensor, frame: CanonicalFrame, model: str,
               z: torch.Tensor, goal: torch.Tensor | None, first: torch.Tensor, lock_feet: bool,
               mirrored: bool = False) -> dict[str, torch.Tensor]:  # fmt: skip
        """The primitive of the M bodies `rows` whose seeds have S = `slots.shape[1]` frames (their slots in the
        seed: (M, S)): the 10 - S new frames predicted, regressed to bodies and re-projected (only those: the S seed
        frames are the seed's own bodies and markers), with `lock_feet` the legs fitted, then the seed frames put in
        front. `mirrored`: predicted and regressed for the seeds' mirror images, the bodies mirrored back and the
        prediction carried over as its offsets from their markers. Returns `Primitive`'s fields, (M, 10, ...) each,
        and "lowest_sole" (M, 10): each new frame's lowest sole point (0 at seed frames)."""
        frames = slots.shape[1]
        seed_world = {name: getattr(seed, name)[rows[:, None], slots] for name in SEED_FIELDS}  # (M, S, ...)
        if mirrored:
            group_seed = self._mirrored_markers(seed_world, frame)
        else:
            group_seed = to_canonical(seed_world["markers"].flatten(1, 2), frame).unflatten(1, (frames, -1))  # (M, S, 67, 3)
        condition = group_seed.flatten(2)
        if getattr(self, model).config.goal_features:
            if goal is None:
                raise ValueError("a goal-conditioned predictor needs the bodies' goals")
            state = goal_observation(seed.markers[rows], first, goal)
            condition = goal_conditioned_seed(state)[:, 2 - frames :]
        dtype = PRECISIONS[self.precision]
        future = self._network(model).decode(condition.to(dtype), z.to(dtype)).unflatten(-1, (-1, 3))  # (M, 10 - S, 67, 3)
        if self.heading_calibration is not None:
            future = rotate_about_centroids(future.float(), -self.heading_calibration.correction(model)).to(dtype)
        regressed = {name: value.float() for name, value in self._network("regressor")(future).items()}
        future = future.float()  # canonical coordinates
        canonical_transl = regressed["transl"]
        canonical_orient = rotation_matrix(regressed["global_orient"])
        pose_matrix = rotation_matrix(regressed["body_pose"])  # made orthonormal once, for the body and the reward
        if mirrored:  # the prediction's offsets from its own bodies' markers, then those bodies mirrored back
            offsets = future - self.body.skin_with_rows(self.body.from_matrices(canonical_transl, canonical_orient, pose_matrix),
                                                        self.marker_rows)  # fmt: skip
            canonical_transl, canonical_orient = mirror_points(canonical_transl), mirror_rotations(canonical_orient)
            pose_matrix = mirror_body_pose(pose_matrix)
        transl = to_world(canonical_transl, frame)
        orient_matrix = frame.rotation[:, None] @ canonical_orient
        posed = self.body.from_matrices(transl, orient_matrix, pose_matrix)
        orient, pose = matrix_to_sixd(orient_matrix), matrix_to_sixd(pose_matrix)  # new tensors, orthonormal
        reprojected = self.body.skin_with_rows(posed, self.marker_rows)
        if mirrored:
            predicted = reprojected + vectors_to_world(mirror_marker_offsets(offsets).flatten(1, 2), frame).unflatten(1, (-1, offsets.shape[2]))
        else:
            predicted = to_world(future.flatten(1, 2), frame).unflatten(1, (-1, future.shape[2]))
        markers = seed_world["markers"].new_empty((len(rows), PRIMITIVE_FRAMES, *predicted.shape[2:]))
        markers[:, :frames] = seed_world["markers"]
        torch.lerp(predicted, reprojected, BLEND_FACTOR, out=markers[:, frames:])  # (1 − f) predicted + f re-projected
        if lock_feet:
            track = torch.cat([seed_world["markers"][:, -1:, self.leg_fit_slots], predicted[:, :, self.leg_fit_slots]], 1)
            targets = locked_feet(track, seed_world["body_markers"][:, -1, self.leg_fit_slots], CONTACT_POINTS, GAMMA_FPS)
            regressed_feet = reprojected[:, :, self.leg_fit_slots]
            targets[..., 2] = regressed_feet[..., 2]  # heights: the regressor's (module doc, 5)
            fitted = fit_legs(self.body, posed, transl, regressed_feet, targets)
            posed = fitted.posed
            pose[..., LEG_POSE_ROWS.to(pose.device), :] = matrix_to_sixd(fitted.leg_pose)
            reprojected = self.body.skin_with_rows(posed, self.marker_rows)
        new = {"predicted_markers": predicted, "reprojected_markers": reprojected, "joints": posed.joints,
               "transl": transl, "global_orient": orient, "body_pose": pose}  # fmt: skip
        seed_of = {"predicted_markers": "markers", "reprojected_markers": "body_markers"}
        fields = {name: torch.cat([seed_world[seed_of.get(name, name)], value], dim=1) for name, value in new.items()}
        soles = self.body.heights_with_rows(posed, self.sole_rows).amin(-1)  # (M, 10 - S)
        return {"markers": markers, **fields, "lowest_sole": torch.cat([soles.new_zeros(len(rows), frames), soles], 1)}


SEED_FIELDS = ("markers", "body_markers", "joints", "transl", "global_orient", "body_pose")
POSITION_FIELDS = ("markers", "predicted_markers", "reprojected_markers", "joints", "transl")


def _ground(fields: dict[str, torch.Tensor], lowest_sole: torch.Tensor, seed_frames: torch.Tensor) -> None:
    """Move each new frame of `Primitive` fields (N, 10, ...), made in this step, vertically in place so that its
    lowest sole point (`lowest_sole`, (N, 10) heights) is at z = 0; seed frames stay."""
    new = torch.arange(PRIMITIVE_FRAMES, device=seed_frames.device) >= seed_frames[:, None]  # (N, 10)
    lift = torch.where(new, -lowest_sole, torch.zeros_like(lowest_sole))  # (N, 10)
    for name in POSITION_FIELDS:
        value = fields[name]
        value[..., 2] += lift if value.dim() == 3 else lift[..., None]


def _merge(parts: list[tuple[torch.Tensor, dict[str, torch.Tensor]]], count: int) -> dict[str, torch.Tensor]:
    """Per-group fields (rows (M,), {name: (M, ...)}) -> {name: (count, ...)}, each body's row from its group."""
    if len(parts) == 1:
        return parts[0][1]  # one group holds every body, in order
    merged = {}
    for name, value in parts[0][1].items():
        merged[name] = value.new_empty((count, *value.shape[1:]))
        for rows, fields in parts:
            merged[name][rows] = fields[name]
    return merged
