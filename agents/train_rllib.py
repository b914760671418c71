"""`motion-envs train ppo|dqn --engine rllib`: PPO (every id) and DQN (ClopsNav) on Ray RLlib's new API stack,
with the SB3 path's files.

Reads top to bottom: join or start Ray (`--address`, or a local one) -> register the env id so that every env
runner steps one native vector env of `num_envs / env_runners` bodies (`agents.rllib_envs`) -> RLlib's PPO with
`agents.rllib_ppo.SB3PolicyModule` (the SB3 actor-critic networks) and `LatentPriorPPOLearner` (the paper's
α Ψ(KL) regulariser) and the SB3 path's settings (`PAPER_SETTINGS`, learning rate, batch, epochs; one update per
`num_envs × n_steps` samples) -> new, cloned from the data's latents (`clone_into`, on the SB3 twin of the
network, then copied in), or the run's latest checkpoint -> train, every `checkpoint_minutes` saving the
algorithm atomically to `run_dir/rllib/` with the steps and wall time so far inside, and appending the success rate
of the episodes that ended since the last save to `run_dir/curve.json` (the best window also as
`run_dir/best.zip`) -> the policy shipped as the SB3 path ships it (`agents.train_ppo.ship_policy`: a PPOKL
.zip with `trained_for`, a manifest entry, the curve plot), which `play`, `view` and every benchmark read.
DQN (`train_rllib_dqn`) runs the same loop with `agents.rllib_dqn.SB3QModule` and ships a
`PrioritizedDoubleDQN` file.

RLlib by default treats a Box policy's outputs as normalised to [-1, 1] and stretches them to the action box
(×4 for our latents); here actions are the sampled latents, clipped to the box, as SB3 does. Differences from
the SB3 path, by RLlib's design: no early stop at a target KL within an update (RLlib has
none), no reward normalisation (the critic and the actor are separate networks and Adam scales each parameter's
step, so the return's scale does not starve the policy), the value loss unclipped (`vf_clip_param` large).
"""

from __future__ import annotations

import json
import shutil
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from tqdm import tqdm

from agents.ppo_kl import PAPER_SETTINGS, PPOKL
from agents.train_ppo import PPOTrainConfig, clone_into, new_model, ship_policy
from agents.vec_env import NativeVecEnv
from motion_envs.atomic import atomic_write
from motion_envs.data.goal_windows import GoalWindows

MODULE_ID = "default_policy"
PROGRESS = "motion_envs_progress.json"
"""In the checkpoint folder: env steps and training seconds so far."""


def start_ray(address: str | None, num_cpus: int | None = None) -> None:
    """Join the cluster at `address`, or start a local Ray bound to 127.0.0.1 (no dashboard); no-op if running."""
    import ray

    if ray.is_initialized():
        return
    if address is None:
        ray.init(num_cpus=num_cpus, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
    else:
        ray.init(address=address, log_to_driver=False)


def export_model(config: PPOTrainConfig) -> Any:
    """The SB3 twin of the RLlib module on the driver, over a 1-body env: PPOKL (latent actions) or SB3's PPO
    (ClopsNav's discrete actions), with the same policy class and network as `SB3PolicyModule`."""
    from stable_baselines3 import PPO

    from agents.rllib_ppo import sb3_policy_class

    kwargs = dict(config.env_kwargs, **({"reward": config.reward} if config.reward is not None else {}))
    venv = NativeVecEnv.make(config.env_id, num_envs=1, **kwargs)
    if isinstance(venv.action_space, gym.spaces.Box):
        with warnings.catch_warnings():  # SB3 asks for batch_size | n_steps × 1 body: this model never collects
            warnings.simplefilter("ignore", UserWarning)
            return new_model(config, venv)
    policy = {"MultiInputActorCriticPolicy": "MultiInputPolicy", "ActorCriticCnnPolicy": "CnnPolicy"}.get(
        sb3_policy_class(venv.observation_space, venv.action_space).__name__, "MlpPolicy")  # fmt: skip
    width = config.net_width
    return PPO(policy, venv, seed=config.seed, policy_kwargs={"net_arch": {"pi": [width, width], "vf": [width, width]}})


def algorithm_config(config: PPOTrainConfig) -> Any:
    """RLlib's `PPOConfig` for the run (the env must be registered: `agents.rllib_envs.register_rllib_env`)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from agents.rllib_envs import EpisodeSuccess, rllib_env_name
    from agents.rllib_ppo import LatentPriorPPOLearner, SB3PolicyModule

    env_config = dict(config.env_kwargs, **({"reward": config.reward} if config.reward is not None else {}),
                      **({"device": config.device} if config.device != "cpu" else {}))  # fmt: skip
    runners = max(config.env_runners, 1)
    return (
        PPOConfig()
        .environment(env=rllib_env_name(config.env_id, config.bootstrap_truncation), env_config=env_config,
                     normalize_actions=False, clip_actions=True)  # latents as sampled, clipped to the box as SB3
        .env_runners(num_env_runners=config.env_runners, num_envs_per_env_runner=config.num_envs // runners,
                     gym_env_vectorize_mode="vector_entry_point", rollout_fragment_length=config.n_steps,
                     num_cpus_per_env_runner=config.cpus_per_env_runner)  # fmt: skip
        .learners(num_gpus_per_learner=1 if config.device.startswith("cuda") else 0, learner_class=LatentPriorPPOLearner,
                  learner_config_dict={"kl_prior_coef": config.alpha})  # fmt: skip
        .training(train_batch_size_per_learner=config.num_envs * config.n_steps, minibatch_size=config.batch_size,
                  num_epochs=config.n_epochs, lr=config.learning_rate, gamma=PAPER_SETTINGS["gamma"],
                  lambda_=PAPER_SETTINGS["gae_lambda"], clip_param=PAPER_SETTINGS["clip_range"], use_kl_loss=False,
                  vf_clip_param=1e9)  # fmt: skip
        .rl_module(rl_module_spec=RLModuleSpec(module_class=SB3PolicyModule,
                                               model_config={"net_width": config.net_width,
                                                             "log_std_init": config.log_std_init}))  # fmt: skip
        .callbacks(EpisodeSuccess)
        .debugging(seed=config.seed)
    )


def module_weights(algorithm: Any) -> dict[str, torch.Tensor]:
    """The learner's module weights as an SB3 policy `state_dict` (the "policy." prefix removed)."""
    state = algorithm.learner_group.get_state()["learner"]["rl_module"][MODULE_ID]
    return {name.removeprefix("policy."): torch.as_tensor(np.asarray(value)) for name, value in state.items()}


def load_weights(algorithm: Any, policy_state: dict[str, torch.Tensor]) -> None:
    """Put an SB3 policy `state_dict` into the learner's module and every env runner's copy."""
    state = {f"policy.{name}": value.cpu().numpy() for name, value in policy_state.items()}
    algorithm.learner_group.set_state({"learner": {"rl_module": {MODULE_ID: state}}})
    algorithm.env_runner_group.sync_weights(from_worker_or_learner_group=algorithm.learner_group, inference_only=True)


def save_checkpoint(algorithm: Any, final: Path, progress: dict[str, float]) -> None:
    """Save the algorithm and `progress` (steps and wall time, `PROGRESS`) to the folder `final` without a
    half-written state: into a temporary folder, then swapped in."""
    temporary, old = final.with_name(final.name + ".tmp"), final.with_name(final.name + ".old")
    shutil.rmtree(temporary, ignore_errors=True)
    algorithm.save_to_path(str(temporary.resolve()))
    (temporary / PROGRESS).write_text(json.dumps(progress))
    if final.exists():
        final.rename(old)
    temporary.rename(final)
    shutil.rmtree(old, ignore_errors=True)


def recover_checkpoint(checkpoint: Path) -> None:
    """Finish a checkpoint swap a kill interrupted (`save_checkpoint`): keep the newest complete folder."""
    old = checkpoint.with_name(checkpoint.name + ".old")
    if old.exists() and checkpoint.exists():
        shutil.rmtree(old)
    elif old.exists():
        old.rename(checkpoint)


def count(metrics: dict[str, Any], key: str) -> float:
    """A per-iteration sum RLlib reports, 0 where it reports nothing (missing, or NaN in an iteration without it)."""
    value = float(metrics.get(key, 0.0))
    return value if np.isfinite(value) else 0.0


def run_rllib(algorithm: Any, config: Any, model: Any, total_timesteps: int) -> list[dict]:
    """Train `algorithm` to `total_timesteps` env steps (resuming its progress file), every
    `config.checkpoint_minutes` appending the success rate of the episodes that ended to `run_dir/curve.json`,
    keeping the best window's policy in `run_dir/best.zip` (through `model`, the SB3 twin) and saving a
    checkpoint; `model` ends with the final weights. Returns the curve."""
    from agents.rllib_envs import ENDED, SUCCESSES

    run_dir, checkpoint = config.run_dir, config.checkpoint_path()
    curve_path = run_dir / "curve.json"
    curve: list[dict] = json.loads(curve_path.read_text()) if curve_path.exists() else []
    progress = json.loads((checkpoint / PROGRESS).read_text()) if checkpoint.exists() else {"timesteps": 0, "wall_seconds": 0.0}
    successes = ended = 0.0
    last_save = time.monotonic()
    with tqdm(total=total_timesteps, initial=progress["timesteps"], unit="step", desc=f"rllib {type(algorithm).__name__}") as bar:
        while progress["timesteps"] < total_timesteps:
            began = time.monotonic()
            runners = algorithm.train()["env_runners"]
            steps = int(count(runners, "num_env_steps_sampled"))
            progress["timesteps"] += steps
            progress["wall_seconds"] = round(progress["wall_seconds"] + time.monotonic() - began, 1)
            successes, ended = successes + count(runners, SUCCESSES), ended + count(runners, ENDED)
            bar.update(steps)
            bar.set_postfix(success=f"{successes / ended:.2f}" if ended else "-")
            finished = progress["timesteps"] >= total_timesteps
            if not finished and time.monotonic() - last_save < 60.0 * config.checkpoint_minutes:
                continue
            if ended:
                best = max((point["success_rate"] for point in curve), default=-1.0)
                curve.append({"timesteps": progress["timesteps"], "wall_seconds": progress["wall_seconds"],
                              "success_rate": successes / ended, "episodes": int(ended)})  # fmt: skip
                if curve[-1]["success_rate"] > best:
                    model.policy.load_state_dict(module_weights(algorithm))
                    atomic_write(run_dir / "best.zip", model.save)
                successes = ended = 0.0
            save_checkpoint(algorithm, checkpoint, progress)
            text = json.dumps(curve, indent=1)
            atomic_write(curve_path, lambda file: file.write(text.encode()))
            last_save = time.monotonic()
    model.policy.load_state_dict(module_weights(algorithm))
    model.num_timesteps = progress["timesteps"]
    return curve


def prepare_run(config: Any) -> str:
    """Make the run folder, recover an interrupted checkpoint swap, start or join Ray and register the env;
    returns the registered env name."""
    from agents.rllib_envs import register_rllib_env

    config.run_dir.mkdir(parents=True, exist_ok=True)
    recover_checkpoint(config.checkpoint_path())
    torch.manual_seed(config.seed)
    start_ray(config.address)
    return register_rllib_env(config.env_id, getattr(config, "bootstrap_truncation", True))


def train_rllib(config: PPOTrainConfig, clone_from: GoalWindows | None = None) -> dict:
    """Train (or resume) a PPO policy on RLlib; returns the manifest entry of the shipped policy."""
    if config.init == "data" and clone_from is None and not config.checkpoint_path().exists():
        raise ValueError("init='data' needs goal windows from the data (clone_from); pass init='scratch' to skip")
    prepare_run(config)
    model = export_model(config)
    algorithm = algorithm_config(config).build_algo()
    if config.checkpoint_path().exists():
        algorithm.restore_from_path(str(config.checkpoint_path().resolve()))
        print(f"resuming {config.checkpoint_path()}", file=sys.stderr)
    elif config.init == "data":
        clone_into(model, clone_from, config)
        load_weights(algorithm, model.policy.state_dict())
    elif config.init != "scratch":
        load_weights(algorithm, type(model).load(config.init, device="cpu").policy.state_dict())
    try:
        curve = run_rllib(algorithm, config, model, config.total_timesteps)
    finally:
        algorithm.stop()
    cloning = config.run_dir / "cloning.json"
    extra = {"cloning": json.loads(cloning.read_text())} if cloning.exists() else {}
    kind = "ppo_policy" if isinstance(model, PPOKL) else "clops_ppo_policy"  # the latter: SB3's PPO, categorical
    return ship_policy(model, config, curve, kind, best=config.keep == "best", engine="rllib", **extra)


def dqn_algorithm_config(config: Any) -> Any:
    """RLlib's `DQNConfig` with `agents.train_dqn.DQNTrainConfig`'s settings: double-Q, prioritised replay
    (α, β), the same replay ratio (`gradient_steps × batch_size` samples trained per `num_envs` transitions),
    target updates and ε schedule."""
    from ray.rllib.algorithms.dqn import DQNConfig
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from agents.rllib_dqn import SB3QModule
    from agents.rllib_envs import EpisodeSuccess, rllib_env_name

    runners = max(config.env_runners, 1)
    return (
        DQNConfig()
        .environment(env=rllib_env_name(config.env_id), env_config=dqn_env_kwargs(config))
        .env_runners(num_env_runners=config.env_runners, num_envs_per_env_runner=config.num_envs // runners,
                     gym_env_vectorize_mode="vector_entry_point", rollout_fragment_length=1)  # fmt: skip
        .learners(num_gpus_per_learner=1 if config.device.startswith("cuda") else 0)
        .training(lr=config.learning_rate, gamma=config.gamma, train_batch_size_per_learner=config.batch_size,
                  replay_buffer_config={"type": "PrioritizedEpisodeReplayBuffer", "capacity": config.buffer_size,
                                        "alpha": config.alpha, "beta": config.beta_start},
                  num_steps_sampled_before_learning_starts=config.learning_starts,
                  target_network_update_freq=config.target_update_interval, double_q=True, dueling=False, n_step=1,
                  training_intensity=config.gradient_steps * config.batch_size / config.num_envs,
                  epsilon=[(0, 1.0), (int(config.exploration_fraction * config.total_timesteps), config.exploration_final_eps)])  # fmt: skip
        .rl_module(rl_module_spec=RLModuleSpec(module_class=SB3QModule))
        .reporting(min_sample_timesteps_per_iteration=config.num_envs)  # one vector step per `train()` (RLlib: 1,000)
        .callbacks(EpisodeSuccess)
        .debugging(seed=config.seed)
    )


def dqn_env_kwargs(config: Any) -> dict[str, Any]:
    """The ClopsNav `gym.make` arguments of a DQN run."""
    return dict(config.env_kwargs, family=config.family, known_goal=config.known_goal, goal_memory=config.goal_memory,
                **({"device": config.device} if config.device != "cpu" else {}))  # fmt: skip


def train_rllib_dqn(config: Any) -> dict:
    """Train (or resume) a ClopsNav DQN policy on RLlib; ships a `PrioritizedDoubleDQN` file as `train dqn` does."""
    from dataclasses import replace

    from agents.train_dqn import make_model

    prepare_run(config)
    venv = NativeVecEnv.make(config.env_id, num_envs=1, **dqn_env_kwargs(config))
    model = make_model(replace(config, buffer_size=1, learning_starts=0), venv)  # the SB3 twin: its buffer is never filled
    algorithm = dqn_algorithm_config(config).build_algo()
    if config.checkpoint_path().exists():
        algorithm.restore_from_path(str(config.checkpoint_path().resolve()))
        print(f"resuming {config.checkpoint_path()}", file=sys.stderr)
    try:
        curve = run_rllib(algorithm, config, model, config.total_timesteps)
    finally:
        algorithm.stop()
    return ship_policy(model, config, curve, "dqn_policy", steps_label="env steps (actions)", engine="rllib")
