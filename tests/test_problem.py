"""The public face of the library: ``DEMProblem`` composes a discretisation and its contact
models, and the API takes what a DOLFINx user holds (MeshTags, numpy scalars, DOLFINx
Functions) and refuses misuse with clear errors."""

import inspect

import dolfinx.fem
import numpy as np
import pytest
from helpers import cell_vector
from mpi4py import MPI

import dolfinx_dem
from dolfinx_dem import errors, meshes

PLATE = dolfinx_dem.ElasticMaterial(E=100.0, nu=0.3, rho=1.0)


def plate(comm=MPI.COMM_WORLD):
    """A 1 x 0.5 plate clamped on its left side (facet tags of meshes.create_rectangle)."""
    mesh, _, tags = meshes.create_rectangle(comm, [0.0, 0.0], [1.0, 0.5], [8, 4])
    return mesh, tags


def test_every_public_name_is_documented_and_every_error_is_a_dem_error():
    for name in dolfinx_dem.__all__[1:]:
        assert inspect.getdoc(getattr(dolfinx_dem, name)), name
    classes = [c for c in vars(errors).values() if inspect.isclass(c) and issubclass(c, Exception)
               and not issubclass(c, Warning)]
    assert len(classes) >= 12 and all(issubclass(c, dolfinx_dem.DEMError) for c in classes)
    assert issubclass(dolfinx_dem.AccuracyWarning, UserWarning)
    assert issubclass(dolfinx_dem.InputError, ValueError) and issubclass(dolfinx_dem.StateError, RuntimeError)
    assert dolfinx_dem.__version__.count(".") >= 2


def test_a_problem_composes_only_contact_models_of_its_discretisation():
    mesh, tags = plate()
    dem = dolfinx_dem.DEMDiscretisation(mesh, PLATE, "A", [dolfinx_dem.DirichletBC(tags.find(meshes.XMIN), [0, 0])])
    other = dolfinx_dem.DEMDiscretisation(mesh, PLATE, "B")
    floor = dolfinx_dem.HalfSpace([0.0, -0.1], [0.0, 1.0], tags.find(meshes.YMIN))
    with pytest.raises(dolfinx_dem.InputError, match="needs a DEMDiscretisation, got Mesh"):
        dolfinx_dem.DEMProblem(mesh)
    with pytest.raises(dolfinx_dem.InputError, match="HalfSpace is not a contact model"):
        dolfinx_dem.DEMProblem(dem, [floor])
    with pytest.raises(dolfinx_dem.InputError, match="built on another discretisation"):
        dolfinx_dem.DEMProblem(dem, [dolfinx_dem.RigidContact(other, [floor])])
    with pytest.raises(dolfinx_dem.InputError, match="at most one contact model of each kind"):
        dolfinx_dem.DEMProblem(dem, [dolfinx_dem.RigidContact(dem, [floor]), dolfinx_dem.RigidContact(dem, [floor])])
    with pytest.raises(dolfinx_dem.InputError, match="needs at least one obstacle"):
        dolfinx_dem.RigidContact(dem, [])
    problem = dolfinx_dem.DEMProblem(dem, [dolfinx_dem.RigidContact(dem, [floor])])
    assert problem.find(dolfinx_dem.RigidContact) is problem.contacts[0]
    assert problem.find(dolfinx_dem.PairContact) is None


def test_memm_takes_a_problem_numpy_scalars_and_refuses_a_step_before_its_start():
    mesh, tags = plate()
    dem = dolfinx_dem.DEMDiscretisation(mesh, PLATE, "A", [dolfinx_dem.DirichletBC(tags.find(meshes.XMIN), [0, 0])],
                                        body_force=[0.0, -1.0])
    with pytest.raises(dolfinx_dem.InputError, match=r"MEMM integrates a DEMProblem, got DEMDiscretisation \(wrap"):
        dolfinx_dem.MEMM(dem, 1e-3)
    problem = dolfinx_dem.DEMProblem(dem)
    for dt in (0.0, -1e-3, np.nan, True, "1e-3"):
        with pytest.raises(dolfinx_dem.InputError, match="time step dt must be a positive finite real number"):
            dolfinx_dem.MEMM(problem, dt)
    stepper = dolfinx_dem.MEMM(problem, np.float32(1e-3), refresh_every=np.int64(10))
    assert stepper.dt == float(np.float32(1e-3)) and stepper.refresh_every == 10
    with pytest.raises(dolfinx_dem.StateError, match=r"MEMM.step\(\) before MEMM.initialise"):
        stepper.step()
    stepper.initialise(dem.create_vector(), dem.create_vector())
    assert stepper.step().t == pytest.approx(float(np.float32(1e-3)), rel=1e-15)


def test_materials_take_numpy_scalars_and_refuse_what_is_not_a_number():
    m = dolfinx_dem.ElasticMaterial(E=np.int64(1), nu=np.float32(0.25), rho=np.float64(2.0), eta=np.int32(3))
    assert (m.E, m.nu, m.rho, m.eta) == (1.0, 0.25, 2.0, 3.0) and type(m.E) is float
    for bad in ({"E": True}, {"E": "1"}, {"nu": np.nan}, {"rho": None}, {"eta": np.inf}):
        with pytest.raises(dolfinx_dem.InputError, match="must be a finite real number, got"):
            dolfinx_dem.ElasticMaterial(**({"E": 1.0, "nu": 0.25, "rho": 1.0} | bad))
    with pytest.raises(dolfinx_dem.InputError, match="E must be > 0, got -1.0"):
        dolfinx_dem.ElasticMaterial(E=np.int64(-1), nu=0.25, rho=1.0)


@pytest.mark.mpi
def test_initial_states_are_dolfinx_functions_vectors_or_arrays():
    """``MEMM.initialise`` takes the DG0 Function of the discretisation, a Function of another
    space of the mesh (interpolated into DG0: its values at the barycentres for a P1 field), a
    PETSc vector of the dofs or an array of the owned values: the same state."""
    mesh, tags = plate()
    dem = dolfinx_dem.DEMDiscretisation(mesh, PLATE, "A", [dolfinx_dem.DirichletBC(tags.find(meshes.XMIN), [0, 0])])
    problem = dolfinx_dem.DEMProblem(dem)

    def field(x):
        return np.stack([0.01 * x[0] + 0.03 * x[1], -0.02 * x[0]])  # affine: a P1 field holds it exactly

    P1 = dolfinx.fem.Function(
        dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 1))
        if hasattr(dolfinx.fem, "VectorFunctionSpace")
        else dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (2,)))
    )
    P1.interpolate(field)
    DG0 = dolfinx.fem.Function(dem.V)
    DG0.interpolate(field)
    vector = cell_vector(dem, lambda x: field(x.T).T)
    states = []
    for v0 in (vector, DG0, P1, vector.array_r.copy()):
        stepper = dolfinx_dem.MEMM(problem, 1e-3)
        stepper.initialise(dem.create_vector(), v0)
        states.append(stepper.v_next.array_r.copy())
    for s in states[1:]:
        assert np.abs(s - states[0]).max() < 1e-15  # the field is affine on each cell: exact
    with pytest.raises(dolfinx_dem.InputError, match="values given for the"):
        dolfinx_dem.MEMM(problem, 1e-3).initialise(dem.create_vector(), np.zeros(3))
