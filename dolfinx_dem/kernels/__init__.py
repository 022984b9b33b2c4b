"""The compiled kernels (cffi, built at install from the C files of this folder, declared in
``dem_kernels.h``), C pointers to numpy arrays and the kernels' structs.

One C file per concern: ``rows.c`` (energy rows, MEMM update, the stability bound's row sums),
``overlap.c`` (overlap geometry), ``flight.c`` (free flight, screen, contact state),
``integral.c`` (events, exact force integral), ``outputs.c`` (facet corrections, forces
between bodies, penetration), ``rigid.c`` (contact with rigid obstacles: force integral,
energy). The kernels take structs (``dem_csr``, ``dem_pairs``, ...) instead of long argument
lists: Python builds each once where its arrays are made (``Struct``, ``csr``) and passes its
pointer (``Struct.c``) per call."""

from __future__ import annotations

import numpy as np
import scipy.sparse

try:
    from dolfinx_dem.kernels._kernels import ffi, lib
except ImportError as err:  # pragma: no cover - an install without the build step
    raise ImportError(
        "dolfinx_dem's compiled kernels (dolfinx_dem.kernels._kernels) are missing: install the package with "
        "`make setup` or `pip install --no-build-isolation -e .`, which builds them with cffi"
    ) from err

_C_ARRAYS = {np.dtype(np.float64): "double[]", np.dtype(np.int32): "int32_t[]", np.dtype(np.int64): "int64_t[]",
             np.dtype(np.int8): "int8_t[]"}
_INT32_MAX = np.iinfo(np.int32).max


def pointer(array: np.ndarray | None):
    """A C array over the data of a C-contiguous float64, int32, int64 or int8 array, passed to
    the kernels as a pointer (NULL for None); it keeps the array alive, and a non-contiguous array
    raises (numpy's buffer). One ``ffi.from_buffer`` call."""
    if array is None:
        return ffi.NULL
    ctype = _C_ARRAYS.get(array.dtype)
    if ctype is None:
        raise TypeError(f"the compiled kernels take float64, int32, int64 or int8 arrays, not {array.dtype}")
    return ffi.from_buffer(ctype, array)


class Struct:
    """A struct of ``dem_kernels.h`` (``ctype``, e.g. "dem_csr") whose pointer fields point into
    numpy arrays, kept alive with it: pass ``c`` (a pointer to the struct) to the kernels.

    Fields are given by name: a numpy array (its data: ``pointer``; a wrong dtype raises) or
    None (NULL), another ``Struct`` (copied into a struct field, kept alive), a cffi pointer
    (kept alive: its memory must outlive the struct), or a number. Fields not given are zero
    (NULL). ``arrays`` holds the numpy arrays given, by field name."""

    __slots__ = ("c", "arrays", "_keep")

    def __init__(self, ctype: str, **fields):
        c = self.c = ffi.new(ctype + " *")
        self.arrays, self._keep = {}, []
        keep = self._keep
        for name, value in fields.items():
            if isinstance(value, np.ndarray):
                self.arrays[name] = value
                value = pointer(value)
                keep.append(value)
            elif value is None:
                value = ffi.NULL
            elif isinstance(value, Struct):
                keep.append(value)
                value = value.c[0]
            elif isinstance(value, ffi.CData):
                keep.append(value)
            setattr(c, name, value)


def csr(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray | None, n_cols: int) -> Struct:
    """A ``dem_csr`` over CSR arrays (len(indptr) - 1 rows; data None: a pattern), as int32
    indices and float64 values (converted if they are not: check with ``.arrays``)."""
    if len(indptr) == 0:
        raise ValueError("a CSR matrix needs indptr[0] = 0 at least")
    if int(indptr[-1]) > _INT32_MAX or n_cols > _INT32_MAX:
        raise ValueError(f"a CSR matrix of {int(indptr[-1])} entries and {n_cols} columns: the kernels take at most "
                         f"{_INT32_MAX} of each")
    return Struct("dem_csr", indptr=np.ascontiguousarray(indptr, dtype=np.int32),
                  indices=np.ascontiguousarray(indices, dtype=np.int32),
                  data=None if data is None else np.ascontiguousarray(data, dtype=np.float64),
                  n_rows=len(indptr) - 1, n_cols=int(n_cols))


def csr_of(A: scipy.sparse.csr_matrix) -> Struct:
    """``csr`` of a scipy CSR matrix."""
    if not isinstance(A, scipy.sparse.csr_matrix):
        raise TypeError(f"csr_of takes a scipy CSR matrix, not {type(A).__name__}")
    return csr(A.indptr, A.indices, A.data, A.shape[1])


def arena():
    """Work memory of the contact kernels (``dem_arena``), kept between their calls and freed
    with the object."""
    return ffi.gc(ffi.new("dem_arena *"), lib.dem_arena_free)
