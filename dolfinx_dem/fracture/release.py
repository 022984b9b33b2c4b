"""The discrete energy release rate of a facet at fixed cell displacements (issue 34; design
note §1.2):

    Delta V_f(u) = V(u; C) - V(u; C + {f}),    G_h(f) = Delta V_f(u) / |f|,

C the current crack set and V the discretisation's potential (eq. (11), (13) and the data's
work). It is exactly the energy that leaves the potential when f breaks at a step boundary,
hence what the fracture energy Gamma books in the MEMM balance (design note §2), and the
literal Griffith criterion G_h >= G_c of the issue (option 1 of the design note §1.6).

Both operators have the same row layout (operator.py), so the difference is summed row by row,

    Delta V_f = sum_r 1/2 (a_r - a'_r)(a_r + a'_r) + sum_T (w'_T - w_T),

a and a' the energy rows before and after, w the tractions' work densities (a scheme A
traction facet of a lip cell changes its reconstruction). Unchanged rows give exact zeros,
so no cancellation between the two potentials, which are much larger than Delta V_f on a big
mesh; ``math.fsum`` makes the sum exactly rounded, hence independent of the order of the rows
(the design note §4 needs it in parallel). In 1D with scheme A (design note §6):

    Delta V_f = 1/2 (E - eta/4) h (a^2 + b^2) + eta/(2h) J_f^2 + eta/2 (a J_l + b J_r),

a, b the gradients of the two cells, J_f, J_l, J_r the jumps of f and of the two neighbouring
facets; (E - eta/4) h eps^2 for a uniform strain eps, (3/4 E - eta/16) h eps^2 with scheme B.

The trial operator is ``break_facets``'s, the one code path of an actual break (design note §3).
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI

from dolfinx_dem.errors import InputError
from dolfinx_dem.fracture.operator import CrackedOperator, lip_openings, row_values, traction_values
from dolfinx_dem.fracture.rebuild import ChangedRows, break_facets_with_changes


def potential_drop(before: CrackedOperator, after: CrackedOperator, u: np.ndarray, g: np.ndarray,
                   t: np.ndarray) -> float:
    """V(u; before) - V(u; after) for two operators of the same intact geometry (module
    docstring), at the cell values ``u`` (N d,), Dirichlet values ``g`` (n_D d,) and tractions
    ``t`` (n_T d,)."""
    a, b = row_values(before, u, g, t), row_values(after, u, g, t)
    w, w_after = traction_values(before, u, g, t), traction_values(after, u, g, t)
    changed = a != b
    return math.fsum(np.concatenate([0.5 * (a[changed] - b[changed]) * (a[changed] + b[changed]), w_after - w]))


def energy_release(op: CrackedOperator, facets: np.ndarray, u: np.ndarray, comm: MPI.Comm,
                   g: np.ndarray | None = None, t: np.ndarray | None = None) -> np.ndarray:
    """G_h of each of the intact geometry's interior ``facets`` (J/m^2 in any dimension: Delta V
    is per unit length in 2D and per unit cross-section in 1D, where |f| = 1), each broken alone
    from the crack set of ``op`` at fixed ``u`` (module docstring); ``g`` and ``t`` default to
    zero data. A facet whose break ``op`` cannot represent raises InputError (crack.py: a tip
    in 2D or 3D)."""
    return trial_breaks(op, facets, u, comm, g, t)[0]


def trial_breaks(op: CrackedOperator, facets: np.ndarray, u: np.ndarray, comm: MPI.Comm,
                 g: np.ndarray | None = None, t: np.ndarray | None = None,
                 step: int | None = None) -> tuple[np.ndarray, list[ChangedRows]]:
    """``energy_release``, the rows each facet's break alone changes (rebuild.ChangedRows) and
    the opening of its lips just after it (``operator.lip_openings``: negative when the break
    would close, under compression), each trial broken at ``step`` (default: the latest break's;
    it orders the lips only)."""
    rec = op.reconstruction
    g = np.zeros(rec.D.shape[1]) if g is None else np.asarray(g, dtype=float)
    t = np.zeros(rec.N.shape[1]) if t is None else np.asarray(t, dtype=float)
    facets = np.asarray(facets, dtype=np.int64)
    step = max(op.crack.last_step, 0) if step is None else step
    drops, changes, openings = [], [], []
    for f in facets:  # one local trial per candidate (the actual break's code path, rebuild.py)
        trial, changed = break_facets_with_changes(op, [f], step, comm)
        drops.append(potential_drop(op, trial, u, g, t))
        changes.append(changed)
        openings.append(lip_openings(trial, [f], u, g, t)[0])
    return np.array(drops) / op.intact.facet_areas[facets], changes, np.array(openings)


def release_bound(op: CrackedOperator, facets: np.ndarray, u: np.ndarray, g: np.ndarray,
                  t: np.ndarray) -> np.ndarray:
    """An upper bound on Delta V_f (J/m^2 in 1D) of each of the intact geometry's interior
    ``facets`` broken alone at ``u``, without a trial: the screen of the candidates (1D).

    Delta V_f = sum over the changed rows of 1/2 (a_r^2 - a'_r^2) <= sum of 1/2 a_r^2, and in 1D
    a break changes the S rows of the facet's two cells and the J rows of their facets only
    (rebuild.ChangedRows: the stencils are the two adjacent cells), so

        Delta V_f <= 1/2 |a_S(c1)|^2 + 1/2 |a_S(c2)|^2 + sum over the facets f' of c1, c2 of 1/2 |a_J(f')|^2,

    the energy of the rows next to f: rigorous, not a fraction of G_h (the design note §1.3's
    closed form 1/2 t^T A^-1 t per cell + 1/2 |a_J(f)|^2 omits the neighbours' J rows and fell to
    0.14-0.25 of G_h on rough 1D fields). A cell with a traction facet changes the tractions'
    work too, which no row bounds: +inf there. Equality holds when both cells lose all their
    energy (one-cell fragments)."""
    geom = op.intact
    if geom.d != 1:
        raise InputError("release_bound knows the rows a break changes in 1D only (2D, 3D: issue 34, stage S2)")
    facets = np.asarray(facets, dtype=np.int64)
    a = row_values(op, u, g, t)
    m = op.rows.num_elastic
    energy_S = 0.5 * (a[:m].reshape(geom.num_cells, -1) ** 2).sum(axis=1)
    energy_J = np.zeros(geom.num_facets)
    energy_J[op.jump_facets] = 0.5 * (a[m:].reshape(len(op.jump_facets), -1) ** 2).sum(axis=1)
    cells = geom.facet_cells[facets]
    near = geom.cell_facets[cells].reshape(len(facets), 2 * (geom.d + 1))  # f itself twice
    bound = energy_S[cells].sum(axis=1) + energy_J[near].sum(axis=1) - energy_J[facets]
    bound[np.isin(near, op.reconstruction.traction_facets).any(axis=1)] = np.inf
    return bound
