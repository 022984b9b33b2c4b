"""The three FEM schemes of the Signorini bar reference (fem/signorini.py), each a time loop on
the bar's P1 operators (``BarOperators``): explicit with a projection of the contact node,
explicit with the modified mass of the contact node, and implicit Newmark with a penalty.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg
import scipy.sparse

from dolfinx_dem.errors import SolverError


def modified_mass(ops) -> tuple[np.ndarray, np.ndarray]:
    """Modified lumped mass and load: the contact node's mass (and load) moved to node 1."""
    m, F = ops.m.copy(), ops.F.copy()
    m[1] += m[0]
    F[1] += F[0]
    m[0], F[0] = 0.0, 0.0
    return m, F


class Series:
    """Preallocated series; ``truncate`` keeps the first k samples."""

    names = ("tip_position", "contact_pressure", "kinetic", "elastic", "penalty", "gravity",
             "mean_velocity")

    def __init__(self, n: int):
        self.data = {name: np.zeros(n) for name in self.names}
        self.count = 0

    def add(self, k: int, **values):
        for name, value in values.items():
            self.data[name][k] = value
        self.count = k + 1

    def truncate(self) -> dict:
        return {name: a[: self.count].copy() for name, a in self.data.items()}


def record(s: Series, n: int, dt: float, budget, growth_limit: float, *, tip_position, contact_pressure,
            kinetic, elastic, gravity, mean_velocity, initial_gravity):
    """Add step ``n`` of an explicit scheme to ``s``; returns (budget, message): the energy budget
    (the initial |kinetic + elastic + gravity|) and a non-empty message if the run blew up."""
    s.add(n, tip_position=tip_position, contact_pressure=contact_pressure, kinetic=kinetic, elastic=elastic,
          gravity=gravity, mean_velocity=mean_velocity)
    if budget is None:
        budget = abs(kinetic + elastic + initial_gravity)
    blown_up = not (math.isfinite(kinetic) and math.isfinite(elastic)) or abs(kinetic) + elastic > growth_limit * budget
    message = (f"unstable: kinetic + elastic energy beyond {growth_limit:g} x the initial energy at t = {n * dt:.6g} s"
               if blown_up else "")
    return budget, message


def run_projection(ops, data, dt, n_steps, s: Series, grav0, growth_limit):
    K, m, F = ops.K, ops.m, ops.F
    h0, v0 = data["h0"], data["v0"]
    mass = m.sum()
    u = np.zeros_like(m)
    a = (F - K @ u) / m
    v_prev = v0 - 0.5 * dt * a  # v^{-1/2}
    v_next = v0 + 0.5 * dt * a  # v^{1/2} (predicted)
    budget = None
    for n in range(n_steps + 1):
        u_new = u + dt * v_next
        r = 0.0
        if u_new[0] < -h0:  # projection onto u_0 >= -h0, consistent velocity
            correction = -h0 - u_new[0]
            u_new[0] = -h0
            v_next[0] += correction / dt
            r = m[0] * correction / dt**2
        budget, message = record(
            s, n, dt, budget, growth_limit, tip_position=h0 + u[0], contact_pressure=r,
            kinetic=0.5 * float(np.dot(v_prev * m, v_next)), elastic=0.5 * float(u @ (K @ u)),
            gravity=grav0 - float(F @ u), mean_velocity=float(np.dot(m, 0.5 * (v_prev + v_next))) / mass,
            initial_gravity=grav0)
        if message:
            return message
        if n == n_steps:
            break
        u = u_new
        a = (F - K @ u) / m
        v_prev = v_next
        v_next = v_next + dt * a
    return ""


def run_modified_mass(ops, data, dt, n_steps, s: Series, grav0, growth_limit):
    K = ops.K
    m, Fm = modified_mass(ops)
    h0, v0 = data["h0"], data["v0"]
    mass = m.sum()
    k00 = K[0, 0]
    row0 = K[[0], :].toarray().ravel()
    row0[0] = 0.0  # K_0j, j > 0
    inner = slice(1, None)
    mi = m[inner]

    def contact_node(u):
        """Static problem of the massless contact node with the Signorini condition."""
        u[0] = max(-h0, (Fm[0] - float(row0 @ u)) / k00)

    u = np.zeros_like(m)
    contact_node(u)
    Ku = K @ u
    a = (Fm[inner] - Ku[inner]) / mi
    v_prev = np.full(len(mi), float(v0)) - 0.5 * dt * a
    v_next = np.full(len(mi), float(v0)) + 0.5 * dt * a
    budget = None
    for n in range(n_steps + 1):
        r = float(Ku[0] - Fm[0])  # reaction of the obstacle on the contact node
        budget, message = record(
            s, n, dt, budget, growth_limit, tip_position=h0 + u[0], contact_pressure=max(r, 0.0),
            kinetic=0.5 * float(np.dot(v_prev * mi, v_next)), elastic=0.5 * float(u @ Ku),
            gravity=grav0 - float(Fm @ u), mean_velocity=float(np.dot(mi, 0.5 * (v_prev + v_next))) / mass,
            initial_gravity=grav0)
        if message:
            return message
        if n == n_steps:
            break
        u[inner] += dt * v_next
        contact_node(u)
        Ku = K @ u
        a = (Fm[inner] - Ku[inner]) / mi
        v_prev = v_next
        v_next = v_next + dt * a
    return ""


def _banded(A: scipy.sparse.csr_matrix) -> np.ndarray:
    """Upper banded storage (2, n) of a symmetric tridiagonal matrix for cholesky_banded."""
    n = A.shape[0]
    ab = np.zeros((2, n))
    ab[0, 1:] = A.diagonal(1)
    ab[1] = A.diagonal()
    return ab


def run_newmark_penalty(ops, data, dt, n_steps, s: Series, grav0, kappa, newton_its):
    K, M, F = ops.K, ops.M, ops.F
    h0, v0 = data["h0"], data["v0"]
    mass = ops.m.sum()
    c0, c1 = 4.0 / dt**2, 4.0 / dt
    chol_A = scipy.linalg.cholesky_banded(_banded((K + c0 * M).tocsr()))
    chol_M = scipy.linalg.cholesky_banded(_banded(M))
    e0 = np.zeros(K.shape[0])
    e0[0] = 1.0
    z = scipy.linalg.cho_solve_banded((chol_A, False), e0)  # A^-1 e_0
    z0 = z[0]

    def reaction(u0):
        return kappa * max(0.0, -(h0 + u0))

    u = np.zeros(K.shape[0])
    v = np.full(K.shape[0], float(v0))
    a = scipy.linalg.cho_solve_banded((chol_M, False), F - K @ u + reaction(u[0]) * e0)
    for n in range(n_steps + 1):
        r = reaction(u[0])
        kinetic = 0.5 * float(v @ (M @ v))
        elastic = 0.5 * float(u @ (K @ u))
        s.add(n, tip_position=h0 + u[0], contact_pressure=r, kinetic=kinetic, elastic=elastic,
              penalty=0.5 * r * r / kappa, gravity=grav0 - float(F @ u),
              mean_velocity=float(ops.m @ v) / mass)
        if n == n_steps:
            break
        b = F + M @ (c0 * u + c1 * v + a)
        y = scipy.linalg.cho_solve_banded((chol_A, False), b)
        # Semi-smooth Newton on R(u) = A u - b - r(u_0) e_0, from the unconstrained predictor y:
        # with the active set chi of the iterate, the Newton update solves
        # (A + kappa chi e_0 e_0^T) u = b - kappa chi h0 e_0, i.e. u = y + z r with
        # u_0 (1 + kappa chi z_0) = y_0 - kappa chi z_0 h0 (Sherman-Morrison).
        w, its = y[0], 0
        tol = 1e-12 * max(1.0, abs(w), abs(h0))
        while True:
            residual = w - y[0] - z0 * reaction(w)
            if abs(residual) <= tol:
                break
            if its == 50:
                raise SolverError(f"semi-smooth Newton did not converge at step {n + 1}")
            chi = 1.0 if h0 + w < 0.0 else 0.0
            w = (y[0] - kappa * chi * z0 * h0) / (1.0 + kappa * chi * z0)
            its += 1
        newton_its[n] = its
        u_new = y + z * reaction(w)
        a_new = c0 * (u_new - u) - c1 * v - a
        v = v + 0.5 * dt * (a + a_new)
        u, a = u_new, a_new
    return ""
