"""The README's pictures (`python -m benchmarks.readme_pictures`): a frame strip of each environment.

GammaReach-v0: one episode of the shipped α = 1 PPO policy (seed 3), four
frames of its ray-cast video side by side -> `docs/gamma_reach.png`.
WandrReach-v0: the shipped PPO policy reaching a goal 2 m ahead and to the
left at chest height (seed 0) -> `docs/wandr_reach.png`.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from motion_envs.atomic import atomic_write
from motion_envs.play import play
from motion_envs.priors.training import WEIGHTS_DIR

DOCS = Path(__file__).resolve().parent.parent / "docs"
POLICY = WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip"
WANDR_POLICY = WEIGHTS_DIR / "ppo_wandrreach_alpha1_default.zip"


def episode_strip(env_id: str, destination: Path, seed: int, **play_kwargs) -> Path:
    """Four frames of one played episode side by side, half size."""
    with tempfile.TemporaryDirectory() as folder:
        video = Path(folder) / "episode.mp4"
        (summary,) = play(env_id, video=video, seed=seed, **play_kwargs)
        frames = iio.imread(video)
    picks = np.linspace(0, len(frames) - 1, 4).round().astype(int)
    strip = np.concatenate([frames[i, 40:-40] for i in picks], axis=1)[::2, ::2]
    print(f"{env_id}: {summary}")
    return atomic_write(destination, lambda file: iio.imwrite(file, strip, extension=".png"))


def gamma_reach_strip(destination: Path = DOCS / "gamma_reach.png", seed: int = 3) -> Path:
    return episode_strip("motion_envs/GammaReach-v0", destination, seed, policy=POLICY)


def wandr_reach_strip(destination: Path = DOCS / "wandr_reach.png", seed: int = 0) -> Path:
    return episode_strip("motion_envs/WandrReach-v0", destination, seed, policy=WANDR_POLICY, goal_angle=(0.6, 0.6),
                         goal_height=(1.2, 1.2), goal_distance=(2.0, 2.0))  # fmt: skip


if __name__ == "__main__":
    print(gamma_reach_strip())
    print(wandr_reach_strip())
