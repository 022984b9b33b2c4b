"""The boundary data of a DEM discretisation: Dirichlet values g(t), tractions t(t) and the body
force, and what they contribute to the energy rows, the force and the potential.

The facet reconstructions are u_F = R u + D g + N t (reconstruction.py), so the energy rows are
a = Q u + q(t) with the lift q(t) = Q_D g(t) + Q_N t(t) (operators.py), and the tractions do the
work W = sum_f |f| t_f . u_f = t_w . (P u) + t_w . (D_T g + N_T t) (t_w = |f| t_f on the own
traction facets). ``BoundaryData`` keeps the lift on the few own rows the data reach, the
external force f(t) = f_body + P^T t_w and the load f(t) - Q^T q(t), evaluated once per time.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.conditions import DirichletBC, facet_values


class BoundaryData:
    """The data part of the potential of ``dem`` (a ``DEMDiscretisation``): ``dirichlet`` and
    ``tractions`` are lists of (held facets, condition), ``condition`` the Dirichlet condition of
    each Dirichlet facet, ``body_force`` the body force per owned dof (PETSc vector)."""

    def __init__(self, dem, dirichlet: list, tractions: list, condition: np.ndarray, body_force: PETSc.Vec):
        self._dem = dem
        self.comm, self.d = dem.comm, dem.d
        rec, rows = dem.reconstruction, dem.rows
        self._dirichlet, self._tractions = dirichlet, tractions
        n_own_rows = rows.num_owned
        Q_dirichlet = rows.Q_dirichlet[:n_own_rows]
        Q_traction = (rows.QF[:n_own_rows] @ rec.N).tocsc()  # the traction lift's rows
        # the own rows that the data reach (a boundary layer), and their rows of Q_D and Q_N only
        self._lift_rows = np.unique(np.concatenate([Q_dirichlet.indices, Q_traction.indices])).astype(np.int32)
        self._Q_dirichlet = Q_dirichlet[self._lift_rows].tocsr()
        self._Q_traction = Q_traction[self._lift_rows].tocsr()
        del Q_dirichlet, Q_traction
        self._q = np.zeros(len(self._lift_rows))  # q(t) on ``_lift_rows`` (zero on the other own rows)
        self._dirichlet_condition = condition  # of each Dirichlet facet
        self._setup_tractions()
        self.body_force = body_force
        self.external_force = dem.create_vector()  # f(t): the body force and the tractions' (P^T t_w)
        self._rhs = dem.create_vector()  # f(t) - Q^T q(t)
        self._lift_time = None
        self._reaction_rows = None  # made on first use (``reactions``)
        #: whether some Dirichlet or traction data depend on time (then q(t), f(t) and ``load`` do)
        self.time_dependent = any(bc.time_dependent for _, bc in self._dirichlet + self._tractions)
        self._update(0.0)

    def rebuilt(self) -> BoundaryData:
        """The same data on the discretisation's current operator (after
        ``DEMDiscretisation.replace_operator``: the lifts read its rows)."""
        return BoundaryData(self._dem, self._dirichlet, self._tractions, self._dirichlet_condition, self.body_force)

    def _setup_tractions(self):
        """The work of the tractions on the facets of the owned cells (each boundary facet counted
        once, by its cell's owner), W = sum_f |f| t_f . u_f with u_f = R_f u + D_f g + N_f t:
        W = t_w . (P u) + t_w . (D_T g + N_T t), t_w = |f| t_f, so that the force it adds is P^T t_w
        (assembled on the held dofs, summed on the owners) and the rest is a constant of u."""
        dem = self._dem
        rec, geom, d = dem.reconstruction, dem.geometry, self.d
        own = rec.traction_facets[geom.facet_cells[rec.traction_facets, 0] < dem.n_owned]
        self._own_tractions = np.searchsorted(rec.traction_facets, own)
        self._traction_weights = np.repeat(geom.facet_areas[own], d)  # |f| per own traction dof
        dofs = (own[:, None] * d + np.arange(d)).ravel()
        self._P_traction = rec.R[dofs].T  # (held dofs, own traction dofs); CSC: no pointer per held dof
        self._DN_traction = (rec.D[dofs], rec.N[dofs])
        self._traction_force = dem.factored.create_vector() if len(self._tractions) else None

    @property
    def dirichlet_conditions(self) -> tuple[DirichletBC, ...]:
        """The Dirichlet conditions, in the order of ``reactions``."""
        return tuple(bc for _, bc in self._dirichlet)

    def dirichlet_values(self, t: float) -> np.ndarray:
        """g(t) of shape (n_D, d), in the order of ``reconstruction.dirichlet_facets`` (the free
        components of a partly fixed facet are read by nothing)."""
        dem = self._dem
        return facet_values("Dirichlet", self._dirichlet, dem.reconstruction.dirichlet_facets,
                            dem.geometry.facet_centres, self.d, t)

    def traction_values(self, t: float) -> np.ndarray:
        """t(t) of shape (n_T, d), in the order of ``reconstruction.traction_facets``."""
        dem = self._dem
        return facet_values("traction", self._tractions, dem.reconstruction.traction_facets,
                            dem.geometry.facet_centres, self.d, t)

    def _update(self, t: float):
        """The boundary data at t: the lift q(t) = Q_D g(t) + Q_N t(t) of the energy rows, the
        external force f(t) = f_body + P^T t_w (``_setup_tractions``), the load f(t) - Q^T q(t)
        and this process's share of the tractions' work at u = 0."""
        if self._lift_time is not None and (not self.time_dependent or self._lift_time == t):
            return
        factored = self._dem.factored
        g, tr = self.dirichlet_values(t).ravel(), self.traction_values(t).ravel()
        self._g, self._t = g, tr
        self._q = self._Q_dirichlet @ g + self._Q_traction @ tr  # a new array: ``lift`` hands it out
        self.body_force.copy(self.external_force)
        self._traction_constant = 0.0
        if self._traction_force is not None:
            tw = self._traction_weights * tr.reshape(-1, self.d)[self._own_tractions].ravel()
            D, N = self._DN_traction
            self._traction_constant = float(tw @ (D @ g + N @ tr))
            factored.local_array(self._traction_force)[:] = self._P_traction @ tw
            self._traction_force.ghostUpdate(PETSc.InsertMode.ADD_VALUES, PETSc.ScatterMode.REVERSE)
            self.external_force.array[:] += self._traction_force.array_r
        factored.residual(None, (self._lift_rows, self._q), self._rhs)
        self._rhs.aypx(-1.0, self.external_force)
        self._lift_time = t

    def lift(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """q(t) = [s(t); j(t)], the boundary data's part of the energy rows Q w + q(t), on the local
        rows that Dirichlet values or traction lifts reach: (local row indices (int32), values); q
        is zero elsewhere."""
        self._update(t)
        return self._lift_rows, self._q

    def load(self, t: float) -> PETSc.Vec:
        """f(t) - Q^T q(t): the force at u = 0 without contact (body force, tractions and the lift),
        the owned dofs. The returned vector is this object's own: read it before the next call
        with another t. A time-dependent lift costs a Q^T product per new t."""
        self._update(t)
        return self._rhs

    def forcing(self, t: float) -> PETSc.Vec:
        """f(t) = f_body + P^T t_w, the external force (owned dofs; this object's own vector)."""
        self._update(t)
        return self.external_force

    def external_potential(self, u: PETSc.Vec, t: float) -> float:
        """This process's share of the external potential -f(t) . u - sum_f |f| t_f . (D g + N t)_f
        (owned dofs, own traction facets; sum it over ranks)."""
        self._update(t)
        return -(self.external_force.array_r @ u.array_r + self._traction_constant)

    def data_potential(self, u: PETSc.Vec, t: float) -> float:
        """This process's share of the part of V(u, t) that the data change, V - 1/2 |Q w|^2 =
        -u . L(t) + 1/2 |q(t)|^2 - sum_f |f| t_f . (D g + N t)_f, L = ``load(t)``: with it MEMM
        counts the work that time-dependent data do (memm.py)."""
        self._update(t)
        return -(self._rhs.array_r @ u.array_r) + 0.5 * (self._q @ self._q) - self._traction_constant

    def external_constant(self, t: float) -> float:
        """This process's share of the tractions' work at u = 0, sum_f |f| t_f . (D g + N t)_f: the
        part of the external potential that the external force does not carry."""
        self._update(t)
        return self._traction_constant

    def row_lift(self, rows: np.ndarray) -> np.ndarray:
        """The data's part q of the energy rows ``rows`` (indices into ``rows.Q``: any row this
        process holds), Q_D g + Q_N t at the data's current time (contact models: constant data)."""
        rows = np.asarray(rows)
        dem = self._dem
        return dem.rows.Q_dirichlet[rows] @ self._g + (dem.rows.QF[rows] @ dem.reconstruction.N) @ self._t

    def facet_lift(self, facets: np.ndarray) -> np.ndarray:
        """The data's part D g + N t of the reconstructions of the local ``facets``, (n, d), at
        the data's current time (contact models: constant data)."""
        rec, d = self._dem.reconstruction, self.d
        dofs = (np.asarray(facets)[:, None] * d + np.arange(d)).ravel()
        return (rec.D[dofs] @ self._g + rec.N[dofs] @ self._t).reshape(-1, d)

    def facet_data(self) -> tuple[np.ndarray, np.ndarray]:
        """The data at the current time, g (n_D d,) and t (n_T d,), flattened (``gradient``)."""
        return self._g, self._t

    def reactions(self, held: np.ndarray, t: float) -> np.ndarray:
        """The force each Dirichlet condition exerts on the body, (n_conditions, d), global sums,
        for the held values ``held`` of u (``DEMDiscretisation.reactions``): the exact derivative
        dV/dg = Q_D^T (Q w + q(t)) - D_T^T t_w of the potential with respect to the condition's
        imposed values, summed over its facets, from the own rows of Q (each row counted once),
        reduced over processes."""
        self._update(t)
        if self._reaction_rows is None:
            fixed = np.diff(self._Q_dirichlet.indptr) > 0  # of the lift rows
            self._reaction_rows = fixed, self._dem.rows.Q[self._lift_rows[fixed]], self._Q_dirichlet[fixed].T.tocsr()
        fixed, Q, QD_T = self._reaction_rows
        dVdg = QD_T @ (Q @ held + self._q[fixed])
        if self._traction_force is not None:
            tw = self._traction_weights * self._t.reshape(-1, self.d)[self._own_tractions].ravel()
            dVdg -= self._DN_traction[0].T @ tw
        out = np.zeros((len(self._dirichlet), self.d))
        np.add.at(out, self._dirichlet_condition, dVdg.reshape(-1, self.d))
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out
