"""The README's pictures (`python -m benchmarks.readme_pictures`): a frame strip of each environment.

GammaReach-v0: one episode of the shipped α = 1 PPO policy (seed 3), four
frames of its ray-cast video side by side -> `docs/gamma_reach.png`.
WandrReach-v0: the shipped PPO policy reaching a goal 2 m ahead and to the
left at chest height (seed 0) -> `docs/wandr_reach.png`.
ClopsNav-v0: the shipped DQN policy with the goal memory (trained on
`open`) in a held-out open room, the egocentric view after each action
inset -> `docs/clops_nav.png`.
Scenes: the first held-out room of each layout family seen from above with a
body and its goal, and under it what the body's head camera sees (semantic
colours, depth, goal mask at 64 × 64, shown 2×) -> `docs/scenes.png`.
GammaWander-v0: `motion-envs populate`'s crowd, 16 bodies in `living:1003` with
the shipped GammaWander policy and tree search, after 2 s and after 12 s ->
`docs/crowd.png`.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np

import torch

from motion_envs.atomic import atomic_write
from motion_envs.body import JOINT_NAMES, BodyModel
from motion_envs.body.head_camera import head_camera
from motion_envs.play import play
from motion_envs.priors.training import WEIGHTS_DIR
from motion_envs.render.camera import Camera
from motion_envs.render.egocentric import EgocentricRenderer
from motion_envs.render.third_person import ThirdPersonRenderer
from motion_envs.scenes import FAMILIES, TEST_SEEDS, make_scene

DOCS = Path(__file__).resolve().parent.parent / "docs"
POLICY = WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip"
WANDR_POLICY = WEIGHTS_DIR / "ppo_wandrreach_alpha1_default.zip"
CLOPS_POLICY = WEIGHTS_DIR / "dqn_clopsnav_open_memory.zip"
WANDER_POLICY = WEIGHTS_DIR / "ppo_gammawander_alpha1_paper.zip"


def episode_strip(env_id: str, destination: Path, seed: int, crop: tuple[int, int] = (40, 40), **play_kwargs) -> Path:
    """Four frames of one played episode side by side, half size, `crop` rows cut from the top and bottom."""
    with tempfile.TemporaryDirectory() as folder:
        video = Path(folder) / "episode.mp4"
        (summary,) = play(env_id, video=video, seed=seed, **play_kwargs)
        frames = iio.imread(video)
    picks = np.linspace(0, len(frames) - 1, 4).round().astype(int)
    strip = np.concatenate([frames[i, crop[0] : len(frames[i]) - crop[1]] for i in picks], axis=1)[::2, ::2]
    print(f"{env_id}: {summary}")
    return atomic_write(destination, lambda file: iio.imwrite(file, strip, extension=".png"))


def gamma_reach_strip(destination: Path = DOCS / "gamma_reach.png", seed: int = 3) -> Path:
    return episode_strip("motion_envs/GammaReach-v0", destination, seed, policy=POLICY)


def wandr_reach_strip(destination: Path = DOCS / "wandr_reach.png", seed: int = 0) -> Path:
    return episode_strip("motion_envs/WandrReach-v0", destination, seed, policy=WANDR_POLICY, goal_angle=(0.6, 0.6),
                         goal_height=(1.2, 1.2), goal_distance=(2.0, 2.0))  # fmt: skip


def clops_nav_strip(destination: Path = DOCS / "clops_nav.png", seed: int = 3) -> Path:
    return episode_strip("motion_envs/ClopsNav-v0", destination, seed, crop=(0, 60), policy=CLOPS_POLICY, split="test",
                         goal_memory=True)  # fmt: skip


def scene_tile(family: str, body: BodyModel, seed: int = TEST_SEEDS[0]) -> np.ndarray:
    """(428, 400, 3) uint8: the room from above with a standing body turned to its goal, and under it the body's egocentric view: semantic colours, depth (near = bright),
    goal mask, 64 × 64 each shown 2×."""
    scene = make_scene(family, seed)
    start, goal_xy = scene.sample_start_goal(np.random.default_rng(seed), min_distance=2.5)
    heading = np.arctan2(*(goal_xy - start)[::-1]) - np.pi / 2  # the rest body faces +y
    standing = torch.zeros(1, 21, 3)
    standing[0, JOINT_NAMES.index("left_shoulder") - 1, 2] = -1.2  # arms down from the rest T-pose (local axes are mannequin-x's: z forward)
    standing[0, JOINT_NAMES.index("right_shoulder") - 1, 2] = 1.2
    pose = body(torch.tensor([[*start, 0.93]], dtype=torch.float32), torch.tensor([[0.0, 0.0, heading]], dtype=torch.float32), standing)
    goal = np.array([*goal_xy, 1.0])
    overview = ThirdPersonRenderer(body, width=400, height=300, scene=scene)
    vertices = body.skin_with_rows(pose, overview.rows).numpy()
    centre = scene.vertices.mean(axis=0) * np.array([1, 1, 0])
    extent = float(np.ptp(scene.vertices[:, :2], axis=0).max())
    camera = Camera(centre + np.array([0.0, -0.75 * extent, 0.95 * extent]), centre, 400, 300, fov=55.0)
    top = overview.render(vertices, camera, goal=goal, goal_radius=0.25, goal_shape="sphere")
    eye = head_camera(pose)
    view = EgocentricRenderer(scene).render(eye.eye, eye.rotation, torch.tensor(goal[None], dtype=torch.float32))[0]
    channels = [view[1:4], np.repeat(1.0 - view[:1] / 10.0, 3, axis=0), np.repeat(view[4:], 3, axis=0)]
    bottom = np.full((128, 400, 3), 255, np.uint8)
    for index, channel in enumerate(channels):
        bottom[:, 4 + index * 132 : 132 + index * 132] = np.kron((channel.transpose(1, 2, 0) * 255).astype(np.uint8), np.ones((2, 2, 1), np.uint8))
    return np.concatenate([top, bottom], axis=0)


def scenes_picture(destination: Path = DOCS / "scenes.png") -> Path:
    body = BodyModel()
    picture = np.concatenate([scene_tile(family, body) for family in FAMILIES], axis=1)
    return atomic_write(destination, lambda file: iio.imwrite(file, picture, extension=".png"))


def crowd_picture(destination: Path = DOCS / "crowd.png", seconds: float = 12.0) -> Path:
    from agents.controllers import PolicyLatent
    from motion_envs.populate import CrowdView, populate

    scene = make_scene("living", 1003)
    policy = WANDER_POLICY if WANDER_POLICY.exists() else POLICY
    result = populate(scene, PolicyLatent(policy, seed=0), bodies=16, seconds=seconds, seed=0, progress=False)
    view = CrowdView(scene)
    picture = np.concatenate([view.frame(result.rollout, index) for index in (2 * 32, result.rollout.frames - 1)], axis=1)
    return atomic_write(destination, lambda file: iio.imwrite(file, picture, extension=".png"))


if __name__ == "__main__":
    print(gamma_reach_strip())
    print(wandr_reach_strip())
    print(clops_nav_strip())
    print(scenes_picture())
    print(crowd_picture())
