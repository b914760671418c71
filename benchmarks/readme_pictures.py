"""The README's pictures (`python -m benchmarks.readme_pictures`): a frame strip of each environment.

GammaReach-v0: one episode of the shipped α = 1 PPO policy (seed 3), four
frames of its ray-cast video side by side -> `docs/gamma_reach.png`.
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


def gamma_reach_strip(destination: Path = DOCS / "gamma_reach.png", seed: int = 3) -> Path:
    with tempfile.TemporaryDirectory() as folder:
        video = Path(folder) / "episode.mp4"
        (summary,) = play("motion_envs/GammaReach-v0", policy=POLICY, video=video, seed=seed)
        frames = iio.imread(video)
    picks = np.linspace(0, len(frames) - 1, 4).round().astype(int)
    strip = np.concatenate([frames[i, 40:-40] for i in picks], axis=1)[::2, ::2]  # half size
    print(f"GammaReach-v0, {POLICY.name}: {summary}")
    return atomic_write(destination, lambda file: iio.imwrite(file, strip, extension=".png"))


if __name__ == "__main__":
    print(gamma_reach_strip())
