import pathlib
import struct

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import _compat, meshes, plotting


def shared_path(tmp_path) -> pathlib.Path:
    """Rank 0's tmp_path, on every rank."""
    return MPI.COMM_WORLD.bcast(tmp_path, root=0)


def png_size(path: pathlib.Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", data[16:24])


def dg0_rows(mesh):
    """Owned rows (plot_cell_field order) of DG0 Functions: centroid x (n,), centroids (n, gdim)."""
    gdim = mesh.geometry.dim
    s = dolfinx.fem.Function(_compat.create_scalar_space(mesh, "DG", 0))
    s.interpolate(lambda x: x[0])
    u = dolfinx.fem.Function(_compat.create_vector_space(mesh, "DG", 0))
    u.interpolate(lambda x: x[:gdim])
    n = mesh.topology.index_map(mesh.topology.dim).size_local
    return s.x.array[:n].copy(), u.x.array[: n * gdim].reshape(n, gdim).copy()


@pytest.mark.mpi
def test_gather_cells_order_and_vertex_average():
    mesh, _, _ = meshes.create_rectangle(MPI.COMM_WORLD, [0, 0], [2, 1], [6, 3], "crossed")
    values, centroids = dg0_rows(mesh)
    gathered = plotting._gather_cells(mesh, centroids, values)
    if MPI.COMM_WORLD.rank != 0:
        assert gathered is None
        return
    points, cells, cell_values, u_points = gathered
    assert cells.shape == (4 * 18, 3)
    assert points.shape == (7 * 4 + 18, 3)  # vertices + one centre per rectangle
    cell_centroids = points[cells].mean(axis=1)
    assert np.allclose(cell_values, cell_centroids[:, 0])  # rows matched to the right cells
    for p in range(points.shape[0]):  # mean of the centroids of the cells around each point
        around = np.any(cells == p, axis=1)
        assert np.allclose(u_points[p], cell_centroids[around, :2].mean(axis=0))


@pytest.mark.mpi
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_plot_cell_field(tmp_path, dim):
    comm = MPI.COMM_WORLD
    if dim == 1:
        mesh, _, _ = meshes.create_interval(comm, 20, 0.0, 1.0)
    elif dim == 2:
        mesh, _, _ = meshes.create_discs(comm, [((0, 0), 1.0), ((2.5, 0), 1.0)], 0.1)
    else:
        mesh, _, _ = meshes.create_box(comm, [0, 0, 0], [2, 1, 1], [6, 3, 3])
    values, centroids = dg0_rows(mesh)
    displacement = 0.1 * centroids**2
    filename = shared_path(tmp_path) / f"field{dim}d.png"
    result = plotting.plot_cell_field(mesh, displacement, values, filename, "x (m)", scale=2.0)
    assert result == str(filename)
    comm.barrier()
    assert png_size(filename) == (1200, 900)
    assert filename.stat().st_size > 10_000


def test_plot_cell_field_undeformed_and_errors(tmp_path):
    mesh, _, _ = meshes.create_rectangle(MPI.COMM_WORLD, [0, 0], [1, 1], [2, 2])
    n = mesh.topology.index_map(2).size_local
    filename = plotting.plot_cell_field(mesh, None, np.arange(n), tmp_path / "a.png", "index")
    assert pathlib.Path(filename).stat().st_size > 0
    with pytest.raises(ValueError, match=r"values must have shape \(8,\)"):
        plotting.plot_cell_field(mesh, None, np.zeros(n + 1), tmp_path / "b.png", "v")
    with pytest.raises(ValueError, match=r"displacement must have shape \(8, 2\)"):
        plotting.plot_cell_field(mesh, np.zeros((n, 3)), np.zeros(n), tmp_path / "b.png", "v")
    with pytest.raises(FileNotFoundError, match="missing"):
        plotting.plot_cell_field(mesh, None, np.zeros(n), tmp_path / "missing" / "b.png", "v")


def test_pictures_are_skipped_above_the_size_limit(tmp_path, monkeypatch):
    """Pictures gather the mesh on rank 0: above PICTURE_MAX_CELLS they are not drawn at all."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_WORLD, 4, 4)
    n = mesh.topology.index_map(2).size_local
    monkeypatch.setattr(plotting, "PICTURE_MAX_CELLS", 31)
    assert plotting.too_large(mesh)
    assert plotting.plot_cell_field(mesh, None, np.zeros(n), tmp_path / "a.png", "v") is None
    assert not (tmp_path / "a.png").exists()
    monkeypatch.setattr(plotting, "PICTURE_MAX_CELLS", 32)
    assert plotting.plot_cell_field(mesh, None, np.zeros(n), tmp_path / "a.png", "v") is not None


@pytest.mark.mpi
def test_plot_bar_and_obstacles(tmp_path):
    """A 1D bar as matplotlib line plots, with its obstacle; 2D and 3D pictures with obstacles."""
    comm = MPI.COMM_WORLD
    mesh, _, _ = meshes.create_interval(comm, 20, 5.0, 15.0)
    values, centroids = dg0_rows(mesh)
    folder = shared_path(tmp_path)
    result = plotting.plot_bar(mesh, 0.1 * centroids, values, folder / "bar.png", 1.5, [([0.0], [1.0])])
    assert result == str(folder / "bar.png")
    comm.barrier()
    assert png_size(folder / "bar.png") == (960, 840)
    mesh2, _, _ = meshes.create_rectangle(comm, [0, 0.1], [1, 0.6], [4, 2])
    values2, _ = dg0_rows(mesh2)
    plotting.plot_cell_field(mesh2, None, values2, folder / "plate.png", "x", obstacles=[([0, 0], [0, 1])])
    comm.barrier()
    assert png_size(folder / "plate.png") == (1200, 900)
    with pytest.raises(ValueError, match="obstacle 0: point and normal need 2 finite numbers"):
        plotting.plot_cell_field(mesh2, None, values2, folder / "x.png", "x", obstacles=[([0], [1])])
    with pytest.raises(ValueError, match="plot_bar draws 1D meshes"):
        plotting.plot_bar(mesh2, None, values2, folder / "x.png", 0.0)


@pytest.mark.skip_in_parallel
def test_animate_bar_draws_the_bar_in_the_layout_of_plot_bar(tmp_path):
    """A 1D animation has plot_bar's layout per frame: a thick bar that moves with its
    displacement next to its obstacle, and the displacement and stress curves; 800 x 640."""
    import imageio

    from dolfinx_dem import io

    mesh, _, _ = meshes.create_interval(MPI.COMM_SELF, 20, 5.0, 15.0)
    x, _ = dg0_rows(mesh)
    u = dolfinx.fem.Function(_compat.create_vector_space(mesh, "DG", 0))
    s = dolfinx.fem.Function(_compat.create_scalar_space(mesh, "DG", 0))
    with io.SolutionWriter(MPI.COMM_SELF, tmp_path, mesh) as writer:
        for t, shift in ((0.0, -1.0), (1.0, -4.0)):
            u.x.array[:] = shift - 0.1 * (x - 5.0)
            s.x.array[:] = -90.0 * t * (15.0 - x) / 10.0
            writer.write(t, {"displacement": u, "stress_xx": s})
    assert plotting.animate_bar(tmp_path / "solution.xdmf", tmp_path / "bar.gif", [([0.0], [1.0])]) == 2
    frames = np.asarray(imageio.mimread(tmp_path / "bar.gif"))[..., :3].astype(int)
    assert frames.shape[:3] == (2, 640, 800)

    def near(colour):  # pixels of a matplotlib colour (the GIF palette rounds it)
        return np.abs(frames - np.array(colour)).sum(axis=-1) < 30

    bar, stress = near((31, 119, 180)), near((214, 39, 40))
    assert bar[:, :120].sum(axis=(1, 2)).min() > 2000  # the bar, ~10 pixels thick, in the top axes
    assert stress[1].sum() > 500
    left_end = [np.flatnonzero(bar[k, :120].any(axis=0)).min() for k in range(2)]
    assert left_end[1] < left_end[0] - 50  # moved 3 m towards the obstacle (about 120 pixels)


@pytest.mark.skip_in_parallel
def test_every_animation_frame_shows_the_displacement_written_at_its_time(tmp_path):
    """The frames of ``animate_solution`` (``solution_frames``): at every output time the points are
    the mesh's plus scale times the cell displacements of solution.xdmf at that time (averaged
    around each point), read by a reader of their own. Before, each frame moved the reader's points
    in place, adding its displacement to all the previous frames' (two-disks: the discs overlapped
    at t = 0.12 s, frames empty or zoomed)."""
    import pyvista

    from dolfinx_dem import scenes, simulation

    scene = scenes.load("two-disks", {"mesh.h": 0.04, "time.end": 0.2, "output.every": 20})
    simulation.run(scenes.validate(scene), tmp_path / "run", quiet=True)
    xdmf, scale = tmp_path / "run" / "solution.xdmf", 10.0
    frames = list(plotting.solution_frames(xdmf, "von_mises", scale))
    assert len(frames) >= 5
    moved = 0.0
    for t, _, grid in frames:
        reader = pyvista.get_reader(str(xdmf))
        reader.set_active_time_value(t)
        blocks = reader.read()
        reference = blocks["von_mises"].copy(deep=True)
        reference.cell_data["u"] = blocks["displacement"].cell_data["displacement"]
        u = reference.cell_data_to_point_data().point_data["u"]
        expected = reference.points + scale * u
        assert np.abs(grid.points - expected).max() < 1e-12
        moved = max(moved, np.abs(scale * u).max())
    assert moved > 0.1  # the discs move (0.3 m/s for 0.2 s, times 10)


@pytest.mark.skip_in_parallel
def test_final_pictures_say_the_scene_the_time_and_the_scale(tmp_path):
    """final.png's caption (``picture_caption``): drawn in the upper left corner, where the picture
    without it is blank (before: no time, scene or scale; the cantilever is drawn x10)."""
    import imageio.v3 as iio

    assert plotting.picture_caption("cantilever", 4.0, 10.0) == "cantilever: t = 4 s, displacement x10"
    static = plotting.picture_caption("hertz", 0.0, 1.0, static=True)
    assert static == "hertz: static, load time t = 0 s, displacement x1"
    mesh, _, _ = meshes.create_rectangle(MPI.COMM_SELF, [0, 0], [2, 1], [6, 3], "crossed")
    values, centroids = dg0_rows(mesh)
    images = []
    for caption in (None, "cantilever: t = 4 s, displacement x10"):
        path = tmp_path / f"{caption is None}.png"
        plotting.plot_cell_field(mesh, 0.01 * centroids, values, path, "x", caption=caption)
        images.append(iio.imread(path)[:60, :500].astype(float))
    assert np.ptp(images[0]) == 0.0  # white
    assert np.ptp(images[1]) > 100.0  # dark text on white


@pytest.mark.skip_in_parallel
def test_the_animation_view_holds_the_body_of_every_frame(tmp_path):
    """A body translated by twice its width: every frame draws all of it (the camera was set
    on the first frame, and the body left the view). Written by a helper on branch pictures."""
    import imageio

    from dolfinx_dem import io

    mesh, _, _ = meshes.create_rectangle(MPI.COMM_SELF, [0, 0], [1, 0.5], [4, 2])
    values, centroids = dg0_rows(mesh)
    u = dolfinx.fem.Function(_compat.create_vector_space(mesh, "DG", 0))
    s = dolfinx.fem.Function(_compat.create_scalar_space(mesh, "DG", 0))
    s.x.array[: values.size] = 1.0
    with io.SolutionWriter(MPI.COMM_SELF, tmp_path, mesh) as writer:
        for k in range(3):
            u.x.array[: centroids.size] = np.tile([1.0 * k, 0.0], len(values))
            writer.write(float(k), {"displacement": u, "von_mises": s})
    assert plotting.animate_solution(tmp_path / "solution.xdmf", tmp_path / "a.gif", "von_mises", "x") == 3
    gif = np.asarray(imageio.mimread(tmp_path / "a.gif"))[..., :3].astype(int)
    body = (np.abs(gif[:, :, :600] - 255).sum(axis=-1) > 60).sum(axis=(1, 2))  # non-white pixels, left column
    assert body.min() > 0.95 * body.max(), f"the body's pixels in each frame: {body}"
