"""What the learned planner sees: :class:`Observation` and its encoders.

An observation of a partition state holds the three silhouettes of the
remaining region resized to ``R x R`` (:func:`resize_views`), the step
``t / max_steps``, per view the ``K`` strongest Harris corners normalised to
``[0, 1]`` (:func:`~slicerecon.corners.pad_corners`) with a validity mask,
and, for actors that choose among them, the heuristic expert's first cuts
at the state (:func:`advice_rows`). :class:`~slicerecon.policy.env.CutEnv` builds
batches of them in training; :func:`observe_state` builds one from a numpy
:class:`~slicerecon.partition.state.PartitionState` at inference, with the
same encoding.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F
from numpy.typing import NDArray

from ..corners import harris_corners, pad_corners
from ..errors import OptionError
from ..partition.cuts import Cut, cut_to_action
from ..partition.heuristic import expert_cuts
from ..partition.state import PartitionState

__all__ = [
    "ADVICE_WIDTH",
    "Observation",
    "resize_views",
    "padded_corners",
    "advice_rows",
    "observe_state",
]

ADVICE_WIDTH = 6
"""Numbers per row of :attr:`Observation.advice`: a cut's action (5) and its validity."""


class Observation(NamedTuple):
    """A batch of policy states.

    Attributes
    ----------
    views : Tensor of shape (B, 3, R, R), float32
        Silhouettes of the remaining region in ``[0, 1]`` (view ``a`` along grid axis ``a``).
    step : Tensor of shape (B, 1), float32
        ``step_count / max_steps``.
    corners : Tensor of shape (B, 3, K, 2), float32
        Corner points per view, ``((row + .5) / M, (col + .5) / N)``; invalid rows 0.
    corner_mask : Tensor of shape (B, 3, K), float32
        1 for the rows that hold a corner.
    advice : Tensor of shape (B, C, 6), float32, or None
        The heuristic expert's first ``C`` cuts at this state, best first, as
        actions with a validity flag (``(x1, y1, x2, y2, c, 1)``; zero rows
        where it has fewer), for actors that choose among them
        (:attr:`~slicerecon.policy.networks.NetConfig.candidates`); None otherwise.
    """

    views: torch.Tensor
    step: torch.Tensor
    corners: torch.Tensor
    corner_mask: torch.Tensor
    advice: torch.Tensor | None = None

    def to(self, device: torch.device | str) -> Observation:
        """The same observation on ``device``."""
        return Observation(*(None if t is None else t.to(device) for t in self))

    def select(self, idx: torch.Tensor | slice) -> Observation:
        """Rows ``idx`` of every field."""
        return Observation(*(None if t is None else t[idx] for t in self))

    @staticmethod
    def cat(parts: Sequence[Observation]) -> Observation:
        """Concatenate batches along the first axis."""
        fields = list(zip(*parts, strict=True))
        if any(f is None for f in fields[-1]) and not all(f is None for f in fields[-1]):
            raise OptionError("cannot concatenate observations with and without advice")
        return Observation(*(None if column[0] is None else torch.cat(column) for column in fields))


def resize_views(images: torch.Tensor, resolution: int) -> torch.Tensor:
    """Resize silhouettes to ``resolution x resolution`` (antialiased bilinear).

    Parameters
    ----------
    images : Tensor of shape (B, M, N), bool or float
    resolution : int

    Returns
    -------
    Tensor of shape (B, R, R), float32 in [0, 1]
    """
    x = images.to(torch.float32).unsqueeze(1)
    if tuple(x.shape[-2:]) != (resolution, resolution):
        x = F.interpolate(
            x,
            size=(resolution, resolution),
            mode="bilinear",
            align_corners=False,
            antialias=True,
        )
    return x.squeeze(1).clamp_(0.0, 1.0)


_CORNER_CACHE: OrderedDict[tuple[bytes, tuple[int, ...], int], NDArray[np.float64]] = OrderedDict()
_CORNER_CACHE_SIZE = 8192


def _cached_corners(image: NDArray[np.bool_], k: int) -> NDArray[np.float64]:
    """:func:`harris_corners` memoised on the silhouette's bits (episodes repeat shapes)."""
    key = (np.packbits(image).tobytes(), image.shape, k)
    hit = _CORNER_CACHE.get(key)
    if hit is not None:
        _CORNER_CACHE.move_to_end(key)
        return hit
    corners = harris_corners(image, max_corners=k)[:k]
    corners.setflags(write=False)
    _CORNER_CACHE[key] = corners
    if len(_CORNER_CACHE) > _CORNER_CACHE_SIZE:
        _CORNER_CACHE.popitem(last=False)
    return corners


def padded_corners(
    image: NDArray[np.bool_], k: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Pixel corners (K, 2), their :func:`pad_corners` encoding (K, 2) and validity (K,)."""
    corners = _cached_corners(image, k)
    px = np.zeros((k, 2), dtype=np.float64)
    px[: len(corners)] = corners
    norm, valid = pad_corners(corners, n_max=k, image_shape=image.shape)
    return px, norm, valid


# -- environment ------------------------------------------------------------------------


def advice_rows(
    cuts: Sequence[Cut], image_shapes: Sequence[Sequence[int]], count: int
) -> NDArray[np.float32]:
    """Cuts as :attr:`Observation.advice` rows of one state.

    Parameters
    ----------
    cuts : sequence of Cut
        The expert's cuts, best first (at most ``count`` are used).
    image_shapes : sequence of 3 (M, N)
        The views' shapes (:func:`~slicerecon.partition.cuts.view_shapes`).
    count : int
        Rows ``C``.

    Returns
    -------
    ndarray of shape (C, 6), float32
        ``(x1, y1, x2, y2, c, 1)`` per cut
        (:func:`~slicerecon.partition.cuts.cut_to_action`), zero rows after them.
    """
    out = np.zeros((int(count), ADVICE_WIDTH), dtype=np.float32)
    for row, cut in enumerate(list(cuts)[: int(count)]):
        out[row, :5] = cut_to_action(cut, image_shapes)
        out[row, 5] = 1.0
    return out


def observe_state(
    state: PartitionState,
    *,
    resolution: int,
    max_corners: int,
    max_steps: int,
    candidates: int = 0,
    device: str | torch.device = "cpu",
) -> Observation:
    """The policy's observation of a numpy :class:`PartitionState` (batch of one).

    The same encoding as :meth:`CutEnv.observation`: silhouettes resized to
    ``resolution`` (:func:`resize_views`, each view on its own), the step over
    ``max_steps`` and the padded, normalised corners
    (:meth:`PartitionState.padded_corners`). ``state.max_corners`` should equal
    ``max_corners`` (the strongest corners are kept). With ``candidates > 0``,
    also the expert's first cuts at the state
    (:func:`~slicerecon.partition.heuristic.expert_cuts`, :func:`advice_rows`).
    """
    views = torch.stack(
        [
            resize_views(torch.from_numpy(np.ascontiguousarray(v))[None], resolution)[0]
            for v in state.projections()
        ]
    )[None]
    pts, valid = state.padded_corners(int(max_corners))
    step = torch.tensor([[state.step_count / max(int(max_steps), 1)]], dtype=torch.float32)
    corners = torch.from_numpy(pts * valid[..., None]).to(torch.float32)[None]
    mask = torch.from_numpy(valid.astype(np.float32))[None]
    hint = None
    if candidates:
        cuts = expert_cuts(state, int(candidates))
        hint = torch.from_numpy(advice_rows(cuts, state.image_shapes, int(candidates)))[None]
    return Observation(views, step, corners, mask, hint).to(device)
