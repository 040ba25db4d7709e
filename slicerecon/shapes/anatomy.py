"""Anatomy-like shapes: a folded brain, a kidney, a lung, a vessel tree and a Y branch."""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from numpy.typing import NDArray

from ..sections import Volume
from .draws import Draws
from .grid import Part, Spacing, compose, rasterize
from .params import Mm, MmXYZ, Seed, between, checked, reject_if
from .solids import capsule, frame, in_capsule, oriented_ellipsoid


@checked
def brain(
    radii: MmXYZ = (60.0, 75.0, 52.0),
    fold_depth: Mm = 5.0,
    fissure_depth: Mm = 12.0,
    *,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A brain-like folded blob: an ellipsoid whose radius is modulated by gyri.

    The surface is ``|p / radii| = 1 + g(u)`` along each direction ``u`` from
    the centre: ``g`` is ``fold_depth * tanh(1.5 n)`` for a sum ``n`` of 24
    random plane waves on the unit sphere (3 to 5.5 cycles over a half
    circle, unit variance) — rounded gyri and sulci — minus a midline
    groove between the hemispheres on the upper half. The shape is
    star-shaped about its centre, so it is one solid without holes or
    cavities for any seed.

    Parameters
    ----------
    radii : sequence of 3 floats, default (60, 75, 52)
        Semi-axes along x (left-right), y (anterior-posterior), z, mm.
    fold_depth : float, default 5
        Amplitude of the gyri, mm (at most a fifth of the smallest radius).
    fissure_depth : float, default 12
        Depth of the interhemispheric groove at the top, mm (at most half the
        smallest radius).
    seed : int, optional
        Seed of the fold pattern. None gives a fixed canonical pattern.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    a, b, c = radii
    fold = fold_depth
    groove = fissure_depth
    small = min(a, b, c)
    reject_if("brain", fold > small / 5, f"fold_depth ({fold} mm) exceeds a fifth of the radii")
    reject_if("brain", groove > small / 2, f"fissure_depth ({groove} mm) exceeds half the radii")
    rng = Draws(seed).rng
    n_waves = 24
    dirs = rng.normal(size=(n_waves, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    freqs = rng.uniform(6.0, 11.0, size=n_waves) * math.pi / 2
    phases = rng.uniform(0.0, 2 * math.pi, size=n_waves)
    weights = rng.uniform(0.5, 1.0, size=n_waves)
    weights /= math.sqrt(float(np.sum(weights**2)) / 2.0)  # the wave sum has unit variance
    amp = fold / float(np.mean([a, b, c]))
    gap = groove / a
    dirs32, freqs32, phases32, weights32 = (
        v.astype(np.float32) for v in (dirs, freqs, phases, weights)
    )

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        shape = np.broadcast_shapes(x.shape, y.shape, z.shape)
        qx, qy, qz = (np.broadcast_to(q, shape).ravel() for q in (x / a, y / b, z / c))
        rho = np.sqrt(qx * qx + qy * qy + qz * qz)
        safe = np.maximum(rho, 1e-12)
        ux, uy, uz = qx / safe, qy / safe, qz / safe
        surface = 1.0 - gap * np.exp(-((ux / 0.06) ** 2)) * np.clip(uz + 0.2, 0.0, 1.0)
        # the folds move the surface by at most amp: decide the rest without the waves
        bound = amp
        out = rho <= surface - bound
        near = np.flatnonzero(~out & (rho <= surface + bound))
        un = [u[near].astype(np.float32) for u in (ux, uy, uz)]  # float32: twice as fast
        g = np.zeros(near.size, dtype=np.float32)
        for d, f, ph, wt in zip(dirs32, freqs32, phases32, weights32, strict=True):
            arg = un[0] * (f * d[0])
            arg += un[1] * (f * d[1])
            arg += un[2] * (f * d[2])
            arg += ph
            g += wt * np.cos(arg)
        out[near] = rho[near] <= surface[near] + amp * np.tanh(1.5 * g)
        return out.reshape(shape)

    reach = 1.0 + fold / small
    part = Part(inside, -reach * np.array([a, b, c]), reach * np.array([a, b, c]))
    return compose([part], spacing=spacing, margin=margin, name="brain")


@checked
def kidney(
    length: Mm = 110.0,
    width: Mm = 55.0,
    thickness: Mm = 40.0,
    *,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A kidney (bean): a bent ellipsoid with a notch (hilum) in its concave side.

    The long axis is x; the ends bend towards ``+y``, where the hilum opens.

    Parameters
    ----------
    length, width, thickness : float, default 110, 55, 40
        Extent of the unbent ellipsoid along x, y, z, mm.
    seed : int, optional
        Seed of the structure: bend and hilum size.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    a = length / 2.0
    b = width / 2.0
    c = thickness / 2.0
    draws = Draws(seed)
    bend = b * draws.uniform(0.2, 0.6, 0.4)
    hilum = draws.uniform(0.8, 1.2, 1.0)

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        yb = y - bend * (x / a) ** 2
        return (x / a) ** 2 + (yb / b) ** 2 + (z / c) ** 2 <= 1.0

    body = Part(inside, np.array([-a, -b, -c]), np.array([a, b + bend, c]))
    notch = oriented_ellipsoid(
        (0.0, b, 0.0), (0.22 * a * hilum, 0.45 * b * hilum, 0.35 * c * hilum)
    )
    return compose([body], minus=[notch], spacing=spacing, margin=margin, name="kidney")


@checked
def lung(
    height: Mm = 120.0,
    width: Mm = 60.0,
    depth: Mm = 90.0,
    fissure_gap: Mm = 8.0,
    *,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A two-lobed lung: a half dome on a domed diaphragm, split by an oblique fissure.

    The side wall rises straight for 15 % of the height and then curves
    (elliptically) to the apex; the base is hollowed upwards by the
    diaphragm (a paraboloid dome inside the footprint).

    The apex points to ``+z``; the medial (flat) side faces ``-x``. The
    fissure, a slab ``fissure_gap`` thick, separates an upper from a lower
    lobe everywhere except in a posterior strip of the medial side, where
    they stay joined (the hilum), so the lung is one solid without tunnels.
    A cardiac notch is cut into the medial side in front.

    Parameters
    ----------
    height : float, default 120
        Base-to-apex height along z, mm.
    width, depth : float, default 60, 90
        Extent of the base along x (lateral) and y (anterior-posterior), mm.
    fissure_gap : float, default 8
        Width of the fissure between the lobes, mm. Wide enough to stay open
        (at least two voxels) on a 32-voxel grid; a narrower gap sampled by
        coarse voxels leaves bridges across the fissure, which add tunnels.
    seed : int, optional
        Seed of the structure: fissure height and tilt, diaphragm dome,
        cardiac notch size.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    h = height
    a = width / 2.0
    b = depth / 2.0
    gap = fissure_gap
    draws = Draws(seed)
    reject_if("lung", gap >= 0.2 * h, "fissure_gap must be under a fifth of the height")
    dome = h * draws.uniform(0.1, 0.25, 0.18)
    medial = -a * draws.uniform(0.45, 0.65, 0.55)

    wall = 0.15 * h  # the side wall rises straight this high before curving to the apex
    # the diaphragm's dome: an elliptic paraboloid hollowing the base, centred in the
    # medially cut footprint and inside it, so that the hollow is a closed bowl
    dome_x = 0.5 * (medial + a)
    dome_a = 0.4 * (a - medial)
    dome_b = 0.8 * b

    def body(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        r2 = (x / a) ** 2 + (y / b) ** 2
        zz = np.clip((z - wall) / (h - wall), 0.0, None)
        hollow = dome * np.maximum(1.0 - ((x - dome_x) / dome_a) ** 2 - (y / dome_b) ** 2, 0.0)
        return (r2 + zz * zz <= 1.0) & (z >= hollow) & (x >= medial)

    parts = [Part(body, np.array([medial, -b, 0.0]), np.array([a, b, h]))]
    tilt = math.radians(draws.uniform(20.0, 40.0, 30.0))
    normal = np.array([0.0, -math.sin(tilt), math.cos(tilt)])  # descends to the front (-y)
    # the fissure passes above the diaphragm's hollow (or it would open a window into it)
    above_hollow = dome + gap / (2 * math.cos(tilt)) + dome_b * math.tan(tilt) + 0.05 * h
    z_fissure = max(h * draws.uniform(0.4, 0.55, 0.45), above_hollow)
    bridge = medial + 0.35 * (a - medial)

    def fissure(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        dist = y * normal[1] + (z - z_fissure) * normal[2]
        return (np.abs(dist) < gap / 2) & ((x > bridge) | (y < -0.1 * b))

    # the cardiac notch stays anterior (y < -b/4) and above the base, clear of the
    # hilum (x < bridge, y > -b/10) that joins the lobes, so it opens no tunnel
    notch_r = a * draws.uniform(0.35, 0.55, 0.45)
    notch_z = dome + 0.25 * h + 1.2 * notch_r
    minus = [
        Part(fissure, np.array([medial, -b, 0.0]), np.array([a, b, h])),
        oriented_ellipsoid((medial, -0.5 * b, notch_z), (notch_r, 0.25 * b, 1.2 * notch_r)),
    ]
    return compose(parts, minus=minus, spacing=spacing, margin=margin, name="lung")


@checked
def vessel_tree(
    trunk_length: Mm = 45.0,
    trunk_radius: Mm = 7.0,
    *,
    generations: Annotated[int, between(1, 6)] = 3,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A branching vessel tree of tapered capsules with shrinking radii.

    The trunk rises along ``+z`` from the origin. Each segment splits into
    two children, ``generations`` times: each child is 65–85 % as long and
    70–85 % as wide as its parent (about Murray's law), 25–45° off the
    parent's direction, the pair on opposite sides; each segment tapers by
    10 % along its length. No segment is thinner than 9 % of the trunk
    length, so that the tree stays connected on a grid of 32 voxels across.

    Parameters
    ----------
    trunk_length : float, default 45
        Length of the trunk, mm.
    trunk_radius : float, default 7
        Radius at the root, mm.
    generations : int, default 3
        Number of bifurcation levels (1 to 6); the tree has
        ``2 ** (generations + 1) - 1`` segments.
    seed : int, optional
        Seed of the branching angles, lengths and radii. None gives a
        symmetric tree whose branching planes turn by 90° per generation.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).

    Notes
    -----
    Branches of different sub-trees are not checked for collisions; for
    unusual seeds two of them may touch, which adds a loop.
    """
    length = trunk_length
    radius = trunk_radius
    levels = generations
    draws = Draws(seed)
    reject_if("vessel_tree", radius >= length / 2, "trunk_radius must be under half trunk_length")
    parts: list[Part] = []
    thinnest = min(0.09 * length, radius)

    def grow(
        start: NDArray, direction: NDArray, seg_len: float, r: float, level: int, roll: float
    ) -> None:
        end = start + seg_len * direction
        r_end = max(0.9 * r, thinnest)
        parts.append(capsule(start, end, r, r_end))
        if level == levels:
            return
        u, v = frame(direction)
        base_azimuth = roll + draws.uniform(-0.6, 0.6, 0.0)
        for k in range(2):
            theta = math.radians(draws.uniform(25.0, 45.0, 35.0))
            phi = base_azimuth + k * math.pi + draws.uniform(-0.3, 0.3, 0.0)
            side = math.cos(phi) * u + math.sin(phi) * v
            child = math.cos(theta) * direction + math.sin(theta) * side
            r_child = max(r_end * draws.uniform(0.7, 0.85, 0.79), thinnest)
            grow(
                end,
                child / np.linalg.norm(child),
                seg_len * draws.uniform(0.65, 0.85, 0.75),
                r_child,
                level + 1,
                roll + math.pi / 2,
            )

    grow(np.zeros(3), np.array([0.0, 0.0, 1.0]), length, radius, 0, 0.0)
    return compose(parts, spacing=spacing, margin=margin, name="vessel_tree")


@checked
def y_branch(
    trunk_length: Mm = 50.0,
    branch_length: Mm = 50.0,
    spread: Mm = 30.0,
    radius: Mm = 8.0,
    *,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A tube along z that splits into two arms (a bifurcating vessel or airway).

    The trunk runs up the z axis from ``z = 0`` to ``z = trunk_length``; two arms
    run from the top of the trunk to ``(±spread, 0, trunk_length +
    branch_length)``. Each part is a capsule of radius ``radius``.

    Parameters
    ----------
    trunk_length : float, default 50
        Length of the trunk axis, mm.
    branch_length : float, default 50
        Height the arms rise above the trunk, mm.
    spread : float, default 30
        Distance of each arm's end from the trunk axis along x, mm; the arms'
        ends are apart when ``spread > radius``.
    radius : float, default 8
        Tube radius, mm.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    trunk = trunk_length
    rise = branch_length
    side = spread
    r = radius
    fork = (0.0, 0.0, trunk)

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        return (
            in_capsule(x, y, z, (0.0, 0.0, 0.0), fork, r)
            | in_capsule(x, y, z, fork, (side, 0.0, trunk + rise), r)
            | in_capsule(x, y, z, fork, (-side, 0.0, trunk + rise), r)
        )

    return rasterize(
        inside,
        (-side - r, -r, -r),
        (side + r, r, trunk + rise + r),
        spacing=spacing,
        margin=margin,
        name="y_branch",
    )
