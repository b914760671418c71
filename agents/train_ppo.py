"""`motion-envs train ppo`: PPOKL on a native batched env, resumable, with a learning curve.

Reads top to bottom: vector env (one process, `num_envs` bodies) -> VecMonitor
-> VecNormalize (rewards only: returns reach ~300 with the goal-absorbing
reward, and SB3 clips the gradient norm of policy and value losses together,
so unscaled returns starve the policy; observations stay raw, so a saved
policy needs no statistics) -> PPOKL (new, or the run's latest checkpoint) -> learn with a callback that
every `checkpoint_minutes` saves the model atomically and appends the
success rate of the episodes finished since the last save -> final policy
under `priors/weights/` + manifest entry + learning-curve plot (success
rate against env steps and against wall time).
"""

from __future__ import annotations

import json
import pickle
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize  # noqa: E402

from agents.ppo_kl import PAPER_SETTINGS, PPOKL  # noqa: E402
from agents.vec_env import NativeVecEnv  # noqa: E402
from motion_envs.atomic import atomic_write  # noqa: E402
from motion_envs.priors.training import WEIGHTS_DIR, record_in_manifest  # noqa: E402


@dataclass
class PPOTrainConfig:
    env_id: str = "motion_envs/GammaReach-v0"
    reward: str = "paper"
    alpha: float = 10.0
    num_envs: int = 64
    n_steps: int = 32
    batch_size: int = 1024
    n_epochs: int = 3
    learning_rate: float = 3e-4
    total_timesteps: int = 500_000
    net_width: int = 256
    """Hidden width of the policy and value MLPs (two layers each); 256 keeps a saved policy under 10 MB."""
    checkpoint_minutes: float = 3.0
    seed: int = 0
    run_dir: Path = Path("runs/ppo")
    weights: Path | None = None
    command: str = ""

    def weights_path(self) -> Path:
        name = self.env_id.split("/")[-1].split("-")[0].lower()
        return self.weights or WEIGHTS_DIR / f"ppo_{name}_alpha{self.alpha:g}_{self.reward}.zip"


class CurveCallback(BaseCallback):
    """Every few minutes: save the model atomically and record the recent success rate."""

    def __init__(self, run_dir: Path, minutes: float, curve: list[dict]) -> None:
        super().__init__()
        self.run_dir, self.seconds, self.curve = run_dir, 60.0 * minutes, curve
        self.successes: list[float] = []
        self.last = time.monotonic()
        self.wall = curve[-1]["wall_seconds"] if curve else 0.0

    def _on_step(self) -> bool:
        for info, done in zip(self.locals["infos"], self.locals["dones"]):
            if done and "is_success" in info:
                self.successes.append(float(info["is_success"]))
        if time.monotonic() - self.last > self.seconds:
            self.save()
        return True

    def save(self) -> None:
        now = time.monotonic()
        self.wall += now - self.last
        self.last = now
        if self.successes:
            self.curve.append({"timesteps": int(self.num_timesteps), "wall_seconds": round(self.wall, 1),
                               "success_rate": float(np.mean(self.successes)), "episodes": len(self.successes)})  # fmt: skip
            self.logger.record("rollout/success_rate_window", self.curve[-1]["success_rate"])
            self.successes = []
        atomic_write(self.run_dir / "model.zip", self.model.save)
        atomic_write(self.run_dir / "vecnormalize.pkl", lambda file: pickle.dump(self.model.get_vec_normalize_env(), file))
        text = json.dumps(self.curve, indent=1)
        atomic_write(self.run_dir / "curve.json", lambda file: file.write(text.encode()))


def train_ppo(config: PPOTrainConfig) -> dict:
    config.run_dir.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(config.seed)
    venv = VecMonitor(NativeVecEnv.make(config.env_id, num_envs=config.num_envs, reward=config.reward))
    venv.seed(config.seed)
    statistics = config.run_dir / "vecnormalize.pkl"
    if statistics.exists():
        venv = VecNormalize.load(str(statistics), venv)
    else:
        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=PAPER_SETTINGS["gamma"])
    checkpoint = config.run_dir / "model.zip"
    curve_path = config.run_dir / "curve.json"
    curve = json.loads(curve_path.read_text()) if curve_path.exists() else []
    if checkpoint.exists():
        model = PPOKL.load(checkpoint, env=venv, device="cpu")
        print(f"resuming {checkpoint} at {model.num_timesteps} steps", file=sys.stderr)
    else:
        width = config.net_width
        model = PPOKL("MlpPolicy", venv, kl_prior_coef=config.alpha, n_steps=config.n_steps, batch_size=config.batch_size,
                      n_epochs=config.n_epochs, learning_rate=config.learning_rate, seed=config.seed, device="cpu",
                      tensorboard_log=str(config.run_dir / "tensorboard"),
                      policy_kwargs={"net_arch": {"pi": [width, width], "vf": [width, width]}})  # fmt: skip
    callback = CurveCallback(config.run_dir, config.checkpoint_minutes, curve)
    remaining = config.total_timesteps - model.num_timesteps
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=callback, reset_num_timesteps=False, progress_bar=True)
    callback.save()
    weights = config.weights_path()
    atomic_write(weights, model.save)
    entry = {"kind": "ppo_policy", "config": {k: str(v) if isinstance(v, Path) else v for k, v in asdict(config).items()},
             "timesteps": int(model.num_timesteps), "curve": curve, "torch": str(torch.__version__)}  # fmt: skip
    record_in_manifest(weights, entry)
    plot_curve(curve, config.run_dir / "curve.png")
    return entry


def plot_curve(curve: list[dict], destination: Path) -> None:
    """Success rate against env steps and against wall time."""
    if not curve:
        return
    figure, (by_steps, by_time) = plt.subplots(1, 2, figsize=(9, 3.5))
    rates = [point["success_rate"] for point in curve]
    by_steps.plot([point["timesteps"] for point in curve], rates)
    by_steps.set(xlabel="env steps (primitives)", ylabel="success rate", ylim=(0, 1))
    by_time.plot([point["wall_seconds"] / 60 for point in curve], rates)
    by_time.set(xlabel="wall time (min)", ylim=(0, 1))
    figure.tight_layout()
    atomic_write(destination, lambda file: figure.savefig(file, format="png", dpi=100))
