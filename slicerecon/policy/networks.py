"""Actor and critic networks of the learned cut planner.

Both networks read an :class:`~slicerecon.policy.observation.Observation` through the
same architecture (separate weights):

* **Views**: each of the three silhouettes ``(R, R)`` gets two CoordConv
  channels (normalised row and column coordinates in ``[-1, 1]``) and goes
  through one small convolutional encoder shared by the three views
  (a 4x4 stride-4 "patchify" CoordConv, a stride-2 and a stride-1 3x3
  convolution, then adaptive average pooling to 4x4, so the encoder works at
  any ``R >= 16``; the stride-4 first layer keeps a CPU update cheap); the three feature vectors are
  concatenated in view order, which keeps the view identity.
* **Step and corners**: the step ``t / T`` and the corner list
  ``(3, K, 2)`` with its validity mask ``(3, K)`` are flattened into one MLP.
* **Actor** ``pi(s)``: an MLP on the joined features, 5 sigmoid outputs in ``[0, 1]``.
* **Advice** (``NetConfig.advice``): the heuristic expert's action at the
  state (:attr:`~slicerecon.policy.observation.Observation.advice`) joins the step and
  corner MLP's input of both networks, and the actor is *residual*: its
  pre-sigmoid outputs are ``logit(advice) + r(s)`` with the last layer of
  ``r`` zero at initialisation, so an untrained actor is the expert (its stop
  included) and learning moves it only where the critic finds better cuts
  (residual policy learning: Silver et al., "Residual Policy Learning",
  arXiv:1812.06298, 2018; Johannink et al., "Residual Reinforcement Learning
  for Robot Control", ICRA 2019).
* **Critic** ``Q(s, a)``: the joined features and the action through an MLP, one output.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

from ..errors import OptionError
from .observation import Observation

__all__ = ["NetConfig", "CoordConv", "ViewEncoder", "StateEncoder", "Actor", "Critic"]

ACTION_DIM = 5
ADVICE_DIM = 6
ADVICE_EPS = 0.01
"""The expert's action is clipped to ``[eps, 1 - eps]`` before its logit."""


@dataclass(frozen=True)
class NetConfig:
    """Sizes of the networks (stored with shipped weights).

    Attributes
    ----------
    resolution : int
        Side ``R`` of the silhouettes.
    max_corners : int
        Corners per view ``K``.
    channels : int
        Channels of the first convolution (doubled once).
    hidden : int
        Width of the MLP layers.
    advice : bool
        The networks read the expert's action and the actor is residual on it
        (see the module docstring). Weights files without this field are not.
    """

    resolution: int = 64
    max_corners: int = 16
    channels: int = 16
    hidden: int = 256
    advice: bool = False

    def __post_init__(self) -> None:
        for name in ("resolution", "max_corners", "channels", "hidden"):
            if int(getattr(self, name)) < 1:
                raise OptionError(f"NetConfig.{name} must be >= 1 (got {getattr(self, name)})")
        if self.resolution < 16:
            raise OptionError(f"resolution must be >= 16 (got {self.resolution})")
        object.__setattr__(self, "advice", bool(self.advice))

    def to_dict(self) -> dict[str, int | bool]:
        """Plain dict of the sizes (and ``advice``)."""
        return {k: (v if isinstance(v, bool) else int(v)) for k, v in asdict(self).items()}


class CoordConv(nn.Module):
    """A 2-D convolution whose input gets two extra channels: normalised row and column.

    Parameters
    ----------
    in_channels, out_channels : int
        Channels before the coordinate channels are added, and after the convolution.
    **conv_kwargs
        Passed to :class:`torch.nn.Conv2d` (kernel_size, stride, padding).
    """

    def __init__(self, in_channels: int, out_channels: int, **conv_kwargs: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_channels + 2, out_channels, **conv_kwargs)  # type: ignore[arg-type]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x: Tensor of shape (N, C, H, W) → (N, C_out, H', W')."""
        n, _, h, w = x.shape
        rows = torch.linspace(-1.0, 1.0, h, device=x.device, dtype=x.dtype)
        cols = torch.linspace(-1.0, 1.0, w, device=x.device, dtype=x.dtype)
        rr = rows.view(1, 1, h, 1).expand(n, 1, h, w)
        cc = cols.view(1, 1, 1, w).expand(n, 1, h, w)
        return self.conv(torch.cat([x, rr, cc], dim=1))


class ViewEncoder(nn.Module):
    """Conv encoder of one silhouette: (N, 1, R, R) → (N, 2 * channels * 16)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        c = int(channels)
        self.net = nn.Sequential(
            CoordConv(1, c, kernel_size=4, stride=4),
            nn.ReLU(),
            nn.Conv2d(c, 2 * c, kernel_size=3, stride=2, padding=1),
            nn.ReLU(),
            nn.Conv2d(2 * c, 2 * c, kernel_size=3, padding=1),
            nn.ReLU(),
        )
        self.out_features = 2 * c * 16

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x: Tensor of shape (N, 1, R, R)."""
        y = self.net(x)
        if tuple(y.shape[-2:]) != (4, 4):
            y = F.adaptive_avg_pool2d(y, 4)
        return y.flatten(1)


class StateEncoder(nn.Module):
    """Features of an observation: three encoded views + the step/corner MLP."""

    def __init__(self, config: NetConfig) -> None:
        super().__init__()
        self.config = config
        self.views = ViewEncoder(config.channels)
        k = config.max_corners
        self.advice = config.advice
        self.corners = nn.Sequential(
            nn.Linear(1 + 3 * k * 3 + (ADVICE_DIM if config.advice else 0), config.hidden),
            nn.ReLU(),
            nn.Linear(config.hidden, config.hidden),
            nn.ReLU(),
        )
        self.view_proj = nn.Sequential(
            nn.Linear(3 * self.views.out_features, config.hidden), nn.ReLU()
        )
        self.out_features = 2 * config.hidden

    def forward(self, obs: Observation) -> torch.Tensor:
        """Features, Tensor of shape (B, 2 * hidden)."""
        b = obs.views.shape[0]
        r = obs.views.shape[-1]
        v = self.views(obs.views.reshape(b * 3, 1, r, r)).reshape(b, -1)
        inputs = [obs.step, obs.corners.reshape(b, -1), obs.corner_mask.reshape(b, -1)]
        if self.advice:
            inputs.append(_advice(obs))
        corner_in = torch.cat(inputs, dim=1)
        return torch.cat([self.view_proj(v), self.corners(corner_in)], dim=1)


def _advice(obs: Observation) -> torch.Tensor:
    if obs.advice is None:
        raise OptionError(
            "this network takes the expert's advice: build observations with advice=True"
        )
    return obs.advice


class Actor(nn.Module):
    """Deterministic policy ``pi(s)``: 5 numbers in ``[0, 1]``."""

    def __init__(self, config: NetConfig) -> None:
        super().__init__()
        self.config = config
        self.encoder = StateEncoder(config)
        self.head = nn.Sequential(
            nn.Linear(self.encoder.out_features, config.hidden),
            nn.ReLU(),
            nn.Linear(config.hidden, ACTION_DIM),
        )
        if config.advice:  # an untrained residual actor is the expert
            nn.init.zeros_(self.head[-1].weight)
            nn.init.zeros_(self.head[-1].bias)

    def forward(self, obs: Observation) -> torch.Tensor:
        """Actions, Tensor of shape (B, 5)."""
        return torch.sigmoid(self.logits(obs))

    def logits(self, obs: Observation) -> torch.Tensor:
        """Pre-sigmoid outputs, Tensor of shape (B, 5)."""
        return self.outputs(obs)[0]

    def outputs(self, obs: Observation) -> tuple[torch.Tensor, torch.Tensor]:
        """Pre-sigmoid outputs and the network's own part of them, both (B, 5).

        Without advice the two are the same; with it the second is the
        residual ``r(s)`` added to the expert's logits (what a penalty on the
        outputs should act on).
        """
        free = self.head(self.encoder(obs))
        if not self.config.advice:
            return free, free
        expert = _advice(obs)[:, :ACTION_DIM].clamp(ADVICE_EPS, 1.0 - ADVICE_EPS)
        return torch.logit(expert) + free, free


class Critic(nn.Module):
    """Action value ``Q(s, a)``."""

    def __init__(self, config: NetConfig) -> None:
        super().__init__()
        self.config = config
        self.encoder = StateEncoder(config)
        self.head = nn.Sequential(
            nn.Linear(self.encoder.out_features + ACTION_DIM, config.hidden),
            nn.ReLU(),
            nn.Linear(config.hidden, config.hidden),
            nn.ReLU(),
            nn.Linear(config.hidden, 1),
        )

    def forward(self, obs: Observation, action: torch.Tensor) -> torch.Tensor:
        """Q values, Tensor of shape (B,)."""
        return self.q(self.encoder(obs), action)

    def q(self, features: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Q values from precomputed state features (``encoder(obs)``), Tensor of shape (B,)."""
        return self.head(torch.cat([features, action], dim=1)).squeeze(1)
