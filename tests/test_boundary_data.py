"""boundary_data.py: the lift q(t) of the energy rows, the external force and the load of the
Dirichlet values, tractions and body force, and the reactions, against hand values and the
translation invariance of the elastic energy."""

import dolfinx.mesh
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC, Traction
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.material import ElasticMaterial

MATERIAL = ElasticMaterial(E=3.0, nu=0.3, rho=2.0)


def square(comm=MPI.COMM_WORLD):
    return dolfinx.mesh.create_unit_square(comm, 3, 3)


def side(mesh, k, value):
    return meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[k], value))


def total(dem, vec):
    return dem.comm.allreduce(vec.array_r.reshape(-1, dem.d).sum(axis=0), op=MPI.SUM)


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["A", "B"])
def test_the_external_force_sums_to_the_load_by_hand(scheme):
    """The facet reconstructions reproduce constants, so the force of the tractions sums to
    sum_f |f| t(x_f): t = (x, 2) on the top side of the unit square gives (1/2, 2) (the
    midpoint rule is exact for x), plus |Omega| times the body force (0.5, -1)."""
    mesh = square()
    top = Traction(side(mesh, 1, 1.0), lambda x, t: np.stack([x[0], np.full(x.shape[1], 2.0)]))
    dem = DEMDiscretisation(mesh, MATERIAL, scheme, [DirichletBC(side(mesh, 1, 0.0), [0.0, 0.0])],
                            body_force=[0.5, -1.0], tractions=[top])
    assert np.allclose(total(dem, dem.data.forcing(0.0)), [0.5 + 0.5, 2.0 - 1.0], rtol=1e-14, atol=0)


@pytest.mark.mpi
def test_the_lift_cancels_a_translation_that_the_dirichlet_values_follow():
    """g(t) = t c on the whole boundary: at u = t c every energy row Q u + q(t) is 0 (the
    potential is -f.u only), at u = 0 the rows are -Q (t c); the lift is linear in t and the
    load at u = 0 is the force there."""
    comm = MPI.COMM_WORLD
    mesh = square()
    c = np.array([0.3, -0.7])
    bc = DirichletBC(meshes.exterior_facets(mesh), lambda x, t: t * c[:, None] * np.ones(x.shape[1]), True)
    dem = DEMDiscretisation(mesh, MATERIAL, "A", [bc])
    rows1, q1 = dem.data.lift(1.0)
    q1 = q1.copy()
    rows2, q2 = dem.data.lift(2.0)
    assert np.array_equal(rows1, rows2) and comm.allreduce(len(rows1), op=MPI.SUM) > 0
    assert np.allclose(q2, 2.0 * q1, rtol=1e-14, atol=0)
    assert comm.allreduce(np.abs(q1).max(initial=0.0), op=MPI.MAX) > 0.1
    u = dem.create_vector()
    u.array.reshape(-1, 2)[:] = 2.0 * c
    e = dem.energies(u, 2.0)
    assert e["elastic"] + e["stabilisation"] < 1e-28
    zero = dem.create_vector()
    e0 = dem.energies(zero, 2.0)
    assert e0["elastic"] > 0.1
    F = dem.create_vector()
    dem.force(zero, 2.0, F)
    assert np.array_equal(dem.data.load(2.0).array_r, F.array_r)


@pytest.mark.mpi
def test_a_constant_lift_is_read_at_t_0():
    """Data not declared time dependent are evaluated once, at t = 0."""
    mesh = square()
    bc = DirichletBC(side(mesh, 0, 0.0), lambda x, t: (1.0 + t) * np.ones((2, x.shape[1])))
    dem = DEMDiscretisation(mesh, MATERIAL, "A", [bc])
    assert not dem.data.time_dependent
    q0 = dem.data.lift(0.0)[1].copy()
    assert np.array_equal(dem.data.lift(5.0)[1], q0)
    assert np.array_equal(dem.data.dirichlet_values(5.0), np.ones((len(dem.reconstruction.dirichlet_facets), 2)))


@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["A", "B"])
def test_reactions_balance_the_forces_by_translation_invariance(scheme):
    """The elastic energy does not change when u and every Dirichlet value move by the same
    constant, and the tractions' work changes by sum_f |f| t_f . c: so for any u the forces of
    the cells sum to the reactions plus the traction resultant (no body force here)."""
    comm = MPI.COMM_WORLD
    mesh = square()
    left = DirichletBC(side(mesh, 0, 0.0), lambda x, t: np.stack([0.1 * x[1], 0.0 * x[1]]))
    bottom = DirichletBC(side(mesh, 1, 0.0), [0.02, -0.03])
    right = Traction(side(mesh, 0, 1.0), [0.4, -0.2])
    dem = DEMDiscretisation(mesh, MATERIAL, scheme, [left, bottom], tractions=[right])
    rng = np.random.default_rng(comm.rank)
    u = dem.create_vector()
    u.array[:] = 0.05 * rng.standard_normal(len(u.array))
    F = dem.create_vector()
    dem.force(u, 0.0, F)
    R = dem.reactions(u, 0.0)
    assert R.shape == (2, 2) and np.abs(R).min() > 1e-3
    assert np.allclose(total(dem, F), R.sum(axis=0) + [0.4, -0.2], rtol=0, atol=1e-12)
