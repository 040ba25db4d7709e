"""Replay buffers of the learned planner (``R_D`` demonstrations, ``R_A`` agent).

A :class:`ReplayBuffer` is a fixed-size ring of transitions held as torch
tensors on the CPU; :meth:`ReplayBuffer.sample` returns a typed
:class:`ReplayBatch` on the training device. Silhouettes are stored as
``uint8`` (``round(255 v)``) to keep the memory small; everything else as
float32. Each transition also stores the heuristic expert's action at its
state, ``pi^h(s)``, and whether the expert had one, for the Q-filtered
behaviour-cloning loss.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch

from ..errors import OptionError
from .observation import ADVICE_WIDTH, Observation

__all__ = ["ReplayBatch", "ReplayBuffer"]


class ReplayBatch(NamedTuple):
    """A minibatch of transitions.

    Attributes
    ----------
    obs, next_obs : Observation
        States before and after the step (batch ``N``).
    actions : Tensor of shape (N, 5)
    rewards : Tensor of shape (N,)
    dones : Tensor of shape (N,)
        1.0 where the step ended the episode (no bootstrap).
    expert_actions : Tensor of shape (N, 5)
        ``pi^h(s)``; 0 where the expert had no action.
    expert_valid : Tensor of shape (N,)
        1.0 where ``expert_actions`` holds an action.
    """

    obs: Observation
    actions: torch.Tensor
    rewards: torch.Tensor
    next_obs: Observation
    dones: torch.Tensor
    expert_actions: torch.Tensor
    expert_valid: torch.Tensor


class ReplayBuffer:
    """Ring buffer of transitions.

    Parameters
    ----------
    capacity : int
        Transitions kept; the oldest are overwritten.
    resolution : int
        Side ``R`` of the silhouettes.
    max_corners : int
        Corners per view ``K``.
    candidates : int, optional
        Also keep the observations' expert cuts (:attr:`Observation.advice`, ``C`` rows).
    """

    def __init__(
        self, capacity: int, *, resolution: int, max_corners: int, candidates: int = 0
    ) -> None:
        if int(capacity) < 1:
            raise OptionError(f"buffer capacity must be >= 1 (got {capacity})")
        n, r, k = int(capacity), int(resolution), int(max_corners)
        self.capacity = n
        self._data: dict[str, torch.Tensor] = {}
        for prefix in ("obs_", "next_"):
            self._data[prefix + "views"] = torch.zeros((n, 3, r, r), dtype=torch.uint8)
            self._data[prefix + "step"] = torch.zeros((n, 1))
            self._data[prefix + "corners"] = torch.zeros((n, 3, k, 2))
            self._data[prefix + "mask"] = torch.zeros((n, 3, k))
            if candidates:
                self._data[prefix + "advice"] = torch.zeros((n, int(candidates), ADVICE_WIDTH))
        self.advice = bool(candidates)
        self._data["actions"] = torch.zeros((n, 5))
        self._data["rewards"] = torch.zeros(n)
        self._data["dones"] = torch.zeros(n)
        self._data["expert_actions"] = torch.zeros((n, 5))
        self._data["expert_valid"] = torch.zeros(n)
        self.pos = 0
        self.full = False

    def __len__(self) -> int:
        return self.capacity if self.full else self.pos

    def add(
        self,
        obs: Observation,
        actions: torch.Tensor,
        rewards: torch.Tensor,
        next_obs: Observation,
        dones: torch.Tensor,
        expert_actions: torch.Tensor | np.ndarray,
        expert_valid: torch.Tensor | np.ndarray,
    ) -> None:
        """Append a batch of ``N`` transitions (first axis)."""
        fields = {
            "actions": actions,
            "rewards": rewards,
            "dones": dones,
            "expert_actions": expert_actions,
            "expert_valid": expert_valid,
        }
        for prefix, o in (("obs_", obs), ("next_", next_obs)):
            fields[prefix + "views"] = torch.round(o.views.detach().cpu() * 255.0).to(torch.uint8)
            fields[prefix + "step"] = o.step
            fields[prefix + "corners"] = o.corners
            fields[prefix + "mask"] = o.corner_mask
            if self.advice:
                if o.advice is None:
                    raise OptionError("this buffer keeps advice: observations must carry it")
                fields[prefix + "advice"] = o.advice
        n = int(actions.shape[0])
        idx = (self.pos + torch.arange(n)) % self.capacity
        for key, value in fields.items():
            tensor = torch.as_tensor(value).detach().cpu()
            self._data[key][idx] = tensor.to(self._data[key].dtype).reshape(
                self._data[key][idx].shape
            )
        self.full = self.full or self.pos + n >= self.capacity
        self.pos = int((self.pos + n) % self.capacity)

    def sample(
        self, batch_size: int, *, generator: torch.Generator, device: torch.device | str = "cpu"
    ) -> ReplayBatch:
        """``batch_size`` transitions drawn uniformly with replacement."""
        size = len(self)
        if size == 0:
            raise OptionError("cannot sample from an empty replay buffer")
        idx = torch.randint(0, size, (int(batch_size),), generator=generator)
        d = {k: v[idx] for k, v in self._data.items()}

        def obs(prefix: str) -> Observation:
            return Observation(
                d[prefix + "views"].to(torch.float32) / 255.0,
                d[prefix + "step"],
                d[prefix + "corners"],
                d[prefix + "mask"],
                d[prefix + "advice"] if self.advice else None,
            ).to(device)

        return ReplayBatch(
            obs("obs_"),
            d["actions"].to(device),
            d["rewards"].to(device),
            obs("next_"),
            d["dones"].to(device),
            d["expert_actions"].to(device),
            d["expert_valid"].to(device),
        )

    def state_dict(self) -> dict[str, Any]:
        """Contents for a checkpoint (only the filled rows)."""
        n = len(self)
        return {
            "capacity": self.capacity,
            "pos": self.pos,
            "full": self.full,
            "data": {k: v[:n].clone() for k, v in self._data.items()},
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` (the capacity must match)."""
        if int(state["capacity"]) != self.capacity:
            raise OptionError(
                f"checkpoint buffer capacity {state['capacity']} differs from {self.capacity}"
            )
        for k, v in state["data"].items():
            self._data[k][: v.shape[0]] = v
        self.pos = int(state["pos"])
        self.full = bool(state["full"])
