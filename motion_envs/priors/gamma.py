"""GAMMA's generative motion primitives (Zhang & Tang, CVPR 2022) as torch modules.

* `MarkerCVAE`: the marker predictor. Seed X (1 or 2 frames of 67 markers,
  canonical) and future Y (10 - |X| frames); GRU encoders of X and Y feed an
  MLP to the latent z; a GRU-cell decoder predicts each next frame as a
  residual on the previous one from [seed state, z, previous frame]. Sizes
  follow the authors' release (REFERENCE_NOTES §1.3): hidden 256, z 128,
  MLP [512, 256], tanh after every linear layer of the MLPs.
* `BodyRegressor`: markers -> body parameters, a residual MLP applied three
  times, each time refining its own estimate (6-D rotations inside), as the
  release's MoshRegressor (hidden 128, 10 blocks, 3 recursions). One network:
  our body has one shape and fixed hands, so the gender split, betas and hand
  PCA of the paper are dropped.
* `PoseVAE`: a small VAE over single body poses standing in for VPoser in
  r_vposer (VPoser's weights are not redistributable and are SMPL-X's).

Losses are pure functions below (`predictor_loss`, `robust_kl`, ...).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from motion_envs.body.rotations import matrix_to_axis_angle, matrix_to_sixd, rotation_matrix
from motion_envs.body.skeleton import NUM_BODY_POSE_JOINTS
from motion_envs.data.primitives import PRIMITIVE_FRAMES
from motion_envs.priors.inference_linear import InferenceSequential, linear

NUM_MARKERS = 67
MARKER_DIM = NUM_MARKERS * 3
BODY_DIM = 3 + 6 + NUM_BODY_POSE_JOINTS * 6
"""Regressor estimate: transl (3), global orient 6-D (6), 21 joints 6-D (126)."""


class TanhMLP(InferenceSequential):
    """Linear layers with tanh after every one (the release's MLP); at inference each linear + tanh is one oneDNN
    call (`inference_linear`; 1,024 × 256 -> 512 in bf16: 0.83 -> 0.27 ms)."""


def tanh_mlp(sizes: list[int]) -> TanhMLP:
    """Linear layers of the given sizes with tanh after every one (the release's MLP)."""
    layers: list[nn.Module] = []
    for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(fan_in, fan_out), nn.Tanh()]
    return TanhMLP(*layers)


@dataclass(frozen=True)
class MarkerCVAEConfig:
    seed_frames: int = 2
    hidden: int = 256
    latent: int = 128
    mlp: tuple[int, ...] = (512, 256)
    goal_features: bool = False
    """GAMMA's g-CVAE baseline: every seed frame also carries the unit vectors from its markers to the goal
    (Eq. 3's goal features; `goal_conditioned_seed`), 402 values per frame instead of 201."""

    @property
    def future_frames(self) -> int:
        return PRIMITIVE_FRAMES - self.seed_frames

    @property
    def seed_dim(self) -> int:
        return 2 * MARKER_DIM if self.goal_features else MARKER_DIM


class MarkerCVAE(nn.Module):
    """Marker predictor: seed (B, S, 201) + z (B, 128) -> future (B, 10 - S, 201).

    With `goal_features` the seed is (B, S, 402): markers, then marker-to-goal unit vectors."""

    def __init__(self, config: MarkerCVAEConfig = MarkerCVAEConfig()) -> None:
        super().__init__()
        if config.seed_frames not in (1, 2):
            raise ValueError(f"seed_frames must be 1 or 2, got {config.seed_frames}")
        self.config = config
        hidden, latent = config.hidden, config.latent
        self.seed_encoder = nn.GRU(config.seed_dim, hidden, batch_first=True)
        self.future_encoder = nn.GRU(MARKER_DIM, hidden, batch_first=True)
        self.posterior = tanh_mlp([2 * hidden, *config.mlp])
        self.mean = nn.Linear(config.mlp[-1], latent)
        self.log_variance = nn.Linear(config.mlp[-1], latent)
        self.initial_state = tanh_mlp([hidden, 512, 256, hidden])
        self.cell = nn.GRUCell(hidden + latent + MARKER_DIM, hidden)
        self.readout = InferenceSequential(tanh_mlp([hidden, *config.mlp]), nn.Linear(config.mlp[-1], MARKER_DIM))

    def seed_state(self, seed: torch.Tensor) -> torch.Tensor:
        """(B, S, 201 | 402) -> (B, hidden) final GRU state of the seed."""
        self._check(seed, self.config.seed_frames, "seed", self.config.seed_dim)
        return self.seed_encoder(seed)[1][0]

    def encode(self, seed: torch.Tensor, future: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Posterior q(z | X, Y): mean and log-variance, (B, latent) each."""
        self._check(future, self.config.future_frames, "future")
        features = torch.cat([self.seed_state(seed), self.future_encoder(future)[1][0]], dim=-1)
        hidden = self.posterior(features)
        return self.mean(hidden), self.log_variance(hidden)

    def decode(self, seed: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """(B, S, 201 | 402) seed and (B, latent) z -> (B, 10 - S, 201) predicted markers.

        The GRU cell's input is [context, z, previous frame]; the first two are the same at every step, so their
        share of the input projection is computed once (`self.cell`'s weights, its equations written out): 384 of
        the 585 input columns, 12 of the 64 ms that decoding 1,024 bodies took (fp32, 2 cores)."""
        context = self.seed_state(seed)
        state = self.initial_state(context)
        previous = seed[:, -1, :MARKER_DIM]
        steady = context.shape[-1] + z.shape[-1]
        weight, bias = self.cell.weight_ih, self.cell.bias_ih
        constant = linear(torch.cat([context, z], dim=-1), weight[:, :steady], bias)  # (B, 3·hidden)
        frame_weight = weight[:, steady:].contiguous()
        frames = []
        features, output = self.readout[0], self.readout[1]
        for _ in range(self.config.future_frames):  # 8 or 9 steps of one primitive, batched over bodies
            # the sums inside the linears (`linear`'s `add`): no separate pass over their outputs
            state = self._cell(linear(previous, frame_weight, add=constant), state)
            previous = linear(features(state), output.weight, output.bias, add=previous)
            frames.append(previous)
        return torch.stack(frames, dim=1)

    def _cell(self, projected: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        """`nn.GRUCell` given its input already projected, `projected` = W_ih x + b_ih (B, 3·hidden); without
        autograd every step after the two sums runs in place (the same values: 9 fresh (B, hidden) tensors a step
        fewer)."""
        hidden = linear(state, self.cell.weight_hh, self.cell.bias_hh)
        reset_in, update_in, new_in = projected.chunk(3, dim=-1)
        reset_h, update_h, new_h = hidden.chunk(3, dim=-1)
        if torch.is_grad_enabled():
            reset, update = torch.sigmoid(reset_in + reset_h), torch.sigmoid(update_in + update_h)
            candidate = torch.tanh(new_in + reset * new_h)
            return candidate + update * (state - candidate)  # (1 − u) n + u h
        reset, update = (reset_in + reset_h).sigmoid_(), (update_in + update_h).sigmoid_()
        candidate = _tanh(new_h.mul_(reset).add_(new_in))
        return (state - candidate).mul_(update).add_(candidate)

    def forward(self, seed: torch.Tensor, future: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Reconstruction through the posterior: (B, 10 - S, 201), mean, log-variance."""
        mean, log_variance = self.encode(seed, future)
        z = mean + torch.randn_like(mean) * torch.exp(0.5 * log_variance)
        return self.decode(seed, z), mean, log_variance

    def _check(self, frames: torch.Tensor, count: int, name: str, size: int = MARKER_DIM) -> None:
        if frames.ndim != 3 or frames.shape[1:] != (count, size):
            raise ValueError(f"{name} must be (B, {count}, {size}), got {tuple(frames.shape)}")


def _tanh(x: torch.Tensor) -> torch.Tensor:
    """tanh of a fresh tensor (overwritten). In bf16 through fp32: torch 2.13's bf16 tanh on the CPU is slower than
    the round trip (1,024 x 256, 2 cores: 213 against 75 us) and gives the same values."""
    if x.dtype == torch.bfloat16:
        return x.float().tanh_().to(torch.bfloat16)
    return x.tanh_()


def goal_conditioned_seed(observation: torch.Tensor) -> torch.Tensor:
    """The environment's state (B, 804) (`goal_observation`: per seed frame, 67 × (marker, unit vector to the
    goal)) -> the g-CVAE's seed (B, 2, 402): per frame, the 201 marker values, then the 201 goal-vector values."""
    per_marker = observation.unflatten(-1, (2, NUM_MARKERS, 6))
    return torch.cat([per_marker[..., :3].flatten(-2), per_marker[..., 3:].flatten(-2)], dim=-1)


def kl_to_standard_normal(mean: torch.Tensor, log_variance: torch.Tensor) -> torch.Tensor:
    """(..., D) -> (...) KL(N(mean, exp(log_variance)) || N(0, I)) averaged over D (the release's scale)."""
    return 0.5 * (mean.pow(2) + log_variance.exp() - 1.0 - log_variance).mean(dim=-1)


def robust_kl(kl: torch.Tensor) -> torch.Tensor:
    """Ψ(s) = sqrt(1 + s²) − 1 (GAMMA Eq. 1): small KL gets a small gradient, against posterior collapse."""
    return torch.sqrt(1.0 + kl.pow(2)) - 1.0


def predictor_loss(
    seed: torch.Tensor,
    future: torch.Tensor,
    reconstruction: torch.Tensor,
    mean: torch.Tensor,
    log_variance: torch.Tensor,
    difference_weight: float = 3.0,
) -> dict[str, torch.Tensor]:
    """GAMMA Eq. 1: |Y − Y_rec| + 3 |ΔY − ΔY_rec| + Ψ(KL). Differences include the step from the last seed frame."""
    target = torch.cat([seed[:, -1:], future], dim=1)
    predicted = torch.cat([seed[:, -1:], reconstruction], dim=1)
    terms = {
        "reconstruction": (future - reconstruction).abs().mean(),
        "difference": (target.diff(dim=1) - predicted.diff(dim=1)).abs().mean(),
        "kl": robust_kl(kl_to_standard_normal(mean, log_variance).mean()),
    }
    terms["total"] = terms["reconstruction"] + difference_weight * terms["difference"] + terms["kl"]
    return terms


@dataclass(frozen=True)
class BodyRegressorConfig:
    hidden: int = 128
    blocks: int = 10
    recursions: int = 3


class ResidualBlock(nn.Module):
    def __init__(self, width: int) -> None:
        super().__init__()
        self.layers = InferenceSequential(
            nn.Linear(width, width), nn.ReLU(inplace=True), nn.Linear(width, width), nn.ReLU(inplace=True)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x + relu(W2 relu(W1 x + b1) + b2); at inference each linear + ReLU is one oneDNN call (the regressor at
        1,024 bodies × 8 frames, bf16: 33 -> 23 ms) and x is added in place into the block's fresh output (the
        same sum; a new (8,192, 128) fp32 tensor per add was 15 of the regressor's 190 ms on one thread)."""
        if torch.is_grad_enabled():
            return x + self.layers(x)
        return self.layers(x).add_(x)


class BodyRegressor(nn.Module):
    """Markers (..., 67, 3) in a primitive's canonical frame -> body parameters of the same frame."""

    def __init__(self, config: BodyRegressorConfig = BodyRegressorConfig()) -> None:
        super().__init__()
        self.config = config
        self.net = InferenceSequential(
            nn.Linear(MARKER_DIM + BODY_DIM, config.hidden),
            *[ResidualBlock(config.hidden) for _ in range(config.blocks)],
            nn.Linear(config.hidden, BODY_DIM),
        )

    def forward(self, markers: torch.Tensor) -> dict[str, torch.Tensor]:
        """Returns transl (..., 3), global_orient (..., 6) and body_pose (..., 21, 6), 6-D rotations."""
        if markers.shape[-2:] != (NUM_MARKERS, 3):
            raise ValueError(f"markers must end in ({NUM_MARKERS}, 3), got {tuple(markers.shape)}")
        flat = markers.reshape(-1, MARKER_DIM)
        estimate = torch.zeros(flat.shape[0], BODY_DIM, dtype=flat.dtype, device=flat.device)
        entry, rest = self.net[0], self.net[1:]
        from_markers = linear(flat, entry.weight[:, :MARKER_DIM], entry.bias)  # the same in every recursion: once
        blocks, exit_layer = rest[:-1], rest[-1]
        for _ in range(self.config.recursions):  # net([markers, estimate]), the first layer split by its inputs
            hidden = blocks(linear(estimate, entry.weight[:, MARKER_DIM:], add=from_markers))
            estimate = linear(hidden, exit_layer.weight, exit_layer.bias, add=estimate)  # the sums inside the linears
        batch = markers.shape[:-2]
        return {
            "transl": estimate[:, :3].reshape(*batch, 3),
            "global_orient": estimate[:, 3:9].reshape(*batch, 6),
            "body_pose": estimate[:, 9:].reshape(*batch, NUM_BODY_POSE_JOINTS, 6),
        }


def to_axis_angle(params: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Regressor output with 6-D rotations -> the same with axis-angle rotations."""
    return {
        "transl": params["transl"],
        "global_orient": matrix_to_axis_angle(rotation_matrix(params["global_orient"])),
        "body_pose": matrix_to_axis_angle(rotation_matrix(params["body_pose"])),
    }


@dataclass(frozen=True)
class PoseVAEConfig:
    hidden: int = 256
    latent: int = 32


class PoseVAE(nn.Module):
    """A VAE over single body poses (21 joints, 6-D in, 6-D out)."""

    def __init__(self, config: PoseVAEConfig = PoseVAEConfig()) -> None:
        super().__init__()
        self.config = config
        width = NUM_BODY_POSE_JOINTS * 6
        self.encoder = InferenceSequential(
            nn.Linear(width, config.hidden), nn.LeakyReLU(0.2), nn.Linear(config.hidden, config.hidden), nn.LeakyReLU(0.2)
        )
        self.mean = nn.Linear(config.hidden, config.latent)
        self.log_variance = nn.Linear(config.hidden, config.latent)
        self.decoder = InferenceSequential(
            nn.Linear(config.latent, config.hidden), nn.LeakyReLU(0.2),
            nn.Linear(config.hidden, config.hidden), nn.LeakyReLU(0.2), nn.Linear(config.hidden, width),
        )  # fmt: skip

    def encode(self, body_pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(..., 21, 3 | 6) poses -> mean, log-variance (..., latent)."""
        return self.encode_sixd(matrix_to_sixd(rotation_matrix(body_pose)))

    def encode_sixd(self, sixd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """`encode` of poses already as orthonormal 6-D rotations (..., 21, 6)."""
        hidden = self.encoder(sixd.flatten(-2))
        mean = linear(hidden, self.mean.weight, self.mean.bias)
        return mean, linear(hidden, self.log_variance.weight, self.log_variance.bias)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """(..., latent) -> (..., 21, 3, 3) rotation matrices."""
        return rotation_matrix(self.decoder(z).unflatten(-1, (NUM_BODY_POSE_JOINTS, 6)))


def pose_vae_loss(model: PoseVAE, body_pose: torch.Tensor, kl_weight: float = 5e-3) -> dict[str, torch.Tensor]:
    """Rotation-matrix reconstruction (MSE) + kl_weight · KL."""
    mean, log_variance = model.encode(body_pose)
    z = mean + torch.randn_like(mean) * torch.exp(0.5 * log_variance)
    target = rotation_matrix(body_pose)
    terms = {
        "reconstruction": (model.decode(z) - target).pow(2).mean(),
        "kl": kl_to_standard_normal(mean, log_variance).mean(),
    }
    terms["total"] = terms["reconstruction"] + kl_weight * terms["kl"]
    return terms
