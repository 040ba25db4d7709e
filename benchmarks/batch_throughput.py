"""Batch throughput: cases per minute in-process, and with 1 and 2 Dask workers.

Generates one directory of small NIfTI masks (seeded variants of four shape
families, about 20-40 voxels a side) and reconstructs it with
:func:`pipelines.batch.run_batch` into a fresh output directory per setting:

* ``workers=0``: one case after the other in this process, no Dask;
* ``workers=1`` / ``workers=2``: a ``distributed.LocalCluster`` with that many
  single-threaded worker processes, started and closed by ``run_batch``.

"wall s" is the whole ``run_batch`` call (discovery, hashing, cluster start
and stop, every case, ``summary.csv``; no HTML report). Cluster start and stop
alone is measured separately, so throughput with and without it can be told
apart. Numbers depend on the machine and on its load; the table says both.
Prints a markdown table (``--out FILE`` also writes it; ``docs/results.md``
shows it)::

    python benchmarks/batch_throughput.py --cases 12 --workers 0,1,2 --slices 8
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

from pipelines.batch import run_batch
from slicerecon.io.nifti import write_nifti
from slicerecon.reconstruct import ReconstructConfig
from slicerecon.shapes import make_shape

SHAPES: dict[str, dict[str, Any]] = {
    "sphere": {"radius": 9.0},
    "ellipsoid": {"radii": (11.0, 8.0, 6.0)},
    "y_branch": {"trunk_length": 15.0, "branch_length": 15.0, "spread": 10.0, "radius": 4.0},
    "torus": {"major": 10.0, "minor": 6.0},
}


def make_cases(indir: Path, n: int) -> None:
    """Write ``n`` seeded masks, cycling through :data:`SHAPES`."""
    names = list(SHAPES)
    for i in range(n):
        name = names[i % len(names)]
        volume = make_shape(name, seed=i, **SHAPES[name])
        write_nifti(volume, indir / f"{name}_{i:02d}.nii.gz")


def cluster_overhead(workers: int) -> float:
    """Seconds to start and close a LocalCluster of ``workers`` processes (and a client)."""
    from distributed import Client, LocalCluster

    start = time.perf_counter()
    with (
        LocalCluster(
            n_workers=workers, processes=True, threads_per_worker=1, dashboard_address=None
        ) as cluster,
        Client(cluster) as client,
    ):
        client.wait_for_workers(workers)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=12, help="number of generated cases")
    parser.add_argument("--workers", default="0,1,2", help="comma-separated worker counts")
    parser.add_argument("--slices", type=int, default=8)
    parser.add_argument("--out", type=Path, default=None, help="markdown file to write")
    args = parser.parse_args()
    settings = [int(w) for w in args.workers.split(",")]
    config = ReconstructConfig(slices=args.slices, n_points=10_000)
    load_before = os.getloadavg()
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        indir = Path(tmp) / "in"
        make_cases(indir, args.cases)
        for workers in settings:
            overhead = cluster_overhead(workers) if workers > 0 else 0.0
            start = time.perf_counter()
            result = run_batch(
                indir, Path(tmp) / f"out{workers}", config, workers=workers, report=False
            )
            wall = time.perf_counter() - start
            compute = max(wall - overhead, 1e-9)
            rows.append(
                {
                    "workers": workers,
                    "ok": result.n_ok,
                    "failed": result.n_failed,
                    "wall": wall,
                    "overhead": overhead,
                    "per_min": 60.0 * len(result.cases) / wall,
                    "per_min_net": 60.0 * len(result.cases) / compute,
                    "case_s": sum(c.seconds for c in result.cases) / len(result.cases),
                    "failures": [
                        (c.case, c.error_type, c.error)
                        for c in result.cases
                        if c.status == "failed"
                    ],
                }
            )
            print(
                f"workers={workers}: {wall:.1f} s, {rows[-1]['per_min']:.1f} cases/min "
                f"({result.n_ok} ok, {result.n_failed} failed)"
            )
    load_after = os.getloadavg()

    lines = [
        "# Batch throughput",
        "",
        f"`python benchmarks/batch_throughput.py --cases {args.cases} --workers "
        f"{args.workers} --slices {args.slices}`: {args.cases} generated NIfTI masks "
        "(sphere, ellipsoid, y_branch, torus; 20-40 voxels a side), "
        f"`ReconstructConfig(slices={args.slices}, n_points=10000)`, no HTML report.",
        "",
        f"Machine: {platform.platform()}, Python {platform.python_version()}, "
        f"{os.cpu_count()} CPUs; 1-minute load average {load_before[0]:.1f} before and "
        f"{load_after[0]:.1f} after (the machine was shared, so absolute times are noisy).",
        "",
        "| workers | mode | cases ok / failed | wall s | cluster start+stop s | cases/min "
        "| cases/min without start-up | mean s per case (in its worker) |",
        "|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        mode = "in-process" if r["workers"] == 0 else "LocalCluster"
        lines.append(
            f"| {r['workers']} | {mode} | {r['ok']} / {r['failed']} | {r['wall']:.1f} "
            f"| {r['overhead']:.1f} | {r['per_min']:.1f} | {r['per_min_net']:.1f} "
            f"| {r['case_s']:.2f} |"
        )
    failures = {case: (kind, error) for r in rows for case, kind, error in r["failures"]}
    if failures:
        lines += [
            "",
            "Cases that failed (counted in the throughput; the batch recorded them and went on):",
            "",
        ]
        lines += [f"* `{case}`: {kind}: {error}" for case, (kind, error) in failures.items()]
    cpus = os.cpu_count() or 1
    if min(load_before[0], load_after[0]) >= cpus:
        lines += [
            "",
            f"The load average stayed at or above the {cpus} CPUs during the run: other "
            "processes competed for the same cores, so the absolute numbers and the gain "
            "from more workers vary from run to run and understate what an idle machine "
            "gives.",
        ]
    lines += [
        "",
        '"cases/min without start-up" subtracts the separately measured cluster start '
        "and stop from the wall time. The first case on each new worker process also pays "
        "for importing slicerecon and its dependencies, which is part of the per-case "
        "seconds.",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)


if __name__ == "__main__":
    main()
