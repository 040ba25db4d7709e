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
from .console import StageProgress, ctrl_c_after, keep_freed_memory, print_run_summary
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
DEFAULT_MAX_MEMORY_GB = 8.0
"""Default of ``--max-memory``; equal to ``slicerecon.io.limits.DEFAULT_MEMORY_BUDGET_GB``
(a test checks it), written here so that ``--help`` imports nothing heavy."""


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
    if verbose or debug:
        from rich.logging import RichHandler

        logging.basicConfig(
            level=logging.DEBUG if debug else logging.INFO,
            format="%(message)s",
            handlers=[RichHandler(show_path=False)],
        )


# ---------------------------------------------------------------------------- info
MaxMemoryOpt = Annotated[
    float,
    typer.Option(
        "--max-memory",
        help="Memory budget per case, GiB: larger inputs are refused before reading.",
    ),
]


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
    from .io.describe import describe_input

    details = describe_input(
        input,
        label=label if label is not None else roi,
        allow_irregular=allow_irregular,
        memory_budget_gb=max_memory,
    )
    if as_json:
        typer.echo(json.dumps(details, indent=2, default=str))
        return
    from rich.console import Console
    from rich.table import Table

    console = Console()
    table = Table(title=str(input), show_header=False)
    lists = {k: v for k, v in details.items() if k in ("structures", "segments", "rois")}
    for key, value in details.items():
        if key in lists:
            continue
        table.add_row(key, json.dumps(value, default=str) if not isinstance(value, str) else value)
    console.print(table)
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
    if isinstance(value, dict) and {"count", "first", "last"} <= value.keys():
        return f"{value['count']} ({value.get('axis', '')} {value['first']}..{value['last']})"
    if isinstance(value, dict) and {"first", "last"} <= value.keys():
        return f"{value['first']:g}..{value['last']:g}"
    return value if isinstance(value, str) else json.dumps(value, default=str)


_METHOD_HELP = (
    "Surface method: sdf (default: signed-distance interpolation across planes), loft "
    "(the paper's lofting) or hybrid (loft where contours correspond simply, sdf "
    "elsewhere), per part of the plan; or a whole-shape baseline "
    "that skips the planner and the carve: poisson, sdf-hull or itk-mci "
    '(needs pip install "slicerecon\\[itk]"). See docs/baselines.md.'
)

# Options shared by run, batch and evaluate-dataset (one definition, one help text).
SlicesOpt = Annotated[
    int | None, typer.Option("--slices", help="Keep N evenly spaced planes (default 16).")
]
EveryOpt = Annotated[int | None, typer.Option("--every", help="Keep every K-th plane.")]
AxisOpt = Annotated[str, typer.Option(help="Plane normal axis: x, y or z.")]
PlannerOpt = Annotated[
    str,
    typer.Option(
        help="heuristic, lookahead (the heuristic checked on held-out planes), none or policy "
        "(learned planner)."
    ),
]
MethodOpt = Annotated[str, typer.Option(help=_METHOD_HELP)]
InterpolationOpt = Annotated[
    str,
    typer.Option(help="Across planes: pchip (default: monotone cubic) or linear (classic)."),
]
ProjectionsOpt = Annotated[
    str,
    typer.Option(
        help="gt, sections, auto (gt for dense inputs), or FILE[,FILE...]: 1-3 NIfTI silhouettes."
    ),
]
FormatOpt = Annotated[str, typer.Option("--format", help="stl, ply or obj.")]
SmoothOpt = Annotated[bool, typer.Option("--smooth", help="Taubin-smooth the mesh.")]
CarveOpt = Annotated[
    bool, typer.Option("--carve/--no-carve", help="Cut the surface to the projections' hull.")
]
CoverOpt = Annotated[
    bool,
    typer.Option(
        "--cover/--no-cover",
        help="With --carve (sdf): also fill the silhouettes whose rays lie in the section planes.",
    ),
]
DriftOpt = Annotated[
    bool,
    typer.Option(
        "--join-drift/--no-join-drift",
        help="(sdf) Join regions that overlap nothing on the next plane along their shift.",
    ),
]
LabelOpt = Annotated[
    str | None,
    typer.Option(
        help="Structures to reconstruct (default: all): label values, SEG segments or "
        "an RTSTRUCT ROI, by number or name, comma-separated."
    ),
]
UnionOpt = Annotated[
    bool, typer.Option("--union", help="Every structure together as one (every non-zero voxel).")
]
RoiOpt = Annotated[str | None, typer.Option(help="Another name for --label (RTSTRUCT ROIs).")]
IrregularOpt = Annotated[
    bool, typer.Option("--allow-irregular", help="Accept uneven DICOM slice spacing.")
]
WeightsOpt = Annotated[
    Path | None, typer.Option(help="Actor weights for --planner policy (default: shipped).")
]


# ----------------------------------------------------------------------------- run
@app.command()
def run(
    input: Annotated[Path, typer.Argument(help="Dense mask, sparse mask or contour input.")],
    outdir: Annotated[Path, typer.Option("-o", "--outdir", help="Output directory.")] = Path(
        "slicerecon-out"
    ),
    slices: SlicesOpt = None,
    every: EveryOpt = None,
    axis: AxisOpt = "z",
    planner: PlannerOpt = "heuristic",
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
    max_memory: MaxMemoryOpt = DEFAULT_MAX_MEMORY_GB,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="No progress and no summary; errors only.")
    ] = False,
) -> None:
    """Reconstruct one input; write meshes, label maps, plan.json, metrics.json and preview.png.

    The label map comes as labels.nii.gz and labels.seg.nrrd (3D Slicer); a DICOM input with
    its image series also gets seg.dcm, and an RTSTRUCT input rtstruct.dcm.
    """
    with ctrl_c_after():
        from .case import run_case

    config = _reconstruct_config(locals())
    with StageProgress(enabled=not quiet) as progress:
        summary = run_case(input, outdir, config, ground_truth=gt, progress=progress)
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

    from .reconstruct import ReconstructConfig

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
    planner: PlannerOpt = "heuristic",
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
    with Progress(*columns, console=console, transient=True) as bar:
        task = bar.add_task("cases", total=None, last="finding cases")

        def advance(result: Any, done: int, total: int) -> None:
            colour = {"ok": "green", "failed": "red", "skipped": "dim"}[result.status]
            bar.update(
                task,
                total=total,
                completed=done,
                last=f"[{colour}]{result.status}[/] {result.case}",
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

    A mesh is scored as the exact surface; a mask as its voxels (docs/metrics.md). A
    ground-truth label map of several structures, without --label, is scored structure by
    structure against a predicted label map or a run's meshes/ directory.
    """
    from .io import load_ground_truth
    from .metrics import evaluate as evaluate_metrics

    if label is None:
        from .evaluation import evaluate_structures

        per_structure = evaluate_structures(
            prediction, ground_truth, n_points=n_points, seed=seed, memory_budget_gb=max_memory
        )
        if per_structure is not None:
            typer.echo(json.dumps(per_structure, indent=2))
            return

    metrics = evaluate_metrics(
        load_ground_truth(prediction, memory_budget_gb=max_memory),
        load_ground_truth(ground_truth, label=label, memory_budget_gb=max_memory),
        n_points=n_points,
        seed=seed,
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
    from .report import write_report

    typer.echo(str(write_report(results_dir, title=title, renders=not no_renders)))


@app.command("evaluate-dataset")
def evaluate_dataset(
    dataset_dir: Annotated[Path, typer.Argument(help="Directory of NIfTI masks (recursive).")],
    outdir: Annotated[Path, typer.Option("-o", "--outdir", help="Results directory.")],
    method: Annotated[
        str, typer.Option(help="Comma-separated surface methods, e.g. sdf,loft,hybrid.")
    ] = "sdf",
    planner: Annotated[str, typer.Option(help="Partition planner.")] = "heuristic",
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


# --------------------------------------------------------------------------- train
@app.command()
def train(
    config: Annotated[
        str,
        typer.Option(
            "--config",
            help=(
                "TOML file (e.g. benchmarks/configs/il_rl_gain.toml), or a shipped config: "
                "ddpg, il, il_rl, ddpg_gain."
            ),
        ),
    ] = "il_rl",
    device: Annotated[str, typer.Option(help="cpu or cuda.")] = "cpu",
    out: Annotated[Path | None, typer.Option("--out", help="Output directory.")] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Continue from OUT/checkpoint.pt.")
    ] = False,
    steps: Annotated[
        int | None, typer.Option("--steps", help="Total updates (overrides the config).")
    ] = None,
    seed: Annotated[int | None, typer.Option("--seed", help="Seed (overrides the config).")] = None,
    threads: Annotated[
        int | None, typer.Option("--threads", help="torch CPU threads (default: torch's).")
    ] = None,
    pool: Annotated[
        Path | None,
        typer.Option(
            "--pool",
            help="Read the training shapes from this file (made by --write-pool) instead of "
            "building them: for machines without the real shapes' packages.",
        ),
    ] = None,
    write_pool: Annotated[
        Path | None,
        typer.Option(
            "--write-pool", help="Build the config's training shapes, write them here and exit."
        ),
    ] = None,
) -> None:
    """Train the learned cut planner (DDPG / imitation / DDPG from demonstrations)."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from .errors import OptionError
    from .policy.train import load_config, training_pool
    from .policy.train import train as run_training

    if device not in ("cpu", "cuda"):
        raise OptionError(f"--device must be cpu or cuda (got {device!r})")
    if threads is not None:
        if threads < 1:
            raise OptionError(f"--threads must be >= 1 (got {threads})")
        import torch

        torch.set_num_threads(threads)
    cfg = load_config(config, total_updates=steps, seed=seed)
    if write_pool is not None:
        if pool is not None:
            raise OptionError("give --pool or --write-pool, not both")
        built = training_pool(cfg)
        built.save(write_pool)
        typer.echo(json.dumps({"pool": str(write_pool), "grids": len(built), "grid": built.grid}))
        return
    shapes = None
    if pool is not None:
        shapes = training_pool(cfg, pool)  # checked before anything is written
    outdir = out if out is not None else Path("runs") / cfg.name
    columns = (
        TextColumn(f"[bold]{cfg.name}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=Console(stderr=True)) as bar:
        task = bar.add_task("train", total=cfg.total_updates, info="")

        def progress(done: int, total: int, metrics: dict[str, float]) -> None:
            info = " ".join(
                f"{k}={v:.3g}"
                for k, v in metrics.items()
                if k in ("critic_loss", "bc_loss", "eval_iou") and v == v
            )
            bar.update(task, completed=done, total=total, info=info)

        result = run_training(
            cfg, out=outdir, device=device, resume=resume, progress=progress, pool=shapes
        )
    typer.echo(
        json.dumps(
            {
                "out": str(result.out),
                "actor": str(result.actor_path),
                "log": str(result.log_path),
                "updates": result.n_updates,
                "eval_iou": round(result.eval_iou, 4),
                "heuristic_eval_iou": round(result.heuristic_eval_iou, 4),
            },
            indent=2,
        )
    )


# ------------------------------------------------------------------------- dataset
dataset_app = typer.Typer(
    help="Make datasets of procedural and real shape masks; list the shapes.",
    no_args_is_help=True,
)
app.add_typer(dataset_app, name="dataset")


def _spacing_option(text: str) -> float | tuple[float, ...]:
    """Parse ``"1.5"`` or ``"0.8,0.8,2"`` (mm)."""
    from .errors import OptionError

    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise OptionError(f"--spacing must be one or three numbers of mm (got {text!r})") from None
    if len(values) not in (1, 3):
        raise OptionError(f"--spacing must be one or three numbers of mm (got {text!r})")
    return values[0] if len(values) == 1 else values


@dataset_app.command("make")
def dataset_make(
    outdir: Annotated[Path, typer.Argument(help="Output directory (new, empty or a dataset).")],
    shapes: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated shapes, families or real shapes (default: all procedural shapes)."
        ),
    ] = None,
    per_shape: Annotated[int, typer.Option(help="Seeded variants per procedural shape.")] = 1,
    seed: Annotated[int, typer.Option(help="Dataset seed.")] = 0,
    size: Annotated[int | None, typer.Option(help="Largest extent of each shape, voxels.")] = None,
    spacing: Annotated[str, typer.Option(help="Voxel size in mm: s or sx,sy,sz.")] = "1",
    margin: Annotated[int, typer.Option(help="Background voxels around each shape.")] = 3,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Write into a non-empty, non-dataset directory.")
    ] = False,
) -> None:
    """Write one NIfTI mask per case and a manifest.json into OUTDIR."""
    from rich.progress import Progress

    from .dataset import make_dataset

    with Progress(transient=True) as bar:
        task = bar.add_task("shapes", total=None)
        manifest = make_dataset(
            outdir,
            shapes=shapes,
            per_shape=per_shape,
            seed=seed,
            size=size,
            spacing=_spacing_option(spacing),
            margin=margin,
            overwrite=overwrite,
            progress=lambda done, total, case: bar.update(
                task, completed=done, total=total, description=case
            ),
        )
    cases = json.loads(manifest.read_text(encoding="utf-8"))["cases"]
    typer.echo(f"wrote {len(cases)} cases to {outdir} (manifest: {manifest})")


@dataset_app.command("list")
def dataset_list(
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """List the shape families, their shapes, and the real shapes installed here."""
    from .realshapes import available_real_shapes, real_shape_names
    from .shapes import FAMILIES

    available = set(available_real_shapes())
    real = {name: name in available for name in real_shape_names()}
    if as_json:
        typer.echo(json.dumps({"families": FAMILIES, "real": real}, indent=2))
        return
    for family, names in FAMILIES.items():
        typer.echo(f"{family}: {', '.join(names)}")
    installed = [n for n, ok in real.items() if ok]
    missing = [n for n, ok in real.items() if not ok]
    typer.echo(f"real (installed): {', '.join(installed) or 'none'}")
    if missing:
        typer.echo(f"real (missing packages): {', '.join(missing)}")


def _usage_line(exc: Exception) -> str:
    """One line for a usage error raised by typer's click: the message and where help is."""
    message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
    message = " ".join(str(message).split()) or "a command is required"
    ctx = getattr(exc, "ctx", None)
    if ctx is not None:
        return f"error: {message} (see '{ctx.command_path} --help')"
    return f"error: {message}"


def _click_exceptions() -> tuple[type[BaseException], ...]:
    """The usage-error base classes of the click that typer runs on.

    Recent typer releases bundle their own copy of click, whose exceptions do
    not derive from the installed ``click``'s; older ones use ``click`` itself.
    Both are caught, so every usage error reaches :func:`main`'s one-line rule.
    """
    import typer.exceptions

    bases: list[type[BaseException]] = [typer.exceptions.TyperException]
    try:
        import click
    except ImportError:  # pragma: no cover - typer always brings a click
        pass
    else:
        bases.append(click.ClickException)
    return tuple(bases)


def _exit_code(exc: BaseException) -> int | None:
    """The exit code of a click/typer ``Exit`` (``--help``, ``--version``), else None."""
    code = getattr(exc, "exit_code", None)
    name = type(exc).__name__
    return int(code) if name == "Exit" and code is not None else None


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``slicerecon`` console script.

    Exit codes: 0 success; 2 bad input or usage error (one ``error:`` line on
    stderr); 1 a batch finished with failed cases; 130 interrupted (Ctrl-C).
    Called without ``argv`` (the console script itself), it first tunes the
    process's allocator (:func:`slicerecon.console.keep_freed_memory`).
    """
    if argv is None:
        keep_freed_memory()
    usage_errors = _click_exceptions()
    args = sys.argv[1:] if argv is None else list(argv)
    debug = (
        "--debug"
        in args[: next((i for i, a in enumerate(args) if not a.startswith("-")), len(args))]
    )
    try:
        result = app(args=argv, prog_name="slicerecon", standalone_mode=False)
    except SlicereconError as exc:
        if debug:
            raise
        typer.echo(f"error: {' '.join(str(exc).split())}", err=True)
        return EXIT_INPUT
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        return 130
    except (*usage_errors, RuntimeError) as exc:
        code = _exit_code(exc)
        if code is not None:
            return code
        if type(exc).__name__ == "Abort":
            typer.echo("interrupted", err=True)
            return 130
        if not isinstance(exc, usage_errors):
            raise
        if debug:
            raise
        typer.echo(_usage_line(exc), err=True)
        return EXIT_INPUT
    if result == 130:  # typer turns a KeyboardInterrupt inside a command into Exit(130)
        typer.echo("interrupted", err=True)
        return 130
    return int(result) if isinstance(result, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
