"""Several organs of one real label map, annotated as clinicians draw them.

The organs of the segmented frog in pyvista's ``frog_tissues.vti`` (loaded from
the installed package; every 2nd voxel in-plane: 2 x 2 x 1.5 mm) form one
label map, the ground truth. Each layout keeps some of its axial slices, as an
annotator would:

``every4``         every organ on every 4th slice (the same slices for all)
``every4+dense``   the same, and the smallest organ (spleen) on every slice it crosses
``every3+extra``   every 3rd slice, and the heart also on one slice between two of them
``interleaved``    organ ``n`` (in the order below) on the slices ``k = n (mod 3)``:
                   three annotators, each on slices of their own

Each sparse label map is reconstructed as a user would
(``slicerecon.case.reconstruct_structures`` on the array and its affine: the
reading is detected, not told) beside two baselines on the same sparse label
map: ITK's morphological contour interpolation (3D Slicer's "Fill between
slices", all axes, every label at once) and plain signed-distance
interpolation, linear between each organ's own drawn slices
(``benchmarks/plain_sdf.py``). Every organ is scored by volume IoU against its
true mask, computed here with numpy::

    python benchmarks/clinical_layouts.py

prints one table per layout (organs, IoU of each method, wins / ties / losses of
ours against each baseline, |difference| <= 0.001 a tie) and how slicerecon read
each layout. Nothing is chosen on these numbers: they show the reading rules of
``docs/formats.md`` on anatomy drawn in the layouts they are for.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from slicerecon.realshapes import FROG_TISSUES

sys.path.insert(0, str(Path(__file__).resolve().parent))

from annotations import iou, itk_mci_labels  # noqa: E402
from plain_sdf import plain_sdf_field  # noqa: E402

ORGANS = {
    name: value
    for name, value in FROG_TISSUES.items()
    if name not in ("blood", "nerve", "skeleton")
}
"""The frog's organs used: its blood vessels and nerves are 1-2 voxels thin at this
resolution (the resampling, not a reconstruction, would be scored), and its skeleton is a
tissue of many bones around the organs, not one organ."""

LAYOUTS = ("every4", "every4+dense", "every3+extra", "interleaved")


def frog() -> tuple[np.ndarray, np.ndarray]:
    """The organs as one label map (uint8, their frog label values) and its affine."""
    from slicerecon.io.vti import read_vti
    from slicerecon.realshapes import frog_tissues_path

    image = read_vti(frog_tissues_path())
    values = np.asarray(image.values)[::2, ::2, :]
    labels = np.where(np.isin(values, list(ORGANS.values())), values, 0).astype(np.uint8)
    affine = image.affine.copy()
    affine[:3, :2] *= 2
    return labels, affine


def layout(truth: np.ndarray, name: str) -> np.ndarray:
    """The sparse label map of one layout."""
    sparse = np.zeros_like(truth)
    z = np.arange(truth.shape[2])
    if name in ("every4", "every4+dense"):
        sparse[:, :, z % 4 == 0] = truth[:, :, z % 4 == 0]
    if name == "every4+dense":
        spleen = truth == ORGANS["spleen"]
        sparse[spleen] = ORGANS["spleen"]
    if name == "every3+extra":
        sparse[:, :, z % 3 == 0] = truth[:, :, z % 3 == 0]
        heart = truth == ORGANS["heart"]
        drawn = np.flatnonzero(heart.any(axis=(0, 1)) & (z % 3 == 0))
        extra = int(drawn[len(drawn) // 2]) + 1  # between two of its planes
        sparse[:, :, extra][heart[:, :, extra]] = ORGANS["heart"]
    if name == "interleaved":
        for n, value in enumerate(ORGANS.values()):
            keep = (z % 3 == n % 3)[None, None, :] & (truth == value)
            sparse[keep] = value
    return sparse


def plain(sparse: np.ndarray, spacing: np.ndarray, value: int) -> np.ndarray:
    """Plain SDF between the organ's own drawn slices (no slicerecon code)."""
    mask = sparse == value
    planes = np.flatnonzero(mask.any(axis=(0, 1)))
    out = np.zeros(mask.shape, dtype=bool)
    if planes.size == 1:
        out[:, :, planes[0]] = mask[:, :, planes[0]]
        return out
    field, (x0, y0) = plain_sdf_field(mask, spacing, planes)
    out[x0 : x0 + field.shape[0], y0 : y0 + field.shape[1], :] = field < 0
    return out


def run(names: list[str]) -> str:
    from slicerecon.case import reconstruct_structures
    from slicerecon.case_inputs import case_from_label_map
    from slicerecon.labels import LabelMap
    from slicerecon.reconstruct import ReconstructConfig

    truth, affine = frog()
    spacing = np.linalg.norm(affine[:3, :3], axis=0)
    lines = []
    for name in names:
        sparse = layout(truth, name)
        start = time.perf_counter()
        reading = case_from_label_map(
            LabelMap.from_array(sparse, affine), ReconstructConfig()
        ).annotation.source
        ours = reconstruct_structures((sparse, affine)).labels
        seconds = time.perf_counter() - start
        itk_labels = itk_mci_labels(sparse, spacing)
        methods = ("ours", "plain SDF", "ITK-MCI")
        scores: dict[str, list[float]] = {m: [] for m in methods}
        rows = []
        for organ, value in ORGANS.items():
            true = truth == value
            row = {
                "ours": iou(ours == value, true),
                "plain SDF": iou(plain(sparse, spacing, value), true),
                "ITK-MCI": iou(itk_labels == value, true),
            }
            for m in methods:
                scores[m].append(row[m])
            rows.append(f"| {organ} | " + " | ".join(f"{row[m]:.3f}" for m in methods) + " |")
        ours_scores = np.array(scores["ours"])
        versus = "; ".join(
            f"{m}: {_counts(ours_scores - np.array(scores[m]))}" for m in methods[1:]
        )
        lines += [
            f"### `{name}`",
            "",
            f"Read as: {reading} ({seconds:.1f} s).",
            "",
            "| organ | ours | plain SDF | ITK-MCI |",
            "|---|---:|---:|---:|",
            *rows,
            "| **mean** | " + " | ".join(f"{np.mean(scores[m]):.3f}" for m in methods) + " |",
            "",
            f"Ours against {versus}.",
            "",
        ]
        print(f"{name}: done", file=sys.stderr, flush=True)
    return "\n".join(lines)


def _counts(diffs: np.ndarray) -> str:
    return (
        f"{int(np.sum(diffs > 0.001))} wins / {int(np.sum(np.abs(diffs) <= 0.001))} ties / "
        f"{int(np.sum(diffs < -0.001))} losses"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--layouts", default=",".join(LAYOUTS))
    args = parser.parse_args(argv)
    names = [n for n in args.layouts.split(",") if n]
    unknown = sorted(set(names) - set(LAYOUTS))
    if unknown:
        parser.error(f"unknown layouts {unknown}; choose from {', '.join(LAYOUTS)}")
    print(run(names))
    return 0


if __name__ == "__main__":
    sys.exit(main())
