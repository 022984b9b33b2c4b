"""The lagged friction bound on rigid obstacles (contact/friction.py): the bound mu Ntilde_f follows
the facet's normal force with the time scale T_f = LAG h_f / c_f, decays on a facet out of
contact, gives the block on a 30 degree slope g (sin t - mu cos t) at mu = 0.3 where the
instantaneous bound mu N_f opened the contact (docs/validation/friction_chatter.md), and is state:
a checkpoint carries it to any number of processes."""

import json

import numpy as np
import pytest
from helpers import CLI, mpi_env, run_command, stop_after
from mpi4py import MPI
from test_friction import BLOCK, SLIDE, G, block, slide

from dolfinx_dem import checkpoint, scenes, simulation
from dolfinx_dem.contact.friction import LAG, CellFriction


def test_the_bound_follows_the_normal_force_with_its_lag():
    """T_f = LAG h_f / c_p (the base facets of 16 x 8 squares: h_f = 1/16, plane strain); the
    first step sets Ntilde = N^+ / dt; then each step relaxes it exactly as exp(-dt / T) towards
    N^+ / dt (a negative N_f counts as 0); a facet out of contact keeps a bound that decays, its
    whole impulse afterwards below mu Ntilde T."""
    friction = block(0.3, [0.0, -G]).contacts[0].friction
    lam, mu_s = BLOCK.lame(2)
    lag = LAG * (1 / 16) / np.sqrt((lam + 2 * mu_s) / BLOCK.rho)
    assert np.allclose(friction.lag, lag, rtol=1e-12) and LAG == 2.0
    n, dt = len(friction.mu), 0.1 * lag
    normal = np.linspace(-1.0, 2.0, n) * dt
    assert not friction.started
    assert np.array_equal(friction.lagged(normal, dt), np.maximum(normal, 0.0) / dt) and friction.started
    start = friction.normal_force.copy()
    for _ in range(5):
        friction.lagged(np.full(n, 3.0 * dt), dt)
    assert np.allclose(friction.normal_force, 3.0 + (start - 3.0) * np.exp(-0.5), rtol=1e-13)
    held = friction.normal_force.copy()
    impulse = sum(0.3 * friction.lagged(np.full(n, -1.0), dt) * dt for _ in range(2000))  # out of contact
    assert np.allclose(impulse, 0.3 * held * dt * np.exp(-0.1) / -np.expm1(-0.1), rtol=1e-12)
    assert (impulse < 0.3 * held * lag).all()


def test_the_lags_must_be_positive():
    with pytest.raises(ValueError, match="lags must be finite and > 0"):
        CellFriction(2, np.zeros(1, dtype=np.int64), np.array([[0.0, 1.0]]), np.array([0.3]), np.array([0.0]),
                     np.zeros(1, dtype=np.int64), 1)


@pytest.mark.mpi
def test_a_block_at_mu_0_3_slides_at_the_coulomb_rate_on_a_fine_contact_mesh():
    """32 x 16 squares, 30 degrees, mu = 0.3: the acceleration within 0.5 % of g (sin t - mu cos t)
    (measured -0.22 %; +12.3 % with the instantaneous bound mu N_f), the balance to 1e-13 of the
    largest energy and D non-decreasing at every step."""
    first, rows, _ = slide(0.3, 30.0, 0.6, n=(32, 16))
    t, v, balance, dissipation = (np.array([r[k] for r in rows]) for k in range(4))
    scale = max(max(r[5] for r in rows), dissipation[-1])
    assert np.abs(balance - first.balance).max() < 1e-13 * scale
    assert np.diff(np.r_[0.0, dissipation]).min() >= 0.0
    late = t > 0.1
    a = np.polyfit(t[late], v[late], 1)[0]
    exact = G * (np.sin(np.radians(30.0)) - 0.3 * np.cos(np.radians(30.0)))
    assert abs(a / exact - 1) < 0.005, a / exact - 1


def test_the_cell_state_round_trips():
    """``cell_state`` holds the own facets' Ntilde at (cell, local facet) and 0 elsewhere;
    ``restore_cell_state`` puts them back exactly and marks the law started."""
    contact = block(0.3, [0.0, -G]).contacts[0]
    contact.friction.normal_force[:] = np.arange(contact.num_own) + 1.0
    table = contact.cell_state()["friction_normal_force"]
    assert table.shape == (contact.dem.n_owned, 3) and np.count_nonzero(table) == contact.num_own
    fresh = block(0.3, [0.0, -G]).contacts[0]
    fresh.restore_cell_state({"friction_normal_force": table})
    assert np.array_equal(fresh.friction.normal_force, contact.friction.normal_force) and fresh.friction.started
    assert block(0.0, [0.0, -G]).contacts[0].cell_state() == {}


@pytest.mark.skip_in_parallel
def test_a_friction_run_resumes_on_another_number_of_processes(tmp_path, monkeypatch):
    """The slide scene at mu = 0.3, interrupted at step 120 on one process (the checkpoint holds
    Ntilde in its cells' file) and resumed on two: the series within 1e-12 of the uninterrupted
    run's (energies against the largest energy, the friction force against its largest)."""
    (tmp_path / "slide.toml").write_text(SLIDE.replace("friction = 0.1", "friction = 0.3"))
    scene = scenes.load(str(tmp_path / "slide.toml"))
    simulation.run(scene, tmp_path / "full", MPI.COMM_SELF, quiet=True)
    stop_after(monkeypatch, 120)
    assert simulation.run(scene, tmp_path / "parts", MPI.COMM_SELF, quiet=True)["status"] == "interrupted"
    monkeypatch.undo()
    root = tmp_path / "parts" / checkpoint.DIRECTORY
    header = json.loads((root / checkpoint.HEADER).read_text())
    with np.load(root / header["data"] / "cells-0.npz") as cells:
        assert cells["contact0_friction_normal_force"].shape == (len(cells["key"]), 3)
        assert cells["contact0_friction_normal_force"].max() > 0
    run_command(["mpirun", "-n", "2", "--oversubscribe", CLI, "resume", str(tmp_path / "parts"), "--quiet"],
                   check=True, env=mpi_env())
    full, parts = (np.genfromtxt(tmp_path / p / "series.csv", delimiter=",", names=True) for p in ("full", "parts"))
    assert full.shape == parts.shape
    energy = max(np.abs(full[c]).max() for c in ("kinetic", "elastic", "external", "dissipation"))
    for column in ("kinetic", "elastic", "dissipation", "balance"):
        assert np.abs(full[column] - parts[column]).max() < 1e-12 * energy, column
    force = np.abs(full["friction_force_obstacle0_x"]).max()
    assert np.abs(full["friction_force_obstacle0_x"] - parts["friction_force_obstacle0_x"]).max() < 1e-12 * force
