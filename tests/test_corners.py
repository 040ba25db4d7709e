"""Harris corners on silhouettes: exact lattice corners, determinism, padding."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.corners import harris_corners, pad_corners, projection_corners
from slicerecon.errors import InputError, OptionError
from slicerecon.sampling import projections_from_volume
from slicerecon.sections import Volume


def _rectangle() -> np.ndarray:
    img = np.zeros((20, 30), dtype=bool)
    img[5:15, 8:25] = True  # rows 5..14, cols 8..24
    return img


def _l_shape() -> np.ndarray:
    img = np.zeros((40, 40), dtype=bool)
    img[2:38, 2:12] = True
    img[28:38, 2:30] = True
    return img


def test_rectangle_gives_its_four_corners_on_the_pixel_boundary() -> None:
    corners = harris_corners(_rectangle())
    expected = [[4.5, 7.5], [4.5, 24.5], [14.5, 7.5], [14.5, 24.5]]
    np.testing.assert_array_equal(corners, expected)


def test_l_shape_gives_six_corners_including_the_concave_one() -> None:
    corners = harris_corners(_l_shape())
    expected = [[1.5, 1.5], [1.5, 11.5], [27.5, 11.5], [27.5, 29.5], [37.5, 1.5], [37.5, 29.5]]
    np.testing.assert_array_equal(corners, expected)
    assert [27.5, 11.5] in corners.tolist()  # the concave corner


def test_disk_has_no_corners_with_the_default_threshold() -> None:
    rows, cols = np.mgrid[:48, :48]
    disk = (rows - 23.5) ** 2 + (cols - 23.5) ** 2 < 20**2
    assert len(harris_corners(disk)) <= 2


def test_silhouette_touching_the_border_keeps_its_corners() -> None:
    corners = harris_corners(np.ones((10, 12), dtype=bool))
    np.testing.assert_array_equal(corners, [[-0.5, -0.5], [-0.5, 11.5], [9.5, -0.5], [9.5, 11.5]])


def test_order_is_deterministic_and_follows_the_image_transpose() -> None:
    img = _l_shape()
    first = harris_corners(img)
    np.testing.assert_array_equal(first, harris_corners(img.copy()))
    assert [tuple(p) for p in first] == sorted(tuple(p) for p in first)
    transposed = harris_corners(img.T)
    np.testing.assert_array_equal(transposed, np.array(sorted(map(tuple, first[:, ::-1]))))


def test_max_corners_and_empty_image() -> None:
    assert len(harris_corners(_l_shape(), max_corners=3)) == 3
    assert harris_corners(np.zeros((8, 8), dtype=bool)).shape == (0, 2)


def test_projection_corners_of_a_box() -> None:
    mask = np.zeros((10, 12, 14), dtype=bool)
    mask[2:6, 3:9, 4:13] = True
    views = projection_corners(projections_from_volume(Volume(mask)))
    np.testing.assert_array_equal(views[0], [[2.5, 3.5], [2.5, 12.5], [8.5, 3.5], [8.5, 12.5]])
    np.testing.assert_array_equal(views[1], [[1.5, 3.5], [1.5, 12.5], [5.5, 3.5], [5.5, 12.5]])
    np.testing.assert_array_equal(views[2], [[1.5, 2.5], [1.5, 8.5], [5.5, 2.5], [5.5, 8.5]])


def test_pad_corners_normalises_to_unit_square_and_masks_padding() -> None:
    corners = np.array([[-0.5, -0.5], [19.5, 29.5], [4.5, 7.5]])
    points, valid = pad_corners(corners, n_max=5, image_shape=(20, 30))
    assert points.shape == (5, 2) and valid.tolist() == [True, True, True, False, False]
    np.testing.assert_allclose(points[:3], [[0, 0], [1, 1], [5 / 20, 8 / 30]])
    np.testing.assert_array_equal(points[3:], 0.0)
    cut, valid = pad_corners(corners, n_max=2, image_shape=(20, 30))
    assert valid.all() and cut.shape == (2, 2)


def test_bad_input_raises_clear_errors() -> None:
    with pytest.raises(InputError, match="2-D"):
        harris_corners(np.zeros((3, 3, 3), dtype=bool))
    with pytest.raises(InputError, match="boolean"):
        harris_corners(np.full((4, 4), 2))
    with pytest.raises(OptionError, match="k must be"):
        harris_corners(_rectangle(), k=0.0)
    with pytest.raises(OptionError, match="n_max"):
        pad_corners(np.zeros((0, 2)), n_max=-1, image_shape=(4, 4))
