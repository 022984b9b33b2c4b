"""Plane-strain Hertz contact of a cylinder on a rigid plane: the analytic solution and the fit
used to measure a contact half-width from discrete pressures (paper §5.2).

For a load P per unit thickness on a cylinder of radius R, E* = E / (1 - nu^2):
    a = sqrt(4 P R / (pi E*)),   p(x) = p0 sqrt(1 - x^2 / a^2),   p0 = 2 P / (pi a).
The paper's disc carries a body force f instead of a point load (P = f pi R^2) and a/R ~ 0.25, so
Hertz is only an approximation there; the converged FEM is the reference.
"""

from __future__ import annotations

import math

import numpy as np


def hertz_half_width(P: float, R: float, E: float, nu: float) -> float:
    """a (m) for a load P (N/m) on a cylinder of radius R (m), plane strain."""
    return math.sqrt(4 * P * R / (math.pi * E / (1 - nu**2)))


def hertz_max_pressure(P: float, R: float, E: float, nu: float) -> float:
    """p0 = 2 P / (pi a) (Pa)."""
    return 2 * P / (math.pi * hertz_half_width(P, R, E, nu))


def fit_hertz_profile(x: np.ndarray, p: np.ndarray, threshold: float = 0.1) -> tuple[float, float]:
    """(a, p0) of the Hertz profile fitted to pressures p at positions x (centred on 0).

    p^2 = p0^2 - (p0^2 / a^2) x^2 is linear in x^2: a least-squares line through the points with
    p > threshold * max(p) gives a and p0 without limiting a to the last point in contact, so the
    edge of the contact zone is resolved below the mesh size.
    """
    x, p = np.asarray(x, dtype=float), np.asarray(p, dtype=float)
    keep = p > threshold * p.max()
    if keep.sum() < 3:
        raise ValueError("fewer than 3 contact points above the threshold: cannot fit a Hertz profile")
    slope, intercept = np.polyfit(x[keep] ** 2, p[keep] ** 2, 1)
    if slope >= 0 or intercept <= 0:
        raise ValueError("the contact pressures do not decrease away from the centre: no Hertz profile")
    p0 = math.sqrt(intercept)
    return math.sqrt(-intercept / slope), p0
