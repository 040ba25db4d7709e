"""The report's summary figures (matplotlib, Agg backend): box plots and IoU against planes.

Every figure is returned as PNG bytes (256 colours, no version stamp), so the
same cases give the same bytes.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..results import CaseResult

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "BOX_METRICS",
    "CAPTIONS",
    "box_plot",
    "group_labels",
    "planes_plot",
    "png_bytes",
    "pyplot",
]

_PNG_METADATA = {"Software": None}
"""Drop matplotlib's version stamp so PNGs only depend on what they show."""

BOX_METRICS = (
    ("volume_iou", "volume IoU"),
    ("surface_iou", "surface IoU"),
    ("chamfer_l1_mm", "Chamfer-L1 (mm)"),
)
"""Metrics of the box plots: key, panel title."""

CAPTIONS = {
    "boxplots": "Volume IoU, surface IoU and Chamfer-L1 per method (box: quartiles, "
    "line: median, triangle: mean, dots: cases; n: the cases with the metric, a case of "
    "several structures counting once with their mean).",
    "iou_vs_planes": "IoU against the number of section planes (line: mean per count; n: "
    "the cases of each method).",
}
"""Caption of each summary figure, by name."""


def pyplot() -> Any:
    """:mod:`matplotlib.pyplot` on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def png_bytes(fig: Figure, *, dpi: int = 80) -> bytes:
    """The figure as a 256-colour PNG (a third of the size of matplotlib's RGBA PNG).

    The figure is closed.
    """
    from PIL import Image

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, metadata=_PNG_METADATA)
    pyplot().close(fig)
    buffer.seek(0)
    with Image.open(buffer) as image:
        palette = image.convert("RGB").quantize(colors=256, method=Image.Quantize.FASTOCTREE)
    out = io.BytesIO()
    palette.save(out, format="png", optimize=True)
    return out.getvalue()


def group_labels(cases: Sequence[CaseResult]) -> dict[str, list[CaseResult]]:
    """Finished cases grouped by method (by method/planner when a method has several).

    Parameters
    ----------
    cases : sequence of CaseResult

    Returns
    -------
    dict of str to list of CaseResult
        Sorted by label.
    """
    planners: dict[str | None, set[str | None]] = {}
    for c in cases:
        planners.setdefault(c.method, set()).add(c.planner)
    grouped: dict[str, list[CaseResult]] = {}
    for c in cases:
        if not c.ok:
            continue
        label = c.method or "?"
        if len(planners[c.method]) > 1:
            label = c.group
        grouped.setdefault(label, []).append(c)
    return dict(sorted(grouped.items()))


def box_plot(cases: Sequence[CaseResult]) -> bytes | None:
    """Box plots of volume IoU, surface IoU and Chamfer-L1 per method.

    Parameters
    ----------
    cases : sequence of CaseResult

    Returns
    -------
    bytes or None
        The PNG; None when no finished case has any of the metrics.
    """
    grouped = group_labels(cases)
    panels = [
        (key, title)
        for key, title in BOX_METRICS
        if any(c.metrics and key in c.metrics for g in grouped.values() for c in g)
    ]
    if not panels:
        return None
    plt = pyplot()
    labels = list(grouped)
    width = max(3.2, 0.55 * len(labels) + 1.4)
    fig, axes = plt.subplots(1, len(panels), figsize=(width * len(panels), 3.6), squeeze=False)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.16, top=0.9, wspace=0.3)
    for ax, (key, title) in zip(axes[0], panels, strict=True):
        data = [
            [
                v
                for c in grouped[label]
                if c.metrics and math.isfinite(v := c.metrics.get(key, math.nan))
            ]
            for label in labels
        ]
        ticks = [f"{label}\nn={len(values)}" for label, values in zip(labels, data, strict=True)]
        ax.boxplot(data, tick_labels=ticks, showmeans=True)
        for i, values in enumerate(data, start=1):
            ax.plot(np.full(len(values), float(i)), values, "o", ms=3, alpha=0.5, color="tab:blue")
        ax.set_title(title, fontsize=10)
        ax.tick_params(axis="x", labelrotation=30, labelsize=8)
        ax.tick_params(axis="y", labelsize=8)
        ax.grid(axis="y", alpha=0.3)
    return png_bytes(fig)


def planes_plot(cases: Sequence[CaseResult]) -> bytes | None:
    """Volume and surface IoU against the number of section planes, per method.

    Parameters
    ----------
    cases : sequence of CaseResult

    Returns
    -------
    bytes or None
        The PNG; None when the finished cases with a volume IoU use fewer
        than two different numbers of planes.
    """
    grouped = group_labels(cases)
    plane_counts = {
        c.planes
        for g in grouped.values()
        for c in g
        if c.planes is not None and c.metrics and "volume_iou" in c.metrics
    }
    if len(plane_counts) < 2:
        return None
    plt = pyplot()
    keys = [(k, t) for k, t in BOX_METRICS if k.endswith("iou")]
    fig, axes = plt.subplots(1, len(keys), figsize=(4.2 * len(keys), 3.6), squeeze=False)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.14, top=0.9, wspace=0.3)
    for ax, (key, title) in zip(axes[0], keys, strict=True):
        for i, (label, members) in enumerate(grouped.items()):
            pts = sorted(
                (c.planes, c.metrics[key])
                for c in members
                if c.planes is not None
                and c.metrics
                and math.isfinite(c.metrics.get(key, math.nan))
            )
            if not pts:
                continue
            colour = f"C{i % 10}"
            xs, ys = np.array(pts, dtype=np.float64).T
            ax.plot(xs, ys, "o", ms=3, alpha=0.35, color=colour)
            levels = np.unique(xs)
            means = [float(ys[xs == x].mean()) for x in levels]
            ax.plot(levels, means, "-o", ms=4, color=colour, label=f"{label} (n={len(pts)})")
        ax.set_xlabel("number of planes", fontsize=9)
        ax.set_ylabel(title, fontsize=9)
        ax.set_title(f"{title} against number of planes", fontsize=9)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
        ax.legend(fontsize=8)
    return png_bytes(fig)
