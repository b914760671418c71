"""Batched state: frozen dataclasses of tensors (or nested batched states) sharing a leading body dimension N.

Environments keep their whole simulation state in one such dataclass so that
it can be cloned, indexed, repeated and restored as a unit (what the tree
search and GAMMA's 32 clones per body need):

    saved = env.state.clone()
    children = env.state.repeat(4)          # each body 4 times, in order
    best = children.index(torch.tensor([2, 5]))
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TypeVar

import torch

State = TypeVar("State", bound="BatchedState")


@dataclasses.dataclass(frozen=True)
class BatchedState:
    """Base class: every field is a tensor whose first dimension is the body index, or a nested BatchedState."""

    @property
    def num_bodies(self) -> int:
        first = getattr(self, dataclasses.fields(self)[0].name)
        return first.num_bodies if isinstance(first, BatchedState) else int(first.shape[0])

    def _map(self: State, tensor_op: Callable[[torch.Tensor], torch.Tensor], state_op: Callable[[BatchedState], BatchedState]) -> State:
        changes = {}
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            changes[field.name] = state_op(value) if isinstance(value, BatchedState) else tensor_op(value)
        return dataclasses.replace(self, **changes)

    def index(self: State, indices: torch.Tensor | slice) -> State:
        """The bodies at `indices` (long tensor, bool mask or slice), as a new state."""
        return self._map(lambda value: value[indices], lambda state: state.index(indices))

    def clone(self: State) -> State:
        """A deep copy: stepping the copy never changes the original."""
        return self._map(torch.clone, lambda state: state.clone())

    def repeat(self: State, times: int) -> State:
        """Each body `times` times in a row: (N, ...) -> (N * times, ...)."""
        return self._map(lambda value: value.repeat_interleave(times, dim=0), lambda state: state.repeat(times))

    def to(self: State, device: torch.device | str) -> State:
        return self._map(lambda value: value.to(device), lambda state: state.to(device))

    def replace_bodies(self: State, mask: torch.Tensor, other: State) -> State:
        """This state with the bodies where `mask` (N,) is true taken from `other` (same N)."""
        changes = {}
        for field in dataclasses.fields(self):
            mine, theirs = getattr(self, field.name), getattr(other, field.name)
            if isinstance(mine, BatchedState):
                changes[field.name] = mine.replace_bodies(mask, theirs)
            else:
                changes[field.name] = where_bodies(mask, theirs, mine)
        return dataclasses.replace(self, **changes)

    @classmethod
    def cat(cls: type[State], states: list[State]) -> State:
        """Bodies of several states one after another."""
        changes = {}
        for field in dataclasses.fields(cls):
            values = [getattr(state, field.name) for state in states]
            changes[field.name] = type(values[0]).cat(values) if isinstance(values[0], BatchedState) else torch.cat(values)
        return cls(**changes)


def where_bodies(mask: torch.Tensor, new: torch.Tensor, old: torch.Tensor) -> torch.Tensor:
    """`new` for the bodies where `mask` (N,) holds, else `old` (both (N, ...))."""
    return torch.where(mask.reshape(-1, *([1] * (new.ndim - 1))), new, old)
