"""Slanted rods whose discs move between planes: one piece or one disc per plane?

A rod of radius 5 mm along z, its axis moving by ``SHIFT`` mm along x per 4 mm
between planes (1 mm voxels, 9 planes). At 12 mm per plane consecutive discs
do not overlap: a pixel-wise blend of signed distances closes each disc off
half-way, and so does ITK's morphological contour interpolation. Each method
reconstructs from the same planes, with silhouettes from the dense mask
(``gt``) or derived from the sections (``sections``, what contour users have);
the table gives volume IoU against the rod and the number of connected pieces.
It is printed (``--out FILE`` also writes it; ``docs/results.md`` shows it)::

    python benchmarks/drifting_rod.py
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from slicerecon.errors import DependencyError
from slicerecon.rasterize import mesh_to_mask
from slicerecon.reconstruct import PLAIN_SDF, reconstruct
from slicerecon.sampling import projections_from_sections, projections_from_volume
from slicerecon.sections import CrossSections, Volume
from slicerecon.shapes.primitives import slanted_rod

RADIUS_MM = 5.0
PLANE_GAP = 4
SHIFTS_MM = (4.0, 8.0, 12.0)
METHODS: dict[str, dict[str, object]] = {
    "plain SDF": PLAIN_SDF.to_dict(),
    "ITK-MCI": {"method": "itk-mci", "planner": "none"},
    "loft + heuristic": {"method": "loft"},
    "default, no join": {"join_drift": False},
    "default": {},
}


def rod(shift_mm: float) -> Volume:
    """The rod for a shift of ``shift_mm`` per plane gap, on a grid that holds it."""
    slope = shift_mm / PLANE_GAP
    depth = 40
    shape = (int(np.ceil(16 + slope * depth)), 30, depth)
    return slanted_rod(radius=RADIUS_MM, slope=slope, shape=shape, start=8.0)


def sections_of(volume: Volume) -> CrossSections:
    planes = list(range(4, volume.shape[2] - 3, PLANE_GAP))
    masks = np.stack([volume.mask[:, :, p] for p in planes])
    return CrossSections(masks, np.asarray(planes, float), 2, volume.affine, volume.shape)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="markdown file to write")
    args = parser.parse_args(argv)
    lines = [
        "| shift per plane (mm) | silhouettes | "
        + " | ".join(f"{m} IoU (pieces)" for m in METHODS)
        + " |",
        "|---|---|" + "---|" * len(METHODS),
    ]
    for shift in SHIFTS_MM:
        volume = rod(shift)
        sections = sections_of(volume)
        for source in ("gt", "sections"):
            if source == "gt":
                projections = projections_from_volume(volume)
            else:
                projections = projections_from_sections(sections)
            cells = []
            for name, options in METHODS.items():
                try:
                    mesh = reconstruct(sections, projections, **options).mesh  # type: ignore[arg-type]
                except DependencyError:
                    cells.append("n/a")
                    continue
                pred = mesh_to_mask(mesh, volume.affine, volume.shape)
                iou = (pred & volume.mask).sum() / (pred | volume.mask).sum()
                pieces = len(mesh.split(only_watertight=False))
                cells.append(f"{iou:.3f} ({pieces})")
                print(f"{shift:4.0f} mm {source:8s} {name:18s} {cells[-1]}", file=sys.stderr)
            lines.append(f"| {shift:.0f} | {source} | " + " | ".join(cells) + " |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(
            "# Slanted rods\n\n```bash\npython benchmarks/drifting_rod.py --out "
            f"{args.out.as_posix()}\n```\n\n{text}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
