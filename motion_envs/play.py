"""`motion-envs play ENV_ID`: run episodes with a policy or a baseline, write a video and a summary line.

Every generated frame (not only one per step) goes into the video, so it
shows what the body did at the prior's own frame rate (40 fps, `--every 2`
keeps every other frame). The summary line per episode: success, steps,
final distance, contact score (GAMMA Eq. 11) and foot skating (WANDR's, 0.2 m/s).
`--search K` plays the branch a tree search (16 roots, 4 children, K kept;
`motion_envs.wrappers.tree_search`) found with the controller as proposal.
WandrReach-v0 episodes (30 fps) use a saved policy or WANDR's own sampler
(`--baseline sampler`, the default there) and report success, frames, the
final and closest wrist distance and foot skating.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import torch

from motion_envs.body.markers import foot_vertex_ids
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.envs.gamma_reach import GammaReachEnv
from motion_envs.metrics import foot_skating, skating_threshold
from motion_envs.priors.canonical import PELVIS
from motion_envs.render.camera import follow_camera
from motion_envs.render.third_person import ThirdPersonRenderer

BASELINES = ("random", "greedy-reward", "greedy-distance")
WANDR_ID = "motion_envs/WandrReach-v0"


def controller_for(policy: Path | None, baseline: str | None, seed: int) -> Callable:
    """A batched controller `(core, state) -> z`: a saved PPOKL policy, or a named baseline (default random)."""
    if policy is not None:
        from agents.controllers import PolicyLatent

        return PolicyLatent(policy, seed=seed)
    from baselines.latent_controllers import GreedyLatent, RandomLatent

    name = baseline or "random"
    if name == "random":
        return RandomLatent(seed)
    if name in ("greedy-reward", "greedy-distance"):
        return GreedyLatent(16, name.split("-")[1], seed)
    raise ValueError(f"unknown baseline {name!r}; choose from {BASELINES}")


def play(env_id: str, policy: Path | None = None, baseline: str | None = None, video: Path | None = None,
         seed: int = 0, episodes: int = 1, every: int = 2, search: int | None = None, **env_kwargs) -> list[dict]:  # fmt: skip
    """Run `episodes` episodes; returns their summaries (and writes `video` when given). `env_kwargs` go to the env;
    `search` (K kept per level) plays tree-search branches instead of the controller's own latents."""
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    if env_id == WANDR_ID:
        if search is not None:
            raise ValueError(f"--search needs a primitive-level env (GammaReach-v0), not {WANDR_ID}")
        return _play_wandr(policy, baseline, video, seed, episodes, every, **env_kwargs)
    if env_id != "motion_envs/GammaReach-v0":
        raise ValueError(f"play supports motion_envs/GammaReach-v0 and {WANDR_ID}, got {env_id!r}")
    env = GammaReachEnv(**env_kwargs)
    controller = controller_for(policy, baseline, seed)
    renderer = ThirdPersonRenderer(env.core.generator.body) if video else None
    writer = imageio.get_writer(str(video), fps=GAMMA_FPS / every, macro_block_size=8) if video else None
    summaries = []
    try:
        for episode in range(episodes):
            summaries.append(_episode(env, controller, renderer, writer, seed + episode, every, search))
    finally:
        if writer is not None:
            writer.close()
    return summaries


def _episode(env: GammaReachEnv, controller: Callable, renderer: ThirdPersonRenderer | None, writer, seed: int,
             every: int, search: int | None) -> dict:  # fmt: skip
    env.reset(seed=seed)
    plan = None
    if search is not None:
        from motion_envs.wrappers.tree_search import SearchSettings, beam_search

        plan = beam_search(env.core, env.state, controller, SearchSettings(keep=search)).latents[0]
    body, feet_ids = env.core.generator.body, foot_vertex_ids()
    feet, contact, trail = [], [], [env.trail[0]]
    info: dict = {}
    steps = 0
    for steps in range(1, env.config.max_primitives + 1):
        z = (controller(env.core, env.state)[0] if plan is None else plan[steps - 1]).numpy()
        _, _, terminated, truncated, info = env.step(z)
        primitive = env.last_primitive
        new = primitive.new_frames()[0]
        transl, orient, pose = primitive.transl[0, new], primitive.global_orient[0, new], primitive.body_pose[0, new]
        with torch.no_grad():
            feet.append(body.skin(body(transl, orient, pose), feet_ids))
        contact.append(info["contact_score"])
        if renderer is not None:
            pelvis = primitive.joints[0, new, PELVIS].numpy()
            vertices = renderer.vertices(transl, orient, pose)
            for frame in range(0, len(vertices), every):
                trail.append(pelvis[frame])
                image = renderer.render(vertices[frame : frame + 1], follow_camera(pelvis[frame]),
                                        goal=env.state.goal[0].numpy(), goal_radius=env.config.goal_radius,
                                        trail=np.array(trail))  # fmt: skip
                writer.append_data(image)
        if terminated or truncated:
            break
    all_feet = torch.cat(feet)[None]
    return {
        "seed": seed,
        "success": bool(info.get("is_success", False)),
        "steps": steps,
        "final_distance": round(info["distance"], 3),
        "contact_score": round(float(np.mean(contact)), 3),
        "foot_skating": round(float(foot_skating(all_feet, skating_threshold(GAMMA_FPS)).float().mean()), 3),
    }


def _play_wandr(policy: Path | None, baseline: str | None, video: Path | None, seed: int, episodes: int, every: int,
                **env_kwargs) -> list[dict]:  # fmt: skip
    """WandrReach episodes rendered frame by frame (`env.render()`, the prior's 30 fps / `every`)."""
    from baselines.wandr_sampler import WandrSampler
    from motion_envs.envs.wandr_reach import WandrReachEnv

    if baseline not in (None, "sampler"):
        raise ValueError(f"unknown baseline {baseline!r} for {WANDR_ID}; choose from ('sampler',)")
    if policy is not None:
        from agents.controllers import PolicyLatent

        controller = PolicyLatent(policy, seed=seed)
    else:
        controller = WandrSampler(seed=seed)
    env = WandrReachEnv(render_mode="rgb_array" if video else None, **env_kwargs)
    writer = imageio.get_writer(str(video), fps=env.metadata["render_fps"] / every, macro_block_size=8) if video else None
    summaries = []
    try:
        for episode in range(episodes):
            env.reset(seed=seed + episode)
            for step in range(env.config.max_steps):
                _, _, terminated, truncated, info = env.step(controller(env.core, env.state)[0].numpy())
                if writer is not None and step % every == 0:
                    writer.append_data(env.render())
                if terminated or truncated:
                    break
            summaries.append({"seed": seed + episode, "success": bool(info["is_success"]), "frames": info["frames"],
                              "final_distance": round(info["distance"], 3), "closest": round(info["closest_distance"], 3),
                              "foot_skating": round(info["foot_skating"], 3)})  # fmt: skip
    finally:
        if writer is not None:
            writer.close()
    return summaries
