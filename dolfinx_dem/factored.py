"""The stiffness K = Q^T Q applied in one pass over the rows of Q (compiled kernel, kernels.c).

Q = [S; J] (operators.py, eq. (11), (13)) has about half the nonzeros of K, and PETSc applies
K in factored form as two MatMults, Q then a stored Q^T, reading Q twice. ``FactoredStiffness``
reads each local row of Q once:

    y_i <- alpha y_i + scale (Q x)_i,    z += y_i Q_i^T    (while the row is in cache),

so that y, the energy rows of eq. (11) and (13), can be kept from step to step (memm.py) and
their squares summed in the same pass. Rounding: the same products and sums as a MatMult, in
the order of the row.

Layout: the process's rows of Q with local column numbers, owned dofs first, then the ghosts
(the dofs of other processes that local rows read). ``create_vector`` makes PETSc vectors with
those ghosts; their global form has the layout of ``Q.createVecRight()``. Communication is the
caller's: a forward ghost update of x before ``apply``, a reverse (adding) update of z after.
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc

from dolfinx_dem.kernels import lib, pointer


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
    """K = Q^T Q from the local rows of a distributed PETSc AIJ matrix Q.

    Parameters
    ----------
    Q : the energy rows, (n_rows, n_dofs); its first ``n_elastic`` local rows are elastic rows
        (S), the others stabilisation rows (J).
    n_elastic : number of local rows of S.
    """

    def __init__(self, Q: PETSc.Mat, n_elastic: int):
        self.Q, self.comm = Q, Q.comm
        indptr, indices, values = Q.getValuesCSR()
        start, stop = Q.getOwnershipRangeColumn()
        self.ghosts, cols = local_numbering(indices, start, stop)  # ghosts: global dofs
        self.n_owned = stop - start
        self.n_rows = len(indptr) - 1
        self.n_elastic = int(n_elastic)
        self.rowptr = np.ascontiguousarray(indptr, dtype=np.int32)
        self.cols = np.ascontiguousarray(cols, dtype=np.int32)
        self.vals = np.ascontiguousarray(values, dtype=np.float64)
        self._csr = (pointer(self.rowptr), pointer(self.cols), pointer(self.vals))

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
            raise ValueError(f"y needs {self.n_rows} float64 entries")
        px, pz = pointer(self.local_array(x)), pointer(self.local_array(z))
        py, ps, pi, pshift = pointer(y), pointer(sums), pointer(shift_index), pointer(shift)
        rowptr, cols, vals = self._csr
        n_rows, n_elastic, kernel = self.n_rows, self.n_elastic, lib.dem_gram_apply

        def apply(alpha: float, scale: float):
            kernel(n_rows, n_elastic, rowptr, cols, vals, px, pi, pshift, py, alpha, scale, pz, ps)

        return apply
