"""`motion-envs view`: a local viser server that replays a saved rollout or runs a policy live.

The bodies are mannequin-x's wooden mannequins (its viser integration:
skinned meshes posed in the browser), the goals spheres or ground rings, the
pelvis trails line segments, a scene's parts coloured by label. In a scene
the walls and furniture are cut at `CUTAWAY_HEIGHT` (as the third-person
renderer's) and the camera opens above the bodies, looking down on them;
the "full walls" checkbox shows the uncut room. A timeline
slider scrubs frames; "play" runs them at the rollout's frame rate, and a
live source (an env with a controller) appends frames when the timeline
reaches its end. The server binds to 127.0.0.1 unless told otherwise.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
import roma
import torch

from motion_envs.body.frames import MANNEQUIN_TO_WORLD
from motion_envs.rollout import Rollout
from motion_envs.scenes.labels import LABELS, PALETTE
from motion_envs.scenes.scene import FLOOR, Scene

GOAL_COLOUR, TRAIL_COLOUR = (50, 180, 80), (230, 115, 25)
CUTAWAY_HEIGHT = 1.2
"""Walls and furniture are shown up to this height (m) unless "full walls" is ticked."""
WORLD_ROTATION = roma.rotmat_to_rotvec(torch.tensor(MANNEQUIN_TO_WORLD)).numpy()
"""mannequin-x's global rotation that turns its Y-up body into the suite's Z-up world."""


def mannequin_pose(template: dict[str, np.ndarray], transl: np.ndarray, rotations: np.ndarray,
                   pelvis_offset: np.ndarray) -> dict[str, np.ndarray]:  # fmt: skip
    """mannequin-x pose parameters of one body from ours: transl (3,) pelvis, rotations (22, 3) axis-angle.

    Our pelvis rotation is in world axes, so it is conjugated into mannequin-x's frame; local joint rotations
    are the same in both; the world rotation is mannequin-x's `global_rotation`, and `pelvis_offset` (3,) is
    where its pelvis lands with no translation."""
    pelvis = MANNEQUIN_TO_WORLD.T @ roma.rotvec_to_rotmat(torch.as_tensor(rotations[0], dtype=torch.float64)).numpy() @ MANNEQUIN_TO_WORLD
    pose = dict(template)
    pose["pelvis_rotation"] = roma.rotmat_to_rotvec(torch.as_tensor(pelvis)).numpy()
    pose["body_pose"] = np.asarray(rotations[1:], dtype=np.float64)
    pose["global_rotation"] = WORLD_ROTATION
    pose["global_translation"] = np.asarray(transl, dtype=np.float64) - pelvis_offset
    return pose


def opening_camera(pelvis: np.ndarray, in_scene: bool) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """(position, look-at) of the first view of bodies with pelvis positions (B, 3): on open ground beside and above
    them; in a scene from high above (over the cut walls), pulled back to frame a crowd's spread."""
    centre = pelvis.mean(axis=0)
    if not in_scene:
        return tuple(centre + np.array([-3.5, -3.5, 2.5])), tuple(centre)
    spread = float(np.ptp(pelvis[:, :2], axis=0).max()) if len(pelvis) > 1 else 0.0
    scale = max(1.0, spread / 3.0)
    look = np.array([centre[0], centre[1], 0.5])
    return tuple(look + scale * np.array([-2.0, -2.0, 4.5])), tuple(look)


class RolloutViewer:
    """Serves `rollout` (and frames that `extend` appends) on http://host:port."""

    def __init__(self, rollout: Rollout, scene: Scene | None = None, host: str = "127.0.0.1", port: int = 8080,
                 extend: Callable[[], Rollout | None] | None = None) -> None:  # fmt: skip
        import mannequin
        import viser

        self.rollout, self.extend = rollout, extend
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.scene.set_up_direction("+z")
        self.server.scene.add_grid("/ground", width=30.0, height=30.0, plane="xy", cell_size=1.0, section_size=5.0)
        if scene is not None:
            self._add_scene(scene)
        models = [mannequin.Mannequin("wooden") for _ in range(rollout.bodies)]
        self.template = models[0].rest_pose()
        zero = mannequin_pose(self.template, np.zeros(3), np.zeros((22, 3)), np.zeros(3))
        self.pelvis_offset = np.asarray(models[0].joint_transforms(zero))[0, :3, 3]
        self.bodies = [mannequin.add_to_scene(self.server.scene, f"/body_{i}", model) for i, model in enumerate(models)]
        self.goals = [self.server.scene.add_icosphere(f"/goal_{i}", radius=rollout.goal_radius if rollout.goal_shape == "sphere" else 0.08,
                                                      color=GOAL_COLOUR) for i in range(rollout.bodies)]  # fmt: skip
        self.trails = [None] * rollout.bodies
        gui = self.server.gui
        self.slider = gui.add_slider("frame", min=0, max=max(rollout.frames - 1, 1), step=1, initial_value=0)
        self.playing = gui.add_checkbox("play", initial_value=True)
        self.slider.on_update(lambda _: self.show(int(self.slider.value)))
        self.server.initial_camera.position, self.server.initial_camera.look_at = opening_camera(rollout.transl[0], scene is not None)
        self._stop = threading.Event()
        self.show(0)

    def _add_scene(self, scene: Scene) -> None:
        """The room twice: cut at `CUTAWAY_HEIGHT` (shown) and whole (shown with "full walls")."""
        cut = Scene([part for part in scene.parts if part.label == FLOOR] + scene.cutaway(CUTAWAY_HEIGHT), scene.name)
        handles = {"cut": [], "full": []}
        for kind, shown in (("cut", cut), ("full", scene)):
            for label in np.unique(shown.face_labels):
                faces = shown.faces[shown.face_labels == label]
                handles[kind].append(self.server.scene.add_mesh_simple(f"/scene_{kind}/{LABELS[label]}", shown.vertices, faces,
                                                                       color=tuple(int(c) for c in PALETTE[label])))  # fmt: skip
        full_walls = self.server.gui.add_checkbox("full walls", initial_value=False)

        def show_walls(_: object = None) -> None:
            for handle in handles["full"]:
                handle.visible = full_walls.value
            for handle in handles["cut"]:
                handle.visible = not full_walls.value

        full_walls.on_update(show_walls)
        show_walls()

    def show(self, frame: int) -> None:
        """Pose every body, goal and trail at `frame`."""
        rollout = self.rollout
        frame = int(np.clip(frame, 0, rollout.frames - 1))
        for i, body in enumerate(self.bodies):
            body.set_pose(mannequin_pose(self.template, rollout.transl[frame, i], rollout.rotations[frame, i], self.pelvis_offset))
            self.goals[i].position = tuple(float(v) for v in rollout.goal[frame, i])
            path = rollout.transl[: frame + 1, i].copy()
            path[:, 2] = 0.01
            if len(path) > 1:
                segments = np.stack([path[:-1], path[1:]], axis=1)
                self.trails[i] = self.server.scene.add_line_segments(f"/trail_{i}", segments, TRAIL_COLOUR, thickness=0.03)

    def run(self, duration: float | None = None) -> None:
        """Play (when the checkbox is on) until `stop()` or `duration` seconds; a live source extends the end."""
        began = time.perf_counter()
        while not self._stop.is_set() and (duration is None or time.perf_counter() - began < duration):
            time.sleep(1.0 / self.rollout.fps)
            if not self.playing.value:
                continue
            frame = int(self.slider.value) + 1
            if frame >= self.rollout.frames and self.extend is not None:
                more = self.extend()
                if more is not None:
                    self._append(more)
            self.slider.value = frame % self.rollout.frames

    def _append(self, more: Rollout) -> None:
        r = self.rollout
        self.rollout = Rollout(*(np.concatenate([getattr(r, n), getattr(more, n)]) for n in ("transl", "rotations", "goal")),
                               fps=r.fps, goal_shape=r.goal_shape, goal_radius=r.goal_radius, env_id=r.env_id, scene=r.scene)  # fmt: skip
        self.slider.max = self.rollout.frames - 1

    @property
    def url(self) -> str:
        """The address the server actually listens on (viser moves to the next free port when the asked one is taken)."""
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def stop(self) -> None:
        self._stop.set()
        self.server.stop()
