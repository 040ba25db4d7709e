"""The long fuzz run: thousands of mutated inputs through the pipeline or the command line.

Same engine as ``tests/test_fuzz.py`` (``tests/io/fuzz_seeds.py``,
``fuzz_mutations.py``, ``fuzz_runner.py``; this script puts ``tests/io`` on
``sys.path`` as pytest does), with more mutants and other run seeds. Mutant
``(seed, index)`` is reproducible on its own, so a failure found here can be
rebuilt with ``--only INDEX``::

    python benchmarks/fuzz_inputs.py --n 5000 --seed 0 --save-failures /tmp/fuzz-failures
    python benchmarks/fuzz_inputs.py --seed 0 --only 1234 --save-failures /tmp/one

``--mode pipeline`` (default) runs ``load_input → prepare_inputs → reconstruct``
in-process; ``--mode cli`` runs every mutant through ``slicerecon run`` and
``slicerecon info`` as a user does (``--max-memory`` = ``--budget-gib``, each
command limited to ``--command-timeout`` seconds, the worker's address space to
``--memory-gib``), so tracebacks, stray Python warnings lines and untidy stderr
count as failures too::

    python benchmarks/fuzz_inputs.py --mode cli --n 10000 --budget-gib 0.5 --memory-gib 2

It prints a table of outcomes per format (``ok``, ``error`` = a SlicereconError,
``escape`` = any other exception, ``memory``, ``timeout``, ``crash``), every
distinct failure (kind, exception, innermost slicerecon frame, formats, one
example), the exceptions that readers turned into project errors (worth a look:
a catch-all boundary hides them), and a markdown snippet for ``docs/results.md``.
Each failing input is copied to ``--save-failures DIR/<kind>-<exception>/<index>-<format>/``
with ``case.json`` (mutations, outcome, traceback).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "io"))

import fuzz_mutations  # noqa: E402 - tests/io, as on pytest's pythonpath
import fuzz_runner  # noqa: E402
import fuzz_seeds  # noqa: E402


def _save(outcome: fuzz_runner.Outcome, directory: Path) -> Path:
    mutant = outcome.mutant
    group = f"{outcome.kind}-{outcome.error or 'none'}".replace(" ", "_")
    target = directory / group / f"{mutant.index:06d}-{mutant.format}"
    if target.exists():
        shutil.rmtree(target)
    target.mkdir(parents=True)
    if mutant.path.is_dir():
        shutil.copytree(mutant.path, target / mutant.path.name)
    else:
        shutil.copyfile(mutant.path, target / mutant.path.name)
    record = {
        "index": mutant.index,
        "format": mutant.format,
        "seed": mutant.seed,
        "input": mutant.path.name,
        "mutations": list(mutant.mutations),
        "method": mutant.method,
        "pixel_spacing": mutant.pixel_spacing,
        "kind": outcome.kind,
        "error": outcome.error,
        "message": outcome.message,
        "where": outcome.where,
        "raised_at": outcome.raised_at,
        "traceback": outcome.traceback,
        "seconds": round(outcome.seconds, 3),
    }
    (target / "case.json").write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    return target


def _revision() -> str:
    """The commit of the slicerecon being fuzzed, ``+modified`` when its files differ from it."""
    import slicerecon

    root = Path(slicerecon.__file__).resolve().parents[1]
    try:
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        changed = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "slicerecon"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "(not a git checkout)"
    return commit + ("+modified" if changed else "")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=5000, help="number of mutants (default 5000)")
    parser.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    parser.add_argument(
        "--only",
        type=int,
        nargs="+",
        metavar="INDEX",
        help="run only these mutant indices (to reproduce a failure)",
    )
    parser.add_argument(
        "--edge-fraction",
        type=float,
        default=fuzz_mutations.EDGE_FRACTION,
        help="share of mutants made from valid but awkward inputs",
    )
    parser.add_argument(
        "--default-method-fraction",
        type=float,
        default=fuzz_mutations.DEFAULT_METHOD_FRACTION,
        help="share of mutants reconstructed with the default method "
        "(the rest: method='sdf', planner='none', carve=False)",
    )
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument(
        "--mode",
        choices=fuzz_runner.MODES,
        default="pipeline",
        help="the library pipeline, or `slicerecon run` and `slicerecon info` (cli)",
    )
    parser.add_argument(
        "--command-timeout",
        type=float,
        default=20.0,
        help="--mode cli: seconds one command may take (default 20)",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=None,
        help="seconds per case before the worker is killed (default 10; "
        "--mode cli: twice --command-timeout plus 10)",
    )
    parser.add_argument(
        "--memory-gib",
        type=float,
        default=2.0,
        help="address-space limit of each worker, GiB (default 2)",
    )
    parser.add_argument(
        "--budget-gib",
        type=float,
        default=0.125,
        help="memory_budget_gb given to the library (default 0.125)",
    )
    parser.add_argument(
        "--save-failures",
        type=Path,
        metavar="DIR",
        help="copy every failing input here, with case.json",
    )
    parser.add_argument("--workdir", type=Path, help="where mutants are written (default: temp)")
    parser.add_argument("--markdown", type=Path, help="also write the markdown snippet here")
    args = parser.parse_args(argv)
    if args.timeout is None:
        args.timeout = 2 * args.command_timeout + 10 if args.mode == "cli" else 10.0

    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="slicerecon-fuzz-"))
    seeds = fuzz_seeds.write_seeds(workdir / "seeds")
    indices = args.only if args.only else range(args.n)

    def cases():  # type: ignore[no-untyped-def]
        yield from fuzz_mutations.seed_cases(seeds)
        for index in indices:
            yield fuzz_mutations.make_mutant(
                seeds,
                index,
                seed=args.seed,
                directory=workdir / "mutants",
                edge_fraction=args.edge_fraction,
                default_method_fraction=args.default_method_fraction,
            )

    outcomes: list[fuzz_runner.Outcome] = []
    start = time.perf_counter()
    for outcome in fuzz_runner.run_mutants(
        cases(),
        workers=args.workers,
        timeout=args.timeout,
        memory=int(args.memory_gib * 2**30),
        budget_gb=args.budget_gib,
        log_dir=workdir / "logs",
        mode=args.mode,
        command_timeout=args.command_timeout,
    ):
        if outcome.mutant.index < 0:
            if outcome.kind != "ok":
                print(
                    f"seed {outcome.mutant.format}/{outcome.mutant.seed} not read: "
                    f"{outcome.kind} {outcome.error}: {outcome.message}",
                    file=sys.stderr,
                )
            continue
        outcomes.append(outcome)
        if outcome.failed and args.save_failures is not None:
            _save(outcome, args.save_failures)
        if not outcome.failed or args.save_failures is not None:
            shutil.rmtree(outcome.mutant.path.parent, ignore_errors=True)
        if len(outcomes) % (100 if args.mode == "cli" else 500) == 0:
            failed = sum(o.failed for o in outcomes)
            print(
                f"{len(outcomes)} cases, {failed} failures, {time.perf_counter() - start:.0f} s",
                file=sys.stderr,
            )
    wall = time.perf_counter() - start

    print(fuzz_runner.failure_report(outcomes, fuzz_seeds.FORMATS))
    causes = Counter(o.cause for o in outcomes if o.cause)
    if causes:
        print("\nproject errors raised from other exceptions (cause at its innermost frame):")
        for cause, count in causes.most_common():
            print(f"{count:5d}  {cause}")
    slow = sorted(outcomes, key=lambda o: -o.seconds)[:5]
    print(
        "\nslowest cases: "
        + ", ".join(
            f"{o.mutant.index} ({o.mutant.format}, {o.kind}, {o.seconds:.1f} s)" for o in slow
        )
    )

    options = [f"--n {len(outcomes)}", f"--seed {args.seed}"]
    if args.mode != "pipeline":
        options.append(f"--mode {args.mode}")
    for name in (
        "edge_fraction",
        "default_method_fraction",
        "command_timeout",
        "memory_gib",
        "budget_gib",
    ):
        if getattr(args, name) != parser.get_default(name):
            options.append(f"--{name.replace('_', '-')} {getattr(args, name):g}")
    if args.timeout != (2 * args.command_timeout + 10 if args.mode == "cli" else 10.0):
        options.append(f"--timeout {args.timeout:g}")
    limits = (
        f"each command {args.command_timeout:g} s (worker killed at {args.timeout:g} s)"
        if args.mode == "cli"
        else f"{args.timeout:g} s per case"
    )
    through = (
        "through `slicerecon run` and `slicerecon info`"
        if args.mode == "cli"
        else "through the library pipeline"
    )
    title = (
        f"`python benchmarks/fuzz_inputs.py {' '.join(options)}` on slicerecon {_revision()}: "
        f"{len(outcomes)} mutated inputs "
        f"({through}), "
        f"{args.workers} workers, {limits}, {args.memory_gib:g} GiB (RLIMIT_AS) per worker, "
        f"memory budget {args.budget_gib:g} GiB; {wall:.0f} s "
        f"({len(outcomes) / max(wall, 1e-9):.2f} mutants/s) on {platform.platform(terse=True)}, "
        f"Python {platform.python_version()}, {os.cpu_count()} CPUs."
    )
    snippet = fuzz_runner.markdown_summary(outcomes, fuzz_seeds.FORMATS, title=title)
    print("\n" + snippet)
    if args.markdown is not None:
        args.markdown.write_text(snippet, encoding="utf-8")
    failed = any(o.failed for o in outcomes)
    if failed and args.save_failures is None:
        print(f"failing inputs kept under {workdir / 'mutants'}", file=sys.stderr)
    elif args.workdir is None:
        shutil.rmtree(workdir, ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
