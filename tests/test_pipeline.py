"""Resampling, retargeting a real clip, canonicalisation, mirroring, splits and the cache."""

from __future__ import annotations

import numpy as np
import pytest
import roma
import torch

from motion_envs.body import MIRROR_JOINTS
from motion_envs.data.build import build, find_sources, load_clip
from motion_envs.data.canonical import body_tensors, facing_angle, lowest_foot_points
from motion_envs.data.dataset import MotionDataset
from motion_envs.data.mirror import mirror
from motion_envs.data.motion import BodyMotion
from motion_envs.data.resample import resample_body, resample_times
from motion_envs.data.cleanup import CleanupConfig
from motion_envs.data.retarget import RetargetConfig
from motion_envs.data.splits import SPLITS, split_of
from motion_envs.data.start_poses import load_start_poses


def _random_motion(frames: int = 40, fps: float = 120.0, seed: int = 0) -> BodyMotion:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, frames)[:, None]
    smooth = lambda scale, *shape: scale * np.sin(2 * np.pi * t.reshape(-1, *[1] * len(shape)) + rng.normal(size=shape))  # noqa: E731
    return BodyMotion("clip", "s", fps, smooth(1.0, 3), smooth(1.0, 3), smooth(0.4, 21, 3))


def test_resampling_keeps_duration_and_is_continuous():
    motion = _random_motion(frames=121, fps=120.0)
    for fps in (30, 40):
        out = resample_body(motion, fps)
        assert out.fps == fps
        assert (out.num_frames - 1) / fps == pytest.approx((motion.num_frames - 1) / motion.fps)
        np.testing.assert_allclose(out.transl[0], motion.transl[0], atol=1e-12)
        np.testing.assert_allclose(out.transl[-1], motion.transl[-1], atol=1e-12)
        # frames that land on source frames reproduce them; rotations stay continuous
        step = int(motion.fps // fps)
        np.testing.assert_allclose(out.body_pose[::1], motion.body_pose[::step][: out.num_frames], atol=1e-9) if 120 % fps == 0 else None
        rotations = roma.rotvec_to_rotmat(torch.as_tensor(out.body_pose))
        jumps = roma.rotmat_geodesic_distance(rotations[1:], rotations[:-1])
        source = roma.rotvec_to_rotmat(torch.as_tensor(motion.body_pose))
        source_jumps = roma.rotmat_geodesic_distance(source[1:], source[:-1])
        assert jumps.max() <= source_jumps.max() * (motion.fps / fps) * 1.01


def test_resample_times_rejects_a_single_frame():
    assert len(resample_times(121, 120, 30)) == 31
    with pytest.raises(ValueError, match="two frames"):
        resample_times(1, 120, 30)


def test_mirroring_twice_is_exact_and_swaps_sides(body):
    motion = _random_motion()
    twice = mirror(mirror(motion))
    np.testing.assert_allclose(twice.body_pose, motion.body_pose, atol=0)
    np.testing.assert_allclose(twice.global_orient, motion.global_orient, atol=0)
    joints = body(*body_tensors(motion)).joints
    mirrored = body(*body_tensors(mirror(motion))).joints
    expected = joints[:, list(MIRROR_JOINTS)] * torch.tensor([-1.0, 1.0, 1.0])
    # exact up to the body's own left/right asymmetry (mannequin-x's SMPL-X skeleton, a few cm)
    assert (mirrored - expected).norm(dim=-1).mean() < 0.03
    rotations = body(*body_tensors(motion)).rotations[:, list(MIRROR_JOINTS)]
    flip = torch.diag(torch.tensor([-1.0, 1.0, 1.0]))
    assert torch.allclose(body(*body_tensors(mirror(motion))).rotations, flip @ rotations @ flip, atol=1e-5)


def test_split_is_fixed_and_every_split_holds_cmu_walking():
    walking_subjects = {"02", "05", "06", "07", "08", "10", "12"}
    for split in SPLITS:
        assert any(split_of(s) == split for s in walking_subjects)
    assert split_of("somebody") == split_of("somebody") in SPLITS


@pytest.mark.mocap
@pytest.mark.parametrize("clip", ["cmu/07_01.bvh", "hdm05/HDM_bd_jogLeftCircle4StepsRstart_001_120.amc"])
def test_real_clip_retargets_within_three_centimetres_and_is_canonical(mocap_dir, body, clip):
    """Uncleaned, the first frame's lowest foot point is the floor; cleaned, the floor the contacts stand on is."""
    source = next(s for s in find_sources(mocap_dir) if s.relative == clip)
    for cleanup in (None, CleanupConfig()):
        motion = load_clip(source, 30, body, RetargetConfig(), cleanup)
        error = np.nanmean(motion.info["retarget_error"])
        assert error < 0.03, f"{clip}: mean joint error {error * 100:.1f} cm"
        with torch.no_grad():
            first = body(*(t[:1] for t in body_tensors(motion))).joints[0].numpy()
        np.testing.assert_allclose(first[0, :2], 0.0, atol=1e-5)  # pelvis over the origin
        assert abs(facing_angle(first)) < 1e-4  # facing +y
        lowest = lowest_foot_points(motion, body)[:, 2]
        if cleanup is None:
            assert abs(lowest[0]) < 1e-4  # lowest foot point on the ground
        else:
            standing = motion.info["contacts"].any(axis=1)
            assert standing.mean() > 0.5 and abs(np.median(lowest[standing])) < 0.01
            assert lowest.min() > -0.03


def _write_amass_folder(folder, seed=0):
    folder.mkdir(parents=True, exist_ok=True)
    motion = _random_motion(frames=60, seed=seed)
    np.savez(folder / "walk_poses.npz", trans=motion.transl, root_orient=np.tile([np.pi / 2, 0, 0], (60, 1)),
             pose_body=0.3 * motion.body_pose.reshape(60, 63), mocap_framerate=120.0)  # fmt: skip


def test_cache_rebuild_is_skipped_when_nothing_changed_and_redone_when_a_source_changes(tmp_path, capsys):
    mocap = tmp_path / "mocap" / "subject1"
    _write_amass_folder(mocap)
    (mocap / "broken.bvh").write_text("HIERARCHY\nROOT hip\n{\n  OFFSET 0 0\n")
    first = build(mocap_dir=tmp_path / "mocap", cache_dir=tmp_path / "cache", fps_list=(30,), progress=False)
    assert first.rebuilt and first.clips == 1
    assert len(first.failures) == 1 and "broken.bvh:4" in first.failures[0]
    assert "skipped subject1/broken.bvh" in capsys.readouterr().err
    dataset = MotionDataset.load(first.caches[30])
    assert list(dataset.arrays["failures"]) == first.failures
    assert dataset.clip(0).num_frames == 15  # 60 frames @ 120 fps -> 0.49 s @ 30 fps

    again = build(mocap_dir=tmp_path / "mocap", cache_dir=tmp_path / "cache", fps_list=(30,), progress=False)
    assert not again.rebuilt and again.caches == first.caches

    _write_amass_folder(mocap, seed=1)
    changed = build(mocap_dir=tmp_path / "mocap", cache_dir=tmp_path / "cache", fps_list=(30,), progress=False)
    assert changed.rebuilt and changed.caches[30] != first.caches[30]


def test_a_killed_build_resumes_from_its_finished_clips(tmp_path, monkeypatch):
    """Each finished clip is kept beside the cache, so a build killed after it does not load it again; the parts go
    once the cache is written, and the resumed cache equals an uninterrupted one."""
    from motion_envs.data import build as build_module

    mocap = tmp_path / "mocap" / "subject1"
    _write_amass_folder(mocap)
    _write_amass_folder(tmp_path / "mocap" / "subject2", seed=1)
    loaded = []
    real_load = build_module.load_clip

    def load_then_die(source, *args):
        if loaded:
            raise KeyboardInterrupt  # the kill, after the first clip
        loaded.append(source.relative)
        return real_load(source, *args)

    monkeypatch.setattr(build_module, "load_clip", load_then_die)
    with pytest.raises(KeyboardInterrupt):
        build(mocap_dir=tmp_path / "mocap", cache_dir=tmp_path / "cache", fps_list=(30,), progress=False)
    assert len(list((tmp_path / "cache").glob("*.parts/*.pkl"))) == 1
    def load_and_count(source, *args):
        loaded.append(source.relative)
        return real_load(source, *args)

    monkeypatch.setattr(build_module, "load_clip", load_and_count)
    resumed = build(mocap_dir=tmp_path / "mocap", cache_dir=tmp_path / "cache", fps_list=(30,), progress=False)
    assert loaded[0] != loaded[1] and len(loaded) == 2 and resumed.clips == 2  # the second clip only
    assert not list((tmp_path / "cache").glob("*.parts"))
    fresh = build(mocap_dir=tmp_path / "mocap", cache_dir=tmp_path / "fresh", fps_list=(30,), progress=False)
    resumed_arrays, fresh_arrays = np.load(resumed.caches[30]), np.load(fresh.caches[30])
    for name in ("transl", "global_orient", "body_pose", "clip_file"):
        np.testing.assert_array_equal(resumed_arrays[name], fresh_arrays[name])


def test_missing_mocap_folder_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        build(mocap_dir=tmp_path / "nowhere", cache_dir=tmp_path / "cache", progress=False)


def test_shipped_start_poses_are_small_canonical_and_both_kinds(body):
    for fps in (30, 40):
        poses = load_start_poses(fps)
        assert set(poses["kind"]) == {"standing", "walking"}
        assert poses["body_pose"].shape[1:] == (10, 21, 3)
        first = body(*(torch.as_tensor(poses[k][:, 0]) for k in ("transl", "global_orient", "body_pose"))).joints
        np.testing.assert_allclose(first[:, 0, :2].numpy(), 0.0, atol=1e-4)
    with pytest.raises(ValueError, match="no shipped start poses at 25 fps"):
        load_start_poses(25)


def test_build_reports_every_bad_file_builds_the_rest_and_keeps_implausible_values_out(tmp_path, mocap_dir, capsys):
    """A garbage npz (BadZipFile) or a zero frame rate (ZeroDivisionError) aborted the whole build, and a BVH with
    1e300 values left inf in the cache; with every clip failing, only the first failure was named."""
    mocap = tmp_path / "mocap" / "subject1"
    _write_amass_folder(mocap)
    (mocap / "garbage.npz").write_bytes(b"PK\x03\x04 not really a zip")
    good = np.load(mocap / "walk_poses.npz")
    np.savez(mocap / "zero_rate.npz", **{**good, "mocap_framerate": 0.0})
    np.savez(mocap / "huge.npz", **{**good, "trans": np.full_like(good["trans"], 1e300)})
    lines = (mocap_dir / "cmu" / "09_03.bvh").read_text().splitlines()
    motion_at = lines.index("MOTION") + 13  # the tenth frame's values (CMU's first frame, a T-pose, is dropped)
    lines[motion_at] = " ".join(["1e300"] * len(lines[motion_at].split()))
    (mocap / "09_03.bvh").write_text("\n".join(lines[: motion_at + 50]).replace(lines[lines.index("MOTION") + 1], "Frames: 60"))
    report = build(mocap_dir=tmp_path / "mocap", cache_dir=tmp_path / "cache", fps_list=(30,), progress=False)
    assert report.clips == 1
    reasons = dict(failure.split(": ", 1) for failure in report.failures)
    assert set(reasons) == {"subject1/garbage.npz", "subject1/zero_rate.npz", "subject1/huge.npz", "subject1/09_03.bvh"}
    assert "not a readable npz" in reasons["subject1/garbage.npz"] and "positive" in reasons["subject1/zero_rate.npz"]
    assert "non-finite" in reasons["subject1/huge.npz"] or "implausible" in reasons["subject1/huge.npz"]
    assert "non-finite" in reasons["subject1/09_03.bvh"] or "implausible" in reasons["subject1/09_03.bvh"]
    dataset = MotionDataset.load(report.caches[30])
    assert all(np.isfinite(dataset.arrays[name]).all() for name in ("transl", "global_orient", "body_pose"))
    (mocap / "walk_poses.npz").unlink()
    with pytest.raises(RuntimeError, match=r"failed \(4\)") as error:
        build(mocap_dir=tmp_path / "mocap", cache_dir=tmp_path / "cache", fps_list=(30,), progress=False)
    assert all(name in str(error.value) for name in ("garbage.npz", "zero_rate.npz", "huge.npz", "09_03.bvh"))
