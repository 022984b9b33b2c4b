"""The memory of the contact between bodies grows with its candidate facets, not with the cells:
what a PairContact keeps (its arrays, found through its attributes) on two meshes with the same
contact faces and four times fewer cells elsewhere."""

import dataclasses

import numpy as np
import scipy.sparse
from helpers import gmsh_mesh
from mpi4py import MPI
from pair_scenes import SOFT

from dolfinx_dem import meshes
from dolfinx_dem.contact import PairContact
from dolfinx_dem.discretisation import DEMDiscretisation
from dolfinx_dem.kernels import Struct


def graded_boxes(far: float, near: float = 0.05):
    """Two 0.2 m cubes 0.01 apart along x, meshed at size ``near`` at the corners of their facing
    sides (the contact boundary) and ``far`` at the other corners: (discretisation, contact)."""

    def build(gmsh):
        for k, x0 in enumerate((0.0, 0.21)):
            box = gmsh.model.occ.addBox(x0, 0.0, 0.0, 0.2, 0.2, 0.2)
            gmsh.model.occ.synchronize()
            gmsh.model.addPhysicalGroup(3, [box], k + 1)
        for dim, tag in gmsh.model.getEntities(0):
            x = gmsh.model.getValue(dim, tag, [])[0]
            gmsh.model.mesh.setSize([(dim, tag)], near if 0.19 < x < 0.22 else far)
        gmsh.model.mesh.generate(3)

    mesh = gmsh_mesh(MPI.COMM_SELF, build, gdim=3)
    dem = DEMDiscretisation(mesh, SOFT, "B")
    return dem, PairContact(dem, meshes.locate_boundary_facets(mesh, lambda x: (x[0] > 0.19) & (x[0] < 0.22)))


def kept_bytes(obj, seen=None) -> int:
    """The bytes of the numpy arrays that ``obj`` keeps through its dolfinx_dem attributes, the
    kernels' structs, sparse matrices, dataclasses, lists and dicts (each array's memory once),
    without the discretisation."""
    seen = set() if seen is None else seen
    if id(obj) in seen or isinstance(obj, DEMDiscretisation):
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        base = obj
        while isinstance(base.base, np.ndarray):
            base = base.base
        if base is not obj:
            if id(base) in seen:
                return 0
            seen.add(id(base))
        return base.nbytes
    if isinstance(obj, scipy.sparse.spmatrix):
        children = [getattr(obj, a) for a in ("data", "indices", "indptr") if hasattr(obj, a)]
    elif isinstance(obj, Struct):
        children = list(obj.arrays.values()) + list(obj._keep)
    elif isinstance(obj, dict):
        children = list(obj.values())
    elif isinstance(obj, (list, tuple)):
        children = list(obj)
    elif dataclasses.is_dataclass(obj) or type(obj).__module__.startswith("dolfinx_dem"):
        children = list(getattr(obj, "__dict__", {}).values())
        children += [getattr(obj, s) for s in getattr(obj, "__slots__", ()) if hasattr(obj, s)]
    else:
        return 0
    return sum(kept_bytes(c, seen) for c in children)


def test_the_contact_keeps_a_few_kilobytes_per_candidate_facet_whatever_the_cells():
    """The same 88 candidate facets in 466 and 1870 cells: the contact keeps the same memory within
    a few percent (12.4 and 12.7 kB per candidate; 13.8 and 14.2 kB before its copies were trimmed:
    the facets of these coarse facing faces list 13 pairs each, about 0.85 kB per pair)."""
    coarse, fine = (graded_boxes(far) for far in (0.1, 0.03))
    cells = [dem.geometry.num_cells for dem, _ in (coarse, fine)]
    candidates = [c.pair_list.num_facets for _, c in (coarse, fine)]
    per_candidate = [kept_bytes(c) / n for (_, c), n in zip((coarse, fine), candidates)]
    assert cells[1] > 3.5 * cells[0] and candidates[0] == candidates[1] > 50
    assert max(per_candidate) < 16e3  # bytes
    assert abs(per_candidate[1] - per_candidate[0]) < 0.06 * per_candidate[0]
