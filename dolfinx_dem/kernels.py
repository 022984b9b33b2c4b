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

_C_TYPES = {np.dtype(np.float64): "double *", np.dtype(np.int32): "int32_t *", np.dtype(np.int64): "int64_t *",
            np.dtype(np.int8): "int8_t *"}


def pointer(array: np.ndarray | None):
    """A C pointer to the data of a contiguous float64, int32, int64 or int8 array (NULL for None).
    The array must stay alive, and at the same address, while the pointer is used."""
    if array is None:
        return ffi.NULL
    if not array.flags.c_contiguous:
        raise ValueError("kernels need contiguous arrays")
    return ffi.cast(_C_TYPES[array.dtype], ffi.from_buffer(array))
