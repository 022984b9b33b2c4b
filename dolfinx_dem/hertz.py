"""Plane-strain Hertz contact of a cylinder on a rigid plane (paper §5.2): the analytic solution
and the measurement of a contact half-width from discrete pressures, shared by the DEM and the
FEM reference.

For a load P per unit thickness on a cylinder of radius R, E* = E / (1 - nu^2):
    a = sqrt(4 P R / (pi E*)),   p(x) = p0 sqrt(1 - x^2 / a^2),   p0 = 2 P / (pi a).
The paper's disc carries a body force f instead of a point load (P = f pi R^2) and a/R ~ 0.25, so
Hertz is only an approximation there; the converged FEM is the reference.
"""

from __future__ import annotations

import typing

import numpy as np
import numpy.typing as npt


# --- analytic Hertz solution --------------------------------------------------------------------


class HertzAnalytic(typing.NamedTuple):
    """Plane-strain Hertz contact of a cylinder (per unit thickness) on a rigid plane."""

    load: float  # P = f pi R^2 (N/m), the total body force per unit thickness
    E_star: float  # plane-strain modulus E / (1 - nu^2) (Pa)
    a: float  # contact half-width sqrt(4 P R / (pi E*)) (m)
    p0: float  # maximum pressure 2 P / (pi a) (Pa)

    def pressure(self, x: npt.ArrayLike) -> np.ndarray:
        """Hertz pressure p0 sqrt(1 - x^2/a^2) (Pa), 0 for |x| >= a; x in m, any shape."""
        x = np.asarray(x, dtype=np.float64)
        return self.p0 * np.sqrt(np.clip(1.0 - (x / self.a) ** 2, 0.0, None))


def hertz_analytic(R: float, E: float, nu: float, body_force: float) -> HertzAnalytic:
    """The Hertz values for the disc of radius R (m) under the body force density f (N/m^3).

    The body force is replaced by its resultant ``P = f pi R^2`` as a point load: Hertz theory
    assumes a/R << 1 and a load applied far from the contact.
    """
    for name, value in (("R (radius)", R), ("E", E), ("body_force", body_force)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value!r}")
    if not -1.0 < nu < 0.5:
        raise ValueError(f"Poisson ratio nu must lie in (-1, 0.5), got {nu!r}")
    f = body_force
    load = f * np.pi * R**2
    E_star = E / (1.0 - nu**2)
    a = np.sqrt(4.0 * load * R / (np.pi * E_star))
    return HertzAnalytic(load=load, E_star=E_star, a=a, p0=2.0 * load / (np.pi * a))


# --- measuring the contact half-width -----------------------------------------------------------


def contact_half_width_fit(
    x: npt.ArrayLike, pressure: npt.ArrayLike, fraction: float = 0.2
) -> tuple[float, float, float]:
    """Contact half-width from a least-squares fit of the Hertz profile to pressure samples.

    The Hertz profile ``p = p0 sqrt(1 - (x - xc)^2 / a^2)`` gives ``p^2`` quadratic in x, so
    ``p^2 = c0 + c1 x + c2 x^2`` is fitted (linear least squares) to the samples with
    ``p >= fraction * max(p)``; this resolves the edge of the contact zone below the mesh size,
    and leaves out the smeared edge itself.

    Args:
        x: Sample positions (m), shape (n,).
        pressure: Pressures (Pa), shape (n,).
        fraction: Fit only samples with p >= fraction * max(p), 0 < fraction < 1.

    Returns:
        (a, p0, xc): the half-width (m), the peak pressure (Pa) and the centre (m) of the fit.
    """
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    p = np.asarray(pressure, dtype=np.float64).reshape(-1)
    if x.shape != p.shape:
        raise ValueError(f"x and pressure must have the same shape, got {x.shape}, {p.shape}")
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"fraction must be in (0, 1), got {fraction!r}")
    if p.size == 0 or not np.max(p) > 0.0:
        raise ValueError("no positive pressure sample: no contact")
    keep = p >= fraction * np.max(p)
    if np.count_nonzero(keep) < 3:
        raise ValueError("fewer than 3 pressure samples above the threshold: cannot fit")
    scale = np.max(np.abs(x[keep]))
    s = x[keep] / scale
    A = np.stack([np.ones_like(s), s, s**2], axis=1)
    c0, c1, c2 = np.linalg.lstsq(A, p[keep] ** 2, rcond=None)[0]
    if not c2 < 0.0:
        raise ValueError("the fitted p^2 is not concave: the samples do not look like Hertz")
    peak = c0 - c1**2 / (4.0 * c2)
    a = np.sqrt(c1**2 - 4.0 * c0 * c2) / (2.0 * abs(c2)) * scale
    return float(a), float(np.sqrt(peak)), float(-c1 / (2.0 * c2) * scale)


def contact_half_width_last(x: npt.ArrayLike, pressure: npt.ArrayLike) -> float:
    """Half the distance between the leftmost and the rightmost sample with p > 0 (m)."""
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    p = np.asarray(pressure, dtype=np.float64).reshape(-1)
    active = x[p > 0.0]
    if active.size == 0:
        return 0.0
    return float(0.5 * (active.max() - active.min()))
