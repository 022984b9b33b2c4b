"""dolfinx_dem: a cell-centred Discrete Element Method for elastodynamics with contact on DOLFINx."""

from dolfinx_dem import _compat

_compat.restore_malloc_mmap()  # after PETSc is loaded (see there)
