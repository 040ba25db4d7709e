"""Regenerate the small example inputs bundled in ``examples/data/``.

The files are made by :mod:`slicerecon.shapes` (nothing is downloaded), so they
can be redistributed freely::

    python examples/make_example_data.py

writes

``examples/data/chair.nii.gz``
    A chair-like label map (seat, four legs, back; 1 mm voxels), the input of
    the README's first command.
``examples/data/y_branch_aniso.nii.gz``
    A bifurcating tube on an anisotropic grid (0.8 x 0.8 x 2.0 mm), like a
    vessel segmented on thick CT slices.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from slicerecon.io.nifti import write_nifti
from slicerecon.shapes import make_shape


def main(outdir: Path) -> None:
    outdir.mkdir(parents=True, exist_ok=True)
    write_nifti(make_shape("chair"), outdir / "chair.nii.gz")
    write_nifti(make_shape("y_branch", spacing=(0.8, 0.8, 2.0)), outdir / "y_branch_aniso.nii.gz")
    for path in sorted(outdir.glob("*.nii.gz")):
        print(f"wrote {path} ({path.stat().st_size} bytes)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outdir", type=Path, default=Path(__file__).parent / "data")
    main(parser.parse_args().outdir)
