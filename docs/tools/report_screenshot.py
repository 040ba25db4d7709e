"""The batch report of six mixed inputs, as a browser shows it: ``docs/figures/batch_report.png``.

The inputs are those of ``tests/pipelines/test_mixed_batch.py`` (a NIfTI
sphere, a multi-label NIfTI, a ``.seg.nrrd`` and a VTI of three organs, a CT
series with an RTSTRUCT of three ROIs, a corrupt file, and two files that are
not inputs). ``slicerecon batch`` runs them in this process and headless
Chromium (``chromium``, Debian package) renders ``report.html``::

    python docs/tools/report_screenshot.py [--out docs/figures/batch_report.png]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "batch_report.png")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=2600)
    args = parser.parse_args(argv)
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        print("error: chromium is not installed (apt-get install chromium)", file=sys.stderr)
        return 2
    sys.path[:0] = [str(ROOT / "tests" / "io"), str(ROOT / "tests" / "pipelines"), str(ROOT)]
    from test_mixed_batch import _write_inputs

    from slicerecon.cli import main as slicerecon

    work = Path(tempfile.mkdtemp(prefix="report-"))
    _write_inputs(work / "in")
    code = slicerecon(["batch", str(work / "in"), "-o", str(work / "out"), "--workers", "0"])
    report = work / "out" / "report.html"
    if not report.is_file():
        print(f"error: batch wrote no report (exit {code})", file=sys.stderr)
        return 1
    args.out.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            f"--window-size={args.width},{args.height}",
            f"--screenshot={args.out.resolve()}",
            report.resolve().as_uri(),
        ],
        check=True,
        capture_output=True,
        timeout=120,
    )
    print(f"batch exit {code}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
