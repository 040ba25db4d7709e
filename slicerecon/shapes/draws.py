"""Seeded structural choices of the family shapes (style, proportions, noise)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import OptionError

STRUCTURE_STREAM = 0x5EED5
"""Entropy mixed into a shape's seed for its structure (style, noise), apart from its sizes."""


class Draws:
    """Random structural choices of a shape: drawn from a seed, canonical without one.

    ``uniform``, ``choice`` and ``style`` return their canonical value when
    the seed is None; ``rng`` (for noise patterns) is then a fixed generator,
    so the canonical shape is deterministic too.

    Parameters
    ----------
    seed : int or None
        A checked seed (:data:`slicerecon.shapes.params.Seed`).
    """

    def __init__(self, seed: int | None) -> None:
        self.seeded = seed is not None
        entropy = [STRUCTURE_STREAM] if seed is None else [STRUCTURE_STREAM, seed]
        self.rng = np.random.default_rng(entropy)

    def uniform(self, low: float, high: float, canonical: float) -> float:
        return float(self.rng.uniform(low, high)) if self.seeded else float(canonical)

    def choice(self, options: Sequence[str], canonical: str) -> str:
        return str(options[int(self.rng.integers(len(options)))]) if self.seeded else canonical

    def style(self, style: object, choices: tuple[str, ...], shape: str) -> str:
        """Validate an explicit ``style`` or draw one (the first choice is canonical)."""
        if style is None:
            return self.choice(choices, choices[0])
        if style not in choices:
            raise OptionError(f"{shape} style must be one of {', '.join(choices)} (got {style!r})")
        return str(style)
