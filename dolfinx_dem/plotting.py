"""Pictures of dolfinx_dem results: deformed meshes coloured by a cell field, and time series.

``plot_cell_field`` renders off-screen with pyvista (no X server needed) on rank 0 after
gathering the owned cells of every rank, the colour bar and the time in a column of their own
beside the body, rigid obstacles (half-spaces) as grey bands bounded by a dark line (2D) or plane
(3D); ``plot_bar`` draws a 1D bar as matplotlib line plots of its displacement and stress, its
obstacles as walls, and ``animate_bar`` animates it in the same layout (``show.py`` draws the
series). Matplotlib draws on its Agg canvas (no display, no global pyplot state).
Pictures gather on rank 0 only meshes of at most ``PICTURE_MAX_CELLS`` cells.
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence

import imageio
import matplotlib.figure
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from mpi4py import MPI

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError, MissingFileError

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
        raise InputError(f"values must have shape ({n},) (owned cells), got {values.shape}")
    if displacement is not None:
        displacement = np.asarray(displacement, dtype=np.float64)
        if displacement.shape != (n, gdim):
            raise InputError(
                f"displacement must have shape ({n}, {gdim}) (owned cells, gdim), got {displacement.shape}"
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
    obstacles: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
    rigid: np.ndarray | None = None,
    caption: str | None = None,
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
    obstacles : rigid half-spaces {x : (x - point) . normal < 0} as (point, normal) pairs of
        ``gdim`` numbers, drawn across the view.
    rigid : (n_owned_cells,) booleans: cells of rigid (prescribed) bodies, drawn light grey
        without the field's colour (their stress means nothing), or None.
    caption : text in the upper left corner, e.g. ``picture_caption(...)``: what, when, how scaled.

    Rows follow the owned DG0 dofs, i.e. dolfinx_dem's cell numbering: for DG0 Functions ``u``
    (vector) and ``s`` (scalar) pass ``u.x.array[:n * gdim].reshape(n, gdim)`` and
    ``s.x.array[:n]``.

    Returns ``str(filename)``, or None without writing anything when the mesh has more than
    ``PICTURE_MAX_CELLS`` cells.
    """
    filename = pathlib.Path(filename)
    _check_output(filename, scale)
    obstacles = _check_obstacles(obstacles, mesh.geometry.dim)
    if too_large(mesh):
        return None
    if rigid is not None:
        values = np.where(rigid, np.nan, values)  # drawn in _show's nan_color
    grid = _grid(mesh, displacement, values, title, scale)
    if grid is None:
        return str(filename)
    plotter = _plotter((1200, 900))
    _show(plotter, grid, title, mesh.geometry.dim, obstacles)
    if caption:
        plotter.subplot(0, 0)
        plotter.add_text(caption, position="upper_left", font_size=11, color="black")
    plotter.screenshot(str(filename))
    plotter.close()
    return str(filename)


def plot_bar(
    mesh,
    displacement: np.ndarray,
    stress: np.ndarray,
    filename: str | pathlib.Path,
    t: float,
    obstacles: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
) -> str:
    """Line plots of a 1D bar at time ``t``: its displaced position with the obstacles, and the
    cell displacement (m) and stress sigma_xx (Pa) against x, as steps (DG0 fields).

    Collective over ``mesh.comm`` (a 1D mesh): the owned cells are gathered on rank 0, which
    writes ``filename``. ``displacement`` (n_owned_cells, 1) and ``stress`` (n_owned_cells,)
    follow the owned DG0 dofs as in ``plot_cell_field``; ``obstacles`` as there (1 number each).
    Returns ``str(filename)``, or None without writing anything when the mesh has more than
    ``PICTURE_MAX_CELLS`` cells.
    """
    filename = pathlib.Path(filename)
    _check_output(filename, 1.0)
    if mesh.topology.dim != 1:
        raise InputError(f"plot_bar draws 1D meshes, not {mesh.topology.dim}D (use plot_cell_field)")
    obstacles = _check_obstacles(obstacles, 1)
    if too_large(mesh):
        return None
    displacement = np.asarray(displacement, dtype=np.float64)
    gathered = _gather_cells(mesh, displacement, stress)
    u_cells = _gather_cells(mesh, None, displacement.reshape(-1))
    if gathered is None:
        return str(filename)
    points, cells, sigma, u_points = gathered
    position = points[:, 0] + u_points[:, 0]
    figure = matplotlib.figure.Figure(figsize=(8.0, 7.0))
    _draw_bar(
        figure, points[cells, 0], position, u_cells[2], sigma, _span(position, points[:, 0], obstacles), t, obstacles
    )
    figure.tight_layout()
    figure.savefig(str(filename), dpi=120)
    return str(filename)


def animate_bar(
    xdmf: str | pathlib.Path,
    filename: str | pathlib.Path,
    obstacles: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
) -> int:
    """An animated GIF of a 1D ``solution.xdmf``, one frame per output time in the layout of
    ``plot_bar`` (the bar's position with the obstacles, its displacement and its stress
    ``stress_xx`` along x), with the axes' limits of the whole run, 800 x 640 pixels.

    Serial, read by VTK as in ``animate_solution``. Returns the number of frames.
    """
    filename = pathlib.Path(filename)
    _check_output(filename, 1.0)
    obstacles = _check_obstacles(obstacles, 1)
    reader = pyvista.get_reader(str(xdmf))
    frames = []  # (t, cells' node x (N, 2), cell u (N,), cell sigma (N,), node x + u (P,))
    for t in reader.time_values:
        reader.set_active_time_value(t)
        blocks = reader.read()
        grid = pyvista.UnstructuredGrid(blocks["stress_xx"])
        grid.cell_data["u"] = blocks["displacement"].cell_data["displacement"].reshape(grid.n_cells, -1)[:, 0]
        u_points = grid.cell_data_to_point_data().point_data["u"]  # mean of the cells around each node
        x = grid.points[:, 0]
        frames.append(
            (
                t,
                x[grid.cell_connectivity.reshape(-1, 2)],
                grid.cell_data["u"].copy(),
                grid.cell_data["stress_xx"].copy(),
                x + u_points,
            )
        )
    span = _span(np.concatenate([f[4] for f in frames]), frames[0][1].ravel(), obstacles)
    limits = [_limits(np.concatenate([f[k] for f in frames])) for k in (2, 3)]
    figure = matplotlib.figure.Figure(figsize=(8.0, 6.4), dpi=100)
    figure.subplots_adjust(left=0.12, right=0.97, bottom=0.08, top=0.94, hspace=0.6)  # fixed: no jitter
    canvas = FigureCanvasAgg(figure)
    with imageio.get_writer(filename, mode="I", duration=100, loop=0) as gif:
        for t, x_cells, u, sigma, position in frames:
            figure.clear()
            axes = _draw_bar(figure, x_cells, position, u, sigma, span, t, obstacles)
            for ax, limit in zip(axes[1:], limits):
                ax.set_ylim(*limit)
            canvas.draw()
            gif.append_data(np.asarray(canvas.buffer_rgba())[:, :, :3])
    return len(frames)


def _span(position: np.ndarray, x: np.ndarray, obstacles) -> tuple[float, float]:
    """The x range of the position axes of ``_draw_bar``: the displaced nodes ``position``, the
    reference nodes ``x`` and the obstacles' points, with a margin of 5 %."""
    low = min(position.min(), x.min(), *(p[0] for p, _ in obstacles))
    high = max(position.max(), x.max(), *(p[0] for p, _ in obstacles))
    margin = 0.05 * (high - low)
    return low - margin, high + margin


def _limits(values: np.ndarray) -> tuple[float, float]:
    """Axis limits holding ``values`` with a margin of 5 % (a flat range gets one of 1)."""
    low, high = float(values.min()), float(values.max())
    margin = 0.05 * (high - low) if high > low else 1.0
    return low - margin, high + margin


def _draw_bar(
    figure,
    x_cells: np.ndarray,
    position: np.ndarray,
    u: np.ndarray,
    sigma: np.ndarray,
    span: tuple[float, float],
    t: float,
    obstacles,
) -> list:
    """Draw ``plot_bar``'s three axes on ``figure``: the bar from the smallest to the largest of
    ``position`` (x + u at the nodes) with the ``obstacles`` over the x range ``span``, and the
    cell displacement ``u`` (N,) and stress ``sigma`` (N,) as steps over the cells ``x_cells``
    (N, 2) node coordinates, any order. Returns the axes."""
    order = np.argsort(x_cells.min(axis=1))
    edges = np.append(x_cells.min(axis=1)[order], x_cells.max(axis=1)[order][-1])
    ax0, ax1, ax2 = figure.subplots(3, 1, gridspec_kw={"height_ratios": [1, 2, 2]})
    ax0.plot([position.min(), position.max()], [0.0, 0.0], color="C0", lw=8, solid_capstyle="butt", label="bar")
    for k, (p, n) in enumerate(obstacles):
        side = (span[0], p[0]) if n[0] > 0 else (p[0], span[1])
        ax0.axvspan(*side, color="0.6", alpha=0.5, hatch="//", label="obstacle" if k == 0 else None)
        ax0.axvline(p[0], color="0.2", lw=2)
    ax0.set_xlim(*span)
    ax0.set_yticks([])
    ax0.set_xlabel("x + u (m)")
    ax0.legend(loc="upper right", fontsize="small")
    ax0.set_title(f"t = {t:.6g} s")
    ax1.stairs(u[order], edges, baseline=None, color="C0", lw=1.5)
    ax1.set_ylabel("displacement u (m)")
    ax2.stairs(sigma[order], edges, baseline=None, color="C3", lw=1.5)
    ax2.set_ylabel("stress $\\sigma_{xx}$ (Pa)")
    for ax in (ax1, ax2):
        ax.set_xlim(edges[0], edges[-1])
        ax.set_xlabel("x (m)")
        ax.grid(True, alpha=0.3)
    return [ax0, ax1, ax2]


def animate_solution(
    xdmf: str | pathlib.Path,
    filename: str | pathlib.Path,
    field: str,
    title: str,
    scale: float = 1.0,
    obstacles: Sequence[tuple[Sequence[float], Sequence[float]]] = (),
    rigid_bodies: Sequence[int] = (),
) -> int:
    """An animated GIF of the cell field ``field`` of a ``solution.xdmf`` (``io.SolutionWriter``)
    on the mesh deformed by ``scale`` times its ``displacement``, one frame per output time, with
    the ``obstacles`` of ``plot_cell_field``; the cells whose ``body`` field is in
    ``rigid_bodies`` light grey, as ``plot_cell_field``'s ``rigid`` cells.

    Serial: VTK reads the file (so a resumed run, whose output times refer to several meshes,
    animates as one). The points move by the mean displacement of the cells around them, as in
    ``plot_cell_field``; the view holds the deformed body of every frame (before, the camera was set
    on the first frame, and bodies that moved left the view), the colour scale of each frame spans
    that frame's values, the frame shows the time (above the colour bar, beside the body). Returns
    the number of frames.
    """
    filename = pathlib.Path(filename)
    _check_output(filename, scale)
    corners = np.array([np.reshape(grid.bounds, (3, 2)).T for _, _, grid in solution_frames(xdmf, field, scale)])
    bounds = np.array([corners[:, 0].min(axis=0), corners[:, 1].max(axis=0)])  # of the whole run
    plotter = _plotter((800, 640))
    plotter.open_gif(str(filename))
    for k, (t, blocks, grid) in enumerate(solution_frames(xdmf, field, scale)):
        grid.cell_data[title] = grid.cell_data[field]
        if len(rigid_bodies):
            grid.cell_data[title][np.isin(blocks["body"].cell_data["body"], rigid_bodies)] = np.nan
        flat = 2 if np.ptp(grid.points[:, 2]) == 0 else 3
        if k == 0:
            obstacles = _check_obstacles(
                obstacles, np.flatnonzero(np.ptp(grid.points, axis=0) > 0).max(initial=0) + 1 if flat == 2 else 3
            )
        _show(plotter, grid, title, flat, obstacles, name="body", reset=k == 0, bounds=bounds)
        plotter.subplot(0, 1)
        plotter.add_text(f"t = {t:.4g} s", position="upper_left", font_size=12, color="black", name="time")
        plotter.subplot(0, 0)
        plotter.write_frame()
    plotter.close()
    return k + 1


def picture_caption(scene: str, t: float, scale: float, static: bool = False) -> str:
    """The caption of a run's ``final.png``: the scene, the (load) time and the displacement scale."""
    when = f"static, load time t = {t:.4g} s" if static else f"t = {t:.4g} s"
    return f"{scene}: {when}, displacement x{scale:g}"


def solution_frames(xdmf: str | pathlib.Path, field: str, scale: float):
    """For each output time of a ``solution.xdmf``: (t, its blocks, a grid of the cell field
    ``field`` whose points are the mesh's moved by ``scale`` times the mean displacement of the
    cells around them). Each frame's grid is a deep copy: the reader keeps its points from time to
    time, and moving them in place added every frame's displacement to the previous ones'."""
    reader = pyvista.get_reader(str(xdmf))
    for t in reader.time_values:
        reader.set_active_time_value(t)
        blocks = reader.read()
        grid = blocks[field].copy(deep=True)
        grid.cell_data["u"] = blocks["displacement"].cell_data["displacement"]
        u = grid.cell_data_to_point_data().point_data["u"].reshape(grid.n_points, -1)  # 1D: one component
        grid.points[:, : u.shape[1]] += scale * u
        yield t, blocks, grid


def _check_output(filename: pathlib.Path, scale: float):
    if not math.isfinite(scale):
        raise InputError(f"scale must be finite, got {scale!r}")
    if not filename.parent.is_dir():
        raise MissingFileError(f"directory {filename.parent} of {filename} does not exist")


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
    grid = pyvista.UnstructuredGrid(connectivity, np.full(num_cells, _VTK_SIMPLEX[tdim], dtype=np.uint8), points)
    grid.cell_data[title] = cell_values
    return grid


def _check_obstacles(obstacles, gdim: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(point, unit normal) arrays of ``gdim`` numbers for each obstacle (a clear error otherwise)."""
    out = []
    for k, (point, normal) in enumerate(obstacles):
        p, n = np.asarray(point, dtype=float), np.asarray(normal, dtype=float)
        if (
            p.shape != (gdim,)
            or n.shape != (gdim,)
            or not (np.isfinite(p).all() and np.isfinite(n).all())
            or not np.linalg.norm(n) > 0
        ):
            raise InputError(f"obstacle {k}: point and normal need {gdim} finite numbers, the normal nonzero")
        out.append((p, n / np.linalg.norm(n)))
    return out


def _plotter(window_size: tuple[int, int]):
    """An off-screen plotter with the body on the left and a narrow column on the right for the
    colour bar and the time, so that neither covers the body."""
    return pyvista.Plotter(off_screen=True, window_size=window_size, shape=(1, 2), col_weights=[3, 1], border=False)


def _obstacle_meshes(obstacles, bounds: np.ndarray, gdim: int) -> tuple[list, np.ndarray]:
    """The obstacles' shapes, each (mesh, style), larger than the view: in 1D and 2D a grey band
    of the half-space and its boundary line, in 3D its boundary plane, centred at the boundary
    point nearest the body's centre; and those points (n_obstacles, 3). ``bounds``: (2, 3) lower
    and upper corners of the body."""
    centre, size = bounds.mean(axis=0), 2.0 * max(np.ptp(bounds, axis=0).max(), 1e-12)
    shapes, feet = [], []
    for p, n in obstacles:
        n3, p3 = np.zeros(3), np.zeros(3)
        n3[: len(n)], p3[: len(p)] = n, p
        foot = centre - np.dot(centre - p3, n3) * n3
        feet.append(foot)
        if gdim == 3:
            plane = pyvista.Plane(center=foot, direction=n3, i_size=2 * size, j_size=2 * size)
            shapes.append((plane, {"color": "grey", "opacity": 0.5}))
        else:
            tangent = np.array([-n3[1], n3[0], 0.0])
            a, b = foot - size * tangent, foot + size * tangent
            shapes.append(
                (pyvista.Rectangle([a, b, b - size * n3]), {"color": "grey", "opacity": 0.35, "lighting": False})
            )
            shapes.append((pyvista.Line(a, b), {"color": "black", "line_width": 4}))
    return shapes, np.reshape(feet, (-1, 3))


def _show(plotter, grid, title: str, gdim: int, obstacles=(), name: str | None = None, reset: bool = True,
          bounds: np.ndarray | None = None):
    """Add ``grid`` (white background, viridis) to the left of ``plotter`` (``_plotter``), its
    colour bar on the right; with ``reset`` set the camera to the body (or to the box ``bounds``,
    (2, 3) lower and upper corners) and the nearest points of the obstacles, and draw the
    obstacles."""
    plotter.subplot(0, 0)
    plotter.set_background("white")
    style = {"scalars": title, "cmap": "viridis", "name": name, "show_scalar_bar": False, "nan_color": "lightgrey"}
    num_cells = grid.n_cells
    if grid.get_cell(0).type == pyvista.CellType.LINE:
        actor = plotter.add_mesh(grid, line_width=10, **style)
    else:
        actor = plotter.add_mesh(grid, show_edges=num_cells <= _MAX_CELLS_WITH_EDGES, edge_color="grey", **style)
    if reset:
        bounds = np.reshape(grid.bounds, (3, 2)).T if bounds is None else bounds
        shapes, feet = _obstacle_meshes(obstacles, bounds, gdim)
        view = np.vstack([bounds, feet])
        for shape, shape_style in shapes:
            plotter.add_mesh(shape, **shape_style)
        if gdim == 3:
            plotter.view_isometric()
        else:
            plotter.camera_position = "xy"
        plotter.reset_camera(bounds=np.column_stack([view.min(axis=0), view.max(axis=0)]).ravel())
    plotter.subplot(0, 1)
    plotter.set_background("white")
    plotter.add_scalar_bar(
        title,
        mapper=actor.mapper,
        color="black",
        vertical=True,
        position_x=0.2,
        position_y=0.08,
        width=0.4,
        height=0.75,
        title_font_size=12,
        label_font_size=12,
    )
    plotter.subplot(0, 0)
