"""glibc's malloc set back to serving large blocks by mmap (Debian's PETSc turns it off).

Imports DOLFINx (hence PETSc) first: the setting PETSc's libraries change happens when they load.
"""

import dolfinx  # noqa: F401  (loads PETSc, whose libraries change the setting)

#: glibc's mallopt parameters (malloc.h) and the values ``restore_malloc_mmap`` sets.
_M_MMAP_THRESHOLD, _M_MMAP_MAX = -3, -4
MMAP_THRESHOLD = 1 << 20  # bytes: larger blocks (every array of the mesh's size) are mmapped
_MMAP_MAX = 65536  # glibc's default


def restore_malloc_mmap() -> None:
    """Let glibc's malloc serve large blocks by mmap again, so that freed arrays return to the system.

    Debian's PETSc links SuperLU_DIST, whose static initialiser (from CombBLAS) calls
    ``mallopt(M_MMAP_MAX, 0)`` when PETSc is loaded: every later array then lives in the brk
    heap, and the memory freed between the phases of the set-up stays resident (a freed block
    below a live one is never returned), measured 250 MB of 840 MB at 250,000 cells. This
    restores glibc's default M_MMAP_MAX and fixes the mmap threshold at ``MMAP_THRESHOLD``
    (a fixed threshold: glibc's dynamic one rises to 32 MB after the first free, which would
    put the arrays of a 1e6-cell mesh back on the heap). Called once on import of dolfinx_dem,
    after DOLFINx (hence PETSc) is loaded; a no-op without glibc.
    """
    import ctypes
    import platform

    if platform.libc_ver()[0] != "glibc":
        return
    libc = ctypes.CDLL("libc.so.6")
    if libc.mallopt(_M_MMAP_MAX, _MMAP_MAX) != 1 or libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) != 1:
        raise RuntimeError("glibc's mallopt refused to restore mmap for large blocks")
