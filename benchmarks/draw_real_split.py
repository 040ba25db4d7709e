"""Draw the development / validation split of the real-shape protocol, once.

Every registered real shape (:data:`slicerecon.realshapes.REAL_SHAPES`) is a
case, except the few listed in :data:`EXCLUDED` with the reason. Cases are
put into *groups* of near-duplicates that must land in the same half (the
left and right copy of a structure, the MNI152 brain and grey-matter masks
whose outer surfaces coincide, the two eye tissues of the frog), and groups
into *strata* by source. Within each stratum the groups are shuffled with a
seeded generator and the first half of them goes to ``dev``, the rest to
``val`` (an odd group out goes to a half drawn by the same generator)::

    python benchmarks/draw_real_split.py --seed 20250611 --out benchmarks/real_split.toml

The split in ``benchmarks/real_split.toml`` was drawn with this command before
any reconstruction of a real shape was scored, and is not to be redrawn:
results on ``val`` are only meaningful while no choice was tuned on it.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from slicerecon.realshapes import REAL_SHAPES

SEED = 20250611
"""Seed of the draw recorded in ``benchmarks/real_split.toml``."""

MIN_EXTENT, MAX_EXTENT, MESH_RESOLUTION = 96, 160, 128
"""Grid normalisation of the protocol (:func:`slicerecon.realshapes.normalise`) and
voxels across a mesh source's longest side."""

EXCLUDED: dict[str, str] = {
    "frog_blood": "vessels 1-2 voxels thin once the frog is brought to <= 160 voxels across: "
    "the tree falls into ~30 pieces, so the case would score the resampling, not a "
    "reconstruction",
    "frog_nerve": "the same: nerves 1-2 voxels thin at <= 160 voxels across, ~19 pieces",
}
"""Registered shapes left out of the protocol, with the reason."""


def stratum(name: str) -> str:
    """The source stratum of a case."""
    if name.startswith("frog_"):
        return "frog"
    if name.startswith(("mni152_", "fsaverage5_")):
        return "mni"
    if name.startswith("dk_"):
        return "atlas"
    if name.startswith("pymeshlab_"):
        return "meshes"
    return "others"


def group(name: str) -> str:
    """The near-duplicate group of a case (cases of one group share a half)."""
    if name in ("mni152_brain", "mni152_gm"):
        return "mni152_brain_gm"
    if name in ("frog_eye_retina", "frog_eye_white"):
        return "frog_eye"
    return re.sub(r"_(left|right)$", "", name)


def draw(names: list[str], seed: int) -> dict[str, str]:
    """Case name → ``"dev"`` or ``"val"``, stratified by source, whole groups at a time."""
    rng = np.random.default_rng(seed)
    halves: dict[str, str] = {}
    for stratum_name in sorted({stratum(n) for n in names}):
        groups = sorted({group(n) for n in names if stratum(n) == stratum_name})
        order = [groups[i] for i in rng.permutation(len(groups))]
        n_dev = len(order) // 2 + (int(rng.integers(2)) if len(order) % 2 else 0)
        for i, g in enumerate(order):
            for n in names:
                if group(n) == g:
                    halves[n] = "dev" if i < n_dev else "val"
    return halves


def render(halves: dict[str, str], seed: int) -> str:
    """The TOML text of the split."""
    lines = [
        "# Development / validation split of the real-shape protocol (docs/realshapes.md).",
        f"# Drawn once by `python benchmarks/draw_real_split.py --seed {seed}` before any",
        "# reconstruction of a real shape was scored. Do not edit or redraw: tune on dev only.",
        "",
        "[protocol]",
        f"seed = {seed}",
        f"min_extent = {MIN_EXTENT}  # longest foreground extent after normalisation, voxels",
        f"max_extent = {MAX_EXTENT}",
        f"mesh_resolution = {MESH_RESOLUTION}  # voxels across a mesh source's longest side",
        "",
        "[excluded]",
    ]
    lines += [f'{name} = "{reason}"' for name, reason in sorted(EXCLUDED.items())]
    lines += ["", "[cases]"]
    for name in sorted(halves, key=lambda n: (halves[n], stratum(n), n)):
        lines.append(
            f'{name} = {{ half = "{halves[name]}", stratum = "{stratum(name)}", '
            f'group = "{group(name)}" }}'
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--out", type=Path, default=None, help="TOML file (default: stdout)")
    args = parser.parse_args(argv)
    names = sorted(n for n in REAL_SHAPES if n not in EXCLUDED)
    text = render(draw(names, args.seed), args.seed)
    if args.out is None:
        sys.stdout.write(text)
    else:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
