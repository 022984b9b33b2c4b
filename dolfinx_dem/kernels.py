"""The compiled kernels of ``kernels.c`` (cffi, built at install) and C pointers to numpy arrays."""

from __future__ import annotations

import numpy as np

try:
    from dolfinx_dem._kernels import ffi, lib
except ImportError as err:  # pragma: no cover - an install without the build step
    raise ImportError(
        "dolfinx_dem's compiled kernels (dolfinx_dem._kernels) are missing: install the package with "
        "`make setup` or `pip install --no-build-isolation -e .`, which builds them from kernels.c with cffi"
    ) from err

_C_ARRAYS = {np.dtype(np.float64): "double[]", np.dtype(np.int32): "int32_t[]", np.dtype(np.int64): "int64_t[]",
             np.dtype(np.int8): "int8_t[]"}


def pointer(array: np.ndarray | None):
    """A C array over the data of a C-contiguous float64, int32, int64 or int8 array, passed to
    the kernels as a pointer (NULL for None); it keeps the array alive, and a non-contiguous array
    raises (numpy's buffer). One ``ffi.from_buffer`` call: the per-step glue calls it some 70
    times."""
    if array is None:
        return ffi.NULL
    ctype = _C_ARRAYS.get(array.dtype)
    if ctype is None:
        raise TypeError(f"the compiled kernels take float64, int32, int64 or int8 arrays, not {array.dtype}")
    return ffi.from_buffer(ctype, array)
