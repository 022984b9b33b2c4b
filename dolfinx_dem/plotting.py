"""Pictures of dolfinx_dem results: deformed meshes coloured by a cell field, and time series.

``plot_cell_field`` renders off-screen with pyvista (no X server needed) on rank 0 after
gathering the owned cells of every rank; ``plot_series`` draws a ``series.csv`` with matplotlib's
Agg canvas (no display, no global pyplot state).
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence

import numpy as np
from mpi4py import MPI

import matplotlib.figure

from dolfinx_dem import _compat

pyvista = _compat.import_pyvista()

_VTK_SIMPLEX = {1: pyvista.CellType.LINE, 2: pyvista.CellType.TRIANGLE, 3: pyvista.CellType.TETRA}
_MAX_CELLS_WITH_EDGES = 5000  # above this the cell edges would hide the colours
#: Pictures gather the mesh on rank 0; above this many cells (globally) they are skipped, so that
#: no process ever holds a large mesh whole (the XDMF output has every field, for ParaView).
PICTURE_MAX_CELLS = 500_000


def too_large(mesh) -> bool:
    """Whether ``mesh`` has more cells than pictures draw (``PICTURE_MAX_CELLS``)."""
    return mesh.topology.index_map(mesh.topology.dim).size_global > PICTURE_MAX_CELLS


def _gather_cells(mesh, displacement: np.ndarray | None, values: np.ndarray):
    """Gather the owned cells on rank 0: points (P, 3), cells (N, d+1), values (N,), u (P, gdim).

    Rows of ``displacement`` and ``values`` follow the owned DG0 dofs (see ``plot_cell_field``).
    ``u`` is the mean displacement of the cells around each point (None without displacement).
    Returns None on the other ranks.
    """
    comm: MPI.Comm = mesh.comm
    gdim = mesh.geometry.dim
    V = _compat.create_scalar_space(mesh, "DG", 0)
    dofs, start, stop = _compat.dg0_cell_dofs(V)
    n = stop - start
    values = np.asarray(values, dtype=np.float64)
    if values.shape != (n,):
        raise ValueError(f"values must have shape ({n},) (owned cells), got {values.shape}")
    if displacement is not None:
        displacement = np.asarray(displacement, dtype=np.float64)
        if displacement.shape != (n, gdim):
            raise ValueError(
                f"displacement must have shape ({n}, {gdim}) (owned cells, gdim), "
                f"got {displacement.shape}"
            )
    row = dofs - start  # row of each owned cell (process-local cell order)
    nodes, x = _compat.owned_cell_nodes(mesh)
    u = None if displacement is None else displacement[row]
    parts = comm.gather((nodes, x, values[row], u), root=0)
    if comm.rank != 0:
        return None

    nodes = np.concatenate([p[0] for p in parts])
    x = np.concatenate([p[1] for p in parts])
    cell_values = np.concatenate([p[2] for p in parts])
    num_cells, k = nodes.shape
    unique, cells = np.unique(nodes.reshape(-1), return_inverse=True)
    cells = cells.reshape(num_cells, k)
    points = np.empty((unique.shape[0], 3))
    points[cells.reshape(-1)] = x.reshape(-1, 3)
    if displacement is None:
        return points, cells, cell_values, None
    u_cells = np.concatenate([p[3] for p in parts])
    u_points = np.zeros((unique.shape[0], gdim))
    np.add.at(u_points, cells.reshape(-1), np.repeat(u_cells, k, axis=0))
    u_points /= np.bincount(cells.reshape(-1), minlength=unique.shape[0])[:, None]
    return points, cells, cell_values, u_points


def plot_cell_field(
    mesh,
    displacement: np.ndarray | None,
    values: np.ndarray,
    filename: str | pathlib.Path,
    title: str,
    scale: float = 1.0,
) -> str:
    """Picture of the mesh, deformed by ``scale * displacement``, coloured by a cell field.

    Collective over ``mesh.comm``; rank 0 renders off-screen and writes ``filename`` (PNG, or any
    format ``pyvista.Plotter.screenshot`` knows).

    Parameters
    ----------
    mesh : 1D, 2D or 3D simplex mesh.
    displacement : (n_owned_cells, gdim) cell displacements (m), or None for the undeformed mesh.
        The points move by the mean displacement of the cells around them.
    values : (n_owned_cells,) cell field, e.g. von Mises stress (Pa).
    filename : picture file; its directory must exist.
    title : title of the scalar bar.
    scale : displacement magnification (dimensionless).

    Rows follow the owned DG0 dofs, i.e. dolfinx_dem's cell numbering: for DG0 Functions ``u``
    (vector) and ``s`` (scalar) pass ``u.x.array[:n * gdim].reshape(n, gdim)`` and
    ``s.x.array[:n]``.

    Returns ``str(filename)``, or None without writing anything when the mesh has more than
    ``PICTURE_MAX_CELLS`` cells.
    """
    filename = pathlib.Path(filename)
    _check_output(filename, scale)
    if too_large(mesh):
        return None
    grid = _grid(mesh, displacement, values, title, scale)
    if grid is None:
        return str(filename)
    plotter = pyvista.Plotter(off_screen=True, window_size=(1200, 900))
    _show(plotter, grid, title, mesh.geometry.dim)
    plotter.screenshot(str(filename))
    plotter.close()
    return str(filename)


def animate_solution(xdmf: str | pathlib.Path, filename: str | pathlib.Path, field: str, title: str,
                     scale: float = 1.0) -> int:
    """An animated GIF of the cell field ``field`` of a ``solution.xdmf`` (``io.SolutionWriter``)
    on the mesh deformed by ``scale`` times its ``displacement``, one frame per output time.

    Serial: VTK reads the file (so a resumed run, whose output times refer to several meshes,
    animates as one). The points move by the mean displacement of the cells around them, as in
    ``plot_cell_field``; the colour scale of each frame spans that frame's values, the frame
    shows the time. Returns the number of frames.
    """
    filename = pathlib.Path(filename)
    _check_output(filename, scale)
    reader = pyvista.get_reader(str(xdmf))
    plotter = pyvista.Plotter(off_screen=True, window_size=(800, 640))
    plotter.open_gif(str(filename))
    for k, t in enumerate(reader.time_values):
        reader.set_active_time_value(t)
        blocks = reader.read()
        grid = pyvista.UnstructuredGrid(blocks[field])
        grid.cell_data["u"] = blocks["displacement"].cell_data["displacement"]
        u = grid.cell_data_to_point_data().point_data["u"].reshape(grid.n_points, -1)  # 1D: one component
        grid.points[:, : u.shape[1]] += scale * u
        grid.cell_data[title] = grid.cell_data[field]
        flat = 2 if np.ptp(grid.points[:, 2]) == 0 else 3
        _show(plotter, grid, title, flat, name="body", reset=k == 0)
        plotter.add_text(f"t = {t:.4g} s", position="upper_left", color="black", name="time")
        plotter.write_frame()
    plotter.close()
    return len(reader.time_values)


def _check_output(filename: pathlib.Path, scale: float):
    if not math.isfinite(scale):
        raise ValueError(f"scale must be finite, got {scale!r}")
    if not filename.parent.is_dir():
        raise FileNotFoundError(f"directory {filename.parent} of {filename} does not exist")


def _grid(mesh, displacement, values, title: str, scale: float):
    """The deformed pyvista grid with the cell field ``title`` on rank 0, None elsewhere."""
    gathered = _gather_cells(mesh, displacement, values)
    if gathered is None:
        return None
    points, cells, cell_values, u_points = gathered
    tdim = mesh.topology.dim
    gdim = mesh.geometry.dim
    if u_points is not None:
        points[:, :gdim] += scale * u_points
    num_cells, k = cells.shape
    connectivity = np.hstack([np.full((num_cells, 1), k), cells]).reshape(-1)
    grid = pyvista.UnstructuredGrid(
        connectivity, np.full(num_cells, _VTK_SIMPLEX[tdim], dtype=np.uint8), points
    )
    grid.cell_data[title] = cell_values
    return grid


def _show(plotter, grid, title: str, gdim: int, name: str | None = None, reset: bool = True):
    """Add ``grid`` (white background, viridis, scalar bar) to ``plotter``; set the camera if
    ``reset``."""
    plotter.set_background("white")
    style = {
        "scalars": title,
        "cmap": "viridis",
        "scalar_bar_args": {"title": title, "color": "black"},
        "name": name,
    }
    num_cells = grid.n_cells
    if grid.get_cell(0).type == pyvista.CellType.LINE:
        plotter.add_mesh(grid, line_width=10, **style)
    else:
        plotter.add_mesh(grid, show_edges=num_cells <= _MAX_CELLS_WITH_EDGES, edge_color="grey", **style)
    if reset:
        if gdim == 3:
            plotter.view_isometric()
        else:
            plotter.camera_position = "xy"


def plot_series(
    csv_path: str | pathlib.Path, columns: Sequence[str], filename: str | pathlib.Path
) -> str:
    """Line plots of ``columns`` of a ``series.csv`` against its column ``t`` (s), one per axes.

    Serial (for ``dolfinx-dem show``). Returns ``str(filename)``.
    """
    csv_path = pathlib.Path(csv_path)
    if not csv_path.is_file():
        raise FileNotFoundError(f"series file {csv_path} does not exist")
    with open(csv_path) as f:
        header = f.readline().strip().split(",")
    columns = list(columns)
    if not columns:
        raise ValueError("columns must name at least one column to plot")
    for name in ["t", *columns]:
        if name not in header:
            raise ValueError(f"column {name!r} is not in {csv_path} (columns: {', '.join(header)})")
    data = np.loadtxt(csv_path, delimiter=",", skiprows=1, ndmin=2)
    if data.shape[0] == 0:
        raise ValueError(f"{csv_path} holds no rows")
    t = data[:, header.index("t")]

    figure = matplotlib.figure.Figure(figsize=(7.0, 0.8 + 2.2 * len(columns)))
    axes = figure.subplots(len(columns), 1, sharex=True, squeeze=False)[:, 0]
    for ax, name in zip(axes, columns):
        ax.plot(t, data[:, header.index(name)])
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t (s)")
    figure.tight_layout()
    figure.savefig(str(filename), dpi=120)
    return str(filename)
