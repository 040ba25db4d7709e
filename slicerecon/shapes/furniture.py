"""Furniture: a chair, a table, a lamp and a sofa, each in several styles."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..errors import OptionError
from ..sections import Volume
from .draws import Draws
from .grid import Spacing, compose, rasterize
from .params import Mm, Seed, checked, reject_if
from .solids import aligned_box, capsule, frustum, in_box, prism, rounded_box

CHAIR_STYLES = ("plain", "armchair", "slat_back")


@checked
def chair(
    seat_width: Mm = 40.0,
    seat_depth: Mm = 40.0,
    seat_thickness: Mm = 5.0,
    leg_height: Mm = 40.0,
    leg_width: Mm = 5.0,
    back_height: Mm = 45.0,
    back_thickness: Mm = 5.0,
    *,
    style: str | None = None,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A chair of boxes: a seat slab, a back and four legs, optionally with arms.

    The legs (square, ``leg_width`` wide) stand at the seat's corners from
    ``z = 0`` to ``z = leg_height``; the seat lies on them; the back rises from
    the seat along its back edge (``+y``). Any z-plane below the seat cuts the
    four legs as four separate squares.

    Styles: ``"plain"`` (a solid back slab), ``"armchair"`` (plus an arm post
    and rest on each side, 35–50 % of the back's height: two loops) and
    ``"slat_back"`` (the back is two posts, a top rail and one to three
    vertical slats, with gaps at least ``leg_width`` wide).

    Parameters
    ----------
    seat_width, seat_depth, seat_thickness : float, default 40, 40, 5
        Seat size along x, y, z, mm.
    leg_height : float, default 40
        Height of the legs below the seat, mm.
    leg_width : float, default 5
        Side of the legs' square cross-section, mm; less than half the seat
        width and depth.
    back_height, back_thickness : float, default 45, 5
        Height of the back above the seat and its thickness along y, mm.
    style : {"plain", "armchair", "slat_back"}, optional
        Default: drawn from ``seed`` (``"plain"`` without a seed).
    seed : int, optional
        Seed of the structure: style, arm height, number of slats. None gives
        the canonical (plain) chair.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    draws = Draws(seed)
    kind = draws.style(style, CHAIR_STYLES, "chair")
    w = seat_width / 2.0
    d = seat_depth / 2.0
    t = seat_thickness
    legs_h = leg_height
    leg = leg_width
    back_h = back_height
    back_t = back_thickness
    if leg >= min(w, d):
        raise OptionError(
            f"leg_width ({leg} mm) must be less than half the seat width and depth "
            f"({2 * w} x {2 * d} mm), or the legs would touch"
        )
    if back_t > 2 * d:
        raise OptionError(f"back_thickness ({back_t} mm) exceeds the seat depth ({2 * d} mm)")
    seat_top = legs_h + t
    parts = [
        ((-w, -d, legs_h), (w, d, seat_top)),
        ((-w, d - back_t, seat_top), (w, d, seat_top + back_h)),
    ]
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            cx, cy = sx * (w - leg / 2.0), sy * (d - leg / 2.0)
            parts.append(((cx - leg / 2, cy - leg / 2, 0.0), (cx + leg / 2, cy + leg / 2, legs_h)))
    if kind != "plain":
        top = seat_top + back_h
        if kind == "armchair":
            arm = seat_top + back_h * draws.uniform(0.35, 0.5, 0.4)
            for sx in (-1.0, 1.0):
                x0, x1 = sorted((sx * w, sx * (w - leg)))
                parts.append(((x0, -d, seat_top), (x1, -d + leg, arm)))  # post
                parts.append(((x0, -d, arm - leg), (x1, d - back_t, arm)))  # rest
        else:  # slat back: replace the slab by posts, a top rail and slats
            parts.pop(1)
            rail = max(leg, 0.2 * back_h)
            parts.append(((-w, d - back_t, top - rail), (w, d, top)))
            for x0, x1 in ((-w, -w + leg), (w - leg, w)):
                parts.append(((x0, d - back_t, seat_top), (x1, d, top)))
            inner = 2 * w - 2 * leg
            most = max(1, min(3, int((inner - leg) // (2 * leg))))  # gaps >= leg
            n = most if not draws.seeded else int(draws.rng.integers(1, most + 1))
            gap = (inner - n * leg) / (n + 1)
            for k in range(n):
                x0 = -w + leg + gap + k * (leg + gap)
                parts.append(((x0, d - back_t, seat_top), (x0 + leg, d, top - rail)))
        boxes = [aligned_box(lo, hi) for lo, hi in parts]
        return compose(boxes, spacing=spacing, margin=margin, name="chair")

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        out = np.zeros(np.broadcast_shapes(x.shape, y.shape, z.shape), dtype=bool)
        for lo, hi in parts:
            out |= in_box(x, y, z, lo, hi)
        return out

    return rasterize(
        inside,
        (-w, -d, 0.0),
        (w, d, seat_top + back_h),
        spacing=spacing,
        margin=margin,
        name="chair",
    )


TABLE_STYLES = ("legs", "pedestal", "trestle")


@checked
def table(
    top_width: Mm = 90.0,
    top_depth: Mm = 60.0,
    top_thickness: Mm = 5.0,
    height: Mm = 70.0,
    leg_width: Mm = 6.0,
    *,
    style: str | None = None,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A table: a top slab on four legs, a central pedestal or two trestle ends.

    Parameters
    ----------
    top_width, top_depth, top_thickness : float, default 90, 60, 5
        Size of the top along x, y, z, mm.
    height : float, default 70
        Height of the top surface above the floor (``z = 0``), mm.
    leg_width : float, default 6
        Side of the square legs (``"legs"``), radius scale of the column
        (``"pedestal"``) and thickness of the end boards (``"trestle"``), mm.
    style : {"legs", "pedestal", "trestle"}, optional
        Default: drawn from ``seed`` (``"legs"`` without a seed).
    seed : int, optional
        Seed of the structure: style, leg inset, base size. None gives the
        canonical table.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    w = top_width / 2.0
    d = top_depth / 2.0
    t = top_thickness
    h = height
    leg = leg_width
    draws = Draws(seed)
    kind = draws.style(style, TABLE_STYLES, "table")
    reject_if("table", t >= h, f"top_thickness ({t} mm) must be less than height ({h} mm)")
    reject_if(
        "table",
        leg >= min(w, d),
        f"leg_width ({leg} mm) must be less than half the top width and depth",
    )
    under = h - t
    parts = [rounded_box((-w, -d, under), (w, d, h), min(t / 2.0, 2.0))]
    if kind == "legs":
        inset = draws.uniform(0.0, 0.12, 0.05)
        cx = w - leg / 2.0 - inset * (w - leg)
        cy = d - leg / 2.0 - inset * (d - leg)
        for sx in (-1.0, 1.0):
            for sy in (-1.0, 1.0):
                parts.append(
                    rounded_box(
                        (sx * cx - leg / 2, sy * cy - leg / 2, 0.0),
                        (sx * cx + leg / 2, sy * cy + leg / 2, under + t / 2),
                        leg / 4,
                    )
                )
    elif kind == "pedestal":
        column = max(leg, 0.12 * min(w, d))
        foot = draws.uniform(0.5, 0.8, 0.65) * min(w, d)
        parts.append(frustum((0.0, 0.0, 0.0), (0.0, 0.0, t), foot, 0.9 * foot))
        parts.append(frustum((0.0, 0.0, t / 2), (0.0, 0.0, under + t / 2), column))
    else:  # trestle: two end boards joined by a stretcher
        end_x = w * draws.uniform(0.6, 0.85, 0.75)
        board_d = d * draws.uniform(0.6, 0.9, 0.8)
        for sx in (-1.0, 1.0):
            parts.append(
                rounded_box(
                    (sx * end_x - leg / 2, -board_d, 0.0),
                    (sx * end_x + leg / 2, board_d, under + t / 2),
                    leg / 4,
                )
            )
        bar = 0.3 * under
        parts.append(rounded_box((-end_x, -leg / 2, bar), (end_x, leg / 2, bar + leg), leg / 4))
    return compose(parts, spacing=spacing, margin=margin, name="table")


LAMP_STYLES = ("floor", "desk")


@checked
def lamp(
    base_radius: Mm = 22.0,
    base_height: Mm = 6.0,
    pole_height: Mm = 70.0,
    pole_radius: Mm = 3.5,
    shade_radius: Mm = 20.0,
    shade_height: Mm = 22.0,
    *,
    style: str | None = None,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A lamp: a round base, a pole and a solid conical shade.

    ``"floor"``: the shade sits on top of a straight pole. ``"desk"``: the
    pole bends into an arm, and the shade hangs tilted from the arm's end.

    Parameters
    ----------
    base_radius, base_height : float, default 22, 6
        Disc-shaped base on the floor (``z = 0``), mm.
    pole_height, pole_radius : float, default 70, 3.5
        Pole above the base, mm.
    shade_radius, shade_height : float, default 20, 22
        Wide radius and height of the shade (its narrow end is 0.35 to 0.6
        times as wide), mm.
    style : {"floor", "desk"}, optional
        Default: drawn from ``seed`` (``"floor"`` without a seed).
    seed : int, optional
        Seed of the structure: style, shade taper, arm angle.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    rb = base_radius
    hb = base_height
    hp = pole_height
    rp = pole_radius
    rs = shade_radius
    hs = shade_height
    draws = Draws(seed)
    kind = draws.style(style, LAMP_STYLES, "lamp")
    reject_if(
        "lamp", rp >= min(rb, rs) / 2, "pole_radius must be under half the base and shade radii"
    )
    narrow = rs * draws.uniform(0.35, 0.6, 0.5)
    parts = [frustum((0.0, 0.0, 0.0), (0.0, 0.0, hb), rb, 0.85 * rb)]
    if kind == "floor":
        top = hb + hp
        parts.append(capsule((0.0, 0.0, hb / 2), (0.0, 0.0, top), rp))
        parts.append(frustum((0.0, 0.0, top - 0.6 * hs), (0.0, 0.0, top + 0.4 * hs), rs, narrow))
    else:
        top = hb + 0.65 * hp
        angle = math.radians(draws.uniform(15.0, 50.0, 30.0))
        arm = 0.6 * hp
        end = np.array([arm * math.cos(angle), 0.0, top + arm * math.sin(angle)])
        parts.append(capsule((0.0, 0.0, hb / 2), (0.0, 0.0, top), rp))
        parts.append(capsule((0.0, 0.0, top), end, rp))
        tilt = math.radians(draws.uniform(10.0, 40.0, 25.0))
        axis = np.array([math.sin(tilt), 0.0, -math.cos(tilt)])
        # a ball joint fills the wedge between arm and shade (no pinched voxels there)
        parts.append(capsule(end, end, narrow))
        parts.append(frustum(end, end + hs * axis, narrow, rs))
    return compose(parts, spacing=spacing, margin=margin, name="lamp")


SOFA_STYLES = ("two_arms", "one_arm", "no_arms", "chaise")


@checked
def sofa(
    width: Mm = 160.0,
    depth: Mm = 80.0,
    seat_height: Mm = 40.0,
    back_height: Mm = 40.0,
    arm_width: Mm = 16.0,
    arm_height: Mm = 20.0,
    *,
    style: str | None = None,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A sofa of rounded blocks: seat base, back, armrests and an optional chaise.

    Parameters
    ----------
    width, depth : float, default 160, 80
        Footprint of the seat base along x, y, mm; the back stands along ``+y``.
    seat_height : float, default 40
        Height of the seat above the floor (``z = 0``), mm.
    back_height : float, default 40
        Height of the back above the seat, mm.
    arm_width, arm_height : float, default 16, 20
        Thickness of the armrests along x and their height above the seat, mm.
    style : {"two_arms", "one_arm", "no_arms", "chaise"}, optional
        ``"chaise"`` adds an L-shaped extension in front of one end (with two
        arms). Default: drawn from ``seed`` (``"two_arms"`` without a seed).
    seed : int, optional
        Seed of the structure: style, back thickness and tilt, chaise side.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    w = width / 2.0
    d = depth / 2.0
    hs = seat_height
    hb = back_height
    aw = arm_width
    ah = arm_height
    draws = Draws(seed)
    kind = draws.style(style, SOFA_STYLES, "sofa")
    reject_if("sofa", 2 * aw >= w, f"arm_width ({aw} mm) must be under a quarter of the width")
    rad = 0.1 * min(hs, d)
    back_t = d * draws.uniform(0.35, 0.6, 0.45)
    lean = back_t * draws.uniform(0.0, 0.5, 0.2)
    parts = [rounded_box((-w, -d, 0.0), (w, d, hs), rad)]
    back = [
        (d - back_t, hs - rad),
        (d, hs - rad),
        (d + lean, hs + hb),
        (d - back_t + lean, hs + hb),
    ]
    parts.append(prism(back, 0, -w, w))
    side = 1.0 if draws.uniform(0.0, 1.0, 0.7) > 0.5 else -1.0
    arms = {"two_arms": (-1.0, 1.0), "chaise": (-1.0, 1.0), "one_arm": (side,), "no_arms": ()}
    for sx in arms[kind]:
        x0, x1 = sorted((sx * w, sx * (w - aw)))
        parts.append(rounded_box((x0, -d, 0.0), (x1, d + lean / 2, hs + ah), rad))
    if kind == "chaise":
        length = 2 * d * draws.uniform(0.6, 1.0, 0.8)
        x0, x1 = sorted((side * w, side * (w - 0.45 * w)))
        parts.append(rounded_box((x0, -d - length, 0.0), (x1, -d + rad * 2, hs), rad))
    return compose(parts, spacing=spacing, margin=margin, name="sofa")
