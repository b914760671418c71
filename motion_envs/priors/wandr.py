"""WANDR's intention-conditioned motion prior (Diomataris et al., CVPR 2024) as a torch module.

A conditional VAE over one frame's pose delta (135, see `wandr_features`):
the encoder sees [condition (277), delta (135)] and gives q(z | ·) with
z ∈ R^64; the decoder maps [z, condition] to the delta. Both are MLPs whose
layers are LayerNorm → dropout → Linear → ReLU (no activation after the
last), hidden widths the release's rule: linspace(in, out) rounded up to a
power of two (REFERENCE_NOTES §2.3). The paper uses 15 layers each; the
default here is `layers = 8`, which trains on 2 CPU cores within an hour
(the manifest records its validation loss) — set `layers=15` for the
paper's depth.

Inputs and outputs are z-scored with statistics of the training data held
as buffers, so a checkpoint carries its own normalisation. Sampling uses
the standard μ + ε·exp(½ logvar) (the release's exp(logvar) is a quirk).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from motion_envs.body import BodyModel, BodyPose
from motion_envs.body.foot_lock import locked_feet
from motion_envs.body.leg_fit import CONTACT_POINTS, LEG_POSE_ROWS, FittedLegs, fit_legs, leg_fit_marker_ids
from motion_envs.body.markers import foot_vertex_ids
from motion_envs.priors.inference_linear import InferenceSequential
from motion_envs.priors.wandr_features import (
    CONDITION_DIM, DELTA_DIM, FPS, INTENTIONS, WandrState, condition, integrate, intention, make_state,
)  # fmt: skip


WANDR_MAX_OFFSET = 0.15
"""The farthest (m) the foot rule holds a WANDR foot from the prior's (GAMMA's: `foot_lock.MAX_OFFSET`, 12 cm).
The shown legs are not fed back, and WANDR's bent legs rarely run out of reach: under the PPO policy's mean latent
(750 grid rollouts) caps of 5 / 8 / 12 / 15 / 20 cm gave WANDR's FS 34.4 / 29.0 / 25.5 / 24.2 / 23.2% (no rule 55.6%)
with 0.08 / 0.19 / 0.26 / - / 0.45% of leg solves out of reach."""

PRIOR_LAYERS = 3
"""Linear layers of the learned prior's network (`WandrConfig.learned_prior`)."""


@dataclass(frozen=True)
class WandrConfig:
    latent: int = 64
    layers: int = 8
    max_width: int = 512
    dropout: float = 0.03
    intentions: tuple[str, ...] = INTENTIONS
    """Intention components the prior is conditioned on (the paper's ablations drop some)."""
    learned_prior: bool = False
    """Ours: a conditional prior p(z | c) = N(μ(c), σ(c)²) (the prior network of Sohn et al.'s CVAE) instead of
    WANDR's N(0, I). Latents given to `generate` stay N(0, I) noise ε, mapped to z = μ(c) + σ(c)·ε, so samplers
    and policies are unchanged. Not shipped: trained from scratch with the shipped recipe it raised the paced
    sampler to 72.0% SR / 76.0% FS (shipped prior 63.2 / 80.9; z = 0: 63.6 / 65.1 against 58.4 / 67.3) but not
    the 8-s one (0.8 / 69.0 against 2.8 / 71.6), on 500 grid rollouts (`benchmarks.wandr_grid`)."""

    def __post_init__(self) -> None:
        unknown = set(self.intentions) - set(INTENTIONS)
        if unknown or not self.intentions:
            raise ValueError(f"intentions must be a non-empty subset of {INTENTIONS}, got {self.intentions}")
        if self.layers < 2:
            raise ValueError(f"layers must be at least 2, got {self.layers}")


def release_widths(fan_in: int, fan_out: int, layers: int, max_width: int) -> list[int]:
    """Sizes of `layers` Linear layers from fan_in to fan_out: linspace rounded up to powers of two."""
    points = torch.linspace(fan_in, fan_out, layers + 1).tolist()
    hidden = [min(max_width, 2 ** math.ceil(math.log2(p))) for p in points[1:-1]]
    return [fan_in, *hidden, fan_out]


def layer_norm_mlp(sizes: list[int], dropout: float) -> InferenceSequential:
    """LayerNorm → dropout → Linear (→ ReLU except after the last) for each consecutive pair of sizes; at inference
    each linear and its ReLU are one oneDNN call (`inference_linear`)."""
    blocks: list[nn.Module] = []
    for index, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        blocks += [nn.LayerNorm(fan_in), nn.Dropout(dropout), nn.Linear(fan_in, fan_out)]
        if index < len(sizes) - 2:
            blocks.append(nn.ReLU())
    return InferenceSequential(*blocks)


class WandrPrior(nn.Module):
    """Encoder q(z | c, d), decoder d = f(z, c), and the statistics that z-score c and d.

    c: (B, 277) condition. d: (B, 135) delta. z: (B, latent).
    """

    def __init__(self, config: WandrConfig = WandrConfig()) -> None:
        super().__init__()
        self.config = config
        widths = (config.layers, config.max_width)
        self.encoder = layer_norm_mlp(release_widths(CONDITION_DIM + DELTA_DIM, 2 * config.latent, *widths), config.dropout)
        self.decoder = layer_norm_mlp(release_widths(config.latent + CONDITION_DIM, DELTA_DIM, *widths), config.dropout)
        self.prior_network = None
        if getattr(config, "learned_prior", False):
            self.prior_network = layer_norm_mlp(release_widths(CONDITION_DIM, 2 * config.latent, PRIOR_LAYERS, config.max_width),
                                                config.dropout)  # fmt: skip
            last = self.prior_network[-1]
            nn.init.zeros_(last.weight)  # starts as N(0, I)
            nn.init.zeros_(last.bias)
        self.register_buffer("condition_mean", torch.zeros(CONDITION_DIM))
        self.register_buffer("condition_std", torch.ones(CONDITION_DIM))
        self.register_buffer("delta_mean", torch.zeros(DELTA_DIM))
        self.register_buffer("delta_std", torch.ones(DELTA_DIM))

    def set_statistics(self, conditions: torch.Tensor, deltas: torch.Tensor, condition_floor: float,
                       delta_floor: float) -> None:  # fmt: skip
        """z-score statistics from training samples: conditions (N, 277), deltas (N, 135); standard
        deviations no smaller than the floors."""
        for name, values, floor in (("condition", conditions, condition_floor), ("delta", deltas, delta_floor)):
            getattr(self, f"{name}_mean").copy_(values.mean(0))
            getattr(self, f"{name}_std").copy_(values.std(0).clamp_min(floor))

    def normalise_condition(self, condition_features: torch.Tensor) -> torch.Tensor:
        return (condition_features - self.condition_mean) / self.condition_std

    def normalise_delta(self, delta: torch.Tensor) -> torch.Tensor:
        return (delta - self.delta_mean) / self.delta_std

    def denormalise_delta(self, normalised: torch.Tensor) -> torch.Tensor:
        return normalised * self.delta_std + self.delta_mean

    def encode(self, normalised_condition: torch.Tensor, normalised_delta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """-> mean (B, latent), log-variance (B, latent)."""
        mean, log_variance = self.encoder(torch.cat([normalised_condition, normalised_delta], 1)).chunk(2, dim=1)
        return mean, log_variance

    def decode(self, z: torch.Tensor, normalised_condition: torch.Tensor) -> torch.Tensor:
        """-> normalised delta (B, 135)."""
        return self.decoder(torch.cat([z, normalised_condition], 1))

    def prior(self, normalised_condition: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """p(z | c): mean (B, latent), log-variance (B, latent); zeros for WANDR's N(0, I)."""
        if self.prior_network is None:
            zeros = normalised_condition.new_zeros(len(normalised_condition), self.config.latent)
            return zeros, zeros
        mean, log_variance = self.prior_network(normalised_condition).chunk(2, dim=1)
        return mean, log_variance

    def generate(self, noise: torch.Tensor, normalised_condition: torch.Tensor) -> torch.Tensor:
        """The normalised delta (B, 135) for latent noise ε (B, latent) ~ N(0, I): decodes z = μ(c) + σ(c)·ε."""
        if self.prior_network is None:
            return self.decode(noise, normalised_condition)
        mean, log_variance = self.prior(normalised_condition)
        return self.decode(mean + noise * torch.exp(0.5 * log_variance), normalised_condition)


class WandrStepper:
    """Rolls bodies forward one frame at a time with a trained prior (the inference of Sec. 3.5).

    Each `step` recomputes the intention towards the goal from the current
    pose (the closed loop), decodes the delta for latent z and integrates it.
    With `ground_feet` (default) the body is then moved vertically so that
    its lowest foot vertex touches the floor: our prior's integrated height
    drifts (see `wandr_features`), and a walking-and-reaching body always
    has a foot down. The paper's generation has no such step; set it off
    to see the prior alone. With `lock_feet` each frame is shown with its
    legs fitted (`motion_envs.body.leg_fit`) so that a foot loaded in the
    previous frame stays where the shown body had it
    (`motion_envs.body.foot_lock`): `WandrState.shown_pose`. As in GAMMA
    (whose next seed keeps the regressor's bodies), the prior goes on from
    its own pose: fed back, the held legs made the prior fold a 15-s walk
    (head over the last second 0.69 m, 1.12 m without the rule; lowest head
    -0.50 m; `bench floor`), and the rule leaves the prior's motion, and the
    policies trained on it, as they are. `intentions` overrides which intention parts the
    prior is shown (default: those it was trained with; () shows none).
    """

    def __init__(self, prior: WandrPrior, body: BodyModel | None = None, ground_feet: bool = True,
                 intentions: tuple[str, ...] | None = None, lock_feet: bool = False) -> None:  # fmt: skip
        self.prior = prior
        self.body = body or BodyModel()
        self.ground_feet, self.lock_feet = ground_feet, lock_feet
        self.fit_rows = self.body.skin_rows(leg_fit_marker_ids().flatten().to(self.body.offsets.device))
        self.intentions = prior.config.intentions if intentions is None else tuple(intentions)
        self.foot_rows = self.body.skin_rows(foot_vertex_ids().to(self.body.offsets.device))

    def feet(self, posed: BodyPose) -> torch.Tensor:
        """(B, V, 3) foot vertices of posed bodies."""
        return self.body.skin_with_rows(posed, self.foot_rows)

    def condition(self, state: WandrState, goal: torch.Tensor, frames_left: torch.Tensor) -> torch.Tensor:
        """(B, 277) the normalised condition of bodies towards goals (B, 3) due in `frames_left` (B,) frames."""
        features = intention(state.joints, state.orient, goal, frames_left, components=self.intentions)
        return self.prior.normalise_condition(condition(state, features))

    def step(self, state: WandrState, z: torch.Tensor, goal: torch.Tensor,
             frames_left: torch.Tensor) -> tuple[WandrState, torch.Tensor]:  # fmt: skip
        """The next frame of bodies `state` (batch B) decoded with latents z (B, latent), and its foot vertices (B, V, 3)."""
        delta = self.prior.denormalise_delta(self.prior.generate(z, self.condition(state, goal, frames_left)))
        return self.advance(state, delta)

    def advance(self, state: WandrState, delta: torch.Tensor) -> tuple[WandrState, torch.Tensor]:
        """Bodies `state` moved by their decoded deltas (B, 135): integrated, grounded, and (`lock_feet`) shown with
        their feet held; and the shown bodies' foot vertices (B, V, 3)."""
        transl, orient, pose = integrate(state.transl, state.orient, state.pose, delta)
        following, posed = make_state(self.body, transl, orient, pose, delta)
        feet = self.feet(posed)
        following, lift = self.grounded(following, feet)
        if not self.lock_feet:
            return following, feet + lift[:, None]
        fitted = self.held_legs(state, posed, following.transl)
        shown = pose.clone()
        shown[:, LEG_POSE_ROWS.to(pose.device)] = fitted.leg_pose
        return following._replace(shown_pose=shown), self.feet(fitted.posed)

    def held_legs(self, state: WandrState, posed: BodyPose, transl: torch.Tensor) -> FittedLegs:
        """The next frame's legs (its body `posed`, before grounding; its pelvis then at `transl`) fitted so that a
        foot loaded at `state` stays where the shown body put it (`locked_feet` over the two frames, the shown
        body's offset from the prior's carried in as the seed offset)."""
        both = (torch.stack([value, value]) for value in (state.transl, state.orient))  # the prior's body and the shown one
        before = self.body.from_matrices(*both, torch.stack([state.pose, state.shown_pose]))  # one batch (2, B)
        prior_first, shown_first = self.body.skin_with_rows(before, self.fit_rows).unflatten(-2, (2, -1))  # (B, 2 feet, 5, 3)
        track = torch.stack([prior_first, self.body.skin_with_rows(posed, self.fit_rows).unflatten(-2, (2, -1))], dim=1)
        targets = locked_feet(track, shown_first, CONTACT_POINTS, FPS, WANDR_MAX_OFFSET)[:, 0]
        return fit_legs(self.body, posed, transl, track[:, 1], targets)

    def grounded(self, state: WandrState, feet: torch.Tensor) -> tuple[WandrState, torch.Tensor]:
        """Bodies moved vertically so that the lowest of their foot vertices (B, V, 3) is on the floor (unmoved
        without `ground_feet`), and the lift (B, 3)."""
        lift = torch.zeros_like(state.transl)
        if self.ground_feet:
            lift[:, 2] = -feet[..., 2].amin(dim=-1)
        return state._replace(transl=state.transl + lift, joints=state.joints + lift[:, None]), lift
