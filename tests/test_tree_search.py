"""Tree search over GammaReach's batched core: branches replay, search beats the bare proposal."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import motion_envs  # noqa: F401
from baselines.latent_controllers import RandomLatent
from motion_envs.envs.gamma_reach import GammaReachConfig, GammaReachCore
from motion_envs.priors.gamma_generator import GammaGenerator
from motion_envs.wrappers.tree_search import SearchCost, SearchSettings, TreeSearch, beam_search


@pytest.fixture(scope="module")
def core() -> GammaReachCore:
    return GammaReachCore(GammaReachConfig(max_primitives=8), GammaGenerator.load())


def _starts(core: GammaReachCore, count: int):
    return core.sample_initial_state([np.random.default_rng(i) for i in range(count)], {"goal": (1.5, 0.5)})


def _final_cost(core: GammaReachCore, start, latents: torch.Tensor, length: torch.Tensor) -> torch.Tensor:
    """Replays each branch and returns the search cost of its last primitive."""
    state, costs = start, torch.zeros(start.num_bodies)
    for level in range(latents.shape[1]):
        before = state
        state, result = core.step(state, latents[:, level])
        last = length == level + 1
        costs[last] = SearchCost()(before, result)[last]
    return costs


def test_a_chosen_branch_replays_to_the_cost_the_search_reported(core):
    start = _starts(core, 3)
    result = beam_search(core, start, RandomLatent(0), SearchSettings(roots=4, children=2, keep=2))
    assert result.latents.shape == (3, int(result.length.max()), 128)
    assert torch.allclose(_final_cost(core, start, result.latents, result.length), result.cost, atol=1e-4)
    expected = 3 * 4 + 3 * 2 * 2 * (int(result.length.max()) - 1)  # every search runs to the depth limit here
    assert result.expanded == expected or bool(result.reached.any())


def test_search_never_ends_worse_than_its_proposal_alone(core):
    """Same seeded proposal: one sample per level (no choice) against 8 roots, 4 children, 2 kept."""
    start = _starts(core, 4)
    alone = beam_search(core, start, RandomLatent(1), SearchSettings(roots=1, children=1, keep=1))
    searched = beam_search(core, start, RandomLatent(1), SearchSettings(roots=8, children=4, keep=2))
    assert alone.expanded == 4 * 8 and searched.expanded > 4 * alone.expanded
    assert searched.cost.mean() < alone.cost.mean()
    assert torch.allclose(_final_cost(core, start, alone.latents, alone.length), alone.cost, atol=1e-4)


def test_the_wrapper_plays_the_branch_as_an_episode():
    env = TreeSearch(gym.make("motion_envs/GammaReach-v0", max_primitives=4), RandomLatent(2),
                     SearchSettings(roots=4, children=2, keep=1))  # fmt: skip
    _, info = env.reset(seed=3)
    assert info["search"]["length"] == 4 or info["search"]["reached"]
    played, ended = 0, False
    while not ended:
        _, reward, terminated, truncated, step_info = env.step(None)
        played, ended = played + 1, terminated or truncated
        assert np.isfinite(reward)
    assert played == info["search"]["length"] and step_info["reached"] == info["search"]["reached"]
    with pytest.raises(RuntimeError, match="all played"):
        env.step(None)


def test_bad_settings_and_envs_are_refused():
    with pytest.raises(ValueError, match="positive"):
        SearchSettings(keep=0)
    with pytest.raises(TypeError, match="clone API"):
        TreeSearch(gym.make("CartPole-v1"), RandomLatent(0))
