"""Boundary conditions and imposed motions of a DEM discretisation: Dirichlet conditions,
tractions and prescribed bodies, and the facets a DOLFINx user selects them by.

Facets are given as process-local facet indices (``dolfinx.mesh.locate_entities_boundary``,
``dolfinx_dem.locate_boundary_facets``) or as a DOLFINx ``MeshTags`` of the facets: all its
facets when it holds one value, or those of ``tag``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError


def _is_meshtags(obj) -> bool:
    return all(hasattr(obj, name) for name in ("indices", "values", "dim", "find"))


def facet_indices(facets, tag: int | None, what: str, tdim: int) -> np.ndarray:
    """The process-local facet indices (int32) that ``facets`` selects: an array of indices, or a
    DOLFINx MeshTags of dimension tdim - 1 (its facets of value ``tag``; with ``tag`` None it must
    hold one value, or the choice would be a guess). Collective for a MeshTags."""
    if _is_meshtags(facets):
        if facets.dim != tdim - 1:
            raise InputError(f"{what}: the MeshTags tags entities of dimension {facets.dim}, not facets "
                             f"(dimension {tdim - 1})")
        if tag is not None:
            return np.asarray(facets.find(int(tag)), dtype=np.int32)
        # the values over all processes (a handful of tags): every process decides alike
        comm = _compat.meshtags_comm(facets)
        values = sorted(set().union(*comm.allgather(np.unique(facets.values).tolist())))
        if len(values) > 1:
            raise InputError(f"{what}: the MeshTags holds the values {values}; pass tag=... to select "
                             "the facets of one of them")
        return np.asarray(facets.indices, dtype=np.int32)
    if tag is not None:
        raise InputError(f"{what}: tag={tag} selects among the values of a MeshTags, but facet indices were given")
    array = np.asarray(facets)
    if array.ndim != 1 or not (array.size == 0 or np.issubdtype(array.dtype, np.integer)):
        raise InputError(f"{what}: facets must be a 1D array of facet indices or a DOLFINx MeshTags, got "
                         f"{type(facets).__name__} of shape {array.shape} and dtype {array.dtype}")
    return array.astype(np.int32)


@dataclasses.dataclass(frozen=True)
class DirichletBC:
    """u_f = value on the given boundary facets, in the components ``components`` (default: all
    d; a roller or a symmetry plane fixes some). The free components of the facets carry no
    traction (scheme A solves (sigma_c n_f)_i = 0 for them, reconstruction.py).

    ``facets``: process-local facet indices or a DOLFINx MeshTags (with ``tag``, its facets of
    that value). ``value`` is a constant vector of length d, or a callable ``value(x, t)`` with
    x of shape (d, n) (facet barycentres) returning shape (d, n); its free components are
    ignored. Pass ``time_dependent=True`` when the callable depends on t; otherwise it is
    evaluated once. ``name`` names the condition's reaction (``DEMDiscretisation.reactions``).
    """

    facets: np.ndarray
    value: Sequence[float] | Callable
    time_dependent: bool = False
    components: Sequence[int] | None = None
    name: str | None = None
    tag: int | None = None


@dataclasses.dataclass(frozen=True)
class Traction:
    """A surface traction t (force per unit area, Pa; per unit length in 2D) on the given
    boundary facets, which must carry no Dirichlet condition. ``facets``, ``tag`` and ``value``
    as for ``DirichletBC``."""

    facets: np.ndarray
    value: Sequence[float] | Callable
    time_dependent: bool = False
    tag: int | None = None


@dataclasses.dataclass(frozen=True)
class PrescribedBody:
    """A body whose motion is imposed, a rigid translation U(t) (m): the cells of cell tag ``tag``,
    which must form whole bodies. Exactly one of ``velocity``, a constant vector of length d
    (U(t) = velocity t), and ``displacement``, a callable ``displacement(t)`` returning d numbers
    (U(t) itself). ``name`` names its reaction and displacement columns in outputs (default: its
    number after the Dirichlet conditions). It acts as an indenter, a punch or a moving wall in
    contact between bodies (contact/pair.py); MEMM counts the work it does (memm.py)."""

    tag: int
    velocity: Sequence[float] | None = None
    displacement: Callable[[float], Sequence[float]] | None = None
    name: str | None = None

    def translation(self, t: float, d: int) -> np.ndarray:
        """U(t), shape (d,)."""
        if self.displacement is None:
            return t * np.asarray(self.velocity, dtype=float)
        U = np.asarray(self.displacement(t), dtype=float).reshape(-1)
        if U.shape != (d,) or not np.isfinite(U).all():
            raise InputError(f"prescribed body {self.tag}: displacement({t:.9g}) must be {d} finite numbers, "
                             f"got {U.tolist()}")
        return U


def facet_values(what: str, conditions, facet_order: np.ndarray, centres: np.ndarray, d: int, t: float):
    """The values at time t of ``conditions`` (pairs (facets, condition with ``value`` and
    ``time_dependent``)) at their facets, (len(facet_order), d) in the order of ``facet_order``;
    a condition that is not time dependent is evaluated at t = 0."""
    values = np.zeros((len(facet_order), d))
    for facets, bc in conditions:
        index = np.searchsorted(facet_order, facets)
        if callable(bc.value):
            values[index] = np.asarray(bc.value(centres[facets].T, t if bc.time_dependent else 0.0),
                                       dtype=float).reshape(d, -1).T
        else:
            value = np.asarray(bc.value, dtype=float)
            if value.shape != (d,):
                raise InputError(f"a constant {what} value needs {d} components, got {value.shape}")
            values[index] = value
    if not np.isfinite(values).all():
        k = int(np.argmax(~np.isfinite(values).all(axis=1)))
        raise InputError(f"the {what} value at t = {t:.9g} is not finite: {values[k].tolist()} on the facet at "
                         f"{centres[facet_order[k]].tolist()}")
    return values
