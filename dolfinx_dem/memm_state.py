"""The arrays and compiled kernels of a MEMM step (memm.py, kernels/rows.c).

``StepState`` holds the state u, v^{n-1/2}, v^{n+1/2} as PETSc vectors with ghost dofs, the
homogeneous energy rows y = Q u (stored divided by dt: their increment is then Q v^{n+1/2} with
no scaling pass), z = Q^T y for this step and the next, and the local sums a step reduces. A step
is, in the terms of memm.py's docstring:

- ``advance_rows``: y += Q (v^{n+1/2} minus its free body's mean velocity), or, refreshing,
  y = Q rel(u^{n+1}) / dt by a true product; z^{n+1} = Q^T y, the squares of y summed (one pass
  over Q, factored.py), between a forward ghost update of v and a reverse one of z;
- ``update``: (35a)-(35b) with the affine force integral -dt^2/2 (z^n + z^{n+1}) plus the step's
  impulse, summing the kinetic, pseudo-kinetic and external terms and the free bodies' momenta
  (and the prescribed bodies' work, from the same force integral on their dofs);
- ``reduce``: the lift q(t)'s share of the energies, then one Allreduce of all the sums.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.errors import InputError
from dolfinx_dem.kernels import Struct, ffi, lib, pointer

_FORWARD = dict(addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
_REVERSE = dict(addv=PETSc.InsertMode.ADD_VALUES, mode=PETSc.ScatterMode.REVERSE)

#: slots of ``StepState.sums``: |y|^2 over the elastic and the stabilisation rows, kinetic,
#: pseudo-kinetic, f . u, the lift's share of the elastic and stabilisation energies, the contact
#: models' (this process's parts of their energy changes, set by MEMM before ``reduce``), the
#: step's work of time-dependent data, v^{n+1/2} . int L dt (added by MEMM), and of prescribed
#: bodies, -v_p^{n+1/2} . I_p (added by ``update``), and the data potential
#: (``BoundaryData.data_potential``); the step's frictional dissipation (added by MEMM); the
#: total momentum sum_c m_c vbar_c at t_n (3 slots, d used); then the momentum of each free body
#: at v^{n+1/2} (d per body, and d for the cells of clamped bodies).
(ROWS_S, ROWS_J, KINETIC, PSEUDO, EXTERNAL, LIFT_S, LIFT_J, CONTACT_S, CONTACT_J, LOAD_POWER, DATA_POTENTIAL,
 DISSIPATION, MOMENTUM) = range(13)
MOMENTA = MOMENTUM + 3


class StepState:
    """The vectors and kernel arguments of MEMM on a ``DEMDiscretisation`` (``problem``) with time step dt."""

    def __init__(self, problem, dt: float):
        self.problem, self.dt = problem, dt
        K = self.rows = problem.factored
        self.u = K.create_vector()
        self.v_prev = K.create_vector()  # v^{n-1/2}
        self.v_next = K.create_vector()  # v^{n+1/2}: the pass over Q reads it at the ghost dofs
        # the pass's input when refreshing, rel(u): u itself when no body is free
        self._x = K.create_vector() if len(problem.bodies.mass) else None
        self._z = [K.create_vector(), K.create_vector()]  # Q^T y^n, and Q^T y^{n+1} accumulated
        self._ghosts = [K.local_array(z)[K.n_owned:] for z in self._z]  # zeroed before accumulating
        self.y = np.zeros(K.n_rows)
        self.impulse = problem.create_vector()  # work vector of MEMM.impulse
        self.load = None  # dt (f - Q^T q) when constant and not zero
        self._lift = None  # (rows, values) of a constant q that is not zero
        self._parallel = problem.comm.size > 1
        d = problem.d
        mass = problem.mass.array_r
        if not np.all(mass.reshape(-1, d) == mass[::d, None]):
            raise InputError("MEMM needs the d dofs of a cell to share their mass")
        self._mass = np.ascontiguousarray(mass[::d])  # the kernel reads one mass per cell
        self._prescribed = problem.prescribed.dofs  # mass 0: the kernel leaves their velocity
        self._minv = np.ascontiguousarray(problem.inverse_mass.array_r[::d])
        body, body_mass = problem.bodies.body_of_cell, problem.bodies.mass
        self.sums = np.zeros(MOMENTA + (len(body_mass) + 1) * d if len(body_mass) else MOMENTA)
        self._body = self._slot = self._means = None
        if len(body_mass):
            self._body = np.ascontiguousarray(body, dtype=np.int32)
            self._body_mass = np.repeat(body_mass, d)
            self._means = np.zeros((len(body_mass) + 1) * d)  # mean velocity per free body; 0 for clamped
            slot = K.create_vector()  # slot of each dof in _means, ghosts included
            slot.array[:] = (self._body[:, None] * d + np.arange(d)).ravel()
            if self._parallel:
                slot.ghostUpdate(**_FORWARD)
            self._slot = K.local_array(slot).astype(np.int32)
            slot.destroy()
        # kernel arguments, once: pass[x, z] reads x (a velocity: minus its free body's mean
        # velocity) and accumulates Q^T y into z
        velocities = (self.v_prev, self.v_next)
        self._pass = {(id(x), id(z)): K.bind(x, self.y, z, self.sums,
                                             *((self._slot, self._means) if x in velocities else ()))
                      for x in (self.u, self.v_prev, self.v_next, self._x) if x is not None for z in self._z}
        self._p = {id(v): pointer(v.array) for v in (self.u, self.v_prev, self.v_next, *self._z, self.impulse)}
        self._p[id(None)] = ffi.NULL  # no impulse
        self._p_sums = pointer(self.sums)
        # f . u, the external potential's share, summed by the kernel for a constant f (not 0); a
        # time-dependent f(t) is read at t_{n+1} in ``reduce`` instead
        force = problem.data.external_force.array
        self._constant_force = bool(force.any()) and not problem.data.time_dependent
        self._cells = Struct("dem_memm_cells", n_blocks=len(self._mass), bs=d, dt=dt, c=0.5 * dt**2, mass=self._mass,
                             minv=self._minv, f=force if self._constant_force else None, body=self._body,
                             sums=self._p_sums + KINETIC, total=self._p_sums + MOMENTUM,
                             momentum=self._p_sums + MOMENTA)

    def restart(self, t0: float):
        """After u, v_prev and v_next are set: the constant loads, and y = Q rel(u) / dt by a true
        product with the local sums of t0 (reduce them with ``reduce``)."""
        problem = self.problem
        self.load = self._lift = None
        if not problem.data.time_dependent:
            load = problem.data.load(t0)
            # collective (the copy is): a load can be zero on some processes (a traction on one side)
            if problem.comm.allreduce(bool(load.array_r.any()), op=MPI.LOR):
                self.load = load.copy()
                self.load.scale(self.dt)
                self._p[id(self.load)] = pointer(self.load.array)
            rows, values = problem.data.lift(t0)
            if values.any():
                self._lift = (rows, values.copy())
        for z in self._z:
            with z.localForm() as local:
                local.set(0.0)
        self.sums.fill(0.0)
        self._pass_over_rows(refresh=True, z=self._z[0])
        M = problem.mass.array_r
        vp, vn = self.v_prev.array_r, self.v_next.array_r
        self.sums[KINETIC:EXTERNAL] = [0.125 * np.dot(M, (vp + vn) ** 2), 0.5 * np.dot(M * vp, vn)]
        d = problem.d
        self.sums[MOMENTUM : MOMENTUM + d] = 0.5 * (self._mass @ (vp + vn).reshape(-1, d))
        if self._constant_force:
            self.sums[EXTERNAL] = np.dot(problem.data.external_force.array_r, self.u.array_r)
        if self._body is not None:
            np.add.at(self.sums[MOMENTA:], self._slot[: len(vn)], M * vn)

    def destroy(self):
        """Frees the PETSc vectors (petsc4py frees a vector not on COMM_SELF only at
        ``PETSc.garbage_cleanup``): for a state that is replaced (``MEMM.rows_changed``)."""
        for v in (self.u, self.v_prev, self.v_next, self._x, *self._z, self.impulse, self.load):
            if v is not None:
                v.destroy()

    def recurrence(self) -> dict[str, np.ndarray]:
        """What the recurrence carries besides u and v (copies, this process's): the rows y^n,
        the owned entries of z^n = Q^T y^n and the free bodies' mean velocities. With them a
        restored step is bit-identical to the step that was not stopped."""
        return {"y": self.y.copy(), "z": self.rows.local_array(self._z[0])[: self.rows.n_owned].copy(),
                "means": np.zeros(0) if self._means is None else self._means.copy()}

    def restore_recurrence(self, t0: float, y: np.ndarray, z: np.ndarray, means: np.ndarray):
        """Continue from ``recurrence()`` of the same rows (the same partition), after u and v
        are set: ``restart(t0)`` for the constant loads, then the stored y, z^n and means."""
        if y.shape != self.y.shape or len(z) != self.rows.n_owned:
            raise InputError("the stored recurrence belongs to other energy rows")
        self.restart(t0)
        self.y[:] = y
        for v in self._z:
            self.rows.local_array(v)[:] = 0.0
        self.rows.local_array(self._z[0])[: self.rows.n_owned] = z
        if self._means is not None:
            self._means[:] = means

    def advance_rows(self, refresh: bool):
        """y^{n+1} from y^n and v^{n+1/2}, or (``refresh``, after u += dt v^{n+1/2}) from u^{n+1} by
        a true product; z^{n+1} = Q^T y^{n+1}. Resets the sums first."""
        self.sums.fill(0.0)
        self._pass_over_rows(refresh, self._z[1])

    def _pass_over_rows(self, refresh: bool, z: PETSc.Vec):
        x = self.problem.bodies.relative_displacement(self.u, out=self._x) if refresh else self.v_next
        if self._parallel:
            x.ghostUpdate(**_FORWARD)
        self._pass[id(x), id(z)](0.0 if refresh else 1.0, 1.0 / self.dt if refresh else 1.0)
        if self._parallel:
            z.ghostUpdate(**_REVERSE)

    def velocities(self, dofs: np.ndarray, impulse: PETSc.Vec) -> tuple[np.ndarray, ...]:
        """At the owned dofs ``dofs``, after ``advance_rows``: v^{n-1/2}, v^{n+1/2}, the v^{n+3/2}
        that ``update`` would make with ``impulse``, and the dofs' masses (contact/friction.py)."""
        z_old, z_new = self._z
        force_integral = impulse.array_r[dofs] - 0.5 * self.dt**2 * (z_old.array_r[dofs] + z_new.array_r[dofs])
        minv = self.problem.inverse_mass.array_r[dofs]
        v_prev = self.v_prev.array_r[dofs]
        return v_prev, self.v_next.array_r[dofs], v_prev + 2.0 * minv * force_integral, self.problem.mass.array_r[dofs]

    def update(self, impulse: PETSc.Vec | None, advance: bool):
        """v^{n+3/2} = v^{n-1/2} + 2 M^-1 (impulse - dt^2/2 (z^n + z^{n+1})), u += dt v^{n+1/2} if
        ``advance``; then v_prev, v_next and z^n, z^{n+1} swap roles."""
        z_old, z_new = self._z
        p = self._p
        if len(self._prescribed):  # their work over the step, -I_p . v_p^{n+1/2} (memm.py)
            q = self._prescribed
            force_integral = -0.5 * self.dt**2 * (z_old.array_r[q] + z_new.array_r[q])
            if impulse is not None:
                force_integral += impulse.array_r[q]
            self.sums[LOAD_POWER] -= self.v_next.array_r[q] @ force_integral
        lib.dem_memm_update(self._cells.c, p[id(z_old)], p[id(z_new)], p[id(impulse)], p[id(self.u)],
                            p[id(self.v_next)], p[id(self.v_prev)], 1 if advance else 0)
        self.u.stateIncrease()  # written by the kernel: PETSc's cached norms are stale
        self.v_prev.stateIncrease()
        self._ghosts[0].fill(0.0)  # z_old becomes the next accumulator, ghost entries too
        self.v_prev, self.v_next = self.v_next, self.v_prev
        self._z.reverse()
        self._ghosts.reverse()

    def reduce(self, t: float) -> np.ndarray:
        """The sums over all processes, with the lift q(t)'s share of the energies and the external
        potential's terms the kernel does not sum (f(t) . u for a time-dependent f, the tractions'
        work at u = 0); the free bodies' mean velocities for the next pass. Returns ``sums``
        (slots above)."""
        s = self.sums
        if self.problem.data.time_dependent:
            s[EXTERNAL] -= self.problem.data.external_potential(self.u, t)
            s[DATA_POTENTIAL] += self.problem.data.data_potential(self.u, t)
        else:
            s[EXTERNAL] += self.problem.data.external_constant(t)
        lift = self.problem.data.lift(t) if self.problem.data.time_dependent else self._lift
        if lift is not None:
            rows, values = lift
            lib.dem_lift_sums(len(rows), pointer(rows), pointer(values), pointer(self.y), self.dt,
                              self.rows.n_elastic, self._p_sums + LIFT_S)
        if self._parallel:
            self.problem.comm.Allreduce(MPI.IN_PLACE, s, op=MPI.SUM)
        if self._body is not None:
            n = len(self._body_mass)
            np.divide(s[MOMENTA : MOMENTA + n], self._body_mass, out=self._means[:n])  # the clamped slot stays 0
        return s
