"""Explicit P1 FEM with penalty contact against rigid half-spaces, and tractions: the solver of
method ``fem-P1`` (fem/scene_run.py).

:class:`PenaltyCentralDifference` is :class:`~dolfinx_dem.fem.elastodynamics.FEMCentralDifference`
(P1, lumped mass m, velocity Verlet) with two more terms in the force ``F - K u``:

* constant surface tractions, assembled once into the load vector ``F`` (``int t . w ds``);
* node-on-obstacle penalty contact, the scheme of explicit FEM codes: each candidate node i (a
  vertex of an obstacle's candidate facets) has the gap ``g_i = n . (x_i + u_i - p)`` to the
  half-space ``{(x - p) . n < 0}`` and receives the force ``kappa_i max(0, -g_i) n``, the gradient
  of the penalty energy ``1/2 kappa_i max(0, -g_i)^2``.

The penalty stiffness is the nodal-mass and time-step ("soft constraint") choice
``kappa_i = PENALTY_FACTOR m_i / dt^2`` (s = 1): it does not depend on E or on the mesh size, it
is a quarter of the stiffest spring a free node carries at the step of the elastic scheme (a
node on a spring of stiffness kappa is stable while ``kappa < 4 m / dt^2``), and the penetration
``p A_i dt^2 / (s m_i)`` under a contact pressure p (A_i the node's share of the contact area,
m_i ~ rho A_i h) vanishes as dt^2 / h, so the scheme converges to the Signorini condition. With
every candidate active, ``lambda_max(m^-1 (K + kappa P)) <= lambda_max(m^-1 K) + s / dt^2``
(Weyl's inequality on the symmetric ``m^-1/2 (K + kappa P) m^-1/2``), so any
``dt < dt_stable sqrt(1 - s / 4)`` is stable (0.866 dt_stable for s = 1); the solver checks the
step against SLEPc's ``lambda_max`` of ``m^-1 (K + kappa P)`` (every candidate active,
:attr:`dt_stable_contact`), and refuses a larger step.

Energy: without contact the scheme conserves ``modified_energy`` exactly; the penalty energy is
piecewise quadratic in u, so at the steps where a node enters or leaves the obstacle the
central-difference scheme makes an error in the energy: it is not conserved exactly
(docs/scenes.md gives the measured figures).

Distributed: a process computes the gaps and forces of its owned candidate nodes (the ghosts are
updated by the solver's forward scatters); the candidates are marked on every process by a
reverse scatter of its owned facets, so a node whose facets another process holds is found.
"""

from __future__ import annotations

from collections.abc import Sequence

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem import _compat
from dolfinx_dem.errors import InputError
from dolfinx_dem.fem.common import check_positive, facet_nodes, node_coordinates, owned_facets
from dolfinx_dem.fem.elastodynamics import FEMCentralDifference, _largest_eigenvalue
from dolfinx_dem.fem.pair_penalty import NodeFacetPenalty

#: s of kappa_i = s m_i / dt^2 (module docstring).
PENALTY_FACTOR = 1.0


def facet_areas(V, facets: np.ndarray) -> np.ndarray:
    """Measures of process-local facets (m^2, m in 2D, 1 for the points of a 1D mesh) from the
    coordinates of their P1 nodes (``facet_nodes``)."""
    tdim = V.mesh.topology.dim
    if tdim == 1:
        return np.ones(len(facets))
    x = node_coordinates(V)[facet_nodes(V, facets)]  # (n, tdim, gdim)
    if tdim == 2:
        return np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    return 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)


class PenaltyCentralDifference(FEMCentralDifference):
    """FEMCentralDifference with tractions and penalty contact on rigid half-spaces.

    Args:
        mesh, E, nu, rho, clamped_facets, initial_displacement, initial_velocity, plane_stress:
            As for FEMCentralDifference.
        dt: The time step (s), or a callable ``dt_stable -> dt`` of the stability limit of the
            lumped P1 scheme without contact (e.g. a fraction of it).
        body_force: Constant body force (N/m^3), shape (gdim,), or None.
        obstacles: (point, normal, facets, tolerance) per half-space: ``normal`` points from the
            obstacle into the free space, ``facets`` are the process-local candidate facets,
            ``tolerance`` (m) how far a candidate node may lie inside at t = 0.
        tractions: (facets, value) per constant traction (N/m^2), value of shape (gdim,).

    Candidate nodes on a clamped facet are held by the clamp and take no contact force.
    """

    def __init__(self, mesh, E, nu, rho, clamped_facets, dt, *, body_force=None, obstacles: Sequence = (),
                 tractions: Sequence = (), pairs: tuple | None = None, **kwargs):
        # None until made: the base computes a first acceleration before the contact exists
        self._contact = self._pairs = self._K_free = self._strain_energy = None
        # the base computes dt_stable; the step is checked below, with the contact
        super().__init__(mesh, E, nu, rho, clamped_facets, cfl=1.0, allow_unstable=True, **kwargs)
        self.dt = check_positive("dt (time step)", dt(self.dt_stable) if callable(dt) else dt)
        d = mesh.geometry.dim
        self.d = d
        self.num_obstacles = len(obstacles)
        self._loads(body_force, tractions)
        self._contact = self._candidates(obstacles) if obstacles else None
        self.dt_stable_contact = self.dt_stable
        if self._contact is not None:
            self.dt_stable_contact = self._stable_step_with_contact()
        if self.dt >= self.dt_stable_contact:
            contact = (f" with the penalty contact (kappa = {PENALTY_FACTOR:g} m_i / dt^2 on every candidate node; "
                       f"without contact {self.dt_stable:.6g} s; any dt below "
                       f"{np.sqrt(1.0 - PENALTY_FACTOR / 4.0):.3f} dt_stable is stable)" if self._contact else "")
            raise InputError(f"the time step dt = {self.dt:.6g} s is not below the stability limit "
                             f"{self.dt_stable_contact:.6g} s of lumped P1 central differences{contact}")
        if self._contact is not None:
            gaps = self._gaps()
            bad = gaps < -self._contact["tolerance"]
            worst = self.comm.allreduce(float(gaps[bad].min()) if bad.any() else np.inf, op=MPI.MIN)
            if np.isfinite(worst):
                raise InputError(f"a candidate node lies {-worst:.6g} m inside its obstacle at t = 0 (more than "
                                 "the obstacle's tolerance)")
        if pairs is not None:
            # the stable step with the obstacles' springs (every candidate active): the pairs add theirs to it
            self._pairs = NodeFacetPenalty(self.V, pairs[0], self.lumped_mass, self._held(), self.dt,
                                           self.dt_stable_contact)
            depth = self._pairs.outputs(_compat.petsc_vec(self.u))[1]
            if depth > pairs[1]:
                raise InputError(f"a candidate node lies {depth:.6g} m inside another body at t = 0 (more than "
                                 "contact.tolerance)")
        self._acceleration()

    # -- set-up ----------------------------------------------------------------------------------
    def _loads(self, body_force, tractions: Sequence) -> None:
        """The load vector ``F`` (body force and tractions, zero on the clamped rows) and
        ``F_free``, the same without the clamp (for the reactions)."""
        mesh, fdim = self.mesh, self.mesh.topology.dim - 1
        w = ufl.TestFunction(self.V)
        form = None
        if body_force is not None:
            form = ufl.inner(dolfinx.fem.Constant(mesh, np.asarray(body_force, dtype=PETSc.ScalarType)), w) * ufl.dx
        if tractions:
            facets = [np.asarray(f, dtype=np.int32) for f, _ in tractions]
            all_facets = np.concatenate(facets)
            if len(np.unique(all_facets)) != len(all_facets):
                raise InputError("traction boundaries overlap (a facet in two tractions)")
            markers = np.concatenate([np.full(len(f), k + 1, dtype=np.int32) for k, f in enumerate(facets)])
            order = np.argsort(all_facets, kind="stable")
            tags = dolfinx.mesh.meshtags(mesh, fdim, all_facets[order], markers[order])
            ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags)
            for k, (_, value) in enumerate(tractions):
                term = ufl.inner(dolfinx.fem.Constant(mesh, np.asarray(value, dtype=PETSc.ScalarType)), w) * ds(k + 1)
                form = term if form is None else form + term
        self.F_free = _compat.petsc_vec(self.u).copy()
        self.F_free.zeroEntries()
        if form is not None:
            F = dolfinx.fem.petsc.assemble_vector(dolfinx.fem.form(form))
            F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            F.copy(self.F_free)
            dolfinx.fem.petsc.set_bc(F, self._bcs)
            self._F = F

    def _candidates(self, obstacles: Sequence) -> dict:
        """The owned candidate nodes (one entry per node and obstacle) with their obstacle data."""
        mesh, V, d = self.mesh, self.V, self.d
        fdim = mesh.topology.dim - 1
        mesh.topology.create_connectivity(fdim, 0)
        marker = dolfinx.fem.Function(V)
        held = self._held()
        nodes, index, normals, points, areas = [], [], [], [], []
        for k, (point, normal, facets, _) in enumerate(obstacles):
            n = np.asarray(normal, dtype=float)
            n = n / np.linalg.norm(n)
            own = owned_facets(mesh, np.asarray(facets, dtype=np.int32))
            share = facet_areas(V, own) / mesh.topology.dim  # each vertex's share of its facet
            marker.x.array[:] = 0.0
            values = marker.x.array.reshape(-1, d)
            np.add.at(values[:, 0], facet_nodes(V, own).ravel(), np.repeat(share, mesh.topology.dim))
            vec = _compat.petsc_vec(marker)
            vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            area = vec.array_r.reshape(-1, d)[:, 0]
            mine = np.flatnonzero((area > 0) & ~held)
            nodes.append(mine)
            index.append(np.full(len(mine), k))
            normals.append(np.tile(n, (len(mine), 1)))
            points.append(np.tile(np.asarray(point, dtype=float), (len(mine), 1)))
            areas.append(area[mine])
        nodes = np.concatenate(nodes).astype(np.int32)
        x = node_coordinates(V)
        m = self.lumped_mass.array_r.reshape(-1, d)[nodes, 0]
        self.num_facets = self.comm.allreduce(sum(len(owned_facets(mesh, np.asarray(ob[2]))) for ob in obstacles))
        return {
            "nodes": nodes,
            "obstacle": np.concatenate(index),
            "normals": np.concatenate(normals).reshape(-1, d),
            "offset": np.einsum("ni,ni->n", np.concatenate(normals).reshape(-1, d),
                                x[nodes] - np.concatenate(points).reshape(-1, d)),
            "x": x[nodes],
            "areas": np.concatenate(areas),
            "kappa": PENALTY_FACTOR * m / self.dt**2,
            "tolerance": np.repeat([ob[3] for ob in obstacles], [len(a) for a in areas]),
        }

    def _held(self) -> np.ndarray:
        """Whether each owned node is clamped (it takes no contact force)."""
        n = self.V.dofmap.index_map.size_local * self.d
        held = np.zeros(n, dtype=bool)
        for bc in self._bcs:
            dofs = bc.dof_indices()[0]
            held[dofs[dofs < n]] = True  # the owned ones (not all before the count it returns in DOLFINx 0.5)
        return held.reshape(-1, self.d).any(axis=1)

    def _stable_step_with_contact(self) -> float:
        """2 / sqrt(lambda_max(m^-1 (K + kappa P))) with every candidate node in contact (SLEPc)."""
        c, d = self._contact, self.d
        Kp = self._K.copy()
        imap = self.V.dofmap.index_map
        first = imap.local_range[0]
        for i, k, n in zip(c["nodes"], c["kappa"], c["normals"]):
            rows = ((first + i) * d + np.arange(d)).astype(np.int32)
            Kp.setValues(rows, rows, (k * np.outer(n, n)).ravel(), addv=PETSc.InsertMode.ADD_VALUES)
        Kp.assemble()
        lam = _largest_eigenvalue(self.comm, Kp, self._inverse_mass)
        Kp.destroy()
        return 2.0 / np.sqrt(lam)

    def momentum(self, absolute: bool = False) -> np.ndarray:
        """The total momentum ``sum_i m_i v_i`` (of ``|m_i v_i|`` with ``absolute``), (d,), summed
        over ranks."""
        n = self.V.dofmap.index_map.size_local
        mv = (self.lumped_mass.array_r * _compat.petsc_vec(self.v).array_r[: n * self.d]).reshape(-1, self.d)
        out = np.abs(mv).sum(axis=0) if absolute else mv.sum(axis=0)
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out

    def energies(self) -> tuple[float, float]:
        """(kinetic, elastic) energy in J, summed over ranks: ``1/2 v.m v`` and the strain energy
        ``1/2 int sigma(u) : eps(u)``, equal to ``1/2 u.K u`` but summed from the strains: for a
        body far from its reference (a bar in flight) u.K u cancels terms of order K |u|^2, and
        its rounding would differ between process counts."""
        if self._strain_energy is None:
            self._strain_energy = dolfinx.fem.form(0.5 * ufl.action(ufl.action(self._k, self.u), self.u))
        v, w = _compat.petsc_vec(self.v), self._work
        w.pointwiseMult(v, self.lumped_mass)
        kinetic = 0.5 * v.dot(w)
        elastic = self.comm.allreduce(dolfinx.fem.assemble_scalar(self._strain_energy), op=MPI.SUM)
        return float(kinetic), float(elastic)

    # -- contact ---------------------------------------------------------------------------------
    def _gaps(self) -> np.ndarray:
        """g_i = n . (x_i + u_i - p) of the owned candidate entries (m)."""
        c = self._contact
        u = _compat.petsc_vec(self.u).array_r.reshape(-1, self.d)[c["nodes"]]
        return c["offset"] + np.einsum("ni,ni->n", c["normals"], u)

    def _residual(self, out: PETSc.Vec) -> PETSc.Vec:
        """``F - K u`` plus the penalty forces, zero on the clamped rows."""
        super()._residual(out)
        if self._pairs is not None:
            self._pairs.add_forces(_compat.petsc_vec(self.u), out.array.reshape(-1, self.d))
        if self._contact is not None:
            c = self._contact
            r = c["kappa"] * np.maximum(-self._gaps(), 0.0)
            f = out.array.reshape(-1, self.d)
            np.add.at(f, c["nodes"], r[:, None] * c["normals"])
        return out

    def penalty_energy(self) -> float:
        """``sum_i 1/2 kappa_i max(0, -g_i)^2`` of the obstacles plus the pairs' penalty energy
        (fem/pair_penalty.py) (J), summed over ranks."""
        energy = 0.0 if self._pairs is None else self._pairs.energy(_compat.petsc_vec(self.u))
        if self._contact is not None:
            g = np.maximum(-self._gaps(), 0.0)
            energy += float(0.5 * np.dot(self._contact["kappa"], g * g))
        return self.comm.allreduce(energy, op=MPI.SUM)

    def contact_outputs(self) -> list[float]:
        """The DEM's rigid-contact series values (contact/rigid.py ``output_columns``): the smallest
        gap, the contact pressure (total normal force over the area of the nodes in contact, each
        node's share of its candidate facets), in 1D the position of the node of smallest gap, and
        the force of each obstacle on the body. Collective."""
        c, d = self._contact, self.d
        g = self._gaps()
        r = c["kappa"] * np.maximum(-g, 0.0)
        forces = np.zeros((self.num_obstacles, d))
        np.add.at(forces, c["obstacle"], r[:, None] * c["normals"])
        sums = np.concatenate([forces.ravel(), [r.sum(), c["areas"][g < 0].sum()]])
        self.comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
        k = int(np.argmin(g)) if len(g) else -1
        u = _compat.petsc_vec(self.u).array_r.reshape(-1, d)
        best = (float(g[k]), float(c["x"][k, 0] + u[c["nodes"][k], 0])) if k >= 0 else (np.inf, np.inf)
        gap, x = min(self.comm.allgather(best))
        n = self.num_obstacles * d
        pressure = sums[n] / sums[n + 1] if sums[n + 1] > 0 else 0.0
        return [gap, pressure] + ([x] if d == 1 else []) + list(sums[:n])

    # -- reactions -------------------------------------------------------------------------------
    def reactions(self, groups: Sequence[np.ndarray]) -> np.ndarray:
        """The force each group of clamped nodes' support exerts on the body, (len(groups), d),
        summed over ranks: ``K u - F`` (without the clamp) at the group's owned nodes, the force
        that keeps them at rest. ``groups``: owned node (block) indices per Dirichlet condition."""
        d = self.d
        if self._K_free is None:
            self._K_free = dolfinx.fem.petsc.assemble_matrix(dolfinx.fem.form(self._k))
            self._K_free.assemble()
        r = self._work
        self._K_free.mult(_compat.petsc_vec(self.u), r)
        r.axpy(-1.0, self.F_free)
        rows = r.array_r.reshape(-1, d)
        out = np.array([rows[g].sum(axis=0) for g in groups]).reshape(len(groups), d)
        self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out
