"""Speed and memory at clinical sizes, as ratios against plain SDF interpolation.

Cases (written as NIfTI masks into a temporary folder):

* ``liver 340x285x120``: pyvista's frog liver resampled so that its cropped
  grid is 340 × 285 × 120 voxels of 0.62 × 0.62 × 1.33 mm (the size of a CT
  liver mask);
* ``liver 510x428x120``: the same mask at CT in-plane resolution (0.41 mm);
* ``liver 512x512x200``: the frog liver at 0.7 × 0.7 × 1.5 mm on a full
  512 × 512 × 200 CT grid;
* ``brain 512x512x300`` (procedural): slicerecon's procedural brain on a
  512 × 512 × 300 grid of 0.7 × 0.7 × 1.5 mm;
* ``sphere 256x256x256``: a ball of radius 126 voxels filling a 256³ grid of
  1 mm voxels, at 16 planes only (:data:`CASE_PLANES`; the in-process target
  is at most 1.7× plain SDF there).

For each case and each plane count (12, 24), in one fresh process per case:

* **in process**: the same planes reconstructed by plain signed-distance
  interpolation + marching cubes (:mod:`plain_sdf`) and by
  :func:`slicerecon.reconstruct.reconstruct` with the defaults, stage by stage,
  best of ``--repeat``, alternating; the ratio is slicerecon / plain;
* **end to end**: ``slicerecon run CASE --slices N`` and ``python
  benchmarks/plain_sdf.py CASE N`` as fresh processes at the same moment
  (alternating, best of ``--repeat``);
* **peak memory**: the peak resident set of a fresh ``slicerecon run`` process.

Absolute seconds vary with the machine and its load; the ratios are what to
compare. The script prints a markdown table (``--out FILE`` also writes it);
``docs/results.md`` shows the tables of::

    python benchmarks/bench_clinical.py
    python benchmarks/bench_clinical.py --planner lookahead --planes 12,24 \\
        --cases 'liver 510x428x120,brain 512x512x300,sphere 256x256x256'
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


# -- cases ---------------------------------------------------------------------------
def _resample(mask: np.ndarray, factors: tuple[float, float, float]) -> np.ndarray:
    """Resize a mask by per-axis factors (linear interpolation of the 0/1 mask, > 0.5)."""
    from scipy import ndimage

    return ndimage.zoom(mask.astype(np.float32), factors, order=1) > 0.5


def _place(mask: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """Put a cropped mask at the centre of an empty grid of ``shape``."""
    from slicerecon.sections import Volume

    lo, hi = Volume(mask).bounding_box_vox()
    crop = mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
    out = np.zeros(shape, dtype=np.uint8)
    start = [(n - c) // 2 for n, c in zip(shape, crop.shape, strict=True)]
    out[tuple(slice(s, s + c) for s, c in zip(start, crop.shape, strict=True))] = crop
    return out


def _liver() -> tuple[np.ndarray, np.ndarray]:
    from slicerecon.realshapes import frog_tissue

    liver = frog_tissue("liver")
    lo, hi = liver.bounding_box_vox()
    return liver.mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]], liver.spacing


CASE_PLANES = {"sphere 256x256x256": [16]}
"""Cases measured at their own plane counts instead of ``--planes``."""


def _liver_sized(liver: np.ndarray) -> np.ndarray:
    target = (334, 279, 114)  # the cropped grid is this plus 3 voxels of margin per side
    return _resample(liver, tuple(t / s for t, s in zip(target, liver.shape, strict=True)))


def liver_340() -> tuple[np.ndarray, tuple[float, float, float]]:
    """The 340 × 285 × 120 liver mask and its spacing (mm), as ``make_cases`` writes it."""
    return _place(_liver_sized(_liver()[0]), (340, 285, 120)), (0.62, 0.62, 1.33)


def make_cases(root: Path) -> dict[str, Path]:
    """Write the case masks as NIfTI files; return name → path."""
    import nibabel as nib

    from slicerecon.shapes import make_shape

    liver, spacing = _liver()
    cases: dict[str, tuple[np.ndarray, tuple[float, float, float]]] = {}
    size = _liver_sized(liver)
    cases["liver 340x285x120"] = (_place(size, (340, 285, 120)), (0.62, 0.62, 1.33))
    fine = _resample(size, (1.5, 1.5, 1.0))
    cases["liver 510x428x120"] = (_place(fine, (510, 428, 120)), (0.41, 0.41, 1.33))
    ct = _resample(liver, (spacing[0] / 0.7 * 1.6, spacing[1] / 0.7 * 1.6, spacing[2] / 1.5 * 1.3))
    cases["liver 512x512x200"] = (_place(ct, (512, 512, 200)), (0.7, 0.7, 1.5))
    brain = make_shape("brain")
    scale = min(480 / brain.shape[0], 480 / brain.shape[1], 280 / brain.shape[2])
    big = _resample(brain.mask, (scale, scale * 0.9, scale))
    cases["brain 512x512x300"] = (_place(big, (512, 512, 300)), (0.7, 0.7, 1.5))
    i, j, k = np.ogrid[:256, :256, :256]
    ball = (i - 127.5) ** 2 + (j - 127.5) ** 2 + (k - 127.5) ** 2 <= 126.0**2
    cases["sphere 256x256x256"] = (ball.astype(np.uint8), (1.0, 1.0, 1.0))
    paths = {}
    for name, (mask, sp) in cases.items():
        path = root / (name.replace(" ", "_") + ".nii.gz")
        nib.save(nib.Nifti1Image(mask, np.diag([*sp, 1.0])), path)
        paths[name] = path
    return paths


# -- one case, in a fresh process -----------------------------------------------------
def in_process(path: str, planes: list[int], repeat: int, planner: str) -> dict[str, Any]:
    """Time plain SDF and slicerecon's reconstruct on the same planes, in this process."""
    from plain_sdf import plain_sdf_mesh

    from slicerecon.io import load_input
    from slicerecon.reconstruct import prepare_inputs, reconstruct

    volume = load_input(path)
    out: dict[str, Any] = {}
    for n in planes:
        sections, projections, truth = prepare_inputs(volume, slices=n)
        assert truth is not None
        best_plain, best_ours, stages = np.inf, np.inf, {}
        for _ in range(repeat):
            start = time.perf_counter()
            plain_sdf_mesh(truth.mask, truth.affine, n)
            best_plain = min(best_plain, time.perf_counter() - start)
            start = time.perf_counter()
            result = reconstruct(sections, projections, planner=planner)
            total = time.perf_counter() - start
            if total < best_ours:
                best_ours, stages = total, dict(result.timings)
        out[str(n)] = {
            "plain_s": best_plain,
            "ours_s": best_ours,
            "stages": stages,
            "grid": list(truth.shape),
            "parts": len(result.plan.parts),
        }
    return out


def _child(args: list[str]) -> dict[str, Any]:
    """Run this script's ``--child`` mode in a fresh interpreter; return its result."""
    import json

    proc = subprocess.run(
        [sys.executable, __file__, "--child", *args], capture_output=True, text=True, check=True
    )
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _timed(command: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MiB) of a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    subprocess.run(command, capture_output=True, check=True)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return seconds, max(after, before) / 1024.0


def end_to_end(path: Path, n: int, repeat: int, tmp: Path, planner: str) -> dict[str, float]:
    """Fresh-process wall time of ``slicerecon run`` and of the plain SDF script."""
    exe = str(Path(sys.executable).with_name("slicerecon"))
    ours = [exe, "run", str(path), "--slices", str(n), "--planner", planner]
    ours += ["-o", str(tmp / "run"), "-q"]
    plain = [sys.executable, str(HERE / "plain_sdf.py"), str(path), str(n), str(tmp / "p.stl")]
    best = {"run_s": np.inf, "plain_s": np.inf}
    for _ in range(repeat):
        best["plain_s"] = min(best["plain_s"], _timed(plain)[0])
        best["run_s"] = min(best["run_s"], _timed(ours)[0])
    return best


def peak_memory(path: Path, n: int, tmp: Path, planner: str) -> float:
    """Peak RSS (MiB) of one fresh ``slicerecon run`` process (measured by a wrapper)."""
    code = (
        "import resource, sys\n"
        "from slicerecon.cli import main\n"
        f"main(['run', {str(path)!r}, '--slices', '{n}', '--planner', {planner!r}, "
        f"'-o', {str(tmp / 'mem')!r}, '-q'])\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(proc.stdout.strip().splitlines()[-1])


# -- report ---------------------------------------------------------------------------
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, help="markdown file to write")
    parser.add_argument("--planes", default="12,24")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--cases", help="comma-separated case names (default: all)")
    parser.add_argument("--planner", default="heuristic", help="slicerecon's planner")
    parser.add_argument(
        "--child", nargs=4, metavar=("PATH", "PLANES", "REPEAT", "PLANNER"), help=argparse.SUPPRESS
    )
    args = parser.parse_args(argv)
    if args.child:
        import json

        path, planes, repeat, planner = args.child
        counts = [int(p) for p in planes.split(",")]
        print(json.dumps(in_process(path, counts, int(repeat), planner)))
        return 0
    planes = [int(p) for p in args.planes.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        paths = make_cases(tmp)
        wanted = args.cases.split(",") if args.cases else list(paths)
        for name in wanted:
            path = paths[name]
            counts = CASE_PLANES.get(name, planes)
            print(f"{name}: in process", file=sys.stderr, flush=True)
            inner = _child([str(path), ",".join(map(str, counts)), str(args.repeat), args.planner])
            for n in counts:
                print(f"{name}, {n} planes: end to end", file=sys.stderr, flush=True)
                e2e = end_to_end(path, n, args.repeat, tmp, args.planner)
                mem = peak_memory(path, n, tmp, args.planner)
                rows.append((name, n, inner[str(n)], e2e, mem))
    lines = [
        "Measured by `"
        + shlex.join(["python", "benchmarks/bench_clinical.py", *(argv or sys.argv[1:])])
        + "` "
        f"({platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}); "
        f"best of {args.repeat}; defaults of `slicerecon run`"
        + ("." if args.planner == "heuristic" else f" but `--planner {args.planner}`."),
        "",
        "| case | cropped grid | planes | parts | plain SDF (s) | slicerecon reconstruct (s) "
        "| stages (s) | ratio in process | `slicerecon run` (s) | plain script (s) "
        "| ratio end to end | peak MiB of `run` |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, n, inner, e2e, mem in rows:
        stages = ", ".join(f"{k} {v:.2f}" for k, v in inner["stages"].items())
        lines.append(
            f"| {name} | {'x'.join(map(str, inner['grid']))} | {n} | {inner['parts']} "
            f"| {inner['plain_s']:.2f} | {inner['ours_s']:.2f} | {stages} "
            f"| {inner['ours_s'] / inner['plain_s']:.2f} | {e2e['run_s']:.2f} "
            f"| {e2e['plain_s']:.2f} | {e2e['run_s'] / e2e['plain_s']:.2f} | {mem:.0f} |"
        )
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)
    print(
        shlex.join(["python", "benchmarks/bench_clinical.py", *(argv or sys.argv[1:])]),
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
