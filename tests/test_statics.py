"""Static DEM by active-set Newton minimisation (paper §5.2): exactness, equilibrium, Hertz."""

import json
import pathlib

import numpy as np
import pytest
from helpers import owned_centres
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, io, meshes, model, scenes, simulation, static_simulation
from dolfinx_dem.conditions import DirichletBC, Traction
from dolfinx_dem.contact import HalfSpace, PairContact, RigidContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import StaticsError
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.problem import DEMProblem
from dolfinx_dem.statics import minimise_energy


@pytest.mark.parametrize("scheme", ["A", "B"])
def test_bar_resting_on_an_obstacle(scheme):
    """1D bar [0, L] on an obstacle at 0 under gravity: u(x) = -rho g (L x - x^2 / 2) / E."""
    L, E, rho, g = 1.0, 100.0, 1.0, 10.0
    errors = []
    for n in (20, 40, 80):
        mesh, _, tags = meshes.create_interval(MPI.COMM_WORLD, n, 0.0, L)
        dem = DEMDiscretisation(mesh, ElasticMaterial(E=E, nu=0.0, rho=rho), scheme, body_force=[-rho * g])
        problem = DEMProblem(dem, [RigidContact(dem, [HalfSpace([0.0], [1.0], tags.find(meshes.XMIN))])])
        result = minimise_energy(problem)
        assert result.gradient_reduction < 1e-8
        x = owned_centres(dem)[:, 0]
        exact = -rho * g * (L * x - x**2 / 2) / E
        errors.append(MPI.COMM_WORLD.allreduce(np.abs(result.u.array - exact).max(), op=MPI.MAX))
        c = problem.find(RigidContact)
        assert c.contact_gap(c.patch_values(result.u))[0] == pytest.approx(0.0, abs=1e-14)
        reaction = MPI.COMM_WORLD.allreduce(c.reactions(result.u).sum(), op=MPI.SUM)  # one facet, |f| = 1
        assert reaction == pytest.approx(rho * g * L, rel=1e-8)
    order = np.log2(errors[0] / errors[2]) / 2
    assert errors[-1] < 1e-2 * rho * g * L**2 / (2 * E)
    assert order > 0.9, (errors, order)


@pytest.mark.slow
@pytest.mark.mpi
def test_hertz_disc_equilibrium_and_symmetry(tempdir):
    scene = scenes.load("hertz", {"mesh.h": 0.02})
    summary = simulation.run(scene, pathlib.Path(tempdir) / "hertz", MPI.COMM_WORLD)
    assert summary["status"] == "completed"
    assert {p.name for p in (pathlib.Path(tempdir) / "hertz").iterdir()} == {
        "summary.json", "series.csv", "solution.xdmf", "solution", "solution.h5", "final.png",
        "contact_pressure.csv"}
    assert {"summary.json", "contact_pressure.csv"} <= set(io.RUN_FILES)  # what --overwrite removes
    load = 2e6 * np.pi * 0.2**2
    assert summary["gradient_norm_reduction"] < 1e-8
    assert summary["contact_force"] == pytest.approx(load, rel=2e-3)
    # Hertz: a = 0.0490 m, p0 = 3.27 MPa; the body-force disc differs by a few percent.
    assert summary["contact_half_width"] == pytest.approx(0.048, rel=0.03)  # moment measure
    assert summary["contact_half_width_fit"] == pytest.approx(0.048, rel=0.08)
    assert summary["kink_facets"] == 0
    assert summary["max_contact_pressure"] == pytest.approx(3.27e6, rel=0.1)
    assert summary["top_vertical_displacement"] == pytest.approx(-0.0139, rel=0.03)
    if MPI.COMM_WORLD.rank == 0:
        data = np.loadtxt(pathlib.Path(tempdir) / "hertz" / "contact_pressure.csv", delimiter=",", skiprows=1)
        x, p = data[:, 0], data[:, 2]
        touching = p > 0
        assert abs(x[touching].mean()) < 0.2 * np.abs(x[touching]).max()  # centred: no rolling, no sliding
        assert json.loads((pathlib.Path(tempdir) / "hertz" / "summary.json").read_text())["iterations"] <= 10


def test_free_body_is_rejected():
    mesh, _, _ = meshes.create_interval(MPI.COMM_WORLD, 10, 0.0, 1.0)
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=1.0, nu=0.0, rho=1.0), "A", body_force=[-1.0])
    with pytest.raises(StaticsError, match=r"body 0 has a free rigid motion \(translation along x\)"):
        minimise_energy(DEMProblem(dem))
    with pytest.raises(ValueError, match="fixed_mean components"):
        minimise_energy(DEMProblem(dem), fixed_mean=(3,))


R_DISC, E_DISC, LOAD = 0.2, 25e6, 2e6  # the disc of the hertz scene


def disc_on_block(comm, h, stiffness=1.0, width=0.12, height=0.04, scheme="A", surface="facet"):
    """The hertz scene's disc (radius 0.2 m, centre 1e-6 m above y = R) resting under its body
    force on an elastic block [-width, width] x [-height, 0] of Young's modulus ``stiffness`` x
    the disc's, clamped at its bottom: contact between bodies on the facets near y = 0."""
    import gmsh

    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        disc = gmsh.model.occ.addDisk(0.0, R_DISC + 1e-6, 0.0, R_DISC, R_DISC)
        block = gmsh.model.occ.addRectangle(-width, -height, 0.0, 2 * width, height)
        gmsh.model.occ.synchronize()
        gmsh.model.addPhysicalGroup(2, [disc], 1)
        gmsh.model.addPhysicalGroup(2, [block], 2)
        gmsh.option.setNumber("Mesh.MeshSizeMin", h)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.model.mesh.generate(2)
    try:
        mesh, cells = _compat.mesh_from_gmsh_model(gmsh.model, comm, 2)[:2]
    finally:
        if comm.rank == 0:
            gmsh.finalize()
    materials = {1: ElasticMaterial(E=E_DISC, nu=0.25, rho=1.0, plane="strain"),
                 2: ElasticMaterial(E=E_DISC * stiffness, nu=0.25, rho=1.0, plane="strain")}
    bottom = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[1], -height))
    dem = DEMDiscretisation(mesh, materials, scheme, [DirichletBC(bottom, [0.0, 0.0])],
                            body_force=[0.0, -LOAD], cell_tags=cells)
    facets = meshes.locate_boundary_facets(mesh, lambda x: (x[1] > -height / 2) & (x[1] < 0.05))
    return DEMProblem(dem, [PairContact(dem, facets, surface=surface)])


def _disc_figures(problem, result):
    """(the disc's body number, its load (N/m), the contact force on it: pairs in contact plus
    the multipliers of pinned pairs (N/m, (2,)), its mean vertical displacement, and the
    contact half-width: the moment measure of the pair forces at the disc facets' centres)."""
    dem, pc = problem.dem, problem.find(PairContact)
    comm, geom = dem.comm, dem.geometry
    up = pc.patch_values(result.u)
    body = geom.cell_bodies[: dem.n_owned]
    disc = comm.allreduce(int(body[geom.cell_centres[: dem.n_owned, 1] > 0].max(initial=0)), op=MPI.MAX)
    volumes = geom.cell_volumes[: dem.n_owned]
    load = LOAD * comm.allreduce(volumes[body == disc].sum(), op=MPI.SUM)
    forces = pc.outputs.pair_forces(up, result.active) + pc.statics().kink_forces(result.pinned, result.kink_forces)
    forces = comm.allreduce(forces, op=MPI.SUM)[0]
    force = forces if pc.body_pairs[0][0] == disc else -forces
    uy = comm.allreduce(volumes[body == disc] @ result.u.array_r.reshape(-1, 2)[body == disc, 1], op=MPI.SUM)
    uy /= comm.allreduce(volumes[body == disc].sum(), op=MPI.SUM)
    # normal force of each touching pair (not pinned) at its disc facet's centre
    L, F = pc.listed, pc.facets_all
    g, w = pc.outputs.pair_states(up)
    c = np.where(np.isin(pc.pair_keys(), result.active), w * g, 0.0)
    normal = np.where(c != 0, -(L.ZT @ (L.Q @ up + pc.row_lift + L.Z @ c)) * w, 0.0)
    x = np.where(F.body[L.i] == disc, F.centre[L.i, 0], F.centre[L.j, 0])
    moments = comm.allreduce(np.array([normal.sum(), normal @ x, normal @ x**2]), op=MPI.SUM)
    half_width = 2 * np.sqrt(moments[2] / moments[0] - (moments[1] / moments[0]) ** 2)
    return disc, load, force, uy, half_width


@pytest.mark.mpi
def test_disc_resting_on_an_elastic_block():
    """Contact between bodies in statics: a disc on an elastic block (the block's size makes the
    minimum sit on a contact switch with gmsh 4.8's mesh: one pair pinned; none with 4.13's).
    The gradient of the potential of the dynamics vanishes to 1e-10 of the load's, the contact
    forces (pinned pair's multiplier included) balance the disc's load to 1e-8, and the solution
    on this communicator agrees with the serial one (COMM_SELF) to 1e-10."""
    results = []
    for comm in [MPI.COMM_WORLD] + ([MPI.COMM_SELF] if MPI.COMM_WORLD.size > 1 else []):
        problem = disc_on_block(comm, 0.04, width=0.3, height=0.2)
        result = minimise_energy(problem, fixed_mean=(0,), fixed_rotation=True)
        assert result.gradient_reduction < 1e-10
        assert len(result.pinned) <= 1 and (result.kink_forces > 0).all()  # a kink, if the mesh has one
        disc, load, force, uy, _ = _disc_figures(problem, result)
        assert force[1] == pytest.approx(load, rel=1e-8)
        results.append((result.energy, uy, force[1], result.iterations))
    assert results[0][3] <= 10
    for other in results[1:]:
        assert other[:3] == pytest.approx(results[0][:3], rel=1e-10)
        assert other[3] == results[0][3]


@pytest.mark.slow
def test_disc_on_a_stiff_block_approaches_the_rigid_plane():
    """With the block 1e4 times stiffer than the disc, contact between bodies approaches the
    statics of the same disc on the rigid plane y = 0 (obstacle contact, scene hertz). Measured
    at h = 0.02 m: the disc's mean vertical displacement differs by 0.32 %, the contact half-width
    (moment measure of the normal forces at the disc facets' centres) by -1.4 %."""
    comm = MPI.COMM_WORLD
    problem = disc_on_block(comm, 0.02, stiffness=1e4)
    result = minimise_energy(problem, fixed_mean=(0,), fixed_rotation=True)
    assert result.gradient_reduction < 1e-10
    disc, load, force, uy, half_width = _disc_figures(problem, result)
    assert force[1] == pytest.approx(load, rel=1e-8)

    mesh, _, _ = meshes.create_disc(comm, [0.0, R_DISC], R_DISC, 0.02)
    rigid = DEMDiscretisation(mesh, ElasticMaterial(E=E_DISC, nu=0.25, rho=1.0, plane="strain"), "A",
                              body_force=[0.0, -LOAD])
    c = RigidContact(rigid, [HalfSpace([0.0, 0.0], [0.0, 1.0],
                                       meshes.locate_boundary_facets(mesh, lambda x: x[1] <= R_DISC), 1e-9)])
    reference = minimise_energy(DEMProblem(rigid, [c]), fixed_mean=(0,), fixed_rotation=True)
    reactions = c.reactions(reference.u)
    x = rigid.geometry.facet_centres[c.facets[: c.num_own], 0]
    moments = comm.allreduce(np.array([reactions.sum(), reactions @ x, reactions @ x**2]), op=MPI.SUM)
    rigid_width = 2 * np.sqrt(moments[2] / moments[0] - (moments[1] / moments[0]) ** 2)
    volumes = rigid.geometry.cell_volumes[: rigid.n_owned]
    rigid_uy = comm.allreduce(volumes @ reference.u.array_r.reshape(-1, 2)[:, 1], op=MPI.SUM)
    rigid_uy /= comm.allreduce(volumes.sum(), op=MPI.SUM)
    assert uy - 1e-6 == pytest.approx(rigid_uy, rel=0.01)  # the disc starts 1e-6 m above the block
    assert half_width == pytest.approx(rigid_width, rel=0.03)


@pytest.mark.parametrize("surface", ["facet", "vertex"])
def test_pair_contact_hessian_is_the_derivative_of_the_force(surface):
    """On a fixed piece (pairs in contact, overlap configuration), the exact Hessian that
    the statics interface of ``PairContact`` adds (``exact``) is the derivative of the force of the
    piece: central differences of the force along random directions, with either surface (the
    Hessian reads the records' rows, K for the vertex surface)."""
    problem = disc_on_block(MPI.COMM_WORLD, 0.04, width=0.3, height=0.2, surface=surface)
    dem = problem.dem
    pc = problem.find(PairContact)
    rng = np.random.default_rng(3)
    u = dem.create_vector()
    u.array.reshape(-1, 2)[:, 1] = np.where(owned_centres(dem)[:, 1] > 0, -0.01, 0.0)  # the disc pressed in
    u.array[:] += 1e-4 * rng.standard_normal(u.array.shape)
    statics = pc.statics()
    statics.prepare(u)
    active = statics.touching(u)
    assert len(active) >= 4
    H = dem.K.copy()
    H.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    statics.add_hessian(H, u, active, True)
    H.assemble()
    plus, minus, Hv = dem.create_vector(), dem.create_vector(), dem.create_vector()
    for _ in range(3):
        v = dem.create_vector()
        v.array[:] = rng.standard_normal(v.array.shape)
        v.scale(1e-6 / v.norm())  # small enough that no overlap end is crossed
        for sign, out in ((1.0, plus), (-1.0, minus)):
            trial = u.copy()
            trial.axpy(sign, v)
            dem.force(trial, 0.0, out)
            pc.add_force(trial, out, active)
        H.mult(v, Hv)
        plus.axpy(-1.0, minus)  # F(u + v) - F(u - v) = -2 H v
        plus.axpy(2.0, Hv)
        assert plus.norm() < 1e-6 * 2 * Hv.norm()


def test_pair_statics_ends_with_an_error_when_it_does_not_converge():
    """Not converged in the iterations allowed: a StaticsError naming the gradient reduction
    reached, never a result."""
    problem = disc_on_block(MPI.COMM_WORLD, 0.04)
    with pytest.raises(StaticsError, match=r"no convergence in 2 iterations \(gradient reduction"):
        minimise_energy(problem, fixed_mean=(0,), fixed_rotation=True, max_iterations=2)
    with pytest.raises(ValueError, match="gradient_rtol"):
        minimise_energy(problem, gradient_rtol=0.0)


def test_statics_refuses_obstacles_with_contact_between_bodies():
    mesh, _, _ = meshes.create_discs(MPI.COMM_WORLD, [((0.0, 0.1), 0.1), ((0.25, 0.1), 0.1)], 0.05)
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=100.0, nu=0.2, rho=1.0), "B", body_force=[0.0, -1.0])
    boundary = meshes.exterior_facets(mesh)
    floor = RigidContact(dem, [HalfSpace([0.0, 0.0], [0.0, 1.0], boundary, tolerance=1e-3)])
    problem = DEMProblem(dem, [floor, PairContact(dem, boundary)])
    with pytest.raises(ValueError, match="rigid obstacles or contact between bodies, not both"):
        minimise_energy(problem, fixed_mean=(0,))


STACKED = {
    "name": "stacked",
    "method": "dem-B",
    "mesh": {"type": "discs", "discs": [[0.0, 0.100001, 0.1], [0.0, -0.1, 0.1]], "h": 0.05},
    "material": {"E": 1e4, "nu": 0.25, "rho": 1.0},
    "loads": {"body_force": [0.0, -100.0]},
    "dirichlet": [{"boundary": "y <= -0.17", "value": [0.0, 0.0]}],
    "contact": {"boundary": ["abs(y) <= 0.05"]},
    "statics": {"fixed_mean": [0], "fixed_rotation": True},
}


@pytest.mark.mpi
@pytest.mark.parametrize("surface", ["facet", "vertex"])
def test_static_scene_with_contact_between_bodies(tempdir, surface):
    """A static scene with a [contact] table: a disc resting on another one clamped at its
    bottom. The run completes; the summary's contact force (pairs in contact plus the pinned
    pairs' multipliers) balances the upper disc's load, with either surface; obstacles with
    contact are refused."""
    scene = STACKED | {"contact": STACKED["contact"] | {"surface": surface}}
    summary = simulation.run(scenes.validate(scene), pathlib.Path(tempdir) / f"stacked-{surface}", MPI.COMM_WORLD)
    assert summary["status"] == "completed" and summary["gradient_norm_reduction"] < 1e-10
    dem = simulation.build(scenes.validate(scene)).dem
    geom = dem.geometry
    upper = geom.cell_bodies[: dem.n_owned][geom.cell_centres[: dem.n_owned, 1] > 0]
    upper = MPI.COMM_WORLD.allreduce(int(upper.max(initial=0)), op=MPI.MAX)
    area = MPI.COMM_WORLD.allreduce(
        geom.cell_volumes[: dem.n_owned][geom.cell_bodies[: dem.n_owned] == upper].sum(), op=MPI.SUM
    )
    force = summary["contact_forces"]["0_1"][1]
    assert abs(force) == pytest.approx(100.0 * area, rel=1e-8)
    with pytest.raises(scenes.SceneError, match="obstacles or contact between bodies"):
        scenes.validate(STACKED | {"obstacles": [{"point": [0.0, -0.3], "normal": [0.0, 1.0], "boundary": "y < 0"}]})


@pytest.mark.mpi
@pytest.mark.parametrize("rtol", [1e-12, 1e-8])
def test_contact_between_bodies_converges_below_the_linear_solves(rtol):
    """The stacked discs hold the upper one by two pairs in contact and one held on its switch
    (multiplier -2.68): the gradient falls to 1e-11 of its initial norm whatever the tolerance of
    CG (the rounding floor of the gradient is 1e-13 of it, measured). Before, each solution's part
    along the upper disc's rigid modes (which contact resists) and the error of the solve of
    F_A (O(1) there, balanced by the multiplier) held the gradient at 2e-11 to 4e-10 (rtol
    1e-12; 3e-9 on 3 processes) and at 1e-9 to 4e-8 (rtol 1e-8), above the target."""
    problem = simulation.build(scenes.validate(STACKED), MPI.COMM_WORLD)
    result = minimise_energy(problem, fixed_mean=(0,), fixed_rotation=True, rtol=rtol, gradient_rtol=1e-11,
                             max_iterations=12)
    assert result.gradient_reduction < 1e-11 and len(result.pinned) == 1


def test_static_scene_rejects_time_and_fem_needs_statics():
    with pytest.raises(scenes.SceneError, match="takes no 'time' table"):
        scenes.load("hertz", {"time": {"end": 1.0, "dt": 0.1}})
    with pytest.raises(scenes.SceneError, match="static scenes"):
        scenes.load("bar-impact", {"method": "fem-P2"})


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"mesh.refine_h": None}, "'mesh.refine_point' and 'mesh.refine_h' go together"),
        ({"mesh.refine_h": 0.05}, "h_min must satisfy"),
        ({"mesh.balls": [[0.0, 0.0, 0.2, 0.2], [0.3, 0.0, 0.2, 0.2]]}, "balls 1 and 2 overlap"),
        ({"mesh.frame": [-1.0, -1.0, -1.0, 1.0, 1.0, 0.3], "mesh.frame_width": 0.1}, "not strictly inside"),
        ({"mesh.cut": ["x", "w"]}, r"mesh.cut\[1\]"),
        ({"method": "fem-P2", "mesh.cut": ["x"]}, "'fem-P2' solves the Hertz problems only"),
        ({"method": "fem-P2", "mesh.refine_point": [0.0, 0.0, 0.1]}, "'fem-P2' solves the Hertz problems only"),
    ],
)
def test_bad_ball_scenes_are_rejected_before_the_run(overrides, message, tmp_path):
    scene = scenes.load("hertz3d")
    for key, value in overrides.items():
        table, name = key.split(".") if "." in key else (None, key)
        target = scene[table] if table else scene
        target.pop(name) if value is None else target.__setitem__(name, value)
    with pytest.raises(scenes.SceneError, match=message):
        simulation.run(scenes.validate(scene), tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.mpi
def test_scheme_b_minimum_on_a_kink(tempdir):
    """Scheme B on the Hertz disc at h = 0.013 (measured: one facet): the minimum of the
    piecewise-quadratic potential sits on a contact switch, where plain active-set iterations
    cycle. The minimisation holds that facet at g = 0 with a multiplier of admissible sign; the
    contact forces, multiplier included, balance the load, and the gradient of the Lagrangian
    vanishes."""
    scene = scenes.load("hertz", {"method": "dem-B", "mesh.h": 0.013})
    summary = simulation.run(scene, pathlib.Path(tempdir) / "kink", MPI.COMM_WORLD)
    dem = simulation.build(scene).dem
    area = MPI.COMM_WORLD.allreduce(dem.geometry.cell_volumes[: dem.n_owned].sum(), op=MPI.SUM)
    load = 2e6 * area  # the polygon's area, not pi R^2
    assert summary["kink_facets"] >= 1
    assert summary["gradient_norm_reduction"] < 1e-8
    assert summary["contact_force"] == pytest.approx(load, rel=1e-9)
    assert summary["top_vertical_displacement"] == pytest.approx(-0.01389, rel=0.02)


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["A", "B"])
def test_bar_under_an_end_traction(scheme):
    """1D bar [0, L] clamped at 0, traction sigma at L: the reaction balances the load to 1e-12
    (both schemes: V is invariant under a common translation of u and g but for the loads); with
    scheme A the solution is exact, u_tip = sigma L / E to 1e-12."""
    L, E, sigma = 2.0, 50.0, 3.0
    mesh, _, tags = meshes.create_interval(MPI.COMM_WORLD, 16, 0.0, L)
    dem = DEMDiscretisation(
        mesh,
        ElasticMaterial(E=E, nu=0.0, rho=1.0),
        scheme,
        [DirichletBC(tags.find(meshes.XMIN), [0.0])],
        tractions=[Traction(tags.find(meshes.XMAX), [sigma])],
    )
    result = minimise_energy(DEMProblem(dem), rtol=1e-14)
    assert dem.reactions(result.u, 0.0)[0, 0] == pytest.approx(-sigma, rel=1e-12)
    if scheme == "A":
        x = owned_centres(dem)[:, 0]
        G = dem.gradient(result.u, 0.0)[:, 0, 0]
        assert np.allclose(G, sigma / E, rtol=1e-12, atol=0)
        tip = result.u.array + G * (L - x)  # the P1 reconstruction (eq. (10)) at x = L
        assert np.allclose(tip, sigma * L / E, rtol=1e-12, atol=0)


@pytest.mark.mpi
def test_patch_test_with_rollers():
    """2D block [0, 2] x [0, 1] (crossed: no cell with two boundary facets) on rollers, u_x = 0
    on the left and u_y = 0 on the bottom, traction (sigma, 0) on the right: with scheme A the
    stress is uniform and exact, sigma_xx = sigma, sigma_yy = sigma_xy = 0, in every cell; the
    rollers balance the load: reactions (-sigma H, 0) on the left, 0 on the bottom."""
    sigma, H = 0.7, 1.0
    mesh, _, tags = meshes.create_rectangle(MPI.COMM_WORLD, [0.0, 0.0], [2.0, H], [6, 3], "crossed")
    dem = DEMDiscretisation(
        mesh,
        ElasticMaterial(E=10.0, nu=0.3, rho=1.0),
        "A",
        [
            DirichletBC(tags.find(meshes.XMIN), [0.0, 0.0], components=[0]),
            DirichletBC(tags.find(meshes.YMIN), [0.0, 0.0], components=[1]),
        ],
        tractions=[Traction(tags.find(meshes.XMAX), [sigma, 0.0])],
    )
    assert dem.num_multi_neumann_cells == 0
    result = minimise_energy(DEMProblem(dem), rtol=1e-14)
    stress = dem.stress(result.u, 0.0)
    exact = np.array([[sigma, 0.0], [0.0, 0.0]])
    error = MPI.COMM_WORLD.allreduce(np.abs(stress - exact).max(initial=0.0), op=MPI.MAX)
    assert error < 1e-11 * sigma
    assert np.allclose(dem.reactions(result.u, 0.0), [[-sigma * H, 0.0], [0.0, 0.0]], rtol=0, atol=1e-12 * sigma)


@pytest.mark.parametrize("n", [2, 3, 8])
def test_bar_pressed_on_a_wall_by_a_traction(n):
    """1D bar [0, L] against a rigid wall at x = 0, pushed by a traction -p at x = L (scheme A):
    the exact solution, uniform stress -p, the wall's force p. With two cells the jump row of the
    middle facet reads both cells' reconstructions, so the contact rows carry the traction's
    lift (a contact model that built its rows' lift from the Dirichlet data alone gave a wrong
    stress there). A traction on a contact candidate facet is refused."""
    L, E, p = 1.0, 20.0, 0.5
    mesh, _, tags = meshes.create_interval(MPI.COMM_SELF, n, 0.0, L)
    dem = DEMDiscretisation(
        mesh, ElasticMaterial(E=E, nu=0.0, rho=1.0), "A", tractions=[Traction(tags.find(meshes.XMAX), [-p])]
    )
    problem = DEMProblem(dem, [RigidContact(dem, [HalfSpace([0.0], [1.0], tags.find(meshes.XMIN))])])
    result = minimise_energy(problem, rtol=1e-14)
    assert np.allclose(problem.stress(result.u, 0.0)[:, 0, 0], -p, rtol=1e-12, atol=0)
    assert float(problem.find(RigidContact).reactions(result.u).sum()) == pytest.approx(p, rel=1e-12)
    with pytest.raises(ValueError, match="must not carry a traction"):
        RigidContact(dem, [HalfSpace([L], [-1.0], tags.find(meshes.XMAX))])


@pytest.mark.mpi
def test_hertz_ball_equilibrium_and_contact_radius(tempdir):
    """The quarter ball of the hertz3d scene on a coarse mesh: the plane carries the whole body
    force (the symmetry conditions act on u_x, u_y only), and the contact radius is near Hertz's
    (a = 0.0384 m; 0.0384 measured at h = 0.04, so 4 % allows for the coarse mesh only)."""
    scene = scenes.load("hertz3d", {"mesh.h": 0.06, "mesh.refine_h": 0.015})
    problem = model.build(scene, MPI.COMM_WORLD)
    dem = problem.dem
    result = minimise_energy(problem)
    assert result.gradient_reduction < 1e-8
    figures = static_simulation._contact_summary(
        problem.find(RigidContact),
        result.u,
        result,
        pathlib.Path(tempdir) / "p.csv",
        ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
    )
    volume = MPI.COMM_WORLD.allreduce(dem.mass.array_r[2::3].sum(), op=MPI.SUM)  # rho = 1
    assert figures["contact_force"] == pytest.approx(3e5 * volume, rel=1e-8)
    assert figures["contact_radius"] == pytest.approx(0.0384, rel=0.04)
    # the facet forces at the barycentres: smaller by the triangles' own second moments, 0.3-3 %
    # of a on this mesh (facet side about 0.014 m)
    assert 0.97 * figures["contact_radius"] < figures["contact_radius_barycentre"] < 0.997 * figures["contact_radius"]
    reactions = dem.reactions(result.u, 0.0)  # symmetry planes: normal forces only
    assert np.all(reactions[:, 2] == 0.0) and reactions[0, 1] == reactions[1, 0] == 0.0


def _static_cantilever(**overrides) -> dict:
    scene = {k: v for k, v in scenes.load("cantilever").items() if k not in ("time", "output")}
    return scene | {"statics": {}} | overrides


@pytest.mark.mpi
@pytest.mark.parametrize(
    ("dirichlet", "statics", "free"),
    [
        ([{"boundary": "left", "components": [0]}], {}, "translation along y"),  # rollers: before, solved silently
        ([{"boundary": "bottom", "components": [1]}], {}, "translation along x"),
        ([], {"fixed_mean": [0, 1]}, "rotation"),
        ([], {}, "translation along x, translation along y and rotation"),
    ],
)
def test_a_free_rigid_motion_of_a_static_body_is_an_error_before_anything_is_written(dirichlet, statics, free,
                                                                                     tmp_path):
    scene = scenes.validate(_static_cantilever(dirichlet=dirichlet, statics=statics))
    with pytest.raises(StaticsError, match=rf"body 0 has a free rigid motion \({free}"):
        static_simulation.StaticRun(scene, MPI.COMM_WORLD)
    with pytest.raises(StaticsError, match="free rigid motion"):
        minimise_energy(model.build(scene, MPI.COMM_WORLD))
    out = MPI.COMM_WORLD.bcast(tmp_path / "out", root=0)
    with pytest.raises(StaticsError):
        simulation.run(scene, out)
    assert not out.exists()


@pytest.mark.mpi
def test_rollers_on_two_sides_hold_a_static_body():
    """Rollers on the left (x fixed) and the bottom (y fixed) hold every rigid motion: it solves, and
    the reactions balance the load."""
    scene = scenes.validate(_static_cantilever(dirichlet=[{"boundary": "left", "components": [0]},
                                                          {"boundary": "bottom", "components": [1]}]))
    problem = model.build(scene, MPI.COMM_WORLD)
    result = minimise_energy(problem)
    reactions = problem.dem.reactions(result.u, 0.0).sum(axis=0)
    assert np.allclose(reactions, [0.0, 0.1 * 0.1], rtol=1e-8, atol=1e-12)  # body force (0, -0.1) over 0.1 m^2
