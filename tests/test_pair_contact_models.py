"""Contact between bodies beside rigid obstacles (the energy changes of both models on shared rows),
scheme A's correction directions where eq. (23)-(24) are not well posed, what a run reports, the
refusals of stale or bad input, and the contact-model protocol."""

import json

import numpy as np
import pytest
from helpers import cell_vector, gmsh_mesh
from mpi4py import MPI
from pair_scenes import SOFT, approach, two_blocks, two_discs

from dolfinx_dem import meshes, model
from dolfinx_dem.contact import PairContact, RigidContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem


@pytest.mark.mpi
def test_rigid_wall_and_contact_between_bodies_together():
    """The two discs collide while sinking onto a rigid floor: both contact models act in the
    same steps (``problem.contacts``) and the pseudo-energy stays exact."""
    from dolfinx_dem.contact import HalfSpace

    dem, facets = two_discs(h=0.03)
    floor = meshes.locate_boundary_facets(dem.mesh, lambda x: x[1] <= 2.27)
    problem = DEMProblem(
        dem, [RigidContact(dem, [HalfSpace([0.0, 2.165], [0.0, 1.0], floor)]), PairContact(dem, facets)]
    )
    assert len(problem.contacts) == 2
    dt = 0.2 * dem.stable_time_step()
    stepper = MEMM(problem, dt)
    v = cell_vector(dem, lambda x: approach(x) + [0.0, -0.1])
    first = stepper.initialise(dem.create_vector(), v)
    pair, wall = problem.find(PairContact), problem.find(RigidContact)
    columns = model.contact_columns(problem)
    assert columns == (
        "contact_gap",
        "contact_pressure",
        "contact_force_obstacle0_x",
        "contact_force_obstacle0_y",
        "contact_force",
        "penetration",
        "contact_force_0_1_x",
        "contact_force_0_1_y",
        "momentum_x",
        "momentum_y",
    )
    both, drift, F, free = 0, 0.0, dem.create_vector(), dem.create_vector()
    for _ in range(int(0.2 / dt)):
        diag = stepper.step()
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy) / first.mechanical)
        on_floor = dem.comm.allreduce(bool((wall.gaps(wall.patch_values(stepper.u)) < 0).any()), op=MPI.LOR)
        if on_floor and pair.outputs.touching(pair.patch_values(stepper.u)):
            both += 1
            # the pair forces cancel: the obstacle's force is the sum of all contact forces
            values = dict(zip(columns, model.contact_values(problem, stepper.u)))
            problem.force(stepper.u, diag.t, F)
            dem.force(stepper.u, diag.t, free)
            total = dem.comm.allreduce((F.array - free.array).reshape(-1, 2).sum(axis=0), op=MPI.SUM)
            floor_force = np.array([values["contact_force_obstacle0_x"], values["contact_force_obstacle0_y"]])
            assert floor_force[1] > 0.0 and values["contact_force_0_1_x"] < 0.0
            assert np.abs(floor_force - total).max() < 1e-12 * np.abs(floor_force).max()
    assert both
    assert drift < 1e-13


def blocks_on_a_floor(scheme="B"):
    """``two_blocks`` 0.01 above the rigid floor y = 0 (candidates: the bottom sides), contact
    between them on the facing sides: the bottom corner cells have a facet of each model."""
    from dolfinx_dem.contact import HalfSpace

    dem, facets = two_blocks(scheme=scheme, y0=0.01)
    bottoms = meshes.locate_boundary_facets(dem.mesh, lambda x: x[1] < 0.02)
    problem = DEMProblem(
        dem, [RigidContact(dem, [HalfSpace([0.0, 0.0], [0.0, 1.0], bottoms)]), PairContact(dem, facets)]
    )
    return problem


def _corrections_of_both_models(problem, u):
    """delta_a of the rigid and of the pair contact on all energy rows (serial)."""
    QF = problem.dem.rows.QF

    def rows(facets, delta):
        return QF[:, (facets[:, None] * 2 + np.arange(2)).ravel()] @ delta.ravel()

    r, p = problem.find(RigidContact), problem.find(PairContact)
    up = r.patch_values(u)
    return (
        rows(r.facets, -np.minimum(r.gaps(up), 0.0)[:, None] * r.directions),
        rows(p.facets, p.outputs.facet_corrections(p.patch_values(u))),
    )


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("scheme", ["A", "B"])
def test_rigid_and_pair_contact_on_shared_rows_is_the_sum_of_both_energy_changes(scheme):
    """Where a cell has a facet on the obstacle and a facet against another body, the two
    corrections touch the same energy rows. The model (docs/theory.md) is V = V_free + dV_rigid
    + dV_pair, each dV = a . delta + |delta|^2 / 2 as if the other were absent: the energy of the
    summed reconstruction minus the cross term delta_rigid . delta_pair. The force is its exact
    gradient (central differences on the shared cells' dofs)."""
    problem = blocks_on_a_floor(scheme)
    dem = problem.dem
    rng = np.random.default_rng(2)
    # The blocks pushed into each other and into the floor, offset vertically (facet ends apart,
    # off the kinks of the overlaps) and with a little strain.
    u = cell_vector(
        dem,
        lambda x: (
            np.where(x[:, :1] < 0.205, [[0.008, -0.012]], [[-0.008, -0.0135]]) + 1e-4 * rng.standard_normal(x.shape)
        ),
    )
    problem.find(PairContact).prepare(u)
    a = dem.rows.Q @ u.array
    d_rigid, d_pair = _corrections_of_both_models(problem, u)
    shared = (d_rigid != 0) & (d_pair != 0)
    assert shared.any()
    cross = float(d_rigid @ d_pair)
    combined = 0.5 * (a + d_rigid + d_pair) @ (a + d_rigid + d_pair)
    V = problem.energies(u, 0.0)["potential"]
    assert V == pytest.approx(combined - cross, rel=1e-12)
    assert abs(cross) > 1e-2 * V  # measured: 5.6e-4 J/m against V = 2.51e-2 J/m (2.2 %)
    # The force on the dofs of the cells both corrections act on is the exact gradient of V.
    cells = np.intersect1d(problem.find(RigidContact).cells, problem.find(PairContact).cells)
    assert len(cells) > 0
    F = dem.create_vector()
    problem.force(u, 0.0, F)
    h = 1e-7
    for k in (cells[:, None] * 2 + np.arange(2)).ravel():
        up, um = u.copy(), u.copy()
        up.array[k] += h
        um.array[k] -= h
        diff = (problem.energies(up, 0.0)["potential"] - problem.energies(um, 0.0)["potential"]) / (2 * h)
        assert abs(diff + F.array[k]) < 1e-6 * np.abs(F.array).max()
    assert np.abs(F.array[(cells[:, None] * 2 + np.arange(2)).ravel()]).max() > 0.1 * np.abs(F.array).max()


@pytest.mark.mpi
def test_blocks_pushed_together_on_a_floor_conserve_the_pseudo_energy():
    """Both models act on the bottom corner cells in the same steps; the pseudo-energy of
    V = V_free + dV_rigid + dV_pair is conserved to rounding and V stays positive."""
    problem = blocks_on_a_floor()
    dem = problem.dem
    rigid, pair = problem.find(RigidContact), problem.find(PairContact)
    dt = 0.3 * dem.stable_time_step()
    stepper = MEMM(problem, dt)
    v = cell_vector(dem, lambda x: np.where(x[:, :1] < 0.205, [[0.3, -0.3]], [[-0.3, -0.3]]))
    first = stepper.initialise(dem.create_vector(), v)
    drift, both, lowest = 0.0, 0, np.inf
    for _ in range(int(0.12 / dt)):
        diag = stepper.step()
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy) / first.mechanical)
        lowest = min(lowest, diag.elastic + diag.stabilisation)
        on_floor = rigid.cells[rigid.gaps(rigid.patch_values(stepper.u)) < 0]
        g, w = pair.outputs.pair_states(pair.patch_values(stepper.u))
        on = (g < 0) & (w > 0)
        facets = np.concatenate([pair.listed.i[on], pair.listed.j[on]])
        touching = pair.cells[facets[facets < len(pair.facets)]]  # local cells in a touching pair
        both += dem.comm.allreduce(len(np.intersect1d(on_floor, touching)) > 0, op=MPI.LOR)
    assert both > 5  # steps in which a cell has a facet of each model in contact (measured: 15 of 20)
    assert drift < 1e-13
    assert lowest > -1e-12 * first.mechanical


def test_contact_table_needs_a_dem_scene():
    """A [contact] table is valid in a static DEM scene (statics.py), not with fem-P2."""
    import tomllib

    from dolfinx_dem import scenes

    scene = tomllib.loads((scenes.BUILTIN / "two-disks.toml").read_text())
    static = {k: v for k, v in scene.items() if k not in ("time", "initial", "output")}
    static |= {"statics": {"fixed_mean": [0]}}
    assert "contact" in scenes.validate(static)
    with pytest.raises(scenes.SceneError, match="needs a DEM method"):
        scenes.validate(static | {"method": "fem-P2"})


def mesh_disc_over_block(gmsh, height: float) -> None:
    """Meshes (in the open gmsh model) a disc of radius 0.1 (facets 0.015, tag 1) whose lowest
    point is ``height`` above the block [-0.3, 0.3] x [-0.2, 0] (facets 0.05, tag 2)."""
    disc = gmsh.model.occ.addDisk(0.0, 0.1 + height, 0.0, 0.1, 0.1)
    block = gmsh.model.occ.addRectangle(-0.3, -0.2, 0.0, 0.6, 0.2)
    gmsh.model.occ.synchronize()
    for tag, (surface, h) in enumerate(((disc, 0.015), (block, 0.05)), start=1):
        gmsh.model.addPhysicalGroup(2, [surface], tag)
        gmsh.model.mesh.setSize(gmsh.model.getBoundary([(2, surface)], recursive=True), h)
    gmsh.model.mesh.generate(2)


def disc_over_block(height: float, comm=MPI.COMM_WORLD, skin: float | None = None):
    """Scheme A, nu = 0.3: the disc over the block of ``mesh_disc_over_block``. Pairs of a disc
    facet far round the disc and a block facet have cos^2 of the disc facet's angle to n below
    kappa = nu: eq. (23)-(24) are not well posed for them (D <= 0 for some). ``skin``: one Verlet
    skin for all facets (default per facet)."""
    mesh = gmsh_mesh(comm, lambda gmsh: mesh_disc_over_block(gmsh, height))
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=100.0, nu=0.3, rho=100.0), "A")
    facets = meshes.locate_boundary_facets(mesh, lambda x: (x[1] <= 0.1 + height) & (x[1] >= -1e-9))
    return DEMProblem(dem, [PairContact(dem, facets, skin=skin)])


def test_scheme_a_directions_where_eq_23_24_are_well_posed():
    """Eq. (23)-(24) are used for a pair exactly when both cells' normal compliances have their
    sign (cos^2 t > kappa = nu for both facets), with bounded directions that close the gap;
    the other pairs use the scheme B rule (e = +-n/2) and are counted. (A skin of the block's
    facet size lists pairs far round the disc: the per-facet default does not.)"""
    problem = disc_over_block(0.01, skin=0.1)
    c = problem.find(PairContact)
    L, F = c.listed, c.facets_all
    cos_i = np.einsum("pi,pi->p", L.n, F.normal[L.i])
    cos_j = np.einsum("pi,pi->p", L.n, F.normal[L.j])
    both_a = F.scheme_a[L.i] & F.scheme_a[L.j]
    posed = both_a & (np.minimum(cos_i**2, cos_j**2) > 0.3)
    rule_b = np.all(L.e_i == 0.5 * L.n, axis=1) & np.all(L.e_j == -0.5 * L.n, axis=1)
    assert np.array_equal(rule_b, ~posed)
    assert (both_a & ~posed).sum() == c.scheme_b_pairs > 0  # measured: 12 of 96 listed pairs
    ni, nj = np.einsum("pi,pi->p", L.n, L.e_i)[posed], np.einsum("pi,pi->p", L.n, L.e_j)[posed]
    assert np.abs(ni - nj - 1).max() < 1e-12
    assert ni.min() > 0 and ni.max() < 1 and nj.max() < 0 and nj.min() > -1
    assert np.linalg.norm(L.e_i[posed], axis=1).max() < 1 / np.sqrt(0.3)
    assert np.linalg.norm(L.e_j[posed], axis=1).max() < 1 / np.sqrt(0.3)


def test_scheme_a_contact_runs_through_pairs_without_a_compliant_solution():
    """The disc falls onto the block: list rebuilds meet pairs with D <= 0 (before: a
    RuntimeError at t = 0.247 s). They use the scheme B rule; the energy stays exact and the
    disc bounces."""
    problem = disc_over_block(0.12)
    dem = problem.dem
    c = problem.find(PairContact)
    assert c.num_pairs == 0 and c.scheme_b_pairs == 0
    dt = 0.3 * dem.stable_time_step()
    stepper = MEMM(problem, dt)
    first = stepper.initialise(
        dem.create_vector(), cell_vector(dem, lambda x: np.where(x[:, 1:] > 0.0, [[0.0, -0.5]], [[0.0, 0.0]]))
    )
    drift = 0.0
    for _ in range(int(0.6 / dt)):
        diag = stepper.step()
        drift = max(drift, abs(diag.pseudo_energy - first.pseudo_energy) / first.mechanical)
    assert c.scheme_b_pairs > 0  # measured: 12
    assert drift < 1e-13
    mass = dem.mass.array_r.reshape(-1, 2)[:, 1]
    disc = dem.geometry.cell_centres[: dem.n_owned, 1] > 0.0
    v = 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, 2)[:, 1]
    assert dem.comm.allreduce(float((mass * v)[disc].sum()), op=MPI.SUM) > 0.0  # moving up again


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_a_run_reports_the_pairs_that_use_the_scheme_b_rule(tmp_path, capsys):
    """summary.json (``contact_pairs_scheme_b_rule``) and the command line report them."""
    import gmsh

    from dolfinx_dem import cli

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        mesh_disc_over_block(gmsh, 0.02)
        gmsh.write(str(tmp_path / "disc_block.msh"))
    finally:
        gmsh.finalize()
    (tmp_path / "scene.toml").write_text(
        'method = "dem-A"\n[mesh]\ntype = "file"\npath = "disc_block.msh"\n'
        "[material]\nE = 100.0\nnu = 0.3\nrho = 100.0\n"
        '[contact]\nboundary = ["(y <= 0.22) & (y >= -1e-9)"]\n'
        '[initial]\nvelocity = ["0", "where(y > 0, -0.5, 0)"]\n[time]\nend = 0.4\ncfl = 0.3\n'
    )
    assert cli.main(["run", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "out")]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["contact_pairs_scheme_b_rule"] > 0 and summary["pseudo_energy_rel_drift"] < 1e-13
    assert (
        f"note: {summary['contact_pairs_scheme_b_rule']} pairs of scheme A facets used the scheme B"
        in capsys.readouterr().out
    )


def test_force_integral_refuses_patch_values_prepare_did_not_return():
    """The integral reads the flight ``prepare`` checked for this step: other patch values, or
    another dt, raise instead of being integrated over an unchecked flight."""
    dem, facets = two_discs(h=0.03)
    problem = DEMProblem(dem, [PairContact(dem, facets)])
    c = problem.find(PairContact)
    u = cell_vector(dem, lambda x: approach(x, 0.05))
    v = cell_vector(dem, approach)
    up, vp = c.prepare(u, v, 1e-3)
    out = dem.create_vector()
    for args in ((up.copy(), vp, 1e-3), (up, vp.copy(), 1e-3), (up, vp, 2e-3)):
        with pytest.raises(RuntimeError, match="needs the patch values that prepare"):
            c.force_integral(*args, out)
    c.force_integral(up, vp, 1e-3, out)


@pytest.mark.mpi
def test_a_step_without_a_touching_pair_anywhere_adds_nothing():
    """``prepare``'s one reduction tells every process whether a pair anywhere may touch during
    the step: if none does, ``force_integral`` adds exactly nothing (no kernel, no reverse
    scatter) on every process, and the outputs' penetration is 0 without its scatter; once the
    discs meet, every process integrates (also those whose own pairs do not touch: the reverse
    scatter is collective) and the force and the penetration are positive."""
    dem, facets = two_discs(h=0.03)
    problem = DEMProblem(dem, [PairContact(dem, facets)])
    c, dt = problem.find(PairContact), 1e-3
    v = cell_vector(dem, approach)
    for shift, touching in ((0.0, False), (0.04, True)):  # the gap is 0.02 m; 0.04 s at +-0.3 m/s close it
        u = cell_vector(dem, lambda x, shift=shift: approach(x) * shift)
        out = dem.create_vector()
        up, vp = c.prepare(u, v, dt)
        assert c._flight.quiet == (not touching)  # the same on every process
        evaluations = c.force_integral(up, vp, dt, out)
        assert dem.comm.allreduce(evaluations, op=MPI.MAX) > 0 if touching else evaluations == 0
        assert (out.norm() > 0) == touching
        closed = dem.comm.allreduce(c.outputs.closed_count(c.patch_values(u)), op=MPI.SUM)
        penetration = model.contact_values(problem, u)[1]
        assert (closed > 0) == touching and (penetration > 0) == touching


def test_a_step_longer_than_the_skin_is_an_error():
    """A facet that moves more than skin/2 in one step cannot be covered by any pair list."""
    dem, facets = two_discs(h=0.03)
    problem = DEMProblem(dem, [PairContact(dem, facets)])
    stepper = MEMM(problem, 0.1)  # 0.3 m/s x 0.1 s = 0.03 m > skin / 2 (facets of ~0.03 m)
    stepper.initialise(dem.create_vector(), cell_vector(dem, approach))
    with pytest.raises(RuntimeError, match="moves 3.000e-02 m in one step, more than half the Verlet skin"):
        stepper.step()


def test_both_contact_models_satisfy_the_contact_model_protocol():
    """RigidContact and PairContact offer every member of ``ContactModel`` with its parameters."""
    import inspect

    from dolfinx_dem.contact import ContactModel

    problem = blocks_on_a_floor()
    members = [m for m in vars(ContactModel) if not m.startswith("_") and callable(getattr(ContactModel, m))]
    assert {"checkpoint_state", "restore_state", "prepare", "force_integral", "add", "add_force"} <= set(members)
    for contact in problem.contacts:
        assert isinstance(contact, ContactModel)
        for name in members:
            expected = list(inspect.signature(getattr(ContactModel, name)).parameters)[1:]
            assert list(inspect.signature(getattr(contact, name)).parameters) == expected, (contact, name)


@pytest.mark.mpi
def test_a_traction_on_a_contact_facet_is_rejected():
    """A contact candidate facet carrying a traction has no defined reconstruction in the
    contact rule: refused on every process, before anything runs."""
    from dolfinx_dem.conditions import Traction

    mesh, _, _ = meshes.create_discs(MPI.COMM_WORLD, [((0.14, 2.27), 0.1), ((0.36, 2.27), 0.1)], 0.05)
    facets = meshes.locate_boundary_facets(mesh, lambda x: (x[0] >= 0.14) & (x[0] <= 0.36))
    dem = DEMDiscretisation(mesh, SOFT, "A", tractions=[Traction(facets, [0.0, -1.0])])
    with pytest.raises(ValueError, match="contact boundary: contact candidate facets must not carry a traction"):
        DEMProblem(dem, [PairContact(dem, meshes.exterior_facets(mesh))])


# -- 3D: tetrahedral bodies, triangular facets ------------------------------------------------
