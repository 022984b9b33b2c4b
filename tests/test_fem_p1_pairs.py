"""Method fem-P1 with contact between bodies (fem/pair_penalty.py): the force is the exact
gradient of the penalty energy and conserves momentum, two-disks agrees with the DEM (scheme A)
on the contact's start, end and impulse, and what it does not run is an error naming the key."""

import os
import pathlib
import sys

import numpy as np
import pytest
from helpers import run_command
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat, model, scenes, simulation
from dolfinx_dem.errors import InputError, SceneError
from dolfinx_dem.fem.scene_run import FEMP1Run

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")


def _overlapping(name, h, push, tolerance=0.01):
    """``name`` under fem-P1 on a mesh of size h, the two first bodies pushed into each other by
    2 push along x at t = 0 (the contact tolerates it)."""
    scene = scenes.load(name, {"method": "fem-P1", "mesh.h": h, "contact.tolerance": tolerance})
    scene["material"].pop("eta", None)
    scene["contact"].pop("surface", None)  # the DEM's contact surface (two-balls: vertex); fem-P1 has its own
    d = 3 if name == "two-balls" else 2
    scene["initial"]["displacement"] = [f"where(x < 0.25, {push}, {-push})"] + ["0"] * (d - 1)
    return scene


def _vector(run, values):
    """A copy of the run's displacement vector holding the (n_nodes, d) ``values``."""
    v = _compat.petsc_vec(run.solver.u).copy()
    v.array[:] = values.ravel()
    v.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    return v


@pytest.mark.mpi
@pytest.mark.parametrize("name, h", [("two-disks", 0.02), ("two-balls", 0.05)])
def test_pair_force_is_the_gradient_of_the_penalty_energy(name, h):
    """On any number of processes: the energy and the slopes summed over them."""
    comm = MPI.COMM_WORLD
    run = FEMP1Run(_overlapping(name, h, 0.0125), comm, quiet=True)
    pairs = run.solver._pairs

    def energy(values):
        return comm.allreduce(pairs.energy(_vector(run, values)), op=MPI.SUM)

    u = _compat.petsc_vec(run.solver.u).array_r.reshape(-1, run.d).copy()
    rng = np.random.default_rng(1 + comm.rank)
    u += 1e-4 * rng.standard_normal(u.shape)  # off the symmetric position
    force = np.zeros_like(u)
    pairs.add_forces(_vector(run, u), force)
    assert comm.allreduce(len(pairs.state(_vector(run, u))["g"]), op=MPI.SUM) > 4 and energy(u) > 0
    # momentum: the forces on the nodes and on the facets' nodes cancel to rounding
    total = comm.allreduce(force.sum(axis=0), op=MPI.SUM)
    assert np.abs(total).max() <= 1e-13 * comm.allreduce(np.abs(force).sum(), op=MPI.SUM)
    eps = 1e-7
    for _ in range(3):
        w = rng.standard_normal(u.shape)
        slope = (energy(u + eps * w) - energy(u - eps * w)) / (2 * eps)
        assert slope == pytest.approx(-comm.allreduce(np.sum(force * w), op=MPI.SUM), rel=1e-6)


def test_the_stable_step_bound_bounds_the_largest_eigenvalue():
    """lambda_max(m^-1 (K + K_c)) of two overlapping discs (K_c = sum_p kappa_p b_p b_p^T, b_p = (n,
    -N_a n)), dense, against ``eigenvalue_bound``."""
    run = FEMP1Run(_overlapping("two-disks", 0.02, 0.0125), MPI.COMM_SELF, quiet=True)
    solver, pairs = run.solver, run.solver._pairs
    st = pairs.state(_compat.petsc_vec(solver.u))
    d = 2
    mass = solver.lumped_mass.array_r
    n_dofs = len(mass)
    K = np.zeros((n_dofs, n_dofs))
    rows, cols, values = solver._K.getValuesCSR()
    for i in range(n_dofs):
        K[i, cols[rows[i]:rows[i + 1]]] = values[rows[i]:rows[i + 1]]
    for s, a, N, n, kappa in zip(pairs.slaves[st["s"]], pairs.known.global_nodes[st["a"]], st["N"], st["n"],
                                 st["kappa"]):
        b = np.zeros(n_dofs)
        b[s * d:(s + 1) * d] = n
        for node, share in zip(a, N):
            b[node * d:(node + 1) * d] -= share * n
        K += kappa * np.outer(b, b)
    w = 1.0 / np.sqrt(mass)
    largest = np.linalg.eigvalsh(w[:, None] * K * w[None, :]).max()
    bound = pairs.eigenvalue_bound(st)
    assert largest <= bound
    assert largest > 4.0 / solver.dt_stable**2 * (1 + 1e-3)  # the springs count
    assert bound < 2.0 * largest  # and the bound is not loose


@pytest.mark.mpi
def test_an_initial_overlap_beyond_the_tolerance_is_an_error():
    with pytest.raises(InputError, match="inside another body at t = 0.*contact.tolerance"):
        FEMP1Run(_overlapping("two-disks", 0.02, 0.011, tolerance=0.0), MPI.COMM_WORLD, quiet=True)


def _contact(summary, data):
    t, F = data["t"], data["contact_force_0_1_x"]
    on = t[np.abs(F) > 0]
    return on[0], on[-1], F.sum() * summary["dt"]  # start, end, impulse of body 1 on body 0


def test_two_disks_against_dem_a(tmp_path):
    """two-disks on the coarse mesh h = 0.02: fem-P1 against dem-A. Measured: start 0.03559 (a
    step of 0.00254 s after the touch at 0.0333, dem-A 0.03367), end 0.5034 (dem-A 0.5327: the
    last nodes of the two discretisations let go at different times, 6 % of the duration; 0.004 s
    apart at h = 0.01), impulse -1.7402 (dem-A -1.7374, 0.16 %), so the rebound velocity
    0.3 + impulse / m of the left disc agrees to 1e-3 m/s. Momentum is conserved to rounding."""
    results = {}
    for method in ("dem-A", "fem-P1"):
        scene = scenes.load("two-disks", {"method": method, "mesh.h": 0.02, "time.end": 0.6,
                                          "output.every": 10**6})
        summary = simulation.run(scene, tmp_path / method, MPI.COMM_SELF, quiet=True)
        data = np.genfromtxt(tmp_path / method / "series.csv", delimiter=",", names=True)
        results[method] = (summary, data, _contact(summary, data))
    summary, data, (start, end, impulse) = results["fem-P1"]
    _, dem, (dem_start, dem_end, dem_impulse) = results["dem-A"]
    assert set(dem.dtype.names) - set(data.dtype.names) == set()  # the DEM's columns, and a ``penalty``
    assert abs(start - dem_start) <= 1.01 * summary["dt"]
    assert abs(start - 0.02 / 0.6) <= 1.01 * summary["dt"]
    assert abs(end - dem_end) < 0.04
    assert impulse == pytest.approx(dem_impulse, rel=5e-3)
    mass = 100.0 * np.pi * 0.1**2
    assert 0.3 + impulse / mass == pytest.approx(-0.253, abs=3e-3)  # the rebound, slower than 0.3 m/s
    assert summary["momentum_rel_change"] < 1e-12
    assert np.abs(data["momentum_x"] - data["momentum_x"][0]).max() < 1e-12
    # within the step: the discs' poles are vertices, they touch at 0.02 / 0.6 s
    assert start - summary["dt"] <= summary["first_contact_time"] <= start
    assert summary["first_contact_time"] == pytest.approx(0.02 / 0.6, abs=1e-12)
    assert summary["first_contact_time"] == pytest.approx(results["dem-A"][0]["first_contact_time"], abs=1e-12)
    assert summary["max_penetration"] == pytest.approx(data["penetration"].max())
    assert 0 < summary["max_penetration"] < 0.005
    # the pairs' normal forces sum to at least the force between the discs, nearly all along x (head-on)
    force_x = np.abs(data["contact_force_0_1_x"])
    assert (force_x <= data["contact_force"] * (1 + 1e-12)).all()
    assert force_x.sum() == pytest.approx(data["contact_force"].sum(), rel=0.01)  # 0.995 measured
    assert summary["pseudo_energy_rel_drift"] < 0.01


@pytest.mark.mpi
def test_a_step_the_bound_does_not_prove_stable_is_an_error(tempdir):
    """Raised on every process (the bound is reduced), as the next error."""
    scene = scenes.load("two-disks", {"method": "fem-P1", "mesh.h": 0.02, "time.cfl": 0.95, "time.end": 0.1})
    with pytest.raises(InputError, match="not proved stable with the contact between bodies.*time.cfl"):
        simulation.run(scene, pathlib.Path(tempdir) / "out", MPI.COMM_WORLD, quiet=True)


@pytest.mark.mpi
def test_contact_deeper_than_the_facets_is_an_error(tempdir):
    scene = scenes.load("two-disks", {"method": "fem-P1", "mesh.h": 0.02, "time.end": 0.1})
    scene["initial"]["velocity"] = ["where(x < 0.25, 30.0, -30.0)", "0"]
    with pytest.raises(InputError, match="no longer resolved.*lower time.cfl"):
        simulation.run(scene, pathlib.Path(tempdir) / "out", MPI.COMM_WORLD, quiet=True)


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("name, options", [("two-disks", ["mesh.h=0.02", "time.end=0.6"]),
                                           ("cradle", ["time.end=0.3"])])
def test_one_two_and_three_processes_give_the_same_series(name, options, tmp_path):
    """The energies agree to 1e-11 of their scale, the momentum to 1e-13 N s (of about 1), the
    contact forces and the penetration to 1e-9 of their largest value: the penalty force
    kappa g turns a rounding difference of the positions (1e-13 m, from the sums' order) into
    kappa times it near a release (measured on two-disks: 1.5e-12 for the energies, 7e-11 for
    the forces; on cradle 4e-12)."""
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none", OMP_NUM_THREADS="1")
    sets = [a for o in ["method=fem-P1", "output.every=100000", *options] for a in ("--set", o)]
    data = []
    for n in (1, 2, 3):
        prefix = [] if n == 1 else ["mpirun", "-n", str(n), "--oversubscribe"]
        run_command([*prefix, CLI, "run", name, *sets, "--quiet", "--out", str(tmp_path / str(n))], check=True,
                       env=env)
        data.append(np.genfromtxt(tmp_path / str(n) / "series.csv", delimiter=",", names=True))
    a = data[0]
    assert a["contact_force"].max() > 0
    energy = max(np.abs(a[c]).max() for c in ("kinetic", "elastic"))
    for b in data[1:]:
        assert a.shape == b.shape
        for column in a.dtype.names:
            if column.startswith("momentum"):
                tolerance = 1e-13
            elif column in model.SERIES_COLUMNS[1:] + ("penalty",):
                tolerance = 1e-11 * energy
            else:
                tolerance = 1e-9 * max(np.abs(a[column]).max(), 1e-300)
            assert np.abs(a[column] - b[column]).max() <= tolerance, column


def test_contact_between_bodies_in_1d_is_an_error(tmp_path):
    scene = scenes.load("bar-impact", {"method": "fem-P1", "time.end": 0.01})
    scene.pop("obstacles")
    scene["contact"] = {"boundary": ["all"]}
    with pytest.raises(SceneError, match="'contact'.*not 1D.*fem-P1"):
        simulation.run(scene, tmp_path / "out", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "out").exists()


def test_cradle_passes_the_momentum_on(tmp_path):
    """cradle (3D, five balls) under fem-P1 to 0.3 s: the first ball strikes the second, the
    forces between the ten body pairs are written, the second ball's force on the first is along
    x, and the total momentum is conserved to rounding."""
    scene = scenes.load("cradle", {"method": "fem-P1", "time.end": 0.3, "output.every": 10**6})
    summary = simulation.run(scene, tmp_path / "out", MPI.COMM_SELF, quiet=True)
    data = np.genfromtxt(tmp_path / "out" / "series.csv", delimiter=",", names=True)
    pairs = [c for c in data.dtype.names if c.startswith("contact_force_") and c.endswith("_x")]
    assert len(pairs) == 10
    # the spheres touch at 0.01 / 0.3 s; their facets (h = 0.04) lie up to h^2 / (8 R) = 2 mm inside
    # them, and a vertex need not sit at a pole: 0.0398 s measured
    assert 0.01 / 0.3 < summary["first_contact_time"] < (0.01 + 2 * 0.04**2 / 0.8) / 0.3 + summary["dt"]
    force = data["contact_force_0_1_x"]
    assert force.min() < -0.01 * data["contact_force"].max() < 0  # ball 1 pushes ball 0 back
    assert np.abs(data["contact_force_0_1_y"]).max() < 0.05 * np.abs(force).max()
    assert summary["momentum_rel_change"] < 1e-12


def test_obstacles_and_contact_between_bodies_together(tmp_path):
    """The two discs on a floor under gravity: one ``penalty`` column, the obstacles' columns,
    then the pairs'; the pairs' stable-step bound starts from the step with the obstacles'
    springs (``dt_stable_contact``)."""
    scene = scenes.load("two-disks", {"method": "fem-P1", "mesh.h": 0.02, "time.end": 0.3, "output.every": 10**6})
    scene["obstacles"] = [{"point": [0.0, 2.17], "normal": [0.0, 1.0], "boundary": "all"}]
    scene["loads"] = {"gravity": [0.0, -1.0]}
    summary = simulation.run(scene, tmp_path / "out", MPI.COMM_SELF, quiet=True)
    data = np.genfromtxt(tmp_path / "out" / "series.csv", delimiter=",", names=True)
    assert data.dtype.names[5:] == ("pseudo_energy", "penalty", "contact_gap", "contact_pressure",
                                    "contact_force_obstacle0_x", "contact_force_obstacle0_y", "contact_force",
                                    "penetration", "contact_force_0_1_x", "contact_force_0_1_y", "momentum_x",
                                    "momentum_y")
    assert summary["min_contact_gap"] < 0 and data["contact_force_obstacle0_y"].max() > 0  # on the floor
    assert data["contact_force"].max() > 0 and summary["first_contact_time"] == pytest.approx(0.02 / 0.6, abs=1e-12)
    assert summary["pseudo_energy_rel_drift"] < 0.01
