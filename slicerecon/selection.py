"""Choosing a structure by number or name: label values, SEG segments, RTSTRUCT ROIs.

Every input that holds several structures names them by a number (a label
value, a SegmentNumber, a ROINumber) and, for SEG and RTSTRUCT, by a name (the
SegmentLabel, the ROIName). ``--label`` takes either; this module is the one
place that matches it, so that every format answers the same way.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .errors import LabelError, OptionError

__all__ = ["choose_structure", "choose_structures", "name_key", "parse_selector"]


def name_key(name: str) -> str:
    """A structure name as names are matched: case, spaces, ``_`` and ``-`` ignored.

    ``"Right kidney"``, ``"right_kidney"`` and ``"RightKidney"`` are one name
    (3D Slicer, RT planning systems and file names spell them differently).

    Parameters
    ----------
    name : str

    Returns
    -------
    str
    """
    return "".join(c for c in name.casefold() if not c.isspace() and c not in "_-")


def parse_selector(value: int | str | None) -> int | str | None:
    """Normalise a structure selector: an int stays, a string of digits becomes an int.

    Parameters
    ----------
    value : int, str or None
        ``3``, ``"3"``, ``" GTV "`` or None.

    Returns
    -------
    int, str or None
        The number, the stripped name, or None.

    Raises
    ------
    OptionError
        For an empty name or a value that is neither a number nor a string.
    """
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | np.integer | str):
        raise OptionError(f"a label is a number or a name (got {value!r})")
    if isinstance(value, int | np.integer):
        return int(value)
    text = value.strip()
    if not text:
        raise OptionError("--label is empty: give a number or a name")
    if text.lstrip("+-").isdigit():
        return int(text)
    return text


def _listing(structures: Mapping[int, str]) -> str:
    return ", ".join(f"{n}: {name}" if name else str(n) for n, name in structures.items())


def choose_structure(
    structures: Mapping[int, str],
    selector: int | str | None,
    *,
    kind: str,
    source: str | Path,
) -> int:
    """The number of the structure ``selector`` picks among ``structures``.

    A name matches exactly, else case- and space-insensitively. A string of
    digits names a structure whose name is exactly that string, else it is a
    number. With no selector, the only structure is chosen.

    Parameters
    ----------
    structures : mapping of int to str
        Structure number → name (``""`` when unnamed, e.g. label-map values).
    selector : int, str or None
        What the user asked for (see :func:`parse_selector`).
    kind : str
        What a structure is called in this input (``"label"``, ``"segment"``,
        ``"ROI"``), for messages.
    source : str or Path
        The input, for messages.

    Returns
    -------
    int
        The chosen structure's number.

    Raises
    ------
    LabelError
        Nothing matches, a name matches several structures, or no selector
        was given while there are several (the message lists them).
    """
    if not structures:
        raise LabelError(f"{source} holds no {kind}")
    if selector is None:
        if len(structures) == 1:
            return next(iter(structures))
        raise LabelError(
            f"{source} holds {len(structures)} {kind}s ({_listing(structures)}); "
            "choose one with --label (a number or a name)"
        )
    if isinstance(selector, str):
        exact = [n for n, name in structures.items() if name == selector]
        folded = exact or [
            n for n, name in structures.items() if name and name_key(name) == name_key(selector)
        ]
        if len(folded) == 1:
            return folded[0]
        if len(folded) > 1:
            raise LabelError(
                f"{kind} name {selector!r} names several {kind}s in {source} "
                f"({_listing({n: structures[n] for n in folded})}); choose one by number"
            )
        number = parse_selector(selector)
        if isinstance(number, int) and number in structures:
            return number
        if not any(structures.values()):
            raise LabelError(
                f"{kind} {selector!r} is not in {source}: its {kind}s have numbers, not "
                f"names; choose one of {_listing(structures)}"
            )
    elif int(selector) in structures:
        return int(selector)
    raise LabelError(
        f"{kind} {selector!r} is not in {source}; its {kind}s are: {_listing(structures)}"
    )


def choose_structures(
    structures: Mapping[int, str], selectors: Sequence[int | str], *, source: Any
) -> list[int]:
    """The numbers of the structures ``selectors`` pick (``--label A,B``), in the order given.

    Each selector as :func:`choose_structure` reads it (``kind="label"``); a
    structure picked twice is kept once.

    Raises
    ------
    LabelError
        A selector names no structure (the message lists them).
    """
    chosen: list[int] = []
    for selector in selectors:
        value = choose_structure(structures, parse_selector(selector), kind="label", source=source)
        if value not in chosen:
            chosen.append(value)
    return chosen
