"""Scenes: procedural rooms, user files, free space and collisions; egocentric and third-person ray casting."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from motion_envs.body.collision_spheres import collision_spheres
from motion_envs.render.camera import follow_camera
from motion_envs.render.egocentric import EgocentricRenderer
from motion_envs.render.third_person import ThirdPersonRenderer
from motion_envs.scenes import FAMILIES, LABELS, PALETTE, TEST_SEEDS, TRAIN_SEEDS, Scene, ScenePart, load_scene, make_scene


def test_a_seed_gives_the_same_room_and_another_seed_another():
    first, again, other = make_scene("living", 3), make_scene("living", 3), make_scene("living", 4)
    assert np.array_equal(first.vertices, again.vertices) and np.array_equal(first.face_labels, again.face_labels)
    assert first.vertices.shape != other.vertices.shape or not np.allclose(first.vertices, other.vertices)
    assert set(TRAIN_SEEDS).isdisjoint(TEST_SEEDS)


@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_family_has_walls_furniture_and_room_to_walk(family):
    scene = make_scene(family, TEST_SEEDS[0])
    names = {LABELS[label] for label in np.unique(scene.face_labels)}
    assert {"floor", "wall"} <= names and len(names - {"floor", "wall"}) >= 1
    walkable_area = scene.walkable.sum() * scene.grid.pitch**2
    assert 5.0 < walkable_area < 120.0
    start, goal = scene.sample_start_goal(np.random.default_rng(0), min_distance=2.0)
    assert np.linalg.norm(start - goal) >= 2.0
    points = torch.tensor([[*start, 1.0], [*goal, 1.0]], dtype=torch.float32)
    assert (scene.grid.query(points) >= 0.25 - scene.grid.pitch).all()  # clear of every solid


def _standing_body(body, xy: np.ndarray):
    pose = body(torch.tensor([[0.0, 0.0, 0.0]]), torch.zeros(1, 3), torch.zeros(1, 21, 3))
    lowest = body.skin(pose, torch.arange(body.num_vertices))[0, :, 2].min()
    transl = torch.tensor([[float(xy[0]), float(xy[1]), float(-lowest)]])
    return body(transl, torch.zeros(1, 3), torch.zeros(1, 21, 3))


def test_a_body_inside_furniture_collides_and_one_in_free_space_does_not(body):
    scene = make_scene("living", 0)
    furniture = next(p for p in scene.parts if LABELS[p.label] in ("cabinet", "shelf", "sofa"))
    inside = _standing_body(body, furniture.mesh.bounds.mean(axis=0)[:2])
    free = _standing_body(body, scene.sample_free(np.random.default_rng(1), 1)[0])
    for pose, collides in ((inside, True), (free, False)):
        centres, radii = collision_spheres(pose)
        assert centres.shape == (1, 63, 3) and radii.shape == (63,)
        assert bool((scene.collisions(centres, radii) > 0).any()) is collides


def test_user_scene_files_load_with_labels_from_node_names_or_face_properties(tmp_path):
    room = trimesh.Scene()
    room.add_geometry(trimesh.creation.box(extents=(4, 4, 0.02), transform=trimesh.transformations.translation_matrix((0, 0, -0.01))), node_name="floor")
    room.add_geometry(trimesh.creation.box(extents=(0.5, 0.5, 0.45)), node_name="chair_1", transform=trimesh.transformations.translation_matrix((1, 0, 0.225)))
    room.add_geometry(trimesh.creation.box(extents=(1.0, 0.6, 0.75)), node_name="Thing.001", transform=trimesh.transformations.translation_matrix((-1, 0, 0.375)))
    glb = tmp_path / "room.glb"
    room.export(glb)
    scene = load_scene(glb)
    assert sorted(LABELS[p.label] for p in scene.parts) == ["chair", "floor", "other"]
    assert scene.grid.occupied.any() and scene.walkable.any()
    from motion_envs.scenes.paths import plan_path

    around = plan_path(scene, np.array([-1.0, -1.5]), np.array([-1.0, 1.5]))  # the 1 x 0.6 m table between them
    assert around.length > 3.0 + 0.1 and np.all(np.abs(around.waypoints[:-1, 0] + 1.0) > 0.5 - 0.05)  # around it

    boxes = trimesh.creation.box(extents=(1, 1, 1))
    boxes.face_attributes["label"] = np.where(np.arange(12) < 6, LABELS.index("shelf"), LABELS.index("table")).astype(np.int32)
    ply = tmp_path / "labelled.ply"
    ply.write_bytes(trimesh.exchange.ply.export_ply(boxes, encoding="ascii"))
    assert sorted(LABELS[p.label] for p in load_scene(ply).parts) == ["shelf", "table"]

    broken = tmp_path / "broken.ply"
    broken.write_text("ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
    with pytest.raises(ValueError, match="broken.ply"):
        load_scene(broken)
    with pytest.raises(FileNotFoundError):
        load_scene(tmp_path / "missing.glb")


def _wall_scene(distance: float) -> Scene:
    """A 20 m wide wall whose near face is `distance` m in front of the origin (+y), and a floor."""
    wall = trimesh.creation.box(extents=(20, 0.2, 3), transform=trimesh.transformations.translation_matrix((0, distance + 0.1, 1.5)))
    floor = trimesh.Trimesh([[-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]], [[0, 1, 2], [0, 2, 3]])
    return Scene([ScenePart(wall, LABELS.index("wall")), ScenePart(floor, LABELS.index("floor"))])


def test_egocentric_depth_matches_a_wall_at_a_known_distance():
    renderer = EgocentricRenderer(_wall_scene(3.0), width=32, height=24, fov=60.0)
    eye = torch.tensor([[0.0, 0.0, 1.5]])
    view = renderer.render(eye, torch.eye(3)[None])  # right = x, gaze = y, up = z
    assert view.shape == (1, 5, 24, 32) and view.dtype == np.float32
    np.testing.assert_allclose(view[0, 0], 3.0, rtol=1e-4)  # planar depth is the same over the whole wall
    np.testing.assert_allclose(view[0, 1:4, 12, 16], PALETTE[LABELS.index("wall")] / 255.0, atol=1e-6)
    looking_down = torch.tensor([[[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]]).transpose(1, 2)  # gaze -z, up +y
    floor = renderer.render(eye, looking_down)
    np.testing.assert_allclose(floor[0, 0], 1.5, rtol=1e-4)
    np.testing.assert_allclose(floor[0, 1:4, 12, 16], PALETTE[LABELS.index("floor")] / 255.0, atol=1e-6)


def test_goal_mask_shows_the_goal_only_in_view_and_not_behind_a_wall():
    renderer = EgocentricRenderer(_wall_scene(3.0), width=32, height=32, fov=90.0)
    eye, forward = torch.tensor([[0.0, 0.0, 1.5]]), torch.eye(3)[None]
    in_view = renderer.render(eye, forward, goal=torch.tensor([[0.3, 2.0, 1.4]]), goal_radius=0.25)[0, 4]
    behind_body = renderer.render(eye, forward, goal=torch.tensor([[0.0, -2.0, 1.5]]), goal_radius=0.25)[0, 4]
    behind_wall = renderer.render(eye, forward, goal=torch.tensor([[0.0, 5.0, 1.5]]), goal_radius=0.25)[0, 4]
    assert in_view.sum() > 5 and set(np.unique(in_view)) == {0.0, 1.0}
    assert behind_body.sum() == 0 and behind_wall.sum() == 0
    assert renderer.render(eye, forward)[0, 4].sum() == 0  # no goal, no mask


def test_egocentric_batch_equals_each_body_alone():
    scene = make_scene("two_rooms", 5)
    renderer = EgocentricRenderer(scene, width=16, height=16)
    rng = np.random.default_rng(0)
    eye = torch.tensor(np.c_[scene.sample_free(rng, 5), np.full(5, 1.6)], dtype=torch.float32)
    yaw = torch.tensor(rng.uniform(0, 2 * np.pi, 5), dtype=torch.float32)
    rotation = torch.zeros(5, 3, 3)
    rotation[:, 0, 0], rotation[:, 1, 0], rotation[:, 0, 1], rotation[:, 1, 1], rotation[:, 2, 2] = yaw.cos(), yaw.sin(), -yaw.sin(), yaw.cos(), 1
    goal = eye + torch.tensor([0.0, 0.0, -0.5])
    together = renderer.render(eye, rotation, goal)
    for index in range(5):
        np.testing.assert_array_equal(together[index], renderer.render(eye[index : index + 1], rotation[index : index + 1], goal[index : index + 1])[0])
    with pytest.raises(ValueError, match="eye"):
        renderer.render(eye[:, :2], rotation)


def test_third_person_shows_the_scene_and_the_goal_sphere_deterministically(body):
    scene = make_scene("open", 1)
    xy = scene.sample_free(np.random.default_rng(2), 1)[0]
    pose = _standing_body(body, xy)
    renderer = ThirdPersonRenderer(body, width=160, height=120, scene=scene)
    vertices = renderer.body.skin_with_rows(pose, renderer.rows).numpy()
    camera = follow_camera(np.array([*xy, 0.9]), width=160, height=120)
    goal = np.array([*xy, 1.2]) + np.array([0.8, 0.0, 0.0])
    image = renderer.render(vertices, camera, goal=goal, goal_radius=0.15, goal_shape="sphere")
    assert np.array_equal(image, renderer.render(vertices, camera, goal=goal, goal_radius=0.15, goal_shape="sphere"))
    bare = ThirdPersonRenderer(body, width=160, height=120).render(vertices, camera, goal=goal, goal_radius=0.15, goal_shape="sphere")
    assert (np.abs(image.astype(int) - bare.astype(int)).sum(-1) > 30).sum() > 200  # walls and furniture drawn
    pixels = image.reshape(-1, 3).astype(int)
    assert ((pixels[:, 1] > pixels[:, 0] + 40) & (pixels[:, 1] > pixels[:, 2] + 40)).sum() > 10  # the green goal
    with pytest.raises(ValueError, match="goal_shape"):
        renderer.render(vertices, camera, goal=goal, goal_shape="cube")
