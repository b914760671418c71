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

The geometry works in a planes layout: components first, vectors (3, ...) and matrices (3, 3, ...), every 3 x 3
product written out over the batch (`rotations.planes_matmul`). A (..., 3, 3) batch of 3 x 3 matmuls spends its time
in per-matrix kernels and layout copies; planes are long contiguous runs (at 1,024 bodies x 8 frames x 2 legs the
fit went from 43-48 to 27-30 ms on one AVX2 core, and the foot rule from 12% of a GAMMA step to 4%). The fitted
rotations go back into the body's rotation rows directly (`BodyModel.with_world_rotations`) and to SMPL-X axes from
the planes (`BodyModel.smplx_local`), with no (..., 3, 3) layout in between: on an AMX Xeon, the same 16,384 legs,
31.5 -> 23.7 ms on one core, 19.9 -> 15.3 ms on two.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from motion_envs.body.kinematics import BodyModel, BodyPose
from motion_envs.body.markers import MARKER_NAMES, marker_ids
from motion_envs.body.rotations import planes_matmul
from motion_envs.body.skeleton import joint_index

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
LEG_BLOCK = slice(LEG_JOINTS[0], LEG_JOINTS[0] + 12)
"""Joints 1-12 in SMPL-X's order, 3 per part (hips, knees, ankles, toes): left and right leg first, then a spine
joint; `leg_joints` views them."""
assert all(LEG_JOINTS[4 * side + part] == LEG_BLOCK.start + 3 * part + side for side in range(2) for part in range(4))
LEG_JOINTS_TENSOR = torch.tensor(LEG_JOINTS)
LEG_POSE_ROWS = LEG_JOINTS_TENSOR - 1
"""`LEG_JOINTS` as rows of a (..., 21, ...) SMPL-X body pose (which has no pelvis)."""


def leg_fit_marker_ids() -> torch.Tensor:
    """(2, 5) vertex ids of `FOOT_FIT_MARKERS`, left then right."""
    return torch.stack([marker_ids(FOOT_FIT_MARKERS[side]) for side in ("left", "right")])


def leg_fit_marker_slots() -> torch.Tensor:
    """(2, 5) positions of `FOOT_FIT_MARKERS` in `MARKER_NAMES` (a 67-marker array's rows), left then right."""
    return torch.tensor([[MARKER_NAMES.index(name) for name in FOOT_FIT_MARKERS[side]] for side in ("left", "right")])


def leg_joints(values: torch.Tensor, trailing: int) -> torch.Tensor:
    """(..., 22, *rest) per-joint values with `trailing` = len(rest) -> (..., 4, 2, *rest) the legs' (hips, knees,
    ankles, toes; left, right): a view, so writing to it writes `values`."""
    axis = values.dim() - 1 - trailing
    block = values.narrow(axis, LEG_BLOCK.start, LEG_BLOCK.stop - LEG_BLOCK.start)
    return block.unflatten(axis, (4, 3)).narrow(axis + 1, 0, 2)


def _matvec(a: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """(3, 3, ...) @ (3, ...) in the planes layout, accumulated as `planes_matmul`'s."""
    product = a[:, 0] * v[:1]
    product.addcmul_(a[:, 1], v[1:2])
    return product.addcmul_(a[:, 2], v[2:])


def _transpose(a: torch.Tensor) -> torch.Tensor:
    """(3, 3, ...) -> its transpose (a view)."""
    return a.transpose(0, 1)


def _dot(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """(3, ...) . (3, ...) -> (1, ...)."""
    return (u * v).sum(0, keepdim=True)


def _norm(v: torch.Tensor) -> torch.Tensor:
    """(C, ...) -> (1, ...) lengths, at least 1e-12 (as `normalize`'s), with a finite gradient at 0 (a sum of
    planes: linalg's norm over a leading axis of 3 costs as much as the rest of the fit)."""
    return v.square().sum(0, keepdim=True).clamp_min(1e-24).sqrt()


def _normalize(v: torch.Tensor) -> torch.Tensor:
    """(3, ...) -> unit vectors."""
    return v / _norm(v)


def smallest_rotation(source: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(3, ...) directions -> (3, 3, ...) the smallest rotation turning `source`'s direction onto `target`'s.
    R = I + [w]x + [w]x² / (1 + c) with w = u x v, c = u . v of the unit vectors; exact for any pair that is not
    opposite (the legs' corrections are a few degrees). [w]x² = w wᵀ - |w|² I, an outer product, not a matmul."""
    u, v = _normalize(source), _normalize(target)
    w = torch.linalg.cross(u, v, dim=0)
    scale = 1.0 / (1.0 + _dot(u, v)).clamp_min(1e-6)  # (1, ...)
    zero = torch.zeros_like(w[0])
    skew = torch.stack([zero, -w[2], w[1], w[2], zero, -w[0], -w[1], w[0], zero]).unflatten(0, (3, 3))
    eye = torch.eye(3, dtype=source.dtype, device=source.device).view(3, 3, *[1] * (w.dim() - 1))
    return w[:, None] * (w * scale)[None] + skew + eye * (1.0 - _dot(w, w) * scale)


def foot_frame(points: torch.Tensor) -> torch.Tensor:
    """(3, ..., 5) `FOOT_FIT_MARKERS` -> (3, 3, ...) an orthonormal frame of the rigid foot (columns): heel to
    first metatarsal, then heel to ankle made orthogonal to it, then their cross product."""
    along = _normalize(points[..., METATARSAL] - points[..., HEEL])
    up = points[..., ANKLE] - points[..., HEEL]
    up = _normalize(up - _dot(up, along) * along)
    return torch.stack([along, up, torch.linalg.cross(along, up, dim=0)], dim=1)


def rigid_foot_motion(current: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The rotation (3, 3, ...) and translation (3, ...) carrying the rigid foot of `current` (3, ..., 5) onto
    `target`'s: the frames of three markers matched, the four rigid markers' centroids. Exact for a rigid
    target; for predicted markers (a few mm from rigid) close to a least-squares fit at a tenth of its cost
    (Kabsch on 16,384 feet: 38 ms on one core)."""
    turn = planes_matmul(foot_frame(target), _transpose(foot_frame(current)))
    centre = current[..., :TOE_TIP].mean(-1)
    return turn, target[..., :TOE_TIP].mean(-1) - _matvec(turn, centre)


def within_reach(hip: torch.Tensor, target: torch.Tensor, length: torch.Tensor) -> torch.Tensor:
    """(3, ...) `target` pulled horizontally towards `hip` until it is within `length` (1, ...) of it, its height
    kept (a target higher or lower than `length` goes straight above or below the hip): a leg that cannot reach
    its foot's target leaves the foot short on the floor, not in the air, so the floor rule does not sink the
    body to put it down."""
    offset = target - hip
    vertical = torch.maximum(torch.minimum(offset[2:], length), -length)
    room = (length**2 - vertical**2).clamp_min(1e-12).sqrt()  # not 0: a finite gradient for latent optimisation
    horizontal = offset[:2]
    scale = (room / _norm(horizontal).clamp_min(1e-9)).clamp_max(1.0)
    return hip + torch.cat([horizontal * scale, vertical])


def two_bone(hip: torch.Tensor, knee: torch.Tensor, ankle: torch.Tensor, target: torch.Tensor,
             forward: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """World rotations that put the ankle on `target` (`within_reach` of the straight leg), keeping both bone
    lengths and the knee's plane. Planes layout: components first.

    Args:
        hip, knee, ankle, target: (3, ...) joint positions and the ankle's target.
        forward: (3, ...) the way the knee bends when the leg is straight (the plane is then undefined).

    Returns:
        thigh (3, 3, ...): the hip's new world rotation is thigh @ old; shin (3, 3, ...): the knee's is
        shin @ thigh @ old.
    """
    thigh_length = _norm(knee - hip)
    shin_length = _norm(ankle - knee)
    reach = within_reach(hip, target, thigh_length + shin_length) - hip
    distance = _norm(reach)
    distance_clamped = distance.clamp((thigh_length - shin_length).abs() + 1e-3, thigh_length + shin_length)
    along = reach / distance.clamp_min(1e-9)
    bend = knee - hip + 1e-6 * forward  # the current knee's side of the hip-target line
    bend = _normalize(bend - _dot(bend, along) * along)
    cosine = (thigh_length**2 + distance_clamped**2 - shin_length**2) / (2.0 * thigh_length * distance_clamped)
    sine = (1.0 - cosine.clamp(-1.0, 1.0) ** 2).clamp_min(1e-12).sqrt()  # not 0: a finite gradient
    new_knee = hip + thigh_length * (cosine * along + sine * bend)
    thigh = smallest_rotation(knee - hip, new_knee - hip)
    shin = smallest_rotation(_matvec(thigh, ankle - knee), hip + distance_clamped * along - new_knee)
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
    joints = leg_joints(posed.joints, 1).movedim(-1, 0).contiguous()  # (3, ..., 4, 2)
    world = leg_joints(posed.rotations, 2).movedim((-2, -1), (0, 1)).contiguous()  # (3, 3, ..., 4, 2)
    hip, knee, ankle, toes = joints.unbind(-2)  # (3, ..., 2) each
    hip_old, knee_old, ankle_old, toe_old = world.unbind(-2)  # (3, 3, ..., 2) each
    current, target_markers = (m.movedim(-1, 0).contiguous() for m in (current, target_markers))  # (3, ..., 2, 5)
    turn, shift = rigid_foot_motion(current, target_markers)  # (3, 3, ..., 2), (3, ..., 2)
    target = _matvec(turn, ankle) + shift
    thigh, shin = two_bone(hip, knee, ankle, target, hip_old[:, 1])  # the rest body faces +y; knees bend forwards
    hip_world = planes_matmul(thigh, hip_old)
    knee_world = planes_matmul(planes_matmul(shin, thigh), knee_old)
    ankle_world = planes_matmul(turn, ankle_old)
    toe_joint = _matvec(turn, toes) + shift
    toe_tip = _matvec(turn, current[..., TOE_TIP]) + shift
    toe_turn = smallest_rotation(toe_tip - toe_joint, target_markers[..., TOE_TIP] - toe_joint)
    toe_world = planes_matmul(planes_matmul(toe_turn, turn), toe_old)
    pelvis = posed.rotations[..., :1, :, :].movedim((-2, -1), (0, 1))  # (3, 3, ..., 1): both hips' parent
    fitted = (hip_world, knee_world, ankle_world, toe_world)  # (3, 3, ..., 2) each
    parents = (pelvis, *fitted[:-1])
    local_world = [planes_matmul(_transpose(parent), child) for parent, child in zip(parents, fitted)]
    leg_pose = body.smplx_local(torch.stack(local_world, dim=-1).flatten(-2))  # (..., 8, 3, 3), `LEG_JOINTS` order
    legs = torch.stack(fitted, dim=-1).flatten(-2)  # (3, 3, ..., 8): the left leg's four, then the right's
    return FittedLegs(leg_pose, body.with_world_rotations(posed, transl, LEG_JOINTS_TENSOR.to(transl.device), legs))
