"""The SB3 adapter over the native batched GAMMA env."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

import motion_envs  # noqa: F401
from agents.vec_env import NativeVecEnv
from motion_envs.envs.gamma_reach import GammaReachEnv
from motion_envs.priors.gamma_generator import GammaGenerator


@pytest.fixture(scope="module")
def gamma() -> GammaGenerator:
    return GammaGenerator.load()


def test_adapter_matches_the_native_env_step_for_step(gamma):
    """fp32 networks: in bf16 (auto on AMX / AVX512-BF16 CPUs) rounding differs between batch sizes by ~1e-3 after
    two primitives, more than the 1e-4 this comparison of the adapter's bookkeeping asserts."""
    venv = NativeVecEnv.make("motion_envs/GammaReach-v0", num_envs=3, generator=gamma, precision="float32")
    venv.seed(20)
    observations = venv.reset()
    actions = np.random.default_rng(0).standard_normal((2, 3, 128)).astype(np.float32)
    stepped = [venv.step(a) for a in actions]
    for i in range(3):
        single = GammaReachEnv(generator=gamma, precision="float32")
        observation, _ = single.reset(seed=20 + i)
        assert np.allclose(observation, observations[i], atol=1e-5)
        for a, (vec_obs, vec_rewards, vec_dones, _) in zip(actions, stepped):
            observation, reward, terminated, truncated, _ = single.step(a[i])
            assert reward == pytest.approx(float(vec_rewards[i]), rel=1e-4)
            assert bool(vec_dones[i]) == (terminated or truncated)
            assert np.allclose(observation, vec_obs[i], atol=1e-4)


def test_adapter_reports_episode_ends_as_sb3_expects(gamma):
    venv = VecMonitor(NativeVecEnv.make("motion_envs/GammaReach-v0", num_envs=2, generator=gamma, max_primitives=2))
    venv = VecNormalize(venv)
    venv.reset()
    venv.step(np.zeros((2, 128), dtype=np.float32))
    _, _, dones, infos = venv.step(np.zeros((2, 128), dtype=np.float32))
    assert dones.all()
    for info in infos:
        assert info["TimeLimit.truncated"] is True and info["is_success"] in (True, False)
        assert info["terminal_observation"].shape == (804,) and info["episode"]["l"] == 2


def test_time_limits_can_be_reported_as_true_ends(gamma):
    """Without bootstrapping, SB3 sees a plain end: no γ·V(last observation) is added to the last reward."""
    venv = NativeVecEnv.make("motion_envs/GammaReach-v0", num_envs=2, generator=gamma, max_primitives=1,
                             bootstrap_truncation=False)  # fmt: skip
    venv.reset()
    _, _, dones, infos = venv.step(np.zeros((2, 128), dtype=np.float32))
    assert dones.all() and not any(info["TimeLimit.truncated"] for info in infos)
    assert all(info["terminal_observation"].shape == (804,) for info in infos)


def test_adapter_rejects_next_step_autoreset_envs():
    import gymnasium as gym

    vector = gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync")
    with pytest.raises(ValueError, match="same-step autoreset"):
        NativeVecEnv(vector)


def test_episode_ends_carry_the_envs_final_info_and_collisions_rank_training_windows(gamma):
    """GammaWander's episode collisions reach SB3's infos (what `CurveCallback` turns into a window's colliding share),
    counted as the env's own per-primitive `collided` flags; the same seeds, actions and batch size in both envs
    make the two runs identical by construction."""
    import gymnasium as gym

    from agents.train_ppo import window_score

    kwargs = {"num_envs": 4, "generator": gamma, "scene": "corridor", "max_primitives": 6}
    raw = gym.make_vec("motion_envs/GammaWander-v0", vectorization_mode="vector_entry_point", **kwargs)
    venv = VecMonitor(NativeVecEnv.make("motion_envs/GammaWander-v0", **kwargs))
    raw.reset(seed=[3, 4, 5, 6])
    venv.seed(3)
    venv.reset()
    actions = np.random.default_rng(1).standard_normal((6, 4, 128)).astype(np.float32)
    collided = np.zeros(4, dtype=int)
    for a in actions:
        _, _, _, _, info = raw.step(a)
        collided += info["collided"]
        _, _, dones, infos = venv.step(a)
    assert dones.all() and collided.sum() > 0
    assert [info["collisions"] for info in infos] == collided.tolist()
    assert all(info["episode"]["l"] == 6 and isinstance(info["is_success"], bool) for info in infos)
    clean, colliding = {"success_rate": 0.9, "collided_share": 0.02}, {"success_rate": 0.92, "collided_share": 0.15}
    assert window_score(clean) > window_score(colliding) and window_score({"success_rate": 0.5}) == 0.5
