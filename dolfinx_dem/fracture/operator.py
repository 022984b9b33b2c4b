"""The discretisation's operator for a crack set: reconstruction and energy rows on the split
geometry (issue 34; design note §1.2 and §3, rows "R rows" and "Q rows").

Breaking a facet changes the potential V = 1/2 |Q u + q|^2 - f.u - W_T(u) (operators.py,
boundary_data.py) through the reconstruction only (design note §1.1-1.2): the lips are boundary
facets (scheme A, eq. (19)-(21), or scheme B where a cell now has two open facets), the gradients
of eq. (8) of the lip cells use their lips' values, and the broken facet has no jump row of
eq. (12)-(13) any more. The mass and the body force's work f.u do not change.

``compute_operator`` forms all of it from scratch on the split geometry (crack.py) with the
functions of the intact discretisation (``compute_reconstruction``, ``compute_energy_rows``),
so the operator of a crack set is by construction the operator of the mesh whose vertices are
duplicated along the crack (for the crack sets without a tip that ``split_geometry`` admits).
``rebuild.break_facets`` is the one entry point that adds broken facets to an operator: it
recomputes only the rows a break changes (design note §3), and equals ``compute_operator``.

Row layout (design note §1.2): the rows keep the intact operator's layout whatever breaks, so
that a row has one meaning in every crack set and energies compare row by row: the m =
d(d+1)/2 elastic rows of each cell (eq. (11)), then the d jump rows of each interior facet of
the intact geometry, ordered by the global numbers of its two cells (the order of
``discretisation._jump_facets`` on one process); the jump rows of broken facets are zero.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse
from mpi4py import MPI

from dolfinx_dem.fracture.crack import CrackState, split_geometry
from dolfinx_dem.geometry import MeshGeometry
from dolfinx_dem.material import CellMaterials
from dolfinx_dem.operators import EnergyRows, compute_energy_rows
from dolfinx_dem.reconstruction import Reconstruction, compute_reconstruction


@dataclasses.dataclass(frozen=True)
class Conditions:
    """What the reconstruction needs besides the geometry (``compute_reconstruction``'s
    arguments): the held cells' materials, the Neumann scheme "A" or "B", the Dirichlet facets
    with the components each fixes (default: all), the traction facets and the facets
    reconstructed by scheme B under scheme A. Facet indices are those of the intact geometry;
    they are boundary facets, so a split leaves them unchanged."""

    materials: CellMaterials
    scheme: str
    dirichlet_facets: np.ndarray = dataclasses.field(default_factory=lambda: np.empty(0, dtype=np.int64))
    fixed: np.ndarray | None = None  # (n_D, d) bool
    traction_facets: np.ndarray | None = None
    scheme_b_facets: np.ndarray | None = None


@dataclasses.dataclass(frozen=True)
class CrackedOperator:
    """The reconstruction u_F = R u + D g + N t and the energy rows a = Q u + Q_D g + QF N t of a
    crack set (module docstring), serial: every cell is owned.

    ``geometry`` is the split geometry (F + k facets, the lips last, ``lips[i]`` the second lip
    of the i-th broken facet in ``crack.lip_order``); ``rows`` has the intact layout, ``jump_facets`` the intact facet
    of each group of d jump rows; R, D and N have the split geometry's F + k facet rows; QF
    the split geometry's boundary-facet columns (the lips' included)."""

    intact: MeshGeometry
    conditions: Conditions
    crack: CrackState
    geometry: MeshGeometry
    lips: np.ndarray  # (k,)
    reconstruction: Reconstruction
    rows: EnergyRows
    jump_facets: np.ndarray  # (n_J,) intact interior facets, in row order

    @property
    def broken(self) -> np.ndarray:
        """The broken facets (intact geometry's indices), sorted."""
        return self.crack.facets(self.intact)


def jump_order(geom: MeshGeometry) -> np.ndarray:
    """The interior facets of ``geom`` in the order of their jump rows: by the global numbers of
    their two cells, smaller first (module docstring)."""
    interior = geom.interior_facets
    g = np.sort(geom.cell_global[geom.facet_cells[interior]], axis=1)
    return interior[np.lexsort((g[:, 1], g[:, 0]))]


def compute_operator(intact: MeshGeometry, conditions: Conditions, crack: CrackState,
                     comm: MPI.Comm) -> CrackedOperator:
    """The operator of ``crack`` on the intact geometry ``intact`` (module docstring), from
    scratch. Serial only (``split_geometry`` raises under MPI)."""
    geom, lips = split_geometry(intact, crack, comm)
    c = conditions
    rec = compute_reconstruction(geom, c.materials, c.dirichlet_facets, c.scheme, fixed=c.fixed,
                                 traction_facets=c.traction_facets, scheme_b_facets=c.scheme_b_facets)
    jump_facets = jump_order(intact)
    intact_jumps = geom.facet_cells[jump_facets, 1] >= 0  # the jump facets not broken
    live = jump_facets[intact_jumps]
    rows = compute_energy_rows(geom, c.materials, rec, geom.num_cells, live, len(live))
    # the rows of the unbroken facets into the intact layout, zero rows for the broken ones
    d, n_elastic = geom.d, rows.num_elastic
    target = np.concatenate([np.arange(n_elastic),
                             n_elastic + (np.flatnonzero(intact_jumps)[:, None] * d + np.arange(d)).ravel()])
    n_rows = n_elastic + len(jump_facets) * d
    place = scipy.sparse.csr_matrix((np.ones(len(target)), (target, np.arange(len(target)))),
                                    shape=(n_rows, rows.Q.shape[0]))
    rows = EnergyRows(Q=(place @ rows.Q).tocsr(), Q_dirichlet=(place @ rows.Q_dirichlet).tocsc(),
                      QF=(place @ rows.QF).tocsc(), num_owned=n_rows, num_elastic=n_elastic)
    return CrackedOperator(intact=intact, conditions=conditions, crack=crack, geometry=geom, lips=lips,
                           reconstruction=rec, rows=rows, jump_facets=jump_facets)


def row_values(op: CrackedOperator, u: np.ndarray, g: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The energy rows a = Q u + Q_D g + QF N t (eq. (11), (13)) at the cell values ``u``
    (N d,), Dirichlet values ``g`` (n_D d,) and tractions ``t`` (n_T d,), flattened in the
    orders of ``reconstruction.dirichlet_facets`` and ``traction_facets``."""
    rows, rec = op.rows, op.reconstruction
    return rows.Q @ u + rows.Q_dirichlet @ g + rows.QF @ (rec.N @ t)


def traction_values(op: CrackedOperator, u: np.ndarray, g: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The tractions' weighted work densities |f| t_f * u_f on the traction facets, (n_T d,),
    u_f = R u + D g + N t: their sum is the work W_T of the potential (boundary_data.py)."""
    rec, geom, d = op.reconstruction, op.geometry, op.geometry.d
    dofs = (rec.traction_facets[:, None] * d + np.arange(d)).ravel()
    u_f = rec.R[dofs] @ u + rec.D[dofs] @ g + rec.N[dofs] @ t
    return np.repeat(geom.facet_areas[rec.traction_facets], d) * t * u_f


def potential(op: CrackedOperator, u: np.ndarray, g: np.ndarray, t: np.ndarray) -> float:
    """The part of the potential V(u) that depends on the crack set: 1/2 |a|^2 - W_T, a =
    ``row_values``, W_T the tractions' work (V less the body force's -f.u, which no break changes)."""
    a = row_values(op, u, g, t)
    return 0.5 * float(a @ a) - float(traction_values(op, u, g, t).sum())


def lip_openings(op: CrackedOperator, facets: np.ndarray, u: np.ndarray, g: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The opening (u_{f'} - u_f) . n_f of each broken facet of ``facets`` (intact geometry's
    indices) at the cell values ``u``: u_f = R u + D g + N t the lips' reconstructions, f the lip of
    the cell that kept the facet's index, f' the other, n_f the outward unit normal of f's cell.
    Negative: the lips pass through each other, which nothing resists without contact of the lips
    (design stage S5)."""
    geom, rec, d = op.geometry, op.reconstruction, op.geometry.d
    facets = np.asarray(facets, dtype=np.int64)
    order = op.crack.lip_order(op.intact)  # lips[i] is the second lip of order[i]
    sort = np.argsort(order)
    other = op.lips[sort[np.searchsorted(order[sort], facets)]]
    both = np.concatenate([facets, other])
    dofs = (both[:, None] * d + np.arange(d)).ravel()
    uF = (rec.R[dofs] @ u + rec.D[dofs] @ g + rec.N[dofs] @ t).reshape(2, len(facets), d)
    c, j = geom.facet_cells[facets, 0], geom.facet_local[facets, 0]
    normal = geom.facet_area_normals[c, j] / geom.facet_areas[facets, None]
    return np.einsum("ij,ij->i", uF[1] - uF[0], normal)
