"""The lagged normal forces of friction between bodies (pair_friction.py; docs/theory.md, "Friction
between bodies"): the pairs' counterpart of the obstacles' Ntilde_f (friction.py).

Each pair p that a process handles (its facet i is an own candidate) carries a lagged normal force
Ntilde_p, which follows the step's mean normal force N_p^+ / dt with the time scale T_p = LAG h_i /
c_i (facet i's diameter, its cell's P-wave speed):

    Ntilde_p^{n+1} = Ntilde_p^n + (1 - exp(-dt / T_p)) (N_p^+ / dt - Ntilde_p^n),

the first step of a run setting Ntilde_p = N_p^+ / dt (the initial state's history) and a pair
that enters the list later starting from 0 (it did not touch). The Coulomb bound of the pair is
mu Ntilde_p dt: it does not see the step's own N_p, whose feedback through the friction opens the
contact at the mesh scale, and it keeps acting, decaying as exp(-t / T_p), on a pair that
separated for a few steps (a contact that chatters gets the mean of its normal force, not the
part of the steps it touches: docs/validation/friction_chatter.md measures both on obstacles).

The state is keyed by the pair's key (``PairList.pair_keys``: its facets' global numbers), which
neither a list rebuild nor the partition changes: a pair keeps its history through the rebuilds
while it is listed; a pair that leaves the list (its facets farther apart than the skin) drops
it, and so does a pair whose Ntilde_p falls below ``TAIL_END`` times the largest of all pairs (its
tail has died out; the maximum is exact on any partition). A checkpoint stores it at facet i's
cell (``table``), so that a resume on any number of processes finds it.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from dolfinx_dem.contact.friction import LAG
from dolfinx_dem.errors import CheckpointError

#: A pair's lagged normal force below this fraction of the largest pair's is dropped (its tail ended)
TAIL_END = 1e-16
_SHIFT = 2**31  # pair key = facet i's global number * _SHIFT + facet j's (PairList.pair_keys)


class PairLag:
    """The lagged normal forces of the pairs this process handles (module docstring), for the
    own candidate facets of a ``PairContact`` ``contact``."""

    def __init__(self, contact):
        dem, own = contact.dem, slice(0, contact.num_own)
        geom = dem.geometry
        facets, self.cells = contact.facets[own], contact.cells[own]
        self.lag = LAG * geom.facet_diameters[facets] / dem.materials.wave_speed(contact.d, self.cells)
        if not (np.isfinite(self.lag).all() and (self.lag > 0).all()):
            raise ValueError("the friction bound's lags must be finite and > 0")
        self.j = np.argmax(geom.cell_facets[self.cells] == facets[:, None], axis=1)  # each facet's place in its cell
        self.facet_key = contact.pair_list.local.key[own].astype(np.int64)
        self._by_key = np.argsort(self.facet_key)
        self.comm, self.d, self.n_owned = contact.comm, contact.d, dem.n_owned
        self.keys, self.values = np.zeros(0, dtype=np.int64), np.zeros(0)  # sorted by key
        self.started = False
        self.active = False  # whether a pair of any process has a lagged normal force (``update``)

    def update(self, keys: np.ndarray, facet: np.ndarray, normal: np.ndarray, dt: float) -> np.ndarray:
        """The lagged normal forces of the handled pairs ``keys`` (their own facets i ``facet``) after
        a step of normal impulses ``normal``; the state becomes theirs (module docstring; collective)."""
        force = np.maximum(normal, 0.0) / dt
        if self.started:
            at = np.minimum(np.searchsorted(self.keys, keys), max(len(self.keys) - 1, 0))
            found = (self.keys[at] == keys) if len(self.keys) else np.zeros(len(keys), dtype=bool)
            previous = np.where(found, self.values[at] if len(self.keys) else 0.0, 0.0)
            lagged = previous - np.expm1(-dt / self.lag[facet]) * (force - previous)
        else:
            lagged, self.started = force, True
        top = self.comm.allreduce(float(lagged.max(initial=0.0)), op=MPI.MAX)
        lagged[lagged < TAIL_END * top] = 0.0
        self.active = top > 0.0  # a pair of some process has a bound (the largest is kept)
        keep = np.flatnonzero(lagged > 0)
        order = keep[np.argsort(keys[keep])]
        self.keys, self.values = keys[order], lagged[order]
        return lagged

    def table(self) -> np.ndarray:
        """The state at the own cells (collective): (n_owned, d + 1, k, 2), row c, column j for the
        facet j of cell c, k slots of (facet j's global number, Ntilde_p) for its pairs (-1, 0:
        none), k the most pairs of a facet on any process."""
        facet = self._by_key[np.searchsorted(self.facet_key[self._by_key], self.keys // _SHIFT)]
        order = np.argsort(facet, kind="stable")
        facet = facet[order]
        first = np.searchsorted(facet, facet)  # the slot of each pair among its facet's
        slot = np.arange(len(facet)) - first
        k = self.comm.allreduce(int(slot.max(initial=-1)) + 1, op=MPI.MAX)
        table = np.zeros((self.n_owned, self.d + 1, k, 2))
        table[..., 0] = -1.0
        table[self.cells[facet], self.j[facet], slot, 0] = self.keys[order] % _SHIFT
        table[self.cells[facet], self.j[facet], slot, 1] = self.values[order]
        return table

    def restore(self, table: np.ndarray) -> None:
        """The state from ``table`` (a step has set it: ``started``)."""
        if table.shape[:2] != (self.n_owned, self.d + 1) or table.ndim != 4 or table.shape[3] != 2:
            raise CheckpointError(f"the pair friction's stored state has the shape {table.shape}, not (cells, "
                                  f"{self.d + 1}, slots, 2)")
        slots = table[self.cells, self.j]  # (own facets, k, 2)
        facet, slot = np.nonzero(slots[..., 0] >= 0)
        keys = self.facet_key[facet] * _SHIFT + slots[facet, slot, 0].astype(np.int64)
        order = np.argsort(keys)
        self.keys, self.values = keys[order], slots[facet, slot, 1][order]
        self.started = True
