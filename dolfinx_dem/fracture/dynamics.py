"""Facets breaking in a MEMM run, with the energy balance exact (issue 34; design note
``docs/design/fracture.md`` §2).

MEMM conserves E^n = 1/2 (v^{n-1/2})^T M v^{n+1/2} + V(u^n) when each flight's force integral
is that of one potential (memm.py, paper eq. (35a)-(35b)). Nothing ties one flight's potential
to the next one's, so the operator may change at a step boundary t_n: E^n then jumps by
-Delta V(u^n) = -[V_old(u^n) - V_new(u^n)] and is conserved from there on, so that

    P^n + D^n + Gamma^n - W^n = P^0,    Gamma^n = sum over the breaks of (P_old - P_new),

P the pseudo-energy (``Diagnostics.pseudo_energy``), D friction's dissipation and W the data's
work (none with fracture yet). Gamma is booked as the difference of the two reported
pseudo-energies at t_n, so the balance holds whatever the rounding of the recurrence; it equals
the drop Delta V(u^n) = G_h |f| of the broken facets (release.py) to rounding.

At each step boundary (``update``, called by ``MEMM.step`` after the step):

1. G_h of the breakable facets not yet broken that pass the screen (``release_bound``: an
   upper bound on Delta V from the energy of the rows a break can change, rigorous in 1D, so
   the screen misses no break), each broken alone at fixed u^n (release.py; every trial is the
   local rebuild of rebuild.py: one code path with the actual break);
2. accepted: those with G_h >= G_c (the literal Griffith criterion, option 1 of the design
   note §1.6), by decreasing G_h (ties by the geometric key x + pi y + e z), each only if its
   changed S cells and J facets are disjoint from those of the facets accepted before (then
   their drops add up exactly); the others are tried again at the next step;
3. the accepted facets broken together (``break_facets``), the operator installed in the
   discretisation (``DEMDiscretisation.replace_operator``: rows sorted, factored, boundary data,
   free bodies, stable step), the stable step checked against dt (InstabilityError if a break
   made it unstable: MEMM cannot change dt), the stepper restarted on the new rows
   (``MEMM.rows_changed``), and Gamma += P_old - P_new.

Then ``fracture_energy`` = G_c x ``cracked_area`` and ``fracture_excess`` = Gamma -
``fracture_energy`` >= 0 (a facet breaks at the first step boundary where G_h >= G_c, so each
break releases G_c |f| plus an excess of order dt dG_h/dt).

Supported in this stage: one process, 1D (a facet is a vertex, every break separates the bar;
2D and 3D cracks have tips, stage S2), one material, constant data, no contact, no prescribed
body, no checkpoint; the others are refused, naming issue 34.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from dolfinx_dem.errors import InputError, InstabilityError, StateError, UnresolvedContactError
from dolfinx_dem.fracture.crack import CrackState
from dolfinx_dem.fracture.operator import Conditions, compute_operator, lip_openings
from dolfinx_dem.fracture.rebuild import break_facets
from dolfinx_dem.fracture.release import release_bound, trial_breaks


@dataclasses.dataclass(frozen=True)
class Break:
    """The facets (intact geometry's indices) broken at ``step``, their G_h (J/m^2) and the
    pseudo-energy their break took, Gamma's increment (J in 3D; per unit length, J/m, in 2D;
    per unit cross-section, J/m^2, in 1D, where |f| = 1)."""

    step: int
    facets: np.ndarray
    release_rates: np.ndarray
    energy: float


class Fracture:
    """Facets of ``dem`` (a ``DEMDiscretisation``) that break when their G_h reaches ``Gc``
    (J/m^2) in a MEMM run (module docstring). ``breakable``: the interior facets that may break
    (indices of ``dem``'s geometry; default: all interior facets). ``screen``: trial only the
    facets whose ``release_bound`` reaches G_c |f| (the same breaks, fewer trials). Give it to
    the problem: ``DEMProblem(dem, fracture=Fracture(dem, Gc))``."""

    #: the series columns (``values``)
    COLUMNS = ("fracture_energy", "cracked_area", "fracture_excess")

    #: the screen's margin: ``release_bound`` equals Delta V for one-cell fragments, up to rounding
    SCREEN_MARGIN = 1e-12

    #: the lips' overlap, over the facet's diameter h_f, at which a run stops (``_check_lips``)
    LIP_OVERLAP = 1e-3

    def __init__(self, dem, Gc: float, breakable: np.ndarray | None = None, screen: bool = True):
        refused = [what for what, present in (
            (f"{dem.comm.size} processes (stage S3)", dem.comm.size > 1),
            (f"{dem.d}D meshes (cracks with tips: stage S2)", dem.d > 1),
            ("several materials", len(dem.materials.materials) > 1),
            ("prescribed bodies", bool(dem.prescribed.flags.any())),
            ("time-dependent data", dem.data.time_dependent)) if present]
        if refused:
            raise InputError(f"fracture (issue 34) is not implemented with {', '.join(refused)} yet: one process, "
                             "1D, one material, constant data")
        if not (math.isfinite(Gc) and Gc > 0):
            raise InputError(f"the fracture energy Gc must be a positive number (J/m^2), got {Gc!r}")
        self.dem, self.Gc, self.screen = dem, float(Gc), screen
        self.trials = 0  # the number of trial breaks so far
        geom, rec = dem.geometry, dem.reconstruction
        self.intact = geom
        conditions = Conditions(dem.materials, rec.scheme, rec.dirichlet_facets, rec.fixed, rec.traction_facets,
                                dem.scheme_b_facets)
        #: the current operator (operator.py): the crack set and its rows, installed in ``dem``
        self.operator = compute_operator(geom, conditions, CrackState.intact(geom), dem.comm)
        interior = geom.interior_facets
        self.breakable = interior if breakable is None else np.unique(np.asarray(breakable, dtype=np.int64))
        if not np.isin(self.breakable, interior).all():
            bad = self.breakable[~np.isin(self.breakable, interior)][0]
            raise InputError(f"breakable facet {bad} is not an interior facet of the mesh")
        self._key = geom.facet_centres @ np.array([1.0, np.pi, np.e][: geom.d])  # ties (design note §4)
        self.gamma = 0.0  # Gamma^n (J)
        self.cracked_area = 0.0  # sum of |f| over the broken facets (m^2)
        self.breaks: list[Break] = []

    @property
    def fracture_energy(self) -> float:
        """G_c times the cracked area (J)."""
        return self.Gc * self.cracked_area

    @property
    def excess(self) -> float:
        """Gamma - G_c x cracked area (J): what the breaks released beyond G_c |f|."""
        return self.gamma - self.fracture_energy

    def values(self) -> list[float]:
        """The values of ``COLUMNS`` now."""
        return [self.fracture_energy, self.cracked_area, self.excess]

    def check_intact(self):
        """Raises StateError once something broke (a run starts from the intact discretisation)."""
        if self.breaks:
            raise StateError("MEMM.initialise after facets broke: build the discretisation and its Fracture again")

    def _check_lips(self, stepper, diag, data):
        """UnresolvedContactError once the lips of a broken facet pass through each other by more
        than ``LIP_OVERLAP`` of its diameter h_f (eq. (13)): nothing resists it before contact of
        the lips and fragments (design stage S5), so the run stops rather than go on wrong."""
        broken = self.operator.broken
        if not len(broken):
            return
        opening = lip_openings(self.operator, broken, stepper.u.array_r, *data)
        limit = -self.LIP_OVERLAP * self.intact.facet_diameters[broken]
        worst = int(np.argmin(opening - limit))
        if opening[worst] < limit[worst]:
            x = self.intact.facet_centres[broken[worst]].tolist()
            raise UnresolvedContactError(
                f"at t = {diag.t:.6g} (step {diag.step}) the lips of the broken facet at {x} pass through each other "
                f"by {-opening[worst]:.3g} m: the fragments met again, and contact between crack lips and fragments "
                "is not implemented yet (issue 34, stage S5); the run stops rather than let them interpenetrate")

    def update(self, stepper, diag):
        """At the step boundary t_n of ``diag`` (after ``MEMM.step``): break the facets the
        criterion accepts and return the diagnostics at t_n (the new ones if something broke,
        with Gamma^n; module docstring)."""
        # at u^n less the free bodies' mean translations, which no row sees (as the stepper's y^n)
        w = self.dem.bodies.relative_displacement(stepper.u).array_r.copy()
        data = self.dem.data.facet_data()
        candidates = self.breakable[~np.isin(self.breakable, self.operator.broken)]
        if self.screen:
            bound = release_bound(self.operator, candidates, w, *data)
            candidates = candidates[bound >= (1 - self.SCREEN_MARGIN) * self.Gc * self.intact.facet_areas[candidates]]
        self._check_lips(stepper, diag, data)
        G, changes, opening = trial_breaks(self.operator, candidates, w, self.dem.comm, *data, step=diag.step)
        self.trials += len(candidates)
        over = np.flatnonzero((G >= self.Gc) & (opening > 0))  # lips that would close: no crack opens
        if not len(over):
            return diag
        accepted, cells, jumps = [], np.empty(0, np.int64), np.empty(0, np.int64)
        for i in over[np.lexsort((self._key[candidates[over]], -G[over]))]:
            if not (np.isin(changes[i].cells, cells).any() or np.isin(changes[i].jump_facets, jumps).any()):
                accepted.append(i)
                cells, jumps = np.union1d(cells, changes[i].cells), np.union1d(jumps, changes[i].jump_facets)
        facets = candidates[accepted]
        self.operator = op = break_facets(self.operator, facets, diag.step, self.dem.comm)
        self.dem.replace_operator(op.geometry, op.reconstruction, op.rows)
        stable = self.dem.stable_time_step()
        if stepper.dt > stable:
            reason = (f"the break of facets {facets.tolist()} at {self.intact.facet_centres[facets].tolist()} raised "
                      f"the bound on lambda_max(M^-1 K): stable step {stable:.6g} < dt")
            raise InstabilityError(f"MEMM is unstable at step {diag.step} (t = {diag.t:.6g}, dt = {stepper.dt:.6g}): "
                                   f"{reason}; lower time.cfl", diag.step, diag.t, stepper.dt, 0.5 * stable, reason)
        new = stepper.rows_changed()
        energy = diag.pseudo_energy - new.pseudo_energy
        self.gamma += energy
        self.cracked_area += float(self.intact.facet_areas[facets].sum())
        self.breaks.append(Break(diag.step, facets, G[accepted], energy))
        return dataclasses.replace(new, fracture=self.gamma)
