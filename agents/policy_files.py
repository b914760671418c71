"""Saved policies (.zip) and what they were trained for: read, check against an env, load.

A policy shipped by `agents.train_ppo.ship_policy` carries `trained_for` (saved with the SB3 model's data): the
env id and the `gym.make` arguments it was trained with that the env must repeat (observation options such as
ClopsNav's `known_goal` / `goal_memory`, the scene family, the reward, the run's `env_kwargs`). Files written
before that are read from the `manifest.json` beside them. `play`, `view` and the benchmarks build their env from
it, and `check_policy_spaces` compares the policy's spaces with the env's before the first step, so a policy for
another env fails with a sentence instead of a shape error inside torch.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym

POLICY_KINDS = {"ppo_policy": "a PPO latent policy (agents.ppo_kl.PPOKL)", "dqn_policy": "a ClopsNav DQN policy (agents.double_dqn)"}
OBSERVATION_FLAGS = ("known_goal", "goal_memory")
"""Boolean env options that change a ClopsNav policy's observation."""


class PolicyFileError(ValueError):
    """A policy file that is not a saved policy, or one made for another env."""


@dataclass(frozen=True)
class TrainedFor:
    """The env a policy was trained for: its id and the `gym.make` arguments to repeat."""

    env_id: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def of_config(cls, config: Any) -> TrainedFor:
        """From a PPO or DQN training config (`PPOTrainConfig`, `DQNTrainConfig`) or its manifest dict."""
        values = asdict(config) if not isinstance(config, dict) else config
        kwargs: dict[str, Any] = {}
        if values.get("family") is not None:
            kwargs["family"] = values["family"]
        if values.get("reward") is not None:
            kwargs["reward"] = values["reward"]
        kwargs.update({flag: True for flag in OBSERVATION_FLAGS if values.get(flag)})
        kwargs.update(values.get("env_kwargs") or {})
        return cls(values["env_id"], kwargs)

    def describe(self) -> str:
        options = ", ".join(f"{key}={value!r}" for key, value in self.env_kwargs.items())
        return f"{self.env_id}" + (f" ({options})" if options else "")


@dataclass(frozen=True)
class PolicyFile:
    """What a saved policy holds, read without building its model."""

    path: Path
    kind: str
    observation_space: gym.Space
    action_space: gym.Space
    trained_for: TrainedFor | None
    alpha: float | None = None
    """PPO (`PPOKL`): α of the latent regulariser; None for DQN."""
    kl_mean: str | None = None
    """PPO: the regulariser's centre ("zero" or "cloned", `PPOKL.prior_mean`); None for DQN."""


def read_policy_file(path: str | Path) -> PolicyFile:
    """Read a policy .zip's kind, spaces and `trained_for`.

    Raises:
        FileNotFoundError: no such file (named as given: SB3 would look for `path.zip`).
        PolicyFileError: not an SB3 save, or of another kind than `POLICY_KINDS`.
    """
    from stable_baselines3.common.save_util import json_to_data
    from stable_baselines3.dqn.policies import DQNPolicy

    from agents.ppo_kl import LatentPriorPolicy

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no policy file at {path}")
    try:  # only the archive's "data" entry (spaces, policy class, trained_for): the weights are not read
        with zipfile.ZipFile(path) as archive:
            data = json_to_data(archive.read("data").decode())
    except Exception as error:  # zipfile, a missing entry, JSON and pickle errors alike
        raise PolicyFileError(f"{path} is not a saved Stable-Baselines3 policy ({type(error).__name__}: {error})") from error
    policy_class = (data or {}).get("policy_class")
    if isinstance(policy_class, type) and issubclass(policy_class, DQNPolicy):
        kind = "dqn_policy"
    elif isinstance(policy_class, type) and issubclass(policy_class, LatentPriorPolicy):
        kind = "ppo_policy"
    else:
        raise PolicyFileError(f"{path} holds a {getattr(policy_class, '__name__', policy_class)!r} policy; expected one of: "
                              + "; ".join(POLICY_KINDS.values()))  # fmt: skip
    stored = data.get("trained_for")
    trained_for = TrainedFor(**stored) if isinstance(stored, dict) else _from_manifest(path)
    return PolicyFile(path, kind, data["observation_space"], data["action_space"], trained_for,
                      data.get("kl_prior_coef"), data.get("prior_mean"))  # fmt: skip


def without_env_options(path: str | Path, names: list[str]) -> bytes:
    """A policy file's bytes with `names` removed from its saved `trained_for` env options (the other entries as
    they are): for a policy trained with an env option that stops applying once it ships, e.g. `weights=` naming a
    prior in a run folder that ships with it as the env's default.

    Raises:
        PolicyFileError: the file carries no `trained_for`, or one without some of `names`.
    """
    path = Path(path)
    read_policy_file(path)  # a saved policy, or a clear error
    buffer = io.BytesIO()
    with zipfile.ZipFile(path) as source, zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as target:
        for item in source.infolist():
            contents = source.read(item.filename)
            if item.filename == "data":
                data = json.loads(contents)
                options = (data.get("trained_for") or {}).get("env_kwargs")
                missing = [name for name in names if options is None or name not in options]
                if missing:
                    raise PolicyFileError(f"{path} was not trained with the env option(s) {missing} (it saved: {options})")
                data["trained_for"]["env_kwargs"] = {key: value for key, value in options.items() if key not in names}
                contents = json.dumps(data, indent=4).encode()
            target.writestr(item, contents)
    return buffer.getvalue()


def _from_manifest(path: Path) -> TrainedFor | None:
    """The `trained_for` of a policy written before files carried it: its record in the manifest beside it."""
    manifest = path.parent / "manifest.json"
    if not manifest.is_file():
        return None
    record = json.loads(manifest.read_text()).get(path.name)
    if not isinstance(record, dict) or "env_id" not in record.get("config", {}):
        return None
    return TrainedFor.of_config(record["config"])


def expect_policy(path: str | Path, kind: str, env_id: str | None = None) -> PolicyFile:
    """The policy file at `path`, checked to be of `kind` and (where it says, and `env_id` is given) trained for
    `env_id`.

    Raises:
        PolicyFileError: another kind of policy, or one trained for another env (both named).
    """
    policy = read_policy_file(path)
    trained = "" if policy.trained_for is None else f", trained for {policy.trained_for.describe()}"
    if policy.kind != kind:
        raise PolicyFileError(f"{policy.path} holds {POLICY_KINDS[policy.kind]}{trained}; {env_id or 'this controller'} "
                              f"needs {POLICY_KINDS[kind]}")  # fmt: skip
    if env_id is not None and policy.trained_for is not None and policy.trained_for.env_id != env_id:
        raise PolicyFileError(f"{policy.path} was trained for {policy.trained_for.describe()}, not {env_id}")
    return policy


def env_kwargs_for(policy: PolicyFile | None, given: dict[str, Any] | None = None) -> dict[str, Any]:
    """The env arguments to play `policy` with: what it was trained for, overridden by `given` (`--env-option`)."""
    trained = {} if policy is None or policy.trained_for is None else dict(policy.trained_for.env_kwargs)
    return {**trained, **(given or {})}


def check_policy_spaces(policy: PolicyFile, observation_space: gym.Space, action_space: gym.Space) -> None:
    """Raise PolicyFileError unless the env's single-body spaces are the policy's, naming both and what the policy
    was trained for."""
    for name, theirs, ours in (("observation", policy.observation_space, observation_space),
                               ("action", policy.action_space, action_space)):  # fmt: skip
        if theirs != ours:
            trained = "" if policy.trained_for is None else f" (trained for {policy.trained_for.describe()})"
            raise PolicyFileError(f"{policy.path}{trained} expects the {name} space {theirs}, but the env has {ours}; "
                                  "build the env the policy was trained for (--env-option KEY=VALUE)")  # fmt: skip
