"""The stiffness K = Q^T Q applied in one pass over the rows of Q (compiled kernel, kernels/rows.c).

Q = [S; J] (operators.py, eq. (11), (13)) has about half the nonzeros of K, and PETSc applies
K in factored form as two MatMults, Q then a stored Q^T, reading Q twice. ``FactoredStiffness``
reads each local row of Q once:

    y_i <- alpha y_i + scale (Q x)_i,    z += y_i Q_i^T    (while the row is in cache),

so that y, the energy rows of eq. (11) and (13), can be kept from step to step (memm.py) and
their squares summed in the same pass. Rounding: the same products and sums as a MatMult, in
the order of the row.

Layout: the process's rows of Q with local column numbers, owned dofs first, then the ghosts
(the held dofs of other processes, ``DEMDiscretisation.columns``). The arrays are those of
``DEMDiscretisation.rows.Q``, whose own rows are its first rows: Q is stored once.
``create_vector`` makes PETSc vectors with those ghosts, in the layout of the DG0 dofs.
Communication is the caller's: a forward ghost update of x before ``apply``, a reverse (adding)
update of z after.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
from petsc4py import PETSc

from dolfinx_dem.errors import InputError
from dolfinx_dem.kernels import csr, lib, pointer


def local_numbering(ids: np.ndarray, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
    """Local numbers of global indices ``ids``: those of this process, in [start, stop), first
    (id - start), then the others (``ghosts``, sorted) numbered from stop - start on. Returns
    (ghosts, local numbers (int32)); only the ghosts are sorted."""
    mine = (ids >= start) & (ids < stop)
    ghosts = np.unique(ids[~mine]).astype(PETSc.IntType)
    local = ids - start
    local[~mine] = (stop - start) + np.searchsorted(ghosts, ids[~mine])
    return ghosts, local.astype(np.int32)


class FactoredStiffness:
    """K = Q^T Q from the local rows of Q (no copy: the kernel reads the arrays of ``rows``).

    Parameters
    ----------
    comm : the communicator of the dofs.
    rows : CSR whose first ``n_rows`` rows are this process's rows of Q, with local column numbers:
        the ``n_owned`` owned dofs, then the ``ghosts`` (global dof numbers) in that order; the
        first ``n_elastic`` rows are elastic rows (S), the others stabilisation rows (J).
    """

    def __init__(self, comm, rows: scipy.sparse.csr_matrix, n_rows: int, n_elastic: int, n_owned: int,
                 ghosts: np.ndarray):
        if rows.indptr.dtype != np.int32 or rows.indices.dtype != np.int32 or rows.data.dtype != np.float64:
            raise InputError("the rows of Q need int32 indices and float64 values")
        self.comm = comm
        self.ghosts = np.asarray(ghosts, dtype=PETSc.IntType)
        self.n_owned = int(n_owned)
        self.n_rows = int(n_rows)
        self.n_elastic = int(n_elastic)
        self.rowptr, self.cols, self.vals = rows.indptr[: self.n_rows + 1], rows.indices, rows.data
        self.csr = csr(self.rowptr, self.cols, self.vals, self.n_owned + len(self.ghosts))  # the kernels' Q
        self._work = None

    def create_vector(self) -> PETSc.Vec:
        """A zero vector over the dofs with this operator's ghosts."""
        v = PETSc.Vec().createGhost(self.ghosts, size=(self.n_owned, PETSc.DECIDE), comm=self.comm)
        with v.localForm() as local:
            local.set(0.0)
        return v

    @staticmethod
    def local_array(v: PETSc.Vec) -> np.ndarray:
        """The owned and ghost entries of a vector of ``create_vector`` (a view: it shares the
        vector's memory)."""
        with v.localForm() as local:
            return local.array

    def bind(self, x: PETSc.Vec, y: np.ndarray, z: PETSc.Vec, sums: np.ndarray,
             shift_index: np.ndarray | None = None, shift: np.ndarray | None = None):
        """``apply(alpha, scale)``: y <- alpha y + scale Q x, z += Q^T y (local part, ghosts
        included) and sums[0], sums[1] += the squares of y over the elastic and the
        stabilisation rows; x and z are vectors of ``create_vector``, y has ``n_rows`` entries,
        sums at least 2. With ``shift_index`` (int32, one per local dof, ghosts included), x_j -
        shift[shift_index[j]] replaces x_j. Pointers are taken once: the arrays must keep their
        addresses."""
        if y.shape != (self.n_rows,) or y.dtype != np.float64:
            raise InputError(f"y needs {self.n_rows} float64 entries")
        px, pz = pointer(self.local_array(x)), pointer(self.local_array(z))
        py, ps, pi, pshift = pointer(y), pointer(sums), pointer(shift_index), pointer(shift)
        Q, n_elastic, kernel = self.csr.c, self.n_elastic, lib.dem_gram_apply

        def apply(alpha: float, scale: float):
            kernel(Q, n_elastic, px, pi, pshift, py, alpha, scale, pz, ps)

        return apply

    def residual(self, w: PETSc.Vec | None, q: tuple[np.ndarray, np.ndarray], out: PETSc.Vec) -> np.ndarray:
        """a = Q w + q and out = Q^T a (owned dofs, summed over processes), for the occasional
        product outside time stepping (``DEMDiscretisation.force``, ``energies``, ``load``);
        w (owned dofs; None: zero) and out are vectors of the dof layout, q = (rows, values) is
        zero off ``rows``. Returns the squares of a summed over this process's elastic and
        stabilisation rows. Collective."""
        if self._work is None:
            self._work = (self.create_vector(), self.create_vector(), np.zeros(2))
        x, z, sums = self._work
        a = np.empty(self.n_rows)  # not kept: 8 bytes per row, as much as the vectors of 3 dofs per row
        x_local = self.local_array(x)
        if w is None:
            x_local[:] = 0.0
        else:
            x_local[: self.n_owned] = w.array_r
            x.ghostUpdate(PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        self.local_array(z)[:] = 0.0
        a[:] = 0.0
        a[q[0]] = q[1]
        sums[:] = 0.0
        self.bind(x, a, z, sums)(1.0, 1.0 if w is not None else 0.0)
        z.ghostUpdate(PETSc.InsertMode.ADD_VALUES, PETSc.ScatterMode.REVERSE)
        out.array[:] = z.array_r
        return sums.copy()
