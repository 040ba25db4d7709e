"""Seeded procedural shapes as binary volumes, for training and tests.

Every shape is a function ``name(size parameters..., *, options..., spacing=1.0,
margin=3)`` returning a :class:`~slicerecon.sections.Volume`. The parameters
before the ``*`` are sizes in millimetres; keyword-only options choose a style
or a count, and the family shapes take a ``seed`` for their structure. Each
shape is defined implicitly (an inside test evaluated at voxel centres;
composite shapes are unions, and differences, of boxes, rounded boxes,
spheres, ellipsoids, capsules, cones and extruded polygons, a capsule being the
points closer than its radius to a segment).

Families
--------
:data:`FAMILIES` groups the shapes: primitives, furniture (chair, table, lamp,
sofa), objects (airplane, car, rifle, guitar), anatomy (brain, kidney, lung,
vessel_tree, y_branch), holes (torus, genus2, plate_with_holes) and
multi_component (two_spheres, blobs); :func:`family_of` names a shape's family.

Grid
----
The grid is axis-aligned with voxel size ``spacing`` (mm, one value or one per
axis x, y, z). It covers the shape's bounding box plus ``margin`` empty voxels
on every side; voxel centres are laid out symmetrically about the bounding
box centre (which thus falls on a voxel corner, so that, e.g., a 60 mm box at
1 mm spacing holds exactly 60 voxels along x). Composite family shapes are
evaluated on a loose box and cropped to the foreground plus exactly
``margin`` voxels. The affine's origin is then chosen so that the centroid of
the foreground voxel centres sits at world ``(0, 0, 0)``; for the symmetric
primitives this is their analytic centre.

Registry
--------
:data:`SHAPES` maps names to shape functions; :func:`make_shape` builds one by
name, optionally with seeded random proportions (every size parameter scaled
by an independent factor drawn from ``U(0.8, 1.2)``; same seed, same mask),
seeded structure (for the shapes that take a ``seed``) and a ``resolution``
(largest extent in voxels). :func:`analytic_volume` gives the exact volume of
the primitives.

Modules
-------
One module per family (:mod:`~slicerecon.shapes.primitives`,
:mod:`~slicerecon.shapes.furniture`, :mod:`~slicerecon.shapes.objects`,
:mod:`~slicerecon.shapes.anatomy`, :mod:`~slicerecon.shapes.holes`,
:mod:`~slicerecon.shapes.multi_component`), built on shared machinery:
:mod:`~slicerecon.shapes.params` (each parameter's check, declared once in
the shape function's signature), :mod:`~slicerecon.shapes.grid` (grid layout
and rasterization), :mod:`~slicerecon.shapes.solids` (the solids composite
shapes are made of), :mod:`~slicerecon.shapes.draws` (seeded structure) and
:mod:`~slicerecon.shapes.registry` (names, families, :func:`make_shape`).
"""

from __future__ import annotations

from .anatomy import brain, kidney, lung, vessel_tree, y_branch
from .furniture import (
    CHAIR_STYLES,
    LAMP_STYLES,
    SOFA_STYLES,
    TABLE_STYLES,
    chair,
    lamp,
    sofa,
    table,
)
from .grid import Inside as Inside  # type aliases, importable from here as before
from .grid import Spacing as Spacing
from .holes import genus2, plate_with_holes, torus
from .multi_component import blobs, two_spheres
from .objects import CAR_STYLES, GUITAR_STYLES, airplane, car, guitar, rifle
from .primitives import box, ellipsoid, sphere
from .registry import (
    FAMILIES,
    SCALE_RANGE,
    SHAPES,
    analytic_volume,
    family_of,
    make_shape,
    shape_names,
    shape_params,
)

__all__ = [
    "CAR_STYLES",
    "CHAIR_STYLES",
    "FAMILIES",
    "GUITAR_STYLES",
    "LAMP_STYLES",
    "SHAPES",
    "SCALE_RANGE",
    "SOFA_STYLES",
    "TABLE_STYLES",
    "airplane",
    "analytic_volume",
    "blobs",
    "box",
    "brain",
    "car",
    "chair",
    "ellipsoid",
    "family_of",
    "genus2",
    "guitar",
    "kidney",
    "lamp",
    "lung",
    "make_shape",
    "plate_with_holes",
    "rifle",
    "shape_names",
    "shape_params",
    "sofa",
    "sphere",
    "table",
    "torus",
    "two_spheres",
    "vessel_tree",
    "y_branch",
]
