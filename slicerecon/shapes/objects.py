"""Vehicles and objects: an airplane, a car, a rifle and a guitar."""

from __future__ import annotations

import math

import numpy as np

from ..sections import Volume
from .draws import Draws
from .grid import Part, Spacing, compose
from .params import Mm, Seed, checked, reject_if
from .solids import capsule, frustum, prism, rounded_box


@checked
def airplane(
    length: Mm = 100.0,
    wingspan: Mm = 100.0,
    fuselage_radius: Mm = 6.0,
    wing_chord: Mm = 20.0,
    wing_thickness: Mm = 4.0,
    *,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """An airplane: a tapered fuselage, swept wings, a tailplane, a fin and engines.

    The nose points to ``+x``, the wings span y, the fin rises along ``+z``.

    Parameters
    ----------
    length : float, default 100
        Fuselage length along x, mm.
    wingspan : float, default 100
        Tip-to-tip span along y, mm.
    fuselage_radius : float, default 6
        Fuselage radius at its widest, mm.
    wing_chord, wing_thickness : float, default 20, 4
        Wing chord at the root and thickness, mm; the tail surfaces are as thick.
    seed : int, optional
        Seed of the structure: sweep, taper, wing position (low or mid),
        T-tail or conventional tail, 0, 2 or 4 engines.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    half = length / 2.0
    span = wingspan / 2.0
    rf = fuselage_radius
    chord = wing_chord
    th = wing_thickness
    draws = Draws(seed)
    reject_if("airplane", rf >= half / 2, "fuselage_radius must be under a quarter of the length")
    reject_if("airplane", th >= 2 * rf, "wing_thickness must be under the fuselage diameter")
    sweep = math.tan(math.radians(draws.uniform(0.0, 35.0, 25.0)))
    taper = draws.uniform(0.3, 0.7, 0.4)
    wing_z = -0.5 * rf if draws.uniform(0.0, 1.0, 0.0) > 0.5 else 0.0
    le_root = half * draws.uniform(0.05, 0.3, 0.15) + chord / 2
    parts = [
        capsule((-half + 0.5 * rf, 0.0, 0.3 * rf), (0.0, 0.0, 0.0), 0.5 * rf, rf),
        capsule((0.0, 0.0, 0.0), (half - 0.8 * rf, 0.0, 0.0), rf, 0.8 * rf),
    ]

    def wing(root_le: float, root_chord: float, tip: float, z0: float) -> list[Part]:
        out = []
        for sy in (-1.0, 1.0):
            tip_le = root_le - tip * sweep
            poly = [
                (root_le, 0.0),
                (root_le - root_chord, 0.0),
                (tip_le - root_chord * taper, sy * tip),
                (tip_le, sy * tip),
            ]
            out.append(prism(poly, 2, z0 - th / 2, z0 + th / 2))
        return out

    parts += wing(le_root, chord, span, wing_z)
    tail_chord = 0.45 * chord
    tail_le = -half + 1.2 * tail_chord
    fin_h = 2.2 * rf + 0.15 * span
    fin = [
        (tail_le, 0.0),
        (-half + 0.3 * rf, 0.0),
        (-half + 0.3 * rf - 0.2 * fin_h, fin_h),
        (-half + 0.3 * rf - 0.2 * fin_h + 0.6 * tail_chord, fin_h),
    ]
    parts.append(prism(fin, 1, -th / 2, th / 2))
    t_tail = draws.uniform(0.0, 1.0, 0.0) > 0.6
    tail_z = fin_h - th / 2 if t_tail else 0.0
    tail_root = tail_le - (0.2 * fin_h if t_tail else 0.0)
    parts += wing(tail_root, tail_chord, 0.35 * span, tail_z)
    engines = int(draws.rng.integers(0, 3)) * 2 if draws.seeded else 2
    for k in range(engines // 2):
        ye = span * (0.35 + 0.3 * k)
        local_chord = chord * (1.0 - (1.0 - taper) * ye / span)
        mid = le_root - ye * sweep - local_chord / 2
        re = 0.45 * rf
        ze = wing_z - th / 2 - 0.4 * re
        for sy in (-1.0, 1.0):
            nacelle = ((mid - 0.12 * half, sy * ye, ze), (mid + 0.12 * half, sy * ye, ze))
            parts.append(capsule(*nacelle, re))
    return compose(parts, spacing=spacing, margin=margin, name="airplane")


CAR_STYLES = ("sedan", "hatchback", "pickup")


@checked
def car(
    length: Mm = 100.0,
    width: Mm = 45.0,
    body_height: Mm = 18.0,
    cabin_height: Mm = 15.0,
    wheel_radius: Mm = 10.0,
    wheel_width: Mm = 8.0,
    *,
    style: str | None = None,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A car: a rounded body, a trapezoidal cabin and four wheels.

    Parameters
    ----------
    length, width : float, default 100, 45
        Body size along x (front at ``+x``) and y, mm.
    body_height, cabin_height : float, default 18, 15
        Height of the body block and of the cabin on top of it, mm.
    wheel_radius, wheel_width : float, default 10, 8
        Wheels (cylinders along y, standing on ``z = 0``), mm.
    style : {"sedan", "hatchback", "pickup"}, optional
        Cabin layout. Default: drawn from ``seed`` (``"sedan"`` without a seed).
    seed : int, optional
        Seed of the structure: style, wheelbase, cabin position and slopes.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    half = length / 2.0
    hw = width / 2.0
    hb = body_height
    hc = cabin_height
    rw = wheel_radius
    ww = wheel_width
    draws = Draws(seed)
    kind = draws.style(style, CAR_STYLES, "car")
    reject_if("car", ww >= hw, "wheel_width must be under half the width")
    reject_if("car", rw >= half / 2, "wheel_radius must be under a quarter of the length")
    z0 = 0.6 * rw
    top = z0 + hb
    parts = [rounded_box((-half, -hw, z0), (half, hw, top), 0.25 * min(hb, hw))]
    wheelbase = half * draws.uniform(0.55, 0.7, 0.62)
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            y0, y1 = sorted((sy * hw, sy * (hw - ww)))
            parts.append(frustum((sx * wheelbase, y0, rw), (sx * wheelbase, y1, rw), rw))
    front_slope = hc * draws.uniform(0.8, 1.6, 1.2)
    rear_slope = hc * draws.uniform(0.4, 1.2, 0.8)
    if kind == "sedan":
        x0, x1 = -0.5 * half, 0.35 * half
    elif kind == "hatchback":
        x0, x1 = -0.9 * half, 0.3 * half
        rear_slope *= 0.3
    else:
        x0, x1 = -0.05 * half, 0.4 * half
        rear_slope *= 0.2
    limit = 0.7 * (x1 - x0)
    if front_slope + rear_slope > limit:  # keep the cabin's roof a proper edge
        scale = limit / (front_slope + rear_slope)
        front_slope, rear_slope = front_slope * scale, rear_slope * scale
    shift = half * draws.uniform(-0.05, 0.05, 0.0)
    x0, x1 = x0 + shift, x1 + shift
    cabin = [
        (x0, top - 1.0),
        (x1, top - 1.0),
        (x1 - front_slope, top + hc),
        (x0 + rear_slope, top + hc),
    ]
    parts.append(prism(cabin, 1, -0.85 * hw, 0.85 * hw))
    return compose(parts, spacing=spacing, margin=margin, name="car")


@checked
def rifle(
    length: Mm = 110.0,
    stock_height: Mm = 20.0,
    barrel_radius: Mm = 3.5,
    thickness: Mm = 10.0,
    *,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A rifle: barrel, receiver, stock, pistol grip, magazine and an optional scope.

    The muzzle points to ``+x``; the rifle lies in the x–z plane, ``thickness``
    thick along y.

    Parameters
    ----------
    length : float, default 110
        Overall length along x, mm.
    stock_height : float, default 20
        Height of the stock at the butt, mm.
    barrel_radius : float, default 3.5
        Barrel radius, mm.
    thickness : float, default 10
        Thickness of receiver, stock and grip along y, mm.
    seed : int, optional
        Seed of the structure: barrel share of the length, grip angle,
        magazine length and curvature, scope or not.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    half = length / 2.0
    hs = stock_height
    rb = barrel_radius
    ht = thickness / 2.0
    draws = Draws(seed)
    reject_if("rifle", rb >= 2 * ht, "barrel_radius must be under the thickness")
    rh = max(0.35 * hs, 1.2 * rb)  # receiver half height
    rec0 = -half + half * draws.uniform(0.7, 0.9, 0.8)
    rec1 = rec0 + half * draws.uniform(0.4, 0.6, 0.5)
    parts = [
        capsule((rec1 - rb, 0.0, 0.3 * rh), (half - rb, 0.0, 0.3 * rh), rb),
        rounded_box((rec0, -ht, -rh), (rec1, ht, rh), 0.3 * ht),
        prism(
            [(rec0 + 1.0, rh), (rec0 + 1.0, -0.5 * rh), (-half, rh - hs), (-half, rh)],
            1,
            -0.9 * ht,
            0.9 * ht,
        ),
    ]
    grip_len = 1.1 * hs
    grip_angle = math.radians(draws.uniform(10.0, 30.0, 20.0))
    gx = rec0 + 0.2 * (rec1 - rec0)
    gw = 0.45 * hs
    dx, dz = grip_len * math.sin(grip_angle), grip_len * math.cos(grip_angle)
    parts.append(
        prism(
            [(gx, -rh + 1.0), (gx + gw, -rh + 1.0), (gx + gw - dx, -rh - dz), (gx - dx, -rh - dz)],
            1,
            -0.8 * ht,
            0.8 * ht,
        )
    )
    mag_len = hs * draws.uniform(1.0, 2.2, 1.5)
    mag_lean = mag_len * draws.uniform(0.0, 0.5, 0.2)
    mx = rec0 + 0.6 * (rec1 - rec0)
    mw = 0.5 * hs
    parts.append(
        prism(
            [
                (mx, -rh + 1.0),
                (mx + mw, -rh + 1.0),
                (mx + mw + mag_lean, -rh - mag_len),
                (mx + mag_lean, -rh - mag_len),
            ],
            1,
            -0.7 * ht,
            0.7 * ht,
        )
    )
    if draws.uniform(0.0, 1.0, 0.0) > 0.5:
        sz = rh + 1.6 * rb + 0.3 * hs
        rs = 0.8 * rb + 0.1 * hs
        for fx in (0.2, 0.8):
            x = rec0 + fx * (rec1 - rec0)
            parts.append(rounded_box((x - rb, -rb, rh - 1.0), (x + rb, rb, sz), 0.5))
        parts.append(capsule((rec0 - 0.1 * half, 0.0, sz), (rec1 + 0.1 * half, 0.0, sz), rs))
    return compose(parts, spacing=spacing, margin=margin, name="rifle")


GUITAR_STYLES = ("acoustic", "electric")


@checked
def guitar(
    body_length: Mm = 48.0,
    body_width: Mm = 38.0,
    body_thickness: Mm = 10.0,
    neck_length: Mm = 45.0,
    neck_width: Mm = 6.0,
    head_length: Mm = 16.0,
    *,
    style: str | None = None,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A guitar: a body of two bouts, a neck and a headstock, lying flat (thickness along z).

    Parameters
    ----------
    body_length, body_width, body_thickness : float, default 48, 38, 10
        Body size along x (kept between 1.15 and 1.85 times the bouts' mean
        diameter, so that the bouts overlap) and y (at the lower bout), and
        its thickness, mm.
    neck_length, neck_width : float, default 45, 6
        Neck beyond the body along ``+x``, mm (the neck is ``0.7 *
        body_thickness`` thick, at least ``neck_width``).
    head_length : float, default 16
        Headstock length, mm (1.6 times the neck's width).
    style : {"acoustic", "electric"}, optional
        ``"electric"`` cuts two horns into the upper bout. Default: drawn from
        ``seed`` (``"acoustic"`` without a seed).
    seed : int, optional
        Seed of the structure: style, upper-bout size, headstock angle.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    bl = body_length
    rl = body_width / 2.0
    bt = body_thickness / 2.0
    nl = neck_length
    nw = neck_width / 2.0
    hl = head_length
    draws = Draws(seed)
    kind = draws.style(style, GUITAR_STYLES, "guitar")
    reject_if("guitar", 1.6 * nw >= rl, "neck_width must be well under the body width")
    ru = rl * draws.uniform(0.65, 0.85, 0.78)
    # centre distance of the bouts, kept so that they overlap into one body
    apart = float(np.clip(bl - rl - ru, 0.3 * (rl + ru), 0.85 * (rl + ru)))
    xl = -(rl + ru + apart) / 2 + rl
    xu = xl + apart
    parts = [
        frustum((xl, 0.0, -bt), (xl, 0.0, bt), rl),
        frustum((xu, 0.0, -bt), (xu, 0.0, bt), ru),
    ]
    neck_t = max(1.4 * bt, 2 * nw)
    end = xu + ru + nl
    parts.append(rounded_box((xu, -nw, bt - neck_t), (end + 1.0, nw, bt), 0.3 * nw))
    head_t = 0.7 * neck_t
    drop = hl * math.tan(math.radians(draws.uniform(0.0, 15.0, 8.0)))
    head = [(end, bt - head_t), (end, bt), (end + hl, bt - drop), (end + hl, bt - drop - head_t)]
    parts.append(prism(head, 1, -1.6 * nw, 1.6 * nw))
    minus = []
    if kind == "electric":
        for sy, size in ((1.0, 0.5), (-1.0, 0.4)):
            rc = size * ru
            minus.append(
                frustum(
                    (xu + 0.6 * ru, sy * (ru + 0.2 * rc), -2 * bt),
                    (xu + 0.6 * ru, sy * (ru + 0.2 * rc), 2 * bt),
                    rc,
                )
            )
    return compose(parts, minus=minus, spacing=spacing, margin=margin, name="guitar")
