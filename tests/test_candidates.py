"""contact/candidates.py: the candidate facets of halo layers 0 and 1 that a marking selects, and
the checks every contact model makes of them."""

import dolfinx.mesh
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC, Traction
from dolfinx_dem.contact import candidates
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.errors import InputError
from dolfinx_dem.material import ElasticMaterial

MATERIAL = ElasticMaterial(E=1.0, nu=0.3, rho=1.0)


def square(comm=MPI.COMM_WORLD):
    return dolfinx.mesh.create_unit_square(comm, 4, 4)


def side(mesh, k, value):
    return meshes.locate_boundary_facets(mesh, lambda x: np.isclose(x[k], value))


@pytest.mark.mpi
def test_the_marked_facets_of_the_owned_cells_are_selected_once_with_their_marks():
    """The bottom side marked 0, the top side 1: 4 owned candidates each over the processes,
    each the facet j of its cell opposite vertex j, at the right height."""
    comm = MPI.COMM_WORLD
    mesh = square()
    dem = DEMDiscretisation(mesh, MATERIAL, "A")
    bottom, top = side(mesh, 1, 0.0), side(mesh, 1, 1.0)
    found = candidates.select(dem, np.concatenate([bottom, top]),
                              np.repeat([0, 1], [len(bottom), len(top)]), "sides")
    geom = dem.geometry
    assert np.array_equal(found.owned, found.cell < dem.n_owned)
    assert np.array_equal(geom.cell_facets[found.cell, found.j], found.facet)
    assert np.all(geom.cell_layer[found.cell] <= 1)
    counts = comm.allreduce(np.bincount(found.mark[found.owned], minlength=2), op=MPI.SUM)
    assert counts.tolist() == [4, 4]
    assert np.array_equal(geom.facet_centres[found.facet, 1], found.mark.astype(float))


@pytest.mark.mpi
def test_a_facet_marked_twice_is_an_error_naming_the_models():
    mesh = square()
    dem = DEMDiscretisation(mesh, MATERIAL, "A")
    bottom = side(mesh, 1, 0.0)
    with pytest.raises(InputError, match="two obstacles share a facet"):
        candidates.select(dem, np.concatenate([bottom, bottom]), np.repeat([0, 1], len(bottom)), "obstacles")


@pytest.mark.mpi
def test_candidates_must_be_free_boundary_facets_with_constant_data():
    mesh = square()
    bottom, left, right = side(mesh, 1, 0.0), side(mesh, 0, 0.0), side(mesh, 0, 1.0)

    def checked(facets, **conditions):
        dem = DEMDiscretisation(mesh, MATERIAL, "A", **conditions)
        candidates.check(dem, candidates.select(dem, facets, np.zeros(len(facets), dtype=np.int64), "c"), "wall")

    checked(bottom, dirichlet=[DirichletBC(left, [0.0, 0.0])], tractions=[Traction(right, [1.0, 0.0])])
    with pytest.raises(InputError, match="wall: contact candidate facets must not carry a Dirichlet condition"):
        checked(np.concatenate([bottom, left]), dirichlet=[DirichletBC(left, [0.0, 0.0])])
    with pytest.raises(InputError, match="wall: contact candidate facets must not carry a traction"):
        checked(np.concatenate([bottom, right]), tractions=[Traction(right, [1.0, 0.0])])
    with pytest.raises(InputError, match="contact with time-dependent Dirichlet conditions or tractions"):
        checked(bottom, tractions=[Traction(right, lambda x, t: t + 0 * x, time_dependent=True)])
    inner = np.setdiff1d(np.arange(mesh.topology.index_map(1).size_local, dtype=np.int32), meshes.exterior_facets(mesh))
    with pytest.raises(InputError, match=r"wall: contact candidates must be boundary facets; the facet at \[.*\] is"):
        checked(inner)
