"""The protocol of a contact model: what the problem (problem.py), MEMM (memm.py), the
checkpoints and the outputs ask of it. A new contact law implements it (contact/rigid.py and
contact/pair.py are the two of the package).

A contact model changes the reconstructions of a few candidate boundary facets of a
discretisation, hence a few of its energy rows a = Q u + q (paper §3.4): its energy change, its
force correction F - F_free (the exact negative gradient of that change) and its change of the
cell gradients of eq. (8) are all computed on a *patch*: the few dofs these rows and facets read,
gathered by a VecScatter (contact/patch.py). Methods that take PETSc vectors are collective;
``up`` are this process's patch values (``patch_values``), valid until the next ``prepare``,
which returns those of the state it prepares for.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol, runtime_checkable

import numpy as np
from petsc4py import PETSc


@runtime_checkable
class ContactModel(Protocol):
    """A contact model of a ``DEMDiscretisation`` ``dem`` (module docstring). Four groups: the
    dynamics (``prepare`` ... ``force_integral``), the outputs (``output_columns`` ...), and
    the checkpoint (``checkpoint_state``, ``restore_state``); statics uses ``statics.StaticContact``
    besides. ``active`` in ``force_correction`` and ``add_force`` imposes a piece of the
    potential in the model's own form (statics); None is the natural piece."""

    dem: object  # the DEMDiscretisation it acts on
    scatter: object  # the PatchScatter of its patch dofs (a pair list round may make a new one)
    tracks_momentum: bool  # whether a run's series report the total momentum with its outputs

    def prepare(self, u: PETSc.Vec, v: PETSc.Vec | None = None, dt: float = 0.0,
                up: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Make the model valid for the states u + tau v, 0 <= tau <= dt (MEMM: every step);
        returns the patch values of u and of v (None without v). ``up``: the patch values of u
        if the caller has them (gathered by the current ``scatter``), else they are gathered."""

    def patch_values(self, vec: PETSc.Vec) -> np.ndarray:
        """The values of ``vec`` at this process's patch dofs."""

    def force_correction(self, up: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """This process's part of F - F_free at the patch dofs (the exact negative gradient of
        ``energy_correction``, summed over processes by ``add``)."""

    def add(self, correction: np.ndarray, out: PETSc.Vec, scale: float = 1.0) -> None:
        """out += scale * correction (patch values; a reverse scatter)."""

    def add_force(self, u: PETSc.Vec, out: PETSc.Vec, active: np.ndarray | None = None) -> None:
        """out += F - F_free at u."""

    def energy_correction(self, up: np.ndarray) -> tuple[float, float]:
        """This process's part of the (elastic, stabilisation) energy changes (sum over processes)."""

    def gradient_correction(self, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(local cells, change of their gradients (n, d, d)) for the touching facets."""

    def force_integral(self, up: np.ndarray, vp: np.ndarray, dt: float, out: PETSc.Vec) -> int:
        """out += int_0^dt (F - F_free)(u + tau v) dtau, exactly, for the patch values up, vp
        of u and v that ``prepare`` returned; returns the evaluations."""

    def output_columns(self) -> tuple[str, ...]:
        """The series columns of the model's outputs (model.py appends them to a run's series)."""

    def output_sums(self, up: np.ndarray) -> np.ndarray:
        """This process's parts of the sums its outputs need (the caller reduces the sums of
        every model in one Allreduce)."""

    def output_values(self, up: np.ndarray, sums: np.ndarray) -> list[float]:
        """The values of ``output_columns`` from the reduced ``output_sums`` (collective)."""

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """The model's state that is not a function of u (e.g. the pair list) and its counters,
        this process's arrays (``checkpoint.py``: read back by the same partition only)."""

    def restore_state(self, state: Mapping[str, np.ndarray] | None) -> None:
        """Restore ``checkpoint_state`` of the same partition; None (another partition): set the
        state up again from the restored displacements at the next ``prepare``."""
