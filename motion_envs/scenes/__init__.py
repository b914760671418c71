"""Scenes: procedural furnished rooms (`make_scene`), user files (`load_scene`), occupancy, free space, collisions."""

from motion_envs.scenes.labels import LABELS, PALETTE
from motion_envs.scenes.layouts import FAMILIES, TEST_SEEDS, TRAIN_SEEDS, make_scene
from motion_envs.scenes.scene import Scene, ScenePart, load_scene

__all__ = ["FAMILIES", "LABELS", "PALETTE", "TEST_SEEDS", "TRAIN_SEEDS", "Scene", "ScenePart", "load_scene", "make_scene"]
