"""The commands that read, reconstruct, score and report cases.

Each command fills a :class:`~slicerecon.reconstruct.ReconstructConfig`, calls
the library and prints; heavy modules are imported inside the commands.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Annotated, Any

import typer

from ..console import StageProgress, ctrl_c_after, print_run_summary
from ..errors import SlicereconError
from .app import (
    DEFAULT_MAX_MEMORY_GB,
    AnnotationOpt,
    AxisOpt,
    CarveOpt,
    CoverOpt,
    DriftOpt,
    EveryOpt,
    FormatOpt,
    InterpolationOpt,
    IrregularOpt,
    LabelOpt,
    MaxMemoryOpt,
    MethodOpt,
    PixelSpacingOpt,
    PlannerOpt,
    ProjectionsOpt,
    RoiOpt,
    SlicesOpt,
    SmoothOpt,
    UnionOpt,
    WeightsOpt,
    app,
    show_messages,
)


@app.command()
def info(
    input: Annotated[Path, typer.Argument(help="NIfTI, DICOM dir/SEG/RTSTRUCT, contours, mesh.")],
    label: Annotated[
        str | None, typer.Option(help="Also describe one structure (number or name).")
    ] = None,
    roi: Annotated[str | None, typer.Option(help="Another name for --label.")] = None,
    allow_irregular: Annotated[
        bool, typer.Option("--allow-irregular", help="Accept uneven DICOM slice spacing.")
    ] = False,
    max_memory: MaxMemoryOpt = DEFAULT_MAX_MEMORY_GB,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Describe an input: grid, spacing, every structure with its planes and extent (mm)."""
    from ..io.describe import describe_input

    details = describe_input(
        input,
        label=label if label is not None else roi,
        allow_irregular=allow_irregular,
        memory_budget_gb=max_memory,
    )
    from ..case_inputs import reading_of

    if "not_a_label_map" not in details:
        try:
            read_as = reading_of(
                input, allow_irregular=allow_irregular, memory_budget_gb=max_memory
            )
        except SlicereconError as exc:  # info describes; run says why it cannot read
            read_as = f"not read by run: {' '.join(str(exc).split())}"
        if read_as is not None:
            details["read as"] = read_as
    if as_json:
        typer.echo(json.dumps(details, indent=2, default=str))
        return
    from rich.console import Console
    from rich.table import Table

    console = Console()
    table = Table(title=str(input), show_header=False)
    refusal = details.get("not_a_label_map")
    lists = {k: v for k, v in details.items() if k in ("structures", "segments", "rois")}
    hidden = {"not_a_label_map", "structures"} if refusal else set()
    lists = {k: v for k, v in lists.items() if k not in hidden}
    for key, value in details.items():
        if key in lists or key in hidden:
            continue
        table.add_row(key, json.dumps(value, default=str) if not isinstance(value, str) else value)
    console.print(table)
    if refusal:
        console.print(f"[bold yellow]not a label map[/]: {refusal}", highlight=False)
    for key, records in lists.items():
        if not records:
            console.print(f"{key}: none")
            continue
        columns = list(dict.fromkeys(k for record in records for k in record))
        listing = Table(*columns, title=key)
        for record in records:
            listing.add_row(*[_cell(record.get(c)) for c in columns])
        console.print(listing)


def _cell(value: Any) -> str:
    """A short human form of one value of ``info``'s structure records."""
    if value is None:
        return ""
    if isinstance(value, dict) and {"min", "max"} <= value.keys():
        lo, hi = value["min"], value["max"]
        return " ".join(f"{a:g}..{b:g}" for a, b in zip(lo, hi, strict=True))
    if isinstance(value, dict) and isinstance(value.get("drawn"), dict):
        return ", ".join(f"{n} along {axis}" for axis, n in value["drawn"].items())
    if isinstance(value, dict) and {"count", "first", "last"} <= value.keys():
        return f"{value['count']} ({value.get('axis', '')} {value['first']}..{value['last']})"
    if isinstance(value, dict) and {"first", "last"} <= value.keys():
        return f"{value['first']:g}..{value['last']:g}"
    return value if isinstance(value, str) else json.dumps(value, default=str)


# ----------------------------------------------------------------------------- run
@app.command()
def run(
    input: Annotated[
        list[Path],
        typer.Argument(
            help="Dense mask, sparse annotation or contours; several sparse inputs of one study "
            "(an axial and a sagittal annotation, a label map and an RTSTRUCT) are combined."
        ),
    ],
    outdir: Annotated[Path, typer.Option("-o", "--outdir", help="Output directory.")] = Path(
        "slicerecon-out"
    ),
    slices: SlicesOpt = None,
    every: EveryOpt = None,
    axis: AxisOpt = "z",
    annotation: AnnotationOpt = "auto",
    planner: PlannerOpt = "auto",
    weights: WeightsOpt = None,
    method: MethodOpt = "sdf",
    interpolation: InterpolationOpt = "pchip",
    projections: ProjectionsOpt = "auto",
    gt: Annotated[
        Path | None, typer.Option("--gt", help="Ground truth (mask or closed mesh).")
    ] = None,
    mesh_format: FormatOpt = "stl",
    smooth: SmoothOpt = False,
    carve: CarveOpt = True,
    cover: CoverOpt = True,
    join_drift: DriftOpt = True,
    label: LabelOpt = None,
    roi: RoiOpt = None,
    union: UnionOpt = False,
    allow_irregular: IrregularOpt = False,
    pixel_spacing: PixelSpacingOpt = None,
    max_memory: MaxMemoryOpt = DEFAULT_MAX_MEMORY_GB,
    quiet: Annotated[
        bool,
        typer.Option("--quiet", "-q", help="No progress, no warnings, no summary; errors only."),
    ] = False,
) -> None:
    """Reconstruct one input; write meshes, label maps, plan.json, metrics.json and preview.png.

    The label map comes as labels.nii.gz and labels.seg.nrrd (3D Slicer); a DICOM input with
    its image series also gets seg.dcm, and an RTSTRUCT input rtstruct.dcm.
    """
    if quiet:
        show_messages(logging.ERROR)
    with ctrl_c_after():
        from ..case import run_case

    config = _reconstruct_config(locals())
    with StageProgress(enabled=not quiet) as progress:
        inputs = input[0] if len(input) == 1 else input
        summary = run_case(inputs, outdir, config, ground_truth=gt, progress=progress)
    if not quiet:
        print_run_summary(summary, outdir)


def _reconstruct_config(options: dict[str, Any]) -> Any:
    """The :class:`~slicerecon.reconstruct.ReconstructConfig` of a command's options.

    The one place the command line turns its shared options (``run`` and
    ``batch`` take the same ones) into the library's config: each option
    fills the field of its name (``--max-memory`` fills ``max_memory_gb``,
    paths become strings); the other options of the command are ignored.
    """
    from dataclasses import fields

    from ..reconstruct import ReconstructConfig

    names = {f.name for f in fields(ReconstructConfig)}
    renamed = {"max_memory": "max_memory_gb"}
    values = {}
    for key, value in options.items():
        name = renamed.get(key, key)
        if name in names:
            values[name] = str(value) if isinstance(value, Path) else value
    return ReconstructConfig(**values)


# --------------------------------------------------------------------------- batch
@app.command()
def batch(
    indir: Annotated[Path, typer.Argument(help="Folder of cases (NIfTI, DICOM, contours).")],
    outdir: Annotated[Path, typer.Option("-o", "--outdir", help="Output directory.")],
    workers: Annotated[
        int | None,
        typer.Option(help="Local worker processes (default: CPUs); 0 runs in this process."),
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Dask scheduler address, e.g. tcp://host:8786.")
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Recompute cases finished by an earlier run.")
    ] = False,
    retries: Annotated[int, typer.Option(help="Re-runs of a case whose worker died.")] = 2,
    no_report: Annotated[
        bool, typer.Option("--no-report", help="Do not write the HTML report.")
    ] = False,
    follow_symlinks: Annotated[
        bool,
        typer.Option(
            "--follow-symlinks",
            help="Read symbolic links that point outside INDIR (default: each is a "
            "failed case, never opened).",
        ),
    ] = False,
    slices: SlicesOpt = None,
    every: EveryOpt = None,
    axis: AxisOpt = "z",
    annotation: AnnotationOpt = "auto",
    planner: PlannerOpt = "auto",
    weights: WeightsOpt = None,
    method: MethodOpt = "sdf",
    interpolation: InterpolationOpt = "pchip",
    projections: ProjectionsOpt = "auto",
    mesh_format: FormatOpt = "stl",
    smooth: SmoothOpt = False,
    carve: CarveOpt = True,
    cover: CoverOpt = True,
    join_drift: DriftOpt = True,
    label: LabelOpt = None,
    roi: RoiOpt = None,
    allow_irregular: IrregularOpt = False,
    pixel_spacing: PixelSpacingOpt = None,
    max_memory: MaxMemoryOpt = DEFAULT_MAX_MEMORY_GB,
) -> None:
    """Reconstruct every case in INDIR on Dask; write OUTDIR/<case>/ and OUTDIR/summary.csv.

    Finished cases are skipped on a re-run (unless --force); a failed case is
    recorded in OUTDIR/<case>/error.json and summary.csv. Symbolic links that
    point outside INDIR are failed cases unless --follow-symlinks. Exit code 0
    when every case is done, 1 when any failed, 2 for a bad invocation, 130
    when interrupted (Ctrl-C; finished cases are kept and a re-run resumes).
    """
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )

    with ctrl_c_after():
        from pipelines.batch import run_batch

    config = _reconstruct_config(locals())
    if not logging.getLogger().handlers:
        logging.getLogger("distributed").setLevel(logging.ERROR)  # keep the bar readable
    console = Console(stderr=True)
    columns = (
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.fields[last]}"),
    )
    # piped: no bar (its live display left a blank line before an error or "interrupted")
    with Progress(
        *columns, console=console, transient=True, disable=not console.is_terminal
    ) as bar:
        task = bar.add_task("cases", total=None, last="finding cases")

        def advance(result: Any, done: int, total: int) -> None:
            colour = {"ok": "green", "failed": "red", "skipped": "dim"}[result.status]
            bar.update(
                task,
                total=total,
                completed=done,
                last=f"[{colour}]{result.status}[/] {result.case}",
            )
            if not console.is_terminal:  # piped: one plain line per case instead of the bar
                console.print(
                    f"progress: case {done}/{total} {result.status}: {result.case}",
                    markup=False,
                    highlight=False,
                    soft_wrap=True,
                )
            if result.status == "ok":  # its warnings, wherever it ran (a Dask worker too)
                for line in result.warnings:
                    console.print(
                        f"warning: {result.case}: {line}",
                        markup=False,
                        highlight=False,
                        soft_wrap=True,
                    )

        outcome = run_batch(
            indir,
            outdir,
            config,
            workers=workers,
            scheduler=scheduler,
            force=force,
            progress=advance,
            retries=retries,
            report=not no_report,
            follow_symlinks=follow_symlinks,
        )
    _print_left_out(console, outcome.skipped_inputs)
    for failed in (c for c in outcome.cases if c.status == "failed"):
        console.print(
            f"[red]failed[/] {failed.case}: {failed.error_type}: {failed.error}",
            markup=True,
            highlight=False,
            soft_wrap=True,
        )
    if outcome.report_error:
        console.print(f"[yellow]report not written[/]: {outcome.report_error}")
    typer.echo(
        f"{len(outcome.cases)} cases: {outcome.n_ok} ok, {outcome.n_failed} failed, "
        f"{outcome.n_skipped} skipped in {outcome.seconds:.1f} s -> {outcome.summary_csv}"
    )
    if not outcome.ok:
        raise typer.Exit(code=1)


MAX_LEFT_OUT_LINES = 20
"""Entries of INDIR that are not cases printed one per line (the rest are counted)."""


def _print_left_out(console: Any, skipped: Any) -> None:
    """One line per entry of INDIR that is not a case, and why (at most
    :data:`MAX_LEFT_OUT_LINES`; all of them are logged with -v)."""
    if not skipped:
        return
    console.print(
        f"{len(skipped)} entr{'y' if len(skipped) == 1 else 'ies'} of INDIR left out (not cases):",
        highlight=False,
    )
    for item in skipped[:MAX_LEFT_OUT_LINES]:
        console.print(
            f"  left out {item.relpath}: {item.reason}",
            markup=False,
            highlight=False,
            soft_wrap=True,
        )
    if len(skipped) > MAX_LEFT_OUT_LINES:
        console.print(
            f"  ... and {len(skipped) - MAX_LEFT_OUT_LINES} more (slicerecon -v batch lists them)",
            highlight=False,
        )


# ------------------------------------------------------------------------ evaluate
@app.command()
def evaluate(
    prediction: Annotated[
        Path, typer.Argument(help="Predicted mesh or mask, or a run's meshes/ directory.")
    ],
    ground_truth: Annotated[Path, typer.Argument(help="Ground-truth mesh or mask.")],
    label: Annotated[
        str | None, typer.Option(help="Structure of the ground truth (number or name).")
    ] = None,
    n_points: Annotated[int, typer.Option(help="Surface samples per mesh.")] = 50_000,
    seed: Annotated[int, typer.Option(help="Sampling seed.")] = 0,
    max_memory: MaxMemoryOpt = DEFAULT_MAX_MEMORY_GB,
) -> None:
    """Print metrics of PREDICTION against GROUND_TRUTH as JSON.

    A mesh is scored as the exact surface; a mask as its voxels (docs/metrics.md), both in
    the ground truth's world frame (RAS or LPS; a mesh in the frame it states). A
    ground-truth label map of several structures, without --label, is scored structure by
    structure against a predicted label map or a run's meshes/ directory.
    """
    from ..io import load_ground_truth, world_frame
    from ..metrics import evaluate as evaluate_metrics

    if label is None:
        from ..evaluation import evaluate_structures

        per_structure = evaluate_structures(
            prediction, ground_truth, n_points=n_points, seed=seed, memory_budget_gb=max_memory
        )
        if per_structure is not None:
            typer.echo(json.dumps(per_structure, indent=2))
            return

    # both in one world frame: the ground truth's, or the prediction's when it is a mesh
    # that states none (an LPS mesh against a RAS labels.nii.gz scored IoU 0.39)
    frame = world_frame(ground_truth) or world_frame(prediction)
    metrics = evaluate_metrics(
        load_ground_truth(prediction, memory_budget_gb=max_memory, frame=frame),
        load_ground_truth(
            ground_truth, label=label, memory_budget_gb=max_memory, frame=frame, truth=True
        ),
        n_points=n_points,
        seed=seed,
        memory_budget_gb=max_memory,
    )
    typer.echo(json.dumps(metrics.to_dict(), indent=2))


# -------------------------------------------------------------- report / evaluate-dataset
@app.command()
def report(
    results_dir: Annotated[Path, typer.Argument(help="Directory of case folders (plan.json).")],
    title: Annotated[str | None, typer.Option("--title", help="Report title.")] = None,
    no_renders: Annotated[
        bool, typer.Option("--no-renders", help="Skip the per-case 3-D renders (faster).")
    ] = False,
) -> None:
    """Write report.html, metrics.csv, summary.json into RESULTS_DIR; print the report path."""
    from ..report import write_report

    typer.echo(str(write_report(results_dir, title=title, renders=not no_renders)))


@app.command("evaluate-dataset")
def evaluate_dataset(
    dataset_dir: Annotated[Path, typer.Argument(help="Directory of NIfTI masks (recursive).")],
    outdir: Annotated[Path, typer.Option("-o", "--outdir", help="Results directory.")],
    method: Annotated[
        str, typer.Option(help="Comma-separated surface methods, e.g. sdf,loft,hybrid.")
    ] = "sdf",
    planner: Annotated[
        str, typer.Option(help="Partition planner (auto, heuristic, lookahead, none, policy).")
    ] = "auto",
    slices: SlicesOpt = None,
    every: EveryOpt = None,
    axis: AxisOpt = "z",
    projections: ProjectionsOpt = "auto",
    mesh_format: FormatOpt = "stl",
    smooth: SmoothOpt = False,
    label: LabelOpt = None,
    n_points: Annotated[int, typer.Option(help="Surface samples per mesh.")] = 50_000,
    seed: Annotated[int, typer.Option(help="Sampling seed.")] = 0,
    title: Annotated[str | None, typer.Option("--title", help="Report title.")] = None,
    no_renders: Annotated[
        bool, typer.Option("--no-renders", help="Skip the per-case 3-D renders.")
    ] = False,
    rerun: Annotated[
        bool, typer.Option("--rerun", help="Recompute cases already done with the same options.")
    ] = False,
    workers: Annotated[
        int | None,
        typer.Option(
            help="Local worker processes; 0 (default) runs the cases one after "
            "the other in this process."
        ),
    ] = 0,
    follow_symlinks: Annotated[
        bool,
        typer.Option(
            "--follow-symlinks",
            help="Read symbolic links that point outside DATASET_DIR (default: each "
            "is a failed case, never opened).",
        ),
    ] = False,
) -> None:
    """Run every mask of DATASET_DIR with each method into OUTDIR/<case>/<method>/; report.

    Runs through the batch runner: a failing case writes error.json and the
    others go on; a re-run skips what is finished (unless --rerun). Prints the
    report path.
    """
    from rich.console import Console

    with ctrl_c_after():
        from pipelines.evaluate import evaluate_dataset as run_dataset

    options = dict(locals())
    options.pop("method")  # one config per method: the runner sets it
    config = _reconstruct_config(options)
    if workers != 0 and not logging.getLogger().handlers:
        logging.getLogger("distributed").setLevel(logging.ERROR)  # keep the status readable

    with Console(stderr=True).status("starting") as status:

        def advance(result: Any, done: int, total: int) -> None:
            status.update(f"[{done}/{total}] {result.status} {result.case}")

        path = run_dataset(
            dataset_dir,
            outdir,
            methods=method.split(","),
            config=config,
            title=title,
            renders=not no_renders,
            resume=not rerun,
            workers=workers,
            follow_symlinks=follow_symlinks,
            progress=advance,
        )
    typer.echo(str(path))
