"""`motion-envs train dqn`: CLOPS's double DQN with prioritised replay on ClopsNav-v0, resumable, with a learning curve.

Reads top to bottom: the native vector env (`num_envs` bodies, each in a
room of `family`) -> VecMonitor -> `PrioritizedDoubleDQN` with SB3's
`CnnPolicy` (NatureCNN on the 5 × 64 × 64 view; `MultiInputPolicy` with the
known goal or the goal memory) -> learn with `CurveCallback` (every `checkpoint_minutes`: the
model saved atomically, the success rate of the episodes finished since) ->
the best window's policy under `priors/weights/` + manifest entry + the
learning-curve plot.

Resuming reloads the model, not the replay buffer (50k views are 2 GB): the
buffer refills for `learning_starts` steps before updates go on. A fine-tune
(`init`: a policy file) starts from that policy's Q-network the same way, its
exploration from `init_exploration` instead of 1.0, since the policy already acts.

The paper's hyperparameter table lost its numbers (REFERENCE_NOTES §5);
ours are sized for two CPU cores (documented on each field).
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import torch
from stable_baselines3.common.vec_env import VecMonitor

from agents.double_dqn import PrioritizedDoubleDQN
from agents.train_ppo import CurveCallback, ship_policy
from agents.vec_env import NativeVecEnv
from motion_envs.priors.training import weights_destination


OBSERVATION_OPTIONS = {"": {}, "_known_goal": {"known_goal": True}, "_memory": {"goal_memory": True}}
"""Policy-file suffix -> the ClopsNav observation options its policy was trained with."""


@dataclass
class DQNTrainConfig:
    env_id: str = "motion_envs/ClopsNav-v0"
    family: str = "open"
    """The layout family trained on (the paper trains one policy per Replica scene)."""
    known_goal: bool = False
    goal_memory: bool = False
    """Observe the env's memory of what the view has shown (`ClopsNavConfig.goal_memory`; ours)."""
    env_kwargs: dict = field(default_factory=dict)
    num_envs: int = 32
    total_timesteps: int = 150_000
    """Actions (transitions); ~1 s of motion each."""
    buffer_size: int = 50_000
    learning_starts: int = 2_000
    batch_size: int = 64
    learning_rate: float = 2.5e-4
    gamma: float = 0.97
    """Episodes are ~15 actions: a horizon of ~30 actions is plenty."""
    gradient_steps: int = 4
    """Per vector step of `num_envs` transitions: 4 × 64 samples per 32 transitions, each replayed ~8 times."""
    target_update_interval: int = 2_000
    exploration_fraction: float = 0.3
    exploration_final_eps: float = 0.05
    alpha: float = 0.6
    beta_start: float = 0.4
    checkpoint_minutes: float = 3.0
    seed: int = 0
    init: Path | None = None
    """A policy file to fine-tune (same observation options and action count), e.g. a shipped policy moved to a
    retrained prior whose action deltas keep their meaning; None: a new Q-network."""
    init_exploration: float = 0.2
    """A fine-tune's first exploration rate (falling to `exploration_final_eps` over `exploration_fraction`)."""
    device: str = "cpu"
    """Where the Q-network and the env's prior run ("cuda" on a GPU machine; the views are ray-cast on the CPU)."""
    run_dir: Path = Path("runs/dqn")
    weights: Path | None = None
    ship: bool = False
    """Write the policy into the package (priors/weights/ + manifest) instead of `run_dir` (`weights_destination`)."""
    command: str = ""
    engine: str = "sb3"
    """"sb3": `PrioritizedDoubleDQN` in this process; "rllib": RLlib's DQN on Ray (`agents.train_rllib.train_rllib_dqn`),
    the same Q-network, double-Q and prioritised replay, the same files."""
    env_runners: int = 0
    """rllib: Ray env-runner actors sharing the `num_envs` bodies; 0: the driver process samples."""
    address: str | None = None
    """rllib: a Ray cluster to join; None: a local Ray."""

    def __post_init__(self) -> None:
        if self.engine not in ("sb3", "rllib"):
            raise ValueError(f"engine must be 'sb3' or 'rllib', got {self.engine!r}")
        if self.env_runners < 0 or (self.env_runners and self.num_envs % self.env_runners):
            raise ValueError(f"env_runners must be >= 0 and split num_envs ({self.num_envs}) evenly, got {self.env_runners}")
        if self.init is not None and (self.engine != "sb3" or not Path(self.init).is_file()):
            raise ValueError(f"init must be an existing policy file and needs engine 'sb3', got {self.init!r} ({self.engine})")
        if not 0 <= self.init_exploration <= 1:
            raise ValueError(f"init_exploration must be within [0, 1], got {self.init_exploration}")

    def checkpoint_path(self) -> Path:
        """What a resumed run continues from: SB3's model.zip, or RLlib's checkpoint folder."""
        return self.run_dir / ("rllib" if self.engine == "rllib" else "model.zip")

    def weights_path(self) -> Path:
        options = {name: True for name in ("known_goal", "goal_memory") if getattr(self, name)}
        suffix = next((suffix for suffix, trained in OBSERVATION_OPTIONS.items() if trained == options), None)
        if suffix is None:
            raise ValueError(f"no policy name for the observation options {options}: choose at most one")
        return weights_destination(f"dqn_clopsnav_{self.family}{suffix}.zip", self.run_dir, self.weights, self.ship)


def make_model(config: DQNTrainConfig, venv: VecMonitor) -> PrioritizedDoubleDQN:
    policy = "MultiInputPolicy" if config.known_goal or config.goal_memory else "CnnPolicy"
    return PrioritizedDoubleDQN(
        policy, venv, alpha=config.alpha, beta_start=config.beta_start, buffer_size=config.buffer_size,
        learning_starts=config.learning_starts, batch_size=config.batch_size, learning_rate=config.learning_rate,
        gamma=config.gamma, train_freq=1, gradient_steps=config.gradient_steps,
        target_update_interval=config.target_update_interval, exploration_fraction=config.exploration_fraction,
        exploration_initial_eps=1.0 if config.init is None else config.init_exploration,
        exploration_final_eps=config.exploration_final_eps, seed=config.seed, device=config.device,
        tensorboard_log=str(config.run_dir / "tensorboard"),
    )  # fmt: skip


def fine_tuned_model(config: DQNTrainConfig, venv: VecMonitor) -> PrioritizedDoubleDQN:
    """The policy file `config.init` as a new run's model: its Q-network (the target a copy of it), and this run's
    step count (0), replay warm-up, exploration (from `init_exploration`) and optimiser settings."""
    try:
        model = PrioritizedDoubleDQN.load(config.init, env=venv, device=config.device)
    except ValueError as error:
        raise ValueError(f"{config.init} does not fit this run's env (observation options or actions): {error}") from error
    fresh = make_model(config, venv)
    fresh.policy.load_state_dict(model.policy.state_dict())
    fresh.q_net_target.load_state_dict(fresh.q_net.state_dict())  # the target starts from the policy's Q-values
    return fresh


def train_dqn(config: DQNTrainConfig) -> dict:
    """Train (or resume) a ClopsNav policy; returns the manifest entry it writes."""
    if config.engine == "rllib":
        from agents.train_rllib import train_rllib_dqn

        return train_rllib_dqn(config)
    config.run_dir.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(config.seed)
    venv = VecMonitor(NativeVecEnv.make(config.env_id, num_envs=config.num_envs, family=config.family,
                                        known_goal=config.known_goal, goal_memory=config.goal_memory, device=config.device,
                                        **config.env_kwargs))  # fmt: skip
    venv.seed(config.seed)
    checkpoint, curve_path = config.run_dir / "model.zip", config.run_dir / "curve.json"
    curve = json.loads(curve_path.read_text()) if curve_path.exists() else []
    if checkpoint.exists():
        model = PrioritizedDoubleDQN.load(checkpoint, env=venv, device=config.device)
        model.learning_starts = model.num_timesteps + config.learning_starts  # refill the (unsaved) buffer first
        print(f"resuming {checkpoint} at {model.num_timesteps} steps", file=sys.stderr)
    elif config.init is not None:
        model = fine_tuned_model(config, venv)
    else:
        model = make_model(config, venv)
    callback = CurveCallback(config.run_dir, config.checkpoint_minutes, curve)
    remaining = config.total_timesteps - model.num_timesteps
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=callback, reset_num_timesteps=False, progress_bar=True)
        callback.save()
    return ship_policy(model, config, curve, "dqn_policy", steps_label="env steps (actions)")
