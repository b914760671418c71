"""Reward terms (GAMMA's, WandrReach's speed term), the contact score and window speeds against hand-computed values."""

from __future__ import annotations

import math

import pytest
import torch

from motion_envs.metrics import contact_score, slowest_marker_speed, window_speeds
from motion_envs.body.canonical_frame import LEFT_HIP, PELVIS, RIGHT_HIP
from motion_envs.rewards import (
    RewardConfig,
    contact_reward,
    facing_direction,
    goal_absorbing_reward,
    goal_reward,
    orientation_reward,
    overspeed,
    path_reward,
    pose_prior_reward,
)


def test_path_reward_is_one_towards_the_goal_zero_away_half_across():
    start = torch.zeros(3, 2)
    end = torch.tensor([[1.0, 0.0]] * 3)
    goals = torch.tensor([[10.0, 0.0], [-10.0, 0.0], [0.0, 10.0]])
    assert torch.allclose(path_reward(start, end, goals), torch.tensor([1.0, 0.0, 0.5]), atol=1e-6)


def _joints_facing(direction: float) -> torch.Tensor:
    """Joints whose hips make the body face `direction` (radians from +x) with the pelvis at (1, 1)."""
    joints = torch.zeros(1, 22, 3)
    joints[0, PELVIS] = torch.tensor([1.0, 1.0, 0.9])
    right = torch.tensor([math.cos(direction - math.pi / 2), math.sin(direction - math.pi / 2), 0.0])
    joints[0, RIGHT_HIP] = joints[0, PELVIS] + 0.1 * right
    joints[0, LEFT_HIP] = joints[0, PELVIS] - 0.1 * right
    return joints


def test_facing_and_orientation_reward():
    joints = _joints_facing(math.pi / 2)  # facing +y
    assert torch.allclose(facing_direction(joints), torch.tensor([[0.0, 1.0]]), atol=1e-6)
    assert orientation_reward(joints, torch.tensor([[1.0, 5.0]])).item() == pytest.approx(1.0, abs=1e-6)
    assert orientation_reward(joints, torch.tensor([[1.0, -5.0]])).item() == pytest.approx(0.0, abs=1e-6)
    assert orientation_reward(joints, torch.tensor([[6.0, 1.0]])).item() == pytest.approx(0.5, abs=1e-6)


def test_contact_reward_paper_and_release_shapes():
    z0, z1, speed = torch.tensor([0.9]), torch.tensor([1.0]), torch.tensor([0.2])
    assert contact_reward(z0, z1, speed).item() == pytest.approx(math.exp(-0.1) * math.exp(-0.04), rel=1e-5)
    assert contact_reward(z0, z1, speed, speed_power=1.0).item() == pytest.approx(math.exp(-0.1) * math.exp(-0.2), rel=1e-5)


def test_pose_prior_goal_and_absorbing_terms():
    mean = torch.zeros(2, 4, 32)
    mean[1, :, :2] = 4.0  # |μ| = sqrt(32), rms 1, every frame
    assert torch.allclose(pose_prior_reward(mean), torch.tensor([1.0, math.exp(-1.0)]))
    mean[1, :2, :2] = 0.0  # rms 0 on half the frames
    assert torch.allclose(pose_prior_reward(mean, power=1.0)[1], torch.tensor(math.exp(-0.5)))
    distances = torch.tensor([0.5, 5.0, 25.0])
    assert torch.allclose(goal_reward(distances, scale=20.0, tolerance=0.75), torch.tensor([1.0, 0.75, 0.0]))
    bonus = goal_absorbing_reward(torch.tensor([True, False]), torch.tensor([10.0, 10.0]), 5.0)
    assert bonus.tolist() == [50.0, 0.0]


def test_reward_configs():
    assert RewardConfig.named("paper") == RewardConfig.paper()
    release = RewardConfig.named("release")
    assert release.orientation == 0.5 and release.goal_scale == 10.0 and release.central_difference
    assert RewardConfig.paper().best_step_reward == 5.0
    with pytest.raises(ValueError, match="unknown reward config 'fast'"):
        RewardConfig.named("fast")


def test_slowest_marker_speed_and_contact_score():
    markers = torch.zeros(2, 3, 2, 3)
    markers[:, :, 0, 0] = torch.tensor([0.0, 0.01, 0.03])  # 0.4 m/s then 0.8 m/s at 40 fps
    markers[:, :, 1, 1] = torch.tensor([0.0, 0.02, 0.04])  # 0.8 m/s throughout
    assert torch.allclose(slowest_marker_speed(markers, 40.0), torch.tensor([0.4, 0.4]))
    assert torch.allclose(slowest_marker_speed(markers, 40.0, central=True), torch.tensor([0.6, 0.6]))
    markers = markers[:, :, :1].clone()
    markers[1, :, 0, 0] = 0.0  # a still marker on the ground: perfect contact
    markers[0, :, 0, 2] = 0.15  # 10 cm above the threshold height
    expected = math.exp(-0.10) * math.exp(-(0.4 - 0.075))
    assert torch.allclose(contact_score(markers, 40.0), torch.tensor([expected, 1.0]), atol=1e-6)


def test_skating_threshold_is_wandrs_speed_at_any_frame_rate():
    from motion_envs.metrics import WANDR_SKATING_THRESHOLD, skating_threshold

    assert skating_threshold(30) == pytest.approx(WANDR_SKATING_THRESHOLD)
    assert skating_threshold(40) == pytest.approx(0.2 / 40)


def test_goal_settlement_completes_the_episode_sum():
    from motion_envs.rewards import goal_settlement

    settled = goal_settlement(torch.tensor([10]), torch.tensor([0.8]), torch.tensor([5.0]))
    assert settled.item() == pytest.approx(3.0)


def test_reward_specs_change_named_fields_and_refuse_unknown_ones():
    from motion_envs.rewards import RewardConfig

    changed = RewardConfig.named("release:goal=5,central_difference=false")
    assert changed.goal == 5.0 and changed.central_difference is False and changed.orientation == 0.5
    assert changed.best_step_reward == RewardConfig.release().best_step_reward + 4.0
    with pytest.raises(ValueError, match="bad reward change 'speed=1'"):
        RewardConfig.named("paper:speed=1")
    with pytest.raises(ValueError, match="unknown reward config 'papers'"):
        RewardConfig.named("papers")


def test_overspeed_counts_only_ground_speed_above_the_limit():
    before = torch.zeros(3, 3)
    after = torch.tensor([[0.05, 0.0, 0.0], [0.1, 0.0, 0.5], [0.0, 0.2, 0.0]])  # 1.5, 3 (and a jump), 6 m/s at 30 fps
    assert torch.allclose(overspeed(before, after, fps=30, limit=2.1), torch.tensor([0.0, 0.9, 3.9]), atol=1e-5)


def test_window_speeds_over_half_seconds_inside_each_track():
    frames = torch.arange(31, dtype=torch.float32)
    walk = torch.stack([frames * 0.04, torch.zeros(31)], -1)  # 1.2 m/s for 30 frames
    run = torch.stack([frames.clamp(max=20) * 0.1, torch.zeros(31)], -1)  # 3 m/s, stopped after 20 frames
    speeds, inside = window_speeds(torch.stack([walk, run]), torch.tensor([30, 20]), fps=30)
    assert speeds.shape == inside.shape == (2, 16)
    assert torch.allclose(speeds[0], torch.full((16,), 1.2), atol=1e-5)
    assert torch.allclose(speeds[1, :6], torch.full((6,), 3.0), atol=1e-5)  # spans ending at frames 15..20
    assert inside[0].all() and inside[1].sum() == 6
    empty, none = window_speeds(torch.zeros(1, 10, 2), torch.tensor([9]), fps=30)
    assert empty.shape == none.shape == (1, 0)


def test_pelvis_drop_counts_only_the_metres_below_the_floor_height():
    from motion_envs.rewards import pelvis_drop

    pelvis = torch.tensor([[0.0, 0.0, 0.9], [1.0, 2.0, 0.3], [0.0, 0.0, 0.1]])
    assert torch.allclose(pelvis_drop(pelvis, 0.3), torch.tensor([0.0, 0.0, 0.2]))
