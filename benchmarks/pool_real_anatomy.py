"""Pool the real-anatomy protocol's CSV over the section axes: the tables of ``docs/results.md``.

Reads the CSV that ``benchmarks/real_anatomy.py`` writes and prints two markdown
tables: per half and plane count, every case-axis pooled (the default against
plain SDF, and the paper's loft and ITK-MCI against plain SDF over the
case-axes where they made a closed mesh), and the default's mean volume IoU
per axis on the validation half (over the cases where every variant made a
mesh, as in ``benchmarks/real_anatomy.py``'s summary). A win / loss is the
CSV's own ``vs_baseline`` (a volume IoU beyond ±0.005 of plain SDF's)::

    python benchmarks/pool_real_anatomy.py docs/data/real_anatomy.csv
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections.abc import Sequence
from pathlib import Path

BASELINE = "sdf-plain"


def _fmt(value: float, digits: int = 3, *, signed: bool = False) -> str:
    return f"{value:+.{digits}f}" if signed else f"{value:.{digits}f}"


def _mean(values: Sequence[float]) -> float:
    return sum(values) / len(values)


def _record(rows: list[dict[str, str]]) -> str:
    counts = [sum(r["vs_baseline"] == k for r in rows) for k in ("win", "tie", "loss")]
    return " / ".join(str(c) for c in counts)


def pooled_lines(rows: list[dict[str, str]]) -> list[str]:
    """Per half and plane count, every axis pooled."""
    out = [
        "| half | planes | cases | plain SDF IoU | default IoU | default ΔIoU | W / T / L "
        "| worst Δ | default Chamfer / HD95 mm (plain) | loft + heuristic ΔIoU, W / T / L "
        "| ITK-MCI ΔIoU, W / T / L |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    settings = sorted({(r["half"], int(r["planes"])) for r in rows})
    for half, planes in settings:
        group = [r for r in rows if r["half"] == half and int(r["planes"]) == planes]
        ok = {
            v: {(r["case"], r["axis"]): r for r in group if r["variant"] == v and not r["error"]}
            for v in (BASELINE, "default", "loft-heuristic", "itk-mci")
        }
        keys = sorted(ok[BASELINE].keys() & ok["default"].keys())
        base = [ok[BASELINE][k] for k in keys]
        default = [ok["default"][k] for k in keys]
        deltas = [float(r["d_iou"]) for r in default]
        cells = [
            half,
            str(planes),
            str(len(keys)),
            _fmt(_mean([float(r["volume_iou"]) for r in base])),
            _fmt(_mean([float(r["volume_iou"]) for r in default])),
            _fmt(_mean(deltas), signed=True),
            _record(default),
            _fmt(min(deltas), signed=True),
            f"{_fmt(_mean([float(r['chamfer_l1_mm']) for r in default]))} / "
            f"{_fmt(_mean([float(r['hd95_mm']) for r in default]), 2)} "
            f"({_fmt(_mean([float(r['chamfer_l1_mm']) for r in base]))} / "
            f"{_fmt(_mean([float(r['hd95_mm']) for r in base]), 2)})",
        ]
        for variant in ("loft-heuristic", "itk-mci"):
            mine = [ok[variant][k] for k in sorted(ok[variant].keys() & ok[BASELINE].keys())]
            d_iou = _mean([float(r["d_iou"]) for r in mine])
            cells.append(f"{_fmt(d_iou, signed=True)}, {_record(mine)}")
        out.append("| " + " | ".join(cells) + " |")
    return out


def per_axis_lines(rows: list[dict[str, str]], half: str = "val") -> list[str]:
    """The default's mean volume IoU (ΔIoU to plain SDF) per plane count and axis.

    Over the cases on which every variant made a mesh, as in the summary that
    ``benchmarks/real_anatomy.py`` prints.
    """
    axes = sorted({r["axis"] for r in rows})
    out = ["| planes | " + " | ".join(axes) + " |", "|---|" + "---|" * len(axes)]
    for planes in sorted({int(r["planes"]) for r in rows if r["half"] == half}):
        cells = []
        for axis in axes:
            group = [
                r for r in rows if (r["half"], r["axis"], int(r["planes"])) == (half, axis, planes)
            ]
            failed = {r["case"] for r in group if r["error"]}
            mine = [r for r in group if r["variant"] == "default" and r["case"] not in failed]
            iou = _mean([float(r["volume_iou"]) for r in mine])
            d_iou = _mean([float(r["d_iou"]) for r in mine])
            cells.append(f"{_fmt(iou)} ({_fmt(d_iou, signed=True)})")
        out.append(f"| {planes} | " + " | ".join(cells) + " |")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "csv", type=Path, nargs="?", default=Path("docs/data/real_anatomy.csv"), help="input CSV"
    )
    args = parser.parse_args(argv)
    with args.csv.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    print("\n".join(pooled_lines(rows)))
    print()
    print("\n".join(per_axis_lines(rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
