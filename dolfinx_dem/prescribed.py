"""Bodies of imposed translation (``conditions.PrescribedBody``) in a DEM discretisation.

Their dofs have mass 0 and inverse mass 0, so that MEMM's update leaves their velocity as set
(memm.py) and the kinetic energy and momenta leave them out. A rigid translation gives their own
energy rows zero energy; their dofs also drop out of the stable step bound (M^-1 = 0: they do not
vibrate).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import bodies as _bodies
from dolfinx_dem.conditions import PrescribedBody
from dolfinx_dem.errors import InputError


class PrescribedMotion:
    """The prescribed bodies of a discretisation, set up from the cell tags (``bodies``: the
    tuple of ``PrescribedBody``). Errors, raised on every process: no cell tags, a tag that
    selects no cell or not whole bodies (a cell of the same body without the tag, or a vertex
    shared with another body), a body selected twice, a Dirichlet condition or a traction on
    the body, not exactly one of velocity and displacement, a velocity of the wrong length."""

    def __init__(self, dem, bodies: Sequence[PrescribedBody], cell_tags):
        self.bodies = tuple(bodies)
        self.d = d = dem.d
        self.comm = comm = dem.comm
        self._cells = []
        self.dofs = np.empty(0, dtype=np.int64)  #: the owned dofs of the prescribed bodies
        geom = dem.geometry
        self._flags = np.zeros(geom.num_bodies, dtype=bool)  # prescribed, per body number
        if not self.bodies:
            return
        if d != 2:
            raise InputError(f"prescribed bodies take part in contact between bodies, implemented in 2D, not {d}D")
        if cell_tags is None:
            raise InputError("prescribed bodies are selected by cell tag: cell_tags are needed")
        owned_bodies = geom.cell_bodies[: dem.n_owned]
        mine = np.zeros(geom.num_bodies, dtype=np.int64)  # bodies of prescribed cells (any body)
        for k, body in enumerate(self.bodies):
            what = f"prescribed body {k if body.name is None else body.name!r} (cell tag {body.tag})"
            if (body.velocity is None) == (body.displacement is None):
                raise InputError(f"{what} needs exactly one of velocity and displacement")
            if body.velocity is not None and np.shape(body.velocity) != (d,):
                raise InputError(f"{what}: velocity must have {d} components, got {list(np.ravel(body.velocity))}")
            cells = _bodies.tagged_cells(dem.V, cell_tags, body.tag)
            if comm.allreduce(len(cells), op=MPI.SUM) == 0:
                raise InputError(f"{what} selects no cell")
            selected = np.zeros(geom.num_bodies, dtype=np.int64)
            selected[owned_bodies[cells]] = 1
            comm.Allreduce(MPI.IN_PLACE, selected, op=MPI.MAX)
            untagged = np.isin(owned_bodies, np.flatnonzero(selected))
            untagged[cells] = False
            if comm.allreduce(int(untagged.sum()), op=MPI.SUM):
                raise InputError(f"{what} is not a whole body: it shares facets with cells without the tag "
                                 "(a prescribed body must be meshed separately)")
            if mine[selected > 0].any():
                raise InputError(f"{what} overlaps another prescribed body")
            mine += selected
            self._cells.append(cells)
        rec = dem.reconstruction
        for what, facets in (("a Dirichlet condition", rec.dirichlet_facets), ("a traction", rec.traction_facets)):
            cells = geom.facet_cells[facets, 0]
            if comm.allreduce(bool(mine[geom.cell_bodies[cells[cells < dem.n_owned]]].any()), op=MPI.LOR):
                raise InputError(f"a prescribed body carries {what}: its motion is imposed already")
        try:
            _bodies.check_share_no_vertex(geom, comm, np.flatnonzero(mine))
        except InputError as err:
            raise InputError(f"a prescribed body is not a whole body: {err}") from None
        self._flags = mine > 0
        self.dofs = (np.concatenate(self._cells)[:, None] * d + np.arange(d)).ravel()

    def __bool__(self) -> bool:
        return bool(self.bodies)

    def __len__(self) -> int:
        return len(self.bodies)

    def __iter__(self):
        return iter(self.bodies)

    @property
    def body_numbers(self) -> np.ndarray:
        """The numbers of the prescribed bodies (``geometry.cell_bodies``; empty without)."""
        return np.flatnonzero(self._flags)

    @property
    def flags(self) -> np.ndarray:
        """Whether each body (by number) is prescribed, (num_bodies,) booleans."""
        return self._flags

    @property
    def moving(self) -> bool:
        """Whether some prescribed body follows a displacement U(t) (MEMM sets its velocity each step)."""
        return any(body.displacement is not None for body in self.bodies)

    def impose(self, u: PETSc.Vec, v: PETSc.Vec, t: float, dt: float, position: bool = True) -> None:
        """On the prescribed bodies' dofs: u = U(t) if ``position``, and v = the constant velocity,
        or (U(t + dt) - u)/dt for a displacement: the velocity v^{n+1/2} of MEMM's step from
        u^n = u at t_n to U(t + dt) (the flight is affine within the step, and u follows U(t)
        without accumulating rounding)."""
        d = self.d
        if position:
            self.hold(u, t)
        for body, cells in zip(self.bodies, self._cells):
            v.array.reshape(-1, d)[cells] = body.velocity if body.velocity is not None else \
                (body.translation(t + dt, d) - u.array_r.reshape(-1, d)[cells]) / dt

    def hold(self, u: PETSc.Vec, t: float) -> None:
        """u = U(t) on the prescribed bodies' dofs (the other dofs untouched)."""
        for body, cells in zip(self.bodies, self._cells):
            u.array.reshape(-1, self.d)[cells] = body.translation(t, self.d)

    def values(self, u: PETSc.Vec, force: PETSc.Vec, forcing: PETSc.Vec) -> np.ndarray:
        """For each prescribed body, its reaction, the force it exerts on the other bodies,
        -(sum of ``force`` - ``forcing`` on its dofs), and its translation (its cells' mean u):
        (n, 2, d), global sums (collective). With ``force`` = -dV/du and ``forcing`` the external
        force f(t) (its body force and tractions), the reaction is dV/dU without the loads on the
        body itself: the forces of the contacts it transmits (its cells translate together, so its
        elastic forces sum to zero)."""
        d = self.d
        out = np.zeros((len(self.bodies), 2, d))
        counts = np.zeros(len(self.bodies))
        for k, cells in enumerate(self._cells):
            out[k, 0] = -(force.array_r.reshape(-1, d)[cells] - forcing.array_r.reshape(-1, d)[cells]).sum(axis=0)
            out[k, 1] = u.array_r.reshape(-1, d)[cells].sum(axis=0)
            counts[k] = len(cells)
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        out[:, 1] /= self.comm.allreduce(counts, op=MPI.SUM)[:, None]
        return out
