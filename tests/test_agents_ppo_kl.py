"""PPOKL: SB3's PPO with GAMMA's latent regulariser."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import motion_envs  # noqa: F401
from agents.ppo_kl import PPOKL
from agents.vec_env import NativeVecEnv
from motion_envs.priors.gamma_generator import GammaGenerator


@pytest.fixture(scope="module")
def venv():
    return NativeVecEnv.make("motion_envs/GammaReach-v0", num_envs=8, generator=GammaGenerator.load(), max_primitives=6)


def _prior_kl(model: PPOKL, observations: np.ndarray) -> float:
    with torch.no_grad():
        model.policy.get_distribution(torch.as_tensor(observations))
        return float(model.policy.prior_kl())


def _trained(venv, alpha: float) -> PPOKL:
    model = PPOKL("MlpPolicy", venv, kl_prior_coef=alpha, n_steps=8, batch_size=32, n_epochs=4, learning_rate=3e-3,
                  seed=0, device="cpu", target_kl=None, policy_kwargs={"log_std_init": 0.7})  # fmt: skip
    model.learn(total_timesteps=128)
    return model


def test_the_regulariser_pulls_the_policy_towards_the_prior(venv):
    venv.seed(0)
    observations = venv.reset()
    free, held = _trained(venv, 0.0), _trained(venv, 100.0)
    assert np.isfinite(held.logger.name_to_value.get("train/prior_kl", 0.0))
    assert _prior_kl(held, observations) < _prior_kl(free, observations)


def test_save_load_round_trip(venv, tmp_path):
    model = PPOKL("MlpPolicy", venv, kl_prior_coef=3.0, n_steps=8, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=64)
    model.save(tmp_path / "policy")
    loaded = PPOKL.load(tmp_path / "policy", device="cpu")
    assert loaded.kl_prior_coef == 3.0 and loaded.gae_lambda == 1.0
    observations = venv.reset()
    assert np.allclose(model.predict(observations, deterministic=True)[0], loaded.predict(observations, deterministic=True)[0])


def test_negative_coefficient_is_rejected(venv):
    with pytest.raises(ValueError, match="kl_prior_coef"):
        PPOKL("MlpPolicy", venv, kl_prior_coef=-1.0)


def test_a_saved_policy_drives_the_batched_core(venv, tmp_path):
    from agents.controllers import PolicyLatent

    model = PPOKL("MlpPolicy", venv, n_steps=8, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.save(tmp_path / "policy.zip")
    core = venv.vector_env.unwrapped.core
    state = core.sample_initial_state([np.random.default_rng(i) for i in range(5)])
    mean = PolicyLatent(tmp_path / "policy.zip", deterministic=True)(core, state)
    expected, _ = model.predict(core.observe(state).numpy(), deterministic=True)
    assert np.allclose(np.clip(mean.numpy(), -4, 4), expected, atol=1e-5)  # SB3's predict clips to the Box; the env does too
    sampled = PolicyLatent(tmp_path / "policy.zip", seed=1)(core, state)
    assert sampled.shape == (5, 128) and not torch.allclose(sampled, mean)


def test_the_cloned_centre_pulls_towards_the_anchor_not_zero(venv):
    """prior_mean="cloned": the same α Ψ(KL) centred on the anchor's mean (here an actor whose mean was moved to
    z = 1 before `set_anchor`, standing in for a cloned one) keeps the policy there; from the same start the paper's
    N(0, I) pulls it towards 0."""
    venv.seed(0)
    observations = torch.as_tensor(venv.reset())
    means = {}
    for prior_mean in ("zero", "cloned"):
        model = PPOKL("MlpPolicy", venv, kl_prior_coef=100.0, prior_mean=prior_mean, n_steps=8, batch_size=32, n_epochs=4,
                      learning_rate=3e-3, seed=0, device="cpu", target_kl=None)  # fmt: skip
        with torch.no_grad():
            model.policy.action_net.bias.fill_(1.0)
        if prior_mean == "cloned":
            model.policy.set_anchor()
        model.learn(total_timesteps=128)
        with torch.no_grad():
            means[prior_mean] = float(model.policy.get_distribution(observations).distribution.loc.mean())
    assert means["cloned"] > 0.8 and means["zero"] < 0.5, means


def test_unknown_prior_mean_is_rejected(venv):
    with pytest.raises(ValueError, match="prior_mean"):
        PPOKL("MlpPolicy", venv, prior_mean="anchor")
