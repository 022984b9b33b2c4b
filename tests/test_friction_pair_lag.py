"""The lagged friction bound between bodies (contact/pair_lag.py): the pairs' bound mu Ntilde_p
follows their normal force with the time scale T = LAG h_i / c_i, keeps its history through list
rebuilds, ends its tail, gives a block on a 30 degree slope on a fine contact mesh g (sin t - mu
cos t) where the instantaneous bound mu N_p did not, and is state: a checkpoint carries it to any
number of processes."""

import json

import numpy as np
import pytest
from helpers import CLI, mpi_env, run_command, stop_after
from mpi4py import MPI
from pair_scenes import two_discs
from test_friction_pairs import oblique_scene

from dolfinx_dem import checkpoint, meshes, simulation
from dolfinx_dem.conditions import DirichletBC
from dolfinx_dem.contact import PairContact
from dolfinx_dem.contact.friction import LAG
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import CheckpointError
from dolfinx_dem.material import ElasticMaterial
from dolfinx_dem.memm import MEMM
from dolfinx_dem.problem import DEMProblem

G = 10.0


@pytest.mark.skip_in_parallel
def test_the_pairs_bound_follows_their_normal_force_through_the_rebuilds():
    """T_p = LAG h_i / c_i; the first step sets Ntilde_p = N_p^+ / dt; then each step relaxes it
    exactly as exp(-dt / T) towards N_p^+ / dt, a pair new to the list from 0, a pair that left it
    dropped; a pair below 1e-16 of the largest dropped (its tail ended); the checkpoint's table
    (several pairs on one facet) restores the state exactly."""
    dem, facets = two_discs()
    contact = PairContact(dem, facets, friction=0.3)
    lag = contact.friction.lag
    own = slice(0, contact.num_own)
    expected = LAG * dem.geometry.facet_diameters[contact.facets[own]] / dem.materials.wave_speed(2, contact.cells[own])
    assert np.allclose(lag.lag, expected, rtol=1e-14) and LAG == 2.0
    pair = lambda f, j: lag.facet_key[f] * 2**31 + j  # noqa: E731  (PairList.pair_keys)
    keys, facet = np.array([pair(0, 7), pair(0, 8), pair(0, 9), pair(1, 7)]), np.array([0, 0, 0, 1])
    dt = 0.1 * lag.lag[:2].min()
    assert not lag.started
    first = lag.update(keys, facet, np.array([1.0, -1.0, 2.0, 0.5]) * dt, dt)
    assert np.array_equal(first, [1.0, 0.0, 2.0, 0.5]) and lag.started
    assert np.array_equal(lag.keys, keys[[0, 2, 3]])  # no history: not kept
    keys, facet = np.array([pair(0, 7), pair(0, 9), pair(1, 7), pair(1, 11)]), np.array([0, 0, 1, 1])
    second = lag.update(keys, facet, np.full(4, 3.0 * dt), dt)
    previous = np.array([1.0, 2.0, 0.5, 0.0])
    assert np.allclose(second, previous - np.expm1(-dt / lag.lag[facet]) * (3.0 - previous), rtol=1e-14)
    assert np.array_equal(lag.keys, np.sort(keys)) and np.array_equal(lag.values, second[np.argsort(keys)])

    table = contact.cell_state()["friction_pairs"]
    assert table.shape == (dem.n_owned, 3, 2, 2) and np.count_nonzero(table[..., 0] >= 0) == 4
    fresh = PairContact(dem, facets, friction=0.3)
    fresh.restore_cell_state({"friction_pairs": table})
    assert np.array_equal(fresh.friction.lag.keys, lag.keys) and np.array_equal(fresh.friction.lag.values, lag.values)
    assert fresh.friction.lag.started
    with pytest.raises(CheckpointError, match="stored state has the shape"):  # not this model's table
        fresh.restore_cell_state({"friction_pairs": table[:, :2]})

    big = lag.update(keys, facet, np.array([1e20, 0.0, 0.0, 0.0]) * dt, dt)
    assert big[0] > 1e18 and (big[1:] == 0.0).all() and np.array_equal(lag.keys, keys[:1])
    assert PairContact(dem, facets).cell_state() == {}


def test_a_block_on_a_slope_slides_at_the_coulomb_rate_on_a_fine_contact_mesh():
    """A 0.2 x 0.1 block on a 0.6 x 0.1 base clamped at its bottom (E = 1e4, nu = 0.3, rho = 1,
    scheme A, h = 0.00625, the block's facets straddling the base's), gravity tilted by 30 degrees,
    mu = 0.3, from rest at zero height: its mean velocity's slope over 0.1 - 0.3 s within 1 % of g
    (sin t - mu cos t) (measured +0.10 %; +3.5 % with the instantaneous bound mu N_p, +17.5 % for a
    0.4 x 0.2 block: docs/validation/friction_bodies.md), the balance to 1e-13 of the largest
    energy, D non-decreasing at every step."""
    theta, h = np.radians(30.0), 0.00625
    mesh, _, _ = meshes.create_discs(MPI.COMM_WORLD, [], h, rectangles=[[-0.3, -0.1, 0.3, 0.0],
                                                                         [-0.0963, 0.0, 0.1037, 0.1]])
    base = meshes.locate_boundary_facets(mesh, lambda x: x[1] <= -0.1 + 1e-9)
    dem = DEMDiscretisation(mesh, ElasticMaterial(E=1e4, nu=0.3, rho=1.0), "A",
                            dirichlet=[DirichletBC(base, [0.0, 0.0])],
                            body_force=list(G * np.array([np.sin(theta), -np.cos(theta)])))
    facets = meshes.locate_boundary_facets(mesh, lambda x: np.abs(x[1]) < 1e-9)
    stepper = MEMM(DEMProblem(dem, [PairContact(dem, facets, friction=0.3)]), 0.5 * dem.stable_time_step())
    first = stepper.initialise(dem.create_vector(), dem.create_vector())
    block = dem.geometry.cell_centres[: dem.n_owned, 1] > 0
    volume = dem.geometry.cell_volumes[: dem.n_owned] * block
    t, v, balance, dissipation, energy = [], [], [], [], 0.0
    while not t or t[-1] < 0.3:
        row = stepper.step()
        vbar = 0.5 * (stepper.v_prev.array_r + stepper.v_next.array_r).reshape(-1, 2)[:, 0]
        t.append(row.t)
        v.append(dem.comm.allreduce(volume @ vbar, op=MPI.SUM) / dem.comm.allreduce(volume.sum(), op=MPI.SUM))
        balance.append(row.balance)
        dissipation.append(row.dissipation)
        energy = max(energy, row.mechanical)
    t, v = np.array(t), np.array(v)
    assert np.abs(np.array(balance) - first.balance).max() < 1e-13 * max(energy, dissipation[-1])
    assert np.diff(np.r_[0.0, dissipation]).min() >= 0.0
    late = t > 0.1
    error = np.polyfit(t[late], v[late], 1)[0] / (G * (np.sin(theta) - 0.3 * np.cos(theta))) - 1
    assert abs(error) < 0.01, error


@pytest.mark.skip_in_parallel
def test_friction_between_bodies_resumes_on_another_number_of_processes(tmp_path, monkeypatch):
    """The oblique two-disks scene (h = 0.03) with mu = 0.3 between the disks, interrupted 5 steps
    before its end while they slide, on one process (the checkpoint holds the pairs' Ntilde in its
    cells' file), resumed on two: the series within 1e-12 of the uninterrupted run's (energies
    against the kinetic energy, the friction force against its largest)."""
    scene = oblique_scene()
    full = simulation.run(scene, tmp_path / "full", MPI.COMM_SELF, quiet=True)
    stop_after(monkeypatch, full["n_steps"] - 5)
    assert simulation.run(scene, tmp_path / "parts", MPI.COMM_SELF, quiet=True)["status"] == "interrupted"
    monkeypatch.undo()
    root = tmp_path / "parts" / checkpoint.DIRECTORY
    header = json.loads((root / checkpoint.HEADER).read_text())
    slots = header["cell_arrays"]["contact0_friction_pairs"]  # (facets of a cell, pairs of a facet, 2)
    assert slots[0] == 3 and slots[1] >= 1 and slots[2] == 2
    with np.load(root / header["data"] / "cells-0.npz") as cells:
        assert cells["contact0_friction_pairs"][..., 1].max() > 0
    run_command(["mpirun", "-n", "2", "--oversubscribe", CLI, "resume", str(tmp_path / "parts"), "--quiet"],
                   check=True, env=mpi_env())
    full, parts = (np.genfromtxt(tmp_path / p / "series.csv", delimiter=",", names=True) for p in ("full", "parts"))
    assert full.shape == parts.shape
    scale = full["kinetic"][0]
    for column in ("kinetic", "elastic", "dissipation", "balance"):
        assert np.abs(full[column] - parts[column]).max() < 1e-12 * scale, column
    force = np.abs(full["friction_force_0_1_y"]).max()
    assert force > 0 and np.abs(full["friction_force_0_1_y"] - parts["friction_force_0_1_y"]).max() < 1e-12 * force
