"""The foot rule: legs fitted to target feet (two-bone IK), loaded feet held, GAMMA's motion kept."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from motion_envs.body import BodyModel
from motion_envs.body.foot_lock import LOCK_SPEED, MAX_OFFSET, RELEASE, locked_feet
from motion_envs.body.leg_fit import CONTACT_POINTS, LEG_POSE_ROWS, fit_legs, leg_fit_marker_ids
from motion_envs.body.rotations import matrix_to_sixd, rotation_matrix
from motion_envs.body.skeleton import JOINT_NAMES
from motion_envs.envs.gamma_reach import SOLE_MARKERS, GammaReachConfig, GammaReachCore
from motion_envs.metrics import loaded_foot_skating
from motion_envs.priors.gamma_generator import GammaGenerator

MOVED_JOINTS = [i for i, name in enumerate(JOINT_NAMES) if any(part in name for part in ("knee", "ankle", "foot"))]
FPS = 40.0


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel()


def _random_bodies(count: int, seed: int, body: BodyModel):
    generator = torch.Generator().manual_seed(seed)
    transl = torch.randn(count, 3, generator=generator) * 0.1 + torch.tensor([0.0, 0.0, 0.9])
    orient = matrix_to_sixd(rotation_matrix(torch.randn(count, 3, generator=generator) * 0.3))
    pose = matrix_to_sixd(rotation_matrix(torch.randn(count, 21, 3, generator=generator) * 0.2))
    return transl, orient, pose


def _feet(body: BodyModel, transl, orient, pose) -> torch.Tensor:
    return body.skin(body(transl, orient, pose), leg_fit_marker_ids().flatten()).unflatten(-2, (2, -1))


def test_fitted_legs_put_the_feet_on_reachable_targets_and_leave_the_rest(body):
    """Targets from the same bodies with other hip, knee, ankle and toe rotations (so reachable): the fit lands every
    foot marker on its target; joints off the legs do not move; a body fitted to its own feet is unchanged."""
    transl, orient, pose = _random_bodies(64, 0, body)
    moved = pose.clone()
    legs = [JOINT_NAMES.index(f"{side}_{part}") - 1 for side in ("left", "right") for part in ("hip", "knee", "ankle", "foot")]
    moved[:, legs] = matrix_to_sixd(rotation_matrix(pose[:, legs]) @ rotation_matrix(torch.randn(64, 8, 3) * 0.15))
    targets = _feet(body, transl, orient, moved)
    posed = body(transl, orient, pose)
    own = _feet(body, transl, orient, pose)
    fit = fit_legs(body, posed, transl, own, targets)
    fitted = fit.posed
    rows = pose.clone()
    rows[:, LEG_POSE_ROWS] = matrix_to_sixd(fit.leg_pose)
    posed_again = body(transl, orient, rows)  # the fit's leg rotations pose the same body by forward kinematics
    assert torch.allclose(posed_again.joints, fitted.joints, atol=1e-5)
    assert torch.allclose(posed_again.rotations, fitted.rotations, atol=1e-5)
    assert (_feet(body, transl, orient, pose) - targets).norm(dim=-1).mean() > 0.03
    error = (body.skin(fitted, leg_fit_marker_ids().flatten()).unflatten(-2, (2, -1)) - targets).norm(dim=-1)
    assert error.max() < 3e-3 and error.mean() < 5e-4  # exact but for the ball marker's 14% skinning to the toes
    others = [i for i in range(len(JOINT_NAMES)) if i not in MOVED_JOINTS]
    assert torch.allclose(fitted.joints[:, others], posed.joints[:, others], atol=1e-5)
    again = fit_legs(body, posed, transl, own, own).posed
    assert torch.allclose(again.joints, posed.joints, atol=1e-5)


def _track(slide_per_frame: float, lift_right: float, frames: int = 9) -> torch.Tensor:
    """(frames, 2, 5, 3) two flat feet: the left on the floor sliding along +y, the right `lift_right` up, still."""
    foot = torch.tensor([[0.0, 0.05, 0.08], [0.0, -0.05, 0.02], [0.0, 0.10, 0.03], [0.0, 0.12, 0.02], [0.0, 0.18, 0.02]])
    left = foot + torch.tensor([-0.1, 0.0, 0.0])
    right = foot + torch.tensor([0.1, 0.0, lift_right])
    step = torch.arange(frames, dtype=torch.float32)[:, None, None] * torch.tensor([0.0, slide_per_frame, 0.0])
    return torch.stack([left + step, right.expand(frames, -1, -1)], dim=1)


def test_a_loaded_foot_is_held_and_a_lifted_one_rejoins_the_prediction():
    """A loaded foot that the prediction slides 0.5 cm per frame (0.2 m/s) stays where it stood; a lifted foot that
    starts 4 cm from its prediction (the body's foot at frame 0) closes the gap by `RELEASE` per frame."""
    track = _track(0.005, lift_right=0.10)
    body_first = track[0].clone()
    body_first[1, :, 0] += 0.04
    targets = locked_feet(track, body_first, CONTACT_POINTS, FPS)
    assert targets.shape == (8, 2, 5, 3)
    assert torch.allclose(targets[:, 0], track[0, 0].expand(8, -1, -1), atol=1e-6)  # held through 4 cm of slide
    gap = (targets[:, 1, :, 0] - track[1:, 1, :, 0])[:, 0]
    assert torch.allclose(gap, 0.04 * RELEASE ** torch.arange(1, 9, dtype=torch.float32), atol=1e-6)
    assert torch.equal(targets[..., 2], track[1:, ..., 2])  # heights are the prediction's


def test_a_foot_is_dragged_on_beyond_the_longest_hold_and_a_fast_one_is_not_held():
    """Sliding 1.5 cm per frame (0.6 m/s, below `LOCK_SPEED`): held until `MAX_OFFSET` behind, then dragged at that
    distance. Sliding faster than `LOCK_SPEED`: a step, not a slip, so the prediction stands."""
    track = _track(0.015, lift_right=0.10)
    targets = locked_feet(track, track[0], CONTACT_POINTS, FPS)
    behind = track[1:, 0, 0, 1] - targets[:, 0, 0, 1]
    assert torch.allclose(behind, torch.clamp(0.015 * torch.arange(1, 9), max=MAX_OFFSET), atol=1e-6)
    fast = _track(1.2 * LOCK_SPEED / FPS, lift_right=0.10)
    assert torch.allclose(locked_feet(fast, fast[0], CONTACT_POINTS, FPS), fast[1:], atol=1e-7)


@pytest.fixture(scope="module")
def gamma() -> GammaGenerator:
    return GammaGenerator.load()


def test_the_foot_rule_keeps_gammas_motion_and_stills_the_loaded_feet(gamma):
    """Random latents from the shipped start poses, the same with and without `lock_feet` (no floor rule, so that
    nothing else differs): the blended markers, which seed the next primitive, and the pelvis agree to float
    rounding over 6 primitives; the bodies' loaded heel or toe marker slides less than half as often."""
    core = GammaReachCore(GammaReachConfig(precision="float32", ground_feet=False), gamma)
    start = core.sample_initial_state([np.random.default_rng([7, i]) for i in range(32)])
    latents = torch.randn(6, 32, 128, generator=torch.Generator().manual_seed(7))
    runs = {}
    for lock in (False, True):
        seed, markers, pelvis, slide = start.seed, [], [], []
        for z in latents:
            primitive, seed = gamma.step(seed, z, lock_feet=lock)
            markers.append(primitive.markers)
            pelvis.append(primitive.transl)
            new = primitive.new_frames()[:, 1:]
            slide.append((loaded_foot_skating(primitive.reprojected_markers[:, :, SOLE_MARKERS], FPS) * new).sum() / new.sum())
        runs[lock] = torch.stack(markers), torch.stack(pelvis), torch.stack(slide).mean()
    assert torch.allclose(runs[True][0], runs[False][0], atol=1e-4)
    assert torch.allclose(runs[True][1], runs[False][1], atol=1e-4)
    # measured (AMX Xeon, fp32): the loaded heel or toe slides in 14.3% of transitions without the rule, 6.3% with it
    assert runs[False][2] > 0.05 and runs[True][2] < 0.5 * runs[False][2], (runs[False][2], runs[True][2])


def test_wandrs_rule_shows_held_legs_and_leaves_the_prior_alone():
    """WandrReach's foot rule is shown, not fed back: the prior's own bodies are the same with and without it (fed
    back, held legs folded a 15-s walk), the shown pose differs from the prior's only at the legs, whose rotations
    stay proper, and the shown loaded feet slide less often than the prior's (sampler, 32 bodies, 90 frames)."""
    from baselines.wandr_sampler import WandrSampler
    from motion_envs.body.leg_fit import LEG_JOINTS
    from motion_envs.body.markers import sole_vertex_ids
    from motion_envs.envs.wandr_reach import WandrReachConfig, WandrReachCore
    from motion_envs.priors.wandr_features import FPS

    slides, joints = {}, {}
    for lock in (False, True):
        core = WandrReachCore(WandrReachConfig(lock_feet=lock))
        state = core.sample_initial_state([np.random.default_rng([3, i]) for i in range(32)])
        sampler, rows = WandrSampler(1.0, seed=3), core.body.skin_rows(sole_vertex_ids())
        body, soles = state.body, []
        for frame in range(90):
            with torch.no_grad():
                body, _ = core.stepper.step(body, sampler(core, state), state.goal, torch.full((32,), 240 - frame))
                soles.append(core.body.skin_with_rows(core.body.from_matrices(body.transl, body.orient, body.shown_pose), rows))
        error = (body.shown_pose.transpose(-1, -2) @ body.shown_pose - torch.eye(3)).abs().max()
        assert error < 1e-4, error
        off_legs = [joint - 1 for joint in range(1, 22) if joint not in LEG_JOINTS]  # body_pose rows start at joint 1
        assert torch.equal(body.shown_pose[:, off_legs], body.pose[:, off_legs])
        slides[lock], joints[lock] = float(loaded_foot_skating(torch.stack(soles, dim=1), FPS).float().mean()), body.joints
    assert torch.allclose(joints[True], joints[False], atol=1e-5)  # the same computation on the prior's side
    assert slides[True] < 0.6 * slides[False], slides  # measured (AMX Xeon): 0.49 without, 0.18 with


def test_a_straight_leg_has_finite_gradients():
    """Latent optimisation backpropagates through the foot rule (WandrReach's default): a leg stretched straight
    at its target must not give the sqrt(0) that turned every latent of a 240-frame optimisation into NaN."""
    from motion_envs.body.leg_fit import two_bone

    hip, knee, ankle = torch.tensor([0.0, 0.0, 1.0]), torch.tensor([0.0, 0.0, 0.6]), torch.tensor([0.0, 0.0, 0.2])
    for target in (torch.tensor([0.0, 0.0, 0.2]), torch.tensor([0.3, 0.0, 0.0])):  # straight at it, out of reach
        target = target.clone().requires_grad_(True)
        thigh, shin = two_bone(hip, knee, ankle, target, torch.tensor([0.0, 1.0, 0.0]))
        (thigh.sum() + shin.sum()).backward()
        assert torch.isfinite(target.grad).all(), target.grad


def test_bench_gamma_feet_walks_the_same_bodies_with_less_skating_under_the_rule():
    """`bench gamma-feet`'s two walks (shipped α = 1 policy, 16 bodies × 6 primitives): the rule changes the legs
    (and, through the floor rule's lift, the heights the policy sees), not the walking: the pelvis keeps its
    speed, and the bodies' feet slide less."""
    from benchmarks.gamma_feet import figures, walk

    core = GammaReachCore(GammaReachConfig(precision="float32"))
    runs = {lock: walk(GammaReachCore(dataclasses.replace(core.config, lock_feet=lock), core.generator), 16, 6, 0)
            for lock in (False, True)}  # fmt: skip
    table = {lock: figures(run, 16, 6) for lock, run in runs.items()}
    speeds = [table[lock]["pelvis ground speed (m/s)"] for lock in (False, True)]
    assert abs(speeds[1] - speeds[0]) < 0.05 * speeds[0] and speeds[0] > 0.3, speeds
    assert table[True]["FS (WANDR's)"] < table[False]["FS (WANDR's)"], table
    assert table[True]["contact-aware FS"] < table[False]["contact-aware FS"], table


def test_leg_joints_is_a_view_of_the_legs_by_part_then_side():
    """`fit_legs` reads and writes the legs through `leg_joints`: hips, knees, ankles, toes, each left then right,
    for per-joint vectors and matrices alike, and a write lands on exactly those joints."""
    from motion_envs.body.leg_fit import LEG_JOINTS, leg_joints

    for trailing, shape in ((1, (3,)), (2, (3, 3))):
        values = torch.arange(22.0).view(1, 22, *[1] * trailing).expand(2, 22, *shape).clone()
        legs = leg_joints(values, trailing)
        assert legs.shape == (2, 4, 2, *shape)
        assert torch.equal(legs[0, ..., *[0] * trailing], torch.tensor(LEG_JOINTS, dtype=torch.float32).view(2, 4).T)
        legs.fill_(-1.0)
        written = (values == -1.0).flatten(2).all(-1)  # (2, 22)
        assert written[:, list(LEG_JOINTS)].all() and written.sum() == 2 * len(LEG_JOINTS)
