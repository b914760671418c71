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
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize  # noqa: E402

from agents.behaviour_cloning import clone_latents, posterior_latents  # noqa: E402
from agents.policy_files import TrainedFor  # noqa: E402
from agents.ppo_kl import PAPER_SETTINGS, PPOKL, PRIOR_MEANS  # noqa: E402
from agents.vec_env import NativeVecEnv  # noqa: E402
from motion_envs.atomic import atomic_write  # noqa: E402
from motion_envs.data.goal_windows import GoalWindows  # noqa: E402
from motion_envs.precision import cpu_description  # noqa: E402
from motion_envs.priors.training import announce_replacement, record_in_manifest, weights_destination  # noqa: E402


DEFAULT_REWARDS = {"motion_envs/GammaReach-v0": "paper", "motion_envs/GammaWander-v0": "paper", "motion_envs/WandrReach-v0": "default"}
"""Each latent-action env's default reward spec (`train ppo` without `--reward`)."""
ENGINES = ("sb3", "rllib")
RLLIB_ONLY_ENVS = ("motion_envs/ClopsNav-v0",)
"""Envs PPO trains only on RLlib (a categorical policy; SB3's path is PPOKL's Gaussian one): no reward spec."""


@dataclass
class PPOTrainConfig:
    env_id: str = "motion_envs/GammaReach-v0"
    reward: str | None = None
    """The env's reward spec (GammaReach: "paper", "release", "paper:goal=5"; WandrReach: "default"); None: the
    env's own default (`DEFAULT_REWARDS`)."""
    env_kwargs: dict = field(default_factory=dict)
    """Further `gym.make` arguments of the env (e.g. WandrReach's frames_per_step)."""
    alpha: float = 10.0
    num_envs: int = 256
    """Bodies per rollout: 256 × 60 primitives = 15,360 samples per update, the paper's 8 episodes × 32 clones × 60."""
    n_steps: int = 60
    """Primitives per body per rollout: one episode's worth."""
    batch_size: int = 1024
    n_epochs: int = 3
    learning_rate: float = 3e-5
    """Not the release's 3e-4: with 128 action dims and σ ≈ 0.37, one Adam step at 3e-4 moves the policy by an
    approximate KL of ~1 (measured: 0.96), so SB3's early stop ends every update after one minibatch and the
    cloned policy decayed to 1% success within 3 minutes; at 3e-5 the KL per update stays ~0.01-0.02."""
    total_timesteps: int = 500_000
    net_width: int = 256
    """Hidden width of the policy and value MLPs (two layers each); 256 keeps a saved policy under 10 MB."""
    log_std_init: float = -1.0
    """Initial log σ of the policy (SB3: 0). Data latents have an rms of ~0.35; σ = 1 drowns them."""
    init: str = "data"
    """"data": the actor starts from the data's latents (`agents.behaviour_cloning`); "scratch": random; or the
    path of a trained policy (.zip, same env and network) to fine-tune, e.g. with another reward."""
    clone_epochs: int = 40
    bootstrap_truncation: bool = False
    """SB3's γ·V(s) at time-limit ends; off: the paper's Monte-Carlo returns (see `NativeVecEnv`)."""
    anchor: float = 0.0
    """β of KL(π ‖ the cloned policy) added to the loss (`PPOKL.anchor_coef`); 0: the paper's loss."""
    kl_mean: str = "zero"
    """Centre of the α Ψ(KL) regulariser: "zero" (the paper's N(0, I)) or "cloned" (N(μ_cloned(s), I), ours;
    `PPOKL.prior_mean`)."""
    keep: str = "best"
    """"best": keep the checkpoint whose training window scored best (`window_score`: success, less the share of
    colliding primitives in envs that report collisions), a guard against late drift (before Monte-Carlo returns,
    runs went 0.23 -> 0.51 -> 0.09 over 230k steps); "last": the final one."""
    checkpoint_minutes: float = 3.0
    seed: int = 0
    device: str = "cpu"
    """Where the policy and the env's prior run ("cuda" on a GPU machine)."""
    run_dir: Path = Path("runs/ppo")
    weights: Path | None = None
    ship: bool = False
    """Write the policy into the package (priors/weights/ + manifest) instead of `run_dir` (`weights_destination`)."""
    command: str = ""
    engine: str = "sb3"
    """"sb3": Stable-Baselines3 in this process (`train_ppo`); "rllib": RLlib's PPO on Ray (`agents.train_rllib`),
    the same networks, loss and files."""
    env_runners: int = 0
    """rllib: Ray env-runner actors, each stepping num_envs / env_runners bodies in one native vector env; 0: the
    driver process samples."""
    address: str | None = None
    """rllib: a Ray cluster to join ("auto", "ray://host:10001", "host:6379"); None: a local Ray on this machine."""
    cpus_per_env_runner: int = 1
    """rllib: CPUs (and torch threads) each env runner takes."""

    def __post_init__(self) -> None:
        if self.engine not in ENGINES:
            raise ValueError(f"engine must be one of {ENGINES}, got {self.engine!r}")
        if self.reward is None and self.env_id in DEFAULT_REWARDS:
            self.reward = DEFAULT_REWARDS[self.env_id]
        elif self.reward is None and not (self.engine == "rllib" and self.env_id in RLLIB_ONLY_ENVS):
            raise ValueError(f"PPO trains {sorted(DEFAULT_REWARDS)}"
                             f"{' (and, with engine rllib, ' + ', '.join(RLLIB_ONLY_ENVS) + ')' if self.engine == 'sb3' else ''}"
                             f", not {self.env_id!r}")  # fmt: skip
        if self.engine == "rllib" and self.anchor > 0:
            raise ValueError("anchor > 0 is SB3-only (engine sb3); RLlib's PPO here has the paper's loss")
        if self.env_runners < 0 or self.env_runners > self.num_envs:
            raise ValueError(f"env_runners must be in 0..num_envs ({self.num_envs}), got {self.env_runners}")
        if self.env_runners and self.num_envs % self.env_runners:
            raise ValueError(f"num_envs ({self.num_envs}) must split evenly over env_runners ({self.env_runners})")
        if self.init not in ("data", "scratch") and not Path(self.init).is_file():
            raise ValueError(f"init must be 'data', 'scratch' or a policy file, got {self.init!r} (no such file)")
        if self.keep not in ("best", "last"):
            raise ValueError(f"keep must be 'best' or 'last', got {self.keep!r}")
        if self.anchor > 0 and self.init != "data":
            raise ValueError("anchor > 0 holds the policy near its cloned start: it needs init='data'")
        if self.kl_mean not in PRIOR_MEANS:
            raise ValueError(f"kl_mean must be one of {PRIOR_MEANS}, got {self.kl_mean!r}")
        if self.kl_mean == "cloned" and (self.init == "scratch" or self.engine != "sb3"):
            raise ValueError("kl_mean='cloned' centres the regulariser on the cloned policy: it needs engine sb3 and "
                             "init='data' or a policy file trained with it (which holds its anchor)")

    def checkpoint_path(self) -> Path:
        """What a resumed run continues from: SB3's model.zip, or RLlib's checkpoint folder."""
        return self.run_dir / ("rllib" if self.engine == "rllib" else "model.zip")

    def weights_path(self) -> Path:
        name = self.env_id.split("/")[-1].split("-")[0].lower()
        if self.reward is None:
            return weights_destination(f"ppo_{name}_{self.engine}.zip", self.run_dir, self.weights, self.ship)
        reward = self.reward.replace(":", "-").replace("=", "").replace(",", "-")  # "paper:goal=5" -> "paper-goal5"
        cloned = "_cloned" if self.kl_mean == "cloned" else ""
        return weights_destination(f"ppo_{name}_alpha{self.alpha:g}_{reward}{cloned}.zip", self.run_dir, self.weights,
                                   self.ship)  # fmt: skip


def window_score(point: dict) -> float:
    """How a training window ranks for `keep="best"`: its success rate, less its share of colliding primitives where
    the env reports collisions (GammaWander: a window that succeeds as often but walks through more furniture is
    worse; its targets are success >= 0.9 with <= 5% colliding primitives)."""
    return point["success_rate"] - point.get("collided_share", 0.0)


class CurveCallback(BaseCallback):
    """Every few minutes: save the model atomically and record the recent success rate (and, where episodes end with
    a `collisions` count, the share of their primitives that collided)."""

    def __init__(self, run_dir: Path, minutes: float, curve: list[dict]) -> None:
        super().__init__()
        self.run_dir, self.seconds, self.curve = run_dir, 60.0 * minutes, curve
        self.successes: list[float] = []
        self.collided: list[tuple[int, int]] = []
        """(colliding primitives, primitives) of each episode that reported collisions."""
        self.last = time.monotonic()
        self.wall = curve[-1]["wall_seconds"] if curve else 0.0

    def _on_step(self) -> bool:
        for info, done in zip(self.locals["infos"], self.locals["dones"]):
            if done and "is_success" in info:
                self.successes.append(float(info["is_success"]))
            if done and "collisions" in info and "episode" in info:
                self.collided.append((int(info["collisions"]), int(info["episode"]["l"])))
        if time.monotonic() - self.last > self.seconds:
            self.save()
        return True

    def save(self) -> None:
        now = time.monotonic()
        self.wall += now - self.last
        self.last = now
        if self.successes:
            best = max((window_score(point) for point in self.curve), default=-np.inf)
            self.curve.append({"timesteps": int(self.num_timesteps), "wall_seconds": round(self.wall, 1),
                               "success_rate": float(np.mean(self.successes)), "episodes": len(self.successes)})  # fmt: skip
            if self.collided:
                collisions, primitives = np.sum(self.collided, axis=0)
                self.curve[-1]["collided_share"] = float(collisions / max(primitives, 1))
                self.logger.record("rollout/collided_share_window", self.curve[-1]["collided_share"])
            self.logger.record("rollout/success_rate_window", self.curve[-1]["success_rate"])
            self.successes, self.collided = [], []
            if window_score(self.curve[-1]) > best:
                atomic_write(self.run_dir / "best.zip", self.model.save)
        atomic_write(self.run_dir / "model.zip", self.model.save)
        normaliser = self.model.get_vec_normalize_env()
        if normaliser is not None:
            atomic_write(self.run_dir / "vecnormalize.pkl", lambda file: pickle.dump(normaliser, file))
        text = json.dumps(self.curve, indent=1)
        atomic_write(self.run_dir / "curve.json", lambda file: file.write(text.encode()))


def train_ppo(config: PPOTrainConfig, clone_from: GoalWindows | None = None) -> dict:
    """Train (or resume) a policy; a new one with `init="data"` first clones `clone_from`'s latents."""
    if config.engine == "rllib":
        from agents.train_rllib import train_rllib

        return train_rllib(config, clone_from)
    if config.init == "data" and clone_from is None and not (config.run_dir / "model.zip").exists():
        raise ValueError("init='data' needs goal windows from the data (clone_from); pass init='scratch' to skip")
    config.run_dir.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(config.seed)
    venv = VecMonitor(NativeVecEnv.make(config.env_id, num_envs=config.num_envs, reward=config.reward, device=config.device,
                                        bootstrap_truncation=config.bootstrap_truncation, **config.env_kwargs))  # fmt: skip
    venv.seed(config.seed)
    statistics = config.run_dir / "vecnormalize.pkl"
    if statistics.exists():
        venv = VecNormalize.load(str(statistics), venv)
    else:
        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=PAPER_SETTINGS["gamma"])
    checkpoint = config.run_dir / "model.zip"
    cloning_path = config.run_dir / "cloning.json"
    curve_path = config.run_dir / "curve.json"
    curve = json.loads(curve_path.read_text()) if curve_path.exists() else []
    if checkpoint.exists():
        model = PPOKL.load(checkpoint, env=venv, device=config.device)
        print(f"resuming {checkpoint} at {model.num_timesteps} steps", file=sys.stderr)
    elif config.init not in ("data", "scratch"):
        model = PPOKL.load(config.init, env=venv, device=config.device, tensorboard_log=str(config.run_dir / "tensorboard"),
                           learning_rate=config.learning_rate, kl_prior_coef=config.alpha, n_steps=config.n_steps,
                           batch_size=config.batch_size, n_epochs=config.n_epochs)  # this run's settings; fmt: skip
        model.num_timesteps = 0  # this run's steps, from the loaded policy
        if model.prior_mean != config.kl_mean:
            raise ValueError(f"{config.init} was trained with kl_mean={model.prior_mean!r}, this run asks for "
                             f"{config.kl_mean!r}: the regulariser's centre (and its anchor) comes with the policy")
        warm_reward_normaliser(model, venv, config.n_steps)
    else:
        model = new_model(config, venv)
        if config.init == "data":
            clone_into(model, clone_from, config)
    callback = CurveCallback(config.run_dir, config.checkpoint_minutes, curve)
    remaining = config.total_timesteps - model.num_timesteps
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=callback, reset_num_timesteps=False, progress_bar=True)
        callback.save()
    extra = {"cloning": json.loads(cloning_path.read_text())} if cloning_path.exists() else {}
    return ship_policy(model, config, curve, "ppo_policy", best=config.keep == "best", **extra)


def warm_reward_normaliser(model: PPOKL, venv: VecNormalize, steps: int) -> None:
    """Run the loaded policy for `steps` steps of every body so that `venv`'s return statistics match its returns.

    A fine-tune (`init` a policy file) loads a critic fitted to returns scaled by its own run's statistics, which
    the shipped zip does not carry; a fresh `VecNormalize` starts from unit variance and few samples, so the first
    updates scale rewards wrongly and the advantages are noise. One rollout of the policy's own actions (no
    learning) puts the scale where the critic was trained."""
    observation = venv.reset()
    for _ in range(steps):
        actions, _ = model.predict(observation, deterministic=False)
        observation, _, _, _ = venv.step(actions)
    print(f"warmed the reward normaliser over {steps} steps x {venv.num_envs} bodies: return std "
          f"{float(np.sqrt(venv.ret_rms.var)):.3g}", file=sys.stderr)


def new_model(config: PPOTrainConfig, venv: Any) -> PPOKL:
    """A new PPOKL model with the run's settings (two hidden layers of `net_width` for actor and critic)."""
    width = config.net_width
    return PPOKL("MlpPolicy", venv, kl_prior_coef=config.alpha, anchor_coef=config.anchor, prior_mean=config.kl_mean,
                 n_steps=config.n_steps,
                 batch_size=config.batch_size, n_epochs=config.n_epochs, learning_rate=config.learning_rate,
                 seed=config.seed, device=config.device, tensorboard_log=str(config.run_dir / "tensorboard"),
                 policy_kwargs={"net_arch": {"pi": [width, width], "vf": [width, width]},
                                "log_std_init": config.log_std_init})  # fmt: skip


def clone_into(model: PPOKL, clone_from: GoalWindows, config: PPOTrainConfig) -> dict[str, float]:
    """Fit the model's actor to the 2-frame predictor's posterior latents of `clone_from` (`agents.behaviour_cloning`),
    set the anchor where the run has one, and record the fit in `run_dir/cloning.json`."""
    generator = model.get_env().get_attr("core")[0].generator
    latents = posterior_latents(generator.predictor_2f, clone_from)
    cloning = clone_latents(model.policy, clone_from.observation, latents, epochs=config.clone_epochs, seed=config.seed)
    print("cloned data latents: " + ", ".join(f"{k} {v:.4f}" for k, v in cloning.items()), file=sys.stderr)
    if config.anchor > 0 or config.kl_mean == "cloned":
        model.policy.set_anchor()
    atomic_write(config.run_dir / "cloning.json", lambda file: file.write(json.dumps(cloning).encode()))
    return cloning


def ship_policy(model: Any, config: Any, curve: list[dict], kind: str, best: bool = True,
                steps_label: str = "env steps (primitives)", **extra: Any) -> dict:  # fmt: skip
    """Write the run's best-window checkpoint (or the last model) to `config.weights_path()` without its optimiser
    state, record a manifest entry (kind, config, steps, curve, torch, machine, `extra`) and plot the curve; returns
    the entry."""
    weights = config.weights_path()
    top = max(curve, key=window_score) if curve else None
    shipped_best = best and top is not None and (config.run_dir / "best.zip").exists()
    chosen = type(model).load(config.run_dir / "best.zip", device="cpu") if shipped_best else model
    optimiser = chosen.policy.optimizer  # shipped without Adam's moments: half the size (runs/ keeps them to resume)
    parameters = [parameter for group in optimiser.param_groups for parameter in group["params"]]
    chosen.policy.optimizer = type(optimiser)(parameters, **optimiser.defaults)
    chosen.trained_for = asdict(TrainedFor.of_config(config))  # saved with the model's data (`agents.policy_files`)
    announce_replacement(weights)
    atomic_write(weights, chosen.save)
    entry = {"kind": kind, "config": {k: str(v) if isinstance(v, Path) else v for k, v in asdict(config).items()},
             "timesteps": int(model.num_timesteps), "curve": curve, "torch": str(torch.__version__),
             "machine": cpu_description(),
             "shipped": f"best window: {top['timesteps']} steps" if shipped_best else "last", **extra}  # fmt: skip
    record_in_manifest(weights, entry)
    plot_curve(curve, config.run_dir / "curve.png", steps_label)
    return entry


def plot_curve(curve: list[dict], destination: Path, steps_label: str = "env steps (primitives)") -> None:
    """Success rate against env steps and against wall time."""
    if not curve:
        return
    figure, (by_steps, by_time) = plt.subplots(1, 2, figsize=(9, 3.5))
    rates = [point["success_rate"] for point in curve]
    by_steps.plot([point["timesteps"] for point in curve], rates)
    by_steps.set(xlabel=steps_label, ylabel="success rate", ylim=(0, 1))
    by_time.plot([point["wall_seconds"] / 60 for point in curve], rates)
    by_time.set(xlabel="wall time (min)", ylim=(0, 1))
    figure.tight_layout()
    atomic_write(destination, lambda file: figure.savefig(file, format="png", dpi=100))
