"""The state of the contact between bodies at one displacement, a step's free flight and its
events, and the exact force integral (paper §4; pair.py): the closed pairs with their gaps,
overlaps and multipliers, the screen of a flight, and the force integral split at the events and
integrated by Gauss-Legendre on each piece.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from dolfinx_dem.contact.pair_list import PairList, Pairs
from dolfinx_dem.errors import InputError, KernelMemoryError, StateError
from dolfinx_dem.kernels import Struct, ffi, lib, pointer


def gauss_legendre(d: int) -> tuple[np.ndarray, np.ndarray]:
    """d-point Gauss-Legendre nodes and weights on [0, 1]: exact to degree 2 d - 1, the degree
    of a pair's force term between events in dimension d (w of degree d - 1 in tau, c_p and
    z_p . (a + delta_a) of degree d, dc_p/du of degree d - 1)."""
    x, weights = np.polynomial.legendre.leggauss(d)
    return 0.5 + 0.5 * x, 0.5 * weights


class Flight(NamedTuple):
    """The free flight u + tau v, 0 <= tau <= dt, that ``PairContact.prepare`` checked valid for
    a step: the patch values ``up``, ``vp`` of u and v, its screen (``screen_flight``'s struct:
    the free facet velocities vc and the screened pairs that may touch during it, which the
    force integral reads) and whether no pair touches anywhere (``quiet``: the force integral
    adds nothing on any process)."""

    up: np.ndarray
    vp: np.ndarray
    dt: float
    screen: ScreenedFlight
    quiet: bool


class ScreenedFlight(NamedTuple):
    """A flight's screen (``dem_flight``: its touching pairs and its candidates, the pairs near
    closing at its end), in the arrays of its list's ``StepWork``, and its number there: it is
    valid while no later flight of the list was screened (``current``). The state at the flight's
    end reads its candidates only, the force integral its touching pairs."""

    pairs: Pairs
    work: StepWork
    number: int

    @property
    def current(self) -> bool:
        """Whether the screen's arrays still hold this flight (no later one of its list)."""
        return self.work.flights == self.number

    @property
    def flight(self) -> Struct:
        """The flight's struct (``dem_flight``); raises if a later flight overwrote it."""
        if not self.current:
            raise StateError("a flight's screen was overwritten by a later one of its pair list: prepare again")
        return self.work.flight


class StepWork:
    """The arrays of one pair list that each step fills, made once per list (the list's
    ``step_work``, ``of``): a flight's screen (``dem_flight``: vc, the screen, the touching pairs,
    the candidates), numbered (``flights``), and a contact state (``dem_pair_state``), held by one
    ``PairState`` at a time (``state_owner``). What a step hands out of them is copied."""

    def __init__(self, pair_list: PairList):
        n, d, n_facets = len(pair_list.pairs), pair_list.d, pair_list.c_pairs.c.n_facets
        self.pairs = pair_list.pairs
        self.flight = Struct("dem_flight", vc=np.empty((n_facets, d)), screen=np.empty(n, np.int8),
                             touching=np.empty(n, np.int64), candidates=np.empty(n, np.int64))
        self.flights = 0  # flights screened in these arrays
        self._inputs = ()  # the last flight's uc and vp, kept alive while the struct points to them
        self.state = Struct("dem_pair_state", closed=np.empty(n, dtype=np.int64), g=np.empty(n), w=np.empty(n),
                            dw=np.empty((n, d)), c=np.empty(n), mu=np.empty(n))
        self.state_owner = None  # the PairState whose values ``state`` holds

    @staticmethod
    def of(pair_list: PairList) -> StepWork:
        """The step arrays of ``pair_list``'s current list (made anew after a build)."""
        work = pair_list.step_work
        if work is None or work.pairs is not pair_list.pairs:
            work = pair_list.step_work = StepWork(pair_list)
        return work

    def start_flight(self, uc: np.ndarray, vp: np.ndarray, dt: float) -> Struct:
        """The flight struct set to the free facet displacements ``uc``, the patch velocities
        ``vp`` and ``dt``, numbered as a new flight (earlier screens of the list are no longer
        current)."""
        c = self.flight.c
        self._inputs = (uc, vp)
        c.uc, c.vp, c.dt = pointer(uc), pointer(vp), float(dt)
        self.flights += 1
        return self.flight


@dataclasses.dataclass(frozen=True)
class ClosedPairs:
    """The listed pairs ``closed`` whose c_p = w_p g_p^- may not vanish (g_p < 0, projections not
    apart), their gap g, overlap w, dw/du_j, c = w g^- and mu_p = z_p . (a + delta) (own rows'
    part), the energy change of the own rows (elastic, stabilisation) and the sum of mu_p w_p."""

    closed: np.ndarray
    g: np.ndarray
    w: np.ndarray
    dw: np.ndarray
    c: np.ndarray
    mu: np.ndarray
    energy: tuple[float, float]
    mu_w: float


class PairState:
    """The contact state at one displacement (patch values ``up``), computed when it is made, in
    one compiled call (``dem_pair_end_state``): the free facet displacements ``uc``, whether the
    list is stale there (``moved``), and, if it is not, the ``ClosedPairs``. The energy of a
    step's end, the outputs there and the next step's flight share it (``PairContact.state``).

    The state reads the last flight's candidates if they hold here (bit 1 of its screen: the only
    pairs that may be closed, when every facet lies within half the slack of the flight's end, as
    at the step's end, where uc = R u^{n+1} and the flight's end uc^n + dt vc differ by rounding);
    else every listed pair is screened (``candidates``: the pairs screened, None: every listed
    pair). Plain attributes, no descriptors: a state is made at every step."""

    __slots__ = ("pair_list", "listed", "up", "uc", "moved", "candidates", "_closed", "_work")

    def __init__(self, pair_list: PairList, patch: Struct, work, end: ScreenedFlight | None, up: np.ndarray):
        self.pair_list, self.listed = pair_list, pair_list.pairs
        flight = end.flight if end is not None and end.pairs is self.listed and end.current else None
        # a read-only array (MEMM's shared patch values) is kept as it is: ``PairContact.state``
        # then knows it by identity; another is copied, since its caller may change it
        self.up = up if not up.flags.writeable else up.copy()
        self._work = step = StepWork.of(pair_list)
        self.uc = uc = np.empty((len(pair_list.lift), pair_list.d))  # the free facet displacements
        state = step.state
        k = lib.dem_pair_end_state(pair_list.c_pairs.c, patch.c, pointer(self.up),
                                   ffi.NULL if flight is None else flight.c, work, pointer(uc), state.c)
        step.state_owner = self
        if k == -1:
            raise KernelMemoryError("contact between bodies: out of memory in the contact state")
        a, s = state.arrays, state.c
        self.moved = k == -2  # the list is stale here (``PairList.moved``)
        self._closed = None if self.moved else ClosedPairs(
            a["closed"][:k].copy(), a["g"][:k].copy(), a["w"][:k].copy(), a["dw"][:k].copy(), a["c"][:k].copy(),
            a["mu"][:k].copy(), (float(s.energy[0]), float(s.energy[1])), float(s.mu_w))
        self.candidates = flight.arrays["candidates"][: flight.c.n_candidates].copy() if s.from_flight else None

    @property
    def pairs(self) -> ClosedPairs:
        """The closed pairs (raises where the list is stale)."""
        if self.moved:
            self.pair_list.check_listed(self.uc)  # raises
        return self._closed

    @property
    def kernel_state(self) -> Struct:
        """The state for the kernels (``dem_pair_state``, in the list's ``StepWork``; raises where
        the list is stale, or if a later state of the list took its arrays)."""
        if self.moved:
            self.pair_list.check_listed(self.uc)  # raises
        if self._work.state_owner is not self:
            raise StateError("a contact state's arrays hold a later state of its pair list: ask PairContact.state "
                             "for this displacement again")
        return self._work.state


def screen_flight(pair_list: PairList, uc: np.ndarray, vp: np.ndarray, dt: float,
                  screen: bool = True) -> tuple[np.ndarray, int, float, np.ndarray | None, ScreenedFlight]:
    """A step's free flight uc + tau vc, 0 <= tau <= dt, from the free facet displacements
    ``uc`` (known facets' rows) and the patch values ``vp`` of the velocity, in one compiled
    call (``dem_pair_flight``): the free facet velocities vc = R_f v, (n, d); the known facet
    that moves farthest from where the list was built, at the flight's end, relative to half
    its skin: its index k (-1 if none) and (|motion| / (s/2))^2; and, if ``screen`` and that
    ratio is at most 1 (else None), the screen: the listed pairs whose c_p = w_p g_p^- may
    not vanish during the flight, their gap negative at an end and their projections not
    separated by the line of a face at some tau (``overlap.separations``: exact, less a margin;
    one pass over the list; ``dem_pair_end_state`` screens a state with it); and the flight's
    screen (``ScreenedFlight``, in the list's ``StepWork``), which keeps those near closing at
    its end for the state there. vc and the screened pairs are copies."""
    c_pairs = pair_list.c_pairs
    if uc.shape != (c_pairs.c.n_facets, pair_list.d):
        raise InputError(f"free facet displacements of shape {uc.shape} for {c_pairs.c.n_facets} known facets")
    work = StepWork.of(pair_list)
    flight = work.start_flight(uc, vp, dt)
    k = lib.dem_pair_flight(c_pairs.c, int(screen), flight.c)
    ratio, found = float(flight.c.ratio), flight.c.n_touching
    touching = None if found < 0 else flight.arrays["touching"][:found].copy()
    return flight.arrays["vc"].copy(), int(k), ratio, touching, ScreenedFlight(pair_list.pairs, work, work.flights)


def integrate_flight(pair_list: PairList, patch: Struct, gauss: Struct, work, up: np.ndarray, flight: Struct,
                     result: np.ndarray, normal: np.ndarray | None = None) -> int:
    """result += int_0^dt (F - F_free)(u + tau v) dtau at the patch dofs, for the screened pairs
    ``touching`` of the flight of free facet displacements uc + tau vc (patch values up + tau vp;
    ``flight``: the struct of a current ``ScreenedFlight``, which holds them but up), in one compiled call
    (``dem_pair_force_integral``); returns the pieces of the pair integral
    with the most pieces. Each touching pair's events (its gap's and its overlap's kinks); the
    pairs sharing an own row (N_pp' != 0) integrated on common pieces, those cut by the events of
    their connected component of that relation (an impact in another component does not split
    them), where every c_p is a polynomial of degree d and each pair's force term one of degree
    2 d - 1: the d-point rule ``gauss`` is exact; a pair's overlap clipped at the nodes of its own
    pieces only and interpolated at its component's; the rows' term -Q^T Z int c dtau on the own
    rows the touching pairs' z_p touch (a = Q u + q + tau Q v there: no sliced Q or Z) and the
    pairs' term -int (z_p . (a + delta_a)) dc_p/du dtau at the facets. ``normal`` (one per listed
    pair, or None): += this process's part of each touching pair's normal impulse (pair_friction.py)."""
    pieces = lib.dem_pair_force_integral(pair_list.c_pairs.c, patch.c, pointer(up), flight.c, gauss.c, work,
                                         pointer(result), pointer(normal))
    if pieces < 0:
        raise KernelMemoryError("contact between bodies: out of memory in the force integral of a step")
    return pieces
