"""preview.png: the result in 3-D, in its colours and in mm, beside the annotated planes."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from slicerecon.case import reconstruct_case
from slicerecon.case_inputs import load_case
from slicerecon.case_outputs import _write_preview
from slicerecon.cli import main
from slicerecon.io.labelmap import write_label_map
from slicerecon.labels import DEFAULT_COLOURS
from slicerecon.preview import SINGLE_COLOUR, _orientation
from slicerecon.reconstruct import ReconstructConfig
from slicerecon.sections import CrossSections


def _three_organs(spacing=(1.0, 1.0, 2.5)) -> tuple[np.ndarray, np.ndarray]:
    labels = np.zeros((40, 36, 24), np.uint8)
    labels[6:20, 6:26, 4:20] = 1
    labels[20:34, 6:26, 4:20] = 2
    labels[12:28, 26:32, 6:18] = 3
    return labels, np.diag([*spacing, 1.0])


def _hue_pixels(image: np.ndarray, colour) -> int:
    """Pixels of the colour's hue, whatever their shading."""
    pixels = image.reshape(-1, 3).astype(np.float64)
    norm = np.maximum(np.linalg.norm(pixels, axis=1, keepdims=True), 1.0)
    direction = np.asarray(colour, np.float64) / np.linalg.norm(colour)
    return int((np.linalg.norm(pixels / norm - direction, axis=1) < 0.03).sum())


@pytest.fixture(scope="module")
def organs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("preview")
    labels, affine = _three_organs()
    path = write_label_map(labels, affine, root / "organs.nii.gz")
    assert main(["run", str(path), "-o", str(root / "out"), "--slices", "6", "-q"]) == 0
    return root / "out" / "preview.png"


def test_every_structure_in_its_colour_in_3d_and_on_the_planes(organs: Path) -> None:
    image = np.asarray(Image.open(organs).convert("RGB"))
    three_d = image[:, : image.shape[1] // 2]
    for colour in DEFAULT_COLOURS[:3]:
        assert _hue_pixels(three_d, colour) > 500, colour  # rendered and shaded
        fill = np.round(255 - 0.4 * (255 - np.asarray(colour, np.float64)))
        contour = np.round(np.asarray(colour, np.float64) * 0.55)
        planes = image[:, image.shape[1] // 2 :].reshape(-1, 3)
        assert (planes == fill).all(axis=1).sum() > 500  # the result's sections
        assert (planes == contour).all(axis=1).sum() > 100  # the annotation over them


def test_the_planes_are_shown_in_mm_at_true_aspect(tmp_path: Path) -> None:
    # in-plane voxels of 1 x 2 mm: a 20 x 20 mm square must stay square
    labels = np.zeros((40, 20, 12), np.uint8)
    labels[10:30, 5:15, 2:10] = 1
    path = write_label_map(labels, np.diag([1.0, 2.0, 2.5, 1.0]), tmp_path / "square.nii.gz")
    assert main(["run", str(path), "-o", str(tmp_path / "out"), "--slices", "4", "-q"]) == 0
    image = np.asarray(Image.open(tmp_path / "out" / "preview.png").convert("RGB"))
    fill = np.round(255 - 0.4 * (255 - np.asarray(SINGLE_COLOUR, np.float64)))
    planes = image[:, image.shape[1] // 2 :]
    contour = np.round(np.array(SINGLE_COLOUR) * 0.55)
    mask = (planes == fill).all(axis=2) | (planes == contour).all(axis=2)
    labelled, _ = ndimage.label(mask)
    sizes = np.bincount(labelled.ravel())[1:]
    biggest = labelled == (np.argmax(sizes) + 1)
    rows, cols = np.flatnonzero(biggest.any(axis=1)), np.flatnonzero(biggest.any(axis=0))
    height, width = rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1
    assert width == pytest.approx(height, abs=2)


def test_radiological_orientation_and_letters() -> None:
    def sections(affine, axis=2) -> CrossSections:
        return CrossSections(np.zeros((1, 4, 4), bool), np.array([1.0]), axis, affine, (4, 4, 4))

    ras = _orientation(sections(np.eye(4)), "RAS")  # axial: R left, A up
    assert (ras.across, ras.up, ras.flip_across, ras.flip_up) == (0, 1, True, True)
    assert ras.letters == ("R", "L", "A", "P")
    lps = _orientation(sections(np.eye(4)), "LPS")  # +x is left, +y posterior: no flips
    assert (lps.flip_across, lps.flip_up) == (False, False)
    assert lps.letters == ("R", "L", "A", "P")
    sagittal = _orientation(sections(np.eye(4), axis=0), "RAS")
    assert sagittal.letters == ("A", "P", "S", "I") and sagittal.across == 1


def test_a_256_cube_preview_takes_well_under_a_second_of_cpu(tmp_path: Path) -> None:
    g = np.ogrid[:256, :256, :256]
    r2 = ((g[0] - 128) / 110.0) ** 2 + ((g[1] - 128) / 100.0) ** 2 + ((g[2] - 128) / 115.0) ** 2
    labels = np.zeros((256, 256, 256), np.uint8)
    labels[r2 < 1] = 1
    labels[(r2 < 1) & (g[0] > 128)] = 2
    labels[r2 < 0.35] = 3
    path = write_label_map(labels, np.diag([1.0, 1.0, 2.5, 1.0]), tmp_path / "big.nii.gz")
    config = ReconstructConfig(slices=12)
    case = load_case(path, config)
    result = reconstruct_case(case, config)
    assert sum(len(r.mesh.faces) for r in result.results) > 500_000
    start = time.process_time()
    _write_preview(tmp_path / "preview.png", case, result, config)
    assert time.process_time() - start < 1.0  # about 0.35 s measured (CPU time: load-proof)
