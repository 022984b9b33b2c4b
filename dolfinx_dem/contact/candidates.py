"""Contact candidate facets: the declared boundary facets a contact model tests, and the checks
shared by every model (they must be boundary facets without a Dirichlet condition or a
traction, and the data must be constant in time).

Each process owns the candidate facets of its owned cells and knows those of its first halo
layer (their rows are among the rows it holds, contact/patch.py).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from mpi4py import MPI

from dolfinx_dem.errors import InputError
from dolfinx_dem.halo import owned_facet_marks


@dataclasses.dataclass(frozen=True)
class Candidates:
    """The candidate facets of the cells of halo layers 0 and 1: cell ``cell`` (local), its
    facet ``j`` (local index in the cell, opposite vertex j), the local facet ``facet``, whether
    the cell is ``owned``, and the mark of each (its value in the model's marking: the obstacle,
    0 for a contact boundary)."""

    cell: np.ndarray
    j: np.ndarray
    facet: np.ndarray
    owned: np.ndarray
    mark: np.ndarray


def select(dem, facets: np.ndarray, values: np.ndarray, what: str) -> Candidates:
    """The candidates of ``dem`` marked with ``values`` on the process-local ``facets`` (a facet
    marked twice with different values: an InputError naming ``what``). Collective."""
    geom = dem.geometry
    marks = dem.halo_exchange(owned_facet_marks(dem.mesh, facets, values, what))
    cell, j = np.nonzero((marks >= 0) & (geom.cell_layer <= 1)[:, None])
    return Candidates(cell, j, geom.cell_facets[cell, j], cell < dem.n_owned, marks[cell, j])


def check(dem, candidates: Candidates, name: str) -> None:
    """The checks every contact model makes of its candidates (``name`` begins the messages):
    they must be boundary facets, carry neither a Dirichlet condition nor a traction, and the
    Dirichlet and traction data must be constant in time (a contact model reads the lift of its
    rows once). Collective: raised on every process."""
    geom, rec, comm = dem.geometry, dem.reconstruction, dem.comm
    f = candidates.facet[candidates.owned]
    interior = geom.facet_cells[f, 1] >= 0
    bad = [b for part in comm.allgather(geom.facet_centres[f[interior][:1]].tolist()) for b in part]
    if bad:
        raise InputError(f"{name}: contact candidates must be boundary facets; the facet at {bad[0]} is interior")
    if comm.allreduce(bool(np.isin(f, rec.dirichlet_facets).any()), op=MPI.LOR):
        raise InputError(f"{name}: contact candidate facets must not carry a Dirichlet condition")
    if comm.allreduce(bool(np.isin(f, rec.traction_facets).any()), op=MPI.LOR):
        raise InputError(f"{name}: contact candidate facets must not carry a traction")
    if dem.data.time_dependent:
        raise InputError("contact with time-dependent Dirichlet conditions or tractions is not supported")
