"""Finite-element peers of the DEM on the 1D dynamic Signorini bar (DEM paper §5.1).

The schemes are representatives of the classes reviewed by Doyen, Ern & Piperno, "Time-integration
schemes for the finite element dynamic Signorini problem", SIAM J. Sci. Comput. 33(1) (2011)
223-249 ("DEP" below), on the two benchmarks of :mod:`dolfinx_dem.exact` and of the scenes
``bar-impact`` and ``bar-bounce``.

Problem and conventions (those of :mod:`dolfinx_dem.exact` and of the scenes): a bar of length
``L`` (m), density ``rho`` (kg/m^3), Young's modulus ``E`` (Pa), wave speed ``c = sqrt(E/rho)``,
occupies ``[h0, h0 + L]`` at ``t = 0`` (the scenes' interval mesh ``x0 = 5, x1 = 15``) above a
rigid obstacle at ``x = 0``. Its lower end (reference coordinate ``X = 0``, the mesh node at
``x = h0``) is the contact end, the upper end is free. Benchmark ``"impact"``: uniform initial
velocity ``v0 = -10`` m/s, no gravity, ``T = 2`` s. Benchmark ``"bounce"``: at rest, gravity
``g = 10`` m/s^2 (body force ``-rho g``), ``T = 20`` s. Everything is per unit cross-section (a
1D bar of area 1 m^2): forces in N, energies in J (= J/m^2 of exact.py), the contact pressure is
the obstacle's reaction divided by the area, ``p >= 0`` in compression.

Space discretisation: P1 Lagrange on a DOLFINx interval mesh of ``n_cells`` cells (``h = L / n``);
the stiffness ``K`` (``E u' w'``), the consistent mass ``M`` (``rho u w``) and the body-force
load ``F`` (``-rho g w``) are assembled by DOLFINx (PETSc matrices, then copied to scipy CSR and
permuted to the natural node order, node 0 = the contact node). The lumped mass is the row sum of
``M`` (``rho h / 2`` at the ends, ``rho h`` inside). The time stepping is numpy/scipy: in 1D the
contact set is one dof (``u_0``, tip position ``x_tip = h0 + u_0``, Signorini:
``x_tip >= 0, p >= 0, p x_tip = 0``). The problem is replicated: every MPI process that calls
:func:`solve_signorini_bar` solves it on ``MPI.COMM_SELF``.

Methods (``method`` argument):

* ``"projection"`` -- (a) explicit central differences, lumped mass ``m``, contact enforced
  exactly at the end of each step (DEP's explicit scheme with the multiplier implicit in the
  contact condition, which for a lumped mass and one contact dof is a projection)::

      v^{n+1/2} = v^{n-1/2} + dt m^-1 (F - K u^n + r^n e_0),   u^{n+1} = u^n + dt v^{n+1/2}

  with the reaction ``r^n >= 0`` that puts the contact node onto the admissible set: the
  predictor ``u_0*`` (``r^n = 0``) is projected, ``u_0^{n+1} = max(u_0*, -h0)``, the node's
  half-step velocity is set consistently ``v_0^{n+1/2} = (u_0^{n+1} - u_0^n) / dt`` and
  ``r^n = m_0 (u_0^{n+1} - u_0*) / dt^2``; ``p(t_n) = r^n``. The normal velocity of the contact
  node is killed at impact: ``m_0 v_0^2 / 2`` (``m_0 = rho h / 2``) is lost there, O(h).
* ``"modified-mass"`` -- (b) the modified-mass method (Khenous, Laborde & Renard 2008; DEP §7;
  explicit variant: Doyen, Ern & Piperno, semi-explicit modified mass method): the lumped mass of
  the contact node is set to zero and moved to its neighbour (``m_1 <- m_1 + m_0``: total mass and
  the load ``F = -g m`` are kept), the other nodes follow explicit central differences, and at
  every step the contact node solves its static problem with the Signorini condition::

      (K u)_0 = F_0 + r,  r >= 0,  u_0 >= -h0,  r (u_0 + h0) = 0
      =>  u_0 = max(-h0, (F_0 - sum_{j>0} K_0j u_j) / K_00) = max(-h0, u_1)  (P1, F_0 = 0)

  ``p = r = (K u)_0 - F_0 = E (u_0 - u_1) / h``. The condensed potential
  ``min_{u_0 >= -h0} 1/2 u.K u`` is C^1 and piecewise quadratic in the other dofs, so the scheme
  is central differences on a Hamiltonian system: no energy is lost at impact, the
  energy error stays small and bounded.
* ``"newmark-penalty"`` -- (c) implicit Newmark, trapezoidal rule (beta = 1/4, gamma = 1/2),
  consistent mass, penalty contact ``r(u) = kappa [-(h0 + u_0)]_+``; ``kappa = penalty * E / h``
  (N/m per unit area, default ``penalty = 100``: penetration ``p h / (100 E)`` = 3.3e-4 m at
  ``p = 300`` Pa, ``h = 0.1``). Each step solves
  ``R(u) = (K + 4/dt^2 M) u - b - r(u) e_0 = 0`` by a semi-smooth Newton method (generalised
  Jacobian ``A + kappa chi e_0 e_0^T``, ``chi`` the active set). ``A = K + 4/dt^2 M`` is
  factored once (banded Cholesky) and the active-set Jacobian is solved by Sherman-Morrison with
  ``z = A^-1 e_0``: every Newton iterate is that of the full system at the cost of one solve per
  step. Newton starts from the unconstrained predictor and stops when the scalar residual is
  below 1e-12 (m, relative to max(1, |u_0|, h0)); R is piecewise affine, so one iteration
  (from an inactive predictor) finds the active set and the exact solution
  (``SignoriniResult.newton_iterations``). ``p = r(u)`` and the
  energy includes the penalty energy ``kappa/2 [-(h0 + u_0)]_+^2``. No time-step limit (the
  linear scheme is unconditionally stable), and the energy is conserved exactly on every step
  whose contact status does not change; but the trapezoidal rule is not exact across a switch,
  and with a stiff penalty (kappa >> m_0 / dt^2, about E / h at CFL 0.75) the contact node
  rattles on and off the obstacle during the contact phase, each switch changing the energy
  (benchmark 1, 100 cells: +11.5 % at the end; benchmark 2 gains far more). ``penalty = 1``
  resolves the contact oscillation (no rattling, +2e-4) but penetrates by about h / 3.

Time step: ``cfl = c dt / h``. Given ``cfl``, ``dt = t_end / ceil(t_end c / (cfl h))`` (the largest
step at most that CFL number that divides ``t_end``); given ``dt``, it must divide ``t_end``. The
explicit methods (a), (b) raise ValueError at or above their linear stability limit
(:func:`stability_limit_cfl`, ``2 / sqrt(lambda_max(m^-1 K))`` over the contact states: CFL 1
exactly for (a), whose free lumped bar has lambda_max = 4 c^2 / h^2, and 1.00003 for (b) on
100 cells) unless ``allow_unstable=True``; at the limit itself central differences grow linearly
(projection, 100 cells, CFL 1: blown up at t = 1.93 s); a run that then blows up is stopped
when its kinetic + elastic energy exceeds ``growth_limit`` times the initial total energy (or is
no longer finite) and returned with ``stable=False`` and the series up to that step.

Energies (``SignoriniResult``): ``kinetic``, ``elastic = 1/2 u.K u``, ``penalty``, ``gravity`` (the
potential ``int rho g x dX`` of exact.py, zero at the obstacle: ``rho g (h0 L + L^2/2) - F.u``) and
``energy`` = their sum. For the explicit schemes the kinetic term is the central-difference
(pseudo-)kinetic energy ``1/2 v^{n-1/2}.m v^{n+1/2}``, with which central differences conserve
``energy`` exactly for a linear problem (the same definition as the DEM's pseudo-energy): its
variations are then due to contact alone. For Newmark it is ``1/2 v^n.M v^n``.
"""

from __future__ import annotations

import dataclasses
import math
import time

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import scipy.linalg
import scipy.sparse
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError
from dolfinx_dem.fem.signorini_schemes import (
    Series,
    modified_mass,
    run_modified_mass,
    run_newmark_penalty,
    run_projection,
)

__all__ = [
    "METHODS",
    "BENCHMARKS",
    "SignoriniResult",
    "BarOperators",
    "assemble_bar",
    "stability_limit_cfl",
    "solve_signorini_bar",
]

METHODS = ("projection", "modified-mass", "newmark-penalty")
"""(a) central differences + projection, (b) modified mass, (c) Newmark + penalty."""

EXPLICIT = ("projection", "modified-mass")

BENCHMARKS: dict[str, dict[str, float]] = {
    "impact": {"L": 10.0, "rho": 1.0, "E": 900.0, "h0": 5.0, "v0": -10.0, "g": 0.0, "t_end": 2.0},
    "bounce": {"L": 10.0, "rho": 1.0, "E": 900.0, "h0": 5.0, "v0": 0.0, "g": 10.0, "t_end": 20.0},
}
"""Data of benchmarks 1 and 2 (SI), identical to the scenes bar-impact and bar-bounce."""

_ALIASES = {"impact": "impact", "bar-impact": "impact", "1": "impact",
            "bounce": "bounce", "bar-bounce": "bounce", "2": "bounce"}

DEFAULT_PENALTY = 100.0
"""Default penalty factor of method (c): kappa = DEFAULT_PENALTY * E / h."""


@dataclasses.dataclass
class SignoriniResult:
    """Time series of one run, on ``t[k] = k dt`` (shape ``(n_steps + 1,)``, fewer if unstable).

    Attributes
    ----------
    method, benchmark : names as in :data:`METHODS`, :data:`BENCHMARKS`.
    n_cells, n_dofs : cells and P1 dofs (``n_cells + 1``).
    dt, cfl, cfl_limit : time step (s), ``c dt / h``, and the linear stability limit of the
        explicit methods (``inf`` for Newmark).
    t : times (s).
    tip_position : ``h0 + u_0`` (m), the gap to the obstacle (negative = penetration, method c).
    contact_pressure : obstacle reaction per unit area (Pa), >= 0.
    kinetic, elastic, penalty, gravity, energy : energies (J per m^2 of cross-section); see the
        module docstring for the kinetic energy of the explicit schemes.
    mean_velocity : momentum / mass (m/s) at each time (rebound velocity; exact +10 after 7/6 s
        on benchmark 1).
    stable : False when an explicit run with ``allow_unstable=True`` blew up (series truncated).
    message : why the run stopped early, else "".
    wall_time_s : setup_time_s (mesh, DOLFINx assembly, factorisations) + solve_time_s (steps).
    penalty_parameter : kappa (N/m per m^2) for method (c), else 0.
    newton_iterations : semi-smooth Newton iterations per step (method c), else empty.
    """

    method: str
    benchmark: str
    n_cells: int
    n_dofs: int
    dt: float
    cfl: float
    cfl_limit: float
    t: np.ndarray
    tip_position: np.ndarray
    contact_pressure: np.ndarray
    kinetic: np.ndarray
    elastic: np.ndarray
    penalty: np.ndarray
    gravity: np.ndarray
    energy: np.ndarray
    mean_velocity: np.ndarray
    stable: bool
    message: str
    wall_time_s: float
    setup_time_s: float
    solve_time_s: float
    penalty_parameter: float = 0.0
    newton_iterations: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=int))

    @property
    def n_steps(self) -> int:
        """Steps actually taken."""
        return len(self.t) - 1

    def energy_error(self) -> np.ndarray:
        """``(energy - energy[0]) / |energy[0]|``, shape of ``t``."""
        return (self.energy - self.energy[0]) / abs(self.energy[0])


@dataclasses.dataclass
class BarOperators:
    """P1 operators of the bar in natural node order (node 0 at the contact end ``x = h0``).

    ``K``, ``M``: scipy CSR (N/m, kg per m^2), ``m``: lumped mass (row sums of M), ``F``: body
    load (N per m^2), ``x``: node coordinates (m), ``h``: cell size (m).
    """

    K: scipy.sparse.csr_matrix
    M: scipy.sparse.csr_matrix
    m: np.ndarray
    F: np.ndarray
    x: np.ndarray
    h: float


# --- validation ---------------------------------------------------------------------------------


def _check_method(method) -> str:
    if method not in METHODS:
        raise InputError(f"method must be one of {METHODS}, got {method!r}")
    return method


def _check_benchmark(benchmark) -> str:
    key = _ALIASES.get(str(benchmark)) if isinstance(benchmark, (str, int)) else None
    if key is None:
        raise InputError(f"benchmark must be one of {sorted(_ALIASES)}, got {benchmark!r}")
    return key


def _check_n(n_cells) -> int:
    if isinstance(n_cells, bool) or not isinstance(n_cells, (int, np.integer)) or n_cells < 2:
        raise InputError(f"n_cells must be an integer >= 2, got {n_cells!r}")
    return int(n_cells)


def _check_positive(name: str, value) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number > 0, got {value!r}") from None
    if not (math.isfinite(value) and value > 0.0):
        raise InputError(f"{name} must be finite and > 0, got {value!r}")
    return value


# --- operators ----------------------------------------------------------------------------------


def _csr(A, perm: np.ndarray) -> scipy.sparse.csr_matrix:
    """A serial PETSc AIJ matrix as scipy CSR, rows and columns permuted by ``perm``."""
    indptr, indices, data = A.getValuesCSR()
    B = scipy.sparse.csr_matrix((data, indices, indptr), shape=A.getSize())
    return B[perm][:, perm].tocsr()


def assemble_bar(n_cells: int, L: float, rho: float, E: float, h0: float, g: float = 0.0) -> BarOperators:
    """Assemble the P1 operators of the bar on ``[h0, h0 + L]`` with DOLFINx (on COMM_SELF)."""
    n_cells = _check_n(n_cells)
    mesh = dolfinx.mesh.create_interval(MPI.COMM_SELF, n_cells, [h0, h0 + L])
    V = _compat.create_scalar_space(mesh, "Lagrange", 1)
    u, w = ufl.TrialFunction(V), ufl.TestFunction(V)
    k_form = dolfinx.fem.form(E * ufl.inner(ufl.grad(u), ufl.grad(w)) * ufl.dx)
    m_form = dolfinx.fem.form(rho * u * w * ufl.dx)
    x = V.tabulate_dof_coordinates()[:, 0]
    perm = np.argsort(x, kind="stable")
    mats = []
    for form in (k_form, m_form):
        A = dolfinx.fem.petsc.assemble_matrix(form)
        A.assemble()
        mats.append(_csr(A, perm))
        A.destroy()
    K, M = mats
    F = np.zeros(len(x))
    if g != 0.0:
        f = dolfinx.fem.Constant(mesh, PETSc.ScalarType(-rho * g))
        b = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(f * w * ufl.dx))
        F = b.array.copy()[perm]
        b.destroy()
    m = np.asarray(M.sum(axis=1)).ravel()
    return BarOperators(K=K, M=M, m=m, F=F, x=x[perm], h=L / n_cells)


def _lambda_max_tridiagonal(K: scipy.sparse.csr_matrix, m: np.ndarray) -> float:
    """Largest eigenvalue of m^-1 K for a tridiagonal K (natural order) and diagonal m > 0."""
    d = K.diagonal() / m
    e = K.diagonal(1) / np.sqrt(m[:-1] * m[1:])
    n = len(d)
    return float(scipy.linalg.eigvalsh_tridiagonal(d, e, select="i", select_range=(n - 1, n - 1))[0])


def _cfl_limit(method: str, ops: BarOperators, c: float) -> float:
    """Linear stability limit (CFL number) of an explicit method: max over the contact states."""
    if method == "projection":
        # Free: the whole lumped system. In contact the contact dof is fixed: a principal
        # submatrix, whose eigenvalues interlace (smaller lambda_max); computed anyway.
        lam = max(_lambda_max_tridiagonal(ops.K, ops.m),
                  _lambda_max_tridiagonal(ops.K[1:, 1:], ops.m[1:]))
    elif method == "modified-mass":
        m, _ = modified_mass(ops)
        Kr = ops.K[1:, 1:].tolil()
        contact = _lambda_max_tridiagonal(Kr.tocsr(), m[1:])  # u_0 = -h0 fixed
        k01, k00 = ops.K[0, 1], ops.K[0, 0]
        Kr[0, 0] -= k01 * k01 / k00  # free: u_0 condensed (Schur complement)
        free = _lambda_max_tridiagonal(Kr.tocsr(), m[1:])
        lam = max(contact, free)
    else:
        return math.inf
    return 2.0 / math.sqrt(lam) * c / ops.h


def stability_limit_cfl(method: str, n_cells: int, benchmark: str = "impact") -> float:
    """CFL number ``c dt_crit / h`` above which the explicit ``method`` is linearly unstable
    (``inf`` for ``"newmark-penalty"``)."""
    method = _check_method(method)
    data = BENCHMARKS[_check_benchmark(benchmark)]
    ops = assemble_bar(_check_n(n_cells), data["L"], data["rho"], data["E"], data["h0"])
    return _cfl_limit(method, ops, math.sqrt(data["E"] / data["rho"]))


# --- time stepping ------------------------------------------------------------------------------


def _time_step(t_end: float, h: float, c: float, cfl, dt) -> tuple[float, int]:
    if (cfl is None) == (dt is None):
        raise InputError("give exactly one of cfl and dt")
    if dt is None:
        cfl = _check_positive("cfl", cfl)
        n_steps = math.ceil(t_end * c / (cfl * h) * (1.0 - 1e-12))
        return t_end / n_steps, n_steps
    dt = _check_positive("dt", dt)
    n_steps = max(1, round(t_end / dt))
    if abs(n_steps * dt - t_end) > 1e-9 * t_end:
        raise InputError(f"dt = {dt!r} does not divide t_end = {t_end!r}")
    return t_end / n_steps, n_steps


def solve_signorini_bar(
    method: str,
    benchmark: str = "impact",
    n_cells: int = 100,
    cfl: float | None = 0.75,
    *,
    dt: float | None = None,
    t_end: float | None = None,
    penalty: float = DEFAULT_PENALTY,
    allow_unstable: bool = False,
    growth_limit: float = 10.0,
) -> SignoriniResult:
    """Run one FEM scheme on benchmark 1 (``"impact"``) or 2 (``"bounce"``).

    Args:
        method: ``"projection"`` (a), ``"modified-mass"`` (b) or ``"newmark-penalty"`` (c).
        benchmark: ``"impact"``/``"bar-impact"`` or ``"bounce"``/``"bar-bounce"``.
        n_cells: P1 cells, integer >= 2 (``h = 10 / n_cells`` m).
        cfl: CFL number ``c dt / h`` (the time step is shortened to divide ``t_end``); pass
            ``cfl=None`` with ``dt``.
        dt: time step (s), must divide ``t_end``; exclusive with ``cfl``.
        t_end: final time (s), default that of the benchmark (2 s, 20 s).
        penalty: method (c): kappa = penalty * E / h, > 0.
        allow_unstable: run explicit methods above their stability limit (stopped when they blow
            up) instead of raising ValueError.
        growth_limit: blow-up threshold (x the initial total energy) for such runs.

    Raises:
        ValueError: unknown method or benchmark, n_cells < 2, non-positive cfl/dt/t_end/penalty,
            dt not dividing t_end, or an explicit method above its stability limit.
    """
    method = _check_method(method)
    key = _check_benchmark(benchmark)
    n_cells = _check_n(n_cells)
    data = BENCHMARKS[key]
    t_end = data["t_end"] if t_end is None else _check_positive("t_end", t_end)
    penalty = _check_positive("penalty", penalty)
    growth_limit = _check_positive("growth_limit", growth_limit)
    L, rho, E, h0, g = data["L"], data["rho"], data["E"], data["h0"], data["g"]
    c = math.sqrt(E / rho)
    h = L / n_cells
    dt, n_steps = _time_step(t_end, h, c, cfl, dt)  # validated before any assembly

    wall = time.perf_counter()
    ops = assemble_bar(n_cells, L, rho, E, h0, g)
    cfl_actual = c * dt / h
    cfl_limit = _cfl_limit(method, ops, c)
    # Strictly below the limit: at it, central differences have a double root -1 (linear growth).
    if method in EXPLICIT and cfl_actual >= cfl_limit * (1.0 - 1e-10) and not allow_unstable:
        raise InputError(f"method {method!r} is unstable at CFL {cfl_actual:.6g} (dt = {dt:.6g} s): it "
                         f"needs a CFL number below its stability limit on {n_cells} cells, "
                         f"{cfl_limit:.6g} (dt = {cfl_limit * h / c:.6g} s); pass allow_unstable=True "
                         f"to run it anyway")
    setup = time.perf_counter() - wall

    series = Series(n_steps + 1)
    grav0 = rho * g * (h0 * L + 0.5 * L * L)
    kappa = penalty * E / h if method == "newmark-penalty" else 0.0
    newton_its = np.zeros(n_steps if method == "newmark-penalty" else 0, dtype=int)
    t0 = time.perf_counter()
    if method == "projection":
        message = run_projection(ops, data, dt, n_steps, series, grav0, growth_limit)
    elif method == "modified-mass":
        message = run_modified_mass(ops, data, dt, n_steps, series, grav0, growth_limit)
    else:
        message = run_newmark_penalty(ops, data, dt, n_steps, series, grav0, kappa, newton_its)
    solve = time.perf_counter() - t0

    d = series.truncate()
    energy = d["kinetic"] + d["elastic"] + d["penalty"] + d["gravity"]
    return SignoriniResult(
        method=method, benchmark=key, n_cells=n_cells, n_dofs=n_cells + 1, dt=dt, cfl=cfl_actual,
        cfl_limit=cfl_limit, t=dt * np.arange(series.count), energy=energy, stable=not message,
        message=message, wall_time_s=setup + solve, setup_time_s=setup, solve_time_s=solve,
        penalty_parameter=kappa, newton_iterations=newton_its, **d,
    )
