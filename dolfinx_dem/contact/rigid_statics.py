"""The statics interface of contact with rigid obstacles (``contact.protocol.StaticContact``).

On a fixed set A of facets in contact the potential is quadratic (contact/rigid.py): the energy
rows change by -sum_{f in A} g_f y_f, with gaps g_f affine in u. A piece is the sorted array of
the process's own candidate facets (indices into the model's own facets) that are in contact:
the active sets stay distributed, and only the few facets pinned on a kink are gathered.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc


class RigidStatics:
    """The statics interface of a ``contact.rigid.RigidContact`` (module docstring)."""

    quadratic = True
    local_pieces = True
    no_contact_message = ("no facet is in contact at the solution: the obstacle does not hold the body (check the "
                          "contact candidate boundary and the load direction)")

    def __init__(self, contact):
        self.contact, self.comm = contact, contact.comm
        own = contact.facets[: contact.num_own]
        #: the smallest candidate facet diameter (m): the scale of the gaps
        self.length_scale = self.comm.allreduce(
            contact.dem.geometry.facet_diameters[own].min(initial=np.inf), op=MPI.MIN)

    def _mask(self, piece: np.ndarray) -> np.ndarray:
        mask = np.zeros(self.contact.num_own, dtype=bool)
        mask[piece] = True
        return mask

    def _gathered(self, values: np.ndarray, pinned: np.ndarray) -> np.ndarray:
        """The own values of the pinned facets of every process, in rank order (the pinned
        candidates' global order)."""
        return np.concatenate(self.comm.allgather(values[pinned]))

    def prepare(self, u: PETSc.Vec) -> None:
        """Nothing to prepare: every candidate is tested at every evaluation."""

    def start_piece(self, u: PETSc.Vec) -> np.ndarray:
        """The facets touching the obstacle at u, to rounding of the smallest gap: the iteration
        adds the facets the solution pushes into it and releases those it lifts off."""
        g = self.contact.own_gaps(u)
        closest = self.comm.allreduce(g.min(initial=np.inf), op=MPI.MIN)
        return np.flatnonzero(g <= closest + 1e-9 * self.length_scale)

    def touching(self, u: PETSc.Vec) -> np.ndarray:
        return np.flatnonzero(self.contact.own_gaps(u) < 0)

    def add_force(self, u: PETSc.Vec, out: PETSc.Vec, piece: np.ndarray) -> None:
        self.contact.add_force(u, out, self._mask(piece))

    def add_hessian(self, H: PETSc.Mat, u: PETSc.Vec, piece: np.ndarray, exact: bool) -> None:
        """The exact Hessian of the quadratic piece (``exact`` changes nothing)."""
        if self.comm.allreduce(bool(len(piece)), op=MPI.LOR):
            self.contact.add_hessian(H, self._mask(piece))

    def step_ratio(self, step: PETSc.Vec) -> float:
        """No limit: every candidate is tested at every evaluation."""
        return 0.0

    def switches_crossed(self, u: PETSc.Vec, step: PETSc.Vec, alpha: float, piece: np.ndarray) -> np.ndarray:
        """The own facets whose gap, affine along u + tau step, reaches 0 for tau in [0, 2 alpha]
        leaving its side."""
        g = self.contact.own_gaps(u)
        rate = self.contact.own_gap_rates(step)
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = np.where(rate != 0, -g / rate, np.inf)
        leaving = np.where(self._mask(piece), rate > 0, rate < 0)
        return np.flatnonzero(leaving & (tau >= 0) & (tau <= 2 * alpha))

    def constraint_gradients(self, u: PETSc.Vec, pinned: np.ndarray) -> list[PETSc.Vec]:
        facets = [(r, int(k)) for r, ks in enumerate(self.comm.allgather(pinned)) for k in ks]
        return [self.contact.gap_gradient(r, k) for r, k in facets]

    def constraint_products(self, u: PETSc.Vec, pinned: np.ndarray, gradients: list[PETSc.Vec],
                            vectors: list[PETSc.Vec]) -> np.ndarray:
        """From the own gap rows and the patch values of the vectors (the gathered rows are the
        pinned facets')."""
        patches = [self.contact.patch_values(v) for v in vectors]  # collective: once per vector
        own = np.array([[self.contact.gap_gradient_dot(k, p) for p in patches] for k in pinned])
        return np.concatenate(self.comm.allgather(own.reshape(len(pinned), len(vectors))))

    def constraint_gaps(self, u: PETSc.Vec, pinned: np.ndarray) -> np.ndarray:
        return self._gathered(self.contact.own_gaps(u), pinned)

    def constraint_reactions(self, u: PETSc.Vec, piece: np.ndarray, pinned: np.ndarray) -> np.ndarray:
        """The forces the pinned facets would carry in contact, the piece and the pinned facets in
        contact."""
        return self._gathered(self.contact.reactions(u, self._mask(np.union1d(piece, pinned))), pinned)

    def own_values(self, values: np.ndarray, pinned: np.ndarray) -> np.ndarray:
        """Per own candidate facet, the ``values`` of the pinned ones (their global order: e.g.
        ``StaticResult.kink_forces``), 0 elsewhere."""
        out = np.zeros(self.contact.num_own)
        offset = self.comm.exscan(len(pinned)) or 0
        out[pinned] = values[offset : offset + len(pinned)]
        return out
