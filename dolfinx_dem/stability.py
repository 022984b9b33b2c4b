"""A guaranteed upper bound on lambda_max(M^-1 K) for the stable time step 2 / sqrt(lambda_max).

MEMM is stable for dt < 2 / sqrt(lambda_max(M^-1 K)) (leapfrog limit, memm.py). SLEPc finds
lambda_max to rtol 1e-8 (``eigenvalues``) in a time that grows about
quadratically with the cells (220 s at 80,000). This module bounds it instead.

With Kt = M^-1/2 K M^-1/2 (M the lumped mass, diagonal) and any positive vector w,

    lambda_max(M^-1 K) = lambda_max(Kt) <= rho(|Kt|) <= max_i (|Kt| w)_i / w_i

(the spectral radius of a matrix is at most that of its entrywise absolute value, and that of a
nonnegative matrix at most any weighted row sum: Gershgorin for D^-1 |Kt| D, D = diag(w);
Collatz-Wielandt). w = 1 is Gershgorin's bound; w_{k+1} = |Kt| w_k (power iteration on |Kt|)
gives a non-increasing sequence of bounds towards rho(|Kt|). Starting from the diagonal of Kt
instead of 1 reaches in two passes what w = 1 reaches in three. The rows of |K| = |Q^T Q| are
computed from the rows of Q (kernels/rows.c, ``dem_gram_abs_rowsums``) without storing K: for each
owned dof, the rows of Q through it (the local rows of Q^T), those of other processes sent by
their owners (neighbours only). The sums run in an order of rows and columns that does not
depend on the partition, so the bound is the same, to the bit, on any number of processes.

Measured against SLEPc (docs/bench/README.md, ``bound_tightness``): rho(|Kt|) is lambda_max
itself on a 1D bar and 1.1-1.4 lambda_max on the 2D and 3D scenes, so the bound's time step is
0.85-1 times the true limit.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.errors import InputError, SolverError
from dolfinx_dem.factored import FactoredStiffness
from dolfinx_dem.halo import alltoall
from dolfinx_dem.kernels import Struct, csr, ffi, lib, pointer

#: Relative margin added to the computed bound for its rounding: each entry of |K| is a sum of
#: a few tens of products, so the computed row sums are within ~1e-14 of the exact ones.
ROUNDING_MARGIN = 1e-12


def _ranges(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The concatenation of the ranges [starts[k], starts[k] + lengths[k])."""
    lengths = np.asarray(lengths, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    return np.repeat(np.asarray(starts, dtype=np.int64) - offsets, lengths) + np.arange(lengths.sum())


def _rows_of_other_processes(factored: FactoredStiffness, row_keys: np.ndarray, ghost_owners: np.ndarray,
                             start: int):
    """The rows of Q of other processes that read this process's dofs: each process sends its
    rows that read ghost dofs to the owners of those dofs (neighbours only). Returns their keys,
    and their CSR with global column numbers, rows in increasing key."""
    comm, n_od = factored.comm, factored.n_owned
    rowptr, cols, vals = factored.rowptr, factored.cols, factored.vals
    block = 2**22  # entries scanned at a time (no mask of the size of Q)
    positions = np.concatenate([np.flatnonzero(cols[a : min(a + block, rowptr[-1])] >= n_od) + a
                                for a in range(0, int(rowptr[-1]), block)] + [np.empty(0, dtype=np.int64)])
    rows = np.searchsorted(rowptr, positions, side="right") - 1
    pairs = np.unique(rows.astype(np.int64) * comm.size + ghost_owners[cols[positions] - n_od])
    rows, destinations = pairs // comm.size, pairs % comm.size
    lengths = np.diff(rowptr)[rows]
    entries = _ranges(rowptr[rows], lengths)
    local = cols[entries]
    global_cols = np.where(local < n_od, start + local, factored.ghosts[np.maximum(local - n_od, 0)])
    headers, _ = alltoall(comm, destinations, np.stack([row_keys[rows], lengths], axis=1).astype(np.int64))
    payload, _ = alltoall(comm, np.repeat(destinations, lengths),
                           np.stack([global_cols.astype(np.float64), vals[entries]], axis=1))
    order = np.argsort(headers[:, 0], kind="stable")
    first = np.concatenate([[0], np.cumsum(headers[:, 1])])
    take = _ranges(first[order], headers[order, 1])
    ptr = np.concatenate([[0], np.cumsum(headers[order, 1])]).astype(np.int32)
    return headers[order, 0].copy(), ptr, payload[take, 0].astype(np.int64), payload[take, 1].copy()


#: Entries of the transposed pattern of the local rows held at a time (``_transposed_blocks``).
PATTERN_BLOCK = 2**21


def _transposed_blocks(factored: FactoredStiffness):
    """A function returning, on each call, an iterable of (first dof, ptr, rows): the transposed
    pattern of the local rows of Q (``kernels.dem_transpose_pattern``) for consecutive blocks of
    owned dofs of about ``PATTERN_BLOCK`` entries each (4 bytes per entry, a block at a time: a
    larger pattern is built again on each pass). A block scans only the rows that can reach it:
    the elastic rows and the jump rows are each in the order of their cells, so the rows through
    a block of dofs lie in one range of each (found once from each row's smallest and largest
    owned column); the cells' numbering keeps neighbours close, so the ranges are short."""
    n, n_rows, Q = factored.n_owned, factored.n_rows, factored.csr.c
    every_row = np.array([0, n_rows], dtype=np.int64)
    counts = np.empty(n + 1, dtype=np.int32)
    # the entries before each owned dof
    lib.dem_transpose_pattern(Q, pointer(every_row), 1, 0, n, pointer(counts), ffi.NULL)
    cuts = np.searchsorted(counts, np.arange(PATTERN_BLOCK, int(counts[-1]), PATTERN_BLOCK), side="right") - 1
    edges = np.unique(np.concatenate([[0], cuts, [n]]))  # block k: owned dofs edges[k] .. edges[k + 1] - 1
    del counts
    lo, hi = np.empty(n_rows, dtype=np.int32), np.empty(n_rows, dtype=np.int32)
    lib.dem_row_column_range(Q, n, pointer(lo), pointer(hi))
    ranges = []
    for a, b in zip(edges[:-1], edges[1:]):
        r = []
        for s0, s1 in ((0, factored.n_elastic), (factored.n_elastic, n_rows)):  # elastic rows, then jump rows
            through = np.flatnonzero((lo[s0:s1] < b) & (hi[s0:s1] >= a))
            if len(through):
                r += [s0 + through[0], s0 + through[-1] + 1]
        ranges.append(np.array(r, dtype=np.int64))
    del lo, hi

    def block(first: int, last: int, rows_range: np.ndarray):
        args = (Q, pointer(rows_range), len(rows_range) // 2, first, last - first)
        ptr = np.empty(last - first + 1, dtype=np.int32)
        lib.dem_transpose_pattern(*args, pointer(ptr), ffi.NULL)
        rows = np.empty(int(ptr[-1]), dtype=np.int32)
        lib.dem_transpose_pattern(*args, pointer(ptr), pointer(rows))
        return int(first), ptr, rows

    if len(edges) <= 2:  # one block (or none): built once
        once = [block(edges[0], edges[-1], ranges[0])] if n else []
        return lambda: once
    return lambda: (block(a, b, r) for a, b, r in zip(edges[:-1], edges[1:], ranges))


def eigenvalue_bounds(factored: FactoredStiffness, row_keys: np.ndarray, ghost_owners: np.ndarray,
                      inverse_mass: PETSc.Vec, iterations: int = 3) -> tuple[float, float]:
    """A lower and an upper bound on lambda_max(M^-1 Q^T Q) (rad^2/s^2). Upper: the smallest of
    ``iterations`` weighted row sums max_i (|Kt| w)_i / w_i, w = d, |Kt| d, |Kt|^2 d, ... with d
    the diagonal of Kt (module docstring). Lower: max_i d_i = max_i e_i . Kt e_i (a Rayleigh
    quotient), so that a step dt > 2 / sqrt(max_i d_i) is beyond the stability limit whatever the
    modes.

    factored : the local rows of Q (``DEMDiscretisation.factored``); row_keys : a number of each
    local row, increasing along them, that orders the rows of all processes independently of the
    partition; ghost_owners : the rank owning each ghost dof of ``factored``; inverse_mass : M^-1
    with the layout of the dofs. Costs ``iterations`` passes over the rows of Q through each owned
    dof, the pattern of the transposed local rows (4 bytes per entry of Q, freed on return) and
    fetching the rows of other processes that reach owned dofs once (from the neighbours only).
    """
    if iterations < 1:
        raise InputError(f"iterations must be >= 1, got {iterations}")
    comm, n = factored.comm, factored.n_owned
    if len(row_keys) != factored.n_rows or np.any(row_keys[1:] <= row_keys[:-1]):
        raise InputError("row_keys must increase along the local rows of Q")
    start, stop = inverse_mass.getOwnershipRange()
    # The pattern of Q^T on the owned dofs: for each, this process's rows through it (in row
    # order, so in key order; ``_transposed_blocks``), and the rows of other processes through it.
    keys2, ptr2, global2, vals2 = _rows_of_other_processes(factored, row_keys, ghost_owners, start)
    mine2 = (global2 >= start) & (global2 < stop)
    rows2 = np.repeat(np.arange(len(keys2), dtype=np.int32), np.diff(ptr2))
    order = np.argsort(global2[mine2], kind="stable")  # by owned dof, rows in key order
    dof2 = global2[mine2][order] - start
    qt2_ptr = np.concatenate([[0], np.cumsum(np.bincount(dof2, minlength=n))]).astype(np.int32)
    qt2_rows = np.ascontiguousarray(rows2[mine2][order])
    # the dofs the rows read: the held ones (owned, then ghosts), then any others
    ghosts = factored.ghosts
    by_value = np.argsort(ghosts)
    other = global2[~mine2]
    at = np.searchsorted(ghosts[by_value], other)
    held = at < len(ghosts)
    held[held] = ghosts[by_value[at[held]]] == other[held]
    extras, extra_index = np.unique(other[~held], return_inverse=True)
    local_other = np.empty(len(other), dtype=np.int64)
    local_other[held] = n + by_value[at[held]]
    local_other[~held] = n + len(ghosts) + extra_index
    cols2 = np.empty(len(global2), dtype=np.int32)
    cols2[mine2] = global2[mine2] - start
    cols2[~mine2] = local_other
    reach = np.concatenate([np.arange(start, stop, dtype=PETSc.IntType), ghosts, extras.astype(PETSc.IntType)])

    self_comm = PETSc.COMM_SELF
    x = inverse_mass.duplicate()
    x_reach = PETSc.Vec().createSeq(len(reach), comm=self_comm)
    scatter = PETSc.Scatter().create(x, PETSc.IS().createGeneral(reach, comm=self_comm), x_reach, None)
    # the rows of Q through the owned dofs: this process's (their pattern by blocks, below), and
    # those of other processes
    row_keys = np.ascontiguousarray(row_keys)
    other = Struct("dem_row_set", rows=csr(ptr2, cols2, vals2, len(reach)), key=keys2, qt_ptr=qt2_ptr,
                   qt_rows=qt2_rows)
    s = np.sqrt(inverse_mass.array_r)
    acc = np.zeros(len(reach))  # the kernel's workspace, left zero
    r = np.empty(n)
    blocks = _transposed_blocks(factored)

    def rowsums(x):
        for first, qt_ptr, qt_rows in blocks():
            own = Struct("dem_row_set", rows=factored.csr, key=row_keys, qt_ptr=qt_ptr, qt_rows=qt_rows)
            lib.dem_gram_abs_rowsums(first, len(qt_ptr) - 1, own.c, other.c, x, pointer(r), pointer(acc))

    # start from the diagonal of Kt (cheaper than w = 1 for the same bound: 2 passes, not 3)
    rowsums(ffi.NULL)
    w = s**2 * r
    lower = comm.allreduce(w.max() if n else 0.0, op=MPI.MAX)
    w = np.maximum(w / lower, np.finfo(float).tiny)
    bound = np.inf
    for _ in range(iterations):
        np.multiply(s, w, out=x.array)
        scatter.scatter(x, x_reach, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        rowsums(pointer(x_reach.array))
        b = np.multiply(s, r, out=r)  # (|Kt| w)_i, in place (vectors of the mesh's size: memory)
        local = np.divide(b, w, out=w).max() if n else 0.0  # w is replaced below
        bound = min(bound, comm.allreduce(local, op=MPI.MAX))
        top = comm.allreduce(b.max() if n else 0.0, op=MPI.MAX)
        # a dof without stiffness keeps a positive weight
        w = np.maximum(np.divide(b, top, out=w), np.finfo(float).tiny, out=w)
    x.destroy()
    x_reach.destroy()
    scatter.destroy()
    return float(lower) * (1.0 - ROUNDING_MARGIN), float(bound) * (1.0 + ROUNDING_MARGIN)


def eigenvalues(
    K: PETSc.Mat, inverse_mass: PETSc.Vec, n: int = 1, largest: bool = False, rtol: float = 1e-10
) -> np.ndarray:
    """The n largest or smallest eigenvalues omega^2 of M^-1 K (rad^2/s^2), ascending, for the
    stiffness K and the inverse lumped mass M^-1 (a vector).

    SLEPc on the symmetric M^-1/2 K M^-1/2 (M is diagonal); the smallest by shift-and-invert
    around 0 with a direct LU solve (MUMPS where PETSc has it).
    """
    from slepc4py import SLEPc

    A = K.copy()
    scale = inverse_mass.copy()
    scale.sqrtabs()
    A.diagonalScale(scale, scale)
    eps = SLEPc.EPS().create(K.getComm())
    eps.setOperators(A)
    eps.setProblemType(SLEPc.EPS.ProblemType.HEP)
    eps.setDimensions(n, max(2 * n + 1, 32))
    eps.setTolerances(rtol, 20000)
    if largest:
        eps.setWhichEigenpairs(SLEPc.EPS.Which.LARGEST_REAL)
    else:
        eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
        eps.setTarget(0.0)
        st = eps.getST()
        st.setType(SLEPc.ST.Type.SINVERT)
        ksp = st.getKSP()
        ksp.setType(PETSc.KSP.Type.PREONLY)
        ksp.getPC().setType(PETSc.PC.Type.LU)
        if PETSc.Sys.hasExternalPackage("mumps"):
            ksp.getPC().setFactorSolverType("mumps")
    eps.solve()
    if eps.getConverged() < n:
        raise SolverError(f"SLEPc converged only {eps.getConverged()} of {n} eigenvalues of M^-1 K")
    values = np.array([eps.getEigenvalue(i).real for i in range(eps.getConverged())])
    eps.destroy()
    A.destroy()
    return np.sort(values)[-n:] if largest else np.sort(values)[:n]
