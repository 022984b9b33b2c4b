"""Bodies with prescribed motion (issue 15): a rigid disc pushed into a clamped block. The work
it does balances the pseudo-energy exactly through contact events (memm.py), its dofs follow
U(t), its reaction is the energy's derivative with respect to U, any process count agrees, and
bad input is refused before a run."""

import types

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import dynamics, io, meshes, model, scenes, statics
from dolfinx_dem.conditions import DirichletBC, PrescribedBody, Traction
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.problem import DEMProblem


def indentation(**prescribed) -> dict:
    """A coarse indentation scene: a rigid disc (radius 0.2) 5e-4 above a clamped block, pushed
    down by ``prescribed`` (default 1 m/s)."""
    return {
        "name": "indentation-test", "method": "dem-B",
        "mesh": {"type": "discs", "discs": [[0.0, 0.2005, 0.2]], "rectangles": [[-0.5, -0.5, 0.5, 0.0]], "h": 0.06},
        "material": {"E": 1e4, "nu": 0.3, "rho": 1.0, "plane": "strain"},
        "dirichlet": [{"boundary": "y <= -0.5", "name": "base"}],
        "prescribed": [{"tag": 1, "name": "disc"} | (prescribed or {"velocity": [0.0, -1.0]})],
        "contact": {"boundary": ["(y >= -1e-9) & (y <= 0.2005)"]},
        "time": {"end": 0.008, "cfl": 0.5},
    }


def run(scene, comm=MPI.COMM_WORLD, check=None):
    """Steps a DynamicRun of ``scene`` (no outputs); returns (run, per-step balances, rows of
    prescribed_values), calling ``check(run)`` after every step."""
    r = dynamics.DynamicRun(scenes.validate(scene), comm, quiet=True)
    balances, values = [r.first.balance], [model.prescribed_values(r.problem, r.stepper.u, 0.0)]
    scale = r.first.mechanical
    for _ in range(r.n_steps):
        diag = r.stepper.step()
        balances.append(diag.balance)
        values.append(model.prescribed_values(r.problem, r.stepper.u, diag.t))
        scale = max(scale, diag.mechanical)
        if check:
            check(r)
    return r, np.array(balances) / scale, np.array(values)


def disc_values(r, name="u"):
    """The values of ``name`` (a stepper vector) on the disc's owned cells, (n, 2)."""
    cells = (
        r.dem.geometry.cell_bodies[: r.dem.n_owned] == 1
    )  # the disc is body 1 (the block's first barycentre is left of it)
    return getattr(r.stepper, name).array_r.reshape(-1, 2)[cells]


@pytest.mark.parametrize(
    "prescribed", [{"velocity": [0.0, -1.0]}, {"displacement": ["0.02 * sin(100 * t)", "-0.5 * t - 30 * t**2"]}]
)
def test_the_work_of_a_prescribed_body_balances_the_energy_through_contact(prescribed):
    """E^n - W^n is constant to rounding while the disc indents the block (events split steps);
    the disc's dofs follow U(t) exactly; the run is declared not conservative."""
    U = (
        (lambda t: np.array([0.0, -t]))
        if "velocity" in prescribed
        else (lambda t: np.array([0.02 * np.sin(100 * t), -0.5 * t - 30 * t**2]))
    )
    follow = []
    r, balances, values = run(
        indentation(**prescribed), check=lambda r: follow.append(np.abs(disc_values(r) - U(r.stepper.t)).max(initial=0))
    )
    assert not r.conservative and r.columns[6:8] == ("work", "balance")
    assert np.abs(balances - balances[0]).max() < 1e-12  # measured 2e-15 (velocity), 5e-15 (displacement)
    assert r.dem.comm.allreduce(r.stepper.max_step_evaluations, op=MPI.MAX) >= 3  # contact events
    assert values[-1, 1] < -1.0  # the disc pushes the block down (reaction_disc_y, N/m)
    assert np.allclose(values[:, 2:], [U(k * r.dt) for k in range(len(values))], atol=1e-15, rtol=0)
    assert max(follow) < 1e-15
    block = r.stepper.u.array_r.reshape(-1, 2)[r.dem.geometry.cell_bodies[: r.dem.n_owned] == 0]
    assert r.dem.comm.allreduce(block.min(initial=0), op=MPI.MIN) < -1e-3  # the block is indented


def test_the_reaction_is_the_derivative_of_the_energy_with_respect_to_the_translation():
    """Central differences of the potential, moving the disc's dofs by +-delta, against the
    reaction_disc column in contact."""
    r, _, values = run(indentation() | {"time": {"end": 0.004, "cfl": 0.5}})
    dem, u, t = r.dem, r.stepper.u, r.stepper.t
    reaction = r.problem.prescribed_values(u, t)[0, 0]
    cells = dem.geometry.cell_bodies[: dem.n_owned] == 1
    delta, fd = 1e-7, np.zeros(2)
    for k in range(2):
        energy = []
        for sign in (1, -1):
            w = u.copy()
            w.array.reshape(-1, 2)[cells, k] += sign * delta
            energy.append(r.problem.energies(w, t)["potential"])
        fd[k] = (energy[0] - energy[1]) / (2 * delta)
    assert reaction[1] < -1.0
    assert np.abs(fd - reaction).max() < 1e-8 * np.abs(reaction).max()  # measured 4e-11
    assert np.allclose(values[-1, :2], reaction, rtol=0, atol=0)


def test_a_prescribed_body_is_rigid_at_its_contact_facets():
    """In contact, the disc's facets keep their imposed translation (no contact correction) and
    the block's facets take the whole correction: the corrections of a fully overlapping pair
    close its gap, and the block's facets carry them."""
    r, _, _ = run(indentation())
    pc = r.pairs
    up = pc.patch_values(r.stepper.u)
    delta = pc.outputs.facet_corrections(up)
    on_disc = pc.facets_all.body[: len(pc.facets)] == 1
    assert r.dem.comm.allreduce(float(np.abs(delta[on_disc]).max(initial=0)), op=MPI.MAX) == 0.0
    assert r.dem.comm.allreduce(float(np.abs(delta[~on_disc]).max(initial=0)), op=MPI.MAX) > 1e-4
    L = pc.listed
    assert np.all(np.where(pc.facets_all.body[L.i] == 1, np.abs(L.e_i).max(axis=1), np.abs(L.e_j).max(axis=1)) == 0)
    assert np.allclose(
        np.where(pc.facets_all.body[L.i] == 1, L.e_j.T, L.e_i.T).T,
        np.where(pc.facets_all.body[L.i] == 1, -1, 1)[:, None] * L.n,
        rtol=0,
        atol=0,
    )


def test_a_free_block_pushed_by_a_prescribed_disc_balances_its_energy():
    """No Dirichlet condition: the block is a free body (its mean translation removed from its
    rows), the disc is not; the balance is exact, and the pushed block gains momentum, so the
    summary reports no momentum_rel_change."""
    r, balances, _ = run(indentation() | {"dirichlet": [], "time": {"end": 0.004, "cfl": 0.5}})
    assert np.abs(balances - balances[0]).max() < 1e-12
    assert r.stepper.diagnostics().momentum[1] < 0.0 and not r.pair_stats.free


def test_the_indentation_scene_writes_a_force_indentation_curve(tmp_path):
    """The built-in scene, coarse and short: its series has the work, balance and prescribed
    columns, the disc's displacement is U(t) and the summary says it is not conservative."""
    from dolfinx_dem import simulation

    scene = scenes.load(
        "indentation", {"mesh.h": 0.06, "mesh.discs": [[0.0, 0.2005, 0.2]], "time.end": 0.006, "output.every": 1000}
    )
    summary = simulation.run(scene, tmp_path / "out", MPI.COMM_SELF, quiet=True)
    assert not summary["conservative"] and summary["pseudo_energy_rel_drift"] < 1e-12
    assert "momentum_rel_change" not in summary
    series = np.genfromtxt(tmp_path / "out" / "series.csv", delimiter=",", names=True)
    assert np.allclose(series["prescribed_disc_displacement_y"], -0.5 * series["t"], rtol=0, atol=1e-15)
    assert series["reaction_disc_y"][-1] < 0 and series["reaction_disc_y"][0] == 0
    assert {"work", "balance", "reaction_base_y", "reaction_disc_x"} <= set(series.dtype.names)
    assert (tmp_path / "out" / "final.png").stat().st_size > 1000


def test_unnamed_reactions_are_numbered_after_the_dirichlet_conditions():
    scene = indentation()
    scene["dirichlet"][0].pop("name")
    scene["prescribed"][0].pop("name")
    problem = model.build(scenes.validate(scene))
    dem = problem.dem
    assert model.reaction_columns(dem) + model.prescribed_columns(dem) == (
        "reaction_0_x",
        "reaction_0_y",
        "reaction_1_x",
        "reaction_1_y",
        "prescribed_1_displacement_x",
        "prescribed_1_displacement_y",
    )


@pytest.mark.mpi
def test_processes_agree_on_the_prescribed_columns():
    """The balances and the prescribed body's columns of a run on all processes against the
    same run on one (each process runs it alone)."""
    scene = indentation(displacement=["0.0", "-t"]) | {"time": {"end": 0.004, "cfl": 0.5}}
    _, balances, values = run(scene)
    assert np.abs(balances - balances[0]).max() < 1e-12
    if MPI.COMM_WORLD.size > 1:
        _, serial_balances, serial_values = run(scene, MPI.COMM_SELF)
        assert np.allclose(values, serial_values, rtol=1e-9, atol=1e-12 * np.abs(serial_values).max())
        assert np.allclose(balances, serial_balances, rtol=0, atol=1e-12)


def _rectangle_tags(comm, tag_of_cell):
    """A unit square mesh with duck-typed cell tags ``tag_of_cell(local cell indices)``."""
    mesh, _, facet_tags = meshes.create_rectangle(comm, [0.0, 0.0], [1.0, 1.0], [4, 4])
    cells = np.arange(mesh.topology.index_map(2).size_local, dtype=np.int32)
    return mesh, types.SimpleNamespace(indices=cells, values=tag_of_cell(cells)), facet_tags


MATERIAL = ElasticMaterial(E=1e4, nu=0.3, rho=1.0)


def pair_force(problem, u):
    """contact_force_0_1 (the force the disc, body 1, exerts on the block, body 0), (2,)."""
    values = dict(zip(model.contact_columns(problem), model.contact_values(problem, u)))
    return np.array([values["contact_force_0_1_x"], values["contact_force_0_1_y"]])


def test_the_reaction_under_gravity_is_the_force_on_the_other_bodies():
    """With gravity the disc's reaction is the force it exerts on the block, the contact force
    between them: 0 before contact (before: the disc's weight, 1.26 N/m, at t = 0 with nothing
    touching), the pair force to rounding after; in statics too."""
    scene = indentation() | {"time": {"end": 0.004, "cfl": 0.5}, "loads": {"gravity": [0.0, -10.0]}}
    r, _, values = run(scene)
    assert np.abs(values[0, :2]).max() == 0.0
    force = pair_force(r.problem, r.stepper.u)
    assert force[1] < -1.0  # measured: -9.07
    assert np.abs(values[-1, :2] - force).max() < 1e-10 * abs(force[1])
    static = {k: v for k, v in scene.items() if k != "time"} | {"statics": {"time": 0.0105}}
    problem = model.build(scenes.validate(static), MPI.COMM_WORLD)
    result = statics.minimise_energy(problem, t=0.0105)
    disc = problem.prescribed_values(result.u, 0.0105, result.force)[0, 0]
    force = pair_force(problem, result.u)
    assert force[1] < -10.0  # measured: -42.14 (before, the reaction: -40.90)
    assert np.abs(disc - force).max() < 1e-8 * abs(force[1])
    # The block's equilibrium: the base and the disc hold its weight (rho g times its area, 0.5 m^2).
    base = problem.dem.reactions(result.u, 0.0105)[0]
    assert abs(base[1] + disc[1] - 5.0) < 1e-8 * abs(base[1])



@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"prescribed": [{"velocity": [0.0, -1.0]}]}, r"'prescribed\[0\].tag' is missing"),
        ({"prescribed": [{"tag": 1}]}, "exactly one of 'velocity' and 'displacement'"),
        ({"prescribed": [{"tag": 1, "velocity": [0.0, -1.0], "displacement": ["0", "-t"]}]}, "exactly one of"),
        ({"prescribed": [{"tag": 1, "velocity": [0.0, -1.0, 0.0]}]}, r"'prescribed\[0\].velocity' must be a list of 2"),
        ({"prescribed": [{"tag": 1, "displacement": ["-t"]}]}, r"'prescribed\[0\].displacement' must be a list of 2"),
        ({"prescribed": [{"tag": 1, "displacement": ["0", "-x * t"]}]}, r"unknown names \['x'\]"),
        ({"prescribed": [{"tag": 1, "velocity": [0.0, -1.0], "name": "base"}]}, "must be unique together"),
        ({"prescribed": [{"tag": 1, "velocity": [0.0, -1.0], "name": "a-b"}]}, "letters, digits and underscores"),
        ({"prescribed": [{"tag": 7, "velocity": [0.0, -1.0]}]}, "selects no cell"),
        ({"dirichlet": [{"boundary": "y >= 0.2"}]}, "prescribed body carries a Dirichlet condition"),
        ({"tractions": [{"boundary": "y >= 0.2", "value": [0.0, 1.0]}]}, "prescribed body carries a traction"),
        (
            {
                "mesh": {"type": "discs", "rectangles": [[0, 0, 1, 1], [1, 1, 2, 2]], "h": 0.5},
                "contact": {"boundary": ["all"]},
                "dirichlet": [],
            },
            "not a whole body: bodies share the vertex",
        ),
    ],
)
def test_bad_prescribed_scenes_are_rejected_before_the_run(overrides, message):
    scene = indentation() | overrides
    with pytest.raises(ValueError, match=message):
        dynamics.DynamicRun(scenes.validate(scene), quiet=True)


def test_bad_prescribed_bodies_are_rejected_by_the_discretisation():
    comm = MPI.COMM_WORLD
    mesh, tags, _ = _rectangle_tags(comm, lambda c: np.where(c % 2, 1, 2))
    with pytest.raises(ValueError, match="not a whole body: it shares facets"):
        DEMDiscretisation(mesh, MATERIAL, "B", cell_tags=tags, prescribed=[PrescribedBody(1, velocity=[0.0, 1.0])])
    mesh, tags, facet_tags = _rectangle_tags(comm, lambda c: np.ones_like(c))
    for body, message in [
        (PrescribedBody(1), "exactly one of velocity and displacement"),
        (PrescribedBody(1, [0.0, 1.0], lambda t: [0.0, t]), "exactly one of"),
        (PrescribedBody(1, velocity=[1.0]), "velocity must have 2 components"),
    ]:
        with pytest.raises(ValueError, match=message):
            DEMDiscretisation(mesh, MATERIAL, "B", cell_tags=tags, prescribed=[body])
    with pytest.raises(ValueError, match="prescribed body 1 .cell tag 1. overlaps another prescribed body"):
        DEMDiscretisation(mesh, MATERIAL, "B", cell_tags=tags, prescribed=[PrescribedBody(1, velocity=[0.0, 1.0])] * 2)
    with pytest.raises(ValueError, match="cell_tags are needed"):
        DEMDiscretisation(mesh, MATERIAL, "B", prescribed=[PrescribedBody(1, velocity=[0.0, 1.0])])
    top = facet_tags.find(meshes.YMAX)
    with pytest.raises(ValueError, match="carries a Dirichlet condition"):
        DEMDiscretisation(
            mesh,
            MATERIAL,
            "B",
            [DirichletBC(top, [0.0, 0.0])],
            cell_tags=tags,
            prescribed=[PrescribedBody(1, velocity=[0.0, 1.0])],
        )
    with pytest.raises(ValueError, match="carries a traction"):
        DEMDiscretisation(
            mesh,
            MATERIAL,
            "B",
            tractions=[Traction(top, [0.0, 1.0])],
            cell_tags=tags,
            prescribed=[PrescribedBody(1, velocity=[0.0, 1.0])],
        )
    dem = DEMDiscretisation(mesh, MATERIAL, "B", cell_tags=tags, prescribed=[PrescribedBody(1, velocity=[0.0, 1.0])])
    with pytest.raises(ValueError, match="the load time t must be finite"):
        statics.minimise_energy(DEMProblem(dem), t=np.nan)
    box, _, _ = meshes.create_box(comm, [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1, 1, 1])
    cells = np.arange(box.topology.index_map(3).size_local, dtype=np.int32)
    with pytest.raises(ValueError, match="implemented in 2D, not 3D"):
        DEMDiscretisation(
            box,
            MATERIAL,
            "B",
            cell_tags=types.SimpleNamespace(indices=cells, values=cells * 0 + 1),
            prescribed=[PrescribedBody(1, velocity=[0.0, 0.0, 1.0])],
        )


def static_indentation(t: float) -> dict:
    """``indentation()`` as a static scene at the load time t (the disc at U(t) = (0, -t))."""
    return {k: v for k, v in indentation().items() if k != "time"} | {"statics": {"time": t}}


def solve_static(t: float, comm=MPI.COMM_WORLD):
    """(problem, result) of minimise_energy on ``static_indentation(t)``."""
    problem = model.build(scenes.validate(static_indentation(t)), comm)
    return problem, statics.minimise_energy(problem, t=t)


@pytest.mark.mpi
def test_statics_holds_the_prescribed_disc_and_balances_its_reaction():
    """The disc sits at U(t), the block is in equilibrium between the disc and the base (their
    reactions cancel), any process count agrees with one process, and the reaction is the
    derivative of the minimum energy with respect to the disc's translation (envelope theorem:
    dV*/dt = dV/dU . dU/dt = -reaction_y)."""
    t = 0.0105  # indentation 0.01
    problem, result = solve_static(t)
    assert result.gradient_reduction < 1e-10
    disc, base = problem.prescribed_values(result.u, t, result.force)[0], problem.dem.reactions(result.u, t)[0]
    assert np.allclose(disc[1], [0.0, -t], rtol=0, atol=1e-15)
    assert disc[0][1] < 0 and np.abs(disc[0] + base).max() < 1e-8 * abs(base[1])
    if MPI.COMM_WORLD.size > 1:
        serial_problem, serial = solve_static(t, MPI.COMM_SELF)
        assert np.allclose(disc, serial_problem.prescribed_values(serial.u, t, serial.force)[0], rtol=1e-8, atol=0)
        assert abs(result.energy - serial.energy) < 1e-10 * abs(serial.energy)
    eps = 1e-5
    energies = [solve_static(t + s)[1].energy for s in (-eps, eps)]
    assert abs((energies[1] - energies[0]) / (2 * eps) + disc[0][1]) < 1e-5 * abs(disc[0][1])


def test_a_static_scene_with_a_prescribed_disc_reports_its_reaction(tmp_path):
    """StaticRun writes the prescribed columns at the load time and the disc's reaction, minus the
    base's, in the summary; a load time that is not a number is refused."""
    from dolfinx_dem.static_simulation import StaticRun

    summary = StaticRun(scenes.validate(static_indentation(0.0105)), MPI.COMM_SELF).run(
        io.OutputDirectory(tmp_path / "out", MPI.COMM_SELF)
    )
    reactions = summary["reactions"]
    assert summary["time"] == 0.0105 and reactions["reaction_disc_y"] < 0
    assert abs(reactions["reaction_disc_y"] + reactions["reaction_base_y"]) < 1e-8 * reactions["reaction_base_y"]
    series = np.genfromtxt(tmp_path / "out" / "series.csv", delimiter=",", names=True)
    assert series["t"] == 0.0105 and np.isclose(series["prescribed_disc_displacement_y"], -0.0105, rtol=1e-14, atol=0)
    with pytest.raises(scenes.SceneError, match="'statics.time' must be a finite number"):
        scenes.validate(static_indentation(0.0) | {"statics": {"time": "1"}})


def test_friction_on_a_prescribed_body_is_refused():
    """Its cells have no mass for the friction law to stop: friction there is an error, not
    silently none."""
    from dolfinx_dem.contact import HalfSpace, RigidContact

    mesh, tags, facet_tags = _rectangle_tags(MPI.COMM_WORLD, lambda c: np.ones_like(c))
    dem = DEMDiscretisation(mesh, MATERIAL, "A", cell_tags=tags, prescribed=[PrescribedBody(1, velocity=[0.0, -1.0])])
    bottom = facet_tags.find(meshes.YMIN)
    assert RigidContact(dem, [HalfSpace([0.0, 0.0], [0.0, 1.0], bottom)]).friction is None
    with pytest.raises(ValueError, match="friction on a prescribed body's facets is not implemented"):
        RigidContact(dem, [HalfSpace([0.0, 0.0], [0.0, 1.0], bottom, friction=0.3)])
