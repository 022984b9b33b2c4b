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


def contact_half_width_moments(m0: float, m1: float, m2: float) -> tuple[float, float]:
    """Contact half-width from the moments of a pressure distribution (the moment measure).

    With ``m_k = integral of x^k p(x) dx`` over the contact zone, the centre is
    ``xc = m1 / m0`` and the half-width ``a = 2 sqrt(m2 / m0 - xc^2)``: for the Hertz profile
    ``p0 sqrt(1 - (x - xc)^2 / a^2)`` the second central moment divided by the total force is
    exactly a^2 / 4. For any other profile it is the half-width of the Hertz profile with the same
    force, centre and second moment. An integral of the pressure (no threshold, no fit), it
    converges like the pressure's integrals do.

    Args:
        m0, m1, m2: The moments (N/m, N, N m per unit thickness), m0 > 0.

    Returns:
        (a, xc): the half-width (m) and the centre (m).
    """
    if not m0 > 0.0:
        raise ValueError(f"the total contact force m0 must be > 0, got {m0!r}: no contact")
    xc = m1 / m0
    variance = m2 / m0 - xc**2
    if not variance > 0.0:
        raise ValueError("the pressure has no spread (second central moment <= 0)")
    return float(2.0 * np.sqrt(variance)), float(xc)


def facet_pressure_moments(
    x_start: npt.ArrayLike, x_end: npt.ArrayLike, force: npt.ArrayLike
) -> tuple[float, float, float]:
    """Moments (m0, m1, m2) of a pressure that is uniform on each of a set of straight facets.

    Facet f spans [x_start_f, x_end_f] in x and carries the force ``force_f`` (its pressure times
    its length), uniformly distributed along it: exactly, ``integral x^k p = force_f * mean of x^k``
    over the facet, i.e. ``x_f`` and ``x_f^2 + dx_f^2 / 12`` (x_f its midpoint, dx_f its
    x-extent) for k = 1, 2.
    """
    x0 = np.asarray(x_start, dtype=np.float64).reshape(-1)
    x1 = np.asarray(x_end, dtype=np.float64).reshape(-1)
    P = np.asarray(force, dtype=np.float64).reshape(-1)
    if not (x0.shape == x1.shape == P.shape):
        raise ValueError(f"x_start, x_end and force must have the same shape, got {x0.shape}, "
                         f"{x1.shape}, {P.shape}")
    xm, dx = 0.5 * (x0 + x1), x1 - x0
    return float(P.sum()), float(P @ xm), float(P @ (xm**2 + dx**2 / 12.0))
