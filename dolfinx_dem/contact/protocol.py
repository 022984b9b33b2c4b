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
    the checkpoint (``checkpoint_state``, ``restore_state``, ``cell_state``, ``restore_cell_state``);
    statics uses ``statics.StaticContact`` besides. ``active`` in ``force_correction`` and
    ``add_force`` imposes a piece of the potential in the model's own form (statics); None is the
    natural piece."""

    dem: object  # the DEMDiscretisation it acts on
    scatter: object  # the PatchScatter of its patch dofs (a pair list round may make a new one)
    tracks_momentum: bool  # whether a run's series report the total momentum with its outputs
    friction: object | None  # its Coulomb friction (contact/friction.py), None if frictionless: then MEMM
    # calls ``add_friction(state, impulse)`` at every step (rigid.RigidContact.add_friction)

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

    def statics(self) -> StaticContact:
        """The model's interface to energy minimisation (statics/), made once."""

    def checkpoint_state(self) -> dict[str, np.ndarray]:
        """The model's state that is not a function of u (e.g. the pair list) and its counters,
        this process's arrays (``checkpoint.py``: read back by the same partition only)."""

    def restore_state(self, state: Mapping[str, np.ndarray] | None) -> None:
        """Restore ``checkpoint_state`` of the same partition; None (another partition): set the
        state up again from the restored displacements at the next ``prepare``."""

    def cell_state(self) -> dict[str, np.ndarray]:
        """The model's state that a resume on any partition needs and that no function of u gives
        (e.g. the lagged normal forces of friction): arrays (n_owned, k) of the owned cells
        (``checkpoint.py`` stores them with the cells' keys)."""

    def restore_cell_state(self, state: Mapping[str, np.ndarray]) -> None:
        """Restore ``cell_state`` (the same names and shapes, of this process's owned cells, on any
        partition; a checkpoint follows at least one step)."""


@runtime_checkable
class StaticContact(Protocol):
    """What energy minimisation (statics/active_set.py) asks of a contact model.

    A *piece* of the potential is a set of candidates in contact (facets on an obstacle, pairs
    of facets between bodies), a sorted int64 array: the process's own candidates if
    ``local_pieces`` (each process holds its part; the global order of a set is the processes'
    parts in rank order), else the same keys on every process. On a piece the potential V is
    smooth: quadratic if ``quadratic`` (one Newton step minimises it), else the iteration is a
    damped Newton method on it. Methods that take PETSc vectors are collective."""

    quadratic: bool
    local_pieces: bool
    length_scale: float  # (m) the scale of the candidates' gaps (a mesh size): rounding tolerances
    no_contact_message: str  # the error when nothing is in contact at an iterate

    def prepare(self, u: PETSc.Vec) -> None:
        """Make the model valid at u (a trial point may move facets far)."""

    def start_piece(self, u: PETSc.Vec) -> np.ndarray:
        """The piece to start from at u: the candidates closest to contact."""

    def touching(self, u: PETSc.Vec) -> np.ndarray:
        """The piece of the candidates in contact at u (g < 0)."""

    def add_force(self, u: PETSc.Vec, out: PETSc.Vec, piece: np.ndarray) -> None:
        """out += the contact force of the piece at u (the exact negative gradient of V_piece - V_free)."""

    def add_hessian(self, H: PETSc.Mat, u: PETSc.Vec, piece: np.ndarray, exact: bool) -> None:
        """H += the Hessian of V_piece - V_free at u (``exact``: with the curvature terms that may
        make it indefinite; else its positive semi-definite Gauss-Newton part). H accepts new
        nonzeros; the caller assembles it."""

    def step_ratio(self, step: PETSc.Vec) -> float:
        """How far a step may go: the largest motion of a candidate relative to what keeps the
        model valid (> 1: the caller shortens the step by this factor; 0 if unbounded)."""

    def switches_crossed(self, u: PETSc.Vec, step: PETSc.Vec, alpha: float, piece: np.ndarray) -> np.ndarray:
        """The candidates whose switch g = 0 the step u + tau step crosses for tau in [0, 2 alpha],
        leaving their side (closing if out of ``piece``, opening if in it)."""

    def constraint_gradients(self, u: PETSc.Vec, pinned: np.ndarray) -> list[PETSc.Vec]:
        """grad g of each pinned candidate (their global order), as distributed vectors."""

    def constraint_products(self, u: PETSc.Vec, pinned: np.ndarray, gradients: list[PETSc.Vec],
                            vectors: list[PETSc.Vec]) -> np.ndarray:
        """grad g_c . v for the pinned candidates c (rows, global order) and the ``vectors``
        (columns), every process; ``gradients``: the caller's projected gradients of them."""

    def constraint_gaps(self, u: PETSc.Vec, pinned: np.ndarray) -> np.ndarray:
        """g_c(u) of the pinned candidates, their global order, every process."""

    def constraint_reactions(self, u: PETSc.Vec, piece: np.ndarray, pinned: np.ndarray) -> np.ndarray:
        """r_c, the normal force each pinned candidate would carry in contact (the jump of
        -dV/dg_c across its switch), their global order, every process."""
