"""Foot locking for generated motion: hold a loaded foot where it touched down, release it smoothly.

The data pipeline locks feet in the training clips (`motion_envs.data.cleanup`), but a prior trained on them
still lets a planted foot drift: GAMMA's predicted foot markers under the shipped GammaReach policy move faster
than 0.2 m/s in 26% of walking transitions at their loaded point (the clean data: 8-16%). `locked_feet` takes one
primitive's foot markers as predicted and moves each foot horizontally so that, while it is loaded, its loaded
point does not move:

- loaded: the foot's lower contact point (heel or ball of the foot) is within `LOCK_HEIGHT` of the lower foot's
  in this frame and the one before (both feet in double support), and the prediction moves it slower than
  `LOCK_SPEED` (a swing foot skimming the floor moves at 1.5-4 m/s);
- while loaded, the foot's horizontal offset from the prediction grows by minus the prediction's step of that
  point, so the point stays put; the foot's rotation is the prediction's (a heel strike rolls about the heel,
  a turn pivots about the ball);
- when the foot lifts, the offset shrinks by `RELEASE` per frame, so the foot rejoins the prediction in a few
  frames without a jump;
- the offset never exceeds `MAX_OFFSET`: where the prediction slides a foot farther (a shuffle, a turn on
  sliding feet) the foot follows it that far behind; the leg is not stretched to hold it (the clamp is applied
  to the recurrence's solution, so a foot held at the limit is released from its unclamped offset: at most a
  frame or two later than a frame-by-frame clamp would);
- the offset at the primitive's first (seed) frame is where the body's foot is minus where the predictor saw
  it, so a contact carries over from one primitive to the next.

The offsets follow the linear recurrence o_k = a_k o_{k-1} + b_k (a_k 1 or `RELEASE`, b_k minus the step or
0), solved for all frames at once: o_k = sum_{j<=k} (a_{j+1}...a_k) b_j + (a_1...a_k) o_0, the products as
exponentials of differences of the cumulative sums of log a.
"""

from __future__ import annotations

import math

import torch

LOCK_HEIGHT = 0.05
"""A foot within this height (m) of the lower foot can be loaded."""

LOCK_SPEED = 0.8
"""Horizontal speed (m/s) of the predicted contact point above which the foot is moving, not slipping."""

RELEASE = 0.5
"""Share of the offset a lifted foot keeps from one frame to the next."""

MAX_OFFSET = 0.12
"""The farthest (m) a foot is held from its prediction: a prediction that keeps sliding (a shuffle) drags it on.
GAMMA's. Measured on the clean prior (the rule is shown only, so success does not move): caps of 5 / 8 / 12 cm
gave the α = 10 (cloned) policy's bodies FS 0.465 / 0.432 / 0.410 (50 pairs × 8 clones, per body 0.77 at every
cap) and put 3.3 / 5.7 / 8.8% of the α = 1 policy's leg solves out of reach (64 bodies × 30 primitives; such a
foot is pulled under the hip, still on the floor); frames side by side showed no stretched legs at 12 cm. (On the
previous prior, 3 / 5 / 8 / 12 cm: FS 0.38 / 0.35 / 0.31 / 0.27 under the α = 1 policy.) WANDR's is its own
(`priors.wandr.WANDR_MAX_OFFSET`)."""


def locked_feet(feet: torch.Tensor, body_first: torch.Tensor, contact_points: tuple[int, int], fps: float,
                max_offset: float = MAX_OFFSET) -> torch.Tensor:  # fmt: skip
    """Predicted foot points with each loaded foot held in place (module doc).

    Args:
        feet: (..., T, 2, P, 3) the points of both feet (left, right) as predicted, world; frame 0 is the seed
            frame as the predictor saw it.
        body_first: (..., 2, P, 3) the same points on the body at frame 0.
        contact_points: which two of the P points can bear weight (e.g. heel and ball of the foot).
        fps: frame rate.
        max_offset: the farthest (m) a foot is held from its prediction (`MAX_OFFSET`: GAMMA's).

    Returns:
        (..., T - 1, 2, P, 3) targets for frames 1..T-1: the prediction moved horizontally.
    """
    candidates = feet[..., list(contact_points), :]  # (..., T, 2, 2, 3)
    lower = (candidates[..., 1, 2] < candidates[..., 0, 2]).long()[..., None]  # (..., T, 2, 1) each foot's loaded
    # point (an argmin over two, written as a comparison: argmin's reduction over a last dimension of 2 was 4 ms)
    point = candidates.gather(-2, lower[..., None].expand(*lower.shape, 3)).squeeze(-2)  # (..., T, 2, 3)
    height = point[..., 2] - point[..., 2].amin(-1, keepdim=True)  # (..., T, 2) above the lower foot
    near = height < LOCK_HEIGHT
    previous = lower[..., :-1, :, :]  # the point loaded at k - 1, followed to k
    now = candidates[..., 1:, :, :, :].gather(-2, previous[..., None].expand(*previous.shape, 3)).squeeze(-2)
    step = now[..., :2] - point[..., :-1, :, :2]  # (..., T-1, 2, 2)
    held = near[..., :-1, :] & near[..., 1:, :] & (step.norm(dim=-1) * fps < LOCK_SPEED)  # (..., T-1, 2)
    log_keep = torch.where(held, torch.zeros_like(step[..., 0]), torch.full_like(step[..., 0], math.log(RELEASE)))
    pushes = torch.where(held[..., None], -step, torch.zeros_like(step))  # (..., T-1, 2, 2)
    cumulative = log_keep.cumsum(-2)  # (..., T-1, 2): log(a_1...a_k)
    frames = step.shape[-3]
    lower_triangle = torch.ones(frames, frames, dtype=torch.bool, device=feet.device).tril()
    decay = cumulative[..., :, None, :] - cumulative[..., None, :, :]  # [k, j] = log(a_{j+1}...a_k)
    weights = torch.where(lower_triangle[:, :, None], decay.clamp_max(0.0).exp(), torch.zeros_like(decay))
    first_lower = lower[..., 0, :, :]  # (..., 2, 1)
    body_point = body_first[..., list(contact_points), :].gather(-2, first_lower[..., None].expand(*first_lower.shape, 3))
    start = (body_point.squeeze(-2) - point[..., 0, :, :])[..., :2]  # (..., 2, 2) o_0
    offsets = (weights[..., None] * pushes[..., None, :, :, :]).sum(-3) + cumulative.exp()[..., None] * start[..., None, :, :]
    offsets = offsets * (max_offset / offsets.norm(dim=-1, keepdim=True).clamp_min(1e-9)).clamp_max(1.0)
    shifted = feet[..., 1:, :, :, :].clone()
    shifted[..., :2] += offsets[..., None, :]
    return shifted
