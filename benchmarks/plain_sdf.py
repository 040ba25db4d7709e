"""The baseline every speed figure is a ratio against: plain signed-distance interpolation.

Read a NIfTI mask, keep ``N`` evenly spaced planes along z from the first to
the last occupied one, take each plane's 2-D signed distance (scipy's exact
Euclidean distance transform), interpolate linearly along z onto every voxel
layer, run marching cubes (scikit-image) and write an STL (trimesh). Nothing of
slicerecon is imported, so that as a script it runs in a fresh process with
only the libraries any user of "shape-based interpolation" would load::

    python benchmarks/plain_sdf.py mask.nii.gz 24 out.stl

:func:`plain_sdf_mesh` is the same reconstruction in process, for benchmarks
that time it beside slicerecon on the same planes.
"""

from __future__ import annotations

import sys
import time

import numpy as np


def plane_indices(mask: np.ndarray, n: int) -> np.ndarray:
    """``n`` evenly spaced z indices from the first to the last occupied plane."""
    occupied = np.flatnonzero(mask.any(axis=(0, 1)))
    first, last = int(occupied[0]), int(occupied[-1])
    k = np.arange(n)
    return first + (k * (last - first) // (n - 1) if n > 1 else k)


def plain_sdf_field(mask: np.ndarray, spacing: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Linear interpolation along z of the planes' 2-D signed distances (mm, < 0 inside).

    Returns a float32 field on the crop of the mask's bounding box (plus one
    voxel), layers outside the first..last plane set to outside.
    """
    from scipy import ndimage

    xs = np.flatnonzero(mask.any(axis=(1, 2)))
    ys = np.flatnonzero(mask.any(axis=(0, 2)))
    x0, x1 = max(xs[0] - 1, 0), min(xs[-1] + 2, mask.shape[0])
    y0, y1 = max(ys[0] - 1, 0), min(ys[-1] + 2, mask.shape[1])
    sampling = spacing[:2]
    distances = []
    for k in planes:
        plane = np.pad(mask[x0:x1, y0:y1, k], 1)
        inside = ndimage.distance_transform_edt(plane, sampling=sampling)
        outside = ndimage.distance_transform_edt(~plane, sampling=sampling)
        distances.append((outside - inside)[1:-1, 1:-1].astype(np.float32))
    field = np.full((x1 - x0, y1 - y0, mask.shape[2]), np.float32(1e3), dtype=np.float32)
    for (k0, d0), (k1, d1) in zip(
        zip(planes[:-1], distances[:-1], strict=True),
        zip(planes[1:], distances[1:], strict=True),
        strict=True,
    ):
        for k in range(k0, k1 + 1):
            t = np.float32((k - k0) / (k1 - k0))
            field[:, :, k] = (1 - t) * d0 + t * d1
    return field, (x0, y0)


def plain_sdf_mesh(mask: np.ndarray, affine: np.ndarray, n: int):  # noqa: ANN201 - trimesh
    """The plain reconstruction of ``mask`` from ``n`` planes: a trimesh in world mm."""
    import trimesh
    from skimage import measure

    spacing = np.linalg.norm(affine[:3, :3], axis=0)
    field, (x0, y0) = plain_sdf_field(mask, spacing, plane_indices(mask, n))
    padded = np.pad(field, 1, constant_values=np.float32(1e3))
    verts, faces, _, _ = measure.marching_cubes(padded, level=0.0)
    verts += np.array([x0 - 1, y0 - 1, -1])
    world = verts @ affine[:3, :3].T + affine[:3, 3]
    return trimesh.Trimesh(world, faces[:, ::-1], process=False)


def main(argv: list[str]) -> int:
    import nibabel as nib

    start = time.perf_counter()
    path, n, out = argv[0], int(argv[1]), argv[2]
    image = nib.load(path)
    mask = np.asanyarray(image.dataobj) != 0
    mesh = plain_sdf_mesh(mask, np.asarray(image.affine, dtype=np.float64), n)
    mesh.export(out)
    print(f"{time.perf_counter() - start:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
