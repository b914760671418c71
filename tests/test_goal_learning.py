"""Learning from goals in the data: goal windows, cloning data latents into a policy, the g-CVAE baseline."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

from agents.behaviour_cloning import clone_latents, posterior_latents
from agents.ppo_kl import LatentPriorPolicy
from baselines.g_cvae import GoalCVAETrainConfig, goal_cvae_generator, train_goal_cvae
from motion_envs.data.goal_windows import GoalWindowSettings, goal_windows
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore
from motion_envs.priors.gamma import MarkerCVAEConfig, goal_conditioned_seed
from motion_envs.priors.gamma_generator import GammaGenerator


@pytest.fixture(scope="module")
def windows(walking_clips):
    return goal_windows(walking_clips, GoalWindowSettings(goals_per_window=2))


@pytest.fixture(scope="module")
def shipped() -> GammaGenerator:
    return GammaGenerator.load()


def test_goal_windows_hold_far_goals_and_the_envs_state(windows):
    assert len(windows) > 100 and windows.observation.shape == (len(windows), 804)
    per_marker = windows.observation.unflatten(1, (2, 67, 6))
    assert torch.allclose(per_marker[..., :3], windows.seed, atol=1e-5)  # markers canonical at the first seed frame
    towards = windows.goal[:, None, None] - windows.seed
    assert torch.allclose(per_marker[..., 3:], towards / towards.norm(dim=-1, keepdim=True), atol=1e-4)
    assert (windows.goal[:, :2].norm(dim=-1) > 0.5).all()  # >= 1 m from the last pelvis, which is near the origin
    assert goal_conditioned_seed(windows.observation).shape == (len(windows), 2, 402)


def test_cloning_fits_the_data_latents_better_than_their_mean(windows, shipped):
    latents = posterior_latents(shipped.predictor_2f, windows)
    assert latents.shape == (len(windows), 128) and torch.isfinite(latents).all()
    space = gym.spaces.Box(-np.inf, np.inf, (804,), np.float32)
    policy = LatentPriorPolicy(space, gym.spaces.Box(-4, 4, (128,), np.float32), lambda _: 1e-3, net_arch=[64, 64])
    fit = clone_latents(policy, windows.observation, latents, epochs=40, batch_size=64)
    assert fit["validation_mse"] < 0.75 * fit["latent_variance"]  # predicting their mean scores the variance
    with pytest.raises(ValueError, match="pair up"):
        clone_latents(policy, windows.observation[:3], latents[:4])


def test_g_cvae_trains_and_steers_a_generator(windows, shipped, tmp_path):
    config = GoalCVAETrainConfig(model=MarkerCVAEConfig(hidden=32, mlp=(32, 32), goal_features=True), epochs=3,
                                 batch_size=32, run_dir=tmp_path / "run", weights=tmp_path / "w" / "g.pt")  # fmt: skip
    entry = train_goal_cvae(config, windows, windows)
    assert entry["train_loss_by_epoch"][-1] < entry["train_loss_by_epoch"][0]
    generator = goal_cvae_generator(config.weights, base=shipped)
    core = GammaReachCore(GammaReachConfig(max_primitives=3), generator)
    state = core.sample_initial_state([np.random.default_rng(0), np.random.default_rng(1)])
    for _ in range(2):  # a 1-frame start, then the goal-conditioned 2-frame model
        state, result = core.step(state, torch.randn(2, 128))
    assert torch.isfinite(result.primitive.markers).all()
    with pytest.raises(ValueError, match="needs the bodies' goals"):
        generator.step(state.seed, torch.zeros(2, 128))
    with pytest.raises(ValueError, match="not a goal-conditioned"):
        goal_cvae_generator(_plain_predictor(tmp_path), base=shipped)


def _plain_predictor(tmp_path):
    """Weights of a predictor without goal features, as `train_predictor` ships them."""
    from dataclasses import asdict

    from motion_envs.priors.gamma import MarkerCVAE
    from motion_envs.priors.training import ship

    config, path = MarkerCVAEConfig(hidden=32, mlp=(32, 32)), tmp_path / "plain" / "p.pt"
    ship(MarkerCVAE(config), path, {"kind": "gamma_predictor", "config": asdict(config)})
    return path


def test_train_ppo_clones_the_data_then_resumes_and_ships(windows, tmp_path):
    """The `motion-envs train ppo` pipeline end to end at toy size (the cloned start, a resume, the manifest)."""
    import json

    from agents.ppo_kl import PPOKL
    from agents.train_ppo import PPOTrainConfig, train_ppo

    config = PPOTrainConfig(num_envs=4, n_steps=4, batch_size=16, n_epochs=1, total_timesteps=16, clone_epochs=30,
                            run_dir=tmp_path / "run", weights=tmp_path / "w" / "policy.zip")  # fmt: skip
    with pytest.raises(ValueError, match="goal windows"):
        train_ppo(config)
    first = train_ppo(config, windows)
    assert first["timesteps"] == 16 and first["cloning"]["validation_mse"] < first["cloning"]["latent_variance"]
    config.total_timesteps = 32
    second = train_ppo(config)  # resumes from the run's checkpoint: no data needed
    assert second["timesteps"] == 32
    manifest = json.loads((tmp_path / "w" / "manifest.json").read_text())
    assert manifest["policy.zip"]["kind"] == "ppo_policy" and "cloning" in manifest["policy.zip"]
    assert PPOKL.load(config.weights, device="cpu").kl_prior_coef == config.alpha
    from agents.policy_files import read_policy_file

    (tmp_path / "w" / "manifest.json").unlink()  # what it was trained for travels in the file itself
    assert read_policy_file(config.weights).trained_for.describe() == "motion_envs/GammaReach-v0 (reward='paper')"
    tuned = PPOTrainConfig(num_envs=4, n_steps=4, batch_size=16, n_epochs=1, total_timesteps=16, init=str(config.weights),
                           learning_rate=1e-5, run_dir=tmp_path / "tune", weights=tmp_path / "w" / "tuned.zip")  # fmt: skip
    assert train_ppo(tuned)["timesteps"] == 16  # a fine-tune counts its own steps from the loaded policy
    start, end = (PPOKL.load(path, device="cpu").policy.state_dict() for path in (config.weights, tuned.weights))
    assert all(torch.allclose(start[name], end[name], atol=0.05) for name in start)  # starts from it, not from scratch
    assert PPOKL.load(tuned.weights, device="cpu").learning_rate == 1e-5
    mismatched = PPOTrainConfig(num_envs=4, n_steps=4, batch_size=16, n_epochs=1, total_timesteps=16,
                                init=str(config.weights), kl_mean="cloned", run_dir=tmp_path / "centred")  # fmt: skip
    with pytest.raises(ValueError, match="trained with kl_mean='zero'"):  # it has no anchor to centre on
        train_ppo(mismatched)
    with pytest.raises(ValueError, match="kl_mean='cloned'"):
        PPOTrainConfig(init="scratch", kl_mean="cloned")
    with pytest.raises(ValueError, match="policy file"):
        PPOTrainConfig(init="runs/no_such_policy.zip")
    with pytest.raises(ValueError, match="keep"):
        PPOTrainConfig(keep="first")
