"""The ``slicerecon`` command line.

A thin Typer layer: each command fills a config, calls the library and prints.
Heavy modules are imported inside the commands so ``slicerecon --help`` is fast.
Errors the user can fix are printed as one line on stderr with a non-zero exit
code; ``--debug`` shows the full traceback instead.
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from . import __version__
from .errors import SlicereconError

app = typer.Typer(
    name="slicerecon",
    help="Reconstruct watertight 3D surfaces from parallel planar cross-sections.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",
)

EXIT_INPUT = 2
_state: dict[str, bool] = {"debug": False}


def _version(value: bool) -> None:
    if value:
        typer.echo(f"slicerecon {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log progress.")] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks on errors.")] = False,
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Show version.")
    ] = False,
) -> None:
    """Reconstruct watertight 3D surfaces from parallel planar cross-sections."""
    _state["debug"] = debug
    if verbose or debug:
        from rich.logging import RichHandler

        logging.basicConfig(
            level=logging.DEBUG if debug else logging.INFO,
            format="%(message)s",
            handlers=[RichHandler(show_path=False)],
        )


# ---------------------------------------------------------------------------- info
def _volume_info(volume: Any) -> dict[str, Any]:
    import numpy as np

    info: dict[str, Any] = {
        "kind": "dense mask",
        "shape": list(volume.shape),
        "spacing_mm": [round(float(s), 6) for s in volume.spacing],
        "oblique": volume.is_oblique,
        "foreground_voxels": int(np.count_nonzero(volume.mask)),
        "volume_mm3": round(volume.volume_mm3, 3),
    }
    if not volume.is_empty:
        lo, hi = volume.bounding_box_mm()
        info["bounding_box_mm"] = {"min": lo.round(3).tolist(), "max": hi.round(3).tolist()}
        for name, ax in (("x", 0), ("y", 1), ("z", 2)):
            planes = volume.occupied_planes(ax)
            info[f"planes_{name}"] = {
                "occupied": int(planes.size),
                "first": int(planes[0]),
                "last": int(planes[-1]),
            }
    return info


def _sections_info(sections: Any) -> dict[str, Any]:
    import numpy as np

    gaps = sections.gaps
    return {
        "kind": "cross-sections",
        "planes": sections.n_planes,
        "axis": "xyz"[sections.axis],
        "positions_mm": [round(float(p), 4) for p in sections.positions],
        "gap_mm": None
        if gaps.size == 0
        else {"min": round(float(gaps.min()), 4), "max": round(float(gaps.max()), 4)},
        "uniform_spacing": bool(gaps.size == 0 or np.ptp(gaps) < 1e-6),
        "in_plane_shape": list(sections.masks.shape[1:]),
        "grid_shape": list(sections.grid_shape),
        "spacing_mm": [round(float(s), 6) for s in sections.spacing],
    }


@app.command()
def info(
    input: Annotated[Path, typer.Argument(help="NIfTI, DICOM dir/SEG/RTSTRUCT, contours, mesh.")],
    label: Annotated[int | None, typer.Option(help="Label value or segment number.")] = None,
    roi: Annotated[str | None, typer.Option(help="RTSTRUCT ROI name or number.")] = None,
    allow_irregular: Annotated[
        bool, typer.Option("--allow-irregular", help="Accept uneven DICOM slice spacing.")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Describe an input: grid, spacing, labels, planes, bounding box (mm)."""
    from .io import detect_kind, load_input
    from .reconstruct import _roi
    from .sections import Volume

    kind = detect_kind(input)
    details: dict[str, Any] = {"path": str(input), "format": kind.kind}
    if kind.kind == "nifti":
        from .io.nifti import nifti_labels

        details["labels"] = nifti_labels(input).to_dict()["labels"]
    elif kind.kind in ("dicom-series", "dicom-seg"):
        from .io.dicom import dicom_info

        details["dicom"] = dicom_info(input)
    elif kind.kind == "rtstruct":
        from .io.rtstruct import list_rois

        details["rois"] = list_rois(input)
    data = load_input(input, label=label, roi=_roi(roi), allow_irregular=allow_irregular)
    details.update(_volume_info(data) if isinstance(data, Volume) else _sections_info(data))
    if as_json:
        typer.echo(json.dumps(details, indent=2, default=str))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=str(input), show_header=False)
    for key, value in details.items():
        table.add_row(key, json.dumps(value, default=str) if not isinstance(value, str) else value)
    Console().print(table)


# ----------------------------------------------------------------------------- run
@app.command()
def run(
    input: Annotated[Path, typer.Argument(help="Dense mask, sparse mask or contour input.")],
    outdir: Annotated[Path, typer.Option("-o", "--outdir", help="Output directory.")] = Path(
        "slicerecon-out"
    ),
    slices: Annotated[
        int | None, typer.Option("--slices", help="Keep N evenly spaced planes (default 16).")
    ] = None,
    every: Annotated[int | None, typer.Option("--every", help="Keep every K-th plane.")] = None,
    axis: Annotated[str, typer.Option(help="Plane normal axis: x, y or z.")] = "z",
    planner: Annotated[str, typer.Option(help="heuristic or none.")] = "heuristic",
    method: Annotated[str, typer.Option(help="Per-part surface: loft or sdf.")] = "loft",
    projections: Annotated[
        str, typer.Option(help="gt, sections or auto (gt for dense inputs).")
    ] = "auto",
    gt: Annotated[
        Path | None, typer.Option("--gt", help="Ground truth (mask or closed mesh).")
    ] = None,
    mesh_format: Annotated[str, typer.Option("--format", help="stl, ply or obj.")] = "stl",
    smooth: Annotated[bool, typer.Option("--smooth", help="Taubin-smooth the mesh.")] = False,
    carve: Annotated[
        bool, typer.Option("--carve/--no-carve", help="Cut the surface to the projections' hull.")
    ] = True,
    label: Annotated[int | None, typer.Option(help="Label value or segment number.")] = None,
    roi: Annotated[str | None, typer.Option(help="RTSTRUCT ROI name or number.")] = None,
    allow_irregular: Annotated[
        bool, typer.Option("--allow-irregular", help="Accept uneven DICOM slice spacing.")
    ] = False,
) -> None:
    """Reconstruct one input; write mesh, plan.json, metrics.json and preview.png."""
    from rich.console import Console

    from .reconstruct import ReconstructConfig, run_case

    config = ReconstructConfig(
        slices=slices,
        every=every,
        axis=axis,
        planner=planner,
        method=method,
        projections=projections,
        smooth=smooth,
        carve=carve,
        mesh_format=mesh_format,
        label=label,
        roi=roi,
        allow_irregular=allow_irregular,
    )
    console = Console(stderr=True)
    with console.status("reading") as status:
        summary = run_case(
            input, outdir, config, ground_truth=gt, progress=lambda s: status.update(s)
        )
    _print_summary(summary, outdir)


def _print_summary(summary: dict[str, Any], outdir: Path) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console()
    console.print(
        f"[bold]{summary['parts']}[/] part(s) from [bold]{summary['planes']}[/] planes -> "
        f"{summary['mesh']} (watertight: {summary['watertight']})"
    )
    metrics = summary.get("metrics")
    if metrics:
        table = Table("metric", "value", title="quality vs ground truth")
        for key, value in metrics.items():
            table.add_row(key, f"{value:.4g}" if isinstance(value, float) else str(value))
        console.print(table)
    times = ", ".join(f"{k} {v:.2f}s" for k, v in summary["timings_s"].items())
    console.print(f"time: {times}")
    console.print(f"outputs in {outdir}")


# ------------------------------------------------------------------------ evaluate
@app.command()
def evaluate(
    prediction: Annotated[Path, typer.Argument(help="Predicted mesh or mask.")],
    ground_truth: Annotated[Path, typer.Argument(help="Ground-truth mesh or mask.")],
    label: Annotated[int | None, typer.Option(help="Label of the ground truth.")] = None,
    n_points: Annotated[int, typer.Option(help="Surface samples per mesh.")] = 50_000,
    seed: Annotated[int, typer.Option(help="Sampling seed.")] = 0,
) -> None:
    """Print metrics of PREDICTION against GROUND_TRUTH as JSON."""
    from .io import detect_kind, load_input
    from .io.mesh import read_mesh
    from .metrics import evaluate as evaluate_metrics
    from .sections import Volume

    def load(path: Path, lab: int | None) -> Any:
        if detect_kind(path).kind == "mesh":
            return read_mesh(path)
        data = load_input(path, label=lab)
        if not isinstance(data, Volume):
            raise SlicereconError(f"{path} holds contours; evaluate needs a mesh or a dense mask")
        return data

    metrics = evaluate_metrics(
        load(prediction, None), load(ground_truth, label), n_points=n_points, seed=seed
    )
    typer.echo(json.dumps(metrics.to_dict(), indent=2))


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``slicerecon`` console script."""
    import click

    try:
        result = app(args=argv, prog_name="slicerecon", standalone_mode=False)
    except SlicereconError as exc:
        if _state["debug"]:
            raise
        typer.echo(f"error: {exc}", err=True)
        return EXIT_INPUT
    except click.exceptions.Exit as exc:
        return int(exc.exit_code)
    except click.ClickException as exc:
        exc.show()
        return int(exc.exit_code)
    except click.exceptions.Abort:
        typer.echo("aborted", err=True)
        return 130
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        return 130
    return int(result) if isinstance(result, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
