"""Fuzzing: no exception but slicerecon's own escapes load_input → prepare_inputs → reconstruct,
and ``slicerecon run`` / ``slicerecon info`` answer every mutant with a result or one line.

Tiny valid seeds of every input format (NIfTI ``.nii`` / ``.nii.gz``, DICOM
series, SEG (overlapping segments too), RTSTRUCT alone and beside its series,
JSON and CSV contours on axial, sagittal, coronal and oblique planes, VTI, NRRD
and 3D Slicer ``.seg.nrrd``) are written here and mutated with a fixed seed
(``tests/io/fuzz_seeds.py``, ``tests/io/fuzz_mutations.py``). Each mutant runs
in a worker process with an address-space limit and a per-case time limit
(``tests/io/fuzz_runner.py``). A :class:`~slicerecon.errors.SlicereconError`
is a clear refusal and passes; any other exception, a ``MemoryError``, a
timeout or a dead worker fails the test, which then lists every distinct
failure with an input kept under ``tmp_path/mutants``. Through the command line
a refusal must be exit 2 with exactly one ``error:`` line, and no Python
warnings line may reach stderr.

The longer runs are ``benchmarks/fuzz_inputs.py`` (same engine, 10,000 mutants;
``--mode cli`` for the command line).
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

N_MUTANTS = 550
"""Mutants per run: 50 per format."""
N_CLI_MUTANTS = 22
"""Mutants through the command line: 2 per format (each runs ``run`` and ``info``; the
seeds themselves go through the command line in ``benchmarks/fuzz_inputs.py --mode cli``)."""
CLI_BUDGET_GB = 0.5
"""``--max-memory`` of the command-line sample, well under :data:`MEMORY_LIMIT`."""
COMMAND_TIMEOUT_S = 20.0
"""Wall-clock limit of one command on an input of a few kB."""
RUN_SEED = 20240601
WORKERS = max(1, min(2, os.cpu_count() or 1))
TIMEOUT_S = 10.0
"""Wall-clock limit per case; a legitimate case takes milliseconds."""
MEMORY_LIMIT = 2 << 30
"""Address-space limit of each worker process (RLIMIT_AS), bytes."""
BUDGET_GB = 0.125
"""``memory_budget_gb`` given to load_input / prepare_inputs: grids over it must be refused,
grids under it must fit well within :data:`MEMORY_LIMIT` and :data:`TIMEOUT_S`."""


def _cases(
    seeds: list[fuzz_seeds.Seed], directory: Path, n: int = N_MUTANTS, *, with_seeds: bool = True
) -> Iterator[fuzz_mutations.Mutant]:
    if with_seeds:
        yield from fuzz_mutations.seed_cases(seeds)
    for index in range(n):
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


def test_the_command_line_answers_every_mutant_in_one_line(tmp_path: Path) -> None:
    """``slicerecon run`` and ``slicerecon info``: exit 0, or exit 2 and one ``error:`` line;
    never a traceback, a Python warnings line, another exit code or a run over 20 s."""
    seeds = fuzz_seeds.write_seeds(tmp_path / "seeds")
    outcomes = []
    for outcome in fuzz_runner.run_mutants(
        _cases(seeds, tmp_path / "mutants", N_CLI_MUTANTS, with_seeds=False),
        workers=WORKERS,
        timeout=2 * COMMAND_TIMEOUT_S + 10,
        memory=MEMORY_LIMIT,
        budget_gb=CLI_BUDGET_GB,
        log_dir=tmp_path / "logs",
        mode="cli",
        command_timeout=COMMAND_TIMEOUT_S,
    ):
        outcomes.append(outcome)
        if outcome.mutant.index >= 0 and not outcome.failed:
            shutil.rmtree(outcome.mutant.path.parent)
    assert len(outcomes) == N_CLI_MUTANTS
    failures = [o for o in outcomes if o.failed]
    assert not failures, (
        f"{len(failures)} of {len(outcomes)} inputs were not answered cleanly by the command "
        f"line (failing inputs kept under {tmp_path / 'mutants'}):\n"
        + fuzz_runner.failure_report(outcomes, fuzz_seeds.FORMATS)
    )
    assert {o.kind for o in outcomes} == {"ok", "error"}  # both sides, as the pipeline's
