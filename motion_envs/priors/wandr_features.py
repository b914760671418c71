"""WANDR's motion representation and intention features (batched torch, differentiable).

A body's state at frame i is its pose p_i (pelvis position `transl`, pelvis
rotation `orient`, 21 local joint rotations `pose`) plus the delta d_{i-1}
that led to it. The prior autoencodes the delta to the next frame, 135
numbers with the heading removed (Sec. 3.3):

* translation (3): R_z(i-1)ᵀ (t_i − t_{i-1}), the pelvis step in the heading frame of frame i−1;
* orientation (6): 6-D of R_{i-1}ᵀ R_i, the pelvis rotation step in the pelvis frame;
* pose (126): 6-D of L_{i-1}ᵀ L_i per joint.

Trained on 17 minutes of CMU mocap for 40 epochs (the paper: AMASS + CIRCLE,
900 epochs), integrated deltas drift in height (the sampler's pelvis height
after 8 s spread from −1.8 m to 1.3 m, 5-95%, half-way through training).
The environments therefore keep the feet on the floor (`ground_feet`).
Predicting the pelvis height absolutely instead was tried and dropped: at
the same point of training its one-frame joint error was several times
higher (the MLP has to copy the height through to a precision the tiny
per-frame steps never ask for).

R_z is the heading: the rotation about +z that turns +y (the rest body's
forward) onto the pelvis's forward projected on the ground. The rotation
deltas carry no heading (the paper subtracts the z Euler angle; the release
composes relative rotations; this is the same invariance without Euler angles).

The condition (Sec. 3.3 and the release, REFERENCE_NOTES §2.1) is
[pelvis height (1), R_zᵀ R as 6-D (6), pose 6-D (126), d_{i-1} (135), intention (9)] = 277.

Intention (Sec. 3.2; all in the heading frame, so it turns with the body):

* wrist I^w = R_zᵀ (G − W_i) / (η/30 + 1e-5): the right wrist's needed mean velocity (m/s), η = frames left;
* pelvis I^p = 2 (1 − e^{−|v|}) v/|v| with v = R_zᵀ (G − P_i) on xy (z = 0): saturates at 2 m;
* orientation I^r = R_zᵀ ĥ_goal − (0, 1, 0) on xy: the goal heading minus the current one
  (training: the body's heading at t_G; inference: the pelvis-to-goal direction).

Where η = 0 (the goal frame itself) the intention is zero, as in the release.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from motion_envs.body import BodyModel, BodyPose, joint_index
from motion_envs.body.rotations import matrix_to_sixd, sixd_to_matrix
from motion_envs.body.skeleton import NUM_BODY_POSE_JOINTS

FPS = 30
DELTA_DIM = 3 + 6 + NUM_BODY_POSE_JOINTS * 6
"""135: translation, orientation and pose steps."""
POSE_DIM = 1 + 6 + NUM_BODY_POSE_JOINTS * 6
"""133: pelvis height, heading-free orientation, pose."""
INTENTION_DIM = 9
CONDITION_DIM = POSE_DIM + DELTA_DIM + INTENTION_DIM
INTENTIONS = ("wrist", "pelvis", "orientation")
"""The intention components in the order they sit in the 9 features (3 each)."""
PELVIS, RIGHT_WRIST = joint_index("pelvis"), joint_index("right_wrist")
PELVIS_INTENTION_MAX = 2.0
WRIST_TIME_EPSILON = 1e-5


class WandrState(NamedTuple):
    """Bodies at one frame.

    transl: (B, 3) pelvis position. orient: (B, 3, 3) pelvis rotation.
    pose: (B, 21, 3, 3) local joint rotations. previous_delta: (B, 135) the delta into this frame.
    joints: (B, 22, 3) world joint positions of this pose.
    shown_pose: (B, 21, 3, 3) the local rotations as shown: `pose` with the legs refitted by the foot rule
    (`WandrStepper`'s `lock_feet`), `pose` itself without it. The prior sees `pose`, renders and foot metrics
    `shown_pose`; the two differ only at the hips, knees, ankles and toes.
    """

    transl: torch.Tensor
    orient: torch.Tensor
    pose: torch.Tensor
    previous_delta: torch.Tensor
    joints: torch.Tensor
    shown_pose: torch.Tensor


def heading(orient: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) pelvis rotations -> (..., 3, 3) rotations about +z taking +y to the ground forward."""
    forward = orient[..., :2, 1]
    norm = forward.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    sine, cosine = (-forward[..., 0:1] / norm), (forward[..., 1:2] / norm)
    zero, one = torch.zeros_like(sine), torch.ones_like(sine)
    rows = [torch.cat([cosine, -sine, zero], -1), torch.cat([sine, cosine, zero], -1), torch.cat([zero, zero, one], -1)]
    return torch.stack(rows, dim=-2)


def pose_delta(transl: torch.Tensor, orient: torch.Tensor, pose: torch.Tensor,
               next_transl: torch.Tensor, next_orient: torch.Tensor, next_pose: torch.Tensor) -> torch.Tensor:  # fmt: skip
    """The delta (..., 135) from a pose to the next: (..., 3), (..., 3, 3), (..., 21, 3, 3) each."""
    step = ((next_transl - transl)[..., None, :] @ heading(orient)).squeeze(-2)  # R_zᵀ (t' − t)
    turn = matrix_to_sixd(orient.transpose(-1, -2) @ next_orient)
    bend = matrix_to_sixd(pose.transpose(-1, -2) @ next_pose).flatten(-2)
    return torch.cat([step, turn, bend], dim=-1)


def integrate(transl: torch.Tensor, orient: torch.Tensor, pose: torch.Tensor,
              delta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:  # fmt: skip
    """Apply a delta (B, 135) to poses (B, 3), (B, 3, 3), (B, 21, 3, 3) -> the next pose (same shapes)."""
    step = (heading(orient) @ delta[:, :3, None]).squeeze(-1)
    next_orient = orient @ sixd_to_matrix(delta[:, 3:9])
    next_pose = pose @ sixd_to_matrix(delta[:, 9:].reshape(-1, NUM_BODY_POSE_JOINTS, 6))
    return transl + step, next_orient, next_pose


def pose_features(state: WandrState) -> torch.Tensor:
    """(B, 133): pelvis height, heading-free orientation 6-D, local pose 6-D."""
    level = heading(state.orient).transpose(-1, -2) @ state.orient
    return torch.cat([state.transl[:, 2:], matrix_to_sixd(level), matrix_to_sixd(state.pose).flatten(1)], dim=1)


def intention(joints: torch.Tensor, orient: torch.Tensor, goal: torch.Tensor, frames_left: torch.Tensor,
              goal_heading: torch.Tensor | None = None, components: tuple[str, ...] = INTENTIONS) -> torch.Tensor:  # fmt: skip
    """The 9 intention features (B, 9) of bodies with joints (B, 22, 3) and pelvis rotations (B, 3, 3)
    towards goals (B, 3) due in `frames_left` (B,) frames.

    goal_heading: (B, 2) the heading to arrive with (training); None: face the goal (inference).
    components: the intention parts kept (the ablations zero the others).
    """
    unknown = set(components) - set(INTENTIONS)
    if unknown:
        raise ValueError(f"unknown intention components {sorted(unknown)}; choose from {INTENTIONS}")
    turn_back = heading(orient)  # R_z; row vectors @ R_z = R_zᵀ v
    frames_left = frames_left.to(goal.dtype)
    to_goal_wrist = ((goal - joints[:, RIGHT_WRIST])[:, None] @ turn_back).squeeze(1)
    wrist = to_goal_wrist / (frames_left[:, None] / FPS + WRIST_TIME_EPSILON)
    to_goal = goal - joints[:, PELVIS]
    to_goal_local = (to_goal[:, None] @ turn_back).squeeze(1) * goal.new_tensor([1.0, 1.0, 0.0])
    distance = to_goal_local.norm(dim=-1, keepdim=True)
    pelvis = PELVIS_INTENTION_MAX * (1 - torch.exp(-distance)) * to_goal_local / distance.clamp_min(1e-6)
    target = to_goal[:, :2] if goal_heading is None else goal_heading
    target = torch.cat([target, torch.zeros_like(target[:, :1])], dim=1)
    target = target / target.norm(dim=-1, keepdim=True).clamp_min(1e-6)
    facing = (target[:, None] @ turn_back).squeeze(1) - goal.new_tensor([0.0, 1.0, 0.0])
    parts = {"wrist": wrist, "pelvis": pelvis, "orientation": facing}
    features = torch.cat([parts[name] if name in components else torch.zeros_like(parts[name]) for name in INTENTIONS], 1)
    return features * (frames_left > 0)[:, None].to(features.dtype)


def condition(state: WandrState, intention_features: torch.Tensor) -> torch.Tensor:
    """(B, 277) the c-VAE's condition: pose features, previous delta, intention."""
    return torch.cat([pose_features(state), state.previous_delta, intention_features], dim=1)


def make_state(body: BodyModel, transl: torch.Tensor, orient: torch.Tensor, pose: torch.Tensor,
               previous_delta: torch.Tensor) -> tuple[WandrState, BodyPose]:  # fmt: skip
    """A `WandrState` shown as it is, with its joints from forward kinematics (rotations as matrices), and the
    posed body."""
    posed = body.from_matrices(transl, orient, pose)
    return WandrState(transl, orient, pose, previous_delta, posed.joints, pose), posed
