"""The report's HTML page, from the jinja2 template ``templates/report.html.j2``.

The template holds the markup; this module gives it what to show: the
summary, the figures (embedded as base64 PNG data URIs, so the page is one
self-contained file), the per-case tables with relative links, the renders and
the failures. Every value is escaped by jinja2's autoescaping.
"""

from __future__ import annotations

import base64
import math
import urllib.parse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from .. import __version__
from ..results import CaseResult
from .figures import CAPTIONS
from .renders import PANEL_PX
from .tables import sort_key

if TYPE_CHECKING:
    import jinja2

__all__ = ["TABLE_METRICS", "Column", "Render", "render_caption", "render_page"]

TEMPLATE = "report.html.j2"


class Column(NamedTuple):
    """A metric column of the HTML tables.

    Attributes
    ----------
    key : str
        The metric's key in ``metrics.json``.
    title : str
        The column title.
    spec : str
        :meth:`str.format` spec of a value.
    """

    key: str
    title: str
    spec: str


TABLE_METRICS = (
    Column("volume_iou", "volume IoU", "{:.3f}"),
    Column("surface_iou", "surface IoU", "{:.3f}"),
    Column("dice", "Dice", "{:.3f}"),
    Column("chamfer_l1_mm", "Chamfer-L1 (mm)", "{:.3f}"),
    Column("chamfer_l1", "Chamfer-L1 / diag", "{:.4f}"),
    Column("f_score", "F-score", "{:.3f}"),
    Column("hd95_mm", "HD95 (mm)", "{:.2f}"),
    Column("assd_mm", "ASSD (mm)", "{:.3f}"),
    Column("volume_error", "volume error", "{:+.3f}"),
)
"""Metrics shown in the HTML tables, in order."""


@dataclass(frozen=True)
class Render:
    """One case's render on the page.

    Attributes
    ----------
    case : CaseResult
        The case.
    png : bytes or None
        The image; None when rendering failed.
    note : str
        Where the ground truth came from and the distance statistics, or why
        the render failed.
    """

    case: CaseResult
    png: bytes | None
    note: str

    @property
    def caption(self) -> str:
        """The figure caption (see :func:`render_caption`)."""
        return render_caption(self.case, self.note)


class _Link(NamedTuple):
    href: str
    text: str


def render_caption(case: CaseResult, note: str) -> str:
    """``"<case> — <method>/<planner>, <n> planes[, <k> structures: …][, volume IoU …]
    [, Chamfer-L1 … mm]; <note>"`` (IoU and Chamfer of several structures: their mean)."""
    metrics = case.metrics or {}
    caption = f"{case.case} — {case.method}/{case.planner}, {case.planes} planes"
    if case.several:
        names = ", ".join(s.label for s in case.structures)
        caption += f", {len(case.structures)} structures ({names})"
        if case.metrics:
            caption += ", metrics: their mean"
    if "volume_iou" in metrics:
        caption += f", volume IoU {metrics['volume_iou']:.3f}"
    if "chamfer_l1_mm" in metrics:
        caption += f", Chamfer-L1 {metrics['chamfer_l1_mm']:.3f} mm"
    return f"{caption}; {note}"


def _fmt(value: float | None, spec: str) -> str:
    if value is None or not math.isfinite(value):
        return "–"
    return spec.format(value)


def _data_uri(data: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


@cache
def _environment() -> jinja2.Environment:
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.PackageLoader("slicerecon.report", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters["fmt"] = _fmt
    env.filters["data_uri"] = _data_uri
    return env


def _href(target: Path, root: Path) -> str:
    return urllib.parse.quote(target.relative_to(root).as_posix())


def _links(case: CaseResult, root: Path) -> list[_Link]:
    """Relative links to the case's mesh (or, for several structures, ``structures.json``:
    each structure's row links its own mesh), preview and plan (or error record)."""
    if case.directory is None:
        return []
    record = case.directory / ("plan.json" if case.ok else "error.json")
    listing = case.directory / "structures.json"
    found = [
        (
            listing if case.several and listing.is_file() else case.mesh_path,
            "structures" if case.several else "mesh",
        ),
        (case.preview_path, "preview"),
        (record, "plan" if case.ok else "error"),
    ]
    return [_Link(_href(target, root), text) for target, text in found if target is not None]


def _structure_rows(case: CaseResult, root: Path) -> list[dict[str, Any]]:
    """One row per structure of a case of several: label, status, planes, metrics, mesh link."""
    if not case.several:
        return []
    return [
        {
            "label": s.label,
            "status": s.status,
            "planes": s.planes,
            "metrics": s.metrics or {},
            "mesh": None if s.mesh_path is None else _href(s.mesh_path, root),
        }
        for s in case.structures
    ]


def render_page(
    *,
    title: str,
    cases: Sequence[CaseResult],
    summary: Mapping[str, Any],
    figures: Mapping[str, bytes],
    renders: Sequence[Render],
    root: Path,
    render_note: str,
) -> str:
    """The report page.

    Parameters
    ----------
    title : str
        Page title (escaped).
    cases : sequence of CaseResult
        Every case, sorted by name.
    summary : mapping
        :func:`~slicerecon.report.tables.summarize` of ``cases``.
    figures : mapping of str to bytes
        Summary figures by name (keys of :data:`~slicerecon.report.figures.CAPTIONS`).
    renders : sequence of Render
        The per-case renders, in order.
    root : Path
        The results folder (links are relative to it).
    render_note : str
        A note above the renders (empty for none).

    Returns
    -------
    str
        The HTML document.
    """

    names = summary["metrics"]
    methods = sorted({c.method for c in cases}, key=sort_key)
    context = {
        "title": title,
        "summary": summary,
        "n_ok": summary["n_cases"] - summary["n_failures"],
        "methods": sorted({c.method or "?" for c in cases}),
        "version": __version__,
        "has_metrics": bool(names),
        "columns": [c for c in TABLE_METRICS if c.key in names],
        "figures": [
            {"name": name, "png": png, "caption": CAPTIONS[name]} for name, png in figures.items()
        ],
        "case_tables": [
            {"method": m, "cases": [c for c in cases if c.method == m]} for m in methods
        ],
        "links": {c.case: _links(c, root) for c in cases},
        "structure_rows": {c.case: _structure_rows(c, root) for c in cases},
        "n_several": sum(1 for c in cases if c.ok and c.several),
        "renders": renders,
        "render_note": render_note,
        "failures": [c for c in cases if not c.ok],
        "warned": [c for c in cases if c.ok and c.warnings],
        "panel_px": PANEL_PX,
    }
    return _environment().get_template(TEMPLATE).render(context)
