"""Contact patches: the process-local piece of the DEM that a contact model works on.

A contact model changes the reconstructions of a few boundary facets, hence a few energy rows
a = Q u + q (``DEMDiscretisation.rows``). Each process handles the candidate facets of its owned
cells, and also knows those of the cells in its first halo layer: together they touch every row
it holds for its owned cells and facets (geometry.py), so the energy change on its own rows and
the forces of its own facets are computed from local data only. ``PatchScatter`` brings the
values of the few dofs these rows and facets read from the distributed vectors (a PETSc VecScatter
of exactly those dofs: no gather of the whole contact boundary), and adds the contact forces back
into the distributed force vector (the reverse scatter, summing over processes).
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from dolfinx_dem.kernels import lib, pointer


def scatter_sum(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """out[index[k]] += values[k] for values of shape (k,) or (k, m), into zeros of n rows: the
    sums of ``np.add.at`` in the same order (the same bits), by ``np.bincount`` per column, many
    times faster on numpy 1.24."""
    if values.ndim == 1:
        return np.bincount(index, weights=values, minlength=n)
    return np.stack([np.bincount(index, weights=values[:, k], minlength=n) for k in range(values.shape[1])],
                    axis=1).reshape(n, *values.shape[1:])


class PatchScatter:
    """Values of distributed vectors (layout of ``template``) at the global dofs ``dofs``, and
    the sum of per-process contributions at those dofs back into a distributed vector.
    Collective: every process of ``template``'s communicator calls ``gather`` and ``add``."""

    def __init__(self, template: PETSc.Vec, dofs: np.ndarray):
        self.dofs = np.asarray(dofs, dtype=PETSc.IntType)
        self._values = np.zeros(len(self.dofs))  # the memory of the patch vector _local
        self._local = PETSc.Vec().createWithArray(self._values, comm=PETSc.COMM_SELF)
        index = PETSc.IS().createGeneral(self.dofs, comm=PETSc.COMM_SELF)
        self._scatter = PETSc.Scatter().create(template, index, self._local, None)

    def __len__(self) -> int:
        return len(self.dofs)

    def gather(self, vec: PETSc.Vec) -> np.ndarray:
        """The values of ``vec`` at the patch dofs (a copy)."""
        self._scatter.scatter(vec, self._local, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        return self._values.copy()

    def add(self, values: np.ndarray, vec: PETSc.Vec, scale: float = 1.0) -> None:
        """vec += scale * values at the patch dofs, summed over the processes."""
        np.multiply(values, scale, out=self._values)
        self.add_zeroed(vec)

    def zeroed(self) -> np.ndarray:
        """The patch's own work array, zeroed, for a caller to sum its values into and then
        ``add_zeroed`` them (no copy; valid until the next call of this scatter)."""
        self._values.fill(0.0)
        return self._values

    def add_zeroed(self, vec: PETSc.Vec) -> None:
        """vec += the values summed into the array of ``zeroed``, at the patch dofs, summed over
        the processes."""
        self._local.stateIncrease()  # written through its array
        self._scatter.scatter(self._local, vec, PETSc.InsertMode.ADD_VALUES, PETSc.ScatterMode.REVERSE)


def negative_part_integral(g0: np.ndarray, slope: np.ndarray, dt: float) -> np.ndarray:
    """int_0^dt min(g0 + slope tau, 0) dtau, exactly, for arrays g0 and slope."""
    end = g0 + slope * dt
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.where(slope != 0, -g0 / slope, np.inf)
    # the interval [a, b] of [0, dt] where the affine function is negative
    a = np.where(g0 < 0, 0.0, np.clip(root, 0.0, dt))
    b = np.where(end < 0, dt, np.clip(root, 0.0, dt))
    b = np.where((g0 >= 0) & (end >= 0), a, b)
    return (b - a) * (g0 + slope * 0.5 * (a + b))


def piecewise_midpoints(rows: np.ndarray, times: np.ndarray, n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Break times ``times`` in (0, dt) of rows ``rows`` (0 <= rows < n, any order and count per
    row): the midpoints and lengths of the pieces of [0, dt] they cut each row into, as (n, K)
    arrays; rows with fewer breaks are padded with pieces of zero length (the compiled kernel
    ``dem_piecewise_midpoints``: each row's times sorted by insertion)."""
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    times = np.ascontiguousarray(times, dtype=np.float64)
    counts = np.bincount(rows, minlength=n)
    k = int(counts.max(initial=0))
    points, mid, length = np.empty((n, k + 2)), np.empty((n, k + 1)), np.empty((n, k + 1))
    lib.dem_piecewise_midpoints(len(rows), pointer(rows), pointer(times), n, k, float(dt), pointer(counts),
                                pointer(points), pointer(mid), pointer(length))
    return mid, length
