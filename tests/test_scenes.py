"""Scene inputs that could mislead: expressions in t without ``time_dependent``, expressions
that are not finite, boundary names a mesh does not define, relative mesh paths, and time steps
the scene would reject."""

import json
import pathlib
import re

import gmsh
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import cli, dynamics, scenes, simulation
from dolfinx_dem.errors import InstabilityError


def test_a_dirichlet_expression_in_t_needs_time_dependent():
    """Before: the value was evaluated once, at t = 0, without a word."""
    moving = [{"boundary": "left", "value": ["0.0", "0.01 * sin(t)"]}]
    with pytest.raises(scenes.SceneError, match=r"'dirichlet\[0\]\.value\[1\]' \('0.01 \* sin\(t\)'\) uses t, "
                                                r"but 'dirichlet\[0\]\.time_dependent' is not true"):
        scenes.load("cantilever", {"dirichlet": moving})
    scene = scenes.load("cantilever", {"dirichlet": [moving[0] | {"time_dependent": True}]})
    assert scene["dirichlet"][0]["time_dependent"] is True


@pytest.mark.parametrize("overrides, message, during_the_run", [
    ({"initial.velocity": ["0 * x / 0"]},
     r"scene key 'initial\.velocity\[0\]' \('0 \* x / 0'\) is not finite at t = 0: nan", False),
    ({"dirichlet": [{"boundary": "left", "value": ["1e-3 * sqrt(0.1 - t)"], "time_dependent": True}]},
     r"scene key 'dirichlet\[0\]\.value\[0\]' \('1e-3 \* sqrt\(0\.1 - t\)'\) is not finite at t = 0\.10", True),
])
def test_expressions_that_are_not_finite_name_the_key_and_the_time(overrides, message, during_the_run, tmp_path):
    """Before: the run went on with NaN and the stability monitor said "energies are no longer
    finite ... Reduce the time step", and summary.json held a bare NaN. An initial field is
    checked before the output folder is made; a Dirichlet value at t > 0 only during the run."""
    scene = scenes.load("bar-wave", {"time.end": 0.2, **overrides})
    with pytest.raises(scenes.SceneError, match=message):
        simulation.run(scene, tmp_path / "out", MPI.COMM_SELF, quiet=True)
    assert (tmp_path / "out").exists() == during_the_run
    if during_the_run:
        assert "Reduce the time step" not in (tmp_path / "out" / "error.txt").read_text()


def test_a_python_dirichlet_value_that_is_not_finite_is_an_error():
    from dolfinx_dem import meshes
    from dolfinx_dem.conditions import DirichletBC
    from dolfinx_dem.discretisation import DEMDiscretisation
    from dolfinx_dem.material import ElasticMaterial

    mesh, _, tags = meshes.create_interval(MPI.COMM_WORLD, 10, 0.0, 1.0)
    with pytest.raises(ValueError, match=r"Dirichlet value at t = 0 is not finite: \[nan\]"):
        DEMDiscretisation(mesh, ElasticMaterial(E=1.0, nu=0.0, rho=1.0), "A",
                          [DirichletBC(tags.find(meshes.XMIN), lambda x, t: np.full_like(x, np.nan))])


def write_plate_msh(path: pathlib.Path):
    """A 1 x 1 plate with a hole of radius 0.2 (gmsh, rank 0): physical surface 7, the outer
    boundary tag 1 named "outer" and the hole tag 4 named "hole" (the issue's plate, where
    boundary = "top" silently selected the hole)."""
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        plate = gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
        hole = gmsh.model.occ.addDisk(0.5, 0.5, 0, 0.2, 0.2)
        body, _ = gmsh.model.occ.cut([(2, plate)], [(2, hole)])
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [body[0][1]], 7)
        curves = [c for _, c in gmsh.model.getBoundary(body, oriented=False)]
        on_hole = [c for c in curves if np.linalg.norm(np.array(gmsh.model.occ.getCenterOfMass(1, c))[:2] - 0.5) < 0.1]
        outer = [c for c in curves if c not in on_hole]
        gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, outer, 1), "outer")
        gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, on_hole, 4), "hole")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.1)
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


@pytest.mark.mpi
def test_file_meshes_take_their_physical_names_not_side_names(tempdir):
    """Side names belong to the generated interval, rectangle and box meshes; a gmsh file's
    boundaries are named by its physical-group names. Before: "top" read as tag 4, the hole."""
    path = pathlib.Path(tempdir) / "plate.msh"
    if MPI.COMM_WORLD.rank == 0:
        write_plate_msh(path)
    MPI.COMM_WORLD.barrier()
    base = scenes.load("cantilever", {"mesh": {"type": "file", "path": str(path)}, "probes": [],
                                      "loads": {}})
    with pytest.raises(scenes.SceneError, match=r"'dirichlet\[0\]\.boundary': unknown boundary 'top' .*"
                                                r"this mesh's names: hole, outer"):
        simulation.build(base | {"dirichlet": [{"boundary": "top"}]})
    dem = simulation.build(base | {"dirichlet": [{"boundary": "hole"}]}).dem
    x = dem.geometry.facet_centres[dem.reconstruction.dirichlet_facets]
    assert len(x) > 8 and np.abs(np.linalg.norm(x - 0.5, axis=1) - 0.2).max() < 0.01


def test_a_disc_has_no_side_names():
    """Before: "left" selected tag 1, the whole circle."""
    scene = scenes.load("cantilever", {"mesh": {"type": "disc", "centre": [0.0, 0.0], "radius": 1.0, "h": 0.5},
                                       "probes": []})
    with pytest.raises(scenes.SceneError, match="unknown boundary 'left' .*this mesh defines none"):
        simulation.build(scene)


@pytest.mark.skip_in_parallel
def test_a_missing_mesh_file_names_the_absolute_path_tried(tmp_path, monkeypatch, capsys):
    """``--set mesh.path=plate.msh`` is relative to the working directory; the error says
    which file it looked for."""
    monkeypatch.chdir(tmp_path)
    code = cli.main(["run", "cantilever", "--set", 'mesh={type="file", path="plate.msh"}',
                     "--out", str(tmp_path / "out"), "--quiet"])
    assert code == 2
    assert f"mesh file plate.msh does not exist (looked for {tmp_path / 'plate.msh'})" in capsys.readouterr().err


def test_dividing_time_steps():
    assert dynamics.dividing_time_step(1.0, 0.0005508) == 0.0005  # not 1/1816
    assert dynamics.dividing_time_step(8.0, 0.005001) == 0.005
    for end, at_most in ((0.35, 0.0005508), (7 / 6, 1e-3), (3.0, 7.0)):
        dt = dynamics.dividing_time_step(end, at_most)
        assert dt <= at_most
        scenes.validate({"mesh": {"type": "interval"}, "material": {"E": 1.0, "nu": 0.0, "rho": 1.0},
                         "time": {"end": end, "dt": dt}})


def test_the_suggested_time_step_is_one_the_scene_accepts(tmp_path):
    """bar-wave at dt = 0.0125 (the limit is 0.0100): the run suggests a step that divides
    time.end = 8, so the scene accepts it, and is no longer than MEMM's own suggestion (half the
    bound's stable step, 0.0049999..., printed 0.005; it was 0.005001 from the eigenvalue, which
    the scene rejected)."""
    scene = scenes.load("bar-wave", {"time": {"end": 8.0, "dt": 0.0125}})
    with pytest.raises(InstabilityError, match=r"Reduce the time step: set time\.dt = 0\.004 \(2000 steps") as error:
        simulation.run(scene, tmp_path / "out", MPI.COMM_SELF, quiet=True)
    assert error.value.suggested_dt == 0.004
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["suggested_dt"] == 0.004
    scenes.load("bar-wave", {"time": {"end": 8.0, "dt": error.value.suggested_dt}})
    memm = float(re.search(r"MEMM suggests at most ([0-9.e-]+),", str(error.value)).group(1))
    assert memm == 0.005 and error.value.suggested_dt <= memm


@pytest.mark.mpi
def test_dem_ab_puts_scheme_b_on_the_contact_candidates_only():
    """method dem-AB: the candidates of [contact] are scheme B facets, the other Neumann facets scheme A
    ones; the energy stays exact through the impact. Without candidates it is an error."""
    comm = MPI.COMM_WORLD
    scene = scenes.load("two-disks", {"method": "dem-AB", "mesh.h": 0.04, "time.end": 0.2})
    r = dynamics.DynamicRun(scenes.validate(scene), comm, quiet=True)
    dem, contact = r.dem, r.problem.contacts[0]
    rec = dem.reconstruction
    own = dem.geometry.facets_of_layers(0)
    neumann = np.intersect1d(rec.neumann_facets, own)
    candidate = np.isin(neumann, contact.facets)
    is_a = np.isin(neumann, rec.scheme_a_facets)
    assert comm.allreduce(int(candidate.sum())) > 10 and comm.allreduce(int((~candidate).sum())) > 10
    assert not is_a[candidate].any() and is_a[~candidate].all()
    first = r.stepper.diagnostics()
    scale, drift = first.mechanical, 0.0
    for _ in range(r.n_steps):
        diag = r.stepper.step()
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy))
    assert comm.allreduce(r.stepper.max_step_evaluations, op=MPI.MAX) > 1  # contact events split steps
    assert drift < 1e-13 * scale
    with pytest.raises(scenes.SceneError, match="'dem-AB' puts scheme B on the contact candidates"):
        scenes.validate(scenes.load("cantilever", {"method": "dem-AB"}))
