"""`motion-envs play ENV_ID`: run episodes with a policy or a baseline, write a video and a summary line.

Every generated frame (not only one per step) goes into the video, so it
shows what the body did at the prior's own frame rate (40 fps, `--every 2`
keeps every other frame). The summary line per episode: success, steps,
final distance, contact score (GAMMA Eq. 11) and foot skating (WANDR's, 0.2 m/s).
`--search K` plays the branch a tree search (16 roots, 4 children, K kept;
`motion_envs.wrappers.tree_search`) found with the controller as proposal.
`--save-rollout out.npz` keeps every generated frame of every episode for
`motion-envs view` (`motion_envs.rollout`); `LiveEpisodes` feeds the viewer
live.
WandrReach-v0 episodes (30 fps) use a saved policy or WANDR's own sampler
(`--baseline sampler`, the default there) and report success, frames, the
final and closest wrist distance and foot skating. ClopsNav-v0 episodes use a
saved DQN policy or random actions and report success, frames, the final
goal distance, collision rate and foot skating; the video shows every frame
with the egocentric view after each action inset.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import torch

from motion_envs.atomic import atomic_path
from motion_envs.body.markers import foot_vertex_ids
from motion_envs.data.primitives import GAMMA_FPS
from motion_envs.envs.gamma_reach import GammaReachEnv
from motion_envs.envs.gamma_wander import GammaWanderEnv
from motion_envs.metrics import foot_skating, skating_threshold
from motion_envs.body.canonical_frame import PELVIS
from motion_envs.render.camera import follow_camera
from motion_envs.render.env_view import ROOM_CAMERA
from motion_envs.render.third_person import ThirdPersonRenderer
from motion_envs.rollout import Rollout, RolloutRecorder

BASELINES = ("random", "greedy-reward", "greedy-distance")
GAMMA_ID, WANDR_ID, CLOPS_ID = "motion_envs/GammaReach-v0", "motion_envs/WandrReach-v0", "motion_envs/ClopsNav-v0"
WANDER_ID = "motion_envs/GammaWander-v0"
POLICY_KIND = {GAMMA_ID: "ppo_policy", WANDER_ID: "ppo_policy", WANDR_ID: "ppo_policy", CLOPS_ID: "dqn_policy"}


def policy_env_kwargs(env_id: str, policy: Path | None, env_kwargs: dict | None = None):
    """(the policy file checked for `env_id`, or None; the env arguments to play it with: what it was trained for,
    overridden by `env_kwargs`)."""
    from agents.policy_files import env_kwargs_for, expect_policy

    if env_id not in POLICY_KIND:
        raise ValueError(f"play supports {', '.join(POLICY_KIND)}, got {env_id!r}")
    if env_id == WANDER_ID:  # GammaReach policies drive GammaWander too (the same spaces); only its own say its kwargs
        file = None if policy is None else expect_policy(policy, POLICY_KIND[env_id])
        own = file is not None and file.trained_for is not None and file.trained_for.env_id == env_id
        return file, env_kwargs_for(file if own else None, env_kwargs)
    file = None if policy is None else expect_policy(policy, POLICY_KIND[env_id], env_id)
    return file, env_kwargs_for(file, env_kwargs)


def check_policy(file, env) -> None:
    """The policy's spaces against the env's (before the first step); nothing without a policy."""
    from agents.policy_files import check_policy_spaces

    if file is not None:
        check_policy_spaces(file, env.observation_space, env.action_space)


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
         seed: int = 0, episodes: int = 1, every: int = 2, search: int | None = None, save_rollout: Path | None = None,
         **env_kwargs) -> list[dict]:  # fmt: skip
    """Run `episodes` episodes; returns their summaries (and writes `video` and `save_rollout` when given).
    `env_kwargs` go to the env; `search` (K kept per level) plays tree-search branches instead of the
    controller's own latents."""
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    file, env_kwargs = policy_env_kwargs(env_id, policy, env_kwargs)
    if env_id == WANDR_ID:
        if search is not None:
            raise ValueError(f"--search needs a primitive-level env (GammaReach-v0), not {WANDR_ID}")
        env = _wandr_env(video is not None, env_kwargs)
        controller = wandr_controller(policy, baseline, seed)
        fps, run = env.metadata["render_fps"], _wandr_episode
    elif env_id in (GAMMA_ID, WANDER_ID):
        env = GammaReachEnv(**env_kwargs) if env_id == GAMMA_ID else GammaWanderEnv(**env_kwargs)
        controller = controller_for(policy, baseline, seed)
        fps, run = GAMMA_FPS, _episode
    elif env_id == CLOPS_ID:
        if search is not None:
            raise ValueError(f"--search needs a primitive-level env (GammaReach-v0), not {CLOPS_ID}")
        from motion_envs.envs.clops_nav import ClopsNavEnv

        env = ClopsNavEnv(render_mode="rgb_array" if video is not None else None, **env_kwargs)
        controller = clops_controller(policy, baseline, seed)
        fps, run = env.metadata["render_fps"] * 30, _clops_episode
    check_policy(file, env)
    recorder = RolloutRecorder(fps, *env.core.goal_marker, env_id=env_id) if save_rollout else None
    summaries = []
    with contextlib.ExitStack() as stack:  # the video appears whole at `video` once every episode ran, or not at all
        writer = None
        if video:
            partial = stack.enter_context(atomic_path(video))
            writer = stack.enter_context(contextlib.closing(imageio.get_writer(str(partial), fps=fps / every, macro_block_size=8)))
        for episode in range(episodes):
            summaries.append(run(env, controller, writer, seed + episode, every, search, recorder))
    if recorder is not None:
        recorder.rollout().save(save_rollout)
    return summaries


class LiveEpisodes:
    """Episodes played on demand for the live viewer: `more()` returns the frames of the next steps (about
    one second of motion), starting a new episode (next seed) when one ends. ClopsNav and GammaWander
    episodes all play in one held-out room (test seed 1000 + `seed` of the env's family), the one the viewer
    shows."""

    def __init__(self, env_id: str, policy: Path | None = None, baseline: str | None = None, seed: int = 0,
                 env_kwargs: dict | None = None) -> None:  # fmt: skip
        file, env_kwargs = policy_env_kwargs(env_id, policy, env_kwargs)
        self.env_id, self.seed = env_id, seed
        from motion_envs.scenes.layouts import TEST_SEEDS

        one_room = {"split": "test", "scene_seeds": (TEST_SEEDS[0] + seed,), **env_kwargs}
        if env_id == CLOPS_ID:
            from motion_envs.envs.clops_nav import ClopsNavEnv

            self.env = ClopsNavEnv(**one_room)
            self.env.keep_frames = True
            self.controller = clops_controller(policy, baseline, seed)
        elif env_id == WANDR_ID:
            self.env, self.controller = _wandr_env(False, env_kwargs), wandr_controller(policy, baseline, seed)
        elif env_id == WANDER_ID:
            self.env, self.controller = GammaWanderEnv(**one_room), controller_for(policy, baseline, seed)
        else:
            self.env, self.controller = GammaReachEnv(**env_kwargs), controller_for(policy, baseline, seed)
        check_policy(file, self.env)
        self.fps = GAMMA_FPS if env_id in (GAMMA_ID, WANDER_ID) else 30
        self.observation, _ = self.env.reset(seed=seed)
        self.done = False

    def more(self) -> Rollout:
        recorder = RolloutRecorder(self.fps, *self.env.core.goal_marker, env_id=self.env_id)
        while len(recorder) < self.fps:
            if self.done:
                self.seed += 1
                self.observation, _ = self.env.reset(seed=self.seed)
            if hasattr(self.env.core, "scene_spec"):  # the viewer rebuilds the room from "family:seed"
                recorder.scene = self.env.core.scene_spec(self.env.state)
            if self.env_id == CLOPS_ID:
                action = self.controller(self.env, self.observation)
            else:
                action = self.controller(self.env.core, self.env.state)[0].numpy()
            self.observation, _, terminated, truncated, _ = self.env.step(action)
            _record_step(self.env, recorder)
            self.done = terminated or truncated
        return recorder.rollout()


def _record_step(env, recorder: RolloutRecorder) -> None:
    """Add the frames the env's last step generated (GammaReach: a primitive's new frames; WandrReach: one;
    ClopsNav: the action's whole chunk)."""
    if isinstance(env, (GammaReachEnv, GammaWanderEnv)):
        primitive, goal = env.last_primitive, env.state.goal[:1]
        for frame in torch.nonzero(primitive.new_frames()[0]).flatten().tolist():
            recorder.add(primitive.transl[:1, frame], primitive.global_orient[:1, frame], primitive.body_pose[:1, frame], goal)
        return
    if hasattr(env, "last_frames"):  # ClopsNav: every frame of the action's chunk
        for body in env.last_frames:
            recorder.add(body.transl, body.orient, body.shown_pose, env.state.goal)
        return
    inputs = env.core.render_inputs(env.state)
    recorder.add(inputs.transl, inputs.global_orient, inputs.body_pose, inputs.goal)


def _episode(env: GammaReachEnv | GammaWanderEnv, controller: Callable, writer, seed: int, every: int, search: int | None,
             recorder: RolloutRecorder | None) -> dict:  # fmt: skip
    """A GammaReach or GammaWander episode (GammaWander: in its room, with the route ahead drawn)."""
    env.reset(seed=seed)
    plan = None
    if search is not None:
        from motion_envs.wrappers.tree_search import SearchSettings, beam_search

        plan = beam_search(env.core, env.state, controller, SearchSettings(keep=search)).latents[0]
    body, feet_ids = env.core.generator.body, foot_vertex_ids()
    scene = env.core.render_scene(env.state) if hasattr(env.core, "render_scene") else None
    if recorder is not None and hasattr(env.core, "scene_spec"):  # the viewer rebuilds the room from "family:seed"
        recorder.scene = env.core.scene_spec(env.state)
    renderer = ThirdPersonRenderer(env.core.body, scene=scene) if writer is not None else None
    feet, contact, trail = [], [], [env.state.seed.joints[0, -1, PELVIS].numpy()]
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
        if recorder is not None:
            _record_step(env, recorder)
        if renderer is not None:
            pelvis = primitive.joints[0, new, PELVIS].numpy()
            vertices = renderer.vertices(transl, orient, pose)
            for frame in range(0, len(vertices), every):
                trail.append(pelvis[frame])
                camera = follow_camera(pelvis[frame], **(ROOM_CAMERA if scene is not None else {}))
                routes = env.core.render_paths(env.state)[:1] if hasattr(env.core, "render_paths") else None
                image = renderer.render(vertices[frame : frame + 1], camera, goal=env.state.goal[0].numpy(),
                                        goal_radius=env.config.goal_radius, trail=np.array(trail), routes=routes)  # fmt: skip
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
        **({"collisions": info["collisions"]} if "collisions" in info else {}),
    }


def wandr_controller(policy: Path | None, baseline: str | None, seed: int) -> Callable:
    """A saved policy, or WANDR's own sampler (the default and only baseline there)."""
    if baseline not in (None, "sampler"):
        raise ValueError(f"unknown baseline {baseline!r} for {WANDR_ID}; choose from ('sampler',)")
    if policy is not None:
        from agents.controllers import PolicyLatent

        return PolicyLatent(policy, seed=seed)
    from baselines.wandr_sampler import WandrSampler

    return WandrSampler(seed=seed)


def _wandr_env(rendered: bool, env_kwargs: dict):
    from motion_envs.envs.wandr_reach import WandrReachEnv

    return WandrReachEnv(render_mode="rgb_array" if rendered else None, **env_kwargs)


def _wandr_episode(env, controller: Callable, writer, seed: int, every: int, search: int | None,
                   recorder: RolloutRecorder | None) -> dict:  # fmt: skip
    """A WandrReach episode rendered frame by frame (`env.render()`, the prior's 30 fps / `every`)."""
    env.reset(seed=seed)
    for step in range(env.config.max_steps):
        _, _, terminated, truncated, info = env.step(controller(env.core, env.state)[0].numpy())
        if recorder is not None:
            _record_step(env, recorder)
        if writer is not None and step % every == 0:
            writer.append_data(env.render())
        if terminated or truncated:
            break
    return {"seed": seed, "success": bool(info["is_success"]), "frames": info["frames"],
            "final_distance": round(info["distance"], 3), "closest": round(info["closest_distance"], 3),
            "foot_skating": round(info["foot_skating"], 3)}  # fmt: skip


def clops_controller(policy: Path | None, baseline: str | None, seed: int) -> Callable:
    """`(env, observation) -> action`: a saved ClopsNav DQN policy, or uniformly random actions (the default)."""
    if baseline not in (None, "random"):
        raise ValueError(f"unknown baseline {baseline!r} for {CLOPS_ID}; choose from ('random',)")
    if policy is not None:
        from agents.double_dqn import PrioritizedDoubleDQN

        model = PrioritizedDoubleDQN.load(policy, device="cpu")
        return lambda env, observation: int(model.predict(observation, deterministic=True)[0])
    generator = np.random.default_rng(seed)
    return lambda env, observation: int(generator.integers(env.action_space.n))


def _clops_episode(env, controller: Callable, writer, seed: int, every: int, search: int | None,
                   recorder: RolloutRecorder | None) -> dict:  # fmt: skip
    """A ClopsNav episode; the video gets every generated frame (30 fps / `every`) with the view after each action."""
    observation, _ = env.reset(seed=seed)
    env.keep_frames = writer is not None or recorder is not None
    if recorder is not None:  # the viewer rebuilds the room from "family:seed" (the last episode's room)
        recorder.scene = env.core.scene_spec(env.state)
    trail = [env.trail[0]]
    info: dict = {}
    for _ in range(10_000):
        observation, _, terminated, truncated, info = env.step(controller(env, observation))
        view = env.state.view[0].cpu().numpy()
        if recorder is not None:
            _record_step(env, recorder)
        for index, body in enumerate(env.last_frames):
            trail.append(body.joints[0, PELVIS].cpu().numpy())
            if writer is not None and index % every == 0:
                writer.append_data(env.render_body(body, view, np.array(trail)))
        if terminated or truncated:
            break
    return {"seed": seed, "success": bool(info["is_success"]), "frames": info["frames"],
            "final_distance": round(info["distance"], 3), "collision_rate": round(info["collision_rate"], 3),
            "foot_skating": round(info["foot_skating"], 3)}  # fmt: skip

