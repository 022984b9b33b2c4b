"""A guaranteed upper bound on lambda_max(M^-1 K) for the stable time step 2 / sqrt(lambda_max).

MEMM is stable for dt < 2 / sqrt(lambda_max(M^-1 K)) (leapfrog limit, memm.py). SLEPc finds
lambda_max to rtol 1e-8 (``DEMDiscretisation.eigenvalues``) in a time that grows about
quadratically with the cells (220 s at 80,000). This module bounds it instead.

With Kt = M^-1/2 K M^-1/2 (M the lumped mass, diagonal) and any positive vector w,

    lambda_max(M^-1 K) = lambda_max(Kt) <= rho(|Kt|) <= max_i (|Kt| w)_i / w_i

(the spectral radius of a matrix is at most that of its entrywise absolute value, and that of a
nonnegative matrix at most any weighted row sum: Gershgorin for D^-1 |Kt| D, D = diag(w);
Collatz-Wielandt). w = 1 is Gershgorin's bound; w_{k+1} = |Kt| w_k (power iteration on |Kt|)
gives a non-increasing sequence of bounds towards rho(|Kt|). Starting from the diagonal of Kt
instead of 1 reaches in two passes what w = 1 reaches in three. The rows of |K| = |Q^T Q| are
computed from the rows of Q (kernels.c, ``dem_gram_abs_rowsums``) without storing K: for each
owned dof, the rows of Q through it (the local rows of Q^T), fetched from their owners. The sums
run in the order of the global numbering, so the bound is the same, to the bit, on any number
of processes.

Measured against SLEPc (docs/bench/README.md, ``bound_tightness``): rho(|Kt|) is lambda_max
itself on a 1D bar and 1.1-1.4 lambda_max on the 2D and 3D scenes, so the bound's time step is
0.85-1 times the true limit.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.factored import FactoredStiffness, local_numbering
from dolfinx_dem.kernels import lib, pointer

#: Relative margin added to the computed bound for its rounding: each entry of |K| is a sum of
#: a few tens of products, so the computed row sums are within ~1e-14 of the exact ones.
ROUNDING_MARGIN = 1e-12


def largest_eigenvalue_bound(factored: FactoredStiffness, QT: PETSc.Mat, inverse_mass: PETSc.Vec,
                             iterations: int = 3) -> float:
    """An upper bound on lambda_max(M^-1 Q^T Q) (rad^2/s^2): the smallest of ``iterations``
    weighted row sums max_i (|Kt| w)_i / w_i, w = d, |Kt| d, |Kt|^2 d, ... with d the diagonal
    of Kt (module docstring).

    factored : the local rows of Q (``DEMDiscretisation.factored``); QT : Q^T, with the rows of
    the owned dofs; inverse_mass : M^-1 with the layout of the dofs. Costs ``iterations`` passes
    over the rows of Q through each owned dof, plus fetching the rows of other processes once.
    """
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    Q = factored.Q
    comm = Q.comm.tompi4py()
    qt_ptr, qt_rows, qt_vals = QT.getValuesCSR()  # for each owned dof i: rows k of Q with Q_ki != 0
    row_start, row_stop = Q.getOwnershipRange()
    remote, qt_local = local_numbering(qt_rows, row_start, row_stop)
    needed = np.concatenate([np.arange(row_start, row_stop, dtype=PETSc.IntType), remote])
    self_comm = PETSc.COMM_SELF
    dof_start, dof_stop = Q.getOwnershipRangeColumn()
    if comm.allreduce(len(remote), op=MPI.MAX) == 0:  # e.g. one process: the local rows are all
        ptr, cols, vals, ghosts = factored.rowptr, factored.cols, factored.vals, factored.ghosts
    else:
        all_cols = PETSc.IS().createStride(Q.getSize()[1], 0, 1, comm=self_comm)
        (rows,) = Q.createSubMatrices(PETSc.IS().createGeneral(needed, comm=self_comm), all_cols)
        ptr, cols, vals = rows.getValuesCSR()
        rows.destroy()
        ghosts, cols = local_numbering(cols, dof_start, dof_stop)  # dofs two rows away from the owned ones
        ptr, vals = np.ascontiguousarray(ptr, dtype=np.int32), np.ascontiguousarray(vals)
    reach = np.concatenate([np.arange(dof_start, dof_stop, dtype=PETSc.IntType), ghosts])
    qt_ptr, qt_vals = np.ascontiguousarray(qt_ptr, dtype=np.int32), np.ascontiguousarray(qt_vals)

    x = inverse_mass.duplicate()
    x_reach = PETSc.Vec().createSeq(len(reach), comm=self_comm)
    scatter = PETSc.Scatter().create(x, PETSc.IS().createGeneral(reach, comm=self_comm), x_reach, None)
    s = np.sqrt(inverse_mass.array_r)
    n = len(s)
    acc = np.zeros(len(reach))  # the kernel's workspace, left zero
    r = np.empty(n)
    # start from the diagonal of Kt (cheaper than w = 1 for the same bound: 2 passes, not 3)
    squares = scipy.sparse.csr_matrix((qt_vals**2, qt_local, qt_ptr), shape=(n, len(needed)))
    w = s**2 * np.asarray(squares.sum(axis=1)).ravel()  # each row summed in its own order
    w = np.maximum(w / comm.allreduce(w.max() if n else 0.0, op=MPI.MAX), np.finfo(float).tiny)
    bound = np.inf
    for _ in range(iterations):
        x.array[:] = s * w
        scatter.scatter(x, x_reach, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        lib.dem_gram_abs_rowsums(n, pointer(qt_ptr), pointer(qt_local), pointer(qt_vals), pointer(ptr),
                                 pointer(cols), pointer(vals), pointer(x_reach.array), pointer(r), pointer(acc))
        b = s * r  # (|Kt| w)_i
        local = (b / w).max() if n else 0.0
        bound = min(bound, comm.allreduce(local, op=MPI.MAX))
        top = comm.allreduce(b.max() if n else 0.0, op=MPI.MAX)
        w = np.maximum(b / top, np.finfo(float).tiny)  # a dof without stiffness keeps a positive weight
    x.destroy()
    x_reach.destroy()
    scatter.destroy()
    return float(bound) * (1.0 + ROUNDING_MARGIN)
