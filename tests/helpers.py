"""Helpers shared by the test modules (tests/ is on sys.path under pytest's default import mode)."""

import numpy as np

from dolfinx_dem import _compat


def gmsh_mesh(comm, build, gdim=2):
    """A DOLFINx mesh from ``build(gmsh)``, which makes and meshes a gmsh model on rank 0."""
    import gmsh

    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        build(gmsh)
    try:
        return _compat.mesh_from_gmsh_model(gmsh.model, comm, gdim)[0]
    finally:
        if comm.rank == 0:
            gmsh.finalize()


def owned_centres(dem):
    """Barycentres of the owned cells, shape (n_owned, d)."""
    return dem.geometry.cell_centres[: dem.n_owned]


def cell_vector(dem, field):
    """PETSc vector of u_c = field(x_c) on the owned cells; field maps (n, d) -> (n, d)."""
    u = dem.create_vector()
    u.array[:] = np.asarray(field(owned_centres(dem))).ravel()
    return u
