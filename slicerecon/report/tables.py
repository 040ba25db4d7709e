"""The report's tables: statistics per group (``summary.json``) and ``metrics.csv``.

Both are computed from :class:`~slicerecon.results.CaseResult` records only;
the numbers are those of each case's ``metrics.json`` (nothing is recomputed).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..results import CaseResult

__all__ = ["metric_names", "metrics_csv_text", "sort_key", "summarize"]


def metric_names(cases: Sequence[CaseResult]) -> list[str]:
    """Every metric key of ``cases``, in the order of first appearance.

    Parameters
    ----------
    cases : sequence of CaseResult

    Returns
    -------
    list of str
    """
    names: dict[str, None] = {}
    for case in cases:
        for key in case.metrics or {}:
            names.setdefault(key, None)
    return list(names)


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _stats(values: Sequence[float]) -> dict[str, float | int | None]:
    data = np.asarray([v for v in values if math.isfinite(v)], dtype=np.float64)
    if data.size == 0:
        return {"n": 0, "mean": None, "median": None, "std": None, "min": None, "max": None}
    return {
        "n": int(data.size),
        "mean": _finite(float(data.mean())),
        "median": _finite(float(np.median(data))),
        "std": _finite(float(data.std(ddof=1))) if data.size > 1 else None,
        "min": _finite(float(data.min())),
        "max": _finite(float(data.max())),
    }


def _group_stats(cases: Sequence[CaseResult], names: Sequence[str]) -> dict[str, Any]:
    ok = [c for c in cases if c.ok]
    return {
        "count": len(cases),
        "failures": len(cases) - len(ok),
        "metrics": {
            name: _stats([c.metrics[name] for c in ok if c.metrics and name in c.metrics])
            for name in names
        },
        "seconds": _stats([s for c in ok if (s := c.stage_seconds) is not None]),
    }


def _structure_groups(cases: Sequence[CaseResult], names: Sequence[str]) -> list[dict[str, Any]]:
    """Statistics per method/planner/structure over the structures of the finished cases."""
    groups: dict[tuple[str | None, str | None, str], list[Any]] = {}
    for case in cases:
        if not case.ok:
            continue
        for record in case.structures:
            name = record.name or record.label
            groups.setdefault((case.method, case.planner, name), []).append(record)
    out = []
    for method, planner, name in sorted(
        groups, key=lambda k: (sort_key(k[0]), sort_key(k[1]), k[2])
    ):
        members = groups[(method, planner, name)]
        out.append(
            {
                "method": method,
                "planner": planner,
                "structure": name,
                "count": len(members),
                "reconstructed": sum(1 for r in members if r.mesh_path is not None),
                "metrics": {
                    key: _stats([r.metrics[key] for r in members if r.metrics and key in r.metrics])
                    for key in names
                },
            }
        )
    return out


def sort_key(value: str | int | None) -> tuple[int, str | int]:
    """Sort key that puts None after every value."""
    return (1, "") if value is None else (0, value)


def summarize(cases: Sequence[CaseResult]) -> dict[str, Any]:
    """Per-group statistics of the metrics (what ``summary.json`` holds).

    Parameters
    ----------
    cases : sequence of CaseResult

    Returns
    -------
    dict
        ``n_cases``, ``n_failures``, ``metrics`` (names), ``groups`` (one
        entry per method/planner: ``method``, ``planner``, ``count`` = cases
        in the group including failures, ``failures``, ``metrics`` =
        ``{name: {n, mean, median, std, min, max}}`` over the finished cases
        that have the metric, ``std`` the sample standard deviation (ddof 1,
        None below two values), ``seconds`` the same statistics of run time
        (the sum of each case's stage timings)), ``by_planes`` (the same per
        method/planner/number of planes), ``structures`` (per
        method/planner/structure name over the structures of the finished
        cases: ``count`` structures, ``reconstructed``, ``metrics`` with the
        same statistics, ``n`` counting structures) and ``failures`` (case,
        method, planner, input, error). A case of several structures counts
        once in ``groups`` and ``by_planes``, with the mean over its
        structures; every statistic has its ``n``. Non-finite values are left
        out of the statistics; absent statistics are None.
    """
    names = metric_names(cases)
    groups: dict[tuple[str | None, str | None], list[CaseResult]] = {}
    by_planes: dict[tuple[str | None, str | None, int | None], list[CaseResult]] = {}
    for case in cases:
        groups.setdefault((case.method, case.planner), []).append(case)
        if case.ok:
            by_planes.setdefault((case.method, case.planner, case.planes), []).append(case)
    return {
        "n_cases": len(cases),
        "n_failures": sum(not c.ok for c in cases),
        "metrics": names,
        "groups": [
            {"method": m, "planner": p, **_group_stats(groups[(m, p)], names)}
            for m, p in sorted(groups, key=lambda k: (sort_key(k[0]), sort_key(k[1])))
        ],
        "by_planes": [
            {"method": m, "planner": p, "planes": n, **_group_stats(by_planes[(m, p, n)], names)}
            for m, p, n in sorted(
                by_planes, key=lambda k: (sort_key(k[0]), sort_key(k[1]), sort_key(k[2]))
            )
        ],
        "structures": _structure_groups(cases, names),
        "failures": [
            {
                "case": c.case,
                "method": c.method,
                "planner": c.planner,
                "input": c.input,
                "error": c.error_text,
            }
            for c in cases
            if not c.ok
        ],
    }


def metrics_csv_text(cases: Sequence[CaseResult]) -> str:
    """``metrics.csv``: one row per case.

    Parameters
    ----------
    cases : sequence of CaseResult

    Returns
    -------
    str
        Columns ``case, structure, method, planner, planes, status`` (``ok`` /
        ``failed``; a structure's row: why it was not reconstructed, when it was
        not), every metric (full precision, empty when absent),
        ``seconds`` (the sum of the stage timings), ``error``. A case with
        several structures has one row per structure (``structure`` is its
        ``<value>_<name>``, ``planes`` the planes holding it) and a row of
        their ``mean`` when they were scored (``planes``: the case's), in the
        order of their values; other cases one row with an empty ``structure``.
    """
    names = metric_names(cases)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(
        ["case", "structure", "method", "planner", "planes", "status", *names, "seconds", "error"]
    )
    for c in cases:
        seconds = c.stage_seconds
        rows = [("", c.metrics or {})]
        own_planes = {s.label: s.planes for s in c.structures}
        own_status = {s.label: s.status for s in c.structures}
        scored = dict(c.structure_metrics or {})
        if scored or len(c.structures) > 1:  # one row per structure (by value), their mean
            labels = [s.label for s in sorted(c.structures, key=lambda s: s.value)]
            labels += sorted(set(scored) - set(labels))
            rows = [(label, scored.get(label, {})) for label in labels]
            rows += [("mean", c.metrics or {})] if scored else []
        for structure, metrics in rows:
            planes = own_planes.get(structure, c.planes) if structure else c.planes
            writer.writerow(
                [
                    c.case,
                    structure,
                    c.method or "",
                    c.planner or "",
                    "" if planes is None else planes,
                    _row_status(c.ok, own_status.get(structure, "")),
                    *(repr(metrics[n]) if n in metrics else "" for n in names),
                    "" if seconds is None else repr(round(seconds, 4)),
                    c.error_text,
                ]
            )
    return buffer.getvalue()


def _row_status(ok: bool, structure: str) -> str:
    """A row's status: the case's (``ok`` / ``failed``), or, in a finished case, why its
    structure was not reconstructed (``structures.json``'s status)."""
    if not ok:
        return "failed"
    return structure if structure and structure != "reconstructed" else "ok"
