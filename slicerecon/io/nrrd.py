"""NRRD label maps and 3D Slicer segmentations (``.nrrd``, ``.seg.nrrd``).

Header fields are parsed by pynrrd (``import nrrd``) from lines read here in
UTF-8, as 3D Slicer writes them (pynrrd alone would drop every non-ASCII
character of a segment name); :mod:`slicerecon.io.nrrd_writer` writes them.
Two kinds of file are read:

* **plain NRRD label maps**: a 3-D image of integer label values (as ITK,
  ITK-SNAP or Slicer's "labelmap volume" export write them); every non-zero
  value is a structure, without a name;
* **Slicer segmentations** (``.seg.nrrd``, any NRRD holding ``Segment<N>_*``
  key/value pairs): each segment has a name, a colour, a label value and a
  layer. A file whose segments overlap has a fourth, ``list`` axis: one 3-D
  layer per group of non-overlapping segments. :func:`read_nrrd_masks` keeps
  each segment whole (what a run reconstructs from when segments overlap);
  :func:`read_nrrd_label_map` flattens the layers into one label map.

Geometry: voxel index ``(i, j, k)`` along the three spatial axes, in the
file's axis order, lies at ``space origin + Σ index · space direction``. The
``space`` field gives the world frame: ``right-anterior-superior`` (RAS) and
``left-posterior-superior`` (LPS, what Slicer writes) are kept as they are,
``left-anterior-superior`` is turned into RAS; spaces without an anatomical
meaning (``scanner-xyz``, ``3D-right-handed``, ...) are used as they are and
called RAS. A file without space fields gets its ``spacings`` (default 1 mm)
along the array axes and its ``axis mins`` (default 0) as origin.

Every check that needs only the header (dimensions, data type, geometry, the
memory budget) runs before a voxel is read. Compressed voxel data (gzip,
bzip2) is decompressed here with a bound: never more bytes than the header
declares (its data and its ``byte skip``, which count against the memory
budget; with ``byte skip: -1``, at most twice the data), so a small file
cannot expand past the memory budget. ``line skip`` is counted in one pass
over the file, and a skip past its end is refused at once.

Segments are never dropped silently: a segment with label value 0 or without a
voxel, and voxels outside a segment's ``Extent`` (left out, as Slicer leaves
them out), are reported in one warning line each; two segments claiming one
value of one layer, or a segment whose value is absent from its layer while
another value there belongs to no segment, are refused (its ``LabelValue`` or
``Layer`` is wrong).
"""

from __future__ import annotations

import bz2
import io
import logging
import math
import os
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import (
    EmptyMaskError,
    FormatError,
    InputError,
    LabelError,
)
from ..labels import LabelMap, Structure, StructureMasks, labels_dtype
from ..sections import Volume
from ..selection import choose_structure, parse_selector
from .limits import (
    DEFAULT_MEMORY_BUDGET_GB,
    check_bytes,
    check_grid,
    check_label_range,
    reading,
)
from .nrrd_header import (
    COMPRESSED,
    NrrdInfo,
    NrrdSegment,
    header_info,
    nrrd_info,
    open_nrrd,
    pynrrd_module,
    read_header,
)

__all__ = [
    "NrrdInfo",
    "NrrdSegment",
    "label_values",
    "nrrd_info",
    "pynrrd_module",
    "read_nrrd",
    "read_nrrd_label_map",
    "read_nrrd_masks",
]

logger = logging.getLogger(__name__)


_CHUNK = 1 << 22
"""Bytes read, or produced by the decompressor, at once."""


def _skip_lines(p: Path, fh: io.BufferedIOBase, count: int) -> None:
    """Move ``fh`` past ``count`` more lines (``line skip``), scanning the file once."""
    if count < 0:
        raise FormatError(f"{p}: 'line skip' must be 0 or more (got {count})")
    left = count
    while left:
        start = fh.tell()
        chunk = fh.read(_CHUNK)
        if not chunk:
            raise FormatError(
                f"{p}: 'line skip: {count}' asks to skip more lines than the file holds after "
                "its header; the header is corrupt"
            )
        end = -1
        for _ in range(min(left, chunk.count(b"\n"))):
            end = chunk.index(b"\n", end + 1)
            left -= 1
        if not left:
            fh.seek(start + end + 1)


def _inflate(p: Path, fh: io.BufferedIOBase, method: str, skip: int, need: int) -> bytearray:
    """The ``need`` bytes that follow the first ``skip`` bytes of a gzip / bzip2 stream.

    Memory is bounded by ``need`` and what the header declares: skipped bytes are
    discarded as they come, and a stream holding more than ``skip + need`` bytes
    is refused without being expanded. With ``skip == -1`` (``byte skip: -1``:
    the data are the last ``need`` bytes) the stream may hold at most ``2 *
    need`` bytes.
    """
    decoder: Any = (
        zlib.decompressobj(zlib.MAX_WBITS | 32) if method == "gzip" else bz2.BZ2Decompressor()
    )
    limit = 2 * need if skip < 0 else skip + need
    out = bytearray()
    produced = 0

    def take(piece: bytes) -> None:
        nonlocal produced
        start = produced
        produced += len(piece)
        if produced > limit:
            raise FormatError(
                f"{p} holds more voxel data than its header declares ({need} bytes"
                f"{f' after {skip} skipped' if skip > 0 else ''}"
                f"{', at most as much again before them with byte skip -1' if skip < 0 else ''}"
                "); the file is corrupt"
            )
        if skip < 0:
            out.extend(piece)
            if len(out) > 2 * need:
                del out[: len(out) - need]
        elif produced > skip:
            out.extend(piece[max(skip - start, 0) :])

    def pending() -> bool:  # output held back by max_length, to be drained
        if method == "gzip":
            return bool(decoder.unconsumed_tail)
        return not decoder.needs_input

    while not decoder.eof:
        chunk = fh.read(_CHUNK)
        if not chunk:
            break
        take(decoder.decompress(chunk, _CHUNK))
        while not decoder.eof and pending():
            take(decoder.decompress(decoder.unconsumed_tail if method == "gzip" else b"", _CHUNK))
    if skip < 0:
        del out[: max(len(out) - need, 0)]
    return out


def _raw(fh: io.BufferedIOBase, skip: int, need: int) -> bytearray:
    """The ``need`` bytes after ``skip`` more bytes (-1: the last ``need`` bytes of the file)."""
    size = os.fstat(fh.fileno()).st_size
    if skip < 0:
        if size < need:
            return bytearray()
        fh.seek(size - need)
    elif skip > size - fh.tell():  # a skip past the end (or too large to seek to)
        return bytearray()
    else:
        fh.seek(skip, os.SEEK_CUR)
    out = bytearray(need)
    got = fh.readinto(out)
    return out[:got] if got < need else out


def _voxels(
    p: Path,
    header: Mapping[str, Any],
    info: NrrdInfo,
    fh: io.BufferedIOBase,
    memory_budget_gb: float,
) -> NDArray[Any]:
    """Every voxel value, shape ``(layers, I, J, K)``.

    ``line skip`` and ``byte skip`` are bounded before anything is read: lines
    are counted in one pass over the file, a raw file's skip cannot pass its
    end, and the decompressed bytes a compressed file's skip asks for count
    against ``memory_budget_gb`` as its data do.
    """
    sizes = [int(s) for s in header["sizes"]]
    count = math.prod(sizes)
    need = count * info.dtype.itemsize
    encoding = str(header["encoding"]).lower()
    line_skip = int(header.get("line skip", header.get("lineskip", 0)))
    byte_skip = int(header.get("byte skip", header.get("byteskip", 0)))
    if byte_skip < -1:
        raise FormatError(f"{p}: 'byte skip' must be -1 or more (got {byte_skip})")
    _skip_lines(p, fh, line_skip)
    if encoding not in COMPRESSED and encoding != "raw":  # text: pynrrd parses it
        plain = {k: v for k, v in header.items() if k not in ("line skip", "lineskip")}
        flat = pynrrd_module().read_data(plain, fh, str(p), index_order="C").ravel()
    else:
        if encoding in COMPRESSED:
            check_bytes(
                need + max(byte_skip, 0),
                what=f"{p} (byte skip {byte_skip} and {need} bytes of voxels, decompressed)",
                memory_budget_gb=memory_budget_gb,
            )
            raw = _inflate(p, fh, COMPRESSED[encoding], byte_skip, need)
        else:
            raw = _raw(fh, byte_skip, need)
        if len(raw) < need:
            held = len(raw) // info.dtype.itemsize
            raise FormatError(
                f"{p} is truncated: its voxel data holds {held} of the {count} values "
                "the header declares"
            )
        flat = np.frombuffer(raw, dtype=info.dtype, count=count)
    data = flat.reshape(sizes[::-1]).T  # NRRD's first axis varies fastest
    if info.layer_axis is None:
        return data[np.newaxis]
    return np.moveaxis(data, info.layer_axis, 0)


def _integer_values(p: Path, data: NDArray[Any]) -> NDArray[np.integer]:
    """The voxels as integers: float data must hold whole, finite numbers within 32 bits."""
    if data.dtype.kind in "iu":
        check_label_range(data, what=str(p))
        return data.astype(data.dtype.newbyteorder("="), copy=False)
    if not np.all(np.isfinite(data)):
        raise LabelError(f"{p} is not a label map: it holds NaN or infinite values")
    fractional = data != np.round(data)
    if fractional.any():
        raise LabelError(
            f"{p} is not a label map: it holds non-integer values (e.g. "
            f"{float(data[fractional].flat[0]):g}); pass an integer label map"
        )
    check_label_range(data, what=str(p))
    lo, hi = (int(data.min()), int(data.max())) if data.size else (0, 0)
    return data.astype(np.result_type(np.min_scalar_type(lo), np.min_scalar_type(hi)))


def label_values(layer: NDArray[np.integer]) -> set[int]:
    """The values a label layer holds (0 when any voxel is background)."""
    foreground = layer[layer != 0]  # label maps are mostly background: count only the rest
    found = {0} if foreground.size < layer.size else set()
    if layer.dtype.kind == "u" and layer.dtype.itemsize <= 2:
        return found | {int(v) for v in np.flatnonzero(np.bincount(foreground))}
    return found | {int(v) for v in np.unique(foreground)}


def _segment_masks(
    p: Path, info: NrrdInfo, data: NDArray[np.integer]
) -> tuple[list[NrrdSegment], dict[int, NDArray[np.bool_]], dict[int, int]]:
    """Each segment's own voxels: the segments kept, their masks by segment index, and the
    value each is given (its ``LabelValue``, or 1, 2, ... in file order when segments of
    different layers share values).

    Nothing is dropped silently: a segment with label value 0, one without a
    voxel, and voxels a segment's ``Extent`` leaves out are each reported in one
    warning line; a header whose segments cannot match the voxels (two segments
    claiming one value of one layer, a segment whose value is absent from its
    layer while another value there belongs to no segment) is refused.
    """
    kept: list[NrrdSegment] = []
    for segment in info.segments:
        if segment.label_value == 0:
            logger.warning(
                "%s: segment %d (%s) has label value 0, the background; it is skipped",
                p,
                segment.index,
                segment.name,
            )
            continue
        kept.append(segment)
    owner: dict[tuple[int, int], NrrdSegment] = {}
    for segment in kept:
        key = (segment.layer, segment.label_value)
        if key in owner:
            first = owner[key]
            raise FormatError(
                f"{p}: segments {first.index} ({first.name}) and {segment.index} "
                f"({segment.name}) both claim label value {segment.label_value} of layer "
                f"{segment.layer}{_defaulted(info, segment)}; one segment's LabelValue or Layer "
                "is wrong: fix the header"
            )
        owner[key] = segment
    unclaimed = {}
    for layer in range(info.layers):
        claimed = {s.label_value for s in info.segments if s.layer == layer}
        stray = sorted(label_values(data[layer]) - claimed - {0})
        if stray:
            unclaimed[layer] = stray
    masks: dict[int, NDArray[np.bool_]] = {}
    for segment in kept:
        mask = data[segment.layer] == segment.label_value
        total = int(np.count_nonzero(mask))
        if total == 0:
            declared_empty = segment.extent is not None and _extent_is_empty(segment.extent)
            if unclaimed and not declared_empty:
                shown = "; ".join(
                    f"layer {layer}: {', '.join(map(str, values[:10]))}"
                    for layer, values in unclaimed.items()
                )
                raise FormatError(
                    f"{p}: segment {segment.index} ({segment.name}) claims label value "
                    f"{segment.label_value} of layer {segment.layer}"
                    f"{_defaulted(info, segment)}, which holds no such voxel, while voxels "
                    f"of values no segment claims are there ({shown}); its LabelValue or "
                    "Layer is wrong: fix the header"
                )
            logger.warning(
                "%s: segment %d (%s) holds no voxel; it is skipped", p, segment.index, segment.name
            )
            continue
        if segment.extent is not None:
            mask &= _inside(segment.extent, info.shape)
            inside = int(np.count_nonzero(mask))
            if inside < total:
                logger.warning(
                    "%s: %s of the %d voxels of segment %d (%s) lie outside its extent "
                    "(Segment%d_Extent %s) and are left out, as 3D Slicer leaves them out%s; "
                    "fix the Extent to keep them",
                    p,
                    "all" if inside == 0 else str(total - inside),
                    total,
                    segment.index,
                    segment.name,
                    segment.index,
                    " ".join(map(str, segment.extent)),
                    ": the segment is skipped" if inside == 0 else "",
                )
                if inside == 0:
                    continue
        masks[segment.index] = mask
    for layer, stray in unclaimed.items():
        logger.warning(
            "%s: layer %d holds values no segment claims (%s%s); they are ignored",
            p,
            layer,
            ", ".join(str(v) for v in stray[:10]),
            ", ..." if len(stray) > 10 else "",
        )
    drawn = [s for s in kept if s.index in masks]
    values = [s.label_value for s in drawn]
    if len(set(values)) == len(values):
        out_value = {s.index: s.label_value for s in drawn}
    else:
        out_value = {s.index: n for n, s in enumerate(drawn, start=1)}
        logger.warning(
            "%s: segments of different layers share label values; they are numbered in file "
            "order: %s",
            p,
            ", ".join(
                f"{s.name or s.index} (layer {s.layer}, value {s.label_value}) -> "
                f"{out_value[s.index]}"
                for s in drawn
            ),
        )
    return drawn, masks, out_value


def _flatten(p: Path, info: NrrdInfo, data: NDArray[np.integer]) -> LabelMap:
    """One label map from the segments of every layer; later layers win on overlap
    (:func:`_segment_masks` says what is reported or refused)."""
    drawn, masks, out_value = _segment_masks(p, info, data)
    labels = np.zeros(info.shape, dtype=labels_dtype(list(out_value.values())))
    overlap = 0
    for segment in sorted(drawn, key=lambda s: (s.layer, s.index)):
        mask = masks[segment.index]
        overlap += int(np.count_nonzero(labels[mask]))
        labels[mask] = out_value[segment.index]
    if overlap:
        logger.warning(
            "%s: segments of different layers overlap on %d voxels; each goes to "
            "the segment of the later layer",
            p,
            overlap,
        )
    present = label_values(labels)
    structures = []
    for segment in sorted(drawn, key=lambda s: out_value[s.index]):
        value = out_value[segment.index]
        if value not in present:  # every voxel taken by a later layer
            logger.warning(
                "%s: segment %d (%s) lies entirely under segments of later layers; it is skipped",
                p,
                segment.index,
                segment.name,
            )
            continue
        structures.append(Structure(value, segment.name, segment.colour))
    return LabelMap(labels, info.affine, tuple(structures), info.coordinates)


def _defaulted(info: NrrdInfo, segment: NrrdSegment) -> str:
    """`` (its LabelValue is missing: 1 assumed)`` when the header did not give it."""
    return "" if segment.label_value_given else " (its LabelValue is missing: 1 is assumed)"


def _extent_is_empty(extent: Sequence[int]) -> bool:
    return any(extent[2 * a] > extent[2 * a + 1] for a in range(3))


def _inside(extent: Sequence[int], shape: Sequence[int]) -> NDArray[np.bool_]:
    """The voxels of ``shape`` inside an inclusive ``(i0, i1, j0, j1, k0, k1)`` extent."""
    box = np.zeros(tuple(shape), dtype=bool)
    region = tuple(slice(max(extent[2 * a], 0), max(extent[2 * a + 1] + 1, 0)) for a in range(3))
    box[region] = True
    return box


def _label_voxels(
    p: Path,
    header: Mapping[str, Any],
    info: NrrdInfo,
    fh: io.BufferedIOBase,
    memory_budget_gb: float,
) -> NDArray[np.integer]:
    """The integer voxels of a label map or segmentation, its grid checked against the budget.

    Shape (L, I, J, K): L layers (1 for a 3-D file).
    """
    check_grid(
        info.shape,
        what=str(p),
        memory_budget_gb=memory_budget_gb,
        bytes_per_voxel=2 * info.layers * info.dtype.itemsize + 5,
    )
    return _integer_values(p, _voxels(p, header, info, fh, memory_budget_gb))


def read_nrrd_label_map(
    path: str | os.PathLike[str],
    *,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> LabelMap:
    """Every structure of a NRRD label map or Slicer segmentation, on one grid.

    Parameters
    ----------
    path : path-like
        A ``.nrrd`` label map (3-D, integer values, or floats holding whole
        numbers) or a ``.seg.nrrd`` segmentation (3-D, or 4-D with a list axis
        of layers).
    memory_budget_gb : float
        Refuse headers whose declared grid would not fit this budget, GiB
        (:func:`slicerecon.io.limits.check_grid`), before reading any voxel.

    Returns
    -------
    LabelMap
        Labels of shape ``(I, J, K)`` (the file's spatial axes in order), the
        affine in ``coordinates`` (``"LPS"`` or ``"RAS"``, from ``space``).
        A plain label map has one structure per non-zero value, unnamed. A
        segmentation has one per segment that holds a voxel, with its name and
        colour; its value is ``Segment<N>_LabelValue``, unless segments of
        different layers share values: then segments are numbered 1, 2, ... in
        file order (with a warning). Segments with label value 0 or without a
        voxel are skipped with a warning; on overlap the later layer wins.
        A file whose every voxel is background gives no structure.

    Raises
    ------
    InputError
        What :func:`nrrd_info` raises; a plain 4-D image of several volumes.
    FormatError
        Truncated or corrupt voxel data, more data than declared, a ``line
        skip`` or ``byte skip`` past the data; segments that cannot match the
        voxels (two claiming one value of a layer; a value absent from its
        layer while another value there belongs to no segment).
    LabelError
        Non-integer or non-finite voxel values, values beyond 32-bit integers.
    MemoryBudgetError
        The declared grid, or the decompressed bytes a ``byte skip`` asks
        for, exceed ``memory_budget_gb``.
    """
    p = open_nrrd(path)
    with reading(p), open(p, "rb") as fh:
        header = read_header(p, fh)
        info = header_info(p, header)
        if not info.is_segmentation and info.layers > 1:
            raise InputError(
                f"{p} is a 4-D image holding {info.layers} volumes and no Slicer segment "
                "fields; extract the one 3-D label map to use and pass that"
            )
        data = _label_voxels(p, header, info, fh, memory_budget_gb)
        if info.is_segmentation:
            result = _flatten(p, info, data)
        else:
            labels = data[0]
            values = sorted(label_values(labels) - {0})
            result = LabelMap(
                labels, info.affine, tuple(Structure(v) for v in values), info.coordinates
            )
    logger.info(
        "read %s: %s, %d structure(s), %s",
        p,
        "x".join(map(str, info.shape)),
        len(result.structures),
        info.coordinates,
    )
    return result


def read_nrrd_masks(
    path: str | os.PathLike[str],
    *,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> StructureMasks:
    """Every segment of a Slicer segmentation as its own mask, overlaps between layers kept.

    Parameters
    ----------
    path : path-like
        A ``.seg.nrrd`` segmentation (3-D, or 4-D with a list axis of layers).
    memory_budget_gb : float
        As for :func:`read_nrrd_label_map`.

    Returns
    -------
    StructureMasks
        One mask of shape ``(I, J, K)`` per segment that holds a voxel, named,
        coloured and numbered as :func:`read_nrrd_label_map` numbers them.

    Raises
    ------
    InputError
        Not a segmentation (no ``Segment<N>_*`` fields), or what
        :func:`read_nrrd_label_map` raises.
    EmptyMaskError
        No segment holds a voxel.
    """
    p = open_nrrd(path)
    with reading(p), open(p, "rb") as fh:
        header = read_header(p, fh)
        info = header_info(p, header)
        if not info.is_segmentation:
            raise InputError(f"{p} holds no Slicer segment fields: read it as a label map")
        data = _label_voxels(p, header, info, fh, memory_budget_gb)
        drawn, masks, out_value = _segment_masks(p, info, data)
    if not drawn:
        raise EmptyMaskError(f"{p} is empty: no segment holds a voxel")
    ordered = sorted(drawn, key=lambda s: out_value[s.index])
    return StructureMasks(
        tuple(masks[s.index] for s in ordered),
        info.affine,
        tuple(Structure(out_value[s.index], s.name, s.colour) for s in ordered),
        info.coordinates,
    )


def read_nrrd(
    path: str | os.PathLike[str],
    *,
    label: int | str | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> Volume:
    """One structure (or every non-zero voxel) of a NRRD label map or segmentation.

    Parameters
    ----------
    path : path-like
        As for :func:`read_nrrd_label_map`.
    label : int or str, optional
        The structure, by value or, for a segmentation, by segment name
        (:func:`slicerecon.selection.choose_structure`). Default: every
        non-zero voxel.
    memory_budget_gb : float
        As for :func:`read_nrrd_label_map`.

    Returns
    -------
    Volume
        The mask and the affine (in the file's frame: see :func:`nrrd_info`).

    Raises
    ------
    EmptyMaskError
        Every voxel is background.
    LabelError
        ``label`` names no structure (the message lists them).
    InputError
        What :func:`read_nrrd_label_map` raises.
    """
    selector = parse_selector(label)
    label_map = read_nrrd_label_map(path, memory_budget_gb=memory_budget_gb)
    if not label_map.structures:
        raise EmptyMaskError(
            f"{path} is empty: every voxel is background, there is nothing to reconstruct"
        )
    if selector is None:
        return label_map.union()
    names = {s.value: s.name for s in label_map.structures}
    kind = "segment" if any(names.values()) else "label"
    return label_map.mask(choose_structure(names, selector, kind=kind, source=Path(path)))
