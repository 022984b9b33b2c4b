"""Isotropic linear elastic material: Hooke's law of eq. (9), in 1D, plane strain/stress and 3D."""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np
from mpi4py import MPI

from dolfinx_dem import bodies
from dolfinx_dem.errors import InputError


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
        for name in ("E", "nu", "rho", "eta"):
            value = getattr(self, name)
            if name == "eta" and value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise InputError(f"material parameter {name} must be a finite real number, got {value!r} "
                                 f"({type(value).__name__})")
            object.__setattr__(self, name, float(value))  # numpy scalars of any kind: stored as floats
        if self.E <= 0:
            raise InputError(f"Young's modulus E must be > 0, got {self.E}")
        if not -1.0 < self.nu < 0.5:
            raise InputError(f"Poisson ratio nu must lie in (-1, 0.5), got {self.nu}")
        if self.rho <= 0:
            raise InputError(f"density rho must be > 0, got {self.rho}")
        if self.plane not in ("strain", "stress"):
            raise InputError(f"plane must be 'strain' or 'stress', got {self.plane!r}")
        if self.eta is not None and not self.eta > 0:
            raise InputError(f"stabilisation parameter eta must be > 0, got {self.eta}")

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


@dataclasses.dataclass(frozen=True)
class CellMaterials:
    """The material of each cell a process holds: cell c is made of ``materials[index[c]]``.

    ``index`` (n_cells,) covers the owned and the halo cells (geometry.py), so that every operator
    of a process reads its cells' C (eq. (9)), rho and eta from local data. All materials share
    ``plane``: plane strain and plane stress are two hypotheses on the third direction of the
    whole body (an infinite prism or a thin plate), and a body cannot be both at an interface.
    """

    materials: tuple[ElasticMaterial, ...]
    index: np.ndarray  # (n_cells,) int

    def __post_init__(self):
        planes = {m.plane for m in self.materials}
        if len(planes) > 1:
            raise InputError(f"all materials must share 'plane' (the body's 2D hypothesis), got {sorted(planes)}")

    @classmethod
    def uniform(cls, material: ElasticMaterial, num_cells: int) -> CellMaterials:
        """One material for all ``num_cells`` cells."""
        return cls((material,), np.zeros(num_cells, dtype=np.int32))

    @property
    def plane(self) -> str:
        """The 2D hypothesis all materials share."""
        return self.materials[0].plane

    def _per_cell(self, values, cells) -> np.ndarray:
        index = self.index if cells is None else self.index[cells]
        return np.asarray(values, dtype=float)[index]

    def rho(self, cells=None) -> np.ndarray:
        """Density of ``cells`` (default: all held cells), (n,)."""
        return self._per_cell([m.rho for m in self.materials], cells)

    def stabilisation(self, cells=None) -> np.ndarray:
        """eta of eq. (13) of ``cells``, (n,) (Pa)."""
        return self._per_cell([m.stabilisation for m in self.materials], cells)

    def wave_speed(self, d: int, cells=None) -> np.ndarray:
        """The P-wave speed (``ElasticMaterial.wave_speed``) of ``cells``, (n,) (m/s)."""
        return self._per_cell([m.wave_speed(d) for m in self.materials], cells)

    def elasticity_tensor(self, d: int, cells=None) -> np.ndarray:
        """C of eq. (9) of ``cells``, (n, d, d, d, d)."""
        return self._per_cell([m.elasticity_tensor(d) for m in self.materials], cells)

    def facet_stabilisation(self, c1: np.ndarray, c2: np.ndarray) -> np.ndarray:
        """eta_f of the facets between cells c1 and c2 (n,), the weight of eq. (13): the harmonic
        mean 2 eta_1 eta_2 / (eta_1 + eta_2) of the two cells' eta, eta itself in one material.
        The term eta_f |f| / h_f |[u]|^2 is a spring across the facet; the two half cells, each of
        width h_f / 2 and modulus eta_i, act in series, which is the harmonic mean (the soft side
        governs, as the elastic energy does across an interface)."""
        e1, e2 = self.stabilisation(c1), self.stabilisation(c2)
        return 2 * e1 * e2 / (e1 + e2)

    def stress(self, grad: np.ndarray) -> np.ndarray:
        """sigma = C : sym(grad) of eq. (9) for the first len(grad) cells, grad of shape (n, d, d)."""
        index = self.index[: len(grad)]
        sigma = np.empty_like(grad)
        for k, m in enumerate(self.materials):
            sigma[index == k] = m.stress(grad[index == k])
        return sigma

    def von_mises(self, G: np.ndarray) -> np.ndarray:
        """Von Mises stress (Pa) of the first n cells of gradients G (n, d, d); the out-of-plane
        stress of plane strain counts."""
        sigma = self.stress(G)
        n, d = G.shape[0], G.shape[-1]
        if d == 1:
            return np.abs(sigma[:, 0, 0])
        s = np.zeros((n, 3, 3))
        s[:, :d, :d] = sigma
        if d == 2 and self.plane == "strain":
            lmbda = np.array([m.lame(2)[0] for m in self.materials])[self.index[:n]]
            s[:, 2, 2] = lmbda * (G[:, 0, 0] + G[:, 1, 1])
        dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] * np.eye(3) / 3
        return np.sqrt(1.5 * np.einsum("nij,nij->n", dev, dev))


def cell_materials(dem, material, cell_tags, prescribed: bool) -> CellMaterials:
    """The ``CellMaterials`` of the held cells of ``dem``: one material, or one per cell tag (the
    owned cells' tags, extended to the halo by ``halo_exchange``). Every cell needs exactly one
    tag of ``material`` and every tag a cell; errors are raised on every process."""
    if isinstance(material, ElasticMaterial):
        if cell_tags is not None and not prescribed:
            raise InputError("cell_tags are only used with several materials ({cell tag: ElasticMaterial}) "
                             "or prescribed bodies")
        return CellMaterials.uniform(material, dem.geometry.num_cells)
    if cell_tags is None:
        raise InputError("several materials ({cell tag: ElasticMaterial}) need cell_tags")
    tags = [int(t) for t in material]
    n, comm = dem.n_owned, dem.comm
    count = np.zeros(n, dtype=np.int64)  # tags of each owned cell (dolfinx_dem's cell order)
    index = np.full(n, -1, dtype=np.int64)
    selected = np.zeros(len(tags), dtype=np.int64)
    for k, tag in enumerate(tags):
        cells = bodies.tagged_cells(dem.V, cell_tags, tag)
        count[cells] += 1
        index[cells] = k
        selected[k] = len(cells)
    selected = comm.allreduce(selected, op=MPI.SUM)
    counts = comm.allreduce(np.array([(count > 1).sum(), (count == 0).sum()]), op=MPI.SUM)
    if np.any(selected == 0):
        raise InputError(f"the material of cell tag {tags[int(np.argmin(selected))]} selects no cell")
    if counts[0]:
        raise InputError(f"{counts[0]} cells carry several material tags (materials overlap); tags {tags}")
    if counts[1]:
        raise InputError(f"{counts[1]} cells carry none of the material tags {tags}: give every cell a material")
    held = dem.halo_exchange(index[:, None])[:, 0]
    return CellMaterials(tuple(material[t] for t in material), held.astype(np.int32))
