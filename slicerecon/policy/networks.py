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
* **Choice among the expert's cuts** (``NetConfig.candidates = C``): the
  expert's first ``C`` cuts at the state
  (:attr:`~slicerecon.policy.observation.Observation.advice`) join the step
  and corner MLP's input of both networks, and the actor's head scores the
  ``C`` cuts and the stop; its action is the softmax-weighted mean of their
  actions (the stop's is zeros), invalid cuts masked out. The scores start
  at a prior that puts almost all weight on the expert's own cut (the last
  layer is zero at initialisation), so an untrained actor is the expert, its
  stop included, and learning moves weight to another of the expert's cuts
  or to stopping. This restricts the learned planner to choices the expert
  proposes, the way residual policy learning starts from a base controller
  (Silver et al., "Residual Policy Learning", arXiv:1812.06298, 2018).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

from ..errors import OptionError
from .observation import ADVICE_WIDTH, Observation

__all__ = [
    "NetConfig",
    "CoordConv",
    "ViewEncoder",
    "StateEncoder",
    "Actor",
    "Critic",
    "choice_targets",
]

ACTION_DIM = 5
CHOICE_PRIOR = 8.0
"""Initial score of the expert's own cut (the others and the stop start at 0)."""


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
    candidates : int
        ``C``: the networks read the expert's first ``C`` cuts and the actor
        chooses among them and the stop (see the module docstring); 0 (and
        weights files without this field): the paper's free actor.
    """

    resolution: int = 64
    max_corners: int = 16
    channels: int = 16
    hidden: int = 256
    candidates: int = 0

    def __post_init__(self) -> None:
        for name in ("resolution", "max_corners", "channels", "hidden"):
            if int(getattr(self, name)) < 1:
                raise OptionError(f"NetConfig.{name} must be >= 1 (got {getattr(self, name)})")
        if self.resolution < 16:
            raise OptionError(f"resolution must be >= 16 (got {self.resolution})")
        if isinstance(self.candidates, bool) or int(self.candidates) < 0:
            raise OptionError(f"NetConfig.candidates must be >= 0 (got {self.candidates!r})")

    def to_dict(self) -> dict[str, int]:
        """Plain dict of the sizes."""
        return {k: int(v) for k, v in asdict(self).items()}


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
        self.candidates = config.candidates
        self.corners = nn.Sequential(
            nn.Linear(1 + 3 * k * 3 + ADVICE_WIDTH * config.candidates, config.hidden),
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
        if self.candidates:
            inputs.append(_advice(obs, self.candidates).reshape(b, -1))
        corner_in = torch.cat(inputs, dim=1)
        return torch.cat([self.view_proj(v), self.corners(corner_in)], dim=1)


def _advice(obs: Observation, count: int) -> torch.Tensor:
    if obs.advice is None or tuple(obs.advice.shape[1:]) != (count, ADVICE_WIDTH):
        got = None if obs.advice is None else tuple(obs.advice.shape[1:])
        raise OptionError(
            f"this network chooses among the expert's first {count} cuts: build observations "
            f"with candidates={count} (their advice is {got})"
        )
    return obs.advice


class Actor(nn.Module):
    """Deterministic policy ``pi(s)``: 5 numbers in ``[0, 1]``."""

    def __init__(self, config: NetConfig) -> None:
        super().__init__()
        self.config = config
        self.encoder = StateEncoder(config)
        outputs = config.candidates + 1 if config.candidates else ACTION_DIM
        self.head = nn.Sequential(
            nn.Linear(self.encoder.out_features, config.hidden),
            nn.ReLU(),
            nn.Linear(config.hidden, outputs),
        )
        if config.candidates:  # an untrained chooser is the expert
            nn.init.zeros_(self.head[-1].weight)
            nn.init.zeros_(self.head[-1].bias)
            prior = torch.zeros(outputs)
            prior[0] = CHOICE_PRIOR
            self.register_buffer("prior", prior, persistent=False)

    def forward(self, obs: Observation) -> torch.Tensor:
        """Actions, Tensor of shape (B, 5)."""
        return self.outputs(obs)[0]

    def outputs(self, obs: Observation) -> tuple[torch.Tensor, torch.Tensor]:
        """Actions (B, 5) and the raw outputs a penalty should act on.

        The free actor's raw outputs are its pre-sigmoid values (B, 5); a
        chooser's are its learned scores (B, C + 1), without the prior.
        """
        raw = self.head(self.encoder(obs))
        if not self.config.candidates:
            return torch.sigmoid(raw), raw
        advice = _advice(obs, self.config.candidates)
        weights = torch.softmax(self._scores(advice, raw), dim=1)[:, :-1]  # the stop's is zeros
        return torch.einsum("bc,bca->ba", weights, advice[:, :, :ACTION_DIM]), raw

    def choice_scores(self, obs: Observation, raw: torch.Tensor) -> torch.Tensor:
        """A chooser's scores (B, C + 1), the cuts' then the stop's, from its raw outputs.

        ``raw`` is the second output of :meth:`outputs` for ``obs``; the
        scores add the prior and give invalid cuts ``-inf``; the action is the
        softmax-weighted mean of the choices' actions.

        Raises
        ------
        OptionError
            For an actor that is not a chooser (``NetConfig.candidates == 0``).
        """
        if not self.config.candidates:
            raise OptionError("choice_scores needs a chooser (NetConfig.candidates > 0)")
        return self._scores(_advice(obs, self.config.candidates), raw)

    def _scores(self, advice: torch.Tensor, raw: torch.Tensor) -> torch.Tensor:
        return (raw + self.prior).masked_fill(~_choice_valid(advice), float("-inf"))


def _choice_valid(advice: torch.Tensor) -> torch.Tensor:
    """Which choices exist, (B, C + 1) bool: the valid cuts, then the stop (always)."""
    stop = torch.ones_like(advice[:, :1, 5], dtype=torch.bool)
    return torch.cat([advice[:, :, 5] > 0.5, stop], 1)


def choice_targets(advice: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """Which of a state's choices (its ``C`` cuts, then the stop) each action is.

    Parameters
    ----------
    advice : Tensor of shape (B, C, 6)
        :attr:`~slicerecon.policy.observation.Observation.advice`.
    actions : Tensor of shape (B, 5)
        Target actions (the expert's or its lookahead's).

    Returns
    -------
    Tensor of shape (B,), int64
        The index in ``0 .. C`` of the nearest valid choice (``C``: the stop,
        all zeros).
    """
    rows = torch.cat([advice[:, :, :ACTION_DIM], torch.zeros_like(advice[:, :1, :ACTION_DIM])], 1)
    d2 = ((rows - actions[:, None, :]) ** 2).sum(dim=2)
    return d2.masked_fill(~_choice_valid(advice), float("inf")).argmin(dim=1)


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
