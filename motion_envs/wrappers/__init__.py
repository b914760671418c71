"""Wrappers that work on top of any motion_envs environment exposing the batched clone/restore API."""
