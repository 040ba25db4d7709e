"""Turn the contours of a DICOM RTSTRUCT into a watertight mesh.

Writes a small RT Structure Set with pydicom: one ROI, "Lesion", outlined by
circles on 9 axial planes 3 mm apart (the sections of a 15 mm ball from
z = -12 mm to z = +12 mm). Reads it back with
:func:`slicerecon.io.rtstruct.read_rtstruct`, reconstructs a surface from the
contours (projections derived from the contours themselves) and writes it as
STL in DICOM patient coordinates (LPS mm).

Run::

    python examples/rtstruct_to_mesh.py [OUTDIR]
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.sequence import Sequence
from pydicom.uid import UID, ExplicitVRLittleEndian, generate_uid

from slicerecon.io.mesh import write_mesh
from slicerecon.io.rtstruct import read_rtstruct
from slicerecon.reconstruct import prepare_inputs, reconstruct

RTSTRUCT_STORAGE = UID("1.2.840.10008.5.1.4.1.1.481.3")
RADIUS_MM = 15.0
PLANES_MM = np.arange(-12.0, 12.1, 3.0)


def circle(radius: float, z: float, *, n: int = 96) -> np.ndarray:
    """A closed planar contour: n points (x, y, z) on a circle, mm."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[radius * np.cos(t), radius * np.sin(t), np.full(n, z)]


def write_rtstruct(path: Path, name: str, contours: list[np.ndarray]) -> Path:
    """Write a minimal RTSTRUCT holding one ROI with closed planar contours."""
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = RTSTRUCT_STORAGE
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = RTSTRUCT_STORAGE
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.Modality = "RTSTRUCT"
    ds.PatientName, ds.PatientID = "Example^Phantom", "EXAMPLE"
    ds.StudyInstanceUID, ds.SeriesInstanceUID = generate_uid(), generate_uid()
    ds.StructureSetLabel = "example"
    roi = Dataset()
    roi.ROINumber, roi.ROIName, roi.ROIGenerationAlgorithm = 1, name, "MANUAL"
    roi.ReferencedFrameOfReferenceUID = generate_uid()
    items = []
    for points in contours:
        item = Dataset()
        item.ContourGeometricType = "CLOSED_PLANAR"
        item.NumberOfContourPoints = len(points)
        item.ContourData = [f"{v:.6g}" for v in points.ravel()]
        items.append(item)
    holder = Dataset()
    holder.ReferencedROINumber = 1
    holder.ROIDisplayColor = [255, 0, 0]
    holder.ContourSequence = Sequence(items)
    ds.StructureSetROISequence = Sequence([roi])
    ds.ROIContourSequence = Sequence([holder])
    ds.save_as(path, enforce_file_format=True)
    return path


def main(outdir: Path) -> dict:
    """Write the RTSTRUCT, reconstruct it into ``outdir`` and return a few numbers."""
    contours = [circle(math.sqrt(RADIUS_MM**2 - z**2), float(z)) for z in PLANES_MM]
    rt_path = write_rtstruct(outdir / "rtstruct.dcm", "Lesion", contours)
    sections = read_rtstruct(rt_path, roi="Lesion", pixel_spacing=0.5)
    sections, projections, _ = prepare_inputs(sections, projections="sections")
    result = reconstruct(sections, projections, planner="heuristic", method="loft")
    mesh_path = write_mesh(result.mesh, outdir / "lesion.stl")
    h = float(PLANES_MM[-1])
    slab = math.pi * (RADIUS_MM**2 * 2 * h - 2 * h**3 / 3)  # the ball between the end planes
    print(
        f"{rt_path.name}: ROI 'Lesion', {sections.n_planes} planes, "
        f"gap {sections.gaps.min():.1f} mm"
    )
    print(
        f"{len(result.plan.parts)} part(s) -> {mesh_path} (watertight: {result.mesh.is_watertight})"
    )
    print(f"mesh volume {result.mesh.volume:.0f} mm³; ball between the end planes {slab:.0f} mm³")
    return {
        "mesh": mesh_path,
        "watertight": bool(result.mesh.is_watertight),
        "volume_mm3": float(result.mesh.volume),
        "reference_mm3": slab,
    }


if __name__ == "__main__":
    if len(sys.argv) > 1:
        target = Path(sys.argv[1])
        target.mkdir(parents=True, exist_ok=True)
        main(target)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            main(Path(tmp))
