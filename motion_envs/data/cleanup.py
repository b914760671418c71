"""Foot contacts, the floor and foot locking for retargeted body motion.

The sources slide their feet (CMU's Daz-friendly converter puts every subject
on one skeleton and keeps the captured root path) and retargeting adds more;
their floors drift (a tilted capture floor: 07_01's lowest foot rises 16 cm
over 2.6 s). `clean` runs after retargeting, on the body itself:

1. **Contacts**, per sole point (`motion_envs.body.markers.SOLE_POINTS`:
   heel and toe of each foot). A point is in contact when it is near the
   local floor (the lowest sole point within +-0.5 s, so steps and stools
   count as floor) and slow, with hysteresis (it enters below
   `contact_height`/`contact_speed` and leaves above `release_height`/
   `release_speed`); gaps and contacts shorter than `min_contact_seconds`
   are closed and dropped, and a contact whose point has slid more than
   `max_contact_travel`, or whose foot has turned more than `max_contact_turn`,
   since it began ends there (a foot shuffling or pivoting on the spot makes
   several contacts). The speed gate is loose
   (0.8 m/s to enter) on purpose: a sliding stance foot of the Daz files
   moves at 0.4-0.5 m/s, a swinging foot at 2-4 m/s.
2. **Floor**: a plane z = a + b x + c y fitted to the contact points with
   outlier trimming. Where its slope is at most `max_floor_slope` the motion is
   rotated so the plane is level and shifted so it is z = 0 (a real floor is
   level; a tilt is the capture's calibration). Contacts more than
   `floor_tolerance` above the plane (steps, stools, ladders) keep their
   height.
3. **Pelvis tilt**, only for clips whose skeleton is not their subject's
   own (`SkeletonMap.subject_skeleton`; CMU's Daz-friendly files, every
   subject on one figure, whose converter also replaced the hip rotations
   with the pre-retargeting ones): retargeted, their pelvis is pitched
   forward 41° (the hips' midpoint -> spine1 from vertical, median over
   frames with both legs straight; 36-54° for 80% of the clips) where the
   subjects' own skeletons give 14° (`35_01`) and 10-12° (`131_0x`), 1° at
   rest, which drops the body ~4 cm and tips the pelvis block visibly. The
   pelvis turns back about its left-right axis by the clip's excess over
   `pelvis_tilt_degrees` (at most `max_tilt_fix_degrees`; none without
   `min_upright_seconds` of straight-legged frames to measure it on); the
   hips and spine1 keep their world rotations and the hips' midpoint stays
   where it was, so the legs keep their poses and move by millimetres (each
   hip turns about the midpoint: 4 mm for 40°), and the upper body rides up
   and back.
4. **Foot locking**: during a contact the point holds one position (the mean
   of its path over the contact; on the floor at z = 0). Adam on the legs'
   6-D rotations (hips, knees, ankles, toes) and the pelvis translation and
   orientation pulls the points there, with the lock's weight ramped in and
   out over `blend_seconds` so nothing pops, a penalty on any sole vertex
   below the floor, a pull towards the original rotations and a penalty on
   the corrections' second differences over time. The spine, arms and head
   keep their local rotations, so the upper body keeps its motion and rides
   on the pelvis.

Everything is batched over the clip's frames (one clip is one optimisation).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np
import roma
import torch
from scipy.ndimage import minimum_filter1d

from motion_envs.body import BodyModel, joint_index
from motion_envs.body.markers import foot_vertex_ids, sole_vertex_ids
from motion_envs.body.rotations import matrix_to_sixd, rotation_matrix
from motion_envs.data.motion import BodyMotion

LEG_JOINTS = ("left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle", "left_foot", "right_foot")
"""Body joints foot locking may rotate (with the pelvis); all others keep their local rotations."""


@dataclass(frozen=True)
class CleanupConfig:
    """Thresholds (m, m/s, s) of contact labelling, floor fitting and foot locking; see the module docstring.

    Pelvis tilt (degrees): the target `pelvis_tilt_degrees` (`35_01`'s, the subject's own skeleton); straight-legged
    frames: both legs' hip-to-ankle at least `upright_straightness` of the leg's length.

    The weights are in m^-2 against the contact residual (m^2, times `lock_weight`): `joint_weight` per m^2 of the joints'
    summed squared displacement (what keeps the upper body and the free frames where they were; not for the
    knee, ankle and toe of a foot being locked), `rotation_weight` per unit 6-D distance
    of a leg joint from its original rotation, `pelvis_weight` per m^2 of pelvis shift, `smooth_weight` per m^2
    (or 6-D unit^2) of a correction's second difference between frames, `floor_weight` per m^2 below z = 0.
    """

    contact_height: float = 0.03
    release_height: float = 0.06
    contact_speed: float = 0.8
    release_speed: float = 1.2
    min_contact_seconds: float = 0.1
    max_contact_travel: float = 0.3
    max_contact_turn: float = 0.35
    floor_window_seconds: float = 1.0
    floor_tolerance: float = 0.03
    max_floor_slope: float = 0.08
    floor_span: float = 0.3
    blend_seconds: float = 0.1
    iterations: int = 300
    learning_rate: float = 0.01
    rotation_weight: float = 1e-3
    pelvis_weight: float = 0.05
    smooth_weight: float = 1.0
    floor_weight: float = 10.0
    lock_weight: float = 30.0
    joint_weight: float = 0.1
    pelvis_tilt_degrees: float = 14.0
    max_tilt_fix_degrees: float = 40.0
    upright_straightness: float = 0.85
    min_upright_seconds: float = 0.5


@dataclass(frozen=True)
class Floor:
    """z = height + slope[0] x + slope[1] y; `level` is whether it was flattened (slope small enough)."""

    height: float
    slope: tuple[float, float]
    level: bool


def sole_points(motion: BodyMotion, body: BodyModel) -> np.ndarray:
    """(T, 4, 3) positions of the sole points (`SOLE_POINTS` order)."""
    with torch.no_grad():
        pose = body(*_tensors(motion, torch.float32))
        return body.skin(pose, sole_vertex_ids()).double().numpy()


def _tensors(motion: BodyMotion, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    return tuple(torch.as_tensor(np.asarray(a), dtype=dtype) for a in (motion.transl, motion.global_orient, motion.body_pose))


def horizontal_speed(points: np.ndarray, fps: float) -> np.ndarray:
    """(T, P) horizontal speed (m/s) of points (T, P, 3): central differences, one-sided at the ends."""
    if len(points) < 2:
        return np.zeros(points.shape[:2])
    return np.linalg.norm(np.gradient(points[..., :2], axis=0), axis=-1) * fps


def hysteresis(enter: np.ndarray, stay: np.ndarray) -> np.ndarray:
    """(T, P) bool: on from a frame where `enter` holds until the first frame where `stay` fails (vectorised)."""
    frames = np.arange(len(enter))[:, None]
    last_enter = np.maximum.accumulate(np.where(enter, frames, -1), axis=0)
    last_leave = np.maximum.accumulate(np.where(~stay & ~enter, frames, -1), axis=0)
    return last_enter > last_leave


def drop_short(labels: np.ndarray, min_frames: int) -> np.ndarray:
    """(T, P) bool with runs of True shorter than `min_frames` set False."""
    kept = labels.copy()
    for point in range(labels.shape[1]):
        for start, stop in runs(labels[:, point]):
            if stop - start < min_frames:
                kept[start:stop, point] = False
    return kept


def fill_gaps(labels: np.ndarray, max_frames: int) -> np.ndarray:
    """(T, P) bool with interior runs of False of at most `max_frames` set True (a stance is not broken by a
    frame or two above a threshold)."""
    filled = labels.copy()
    for point in range(labels.shape[1]):
        for start, stop in runs(~labels[:, point]):
            if start > 0 and stop < len(labels) and stop - start <= max_frames:
                filled[start:stop, point] = True
    return filled


def split_travelling(labels: np.ndarray, points: np.ndarray, max_travel: float, max_turn: float) -> np.ndarray:
    """(T, 4) bool with each run of True ended (one frame off) where its point has moved more than `max_travel`
    horizontally, or its foot (heel -> toe) has turned more than `max_turn` radians about the vertical, since
    the run began; the rest starts a new run: a foot shuffling or pivoting on the spot makes several contacts
    (one lock over a turn would twist the leg)."""
    split = labels.copy()
    heel_to_toe = points[:, [1, 1, 3, 3], :2] - points[:, [0, 0, 2, 2], :2]
    yaw = np.arctan2(heel_to_toe[..., 1], heel_to_toe[..., 0])  # (T, 4): each point's foot
    for point in range(labels.shape[1]):
        for start, stop in runs(labels[:, point]):
            anchor = start
            for frame in range(start + 1, stop):
                turn = abs(np.angle(np.exp(1j * (yaw[frame, point] - yaw[anchor, point]))))
                if np.linalg.norm(points[frame, point, :2] - points[anchor, point, :2]) > max_travel or turn > max_turn:
                    split[frame, point] = False
                    anchor = frame + 1
    return split


def runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each run of True in a (T,) bool array."""
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


def label_contacts(points: np.ndarray, fps: float, config: CleanupConfig = CleanupConfig()) -> np.ndarray:
    """(T, 4) bool contact labels of sole points (T, 4, 3) (see the module docstring)."""
    window = max(1, int(round(config.floor_window_seconds * fps)) | 1)
    local_floor = minimum_filter1d(points[..., 2].min(axis=1), size=window, mode="nearest")
    height = points[..., 2] - local_floor[:, None]
    speed = horizontal_speed(points, fps)
    enter = (height < config.contact_height) & (speed < config.contact_speed)
    stay = (height < config.release_height) & (speed < config.release_speed)
    shortest = max(1, int(round(config.min_contact_seconds * fps)))
    labels = split_travelling(fill_gaps(hysteresis(enter, stay), shortest), points, config.max_contact_travel,
                              config.max_contact_turn)
    return drop_short(labels, shortest)


def fit_floor(points: np.ndarray, contacts: np.ndarray, config: CleanupConfig = CleanupConfig()) -> Floor:
    """The floor plane under the contact points.

    Starting from the contacts within `floor_tolerance` of their 10th height percentile (the lowest level
    the feet stand on: a clip that climbs steps spends most contacts above its floor), ridge least squares on
    centred coordinates (a slope along a direction the contacts span less than `floor_span` is damped: a
    straight walk says nothing about the sideways tilt), trimmed of points more than `floor_tolerance` off
    the plane, three times. A constant height (of that lowest level) when the slope exceeds
    `max_floor_slope` (a ramp or stairs, not a tilted capture floor) or there are no contacts.
    """
    touching = points[contacts]
    if len(touching) == 0:
        return Floor(float(points[..., 2].min()), (0.0, 0.0), False)
    ground = np.percentile(touching[:, 2], 10)  # the lowest level the feet stand on, not the steps above it
    inliers = np.abs(touching[:, 2] - ground) <= config.floor_tolerance
    slope, height = np.zeros(2), float(np.median(touching[inliers, 2]))
    for _ in range(3):
        xy, z = touching[inliers, :2], touching[inliers, 2]
        centre = xy.mean(axis=0)
        offsets = xy - centre
        slope = np.linalg.solve(offsets.T @ offsets + len(xy) * config.floor_span**2 * np.eye(2), offsets.T @ (z - z.mean()))
        height = z.mean() - centre @ slope
        residual = touching[:, 2] - (height + touching[:, :2] @ slope)
        trimmed = np.abs(residual) <= config.floor_tolerance
        if trimmed.sum() < 3:
            break
        inliers = trimmed
    if np.hypot(*slope) > config.max_floor_slope:
        return Floor(float(np.median(touching[np.abs(touching[:, 2] - ground) <= config.floor_tolerance, 2])), (0.0, 0.0), False)
    return Floor(float(height), (float(slope[0]), float(slope[1])), True)


def level_floor(motion: BodyMotion, floor: Floor) -> BodyMotion:
    """The motion rotated about the world origin so the floor plane is level, and shifted so it is z = 0
    (`transl` is the pelvis position and `global_orient` turns about it, so both simply rotate)."""
    normal = np.array([-floor.slope[0], -floor.slope[1], 1.0])
    normal /= np.linalg.norm(normal)
    axis = np.cross(normal, [0.0, 0.0, 1.0])
    angle = np.arctan2(np.linalg.norm(axis), normal[2])
    rotvec = axis / np.linalg.norm(axis) * angle if np.linalg.norm(axis) > 1e-12 else np.zeros(3)
    turn = roma.rotvec_to_rotmat(torch.as_tensor(rotvec)).numpy()
    # the plane's point above the origin, rotated, gives the new floor height
    height = (turn @ np.array([0.0, 0.0, floor.height]))[2]
    orient = roma.rotmat_to_rotvec(
        torch.as_tensor(turn) @ roma.rotvec_to_rotmat(torch.as_tensor(np.asarray(motion.global_orient, np.float64)))
    ).numpy()
    return replace(motion, transl=motion.transl @ turn.T - np.array([0.0, 0.0, height]), global_orient=orient)


def pelvis_tilt(joints: np.ndarray) -> np.ndarray:
    """(T,) degrees: the angle from vertical of the hips' midpoint -> spine1 of body joints (T, 22, 3) (1° at rest)."""
    trunk_base = joints[:, joint_index("spine1")] - joints[:, [joint_index("left_hip"), joint_index("right_hip")]].mean(axis=1)
    return np.degrees(np.arccos(np.clip(trunk_base[:, 2] / np.linalg.norm(trunk_base, axis=-1), -1.0, 1.0)))


def straightness(joints: np.ndarray, side: str) -> np.ndarray:
    """(T,) hip-to-ankle distance over the leg's length (thigh + shank) of one leg of body joints (T, 22, 3)."""
    hip, knee, ankle = (joints[:, joint_index(f"{side}_{part}")] for part in ("hip", "knee", "ankle"))
    return np.linalg.norm(hip - ankle, axis=-1) / (np.linalg.norm(hip - knee, axis=-1) + np.linalg.norm(knee - ankle, axis=-1))


def tilt_excess(joints: np.ndarray, fps: float, config: CleanupConfig = CleanupConfig()) -> float:
    """Degrees by which the pelvis of body joints (T, 22, 3) is pitched beyond `pelvis_tilt_degrees` (median over
    straight-legged frames, at most `max_tilt_fix_degrees`; 0 with fewer than `min_upright_seconds` of them)."""
    upright = np.minimum(straightness(joints, "left"), straightness(joints, "right")) >= config.upright_straightness
    if upright.sum() < config.min_upright_seconds * fps:
        return 0.0
    return float(np.clip(np.median(pelvis_tilt(joints)[upright]) - config.pelvis_tilt_degrees, 0.0, config.max_tilt_fix_degrees))


def untilt_pelvis(motion: BodyMotion, body: BodyModel, degrees: float) -> BodyMotion:
    """The pelvis turned top-backwards by `degrees` about its rest left-right axis (world x at rest), its children
    (the hips and spine1) keeping their world rotations, and the pelvis moved so the hips' midpoint stays where it
    was: the legs keep their world poses (each hip moves a few mm about the midpoint), the upper body rides on
    the turned pelvis (module docstring, step 3)."""
    if degrees == 0.0:
        return motion
    transl, orient, pose = _tensors(motion, torch.float64)
    turn = roma.rotvec_to_rotmat(torch.tensor([np.radians(degrees), 0.0, 0.0], dtype=torch.float64))
    axes = body.axes_to_world.double()
    children = [joint_index(name) - 1 for name in ("left_hip", "right_hip", "spine1")]
    local = roma.rotvec_to_rotmat(pose)
    local[:, children] = (axes.T @ turn.T @ axes) @ local[:, children]  # world rotation G·A·L·Aᵀ unchanged
    orient_turned = roma.rotvec_to_rotmat(orient) @ turn
    model = copy.deepcopy(body).double()
    hips = [joint_index("left_hip"), joint_index("right_hip")]
    with torch.no_grad():
        before = model(transl, orient, pose).joints[:, hips].mean(dim=1)
        after = model.from_matrices(transl, orient_turned, local).joints[:, hips].mean(dim=1)
    return replace(motion, transl=(transl + before - after).numpy(), global_orient=roma.rotmat_to_rotvec(orient_turned).numpy(),
                   body_pose=roma.rotmat_to_rotvec(local).numpy())  # fmt: skip


def lock_targets(points: np.ndarray, contacts: np.ndarray, fps: float,
                 config: CleanupConfig = CleanupConfig()) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Lock targets (T, 4, 3) and weights (T, 4) for sole points (T, 4, 3) on a levelled floor.

    Over each contact a point holds where it is at one reference frame of its foot's stance (a stance: a run of
    heel or toe contact; its reference: the middle of the frames where both touch, else of the point's own
    contact), so heel and toe targets stay one rigid foot length apart. On the floor (within `floor_tolerance`
    of z = 0 at the median of the contact) the target is at z = 0, else at its median height (a step). Weight 1
    over the contact; for `blend_seconds` on each side the point keeps its own path plus the correction at the
    contact's nearer end, faded linearly to nothing (weight 1), so the lock eases in and out; elsewhere 0.
    """
    targets = points.copy()
    weights = np.zeros(contacts.shape)
    ramps = np.zeros(contacts.shape)
    blend = max(1, int(round(config.blend_seconds * fps)))
    frames = np.arange(len(points))
    for heel, toe in ((0, 1), (2, 3)):
        for stance_start, stance_stop in runs(contacts[:, heel] | contacts[:, toe]):
            both = np.flatnonzero(contacts[stance_start:stance_stop, heel] & contacts[stance_start:stance_stop, toe])
            for point in (heel, toe):
                for start, stop in runs(contacts[stance_start:stance_stop, point]):
                    start, stop = start + stance_start, stop + stance_start
                    reference = stance_start + both[len(both) // 2] if len(both) else (start + stop - 1) // 2
                    target = points[reference, point].copy()
                    height = np.median(points[start:stop, point, 2])
                    target[2] = 0.0 if abs(height) <= config.floor_tolerance else height
                    before, after = start - frames, frames - (stop - 1)
                    ramp = np.clip(1.0 - np.maximum(before, after).clip(min=0) / (blend + 1), 0.0, 1.0)
                    edge = np.where(before > 0, start, stop - 1)  # the contact frame each blend frame eases from
                    eased = points[:, point] + ramp[:, None] * (target - points[edge, point])
                    eased[start:stop] = target
                    better = ramp > ramps[:, point]
                    ramps[better, point] = ramp[better]
                    weights[better, point] = 1.0
                    targets[better, point] = eased[better]
    return targets, weights


def lock_feet(motion: BodyMotion, body: BodyModel, targets: np.ndarray, weights: np.ndarray,
              config: CleanupConfig = CleanupConfig()) -> BodyMotion:  # fmt: skip
    """Foot locking by batched IK over the clip (see the module docstring): (T, 4, 3) targets, (T, 4) weights."""
    model = copy.deepcopy(body).double()
    transl0, orient0, pose0 = _tensors(motion, torch.float64)
    legs = torch.tensor([joint_index(name) - 1 for name in LEG_JOINTS])
    orient_init = matrix_to_sixd(roma.rotvec_to_rotmat(orient0))
    legs_init = matrix_to_sixd(roma.rotvec_to_rotmat(pose0[:, legs]))
    orient = orient_init.clone().requires_grad_(True)
    leg_pose = legs_init.clone().requires_grad_(True)
    shift = torch.zeros_like(transl0, requires_grad=True)
    target = torch.as_tensor(targets)
    weight = torch.as_tensor(weights)
    soles, feet = sole_vertex_ids(), foot_vertex_ids()
    pose_matrices = roma.rotvec_to_rotmat(pose0)

    def second_difference(x: torch.Tensor) -> torch.Tensor:
        return (x[2:] - 2 * x[1:-1] + x[:-2]).pow(2).flatten(1).sum(-1).mean() if len(x) > 2 else x.sum() * 0

    def posed():
        local = pose_matrices.clone()
        local[:, legs] = rotation_matrix(leg_pose)
        return model.from_matrices(transl0 + shift, rotation_matrix(orient), local)

    with torch.no_grad():
        original = posed().joints
    free = torch.ones(original.shape[:2], dtype=torch.float64)  # (T, 22): a locked foot's leg may move freely
    for side, points in (("left", [0, 1]), ("right", [2, 3])):
        for name in (f"{side}_knee", f"{side}_ankle", f"{side}_foot"):
            free[:, joint_index(name)] = 1.0 - weight[:, points].amax(-1)
    optimiser = torch.optim.Adam([orient, leg_pose, shift], lr=config.learning_rate)
    for _ in range(config.iterations):
        optimiser.zero_grad()
        pose = posed()
        lock = ((model.skin(pose, soles) - target).pow(2).sum(-1) * weight).sum(-1).mean()
        below = model.skin(pose, feet)[..., 2].clamp(max=0.0).pow(2).sum(-1).mean()
        rotations = (leg_pose - legs_init).pow(2).sum((-1, -2)).mean() + (orient - orient_init).pow(2).sum(-1).mean()
        smooth = second_difference(shift) + second_difference(leg_pose - legs_init) + second_difference(orient - orient_init)
        moved = ((pose.joints - original).pow(2).sum(-1) * free).sum(-1).mean()
        loss = (config.lock_weight * lock + config.floor_weight * below + config.rotation_weight * rotations + config.joint_weight * moved
                + config.pelvis_weight * shift.pow(2).sum(-1).mean() + config.smooth_weight * smooth)  # fmt: skip
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        body_pose = pose0.clone()
        body_pose[:, legs] = roma.rotmat_to_rotvec(rotation_matrix(leg_pose))
        return replace(
            motion,
            transl=(transl0 + shift).numpy(),
            global_orient=roma.rotmat_to_rotvec(rotation_matrix(orient)).numpy(),
            body_pose=body_pose.numpy(),
        )


@dataclass(frozen=True)
class CleanupResult:
    """motion: cleaned. contacts: (T, 4) bool per sole point. floor: as fitted before levelling. pelvis_tilt_fix:
    degrees the pelvis was turned back (0 unless asked for). joint_shift: (T, 22) m each joint moved by foot
    locking (levelling, a rigid turn of the whole clip, and the pelvis-tilt fix excluded).
    lock_residual: (T, 4) m distance of each contact point from its lock target (NaN outside contacts)."""

    motion: BodyMotion
    contacts: np.ndarray
    floor: Floor
    pelvis_tilt_fix: float
    joint_shift: np.ndarray
    lock_residual: np.ndarray


def clean(motion: BodyMotion, body: BodyModel, config: CleanupConfig = CleanupConfig(),
          correct_pelvis_tilt: bool = False) -> CleanupResult:  # fmt: skip
    """Contacts, floor, pelvis tilt (with `correct_pelvis_tilt`: a skeleton not the subject's own) and foot locking
    for one clip (see the module docstring)."""
    points = sole_points(motion, body)
    contacts = label_contacts(points, motion.fps, config)
    floor = fit_floor(points, contacts, config)
    levelled = level_floor(motion, floor if floor.level else replace(floor, slope=(0.0, 0.0)))
    tilt = 0.0
    if correct_pelvis_tilt:
        with torch.no_grad():
            tilt = tilt_excess(body(*_tensors(levelled, torch.float32)).joints.double().numpy(), motion.fps, config)
        levelled = untilt_pelvis(levelled, body, tilt)
    points = sole_points(levelled, body)
    targets, weights = lock_targets(points, contacts, motion.fps, config)
    locked = lock_feet(levelled, body, targets, weights, config)
    with torch.no_grad():
        before = body(*_tensors(levelled, torch.float32)).joints
        after = body(*_tensors(locked, torch.float32)).joints
    residual = np.linalg.norm(sole_points(locked, body) - targets, axis=-1)
    residual[~contacts] = np.nan
    return CleanupResult(locked, contacts, floor, tilt, (after - before).norm(dim=-1).numpy(), residual)
