"""Body model: agreement with mannequin-x, markers, foot vertices, head camera, bad input."""

from __future__ import annotations

import mannequin
import numpy as np
import pytest
import roma
import torch

from motion_envs.body import JOINT_NAMES, MIRROR_JOINTS, BodyModel
from motion_envs.body.frames import MANNEQUIN_TO_WORLD
from motion_envs.body.head_camera import head_camera
from motion_envs.body.markers import (
    FOOT_MARKERS,
    MARKER_NAMES,
    MARKER_VERTICES,
    foot_vertex_ids,
    marker_ids,
    place_all,
)
from motion_envs.body.rotations import matrix_to_sixd, rotation_matrix
from motion_envs.body.skeleton import PARENTS


def _random_pose(generator: torch.Generator, n: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    transl = torch.randn(n, 3, generator=generator, dtype=torch.float64)
    orient = torch.randn(n, 3, generator=generator, dtype=torch.float64)
    pose = 0.6 * torch.randn(n, 21, 3, generator=generator, dtype=torch.float64)
    return transl, orient, pose


def _mannequin_reference(transl, orient, pose, with_vertices: bool = False):
    """The same poses through mannequin-x's numpy model, mapped into our Z-up world."""
    model = mannequin.Mannequin("wooden")
    to_world = torch.as_tensor(MANNEQUIN_TO_WORLD)
    rotation = to_world.T @ roma.rotvec_to_rotmat(orient) @ to_world
    rest_pelvis = torch.as_tensor(model._identity["local_joint_offsets"][0], dtype=torch.float64)
    params = model.rest_pose(batch_dims=(len(transl),), dtype=np.float64)
    params["body_pose"] = pose.numpy()
    params["global_rotation"] = roma.rotmat_to_rotvec(rotation).numpy()
    params["global_translation"] = (transl @ to_world - rotation @ rest_pelvis).numpy()
    transforms = torch.as_tensor(model.joint_transforms(params))
    if not with_vertices:
        return transforms, None, to_world
    chunks = [  # mannequin-x skins every vertex at once: chunk to bound memory
        model.vertices({key: value[start : start + 50] for key, value in params.items()})
        for start in range(0, len(transl), 50)
    ]
    vertices = torch.as_tensor(np.concatenate(chunks)) @ to_world.T
    return transforms, vertices, to_world


def test_forward_kinematics_matches_mannequin_on_1000_poses(body, generator):
    transl, orient, pose = _random_pose(generator, 1000)
    out = body.double()(transl, orient, pose)
    transforms, _, to_world = _mannequin_reference(transl, orient, pose)
    joints = transforms[:, :22, :3, 3] @ to_world.T
    rotations = to_world @ transforms[:, :22, :3, :3] @ to_world.T
    assert (out.joints - joints).abs().max() < 1e-4
    assert (out.rotations - rotations).abs().max() < 1e-4
    body.float()


def test_skinning_matches_mannequin_vertices(generator):
    """200 poses (mannequin-x skins all 24k vertices per pose, ~30 ms each)."""
    body = BodyModel().double()
    transl, orient, pose = _random_pose(generator, 200)
    _, vertices, _ = _mannequin_reference(transl, orient, pose, with_vertices=True)
    ids = torch.cat([marker_ids(), foot_vertex_ids(), torch.arange(0, body.num_vertices, 97)])
    posed = body(transl, orient, pose)
    skinned = body.skin(posed, ids)
    assert (skinned - vertices[:, ids]).abs().max() < 1e-4
    grid = body(transl[:10].unflatten(0, (2, 5)), orient[:10].unflatten(0, (2, 5)), pose[:10].unflatten(0, (2, 5)))
    heights = body.heights_with_rows(grid, body.skin_rows(ids))  # (2, 5, V): the z of `skin`, batch shape kept
    assert heights.shape == (2, 5, len(ids)) and (heights.flatten(0, 1) - vertices[:10, ids, 2]).abs().max() < 1e-4


def test_six_d_rotations_give_the_same_pose(body, generator):
    transl, orient, pose = (t.float() for t in _random_pose(generator, 64))
    axis_angle = body(transl, orient, pose)
    sixd = body(transl, matrix_to_sixd(roma.rotvec_to_rotmat(orient)), matrix_to_sixd(roma.rotvec_to_rotmat(pose)))
    assert torch.allclose(axis_angle.joints, sixd.joints, atol=1e-5)


def test_rotation_matrices_give_the_same_pose_and_local_rotations_come_back(body, generator):
    """`from_matrices` (the axes map applied by a gather) poses what `forward` poses from axis-angle, and
    `smplx_local` takes the posed world rotations' parent-relative products back to the SMPL-X rotations."""
    transl, orient, pose = (t.float() for t in _random_pose(generator, 64))
    reference = body(transl, orient, pose)
    matrices = roma.rotvec_to_rotmat(pose)
    posed = body.from_matrices(transl, roma.rotvec_to_rotmat(orient), matrices)
    assert torch.allclose(posed.joints, reference.joints, atol=1e-5)
    assert torch.allclose(posed.rotations, reference.rotations, atol=1e-5)
    parents = torch.tensor(PARENTS[1:])
    local_world = posed.rotations[:, parents].transpose(-1, -2) @ posed.rotations[:, 1:]
    assert torch.allclose(body.smplx_local(local_world.movedim((-2, -1), (0, 1))), matrices, atol=1e-5)


def test_rest_body_stands_upright_facing_plus_y(body):
    zeros = torch.zeros(1, 3)
    rest = body(zeros, zeros, torch.zeros(1, 21, 3))
    joints = rest.joints[0]
    head, left_foot = joints[JOINT_NAMES.index("head")], joints[JOINT_NAMES.index("left_foot")]
    assert head[2] > 0.5 and left_foot[2] < -0.8  # z is up
    assert joints[JOINT_NAMES.index("left_hip"), 0] < 0 < joints[JOINT_NAMES.index("right_hip"), 0]
    assert left_foot[1] > joints[JOINT_NAMES.index("left_ankle"), 1]  # toes point +y
    camera = head_camera(rest)
    assert torch.allclose(camera.gaze[0], torch.tensor([0.0, 1.0, 0.0]), atol=1e-6)
    assert camera.eye[0, 2] > head[2]


def test_forward_kinematics_is_differentiable(body):
    pose = torch.zeros(2, 21, 3, requires_grad=True)
    out = body(torch.zeros(2, 3), torch.zeros(2, 3), pose)
    body.skin(out, marker_ids()).sum().backward()
    assert pose.grad is not None and pose.grad.abs().sum() > 0


def test_forward_kinematics_gradients_match_finite_differences(generator):
    """The planes-layout composition (in-place accumulated products, rows written through views) differentiates
    correctly: float64 gradients of joints and rotations against finite differences, for axis-angle, 6-D and
    matrix inputs."""
    body = BodyModel().double()
    transl, orient, pose = (0.5 * t.double() for t in _random_pose(generator, 1))
    sixd = torch.randn(1, 21, 6, generator=generator, dtype=torch.float64)
    matrices = rotation_matrix(sixd)

    def outputs(posed):
        return posed.joints, posed.rotations

    for arguments, call in (((transl, orient, pose), body), ((transl, orient, sixd), body),
                            ((transl, rotation_matrix(orient), matrices), body.from_matrices)):  # fmt: skip
        inputs = tuple(a.clone().requires_grad_(True) for a in arguments)
        assert torch.autograd.gradcheck(lambda *a: outputs(call(*a)), inputs, eps=1e-6, atol=1e-5)


def test_frozen_marker_table_matches_the_placement_rules():
    assert tuple(MARKER_VERTICES) == MARKER_NAMES and len(MARKER_NAMES) == 67
    assert place_all() == MARKER_VERTICES
    assert len(set(MARKER_VERTICES.values())) == 67


def test_markers_sit_where_their_names_say(body):
    zeros = torch.zeros(1, 3)
    markers = body.skin(body(zeros, zeros, torch.zeros(1, 21, 3)), marker_ids())[0]
    where = dict(zip(MARKER_NAMES, markers))
    for name, point in where.items():
        if name[0] == "L":
            assert point[0] < 0, name  # the body's left is -x
        if name[0] == "R":
            assert point[0] > 0, name
    for side in "LR":
        assert where[f"{side}HEE"][1] < where[f"{side}TOE"][1]  # heel behind toe
        assert where[f"{side}FHD"][1] > where[f"{side}BHD"][1]
        assert where[f"{side}FHD"][2] > where[f"{side}SHO"][2] > where[f"{side}KNE"][2] > where[f"{side}ANK"][2]
        assert abs(where[f"{side}KNE"][0]) > abs(where[f"{side}KNI"][0])  # lateral vs medial knee
    assert where["STRN"][1] > where["T8"][1]
    for name in FOOT_MARKERS:
        assert where[name][2] < -0.85


def test_foot_vertices_hold_the_lowest_point_of_the_feet(body, generator):
    transl, orient, pose = (0.3 * t.float() for t in _random_pose(generator, 200))  # near upright
    posed = body(transl, orient, pose)
    every = body.skin(posed, torch.arange(body.num_vertices))
    feet = body.skin(posed, foot_vertex_ids())
    dominant = body.skin_joints[torch.arange(body.num_vertices), body.skin_weights.argmax(1)]
    foot_part = torch.isin(dominant, torch.tensor([7, 8, 10, 11]))
    exact = every[:, foot_part, 2].min(dim=1).values
    assert (feet[..., 2].min(dim=1).values - exact).abs().max() < 0.01


def test_mirror_joints_swap_sides():
    for joint, mirror in enumerate(MIRROR_JOINTS):
        name = JOINT_NAMES[joint]
        expected = name.replace("left", "R").replace("right", "left").replace("R", "right")
        assert JOINT_NAMES[mirror] == expected


@pytest.mark.parametrize(
    ("transl", "orient", "pose", "message"),
    [
        ((2, 2), (2, 3), (2, 21, 3), "transl"),
        ((2, 3), (2, 4), (2, 21, 3), "global_orient"),
        ((2, 3), (2, 3), (2, 22, 3), "body_pose"),
        ((2, 3), (3, 3), (2, 21, 3), "global_orient"),
    ],
)
def test_wrong_shapes_raise_naming_the_argument(body, transl, orient, pose, message):
    with pytest.raises(ValueError, match=message):
        body(torch.zeros(transl), torch.zeros(orient), torch.zeros(pose))


def test_rodrigues_matches_roma_and_has_finite_gradients_at_zero(generator):
    from motion_envs.body.rotations import axis_angle_to_matrix

    rotvec = torch.cat([torch.randn(1000, 3, generator=generator), 1e-6 * torch.randn(10, 3, generator=generator)])
    assert torch.allclose(axis_angle_to_matrix(rotvec), roma.rotvec_to_rotmat(rotvec), atol=2e-6)
    zero = torch.zeros(4, 3, requires_grad=True)
    axis_angle_to_matrix(zero).sum().backward()
    assert torch.isfinite(zero.grad).all()


def test_batch_dimensions_are_kept(body):
    pose = body(torch.zeros(2, 5, 3), torch.zeros(2, 5, 3), torch.zeros(2, 5, 21, 3))
    assert pose.joints.shape == (2, 5, 22, 3) and pose.rotations.shape == (2, 5, 22, 3, 3)
    assert body.skin(pose, marker_ids()).shape == (2, 5, 67, 3)
    single = body(torch.zeros(3), torch.zeros(3), torch.zeros(21, 3))
    assert single.joints.shape == (22, 3)


def test_sixd_gram_schmidt_matches_roma_and_has_gradients(generator):
    from motion_envs.body.rotations import matrix_to_sixd, sixd_to_matrix

    rotations = roma.random_rotmat(1000, generator=generator)
    noisy = matrix_to_sixd(rotations) + 0.05 * torch.randn(1000, 6, generator=generator)  # not orthonormal
    expected = roma.special_gramschmidt(noisy.reshape(-1, 2, 3).transpose(-1, -2))
    ours = sixd_to_matrix(noisy.reshape(10, 100, 6))
    assert ours.shape == (10, 100, 3, 3) and torch.allclose(ours.reshape(-1, 3, 3), expected, atol=1e-6)
    assert torch.allclose(sixd_to_matrix(matrix_to_sixd(rotations)), rotations, atol=1e-6)
    sixd = noisy[:4].clone().requires_grad_(True)
    sixd_to_matrix(sixd).sum().backward()
    assert torch.isfinite(sixd.grad).all() and sixd.grad.abs().sum() > 0
