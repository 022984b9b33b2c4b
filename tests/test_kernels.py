"""The C pointers of the compiled kernels (``kernels.pointer``): the arrays they accept and refuse."""

import numpy as np
import pytest

from dolfinx_dem.kernels import ffi, pointer


def test_pointer_reads_the_arrays_data_and_refuses_what_a_kernel_cannot_read():
    """A pointer to a contiguous array reads its data (also read-only arrays, also past an
    offset), None is NULL; a non-contiguous array or another dtype raises instead of handing a
    kernel the wrong memory."""
    a = np.arange(6.0)
    a.flags.writeable = False
    p = pointer(a)
    assert p[0] == 0.0 and (p + 4)[0] == 4.0 and ffi.typeof(p + 4) is ffi.typeof("double *")
    assert pointer(np.array([3, 7], dtype=np.int32))[1] == 7 and pointer(np.array([-2], dtype=np.int8))[0] == -2
    assert pointer(None) == ffi.NULL
    with pytest.raises(ValueError, match="not C-contiguous"):
        pointer(np.zeros((3, 2)).T)
    with pytest.raises(ValueError, match="not C-contiguous"):
        pointer(np.arange(6.0)[::2])
    with pytest.raises(TypeError, match="float64, int32, int64 or int8 arrays, not float32"):
        pointer(np.zeros(3, dtype=np.float32))
