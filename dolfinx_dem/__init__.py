"""dolfinx_dem: a cell-centred Discrete Element Method for elastodynamics with contact on DOLFINx.

The library, bottom up (docs/architecture.md):

- a mesh of DOLFINx and its boundary facets (``locate_boundary_facets``, ``create_discs``, ...);
- ``DEMDiscretisation(mesh, ElasticMaterial(...), scheme, [DirichletBC(...)], ...)``: the DEM
  space discretisation, its energy and the exact force;
- contact models acting on it: ``RigidContact(dem, [HalfSpace(...)])``, ``PairContact(dem, facets)``;
- ``DEMProblem(dem, contacts)``: energies, forces and gradients with contact;
- ``MEMM(problem, dt)``: the explicit pseudo-energy conserving time stepping;
  ``minimise_energy(problem)``: statics;
- ``run(scene, out)``, ``resume(out)``: a scene file to its outputs (the ``dolfinx-dem`` command).

Every error the package raises derives from ``DEMError``.
"""

import importlib
import importlib.metadata

from dolfinx_dem import _malloc

_malloc.restore_malloc_mmap()  # after PETSc is loaded (see there)

#: where each public name lives: imported on first use (PEP 562), so that ``import dolfinx_dem``
#: and the command line's ``list`` load no more than they need
_PUBLIC = {
    "dolfinx_dem.conditions": ("DirichletBC", "PrescribedBody", "Traction"),
    "dolfinx_dem.contact": ("ContactModel", "HalfSpace", "PairContact", "RigidContact"),
    "dolfinx_dem.contact.protocol": ("StaticContact",),
    "dolfinx_dem.discretisation": ("DEMDiscretisation",),
    "dolfinx_dem.errors": ("AccuracyWarning", "CheckpointError", "DEMError", "InputError", "InstabilityError",
                           "MissingFileError", "OutputError", "OutputFolderError", "SceneError", "SolverError",
                           "StateError", "StaticsError", "UnresolvedContactError"),
    "dolfinx_dem.material": ("ElasticMaterial",),
    "dolfinx_dem.memm": ("MEMM", "Diagnostics"),
    "dolfinx_dem.meshes": ("create_balls", "create_box", "create_disc", "create_discs", "create_interval",
                           "create_rectangle", "exterior_facets", "locate_boundary_facets", "read_mesh"),
    "dolfinx_dem.problem": ("DEMProblem",),
    "dolfinx_dem.simulation": ("resume", "run"),
    "dolfinx_dem.stability": ("eigenvalues",),
    "dolfinx_dem.statics": ("StaticResult", "minimise_energy"),
}
_MODULE_OF = {name: module for module, names in _PUBLIC.items() for name in names}


def __getattr__(name: str):
    if name in _MODULE_OF:
        value = getattr(importlib.import_module(_MODULE_OF[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'dolfinx_dem' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_MODULE_OF))


__version__ = importlib.metadata.version("dolfinx-dem")

__all__ = ["__version__", *sorted(_MODULE_OF)]
