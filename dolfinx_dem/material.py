"""Isotropic linear elastic material: Hooke's law of eq. (9), in 1D, plane strain/stress and 3D."""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class ElasticMaterial:
    """Homogeneous isotropic linear elastic material.

    Parameters
    ----------
    E : Young's modulus (Pa), > 0.
    nu : Poisson ratio, in (-1, 0.5). Ignored in 1D (sigma = E u').
    rho : density (kg/m^d), > 0.
    plane : "strain" (default) or "stress", the 2D hypothesis.
    eta : stabilisation parameter of eq. (13) (Pa), > 0; defaults to E (paper §3.2).
    """

    E: float
    nu: float
    rho: float
    plane: str = "strain"
    eta: float | None = None

    def __post_init__(self):
        for name in ("E", "nu", "rho"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"material parameter {name} must be a finite number, got {value!r}")
        if self.E <= 0:
            raise ValueError(f"Young's modulus E must be > 0, got {self.E}")
        if not -1.0 < self.nu < 0.5:
            raise ValueError(f"Poisson ratio nu must lie in (-1, 0.5), got {self.nu}")
        if self.rho <= 0:
            raise ValueError(f"density rho must be > 0, got {self.rho}")
        if self.plane not in ("strain", "stress"):
            raise ValueError(f"plane must be 'strain' or 'stress', got {self.plane!r}")
        if self.eta is not None and not (math.isfinite(self.eta) and self.eta > 0):
            raise ValueError(f"stabilisation parameter eta must be > 0, got {self.eta}")

    @property
    def stabilisation(self) -> float:
        """eta of eq. (13): E unless given."""
        return self.E if self.eta is None else float(self.eta)

    def lame(self, d: int) -> tuple[float, float]:
        """Lamé coefficients (lambda, mu) in dimension d (plane stress modifies lambda in 2D)."""
        E, nu = self.E, self.nu
        lmbda = E * nu / ((1 + nu) * (1 - 2 * nu))
        mu = E / (2 * (1 + nu))
        if d == 2 and self.plane == "stress":
            lmbda = 2 * lmbda * mu / (lmbda + 2 * mu)
        return lmbda, mu

    def wave_speed(self, d: int) -> float:
        """Largest (P-wave) speed sqrt((lambda + 2 mu)/rho), or sqrt(E/rho) in 1D (m/s)."""
        if d == 1:
            return math.sqrt(self.E / self.rho)
        lmbda, mu = self.lame(d)
        return math.sqrt((lmbda + 2 * mu) / self.rho)

    def elasticity_tensor(self, d: int) -> np.ndarray:
        """C_ijkl of sigma = C : eps, shape (d, d, d, d); C_1111 = E in 1D."""
        if d == 1:
            return np.full((1, 1, 1, 1), float(self.E))
        lmbda, mu = self.lame(d)
        I = np.eye(d)
        return (
            lmbda * np.einsum("ij,kl->ijkl", I, I)
            + mu * (np.einsum("ik,jl->ijkl", I, I) + np.einsum("il,jk->ijkl", I, I))
        )

    def stress(self, grad: np.ndarray) -> np.ndarray:
        """sigma = C : sym(grad), grad of shape (..., d, d)."""
        d = grad.shape[-1]
        return np.einsum("ijkl,...kl->...ij", self.elasticity_tensor(d), grad)
