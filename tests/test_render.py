"""Ray-cast third-person rendering: real embree images of real bodies, and videos of an env."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from motion_envs.render.camera import Camera, follow_camera
from motion_envs.render.third_person import ThirdPersonRenderer, body_mesh, facing


def test_lower_detail_mesh_keeps_a_subset_of_the_vertices():
    mesh = body_mesh(0.015)
    assert 5_000 < len(mesh.vertex_ids) < 24_256 and mesh.faces.max() == len(mesh.vertex_ids) - 1
    assert len(np.unique(mesh.vertex_ids)) == len(mesh.vertex_ids)


def test_camera_projects_its_own_rays_back_to_their_pixels():
    camera = Camera(np.array([-3.0, -4.0, 2.0]), np.array([0.0, 0.0, 0.9]), width=64, height=48)
    directions = camera.ray_directions()
    points = camera.eye + 2.5 * directions[[0, 10, 47], [0, 33, 63]]
    pixels, in_front = camera.project(points)
    assert in_front.all() and np.allclose(pixels, [[0, 0], [10, 33], [47, 63]], atol=1e-4)  # float32 rays


def test_render_shows_the_body_the_goal_and_the_trail(body):
    renderer = ThirdPersonRenderer(body, width=160, height=120)
    vertices = renderer.vertices(torch.tensor([[0.0, 0.0, 0.93]]), torch.zeros(1, 3), torch.zeros(1, 21, 3))
    camera = follow_camera(np.array([0.0, 0.0, 0.9]), width=160, height=120)
    image = renderer.render(vertices, camera, goal=np.array([1.5, 1.0, 0.0]), trail=np.array([[0, -2, 0.9], [0, 0, 0.9]]))
    assert image.shape == (120, 160, 3) and image.dtype == np.uint8
    pixels = image.reshape(-1, 3).astype(int)
    wood = (pixels[:, 0] > pixels[:, 2] + 40) & (pixels[:, 1] > pixels[:, 2] + 10)
    green = (pixels[:, 1] > pixels[:, 0] + 40) & (pixels[:, 1] > pixels[:, 2] + 40)
    assert 100 < wood.sum() < 0.5 * len(pixels)  # the body is there and is not everything
    assert green.sum() > 10
    empty = renderer.render(vertices + np.array([0.0, 0.0, 50.0]), camera)  # body far above the view
    assert not ((empty.reshape(-1, 3)[:, 0].astype(int) > empty.reshape(-1, 3)[:, 2].astype(int) + 40).sum() > 100)


# moviepy (RecordVideo's writer) rounds the clip's duration and can drop the last frame for some counts
# (7 frames at 30 fps come back as 6), so the step counts here are ones it keeps whole.
@pytest.mark.parametrize(("env_id", "steps"), [("motion_envs/GammaReach-v0", 3), ("motion_envs/WandrReach-v0", 7)])
def test_env_renders_and_records_a_video_of_every_step(tmp_path, env_id, steps):
    import gymnasium as gym
    import imageio.v3 as iio
    from gymnasium.wrappers import RecordVideo

    import motion_envs  # noqa: F401

    env = gym.make(env_id, render_mode="rgb_array")
    env = RecordVideo(env, str(tmp_path), episode_trigger=lambda episode: True, disable_logger=True)
    env.reset(seed=0)
    for _ in range(steps):
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    env.close()
    (video,) = tmp_path.glob("*.mp4")
    frames = iio.imread(video)
    assert frames.shape == (steps + 1, 360, 480, 3)  # the reset frame and one per step, read back from the file
    assert frames[0].std() > 10  # not a blank frame
    with pytest.raises(ValueError, match="render_mode"):
        gym.make(env_id, render_mode="depth")


def test_vector_env_draws_several_bodies_in_one_image():
    import gymnasium as gym

    import motion_envs  # noqa: F401

    def wood_pixels(render_bodies: int) -> int:
        env = gym.make_vec("motion_envs/WandrReach-v0", num_envs=4, vectorization_mode="vector_entry_point",
                           render_mode="rgb_array", render_bodies=render_bodies)  # fmt: skip
        env.reset(seed=[0, 7, 13, 21])
        env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        pixels = env.render().reshape(-1, 3).astype(int)
        return int(((pixels[:, 0] > pixels[:, 2] + 40) & (pixels[:, 1] > pixels[:, 2] + 10)).sum())

    one, four = wood_pixels(1), wood_pixels(4)
    assert one > 100 and four > 1.5 * one  # the start poses overlap a little, never completely


def test_play_writes_a_video_of_every_kept_frame_and_summarises(tmp_path):
    import imageio.v3 as iio

    from motion_envs.play import play

    video = tmp_path / "episode.mp4"
    (summary,) = play("motion_envs/GammaReach-v0", baseline="random", video=video, every=4, max_primitives=3)
    assert summary["steps"] == 3 and summary["success"] is False and 0.0 <= summary["foot_skating"] <= 1.0
    frames = iio.imread(video)
    assert frames.shape[1:] == (360, 480, 3) and len(frames) == 3 + 2 + 2  # 9, 8, 8 new frames, every 4th
    with pytest.raises(ValueError, match="unknown baseline"):
        play("motion_envs/GammaReach-v0", baseline="dance")
    from motion_envs.priors.training import WEIGHTS_DIR
    from motion_envs.rollout import Rollout

    (wander,) = play("motion_envs/GammaWander-v0", WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip", video=video, every=4,
                     save_rollout=tmp_path / "wander.npz", max_primitives=3, scene="living")  # a GammaReach policy drives it
    assert wander["steps"] == 3 and "collisions" in wander and len(iio.imread(video)) == 7
    assert Rollout.load(tmp_path / "wander.npz").scene.startswith("living:")


def test_only_faces_towards_the_eye_go_to_embree_and_a_closed_mesh_casts_the_same():
    """`facing` keeps the front faces: rays from outside a closed mesh (an icosphere) hit the same points through
    the kept half as through the whole mesh; seen from the other side the other half is kept."""
    import trimesh

    from motion_envs.render.raycast import RayCaster

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    vertices, faces = sphere.vertices.astype(np.float32), sphere.faces
    eye = np.array([3.0, 0.4, 0.2], dtype=np.float32)
    kept = facing(vertices, faces, eye)
    assert 0.3 < kept.mean() < 0.5  # a little under half: the eye is 3 m away, not at infinity
    assert not (kept & facing(vertices, faces, -eye)).any()
    targets = vertices[np.random.default_rng(0).choice(len(vertices), 200)] * 0.9  # rays through the sphere
    rays = (targets - eye) / np.linalg.norm(targets - eye, axis=1, keepdims=True)
    origins = np.broadcast_to(eye, rays.shape)
    _, whole = RayCaster(vertices, faces).cast(origins, rays)
    _, front = RayCaster(vertices, faces[kept]).cast(origins, rays)
    assert np.isfinite(whole).all() and np.allclose(whole, front, atol=1e-5)


def test_scene_faces_are_lit_on_the_side_each_ray_sees():
    """The cut-away room lights each face from the side of its plane the eye is on (one test per face and frame);
    every hit ray must agree: it sees a face's back exactly where it travels along the face's normal."""
    from motion_envs.render.camera import follow_camera
    from motion_envs.render.third_person import _CutawayScene
    from motion_envs.scenes import make_scene

    scene = _CutawayScene(make_scene("living", 0), 1.2)
    centre = scene.bounds.mean(axis=0)
    for azimuth in (-2.2, 0.3, 1.9):  # eyes outside and above the room, looking in from three sides
        camera = follow_camera(centre, azimuth=azimuth)
        rays = camera.ray_directions().reshape(-1, 3)
        triangle, _ = scene.caster.cast(np.broadcast_to(camera.eye, rays.shape), rays)
        hit = triangle >= 0
        assert hit.mean() > 0.2
        per_face = scene.normals @ camera.eye < scene.offsets
        per_ray = np.einsum("rk,rk->r", scene.normals[triangle[hit]], rays[hit]) > 0
        assert per_face.any() and not per_face.all()  # the eye is behind some faces' planes, in front of others
        assert (per_face[triangle[hit]] == per_ray).mean() > 0.999  # grazing rays may round either way
