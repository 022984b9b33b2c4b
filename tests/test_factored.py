"""K = Q^T Q in one pass over the rows of Q (factored.py): the same products as PETSc's two
MatMults, on any number of processes, and the local numbering of owned and ghost dofs."""

import dolfinx.mesh
import numpy as np
import pytest
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.factored import local_numbering
from dolfinx_dem.material import ElasticMaterial

MATERIAL = ElasticMaterial(E=1.0, nu=0.3, rho=1.0)

FORWARD = dict(addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
REVERSE = dict(addv=PETSc.InsertMode.ADD_VALUES, mode=PETSc.ScatterMode.REVERSE)


def test_local_numbering():
    ghosts, local = local_numbering(np.array([7, 3, 12, 4, 3, 20, 5]), 3, 6)
    assert ghosts.tolist() == [7, 12, 20]
    assert local.tolist() == [3, 0, 4, 1, 0, 5, 2]
    assert local.dtype == np.int32


@pytest.mark.mpi
@pytest.mark.parametrize("alpha", [0.0, 1.0])
def test_one_pass_equals_the_two_matmults(alpha):
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [2.0, 0.5]], [12, 5])
    left = meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
    dem = DEMDiscretisation(mesh, MATERIAL, dirichlet=[DirichletBC(left, [0.0, 0.0])])
    K = dem.factored
    rng = np.random.default_rng(comm.rank)
    x, z = K.create_vector(), K.create_vector()
    x.array[:] = rng.normal(size=x.array.shape)
    x.ghostUpdate(**FORWARD)
    y = rng.normal(size=K.n_rows)
    y0, sums = y.copy(), np.zeros(2)
    K.bind(x, y, z, sums)(alpha, 0.5)
    z.ghostUpdate(**REVERSE)

    Q = dem.assemble_Q()
    a, out = Q.createVecLeft(), dem.create_vector()
    Q.mult(x, a)
    expected = alpha * y0 + 0.5 * a.array
    a.array[:] = expected
    Q.transpose(PETSc.Mat()).mult(a, out)  # the reference: PETSc's Q^T
    scale = comm.allreduce(np.abs(expected).max(), op=MPI.MAX)
    assert comm.allreduce(np.abs(y - expected).max(), op=MPI.MAX) <= 1e-14 * scale
    zscale = comm.allreduce(np.abs(out.array).max(), op=MPI.MAX)
    assert comm.allreduce(np.abs(z.array - out.array).max(), op=MPI.MAX) <= 1e-13 * zscale
    n = K.n_elastic
    local = np.array([expected[:n] @ expected[:n], expected[n:] @ expected[n:]])
    assert np.allclose(comm.allreduce(sums), comm.allreduce(local), rtol=1e-13)


@pytest.mark.mpi
def test_shift_removes_a_translation_per_group():
    """x - shift[index] in the pass equals the pass applied to the shifted vector."""
    comm = MPI.COMM_WORLD
    mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [1.0, 1.0]], [6, 6])
    dem = DEMDiscretisation(mesh, MATERIAL)  # free: translations are in the kernel of Q
    K = dem.factored
    x, z, shifted, z2 = K.create_vector(), K.create_vector(), K.create_vector(), K.create_vector()
    rng = np.random.default_rng(1 + comm.rank)
    x.array[:] = rng.normal(size=x.array.shape) + 1e3  # a large translation plus a deformation
    x.ghostUpdate(**FORWARD)
    index = np.tile(np.arange(2, dtype=np.int32), len(K.local_array(x)) // 2)
    shift = np.array([1e3, 1e3 - 0.25])
    shifted.array[:] = x.array - shift[index[: len(x.array)]]
    shifted.ghostUpdate(**FORWARD)
    y, y2 = np.zeros(K.n_rows), np.zeros(K.n_rows)
    K.bind(x, y, z, np.zeros(2), index, shift)(0.0, 1.0)
    K.bind(shifted, y2, z2, np.zeros(2))(0.0, 1.0)
    assert np.array_equal(y, y2)
