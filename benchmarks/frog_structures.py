"""pyvista's 15 frog tissues reconstructed in one run: per-label quality and cost.

The label map ``frog_tissues.vti`` (inside the installed pyvista package; read
by slicerecon's own VTI reader) holds 15 tissues (labels 1-15) and a few
hundred stray voxels with labels 16-29, which are left out here. The script

* runs :func:`slicerecon.case.reconstruct_structures` on labels 1-15 at
  ``--planes`` planes along z, chosen once over their union, and scores each
  tissue's joint share against its own mask (:func:`slicerecon.metrics.evaluate`);
* reconstructs each tissue on the same planes by plain signed-distance
  interpolation (linear, one part, no carve) as the baseline;
* times the joint run against the sum of 15 single-structure runs of the
  default pipeline on the same planes (each on its own crop, as ``slicerecon
  run --label N`` would);

and prints a markdown table (``--out FILE`` also writes it; ``docs/results.md``
shows it)::

    python benchmarks/frog_structures.py --planes 24
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from slicerecon.case import crop_to_structure, reconstruct_structures
from slicerecon.io.labelmap import read_label_map
from slicerecon.metrics import evaluate
from slicerecon.realshapes import FROG_TISSUES, frog_tissues_path
from slicerecon.reconstruct import PLAIN_SDF, reconstruct
from slicerecon.sections import CrossSections, Volume

NAMES = {v: k for k, v in FROG_TISSUES.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--planes", type=int, default=24)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args(argv)

    label_map = read_label_map(frog_tissues_path()).select(
        list(range(1, 16)), source="frog_tissues.vti"
    )
    start = time.perf_counter()
    joint = reconstruct_structures(label_map, slices=args.planes)
    joint_seconds = time.perf_counter() - start
    sections = joint.sections
    planes = np.rint(sections.indices).astype(int)

    rows, single_seconds = [], 0.0
    for item in joint.results:
        value = item.structure.value
        truth = joint.truth_mask(value)
        own = CrossSections(
            np.moveaxis(truth.mask, 2, 0)[planes],
            sections.indices,
            2,
            sections.affine,
            sections.grid_shape,
        )
        if item.mesh is None or not own.masks.any():
            rows.append((value, item.status, None, None, None))
            continue
        score = evaluate(item.mesh, truth, pred_occupancy=item.occupancy, n_points=20_000)
        sub, projections, _ = crop_to_structure(own, truth.mask)
        t0 = time.perf_counter()
        reconstruct(sub, projections)
        single_seconds += time.perf_counter() - t0
        plain = reconstruct(sub, projections, PLAIN_SDF)
        crop = Volume(truth.mask, sections.affine)
        plain_score = evaluate(plain.mesh, crop, n_points=20_000)
        rows.append((value, item.status, score.volume_iou, plain_score.volume_iou, score.hd95_mm))
        print(
            f"{NAMES[value]}: IoU {score.volume_iou:.3f} (plain {plain_score.volume_iou:.3f})",
            file=sys.stderr,
            flush=True,
        )

    lines = [
        f"Measured by `python benchmarks/frog_structures.py {shlex.join(argv or sys.argv[1:])}`: "
        f"pyvista's frog tissues 1-15, {args.planes} planes along z chosen once over their "
        f"union, grid {'x'.join(map(str, sections.grid_shape))}.",
        "",
        "| label | tissue | status | volume IoU (joint) | plain SDF IoU | difference | HD95 (mm) |",
        "|---|---|---|---|---|---|---|",
    ]
    done = [r for r in rows if r[2] is not None]
    for value, status, iou, plain, hd95 in rows:
        if iou is None:
            lines.append(f"| {value} | {NAMES[value]} | {status} | - | - | - | - |")
            continue
        lines.append(
            f"| {value} | {NAMES[value]} | {status} | {iou:.3f} | {plain:.3f} | "
            f"{iou - plain:+.3f} | {hd95:.2f} |"
        )
    lines += [
        f"| | **mean** | | **{np.mean([r[2] for r in done]):.3f}** | "
        f"**{np.mean([r[3] for r in done]):.3f}** | "
        f"{np.mean([r[2] - r[3] for r in done]):+.3f} | |",
        "",
        f"Time: the joint run of all {len(rows)} tissues took {joint_seconds:.1f} s "
        f"(reconstruction {joint.timings.get('reconstruct', 0):.1f} s, joint resolution "
        f"{joint.timings.get('resolve', 0):.1f} s); the {len(done)} single-structure "
        f"reconstructions on the same planes took {single_seconds:.1f} s together.",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
