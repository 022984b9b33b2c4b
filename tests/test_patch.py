"""The contact patches (contact/patch.py): the scatter of a patch's dofs between processes; the
pieces that break times cut a step into (the compiled ``dem_piecewise_midpoints``)."""

import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.contact.patch import PatchScatter
from dolfinx_dem.kernels import lib, pointer


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


def test_piecewise_midpoints_cut_each_row_at_its_sorted_times():
    """The compiled cutting of [0, dt] at each row's break times (any order and count per row;
    rows without any keep one piece), against sorting them row by row."""

    def piecewise_midpoints(rows, times, n, dt):
        counts = np.bincount(rows, minlength=n)
        k = int(counts.max(initial=0))
        points, mid, length = np.empty((n, k + 2)), np.empty((n, k + 1)), np.empty((n, k + 1))
        lib.dem_piecewise_midpoints(len(rows), pointer(rows), pointer(times), n, k, dt, pointer(counts),
                                    pointer(points), pointer(mid), pointer(length))
        return mid, length

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
