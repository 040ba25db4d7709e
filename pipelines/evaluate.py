"""``slicerecon evaluate-dataset``: every NIfTI mask with several methods, then the report.

A thin use of the runner (:func:`pipelines.batch.run_cases`): the NIfTI masks
of a dataset folder are the cases, each method is one named configuration, so
each case and method lands in ``OUTDIR/<case>/<method>/`` with the batch's
failure records, resume keys and atomic outputs; then the report is written
(:func:`slicerecon.report.write_report`).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from slicerecon.errors import InputError, OptionError
from slicerecon.io import kind_of_name

from .batch import Progress, check_dirs, run_cases
from .discover import Case, discover_cases

if TYPE_CHECKING:
    from slicerecon.reconstruct import ReconstructConfig

__all__ = ["dataset_cases", "evaluate_dataset", "method_configs"]


def _is_mask(case: Case) -> bool:
    """A NIfTI mask, or a link named like one that is not followed (recorded as failed)."""
    if case.kind == "nifti":
        return True
    named = kind_of_name(Path(case.relpath).name)
    return case.kind == "symlink" and named is not None and named[0] == "nifti"


def dataset_cases(
    dataset_dir: str | os.PathLike[str],
    outdir: str | os.PathLike[str],
    *,
    follow_symlinks: bool = False,
) -> list[Case]:
    """The NIfTI masks of a dataset folder, as batch cases.

    Parameters
    ----------
    dataset_dir : path-like
        Folder searched recursively for ``*.nii`` and ``*.nii.gz`` (hidden
        entries and ``outdir`` skipped; other files, e.g. a ``manifest.json``,
        are ignored).
    outdir : path-like
        The results folder (not searched when it lies inside ``dataset_dir``).
    follow_symlinks : bool
        Read links that point outside ``dataset_dir`` (as for ``batch``);
        otherwise each is a case recorded as failed.

    Returns
    -------
    list of Case
        In sorted input order, named as :func:`~pipelines.discover.discover_cases`
        names them (``sub/liver.nii.gz`` → ``sub__liver``).

    Raises
    ------
    InputError
        If the folder does not exist or holds no NIfTI mask.
    OptionError
        If ``outdir`` is ``dataset_dir``.
    """
    root, out = Path(dataset_dir), Path(outdir)
    if not root.is_dir():
        raise InputError(f"dataset directory not found: {root}")
    check_dirs(root, out)
    cases = [
        c
        for c in discover_cases(root, exclude=[out.resolve()], follow_symlinks=follow_symlinks)
        if _is_mask(c)
    ]
    if not cases:
        inside = root.resolve() in out.resolve().parents
        where = " outside the output directory" if inside else ""
        raise InputError(f"{root} holds no NIfTI masks (*.nii, *.nii.gz){where}")
    return cases


def method_configs(
    methods: Sequence[str], config: ReconstructConfig
) -> dict[str, ReconstructConfig]:
    """One configuration per method: ``config`` with its ``method`` replaced.

    Parameters
    ----------
    methods : sequence of str
        Surface methods (values of ``ReconstructConfig.method``); blank entries
        are dropped.
    config : ReconstructConfig
        Every other option.

    Returns
    -------
    dict of str to ReconstructConfig
        By method, in the order given.

    Raises
    ------
    OptionError
        If no method is given, one is repeated, or one is unknown.
    """
    cleaned = [m.strip() for m in methods if m.strip()]
    if not cleaned:
        raise OptionError("give at least one method (e.g. --method loft,sdf)")
    if len(set(cleaned)) != len(cleaned):
        raise OptionError(f"methods are repeated: {', '.join(cleaned)}")
    return {m: dataclasses.replace(config, method=m) for m in cleaned}  # validates each name


def evaluate_dataset(
    dataset_dir: str | os.PathLike[str],
    outdir: str | os.PathLike[str],
    *,
    methods: Sequence[str] = ("hybrid",),
    config: ReconstructConfig | None = None,
    title: str | None = None,
    renders: bool = True,
    resume: bool = True,
    workers: int | None = 0,
    follow_symlinks: bool = False,
    progress: Progress | None = None,
) -> Path:
    """Reconstruct every mask of a dataset with each method, then write the report.

    For each NIfTI mask (:func:`dataset_cases`) and each method, the runner
    (:func:`pipelines.batch.run_cases`) writes ``outdir/<case>/<method>/``; a
    failing case writes ``error.json`` there and the others go on. Then
    ``summary.csv`` and the report of ``outdir`` are written.

    Parameters
    ----------
    dataset_dir : path-like
        Directory of NIfTI masks (searched recursively).
    outdir : path-like
        Results directory.
    methods : sequence of str
        Surface methods (values of ``ReconstructConfig.method``).
    config : ReconstructConfig, optional
        Every other option; its ``method`` is replaced by each of ``methods``.
    title : str, optional
        Report title.
    renders : bool
        Draw per-case renders in the report.
    resume : bool
        Skip a case/method finished by an earlier run with the same input
        bytes and options (its ``done.json`` key); False recomputes it.
    workers : int or None
        0 (the default) runs the cases one after the other in this process;
        N >= 1 on N local Dask worker processes; None: one per CPU.
    follow_symlinks : bool
        Read links that point outside ``dataset_dir``.
    progress : callable, optional
        Called as ``progress(result, n_done, n_total)`` after each case and method.

    Returns
    -------
    Path
        The ``report.html`` file.

    Raises
    ------
    InputError
        If the dataset holds no NIfTI mask.
    OptionError
        If a method is unknown or repeated, or ``outdir`` is ``dataset_dir``.
    """
    from slicerecon.reconstruct import ReconstructConfig
    from slicerecon.report import write_report

    configs = method_configs(methods, config if config is not None else ReconstructConfig())
    cases = dataset_cases(dataset_dir, outdir, follow_symlinks=follow_symlinks)
    run_cases(
        cases, outdir, configs, workers=workers, force=not resume, progress=progress, report=False
    )
    return write_report(Path(outdir), title=title, renders=renders)
