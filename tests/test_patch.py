"""The contact patches (contact/patch.py): the scatter of a patch's dofs between processes, the
compiled sums, the exact integral of a negative part and the pieces cut at break times."""

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.contact.patch import PatchScatter, negative_part_integral, scatter_sum


@pytest.mark.mpi
def test_a_patch_gathers_and_adds_any_processes_dofs():
    """Every process asks for dofs owned anywhere (its own choice, repeated and unsorted):
    ``gather`` returns their values, ``add`` sums every process's contributions into their
    owners (the sum over processes of what each added, checked against the global formula)."""
    comm = MPI.COMM_WORLD
    n_local = 5 + comm.rank
    vec = PETSc.Vec().createMPI((n_local, PETSc.DECIDE), comm=comm)
    lo, hi = vec.getOwnershipRange()
    N = vec.getSize()
    vec.array[:] = 10.0 * np.arange(lo, hi) + 1.0
    rng = np.random.default_rng(comm.rank)
    dofs = rng.integers(0, N, 7)
    scatter = PatchScatter(vec, dofs)
    assert len(scatter) == len(dofs)
    assert np.array_equal(scatter.gather(vec), 10.0 * dofs + 1.0)
    out = vec.duplicate()
    out.set(0.0)
    scatter.add(np.full(len(dofs), 1.0), out, scale=2.0)
    counts = np.zeros(N)
    for r in range(comm.size):  # what every process added, known from its seed
        np.add.at(counts, np.random.default_rng(r).integers(0, N, 7), 2.0)
    assert np.array_equal(out.array_r, counts[lo:hi])


def test_scatter_sum_is_add_at_bit_for_bit():
    rng = np.random.default_rng(1)
    index, values = rng.integers(0, 9, 200), rng.standard_normal((200, 3))
    expected = np.zeros((9, 3))
    np.add.at(expected, index, values)
    assert np.array_equal(scatter_sum(index, values, 9), expected)
    expected1 = np.zeros(9)
    np.add.at(expected1, index, values[:, 0])
    assert np.array_equal(scatter_sum(index, values[:, 0], 9), expected1)


def test_the_negative_part_integral_is_exact():
    """int_0^dt min(g0 + s tau, 0) dtau against a fine midpoint sum, in every case: negative
    throughout, positive throughout, a root inside from either side, a zero slope."""
    g0 = np.array([-1.0, 1.0, -1.0, 1.0, -2.0, 0.5])
    slope = np.array([-1.0, 1.0, 4.0, -4.0, 0.0, 0.0])
    dt, m = 0.5, 200000
    tau = (np.arange(m) + 0.5) * dt / m
    fine = np.minimum(g0[:, None] + slope[:, None] * tau, 0.0).sum(axis=1) * dt / m
    exact = negative_part_integral(g0, slope, dt)
    assert np.abs(exact - fine).max() < 1e-9
    assert exact[1] == 0.0 and exact[5] == 0.0 and exact[4] == -1.0


def test_piecewise_midpoints_cut_each_row_at_its_sorted_times():
    """The compiled cutting of [0, dt] at each row's break times (any order and count per row;
    rows without any keep one piece), against sorting them row by row."""
    from dolfinx_dem.contact.patch import piecewise_midpoints

    rng = np.random.default_rng(3)
    n, dt = 7, 0.5
    rows = rng.integers(0, n - 1, 40)  # the last row has no break
    times = rng.uniform(0.0, dt, 40)
    times[5] = times[6]  # a repeated time: an empty piece
    rows[6] = rows[5]
    mid, length = piecewise_midpoints(rows, times, n, dt)
    k = np.bincount(rows, minlength=n).max()
    assert mid.shape == length.shape == (n, k + 1)
    for r in range(n):
        points = np.concatenate([[0.0], np.sort(times[rows == r]), np.full(k - (rows == r).sum(), dt), [dt]])
        assert np.array_equal(mid[r], 0.5 * (points[:-1] + points[1:]))
        assert np.array_equal(length[r], np.diff(points))
    assert np.array_equal(length[n - 1], [dt] + [0.0] * k)
    empty = piecewise_midpoints(np.zeros(0, dtype=np.int64), np.zeros(0), 3, dt)
    assert np.array_equal(empty[0], np.full((3, 1), 0.5 * dt)) and np.array_equal(empty[1], np.full((3, 1), dt))
