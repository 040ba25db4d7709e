"""The commands that train the learned planner and make datasets of shapes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from .app import app


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

    from ..errors import OptionError
    from ..policy.train import load_config, training_pool
    from ..policy.train import train as run_training

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
    from ..errors import OptionError

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

    from ..dataset import make_dataset

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
    from ..realshapes import available_real_shapes, real_shape_names
    from ..shapes import FAMILIES

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
