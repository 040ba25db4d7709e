"""Scoring structures: each structure against its own ground truth.

:func:`mean_metrics` is how a case of several structures is summarised (the
mean of each metric; a structure's own for one); :func:`evaluate_structures`
scores the structures of a prediction on disk (a label map, or a run's
``meshes/``) against a label-map ground truth (``slicerecon evaluate``);
:func:`score_case` scores a case just reconstructed (``slicerecon run``).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import InputError
from .io import detect_kind, load_ground_truth
from .io.labelmap import LABEL_MAP_KINDS, read_label_map
from .io.limits import DEFAULT_MEMORY_BUDGET_GB
from .labels import LabelMap, StructureMasks
from .metrics import evaluate
from .plane_detection import refuse_sparse_truth
from .sections import AXIS_NAMES, in_plane_axes

if TYPE_CHECKING:
    from .case import CaseReconstruction
    from .case_input import CaseInput
    from .reconstruct import ReconstructConfig

__all__ = ["evaluate_structures", "mean_metrics", "score_case"]

logger = logging.getLogger(__name__)


def mean_metrics(per_structure: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The mean of each numeric metric over the structures (a structure's own for one).

    Parameters
    ----------
    per_structure : dict of str to dict
        Each structure's metrics (:meth:`slicerecon.metrics.Metrics.to_dict`).

    Returns
    -------
    dict
    """
    if len(per_structure) == 1:
        return dict(next(iter(per_structure.values())))
    keys = [
        k
        for k, v in next(iter(per_structure.values())).items()
        if isinstance(v, int | float) and not isinstance(v, bool)
    ]
    return {k: float(np.mean([m[k] for m in per_structure.values()])) for k in keys}


def evaluate_structures(
    prediction: str | os.PathLike[str],
    ground_truth: str | os.PathLike[str],
    *,
    n_points: int = 50_000,
    seed: int = 0,
    memory_budget_gb: float | None = None,
) -> dict[str, Any] | None:
    """Score every structure of a label-map ground truth against its own prediction.

    Parameters
    ----------
    prediction : path-like
        A label map with the ground truth's label values (NIfTI, NRRD, VTI,
        DICOM; e.g. a run's ``labels.nii.gz``), or a run's output directory
        holding ``meshes/``, or that ``meshes/`` directory itself
        (``<value>_<name>.<fmt>`` files: each mesh is scored as the exact
        surface of structure ``<value>``).
    ground_truth : path-like
        A dense label map.
    n_points, seed
        As for :func:`slicerecon.metrics.evaluate`. Each prediction is scored in
        the ground truth's world frame (RAS or LPS; a mesh by the frame it
        states, :func:`slicerecon.io.world_frame`).
    memory_budget_gb : float, optional
        As for :func:`slicerecon.io.load_input`.

    Returns
    -------
    dict or None
        None when the ground truth holds fewer than two structures (score it
        as one shape). Otherwise ``{"structures": {"<value>_<name>": metrics},
        "mean": {...}, "missing": [...]}`` as in a run's ``metrics.json``:
        ``missing`` lists the ground-truth structures the prediction does not
        hold (left out of the mean).

    Raises
    ------
    InputError
        A prediction that is a single mesh (it cannot say which structure it
        is: give ``--label``), or a directory without meshes.
    """

    budget = DEFAULT_MEMORY_BUDGET_GB if memory_budget_gb is None else memory_budget_gb
    if detect_kind(ground_truth).kind not in LABEL_MAP_KINDS:
        return None
    truth = read_label_map(ground_truth, memory_budget_gb=budget)
    if truth is None or len(truth.structures) < 2:
        return None
    refuse_sparse_truth(truth.labels, truth.affine, str(ground_truth))
    pred_path = Path(prediction)
    meshes: dict[int, Path] = {}
    pred_map: LabelMap | None = None
    if pred_path.is_dir():
        folder = pred_path / "meshes" if (pred_path / "meshes").is_dir() else pred_path
        for file in sorted(folder.iterdir()):
            value = _mesh_value(file)
            if value is not None and file.suffix.lower() in (".stl", ".ply", ".obj", ".off"):
                meshes[value] = file
        if not meshes:
            raise InputError(
                f"{pred_path} holds no <value>_<name> meshes (a run's meshes/ directory) to "
                "score each structure of the ground truth"
            )
    elif detect_kind(pred_path).kind == "mesh":
        raise InputError(
            f"the ground truth {ground_truth} holds {len(truth.structures)} structures and "
            f"{pred_path.name} is one mesh: give --label to score it against one, or pass a "
            "label map or a meshes/ directory"
        )
    else:
        read = read_label_map(pred_path, memory_budget_gb=budget)
        pred_map = None if read is None else read.in_frame(truth.coordinates)  # RAS or LPS
    scored: dict[str, dict[str, Any]] = {}
    missing: list[str] = []
    for structure in truth.structures:
        target = truth.mask(structure.value)
        pred: Any = None
        if pred_map is not None:
            if any(s.value == structure.value for s in pred_map.structures):
                pred = pred_map.mask(structure.value)
        elif structure.value in meshes:
            pred = load_ground_truth(meshes[structure.value], frame=truth.coordinates)
        if pred is None:
            missing.append(structure.label)
            continue
        scored[structure.label] = evaluate(
            pred, target, n_points=n_points, seed=seed, memory_budget_gb=budget
        ).to_dict()
    if not scored:
        raise InputError(
            f"{pred_path} holds none of the {len(truth.structures)} structures of {ground_truth}"
        )
    return {"structures": scored, "mean": mean_metrics(scored), "missing": missing}


def _mesh_value(path: Path) -> int | None:
    """The label value a ``meshes/`` file is named for (``<value>_<name>.<fmt>``)."""
    head = path.name.split(".")[0].split("_")[0]
    return int(head) if head.isdigit() else None


def score_case(
    case: CaseInput, result: CaseReconstruction, config: ReconstructConfig
) -> dict[str, Any] | None:
    """Score every reconstructed structure of a case against its own ground truth: a
    separate one (``--gt``, in the input's world frame) first, else the dense input's own
    labels; a sparse input without ``--gt`` has none.

    Returns
    -------
    dict or None
        None without a ground truth. Otherwise ``{"structures": {label:
        metrics}, "mean": {...}, "missing": [label, ...]}``
        (:func:`slicerecon.metrics.evaluate`): ``missing`` lists the ground
        truth's structures that were not scored (not reconstructed), left out of
        the mean. Each structure's metrics are also kept on its
        :class:`~slicerecon.case.StructureResult`.
    """
    truths: Any = case.truth if case.truth is not None else case.labels  # --gt first
    truths = truths if isinstance(truths, LabelMap | StructureMasks) else None
    scored: dict[str, dict[str, Any]] = {}
    every_plane: list[tuple[str, int, int]] = []  # self-scored, with nothing held out
    for item in result.reconstructed:
        truth: Any = case.truth
        if truths is not None:
            if not any(s.value == item.structure.value for s in truths.structures):
                logger.warning(
                    "the ground truth holds no structure %s: not scored", item.structure.label
                )
                continue
            truth = truths.mask(item.structure.value)
        if truth is None or item.mesh is None:
            continue
        item.metrics = evaluate(
            item.mesh,
            truth,
            n_points=config.n_points,
            seed=config.seed,
            pred_occupancy=item.occupancy,
            memory_budget_gb=config.max_memory_gb,
        ).to_dict()
        scored[item.structure.label] = item.metrics
        spanned = _planes_if_all_kept(item.sections, truth) if case.truth is None else 0
        if spanned:
            every_plane.append((item.structure.label, spanned, item.sections.axis))
    if not scored:
        return None
    if every_plane:
        _say_nothing_was_held_out(every_plane)
    # the ground truth's structures left unscored (not reconstructed: no planes between
    # the kept ones) are listed, as evaluate lists them, and left out of the mean
    missing = (
        [] if truths is None else [s.label for s in truths.structures if s.label not in scored]
    )
    return {"structures": scored, "mean": mean_metrics(scored), "missing": missing}


def _planes_if_all_kept(sections: Any, truth: Any) -> int:
    """The planes a structure spans along its sections' axis when its sections kept every
    one of them (more than one), else 0."""
    if sections is None:
        return 0
    voxels = np.asarray(getattr(truth, "mask", truth))  # a Volume, or its array
    spanned = int(np.count_nonzero(voxels.any(axis=in_plane_axes(sections.axis))))
    return spanned if spanned > 1 and len(sections.indices) >= spanned else 0


def _say_nothing_was_held_out(every_plane: list[tuple[str, int, int]]) -> None:
    """Warn once when a dense input scored against itself kept every plane of some
    structure: nothing lay between the planes, so its scores only check that the mesh
    reproduces the mask (a 48-voxel torus of ``dataset make`` kept its 10 planes under
    the default 16 and printed volume IoU 1 without a word)."""
    label, spanned, axis = every_plane[0]
    more = f" (and {len(every_plane) - 1} more structure(s))" if len(every_plane) > 1 else ""
    logger.warning(
        "structure %s: every one of the %d planes it spans along %s was kept%s: nothing "
        "lay between them to reconstruct, so its scores only check that the mesh "
        "reproduces the mask; keep fewer with --slices or --every",
        label,
        spanned,
        AXIS_NAMES[axis],
        more,
    )
