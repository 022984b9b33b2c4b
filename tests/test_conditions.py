"""conditions.py: the facets a condition selects (indices or a DOLFINx MeshTags), the values of
conditions at their facets, and the translation of a prescribed body."""

import dolfinx.mesh
import numpy as np
import pytest
from helpers import cell_vector
from mpi4py import MPI

import dolfinx_dem
from dolfinx_dem import meshes
from dolfinx_dem.conditions import DirichletBC, PrescribedBody, Traction, facet_indices, facet_values
from dolfinx_dem.errors import InputError

PLATE = dolfinx_dem.ElasticMaterial(E=100.0, nu=0.3, rho=1.0)


def plate(comm=MPI.COMM_WORLD):
    """A 1 x 0.5 plate clamped on its left side (facet tags of meshes.create_rectangle)."""
    mesh, _, tags = meshes.create_rectangle(comm, [0.0, 0.0], [1.0, 0.5], [8, 4])
    return mesh, tags


@pytest.mark.mpi
def test_conditions_take_meshtags_and_their_tags():
    """A MeshTags of the facets with ``tag`` selects the facets of that value: the same
    discretisation as the facet indices; a MeshTags of several values without a tag, of cells,
    or a tag with facet indices, is refused."""
    mesh, tags = plate()
    u = None
    reactions = []
    for bc in (dolfinx_dem.DirichletBC(tags.find(meshes.XMIN), [0.0, 0.0]),
               dolfinx_dem.DirichletBC(tags, [0.0, 0.0], tag=meshes.XMIN)):
        dem = dolfinx_dem.DEMDiscretisation(mesh, PLATE, "A", [bc], body_force=[0.0, -1.0])
        u = cell_vector(dem, lambda x: 0.01 * x ** 2) if u is None else u
        reactions.append(dem.reactions(u, 0.0))
    assert np.array_equal(reactions[0], reactions[1]) and np.abs(reactions[0]).max() > 0
    message = r"Dirichlet condition 0: the MeshTags holds the values \[1, 2, 3, 4\]"
    with pytest.raises(dolfinx_dem.InputError, match=message):
        dolfinx_dem.DEMDiscretisation(mesh, PLATE, "A", [dolfinx_dem.DirichletBC(tags, [0.0, 0.0])])
    with pytest.raises(dolfinx_dem.InputError, match="tag=1 selects among the values of a MeshTags"):
        dolfinx_dem.DEMDiscretisation(mesh, PLATE, "A", [dolfinx_dem.DirichletBC(tags.find(1), [0.0, 0.0], tag=1)])
    message = "facets must be a 1D array of facet indices or a DOLFINx MeshTags"
    with pytest.raises(dolfinx_dem.InputError, match=message):
        dolfinx_dem.DEMDiscretisation(mesh, PLATE, "A", [dolfinx_dem.DirichletBC(np.array([0.5, 1.5]), [0.0, 0.0])])
    dem = dolfinx_dem.DEMDiscretisation(mesh, PLATE, "A", [dolfinx_dem.DirichletBC(tags, [0, 0], tag=meshes.XMIN)])
    floor = dolfinx_dem.RigidContact(dem, [dolfinx_dem.HalfSpace([0.0, -0.1], [0.0, 1.0], tags, tag=meshes.YMIN)])
    assert MPI.COMM_WORLD.allreduce(floor.num_own, op=MPI.SUM) == 8  # the 8 facets of the lower side


@pytest.mark.mpi
def test_facet_indices_of_meshtags_and_arrays():
    mesh, tags = plate()
    left = facet_indices(tags, meshes.XMIN, "left", 2)
    assert left.dtype == np.int32 and np.array_equal(left, tags.find(meshes.XMIN))
    assert MPI.COMM_WORLD.allreduce(len(left), op=MPI.SUM) == 4
    one = dolfinx.mesh.meshtags(mesh, 1, left, np.full(len(left), 5, dtype=np.int32))
    assert np.array_equal(facet_indices(one, None, "one", 2), left)  # one value: all its facets
    assert facet_indices([3, 1], None, "list", 2).tolist() == [3, 1]
    assert facet_indices(np.empty(0), None, "empty", 2).dtype == np.int32
    ncells = mesh.topology.index_map(2).size_local
    cells = dolfinx.mesh.meshtags(mesh, 2, np.arange(ncells, dtype=np.int32), np.ones(ncells, dtype=np.int32))
    with pytest.raises(InputError, match=r"cells: the MeshTags tags entities of dimension 2, not facets \(dim"):
        facet_indices(cells, None, "cells", 2)
    with pytest.raises(InputError, match="floats: facets must be a 1D array of facet indices"):
        facet_indices(np.array([0.5]), None, "floats", 2)


def test_facet_values_in_the_order_of_the_facets():
    """Constant and callable values at their facets; a callable not time dependent is read at
    t = 0; a value that is not finite names the facet."""
    centres = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.5], [3.0, 1.0]])
    order = np.array([0, 2, 3])
    conditions = [(np.array([3]), Traction(None, [1.0, -1.0])),
                  (np.array([0, 2]), Traction(None, lambda x, t: np.stack([x[0] + t, x[1] * t]), time_dependent=True))]
    values = facet_values("traction", conditions, order, centres, 2, 2.0)
    assert np.array_equal(values, [[2.0, 0.0], [4.0, 1.0], [1.0, -1.0]])
    frozen = [(np.array([0, 2]), Traction(None, lambda x, t: np.stack([x[0] + t, x[1] * t])))]
    assert np.array_equal(facet_values("traction", frozen, order, centres, 2, 2.0),
                          [[0.0, 0.0], [2.0, 0.0], [0.0, 0.0]])
    with pytest.raises(InputError, match=r"a constant Dirichlet value needs 2 components, got \(3,\)"):
        facet_values("Dirichlet", [(np.array([0]), DirichletBC(None, [0.0, 0.0, 0.0]))], order, centres, 2, 0.0)
    blowing = [(np.array([2]), DirichletBC(None, lambda x, t: np.stack([1 / (x[0] - 2), x[1]])))]
    with np.errstate(divide="ignore"), pytest.raises(
            InputError, match=r"the Dirichlet value at t = 0 is not finite: \[inf, 0.5\] on the facet at \[2.0, 0.5\]"):
        facet_values("Dirichlet", blowing, order, centres, 2, 0.0)


def test_prescribed_translation():
    assert np.array_equal(PrescribedBody(1, velocity=[2.0, -1.0]).translation(0.5, 2), [1.0, -0.5])
    body = PrescribedBody(1, displacement=lambda t: (np.sin(t), t**2))
    assert np.array_equal(body.translation(0.3, 2), [np.sin(0.3), 0.09])
    with pytest.raises(InputError, match=r"prescribed body 4: displacement\(1\) must be 3 finite numbers, got \[1.0"):
        PrescribedBody(4, displacement=lambda t: [1.0, 2.0]).translation(1.0, 3)
    with pytest.raises(InputError, match="must be 2 finite numbers, got \\[nan, 0.0\\]"):
        PrescribedBody(4, displacement=lambda t: [np.nan, 0.0]).translation(1.0, 2)
