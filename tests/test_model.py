"""The model of a scene (model.py): what ``build`` refuses before a run touches its output folder,
the series columns of the contact models, and the probes."""

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import model, scenes, simulation


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"mesh.foo": 1}, "'mesh.foo' is unknown"),
        ({"material.nu": 0.5}, "Poisson ratio nu"),
        ({"material.E": -1.0}, "Young.s modulus E must be > 0"),
        ({"initial.velocity": ["foo * x"]}, "unknown names \\[.foo.\\]"),
        ({"probes": [{"name": "p"}]}, "probes\\[0\\].point. is missing"),
        ({"time": {"end": 1.0, "dt": 0.03}}, "must be a multiple"),
        ({"material.rho": 0.0}, "density rho must be > 0"),
        ({"time.dt": -0.1}, "'time.dt' must be > 0"),
        ({"method": "dem-C"}, "'method' must be a string"),
        ({"mesh.n": "many"}, "'mesh.n' must be a list"),
        ({"initial.velocity": ["sin(x"]}, "not a valid expression"),
    ],
)
def test_bad_scene_values_are_rejected(overrides, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        scene = scenes.load("bar-wave", overrides)
        simulation.run(scene, tmp_path / "bad", MPI.COMM_SELF, quiet=True)


@pytest.mark.parametrize("names, message", [
    (["tip", "tip"], "probe names must be unique"),
    (["kinetic"], "probe names \\['kinetic'\\] are series columns"),
    (["contact_pressure"], "probe names \\['contact_pressure'\\] are series columns"),
    (["contact_force_obstacle0_x"], "probe names \\['contact_force_obstacle0_x'\\] are series columns"),
])
def test_probe_names_that_clash_with_a_series_column_are_rejected(names, message, tmp_path):
    """Probe names are series columns: a clash with any other column (energies, contact) is an
    error before the output folder is made."""
    probes = [{"name": name, "point": [10.0], "component": 0} for name in names]
    scene = scenes.load("bar-impact", {"probes": probes})
    with pytest.raises(scenes.SceneError, match=message):
        simulation.run(scene, tmp_path / "bad", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "bad").exists()


def test_both_dt_and_cfl_or_an_unknown_boundary_are_rejected(tmp_path):
    with pytest.raises(scenes.SceneError, match="exactly one of 'time.dt' and 'time.cfl'"):
        scenes.load("bar-wave", {"time.dt": 0.01})
    scene = scenes.load("cantilever", {"dirichlet": [{"boundary": "nowhere"}]})
    with pytest.raises(scenes.SceneError, match="unknown boundary 'nowhere'"):
        simulation.run(scene, tmp_path / "b", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "b").exists()  # checked before the output folder is made


@pytest.mark.parametrize(
    "obstacle, message",
    [
        ({"point": [6.0], "normal": [1.0], "boundary": "left"}, "intersects the body at t = 0"),
        ({"point": [0.0], "normal": [1.0], "boundary": "left", "tolerance": -1.0}, "must be >= 0"),
        ({"point": [0.0], "normal": [1.0]}, "'obstacles\\[0\\].boundary' is missing"),
        ({"point": [0.0], "normal": [1.0], "boundary": "nowhere"}, "unknown boundary 'nowhere'"),
    ],
)
def test_bad_obstacles_are_rejected_before_the_run(obstacle, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        scene = scenes.load("bar-impact", {"obstacles": [obstacle]})
        simulation.run(scene, tmp_path / "bad", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "bad" / "series.csv").exists()


@pytest.mark.mpi
def test_a_probe_reads_an_affine_field_exactly():
    """A probe is the P1 reconstruction (eq. (10)) of the cell nearest to its point: exact for
    an affine displacement on interior cells (their facet values interpolate it exactly), on
    any number of processes."""
    problem = simulation.build(scenes.load("cantilever"), MPI.COMM_WORLD)
    dem = problem.dem
    A, b = np.array([[1e-3, 2e-3], [-3e-3, 5e-4]]), np.array([1e-4, -2e-4])
    u = dem.create_vector()
    u.array[:] = (dem.geometry.cell_centres[: dem.n_owned, :2] @ A.T + b).ravel()
    points = [[0.5, 0.05], [0.3141, 0.0427], [0.77, 0.061]]
    specs = [{"name": f"p{k}_{c}", "point": p, "component": c} for k, p in enumerate(points) for c in (0, 1)]
    values = model.Probes(problem, specs).values(u, 0.0)
    expected = [(A @ p + b)[c] for p in points for c in (0, 1)]
    assert np.abs(np.asarray(values) - expected).max() < 1e-15


def test_contact_columns_follow_the_contact_models_in_order():
    """The series columns of contact are each model's ``output_columns`` in the order of
    ``problem.contacts``, then the momentum (tracked by the contact between bodies), and
    ``contact_values`` gives one value per column but the momenta."""
    problem = simulation.build(scenes.load("ball-drop", {"mesh.h": 0.07}), MPI.COMM_SELF)
    rigid, pairs = problem.contacts
    columns = model.contact_columns(problem)
    assert columns == (*rigid.output_columns(), *pairs.output_columns(), "momentum_x", "momentum_y", "momentum_z")
    assert "contact_gap" in columns and "penetration" in columns
    values = model.contact_values(problem, problem.create_vector())
    assert len(values) == len(columns) - 3
    assert values[columns.index("penetration")] == 0.0  # nothing touches at rest


@pytest.mark.mpi
def test_a_probe_on_a_curved_boundary_is_accepted_and_one_beyond_it_is_not():
    """A point of the circle between two vertices of the polygonal disc lies a little outside the
    mesh (here 0.015 of its cell's height): before, "outside the mesh"; now its nearest cell reads it.
    0.002 m beyond the circle (0.26 of a height) it is still refused."""
    theta = 0.5 * (2 * np.pi / 63)  # about halfway between two boundary vertices
    for radius, accepted in ((0.1, True), (0.102, False)):
        point = [0.14 + radius * np.cos(theta), 2.27 + radius * np.sin(theta)]
        scene = scenes.load("two-disks", {"probes": [{"name": "edge", "point": point, "component": 0}]})
        problem = simulation.build(scene, MPI.COMM_WORLD)
        if accepted:
            assert model.Probes(problem, scene["probes"]).names == ["edge"]
        else:
            with pytest.raises(scenes.SceneError, match="'edge' .* is outside the mesh"):
                model.Probes(problem, scene["probes"])
