"""Fuzzing: no exception but slicerecon's own escapes load_input → prepare_inputs → reconstruct.

Tiny valid seeds of every input format (NIfTI ``.nii`` / ``.nii.gz``, DICOM
series, SEG, RTSTRUCT alone and beside its series, JSON and CSV contours, VTI)
are written here and mutated with a fixed seed (``tests/io/fuzz_seeds.py``,
``tests/io/fuzz_mutations.py``). Each mutant runs through the pipeline in a
worker process with an address-space limit and a per-case time limit
(``tests/io/fuzz_runner.py``). A :class:`~slicerecon.errors.SlicereconError`
is a clear refusal and passes; any other exception, a ``MemoryError``, a
timeout or a dead worker fails the test, which then lists every distinct
failure with an input kept under ``tmp_path/mutants``.

The longer run is ``benchmarks/fuzz_inputs.py`` (same engine, 5,000+ mutants).
"""

from __future__ import annotations

import os
import shutil
import sys
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import fuzz_mutations  # tests/io, on pytest's pythonpath
import fuzz_runner
import fuzz_seeds
import pytest

pytestmark = pytest.mark.skipif(
    sys.platform == "win32", reason="the fuzz workers use select() on pipes and RLIMIT_AS (POSIX)"
)

N_MUTANTS = 540
"""Mutants per run: 60 per format."""
RUN_SEED = 20240601
WORKERS = max(1, min(2, os.cpu_count() or 1))
TIMEOUT_S = 10.0
"""Wall-clock limit per case; a legitimate case takes milliseconds."""
MEMORY_LIMIT = 2 << 30
"""Address-space limit of each worker process (RLIMIT_AS), bytes."""
BUDGET_GB = 0.125
"""``memory_budget_gb`` given to load_input / prepare_inputs: grids over it must be refused,
grids under it must fit well within :data:`MEMORY_LIMIT` and :data:`TIMEOUT_S`."""


def _cases(seeds: list[fuzz_seeds.Seed], directory: Path) -> Iterator[fuzz_mutations.Mutant]:
    yield from fuzz_mutations.seed_cases(seeds)
    for index in range(N_MUTANTS):
        yield fuzz_mutations.make_mutant(seeds, index, seed=RUN_SEED, directory=directory)


def test_no_foreign_exception_escapes_the_pipeline(tmp_path: Path) -> None:
    seeds = fuzz_seeds.write_seeds(tmp_path / "seeds")
    outcomes = []
    for outcome in fuzz_runner.run_mutants(
        _cases(seeds, tmp_path / "mutants"),
        workers=WORKERS,
        timeout=TIMEOUT_S,
        memory=MEMORY_LIMIT,
        budget_gb=BUDGET_GB,
        log_dir=tmp_path / "logs",
    ):
        outcomes.append(outcome)
        if outcome.mutant.index >= 0 and not outcome.failed:
            shutil.rmtree(outcome.mutant.path.parent)  # keep the failing inputs only
    mutants = [o for o in outcomes if o.mutant.index >= 0]
    assert len(mutants) == N_MUTANTS

    failures = [o for o in outcomes if o.failed]
    assert not failures, (
        f"{len(failures)} of {len(outcomes)} inputs raised something other than a "
        f"SlicereconError (failing inputs kept under {tmp_path / 'mutants'}):\n"
        + fuzz_runner.failure_report(outcomes, fuzz_seeds.FORMATS)
    )

    refused_seeds = [o for o in outcomes if o.mutant.index < 0 and o.kind != "ok"]
    assert not refused_seeds, "valid seeds were refused:\n" + "\n".join(
        f"{o.mutant.format} {o.mutant.seed}: {o.error}: {o.message}" for o in refused_seeds
    )

    # the mutants exercise both sides of every reader: some are reconstructed, some refused
    kinds = {
        fmt: Counter(o.kind for o in mutants if o.mutant.format == fmt)
        for fmt in fuzz_seeds.FORMATS
    }
    one_sided = {fmt: dict(c) for fmt, c in kinds.items() if not (c["ok"] and c["error"])}
    assert not one_sided, f"formats whose mutants all pass or all fail: {one_sided}"
