"""The result frames read by the readers users have: meshio 5.3.5 (what most Python
pipelines use) and pyvista (VTK's own XML reader, what ParaView runs), pinned by
scripts/vtu-readers.sh.

For each series directory given: every frame listed in series.pvd loads in both readers;
both see the point and cell counts the file declares (read here with xml.etree, a third
reader); the cell data `region` and the point vector `displacement_m` are the same values in
both (exactly: ASCII numbers parsed twice); the region names are in both readers' field data
as `region:NAME` arrays whose tags occur in `region`; pyvista's PVD reader gives the frames'
times in order. A directory given as `DIR:TYPE,...` must hold exactly those meshio cell
types (e.g. `tetra`, `hexahedron,wedge`) in every frame. The last frame must have moved (max |u| > 1e-6 m), so the comparison is not
of zero fields. Exits non-zero with the file and the property on the first failure.
"""
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pyvista as pv

PREFIX = "region:"


def fail(path, what):
    sys.exit(f"vtu-readers: {path}: {what}")


def declared_counts(path):
    piece = ET.parse(path).getroot().find("./UnstructuredGrid/Piece")
    return int(piece.get("NumberOfPoints")), int(piece.get("NumberOfCells"))


def check_frame(path, types):
    n_points, n_cells = declared_counts(path)
    m = meshio.read(path)
    g = pv.read(path)
    seen = sorted({b.type for b in m.cells})
    if types and seen != sorted(types):
        fail(path, f"cell types {seen}, expected {sorted(types)}")
    if len(m.points) != n_points or g.n_points != n_points:
        fail(path, f"points: file {n_points}, meshio {len(m.points)}, pyvista {g.n_points}")
    m_cells = sum(len(b.data) for b in m.cells)
    if m_cells != n_cells or g.n_cells != n_cells:
        fail(path, f"cells: file {n_cells}, meshio {m_cells}, pyvista {g.n_cells}")
    m_region = np.concatenate(m.cell_data["region"])
    g_region = np.asarray(g.cell_data["region"])
    if not np.array_equal(m_region, g_region):
        fail(path, "cell data region differs between meshio and pyvista")
    m_u = np.asarray(m.point_data["displacement_m"])
    g_u = np.asarray(g.point_data["displacement_m"])
    if m_u.shape != (n_points, 3) or not np.array_equal(m_u, g_u):
        fail(path, f"displacement_m differs: meshio {m_u.shape}, pyvista {g_u.shape}")
    m_names = {k[len(PREFIX):]: int(np.ravel(v)[0]) for k, v in m.field_data.items() if k.startswith(PREFIX)}
    g_names = {k[len(PREFIX):]: int(np.ravel(g.field_data[k])[0]) for k in g.field_data.keys() if k.startswith(PREFIX)}
    if not m_names or m_names != g_names:
        fail(path, f"region names: meshio {m_names}, pyvista {g_names}")
    unknown = set(m_names.values()) - set(np.unique(m_region).tolist())
    if unknown:
        fail(path, f"named regions {sorted(unknown)} occur in no cell")
    return np.abs(m_u).max(), m_names


def check_series(arg):
    directory, _, kinds = arg.partition(":")
    types = [t for t in kinds.split(",") if t]
    pvd = Path(directory) / "series.pvd"
    frames = [Path(directory) / d.get("file") for d in ET.parse(pvd).getroot().iter("DataSet")]
    times = [float(d.get("timestep")) for d in ET.parse(pvd).getroot().iter("DataSet")]
    if len(frames) < 2:
        fail(pvd, f"{len(frames)} frames: too few to compare")
    reader = pv.get_reader(str(pvd))
    if not np.allclose(reader.time_values, times, rtol=0, atol=0):
        fail(pvd, f"pyvista's PVD times {reader.time_values[:3]}... differ from the file's")
    moved = 0.0
    for f in frames:
        moved, names = check_frame(f, types)
    if not moved > 1e-6:
        fail(frames[-1], f"max |u| = {moved}: nothing moved, the comparison is of zeros")
    print(f"vtu-readers: {directory}: {len(frames)} frames load in meshio {meshio.__version__} "
          f"and pyvista {pv.__version__} (VTK {pv.vtk_version_info}); regions {sorted(names)}; "
          f"last max |u| {moved:.3e} m; cell types {types or 'any'}")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit("usage: readers.py SERIES_DIR...")
    for d in sys.argv[1:]:
        check_series(d)
