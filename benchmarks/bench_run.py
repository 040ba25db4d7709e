"""Speed and memory of ``slicerecon run`` against marching cubes on the same grid.

For each test mask (about 256³ voxels) the script writes a NIfTI file, then in
this one process:

* runs the whole ``slicerecon run`` pipeline (:func:`slicerecon.reconstruct.run_case`,
  16 planes, the default planner and method) and reports its stage timings
  (read, sections, plan, surface, metrics, write incl. preview);
* runs the classical reference on the same grid: read the same file, marching
  cubes on the dense mask (:func:`slicerecon.surface.marching.volume_to_mesh`)
  and write the mesh;
* repeats both under ``tracemalloc`` for the peak Python/numpy memory.

Times are the best of ``--repeat`` runs. Ratios (run / marching cubes) are what
to compare across machines; absolute seconds depend on the machine. Prints a
markdown table (``--out FILE`` also writes it; ``docs/results.md`` shows it)::

    python benchmarks/bench_run.py
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

from slicerecon.case import run_case
from slicerecon.io.mesh import write_mesh
from slicerecon.io.nifti import read_nifti, write_nifti
from slicerecon.reconstruct import ReconstructConfig
from slicerecon.sections import Volume
from slicerecon.shapes import make_shape
from slicerecon.surface.marching import volume_to_mesh


def cases() -> dict[str, Volume]:
    """Masks on grids of about 256 voxels per side."""
    return {
        "sphere r=126": make_shape("sphere", radius=126.0, margin=2),  # a 256³ mask
        "chair x2.5": make_shape(
            "chair",
            seat_width=100.0,
            seat_depth=100.0,
            seat_thickness=12.5,
            leg_height=100.0,
            leg_width=12.5,
            back_height=112.5,
            back_thickness=12.5,
        ),
        "y_branch x2": make_shape("y_branch", spacing=0.5),
    }


def _marching_cubes(path: Path, out: Path) -> dict[str, float]:
    timings: dict[str, float] = {}
    start = time.perf_counter()
    volume = read_nifti(path)
    timings["read"] = time.perf_counter() - start
    start = time.perf_counter()
    mesh = volume_to_mesh(volume)
    timings["surface"] = time.perf_counter() - start
    start = time.perf_counter()
    write_mesh(mesh, out / "mc.stl")
    timings["write"] = time.perf_counter() - start
    return timings


def _run(path: Path, out: Path, config: ReconstructConfig) -> dict[str, float]:
    return dict(run_case(path, out, config)["timings_s"])


def _peak_mib(fn: Any, *args: Any) -> float:
    tracemalloc.start()
    try:
        fn(*args)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak / 2**20


def _best(fn: Any, repeat: int, *args: Any) -> dict[str, float]:
    runs = [fn(*args) for _ in range(repeat)]
    return min(runs, key=lambda t: sum(t.values()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slices", type=int, default=16)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--out", type=Path, help="write a markdown table here")
    args = parser.parse_args()
    config = ReconstructConfig(slices=args.slices)
    stages = ["read", "sections", "plan", "surface", "carve", "metrics", "write"]
    lines = [
        "Measured by `python benchmarks/bench_run.py` "
        f"({platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs, Python {sys.version.split()[0]}); best of {args.repeat}; "
        f"{args.slices} planes; default planner and method.",
        "",
        "| mask | grid | " + " | ".join(stages) + " | run total | run w/o metrics+preview "
        "| marching cubes total | ratio run/MC | ratio w/o metrics+preview /MC "
        "| peak MiB run | peak MiB MC |",
        "|---" * (len(stages) + 9) + "|",
    ]
    with tempfile.TemporaryDirectory() as tmp:
        for name, volume in cases().items():
            path = Path(tmp) / "mask.nii.gz"
            write_nifti(volume, path)
            out = Path(tmp) / "out"
            run_t = _best(_run, args.repeat, path, out, config)
            mc_t = _best(_marching_cubes, args.repeat, path, out)
            run_mem = _peak_mib(_run, path, out, config)
            mc_mem = _peak_mib(_marching_cubes, path, out)
            total = sum(run_t.values())
            core = total - run_t.get("metrics", 0.0) - run_t.get("write", 0.0)
            mc_total = sum(mc_t.values())
            cells = [f"{run_t.get(s, 0.0):.2f}" for s in stages]
            lines.append(
                f"| {name} | {'x'.join(map(str, volume.shape))} | "
                + " | ".join(cells)
                + f" | {total:.2f} | {core:.2f} | {mc_total:.2f} | {total / mc_total:.2f} "
                f"| {core / mc_total:.2f} "
                f"| {run_mem:.0f} | {mc_mem:.0f} |"
            )
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    if args.out:
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
