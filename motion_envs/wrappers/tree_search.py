"""GAMMA's tree search at test time: a beam over motion primitives, batched over many searches.

From a start state, the root gets `roots` children (latents from a proposal:
policy samples or random z); then, level by level, the `keep` cheapest
children survive and each gets `children` children of its own, until a kept
node reaches the goal or `max_depth` levels are done. The chosen branch (the
cheapest node that reached the goal, else the cheapest at the last level) is
returned as its latent codes, with the branch's scene collisions as the search
saw them. The prior is deterministic given z, but a replay in another batch
shape is not guaranteed to be bit-identical to the search (matmul kernels may
sum in another order per batch size, most of all in bf16); measured on 20
living rooms (fp32 and bf16, 1 and 4 kept), replays reproduced the searched
collisions exactly. Defaults follow the authors' release (REFERENCE_NOTES
§1.8): 16 roots, 4 children per node, 4 kept.

Node cost (lower is better; the release's soft-contact cost, weights in
`SearchCost`), on the node's own primitive:

    w_ground · max(|min z of any marker| − 0.05, 0) + w_skate · max(slowest marker speed − 0.075, 0)
    + w_orientation · (1 − cos(facing, direction to goal)) + w_distance · (pelvis-goal distance)
    + w_collision · [a body sphere entered the scene] + w_crowd · (metres inside another body's space)
    + w_clearance · max(margin − clearance, 0)

The scene terms need results that report them (`GammaWander-v0`'s `collided`, `crowding` and `clearance`);
the collision weight is large, so a branch that walks into furniture or a wall is pruned unless every branch
does (ours; the release's scene search has the same rule as a hard check). The clearance term (ours) keeps
branches a margin away from furniture: ranked by distance alone, a search hugs the furniture it walks around,
until every child of its kept nodes touches it and the pruning has nothing left to choose.

## What an environment must offer (the batched clone/restore API)

`beam_search` works for any environment core with
- `core.step(state, z) -> (next_state, result)` for N bodies at once, the
  core itself stateless (states go in and out);
- states that are `motion_envs.batched.BatchedState` (`repeat`, `index`) and
  carry `goal` (N, 3);
- results with `reached` (N,) bool, `distance` (N,) metres, and
  `primitive.markers` (N, T, M, 3) and `primitive.joints` (N, T, 22, 3) in
  world coordinates (z up);
- `core.config.max_primitives` for the default depth and
  `core.generator.latent_size`;
- optionally, results with `collided` (N,) bool, `crowding` (N,) and `clearance` (N,) metres, and states with
  `collisions` (N,) so far (`SearchCost`'s scene terms).

`GammaReachCore` offers all of it; `TreeSearch` wraps a single env whose
`unwrapped` has `core` and a settable `state` (e.g. `GammaReach-v0`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable

import gymnasium as gym
import torch

from motion_envs.batched import BatchedState
from motion_envs.metrics import slowest_marker_speed
from motion_envs.rewards import orientation_reward

Proposal = Callable[[Any, BatchedState], torch.Tensor]
"""`proposal(core, states) -> z (N, latent)`: e.g. `agents.controllers.PolicyLatent` or `RandomLatent`."""


@dataclass(frozen=True)
class SearchCost:
    """Weights and tolerances of the node cost (defaults: the release's)."""

    ground: float = 1.0
    skate: float = 1.0
    orientation: float = 0.1
    distance: float = 0.1
    ground_tolerance: float = 0.05
    """Metres the lowest marker may be off the ground for free."""
    skate_tolerance: float = 0.075
    """m/s the slowest marker may move for free (forward difference)."""
    fps: int = 40
    collision: float = 1000.0
    """Added per collision of a node's branch with the scene (results with `collided`): such branches are pruned."""
    crowd: float = 10.0
    """Per metre a pelvis came inside another body's personal space (results with `crowding`)."""
    clearance: float = 10.0
    """Per metre a body sphere came inside `clearance_margin` of the scene (results with `clearance`)."""
    clearance_margin: float = 0.1

    @classmethod
    def distance_only(cls) -> SearchCost:
        """The pelvis-goal distance alone. Our CMU-trained prior skates more than the release's tolerances
        (0.05 m, 0.075 m/s) allow, so the release's cost prefers primitives that stand still: with the
        same policy and 24 pairs, top-4 reached 0.38 of goals with it and 0.75 with distance alone
        (contact score 0.97 vs 0.87)."""
        return cls(ground=0.0, skate=0.0, orientation=0.0, distance=1.0)

    def __call__(self, state: BatchedState, result: Any) -> torch.Tensor:
        """(N,) cost of the primitives just generated from `state`."""
        markers = result.primitive.markers
        lowest = markers[..., 2].amin(dim=(1, 2)).abs()
        slowest = slowest_marker_speed(markers, self.fps)
        misaligned = 2.0 * (1.0 - orientation_reward(result.primitive.joints[:, -1], state.goal))  # 1 - cos
        cost = (self.ground * (lowest - self.ground_tolerance).clamp_min(0.0)
                + self.skate * (slowest - self.skate_tolerance).clamp_min(0.0)
                + self.orientation * misaligned + self.distance * result.distance)  # fmt: skip
        if hasattr(result, "collided"):  # with the branch's earlier collisions (`state.collisions`): pruned for good
            collisions = state.collisions.to(cost.dtype) + result.collided.to(cost.dtype)
            cost = cost + self.collision * collisions + self.crowd * result.crowding
        if hasattr(result, "clearance"):
            cost = cost + self.clearance * (self.clearance_margin - result.clearance).clamp_min(0.0)
        return cost


@dataclass(frozen=True)
class SearchSettings:
    roots: int = 16
    children: int = 4
    keep: int = 4
    max_depth: int | None = None
    """Levels (primitives) at most; None: the core's `config.max_primitives`."""
    cost: SearchCost = SearchCost()

    def __post_init__(self) -> None:
        if min(self.roots, self.children, self.keep) < 1 or (self.max_depth is not None and self.max_depth < 1):
            raise ValueError(f"roots, children, keep and max_depth must be positive, got {self}")


@dataclass(frozen=True)
class SearchResult:
    """B searches' chosen branches. latents: (B, D, latent), zero after a branch's end. length: (B,) primitives.
    reached: (B,) bool. cost: (B,) the chosen last node's cost. spread: (B,) mean pelvis-goal ground distance
    of the nodes kept at the last level (GAMMA's "avg. dist." of a top-K search). expanded: body-primitives
    generated in all. collisions: (B,) long, the chosen branch's primitives that collided with the scene as
    searched (zeros where states have no `collisions`)."""

    latents: torch.Tensor
    length: torch.Tensor
    reached: torch.Tensor
    cost: torch.Tensor
    spread: torch.Tensor
    expanded: int
    collisions: torch.Tensor


@torch.no_grad()
def beam_search(core: Any, start: BatchedState, proposal: Proposal, settings: SearchSettings = SearchSettings()) -> SearchResult:
    """One search per body of `start` (B bodies), each level one batched step over every live search's nodes."""
    count = start.num_bodies
    depth_limit = settings.max_depth or core.config.max_primitives
    latent_size = core.generator.latent_size
    live = torch.arange(count)  # searches still going, in order
    parents = start  # level 0 expands the root alone, `roots` times
    history: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []  # per level: live, kept's parents, kept's z
    last_level = torch.zeros(count, dtype=torch.long)
    reached = torch.zeros(count, dtype=torch.bool)
    final_cost, spread = torch.zeros(count), torch.zeros(count)
    collisions = torch.zeros(count, dtype=torch.long)
    expanded = 0
    for level in range(depth_limit):
        repeats = settings.roots if level == 0 else settings.children
        children = parents.repeat(repeats)  # row (parent p, child c) = p * repeats + c; parents are search-major
        z = proposal(core, children).to(torch.float32)
        next_state, result = core.step(children, z)
        expanded += children.num_bodies
        cost = settings.cost(children, result).reshape(len(live), -1)  # (L, parents per search × repeats)
        done = result.reached.reshape(len(live), -1).cpu()
        cost = cost.cpu()
        kept = torch.where(done, cost - 1e6, cost).topk(min(settings.keep, cost.shape[1]), dim=1, largest=False).indices
        rows = torch.arange(len(live))[:, None]
        history.append((live, kept // repeats, z.cpu().reshape(len(live), -1, latent_size)[rows, kept]))
        best_done, best_cost = done[rows, kept[:, :1]][:, 0], cost[rows, kept[:, :1]][:, 0]
        finished = best_done | (level == depth_limit - 1)
        ended = live[finished]
        last_level[ended], reached[ended], final_cost[ended] = level, best_done[finished], best_cost[finished]
        spread[ended] = result.distance.cpu().reshape(len(live), -1)[rows, kept].mean(dim=1)[finished]
        if hasattr(next_state, "collisions"):
            collisions[ended] = next_state.collisions.cpu().reshape(len(live), -1)[rows, kept[:, :1]][finished, 0].long()
        if finished.all():
            break
        going = torch.nonzero(~finished).flatten()
        live = live[going]
        flat_rows = (going[:, None] * cost.shape[1] + kept[going]).flatten()
        parents = next_state.index(flat_rows.to(result.distance.device))
    latents = _backtrack(history, last_level, count, latent_size)
    return SearchResult(latents, last_level + 1, reached, final_cost, spread, expanded, collisions)


def _backtrack(history: list, last_level: torch.Tensor, count: int, latent_size: int) -> torch.Tensor:
    """(B, levels, latent): the latents along each search's chosen branch (the cheapest kept node of its
    last level), following parent links from there back to the root."""
    latents = torch.zeros(count, len(history), latent_size)
    node = torch.zeros(count, dtype=torch.long)  # kept nodes are sorted by cost: the chosen one is 0
    row_of = torch.empty(count, dtype=torch.long)
    for level in range(len(history) - 1, -1, -1):
        live, parents, z = history[level]
        row_of[live] = torch.arange(len(live))
        searches = live[last_level[live] >= level]  # branches that pass through this level
        rows = row_of[searches]
        latents[searches, level] = z[rows, node[searches]]
        node[searches] = parents[rows, node[searches]]
    return latents


class TreeSearch(gym.Wrapper):
    """A single env whose episodes are tree searches: `reset` searches from the start state, and each
    `step` plays the next primitive of the chosen branch. The action passed to `step` is ignored (pass
    `None`), so the search's motion comes out as one ordinary trajectory: rewards, infos, `render` and
    videos as the wrapped env gives them. `info["search"]` at reset has the branch's length, whether it
    reached the goal, its cost and the body-primitives the search generated.

        env = TreeSearch(gym.make("motion_envs/GammaReach-v0"), PolicyLatent("policy.zip"), SearchSettings(keep=1))
        observation, info = env.reset(seed=0)
        while not (terminated or truncated): observation, reward, terminated, truncated, info = env.step(None)
    """

    def __init__(self, env: gym.Env, proposal: Proposal, settings: SearchSettings = SearchSettings()) -> None:
        super().__init__(env)
        for name in ("core", "state"):
            if not hasattr(env.unwrapped, name):
                raise TypeError(f"TreeSearch needs an env whose unwrapped env has `{name}` (the batched clone API)")
        self.proposal, self.settings = proposal, settings
        self.plan: torch.Tensor | None = None
        self.played = 0

    def reset(self, **kwargs: Any):
        observation, info = self.env.reset(**kwargs)
        unwrapped = self.env.unwrapped
        remaining = unwrapped.core.config.max_primitives - int(unwrapped.state.steps[0])
        settings = dataclasses.replace(self.settings, max_depth=min(self.settings.max_depth or remaining, remaining))
        result = beam_search(unwrapped.core, unwrapped.state, self.proposal, settings)
        self.plan, self.played = result.latents[0, : int(result.length[0])], 0
        info["search"] = {"length": int(result.length[0]), "reached": bool(result.reached[0]),
                          "cost": float(result.cost[0]), "expanded": result.expanded}  # fmt: skip
        return observation, info

    def step(self, action: Any = None):
        if self.plan is None:
            raise RuntimeError("call reset() before step()")
        if self.played >= len(self.plan):
            raise RuntimeError(f"the searched branch has {len(self.plan)} primitives, all played; call reset()")
        latent = self.plan[self.played].numpy()
        self.played += 1
        return self.env.step(latent)
