"""Hertz contact on a rigid plane: the plane-strain cylinder (paper §5.2) and the 3D ball, their
analytic solutions and the measurement of the contact size from discrete pressures, shared by
the DEM and the FEM reference.

Cylinder (2D), load P per unit thickness, radius R, E* = E / (1 - nu^2):
    a = sqrt(4 P R / (pi E*)),   p(x) = p0 sqrt(1 - x^2 / a^2),   p0 = 2 P / (pi a).
The paper's disc carries a body force f instead of a point load (P = f pi R^2) and a/R ~ 0.25, so
Hertz is only an approximation there; the converged FEM is the reference.

Ball (3D), load P, radius R:
    a = (3 P R / (4 E*))^(1/3),   p(r) = p0 sqrt(1 - r^2 / a^2),   p0 = 3 P / (2 pi a^2),
and the approach (of the plane and the points of the ball far from the contact) delta = a^2 / R.
With a body force f, P = f 4/3 pi R^3; again an approximation (a/R ~ 0.2).
"""

from __future__ import annotations

import typing

import numpy as np
import numpy.typing as npt

from dolfinx_dem.errors import InputError

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
            raise InputError(f"{name} must be a positive number, got {value!r}")
    if not -1.0 < nu < 0.5:
        raise InputError(f"Poisson ratio nu must lie in (-1, 0.5), got {nu!r}")
    f = body_force
    load = f * np.pi * R**2
    E_star = E / (1.0 - nu**2)
    a = np.sqrt(4.0 * load * R / (np.pi * E_star))
    return HertzAnalytic(load=load, E_star=E_star, a=a, p0=2.0 * load / (np.pi * a))


class HertzAnalytic3D(typing.NamedTuple):
    """Hertz contact of a ball on a rigid plane."""

    load: float  # P = f 4/3 pi R^3 (N), the total body force
    E_star: float  # E / (1 - nu^2) (Pa)
    a: float  # contact radius (3 P R / (4 E*))^(1/3) (m)
    p0: float  # maximum pressure 3 P / (2 pi a^2) (Pa)
    approach: float  # delta = a^2 / R (m)


def hertz_analytic_3d(R: float, E: float, nu: float, body_force: float) -> HertzAnalytic3D:
    """The Hertz values for the ball of radius R (m) under the body force density f (N/m^3),
    replaced by its resultant P = f 4/3 pi R^3 as a point load (as ``hertz_analytic``)."""
    cylinder = hertz_analytic(R, E, nu, body_force)  # the same checks, and E*
    load = body_force * 4.0 / 3.0 * np.pi * R**3
    a = (3.0 * load * R / (4.0 * cylinder.E_star)) ** (1.0 / 3.0)
    return HertzAnalytic3D(load=load, E_star=cylinder.E_star, a=a, p0=3.0 * load / (2.0 * np.pi * a**2),
                           approach=a**2 / R)


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
        raise InputError(f"x and pressure must have the same shape, got {x.shape}, {p.shape}")
    if not 0.0 < fraction < 1.0:
        raise InputError(f"fraction must be in (0, 1), got {fraction!r}")
    if p.size == 0 or not np.max(p) > 0.0:
        raise InputError("no positive pressure sample: no contact")
    keep = p >= fraction * np.max(p)
    if np.count_nonzero(keep) < 3:
        raise InputError("fewer than 3 pressure samples above the threshold: cannot fit")
    scale = np.max(np.abs(x[keep]))
    s = x[keep] / scale
    A = np.stack([np.ones_like(s), s, s**2], axis=1)
    c0, c1, c2 = np.linalg.lstsq(A, p[keep] ** 2, rcond=None)[0]
    if not c2 < 0.0:
        raise InputError("the fitted p^2 is not concave: the samples do not look like Hertz")
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
        raise InputError(f"the total contact force m0 must be > 0, got {m0!r}: no contact")
    xc = m1 / m0
    variance = m2 / m0 - xc**2
    if not variance > 0.0:
        raise InputError("the pressure has no spread (second central moment <= 0)")
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
        raise InputError(f"x_start, x_end and force must have the same shape, got {x0.shape}, "
                         f"{x1.shape}, {P.shape}")
    xm, dx = 0.5 * (x0 + x1), x1 - x0
    return float(P.sum()), float(P @ xm), float(P @ (xm**2 + dx**2 / 12.0))


def contact_radius_moments(m0: float, m2: float) -> float:
    """Contact radius from the moments of an axisymmetric pressure (the 3D moment measure).

    With ``m0 = integral of p dA`` and ``m2 = integral of r^2 p dA``, r the distance from the
    axis of symmetry: for the Hertz profile p0 sqrt(1 - r^2 / a^2),
    ``m0 = 2 pi p0 a^2 / 3`` and ``m2 = 2 pi p0 a^4 integral_0^1 s^3 sqrt(1 - s^2) ds
    = 4 pi p0 a^4 / 15``, so ``m2 / m0 = 2 a^2 / 5`` and ``a = sqrt(5 m2 / (2 m0))`` exactly.
    The axis is given, not fitted: a symmetric part of the zone (a quarter) has the same m2 / m0.
    """
    if not m0 > 0.0:
        raise InputError(f"the total contact force m0 must be > 0, got {m0!r}: no contact")
    if not m2 > 0.0:
        raise InputError("the pressure has no spread (second moment <= 0)")
    return float(np.sqrt(2.5 * m2 / m0))


def triangle_pressure_moments(
    vertices: npt.ArrayLike, force: npt.ArrayLike, point: npt.ArrayLike, axis: npt.ArrayLike
) -> tuple[float, float]:
    """Moments (m0, m2) of a pressure that is uniform on each of a set of flat triangles.

    Triangle f, of vertices ``vertices[f]`` (3, 3), carries the force ``force_f`` (its pressure
    times its area) uniformly; r is the distance from the line through ``point`` along ``axis``.
    With w_i the vertices' components perpendicular to the axis (w is affine on the triangle),
    exactly, ``integral r^2 p = force_f (sum |w_i|^2 + |sum w_i|^2) / 12``.
    """
    v = np.asarray(vertices, dtype=np.float64)
    P = np.asarray(force, dtype=np.float64).reshape(-1)
    if v.ndim != 3 or v.shape[1:] != (3, 3) or v.shape[0] != P.shape[0]:
        raise InputError(f"vertices must have the shape (n, 3, 3) and force (n,), got {v.shape}, {P.shape}")
    n = np.asarray(axis, dtype=np.float64)
    n = n / np.linalg.norm(n)
    w = v - np.asarray(point, dtype=np.float64)
    w -= (w @ n)[..., None] * n
    mean_r2 = (np.sum(w**2, axis=(1, 2)) + np.sum(w.sum(axis=1) ** 2, axis=1)) / 12.0
    return float(P.sum()), float(P @ mean_r2)


def point_force_moments(
    points: npt.ArrayLike, force: npt.ArrayLike, point: npt.ArrayLike, axis: npt.ArrayLike
) -> tuple[float, float]:
    """Moments (m0, m2) of point forces: ``force_f`` at ``points[f]`` (n, 3), r the distance
    from the line through ``point`` along ``axis``: ``m0 = sum force_f``, ``m2 = sum force_f r_f^2``.

    The DEM's facet forces act where its facets' gaps are measured, at their barycentres; the
    same forces spread uniformly over their triangles (``triangle_pressure_moments``) have the
    larger m2, by each triangle's own second moment about its barycentre, force_f sum |e_i|^2 / 12
    (e_i its vertices about the barycentre, perpendicular to the axis).
    """
    x = np.asarray(points, dtype=np.float64)
    P = np.asarray(force, dtype=np.float64).reshape(-1)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] != P.shape[0]:
        raise InputError(f"points must have the shape (n, 3) and force (n,), got {x.shape}, {P.shape}")
    n = np.asarray(axis, dtype=np.float64)
    n = n / np.linalg.norm(n)
    w = x - np.asarray(point, dtype=np.float64)
    w -= (w @ n)[:, None] * n
    return float(P.sum()), float(P @ np.sum(w**2, axis=1))
