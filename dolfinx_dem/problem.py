"""A DEM problem: a discretisation and the contact models acting on it (paper §3.4).

The discretisation (discretisation.py) knows nothing of contact. Contact changes the
reconstructions of a few boundary facets, so it changes the energy rows a = Q u + q near them
by delta_a (contact/), and with them the potential, its gradient and the cell gradients of
eq. (8). ``DEMProblem(dem, contacts)``, in the spirit of dolfinx_mpc's
``LinearProblem(a, L, mpc)``, composes the two: what MEMM (memm.py), statics (statics/) and the
outputs ask of a problem, with every contact model's correction added.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from petsc4py import PETSc

from dolfinx_dem.contact.protocol import ContactModel
from dolfinx_dem.discretisation import DEMDiscretisation, energies_of
from dolfinx_dem.errors import InputError


class DEMProblem:
    """The discretisation ``dem`` with the contact models ``contacts`` (each built on ``dem``;
    at most one of each kind, e.g. ``contact.RigidContact`` for rigid obstacles and
    ``contact.PairContact`` for contact between bodies).

    The potential is V(u, t) of ``dem`` plus each model's energy change, and ``force`` is its
    exact negative gradient (contact/: every correction is the gradient of its energy).
    ``fracture``: a ``fracture.Fracture`` built on ``dem`` (issue 34; no contact models then),
    whose breaks change ``dem``'s operator between MEMM's steps.
    """

    def __init__(self, dem: DEMDiscretisation, contacts: Sequence[ContactModel] = (), fracture=None):
        if not isinstance(dem, DEMDiscretisation):
            raise InputError(f"DEMProblem needs a DEMDiscretisation, got {type(dem).__name__}")
        contacts = tuple(contacts)
        for c in contacts:
            if not isinstance(c, ContactModel):
                raise InputError(f"{type(c).__name__} is not a contact model (contact.protocol.ContactModel)")
            if c.dem is not dem:
                raise InputError(f"the {type(c).__name__} was built on another discretisation than the problem's")
        kinds = [type(c) for c in contacts]
        if len(set(kinds)) != len(kinds):
            raise InputError("a problem takes at most one contact model of each kind (one RigidContact holds "
                             "every obstacle, one PairContact every contact boundary)")
        self.dem = dem
        self.comm, self.d = dem.comm, dem.d
        #: the contact models, in the order given (their outputs follow it)
        self.contacts = contacts
        if fracture is not None and (contacts or fracture.dem is not dem):
            raise InputError("fracture (issue 34) needs a problem without contact models, on the discretisation "
                             "it was built on: contact with fracture is design stage S5")
        #: the breaking facets (fracture.Fracture), or None; MEMM calls its ``update`` after each step
        self.fracture = fracture
        self._work = None

    def find(self, kind: type) -> ContactModel | None:
        """The contact model of class ``kind`` (e.g. ``contact.PairContact``), None if there is none."""
        return next((c for c in self.contacts if isinstance(c, kind)), None)

    def create_vector(self) -> PETSc.Vec:
        """A PETSc vector with the layout of the owned DG0 dofs (``DEMDiscretisation.create_vector``)."""
        return self.dem.create_vector()

    def force(self, u: PETSc.Vec, t: float, out: PETSc.Vec) -> PETSc.Vec:
        """out = -dV/du (u, t): the discretisation's force plus each contact model's correction
        (collective)."""
        self.dem.force(u, t, out)
        for c in self.contacts:
            c.add_force(u, out)
        return out

    def energies(self, u: PETSc.Vec, t: float) -> dict[str, float]:
        """Elastic, stabilisation and external energies with the contact models' changes of the
        elastic and stabilisation rows, global sums, and ``potential``, their total: the
        potential whose exact gradient ``force`` computes (collective)."""
        local = self.dem.local_energies(u, t)
        for c in self.contacts:  # this process's part of the contact energy changes
            local[:2] += c.energy_correction(c.patch_values(u))
        return energies_of(self.comm, local)

    def gradient(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Cell gradients G_c of eq. (8) of the owned cells, (n_owned, d, d), from the contact-aware
        facet reconstructions (collective)."""
        G = self.dem.gradient(u, t)
        for c in self.contacts:
            cells, change = c.gradient_correction(c.patch_values(u))
            np.add.at(G, cells, change)
        return G

    def stress(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Cell stresses sigma_c of eq. (9), (n_owned, d, d) (in-plane part in 2D; collective)."""
        return self.dem.materials.stress(self.gradient(u, t))

    def von_mises(self, u: PETSc.Vec, t: float) -> np.ndarray:
        """Von Mises stress of the owned cells (Pa; collective)."""
        return self.dem.materials.von_mises(self.gradient(u, t))

    def prescribed_values(self, u: PETSc.Vec, t: float, force: PETSc.Vec | None = None) -> np.ndarray:
        """For each prescribed body, its reaction, the force it exerts on the other bodies (dV/dU,
        the exact derivative of the potential with respect to its translation U, without the loads
        on the body itself: its weight does not count), and its translation: (n, 2, d), global. ``force``: the force
        vector to sum instead of ``force(u, t)`` (statics: the Lagrangian's, whose multipliers
        carry the pairs held on a contact switch). Collective (a force evaluation)."""
        if force is None:
            if self._work is None:
                self._work = self.dem.create_vector()
            force = self.force(u, t, self._work)
        return self.dem.prescribed.values(u, force, self.dem.data.forcing(t))
