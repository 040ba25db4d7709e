"""Reconstruct a whole directory of masks on a local Dask cluster.

Generates 6 small NIfTI masks (seeded random proportions of three shape
families) plus one corrupt file, then runs :func:`pipelines.batch.run_batch`
with 2 worker processes. Each case lands in ``OUTDIR/<case>/``; the corrupt one
is recorded in ``OUTDIR/corrupt/error.json`` and in ``OUTDIR/summary.csv``
without stopping the others. Running the script again on the same OUTDIR
skips every finished case.

Run::

    python examples/batch_directory.py [OUTDIR]

The ``if __name__ == "__main__":`` guard is required: Dask starts its worker
processes by importing this file again.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

from pipelines.batch import run_batch
from slicerecon.io.nifti import write_nifti
from slicerecon.reconstruct import ReconstructConfig
from slicerecon.shapes import make_shape

SHAPES: dict[str, dict[str, Any]] = {
    "sphere": {"radius": 8.0},
    "ellipsoid": {"radii": (10.0, 7.0, 6.0)},
    "y_branch": {"trunk_length": 14.0, "branch_length": 14.0, "spread": 10.0, "radius": 4.0},
}


def make_inputs(indir: Path) -> None:
    """Write two seeded variants of each shape and one corrupt file into ``indir``."""
    for name, params in SHAPES.items():
        for seed in (1, 2):
            write_nifti(make_shape(name, seed=seed, **params), indir / f"{name}_{seed}.nii.gz")
    (indir / "corrupt.nii.gz").write_bytes(b"\x1f\x8b not really gzip")


def main(workdir: Path, *, workers: int = 2) -> int:
    """Build the inputs under ``workdir/masks`` and reconstruct them into ``workdir/results``."""
    indir, outdir = workdir / "masks", workdir / "results"
    if not indir.exists():
        make_inputs(indir)
    config = ReconstructConfig(slices=8, n_points=10_000)

    def progress(result, done, total):
        print(f"[{done}/{total}] {result.case:12s} {result.status}")

    batch = run_batch(indir, outdir, config, workers=workers, progress=progress)
    print(
        f"{batch.n_ok} ok, {batch.n_failed} failed, {batch.n_skipped} skipped "
        f"in {batch.seconds:.1f} s; table: {batch.summary_csv}"
    )
    for case in batch.cases:
        if case.status == "failed":
            print(f"  {case.case}: {case.error_type}: {case.error}")
        else:
            print(f"  {case.case}: volume IoU {case.metrics.get('volume_iou', float('nan')):.3f}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1:
        target = Path(sys.argv[1])
        target.mkdir(parents=True, exist_ok=True)
        sys.exit(main(target))
    with tempfile.TemporaryDirectory() as tmp:
        sys.exit(main(Path(tmp)))
