"""Fit a posed body's legs to target foot markers: analytic two-bone IK, batched, no iterations.

GAMMA's body regressor recovers each frame's body from its markers independently, and its error (about 2 cm
per marker) differs from frame to frame. At 40 fps a 1 cm error that changes between frames is 0.4 m/s of
apparent foot motion, so a foot the predictor holds still slides on the regressed body: under the shipped
GammaReach policy the loaded sole marker moves faster than 0.2 m/s in 30% of walking transitions of the
predicted markers and in 80% of the regressed body's (runs of 128 bodies x 40 primitives). GAMMA's authors name
this gap (appendix B.1: the regressor "cannot guarantee" a valid body; MOJO's optimisation-based fitting is
better but 2 s per frame) and leave a real-time body optimiser to future work. `fit_legs` is ours: it keeps the
regressed pelvis, spine and arms and moves only the hips, knees and ankles so that each foot lands where the
predicted markers put it:

1. the foot's rigid pose: the rotation and translation that carry the body's ankle-borne foot markers
   (`FOOT_FIT_MARKERS`: ankle, heel, first metatarsal, ball of the foot) onto the targets
   (`rigid_foot_motion`); its translation moves the ankle joint, and the toes turn (smallest
   rotation about their joint) so that the toe-tip marker points at its target;
2. hip and knee: the knee stays in the plane of hip, ankle target and the current knee (so the leg does not
   twist), the thigh and shin keep their lengths, and each bone turns by the smallest rotation onto its new
   direction (a target out of reach is pulled horizontally towards the hip, keeping its height);
3. the ankle's world rotation is the Kabsch rotation times the regressed one.

All in world axes on `BodyPose.rotations`; the result is SMPL-X local rotations as matrices (`body_pose`
convention, `motion_envs.body.kinematics`; `BodyModel.from_matrices` poses them).
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from motion_envs.body.kinematics import BodyModel, BodyPose
from motion_envs.body.markers import MARKER_NAMES, marker_ids
from motion_envs.body.skeleton import PARENTS, joint_index

FOOT_FIT_MARKERS: dict[str, tuple[str, ...]] = {
    "left": ("LANK", "LHEE", "LMT1", "LRSTBEEF", "LTOE"),
    "right": ("RANK", "RHEE", "RMT1", "RRSTBEEF", "RTOE"),
}
"""Each foot's fitted markers: four skinned (almost) only to the ankle joint, the rigid foot, then the toe tip."""
ANKLE, HEEL, METATARSAL, BALL, TOE_TIP = range(5)
CONTACT_POINTS = (HEEL, TOE_TIP)
"""The heel and the toe tip in `FOOT_FIT_MARKERS`: the points a foot stands on (`foot_lock.locked_feet`)."""

LEG_JOINTS = tuple(joint_index(f"{side}_{part}") for side in ("left", "right") for part in ("hip", "knee", "ankle", "foot"))
"""The joints whose rotations the fit sets, left leg then right."""
LEG_PARTS = tuple(slice(LEG_JOINTS[part], LEG_JOINTS[part + 4] + 1) for part in range(4))
"""Hips, knees, ankles and toes: left and right are neighbours in SMPL-X's joint order (a slice each, a view)."""
assert all(part.stop - part.start == 2 for part in LEG_PARTS)
LEG_POSE_ROWS = torch.tensor(LEG_JOINTS) - 1
"""`LEG_JOINTS` as rows of a (..., 21, ...) SMPL-X body pose (which has no pelvis)."""


def leg_fit_marker_ids() -> torch.Tensor:
    """(2, 5) vertex ids of `FOOT_FIT_MARKERS`, left then right."""
    return torch.stack([marker_ids(FOOT_FIT_MARKERS[side]) for side in ("left", "right")])


def leg_fit_marker_slots() -> torch.Tensor:
    """(2, 5) positions of `FOOT_FIT_MARKERS` in `MARKER_NAMES` (a 67-marker array's rows), left then right."""
    return torch.tensor([[MARKER_NAMES.index(name) for name in FOOT_FIT_MARKERS[side]] for side in ("left", "right")])


def smallest_rotation(source: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(..., 3) directions -> (..., 3, 3) the smallest rotation turning `source`'s direction onto `target`'s.
    R = I + [w]x + [w]x² / (1 + c) with w = u x v, c = u . v of the unit vectors; exact for any pair that is not
    opposite (the legs' corrections are a few degrees). [w]x² = w wᵀ - |w|² I, an outer product, not a matmul."""
    u = torch.nn.functional.normalize(source, dim=-1)
    v = torch.nn.functional.normalize(target, dim=-1)
    w = torch.linalg.cross(u, v)
    c = (u * v).sum(-1)
    zero = torch.zeros_like(c)
    skew = torch.stack([zero, -w[..., 2], w[..., 1], w[..., 2], zero, -w[..., 0], -w[..., 1], w[..., 0], zero], -1)
    skew = skew.unflatten(-1, (3, 3))
    scale = 1.0 / (1.0 + c).clamp_min(1e-6)  # (...)
    eye = torch.eye(3, dtype=source.dtype, device=source.device)
    outer = w[..., :, None] * (w * scale[..., None])[..., None, :]
    return outer + skew + eye * (1.0 - (w * w).sum(-1) * scale)[..., None, None]


def foot_frame(points: torch.Tensor) -> torch.Tensor:
    """(..., 5, 3) `FOOT_FIT_MARKERS` -> (..., 3, 3) an orthonormal frame of the rigid foot (columns): heel to
    first metatarsal, then heel to ankle made orthogonal to it, then their cross product."""
    along = torch.nn.functional.normalize(points[..., METATARSAL, :] - points[..., HEEL, :], dim=-1)
    up = points[..., ANKLE, :] - points[..., HEEL, :]
    up = torch.nn.functional.normalize(up - (up * along).sum(-1, keepdim=True) * along, dim=-1)
    return torch.stack([along, up, torch.linalg.cross(along, up)], dim=-1)


def rigid_foot_motion(current: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The rotation (..., 3, 3) and translation (..., 3) carrying the rigid foot of `current` (..., 5, 3) onto
    `target`'s: the frames of three markers matched, the four rigid markers' centroids. Exact for a rigid
    target; for predicted markers (a few mm from rigid) close to a least-squares fit at a tenth of its cost
    (Kabsch on 16,384 feet: 38 ms on one core)."""
    turn = foot_frame(target) @ foot_frame(current).transpose(-1, -2)
    centre = current[..., :TOE_TIP, :].mean(-2)
    return turn, target[..., :TOE_TIP, :].mean(-2) - (turn @ centre[..., None])[..., 0]


def within_reach(hip: torch.Tensor, target: torch.Tensor, length: torch.Tensor) -> torch.Tensor:
    """(..., 3) `target` pulled horizontally towards `hip` until it is within `length` (..., 1) of it, its height
    kept (a target higher or lower than `length` goes straight above or below the hip): a leg that cannot reach
    its foot's target leaves the foot short on the floor, not in the air, so the floor rule does not sink the
    body to put it down."""
    offset = target - hip
    vertical = torch.maximum(torch.minimum(offset[..., 2:], length), -length)
    room = (length**2 - vertical**2).clamp_min(1e-12).sqrt()  # not 0: a finite gradient for latent optimisation
    horizontal = offset[..., :2]
    scale = (room / horizontal.norm(dim=-1, keepdim=True).clamp_min(1e-9)).clamp_max(1.0)
    return hip + torch.cat([horizontal * scale, vertical], dim=-1)


def two_bone(hip: torch.Tensor, knee: torch.Tensor, ankle: torch.Tensor, target: torch.Tensor,
             forward: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """World rotations that put the ankle on `target` (`within_reach` of the straight leg), keeping both bone
    lengths and the knee's plane.

    Args:
        hip, knee, ankle, target: (..., 3) joint positions and the ankle's target.
        forward: (..., 3) the way the knee bends when the leg is straight (the plane is then undefined).

    Returns:
        thigh (..., 3, 3): the hip's new world rotation is thigh @ old; shin (..., 3, 3): the knee's is
        shin @ thigh @ old.
    """
    thigh_length = (knee - hip).norm(dim=-1, keepdim=True)
    shin_length = (ankle - knee).norm(dim=-1, keepdim=True)
    reach = within_reach(hip, target, thigh_length + shin_length) - hip
    distance = reach.norm(dim=-1, keepdim=True)
    distance_clamped = distance.clamp((thigh_length - shin_length).abs() + 1e-3, thigh_length + shin_length)
    along = reach / distance.clamp_min(1e-9)
    bend = knee - hip + 1e-6 * forward  # the current knee's side of the hip-target line
    bend = torch.nn.functional.normalize(bend - (bend * along).sum(-1, keepdim=True) * along, dim=-1)
    cosine = (thigh_length**2 + distance_clamped**2 - shin_length**2) / (2.0 * thigh_length * distance_clamped)
    sine = (1.0 - cosine.clamp(-1.0, 1.0) ** 2).clamp_min(1e-12).sqrt()  # not 0: a finite gradient
    new_knee = hip + thigh_length * (cosine * along + sine * bend)
    thigh = smallest_rotation(knee - hip, new_knee - hip)
    turned_shin = (thigh @ (ankle - knee)[..., None])[..., 0]
    shin = smallest_rotation(turned_shin, hip + distance_clamped * along - new_knee)
    return thigh, shin


class FittedLegs(NamedTuple):
    """Legs fitted by `fit_legs`.

    leg_pose: (..., 8, 3, 3) the `LEG_JOINTS`' SMPL-X local rotations (rows `LEG_POSE_ROWS` of a body pose).
    posed: the fitted body (joints (..., 22, 3), rotations (..., 22, 3, 3)).
    """

    leg_pose: torch.Tensor
    posed: BodyPose


def fit_legs(body: BodyModel, posed: BodyPose, transl: torch.Tensor, current: torch.Tensor,
             target_markers: torch.Tensor) -> FittedLegs:  # fmt: skip
    """Both legs of a posed body fitted to the targets of their feet (module doc).

    Args:
        body: the body model that posed `posed`.
        posed: BodyPose with joints (..., 22, 3) and rotations (..., 22, 3, 3).
        transl: (..., 3) where the fitted body's pelvis goes (`posed`'s own, or it moved as a whole).
        current: (..., 2, 5, 3) `leg_fit_marker_ids` (left, right) on `posed` (the callers have skinned them).
        target_markers: (..., 2, 5, 3) where `leg_fit_marker_ids` (left, right) should be.

    Returns:
        The legs' local rotations and the fitted body, posed without forward kinematics: the legs' world
        rotations are the fit's and the rest are `posed`'s (the legs have no other children). Products of
        rotations, orthonormal to rounding, and nothing feeds them back to a prior (WANDR shows its fitted legs and
        goes on from its own; GAMMA's next primitive regresses its bodies afresh), so rounding does not build up
        (it did when WANDR fed fitted legs back: wrists 10^9 long within 200 frames).
    """
    joints, world = posed.joints, posed.rotations
    turn, shift = rigid_foot_motion(current, target_markers)  # (..., 2, 3, 3), (..., 2, 3)
    hip, knee, ankle, toes = (joints[..., part, :] for part in LEG_PARTS)  # (..., 2, 3) each
    target = (turn @ ankle[..., None])[..., 0] + shift
    forward = world[..., LEG_PARTS[0], :, 1]  # the rest body faces +y, and knees bend forwards
    thigh, shin = two_bone(hip, knee, ankle, target, forward)
    hip_world = thigh @ world[..., LEG_PARTS[0], :, :]
    knee_world = shin @ thigh @ world[..., LEG_PARTS[1], :, :]
    ankle_world = turn @ world[..., LEG_PARTS[2], :, :]
    toe_joint = (turn @ toes[..., None])[..., 0] + shift
    toe_tip = (turn @ current[..., TOE_TIP, :, None])[..., 0] + shift
    toe_turn = smallest_rotation(toe_tip - toe_joint, target_markers[..., TOE_TIP, :] - toe_joint)
    toe_world = toe_turn @ turn @ world[..., LEG_PARTS[3], :, :]
    legs = (hip_world, knee_world, ankle_world, toe_world)  # (..., 2, 3, 3) each
    rotations = world.clone()
    for part, leg_world in zip(LEG_PARTS, legs):
        rotations[..., part, :, :] = leg_world
    stacked = torch.stack(legs, dim=-3)  # (..., 2, 4, 3, 3)
    pelvis = world[..., :1, None, :, :].expand_as(stacked[..., :1, :, :])  # both hips' parent
    parents = torch.cat([pelvis, stacked[..., :-1, :, :]], dim=-3)
    local_world = (parents.transpose(-1, -2) @ stacked).flatten(-4, -3)  # (..., 8, 3, 3) in `LEG_JOINTS` order
    return FittedLegs(body.smplx_local(local_world), body.from_world_rotations(transl, rotations))
