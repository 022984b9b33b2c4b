"""Reference solutions of the 1D dynamic Signorini benchmarks (DEM paper §5.1).

The two benchmarks are those of Doyen, Ern & Piperno, "Time-integration schemes for the finite
element dynamic Signorini problem", SIAM J. Sci. Comput. 33(1) (2011) 223-249 (§5 there): a 1D
linear elastic bar of length ``L`` (m), density ``rho`` (kg/m^3) and Young's modulus ``E`` (Pa),
wave speed ``c = sqrt(E / rho)`` (m/s), occupies ``[h0, h0 + L]`` at ``t = 0`` above a rigid
obstacle at ``x = 0``; ``h0 > 0`` (m) is the initial gap. Its lower end (reference coordinate
``X = 0``) is the contact end, its upper end (``X = L``) is free. The outputs are

* the tip position ``x_tip(t) = h0 + u(t, X=0) >= 0`` (m), and
* the contact pressure ``p(t) = -sigma(t, X=0) >= 0`` (Pa), the compressive normal stress at the
  contact end, zero when the bar is not in contact.

All quantities are SI; time ``t`` in s. Functions of ``t`` accept scalars or arrays of any shape
and return float arrays of the same shape.

Benchmark 1 (``impact_*``): ``L = 10, rho = 1, E = 900 (c = 30), h0 = 5``, uniform initial
velocity ``v0 = -10``, no gravity. Closed form: free flight until ``t1 = h0 / |v0|``, contact on
``[t1, t1 + 2 L / c)`` with ``x_tip = 0`` and ``p = rho c |v0|``, then a rigid rebound with
velocity ``|v0|`` and no stress.

Benchmark 2 (``bounce_*``): the same bar released at rest under gravity ``g = 10`` (body force
``-rho g``); first contact at ``t = sqrt(2 h0 / g) = 1`` with velocity ``-g t = -10``, then
``p(t) = rho c g t = 300 t`` on ``[1, 1 + 2 L / c) = [1, 5/3)``, released at ``5/3`` with
``p(5/3^-) = 500``. It is computed by the method of characteristics below, exact on its grid.
What the solver finds (checked in ``tests/test_exact.py``, not imposed): the solution is
periodic with period ``16/3`` s, when the bar is back at rest, unstressed, at height ``h0``.
Each period holds two contacts of ``2 L / c = 2/3`` s, 8/3 s apart (on ``[1, 5/3)`` and
``[11/3, 13/3)``); the first starts with ``p = 300`` rising to 500, the second with 500 falling
to 300, because the motion is symmetric under ``t -> 16/3 - t``. 8/3 s is not a period: the bar
leaves the first contact vibrating (during the flight its elastic energy is 2000/27 = 74.07
J/m^2 of the 1000 J/m^2 total; the tip comes up only to 4.44 m and its velocity jumps at each
wave arrival) and the second contact takes that vibration out again.

Method of characteristics (:func:`signorini_bar_characteristics`). With ``v = u_t`` and
``sigma = E u_X`` the bar obeys ``v_t = sigma_X / rho - g``, ``sigma_t = E v_X``. The Riemann
invariants ::

    w+ = v - sigma / (rho c)   (transported with speed +c, towards the free end)
    w- = v + sigma / (rho c)   (transported with speed -c, towards the contact end)

satisfy ``dw/dt = -g`` along their characteristics ``dX/dt = +-c``. On the grid
``X_j = j dx``, ``t_k = k dt`` with ``dx = c dt`` a characteristic leaving a node at ``t_k``
arrives at the neighbouring node at ``t_{k+1}``: each field is shifted by one cell per step and
decreased by ``g dt``, with no interpolation. Each cell stores the two end values (one-sided
limits) of ``w+`` and ``w-``, linear inside the cell, so discontinuities on the nodes (the
impact shock and its reflections) are represented exactly; with constant initial data the
fields stay piecewise linear with kinks and jumps on nodes only as long as the contact status
changes only at grid times. Boundary conditions, reflected within the boundary cell:

* free end ``X = L``: ``sigma = 0``, i.e. ``w- = w+``;
* contact end ``X = 0``, free (``sigma = 0``): ``w+ = w-``, tip velocity ``v = w-``;
* contact end in contact (``v = 0``): ``w+ = -w-``, ``sigma = rho c w-`` which must be ``<= 0``.

The status is chosen at the start of every step from the one-sided (``t_k^+``) values: a free
tip switches to contact when its position, integrated exactly from the tip velocity (linear in
time within a step), reaches 0 with a downward velocity; a tip in contact is released when the
incoming ``w-`` makes the reaction tensile (``w- > 0``). The solution is then exact up to
round-off on the grid (and, because it is piecewise linear/quadratic within steps, between grid
times) whenever every status change falls on a grid time; a status change strictly inside a
step is recorded in ``events`` with ``on_grid = False`` (the status then switches at the next
grid time, a first-order local error) and a :class:`RuntimeWarning` is issued. Benchmark 1
(``t1 = 0.5 = 1.5 n dt``, ``2 L / c = 2 n dt``) is on the grid for even ``n``; benchmark 2's
events lie on multiples of 1/3 s, on the grid for every ``n`` (``dt = 1 / (3 n)``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings

import numpy as np

from dolfinx_dem.errors import InputError

__all__ = [
    "BarSolution",
    "signorini_bar_characteristics",
    "impact_tip_position",
    "impact_tip_velocity",
    "impact_contact_pressure",
    "bounce_solution",
    "bounce_tip_position",
    "bounce_contact_pressure",
    "BOUNCE_PERIOD",
]

BOUNCE_PERIOD = 16.0 / 3.0
"""Period (s) of benchmark 2 with its default data, as found by the characteristic solver."""

_BOUNCE_N = 120  # default cells of the cached benchmark 2 solution (dt = 1/360 s)


@dataclasses.dataclass(frozen=True)
class BarSolution:
    """Grid solution of the 1D Signorini bar (:func:`signorini_bar_characteristics`).

    Time series have shape ``(n_steps + 1,)`` on ``t[k] = k dt``. Where the tip velocity or the
    pressure jumps at a grid time, ``v_tip`` and ``p`` are the right limits (the values on the
    step starting at ``t[k]``) and ``v_tip_minus``, ``p_minus`` the left limits (``p_minus[0]``,
    ``v_tip_minus[0]`` repeat the initial values). Within a step the tip velocity and the
    pressure are linear and the tip position quadratic; :meth:`tip_position` and
    :meth:`contact_pressure` evaluate them so at any time in ``[0, t_end]``.

    Attributes
    ----------
    t : grid times (s).
    x_tip : tip position ``h0 + u(t, 0)`` (m), ``>= 0``.
    v_tip, v_tip_minus : tip velocity (m/s), right and left limits.
    p, p_minus : contact pressure ``-sigma(t, 0)`` (Pa), right and left limits, ``>= 0``.
    contact : status on each step ``[t[k], t[k+1])``, shape ``(n_steps,)``.
    kinetic, elastic, gravity : energies per unit cross-section (J/m^2) from the grid fields:
        ``int rho v^2 / 2``, ``int sigma^2 / (2 E)`` and ``int rho g x dX`` (potential of the
        body force, zero at the obstacle).
    w_plus, w_minus : final fields, shape ``(n, 2)``: the values of ``w+``, ``w-`` (m/s) at the
        lower and upper end of each cell at ``t[-1]``.
    events : tuples ``(time, kind, on_grid)`` with kind ``"contact"`` or ``"release"``.
    n, dt, dx, L, rho, E, g : grid and data.
    """

    t: np.ndarray
    x_tip: np.ndarray
    v_tip: np.ndarray
    v_tip_minus: np.ndarray
    p: np.ndarray
    p_minus: np.ndarray
    contact: np.ndarray
    kinetic: np.ndarray
    elastic: np.ndarray
    gravity: np.ndarray
    w_plus: np.ndarray
    w_minus: np.ndarray
    events: tuple
    n: int
    dt: float
    dx: float
    L: float
    rho: float
    E: float
    g: float

    @property
    def energy(self) -> np.ndarray:
        """Total energy ``kinetic + elastic + gravity`` (J/m^2), shape ``(n_steps + 1,)``."""
        return self.kinetic + self.elastic + self.gravity

    @property
    def exact(self) -> bool:
        """True when every status change fell on a grid time (the solution is then exact)."""
        return all(on_grid for _, _, on_grid in self.events)

    def _locate(self, t):
        t = np.asarray(t, dtype=float)
        if np.any(t < -1e-12 * self.dt) or np.any(t > self.t[-1] * (1 + 1e-14) + 1e-12 * self.dt):
            raise InputError(f"times must lie in [0, {self.t[-1]}]")
        k = np.clip(np.floor(t / self.dt + 1e-9).astype(int), 0, len(self.t) - 2)
        return t, k, np.clip(t - self.t[k], 0.0, self.dt)

    def tip_position(self, t) -> np.ndarray:
        """Tip position (m) at times ``t`` (s) in ``[0, t_end]``, exact within steps."""
        t, k, s = self._locate(t)
        a, b = self.v_tip[k], self.v_tip_minus[k + 1]
        x = self.x_tip[k] + a * s + (b - a) * s**2 / (2 * self.dt)
        return np.where(self.contact[k], 0.0, np.maximum(x, 0.0))

    def contact_pressure(self, t) -> np.ndarray:
        """Contact pressure (Pa) at times ``t`` (s), right-continuous, linear within steps."""
        t, k, s = self._locate(t)
        p = self.p[k] + (self.p_minus[k + 1] - self.p[k]) * s / self.dt
        return np.where(self.contact[k], p, 0.0)


class _Energies:
    """Kinetic, elastic and gravity energy of the piecewise-linear cell fields (exact quadrature).

    With ``v = (w+ + w-) / 2`` and ``sigma = rho c (w- - w+) / 2`` linear in each cell:
    ``int f^2 = dx / 3 (f_lo^2 + f_lo f_hi + f_hi^2)`` per cell, and the body-force potential
    ``rho g int_0^L x dX`` with ``x(X) = x_tip + int_0^X (1 + sigma / E)``, i.e.
    ``int_0^L x dX = L x_tip + L^2 / 2 + int_0^L (L - X) sigma / E dX``.
    """

    def __init__(self, n, dx, L, rho, E, g):
        c = math.sqrt(E / rho)
        lo = L - dx * np.arange(n)  # L - X at the lower and upper end of each cell
        hi = lo - dx
        scale = dx / 6.0 * 0.5 * rho * c / E  # int of a product of linear functions, sigma / E
        self.weights = np.column_stack([2 * lo + hi, lo + 2 * hi]).ravel() * scale
        self.k_kin = 0.5 * rho * dx / 3.0 * 0.25
        self.k_ela = (0.5 * rho * c) ** 2 * dx / 3.0 / (2.0 * E)
        self.rho_g, self.L = rho * g, L

    def __call__(self, wp, wm, x_tip):
        v = (wp + wm).ravel()  # 2 v
        s = (wm - wp).ravel()  # 2 sigma / (rho c)
        kinetic = self.k_kin * (v @ v + v[0::2] @ v[1::2])
        elastic = self.k_ela * (s @ s + s[0::2] @ s[1::2])
        gravity = self.rho_g * (self.L * x_tip + 0.5 * self.L * self.L + s @ self.weights)
        return kinetic, elastic, gravity


def signorini_bar_characteristics(L, rho, E, v0, g, h0, t_end, n) -> BarSolution:
    """Exact grid solution of the 1D dynamic Signorini bar by the method of characteristics.

    The bar (length ``L`` m, density ``rho`` kg/m^3, Young's modulus ``E`` Pa) starts unstressed
    with uniform velocity ``v0`` (m/s, negative towards the obstacle) with its lower end at
    height ``h0 > 0`` (m) above a rigid obstacle at ``x = 0``; gravity ``g`` (m/s^2, ``>= 0``)
    pulls it towards the obstacle. ``n`` cells, ``dx = L / n``, ``dt = dx / c``, and
    ``ceil(t_end / dt)`` steps (the last grid time may exceed ``t_end`` by less than ``dt``).
    See the module docstring for the method (Doyen, Ern & Piperno 2011, §5 benchmarks).
    Benchmark 1 is ``g = 0, v0 = -10``; benchmark 2 is ``v0 = 0, g = 10``.

    Returns a :class:`BarSolution`. Cost: ``O(n * t_end / dt)``, vectorised over the cells.
    """
    L, rho, E, v0, g, h0, t_end = (float(a) for a in (L, rho, E, v0, g, h0, t_end))
    n = int(n)
    if min(L, rho, E) <= 0 or h0 < 0 or g < 0 or t_end < 0 or n < 1:
        raise InputError("need L, rho, E > 0, h0 >= 0, g >= 0, t_end >= 0 and n >= 1")
    c = math.sqrt(E / rho)
    dx = L / n
    dt = dx / c
    n_steps = int(math.ceil(t_end / dt - 1e-9))
    scale_v = abs(v0) + g * max(t_end, dt) + 1.0
    tol_v = 1e-12 * scale_v
    tol_x = 1e-11 * (h0 + L + scale_v * dt)

    wp = np.full((n, 2), v0)  # unstressed: w+ = w- = v0
    wm = np.full((n, 2), v0)
    new_wp = np.empty_like(wp)
    new_wm = np.empty_like(wm)

    t = np.arange(n_steps + 1) * L / (n * c)  # k dt, exact where k dt is (0.5 = 90 L / (60 c))
    x_tip = np.empty(n_steps + 1)
    v_r, v_l = np.empty(n_steps + 1), np.empty(n_steps + 1)
    p_r, p_l = np.empty(n_steps + 1), np.empty(n_steps + 1)
    contact = np.zeros(n_steps + 1, dtype=bool)  # the last entry: status just after t_end
    kin, ela, grav = np.empty(n_steps + 1), np.empty(n_steps + 1), np.empty(n_steps + 1)
    events = []
    energies = _Energies(n, dx, L, rho, E, g)
    x = h0
    in_contact = False
    pending = False  # a status change inside the previous step, already recorded
    x_tip[0], v_l[0], p_l[0] = x, v0, 0.0

    for k in range(n_steps + 1):
        a, b = wm[0, 0], wm[0, 1]  # w- at the contact end: t_k^+ and (before -g dt) t_{k+1}^-
        end = b - g * dt
        # status on [t_k, t_{k+1}) from the one-sided values at t_k^+
        if in_contact:
            if a > tol_v or (a >= -tol_v and end > tol_v):
                in_contact = False
                if not pending:
                    events.append((t[k], "release", True))
                pending = False
            elif end > tol_v and not pending:  # the reaction turns tensile inside the step
                events.append((t[k] + dt * a / (a - end), "release", False))
                pending = True
        elif x <= tol_x and (a < -tol_v or (a <= tol_v and end < -tol_v)):
            in_contact = True
            x = 0.0
            if not pending:
                events.append((t[k], "contact", True))
            pending = False
        x_tip[k] = x
        contact[k] = in_contact
        v_r[k] = 0.0 if in_contact else a
        p_r[k] = -rho * c * a if in_contact else 0.0
        kin[k], ela[k], grav[k] = energies(wp, wm, x)
        if k == n_steps:
            break

        # tip over the step; free: v = a + (b - a) s / dt - g s, exactly integrated
        if in_contact:
            v_l[k + 1], p_l[k + 1] = 0.0, -rho * c * end
        else:
            x = x + 0.5 * dt * (a + b) - 0.5 * g * dt * dt
            v_l[k + 1], p_l[k + 1] = end, 0.0
            if x < -tol_x:  # the tip reaches the obstacle inside the step
                coeffs = [0.5 * (b - a) / dt - 0.5 * g, a, x_tip[k]]
                roots = [r.real for r in np.roots(coeffs)
                         if abs(r.imag) < 1e-12 and 0 <= r.real <= dt]
                events.append((t[k] + (min(roots) if roots else dt), "contact", False))
                pending = True
                x = 0.0
            elif x < 0.0:
                x = 0.0

        # transport: shift by one cell, -g dt along every characteristic, reflect at the ends
        sign = -1.0 if in_contact else 1.0
        new_wp[1:] = wp[:-1] - g * dt
        new_wm[:-1] = wm[1:] - g * dt
        new_wm[-1, 0] = wp[-1, 1] - g * dt  # free end: w- = w+, mirrored in the last cell
        new_wm[-1, 1] = wp[-1, 0] - g * dt
        new_wp[0, 0] = sign * end  # contact end: w+ = +-w-, mirrored in the first cell
        new_wp[0, 1] = sign * a - g * dt
        wp, new_wp = new_wp, wp
        wm, new_wm = new_wm, wm

    if not all(on_grid for _, _, on_grid in events):
        off = [ev for ev in events if not ev[2]]
        warnings.warn(
            f"{len(off)} contact status change(s) between grid times (first at t = "
            f"{off[0][0]:.6g} s): the characteristic solution is not exact; choose n so that "
            "they fall on the grid",
            RuntimeWarning, stacklevel=2,
        )
    return BarSolution(
        t=t, x_tip=x_tip, v_tip=v_r, v_tip_minus=v_l, p=p_r, p_minus=p_l,
        contact=contact[:-1].copy(), kinetic=kin, elastic=ela, gravity=grav,
        w_plus=wp.copy(), w_minus=wm.copy(), events=tuple(events),
        n=n, dt=dt, dx=dx, L=L, rho=rho, E=E, g=g,
    )


# -- benchmark 1: closed form ---------------------------------------------------------------------


def _impact_times(L, rho, E, v0, h0):
    c = math.sqrt(E / rho)
    if v0 >= 0:
        return math.inf, math.inf, c
    t1 = h0 / abs(v0)
    return t1, t1 + 2.0 * L / c, c


def impact_tip_position(t, L=10.0, rho=1.0, E=900.0, v0=-10.0, h0=5.0):
    """Benchmark 1 tip position (m) at times ``t`` (s), closed form, same shape as ``t``.

    ``h0 + v0 t`` before the impact at ``t1 = h0 / |v0|``, 0 during the contact
    ``[t1, t1 + 2 L / c)``, ``|v0| (t - t1 - 2 L / c)`` after (rigid rebound).
    """
    t = np.asarray(t, dtype=float)
    t1, t2, _ = _impact_times(L, rho, E, v0, h0)
    return np.where(t < t1, h0 + v0 * t, np.where(t < t2, 0.0, abs(v0) * (t - t2)))


def impact_tip_velocity(t, L=10.0, rho=1.0, E=900.0, v0=-10.0, h0=5.0):
    """Benchmark 1 tip velocity (m/s), right-continuous: ``v0``, 0 on ``[t1, t2)``, ``|v0|``."""
    t = np.asarray(t, dtype=float)
    t1, t2, _ = _impact_times(L, rho, E, v0, h0)
    return np.where(t < t1, v0, np.where(t < t2, 0.0, abs(v0)))


def impact_contact_pressure(t, L=10.0, rho=1.0, E=900.0, v0=-10.0, h0=5.0):
    """Benchmark 1 contact pressure (Pa): ``rho c |v0|`` on ``[t1, t1 + 2 L / c)``, else 0."""
    t = np.asarray(t, dtype=float)
    t1, t2, c = _impact_times(L, rho, E, v0, h0)
    return np.where((t >= t1) & (t < t2), rho * c * abs(v0), 0.0)


# -- benchmark 2: characteristics -----------------------------------------------------------------


def bounce_solution(t_end=20.0, n=_BOUNCE_N, L=10.0, rho=1.0, E=900.0, g=10.0, h0=5.0):
    """Benchmark 2 (bar released at rest under gravity) on the characteristic grid.

    Returns ``(t, x_tip, p)``, arrays of shape ``(n_steps + 1,)``: grid times (s), tip position
    (m) and contact pressure (Pa, right limits at jumps); ``dt = L / (n c)``. For the full
    :class:`BarSolution` call :func:`signorini_bar_characteristics` with ``v0 = 0``.
    """
    sol = _bounce_cached(float(t_end), int(n), float(L), float(rho), float(E), float(g), float(h0))
    return sol.t.copy(), sol.x_tip.copy(), sol.p.copy()


@functools.lru_cache(maxsize=8)
def _bounce_cached(t_end, n, L, rho, E, g, h0):
    return signorini_bar_characteristics(L, rho, E, 0.0, g, h0, t_end, n)


def _bounce_for(t, n, kwargs):
    t = np.asarray(t, dtype=float)
    t_max = float(np.max(t)) if t.size else 0.0
    t_end = 20.0 * max(1, math.ceil(t_max / 20.0 - 1e-12))  # cache whole multiples of 20 s
    data = {"L": 10.0, "rho": 1.0, "E": 900.0, "g": 10.0, "h0": 5.0, **kwargs}
    return _bounce_cached(t_end, int(n), *(float(data[k]) for k in ("L", "rho", "E", "g", "h0")))


def bounce_tip_position(t, n=_BOUNCE_N, **data):
    """Benchmark 2 tip position (m) at times ``t >= 0`` (s), same shape as ``t``.

    Evaluated from a cached characteristic solution (``n`` cells, computed up to the next
    multiple of 20 s), exactly within each step (the tip velocity is linear there). ``data``
    overrides ``L, rho, E, g, h0``.
    """
    return _bounce_for(t, n, data).tip_position(t)


def bounce_contact_pressure(t, n=_BOUNCE_N, **data):
    """Benchmark 2 contact pressure (Pa) at times ``t >= 0`` (s), right-continuous; see
    :func:`bounce_tip_position`."""
    return _bounce_for(t, n, data).contact_pressure(t)
