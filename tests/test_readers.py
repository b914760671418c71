"""BVH and ASF/AMC readers on handwritten files, malformed files, and the AMASS npz reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion_envs.data.amass import read_amass_npz
from motion_envs.data.asf_amc import read_amc, read_asf
from motion_envs.data.bvh import read_bvh
from motion_envs.data.motion import MocapFormatError
from motion_envs.data.skeleton_maps import CMU_ACCLAIM, UnknownSkeletonError, match_skeleton

HANDWRITTEN_BVH = """HIERARCHY
ROOT hip
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
1 2 3 0 0 0 0 0 0
1 2 3 90 0 0 0 90 0
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_handwritten_bvh_positions_follow_the_euler_convention(tmp_path):
    motion = read_bvh(write(tmp_path, "chain.bvh", HANDWRITTEN_BVH))
    assert motion.skeleton.names == ("hip", "spine", "spine_end")
    assert motion.fps == pytest.approx(30.0, rel=1e-4)
    positions, _ = motion.global_transforms()
    np.testing.assert_allclose(positions[0], [[1, 2, 3], [1, 12, 3], [1, 17, 3]], atol=1e-9)
    # frame 1: hip turns 90° about z, so the spine points along -x; the spine then
    # turns 90° about its own x, which is now along +y: the end site points along +z... of the
    # rotated frame: Rz(90) Rx(90) (0, 5, 0) = Rz(90) (0, 0, 5) = (0, 0, 5)
    np.testing.assert_allclose(positions[1], [[1, 2, 3], [-9, 2, 3], [-9, 2, 8]], atol=1e-9)


@pytest.mark.parametrize(
    ("corruption", "line", "message"),
    [
        (("OFFSET 0 10 0", "OFFSET 0 ten 0"), 8, "expected numbers"),
        (("Frames: 2", "Frames: 3"), 17, "but 2 data rows"),
        (("1 2 3 90 0 0 0 90 0", "1 2 3 90 0 0 0 90"), 20, "expected 9 values"),
        (("1 2 3 90 0 0 0 90 0", "1 2 3 90 0 x 0 90 0"), 20, "non-numeric"),
        (("CHANNELS 3 Zrotation", "CHANNELS 3 Wrotation"), 9, "bad CHANNELS"),
        (("MOTION", "MOTON"), 16, "expected 'MOTION'"),
    ],
)
def test_malformed_bvh_names_file_and_line(tmp_path, corruption, line, message):
    path = write(tmp_path, "broken.bvh", HANDWRITTEN_BVH.replace(*corruption))
    with pytest.raises(MocapFormatError, match=message) as error:
        read_bvh(path)
    assert error.value.path == path and error.value.line == line
    assert f"broken.bvh:{line}" in str(error.value)


HANDWRITTEN_ASF = """:version 1.10
:name test
:units
  mass 1.0
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name thigh
     direction 0 -1 0
     length 2
     axis 0 0 0 XYZ
     dof rx ry rz
  end
  begin
     id 2
     name shin
     direction 0 -1 0
     length 3
     axis 0 0 90 XYZ
     dof rx
  end
:hierarchy
  begin
    root thigh
    thigh shin
  end
"""

HANDWRITTEN_AMC = """:FULLY-SPECIFIED
:DEGREES
1
root 0 10 0 0 0 0
thigh 0 0 0
shin 0
2
root 0 10 0 0 0 0
thigh 90 0 0
shin 90
"""


def test_handwritten_asf_amc(tmp_path):
    asf = read_asf(write(tmp_path, "t.asf", HANDWRITTEN_ASF))
    motion = read_amc(write(tmp_path, "t_01.amc", HANDWRITTEN_AMC), asf)
    assert asf.metres_per_unit == pytest.approx(0.0254 / 0.45)
    positions, _ = motion.global_transforms()
    np.testing.assert_allclose(positions[0], [[0, 10, 0], [0, 10, 0], [0, 8, 0]], atol=1e-9)
    # thigh rx 90: the thigh (0, -2, 0) swings to (0, 0, -2); the shin's rx is about its
    # axis-rotated x (the ASF axis turns it 90° about z), i.e. about y, which leaves it be
    np.testing.assert_allclose(positions[1], [[0, 10, 0], [0, 10, 0], [0, 10, -2]], atol=1e-9)


def test_amc_with_wrong_value_count_names_the_line(tmp_path):
    asf = read_asf(write(tmp_path, "t.asf", HANDWRITTEN_ASF))
    path = write(tmp_path, "t_02.amc", HANDWRITTEN_AMC.replace("shin 90", "shin 90 1"))
    with pytest.raises(MocapFormatError, match=r"t_02.amc:10: shin needs 1 values"):
        read_amc(path, asf)


def test_unknown_skeleton_lists_its_joints():
    with pytest.raises(UnknownSkeletonError, match="hip, spine, spine_end"):
        match_skeleton(("hip", "spine", "spine_end"))
    assert match_skeleton(CMU_ACCLAIM.source_names() | {"lfingers"}) is CMU_ACCLAIM


def test_amass_npz_reader_converts_up_axis_and_translation(tmp_path, body):
    import torch

    frames = 5
    rng = np.random.default_rng(0)
    pose_body = 0.2 * rng.normal(size=(frames, 63))
    trans = rng.normal(size=(frames, 3))
    upright = np.tile([np.pi / 2, 0.0, 0.0], (frames, 1))  # AMASS's usual root: SMPL's Y up -> Z up
    path = tmp_path / "clip_poses.npz"
    np.savez(path, trans=trans, root_orient=upright, pose_body=pose_body, mocap_framerate=120.0)
    motion = read_amass_npz(path)
    assert motion.fps == 120.0 and motion.body_pose.shape == (frames, 21, 3)
    # SMPL's Y-up body raised by +90° about x faces -y; ours at rest faces +y, so the
    # converted orientation is a half turn about z
    np.testing.assert_allclose(np.abs(motion.global_orient[:, 2]), np.pi, atol=1e-6)
    pelvis = body(*(torch.as_tensor(x, dtype=torch.float32) for x in (motion.transl, motion.global_orient, motion.body_pose))).joints[:, 0]
    np.testing.assert_allclose(pelvis.numpy(), motion.transl, atol=1e-6)
    np.savez(tmp_path / "bad.npz", trans=trans, poses=np.zeros((frames, 10)), mocap_framerate=30.0)
    with pytest.raises(MocapFormatError, match="poses"):
        read_amass_npz(tmp_path / "bad.npz")
