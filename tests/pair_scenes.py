"""Scenes of two bodies in contact shared by the tests of the contact between bodies."""

import numpy as np
from helpers import gmsh_mesh
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import ElasticMaterial

SOFT = ElasticMaterial(E=100.0, nu=0.2, rho=100.0)


def two_discs(h=0.03, comm=MPI.COMM_WORLD, scheme="B"):
    """The two disks of paper §5.3 with their facing halves as contact boundary."""
    mesh, _, tags = meshes.create_discs(comm, [((0.14, 2.27), 0.1), ((0.36, 2.27), 0.1)], h)
    dem = DEMDiscretisation(mesh, SOFT, scheme)
    facets = meshes.locate_boundary_facets(mesh, lambda x: (x[0] >= 0.14) & (x[0] <= 0.36))
    return dem, facets


def approach(x, speed=0.3):
    """Velocity field: the left body moves right, the right body left."""
    return np.stack([np.where(x[:, 0] < 0.25, speed, -speed), np.zeros(len(x))], axis=1)


def two_blocks(comm=MPI.COMM_WORLD, n=6, scheme="B", y0=0.0):
    """Two 0.2 x 0.2 squares 0.01 apart along x with matching facets on their facing sides,
    bottoms at y = y0."""

    def build(gmsh):
        for x0 in (0.0, 0.21):
            s = gmsh.model.occ.addRectangle(x0, y0, 0.0, 0.2, 0.2)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(2, [s], 1 if x0 == 0 else 2)
            for _, c in gmsh.model.getBoundary([(2, s)], oriented=False):
                gmsh.model.mesh.setTransfiniteCurve(c, n + 1)
            gmsh.model.mesh.setTransfiniteSurface(s)
        gmsh.model.mesh.generate(2)

    mesh = gmsh_mesh(comm, build)
    dem = DEMDiscretisation(mesh, SOFT, scheme)
    facets = meshes.locate_boundary_facets(mesh, lambda x: (x[0] > 0.19) & (x[0] < 0.22))
    return dem, facets
