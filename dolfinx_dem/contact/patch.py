"""Contact patches: the process-local piece of the DEM that a contact model works on.

A contact model changes the reconstructions of a few boundary facets, hence a few energy rows
a = Q u + q (``DEMDiscretisation.rows``). Each process handles the candidate facets of its owned
cells, and also knows those of the cells in its first halo layer: together they touch every row
it holds for its owned cells and facets (geometry.py), so the energy change on its own rows and
the forces of its own facets are computed from local data only. ``PatchScatter`` brings the
values of the few dofs these rows and facets read from the distributed vectors (a PETSc VecScatter
of exactly those dofs: no gather of the whole contact boundary), and adds the contact forces back
into the distributed force vector (the reverse scatter, summing over processes).
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc


class PatchScatter:
    """Values of distributed vectors (layout of ``template``) at the global dofs ``dofs``, and
    the sum of per-process contributions at those dofs back into a distributed vector.
    Collective: every process of ``template``'s communicator calls ``gather`` and ``add``."""

    def __init__(self, template: PETSc.Vec, dofs: np.ndarray):
        self.dofs = np.asarray(dofs, dtype=PETSc.IntType)
        self._values = np.zeros(len(self.dofs))  # the memory of the patch vector _local
        self._local = PETSc.Vec().createWithArray(self._values, comm=PETSc.COMM_SELF)
        index = PETSc.IS().createGeneral(self.dofs, comm=PETSc.COMM_SELF)
        self._scatter = PETSc.Scatter().create(template, index, self._local, None)

    def __len__(self) -> int:
        return len(self.dofs)

    def gather(self, vec: PETSc.Vec) -> np.ndarray:
        """The values of ``vec`` at the patch dofs (a copy)."""
        self._scatter.scatter(vec, self._local, PETSc.InsertMode.INSERT, PETSc.ScatterMode.FORWARD)
        return self._values.copy()

    def add(self, values: np.ndarray, vec: PETSc.Vec, scale: float = 1.0) -> None:
        """vec += scale * values at the patch dofs, summed over the processes."""
        np.multiply(values, scale, out=self._values)
        self.add_zeroed(vec)

    def zeroed(self) -> np.ndarray:
        """The patch's own work array, zeroed, for a caller to sum its values into and then
        ``add_zeroed`` them (no copy; valid until the next call of this scatter)."""
        self._values.fill(0.0)
        return self._values

    def add_zeroed(self, vec: PETSc.Vec) -> None:
        """vec += the values summed into the array of ``zeroed``, at the patch dofs, summed over
        the processes."""
        self._local.stateIncrease()  # written through its array
        self._scatter.scatter(self._local, vec, PETSc.InsertMode.ADD_VALUES, PETSc.ScatterMode.REVERSE)
