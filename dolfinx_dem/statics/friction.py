"""Statics with Coulomb friction on rigid obstacles (2D): a tangential load applied along a path.

Friction is path dependent, so a static solution with friction is the end of a load path. The
path here is the classical one of Cattaneo and Mindlin:

1. the normal load (the problem's own data at the load time t) on *frictionless* obstacles:
   ``minimise_energy``'s solution. Classically the normal load raises no tangential traction
   (Dundurs' beta = 0); a body on a rigid plane with beta != 0 would lock some in if friction
   acted while the contact grows. The frictionless start is the classical reference state.
2. the tangential body force b, applied in n equal increments b_k = (k / n) b, each solved as
   the incremental Coulomb problem from the previous increment's solution u_{k-1}.

As in the dynamics (contact/friction.py), friction acts on the cell c of each candidate facet in
contact, along the obstacle's tangent t (the obstacles' normals lie along a coordinate axis, so
t is the other axis), and the slip is the cell's tangential displacement increment
s_c = t . (u_c - u_{k-1,c}). Its bound is mu N_c = sum of mu_f N_f over the cell's facets in
contact (N_f the normal reaction, ``RigidContact.reactions``, or the force of a facet held on a
kink). Each cell in contact is in one of two states:

    stick: s_c = 0 (its tangential dof is held at u_{k-1}), the tangential force T_c it then
           carries (the hold's reaction) satisfying |T_c| <= mu N_c;
    slip:  T_c = -sigma_c mu N_c with the slip sigma_c s_c >= 0 (sigma_c = +1 or -1: the force
           opposes the slip).

Given the states and the bounds N_c, the increment is a minimisation of the potential minus the
work of the loads and of the slip forces, with the stick dofs held: the active-set Newton of
frictionless statics (active_set.py; the obstacles' normal contact stays its active set). The
states and bounds are then updated from the solution: a stick cell whose |T_c| exceeds mu N_c
slips, its force keeping its direction (sigma_c = -sign T_c); a slip cell that moved against
its force (sigma_c s_c < 0, beyond the rounding of the increment's slips) sticks; a cell
entering contact (free in that solve) sticks if it did not move along t in the increment, else
slips against its motion; N_c is recomputed. The
iteration ends when no state changes and the bounds have settled to ``bound_rtol``: the states
and the solution then satisfy the incremental Coulomb law exactly (to those tolerances), i.e.
they are the incremental Coulomb solution. A set of states that comes back (cycling) or no
convergence in ``state_iterations`` is a StaticsError, as is an increment in which no cell
sticks (gross slip: the load exceeds the friction's capacity and the body has no static
equilibrium).

The tangential load is the body force b along the obstacles' tangent plus, per body, the couple
(a rotation field about its centroid G) that moves its line of action onto the obstacle's line:
a tangential force acting at the contact, the classical load of Cattaneo and Mindlin, which does
not roll the body (b alone acts at G, at the height n . (G - p) above the obstacle, and rolls a
disc: the contact pressure cannot hold that moment). The increments then need no constraint on
the rigid motions: the stick cells hold the tangential ones and the contact the others, so the
constraints of the normal step (``fixed_mean``, ``fixed_rotation``) are released, and the
tangential forces T_c balance the load exactly.

The states are those of each process's own facets' cells (owned): the sets stay distributed and
the result does not depend on the partition beyond rounding.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.contact.pair import PairContact
from dolfinx_dem.contact.rigid import RigidContact
from dolfinx_dem.errors import InputError, StaticsError
from dolfinx_dem.problem import DEMProblem
from dolfinx_dem.statics import StaticResult, minimise_energy
from dolfinx_dem.statics.active_set import ActiveSetNewton, Iterate
from dolfinx_dem.statics.linear import Constraints, LinearSolver, project
from dolfinx_dem.statics.pair_friction import PairFrictionResult, Pairs

__all__ = ["FrictionIncrement", "FrictionResult", "check_load_path", "load_tangentially"]

#: The slip s_c of a slip cell counts as against its force only beyond this fraction of the
#: increment's largest slip (rounding of a cell on the edge of the stick zone).
SLIP_ROUNDING = 1e-9
#: A stick cell's force may exceed mu N_c by this relative rounding before it slips.
BOUND_ROUNDING = 1e-9


@dataclasses.dataclass(frozen=True)
class FrictionIncrement:
    """One converged increment: its load factor k / n, the state iterations it took, the cells in
    contact that stick and slip (global counts), and the tangential force the obstacles exert
    (N/m), the sum of the T_c."""

    factor: float
    state_iterations: int
    stick: int
    slip: int
    friction_force: float


@dataclasses.dataclass(frozen=True)
class FrictionResult:
    """The solution at the end of the path. Per own frictional candidate facet (the contact's
    own facets with mu > 0, in their order): ``facets`` (indices into the contact's own facets),
    ``normal`` N_f and ``tangential`` T_f (N/m: the cell's T_c shared among its facets in contact
    in proportion to N_f; along the obstacle's tangent axis ``axis``), ``stick`` (bool) and
    ``slip`` (the cell's tangential displacement over the path since the normal step, m).
    ``static``: the last Newton solve, as ``minimise_energy`` reports it (its ``force`` with the
    loads, its ``energy`` the potential minus the tangential load's work - the slip forces are
    dissipative, not in it -, ``iterations`` and ``linear_iterations`` summed over the path, the
    normal step's included); ``tangential_load`` the applied load's resultant (N/m)."""

    u: PETSc.Vec
    static: StaticResult
    tangential_load: np.ndarray
    increments: list[FrictionIncrement]
    facets: np.ndarray
    normal: np.ndarray
    tangential: np.ndarray
    stick: np.ndarray
    slip: np.ndarray
    axis: int
    mu: np.ndarray


class _Cells:
    """The own frictional candidate facets of a RigidContact grouped by their (owned) cells: the
    units of friction on obstacles."""

    name = "cell"

    def __init__(self, contact: RigidContact):
        friction, comm = contact.friction, contact.comm
        self.contact = contact
        self.facets = np.flatnonzero(friction.mu > 0)
        normals = friction.normals[self.facets]
        axes = np.abs(normals).argmin(axis=1)  # the tangent axis
        if not comm.allreduce(bool((normals[np.arange(len(axes)), axes] == 0.0).all()), op=MPI.LAND):
            raise InputError("statics with friction needs obstacles whose normal lies along a coordinate axis (the "
                             "stick condition holds the cells' tangential dof)")
        lines = sorted({(tuple(n), float(n @ p)) for n, p in zip(normals, contact.points[self.facets])})
        lines = sorted(set().union(*comm.allgather(set(lines))))
        if len(lines) != 1:
            raise InputError("statics with friction takes one frictional obstacle line (the tangential load's line "
                             f"of action is moved onto it), got {len(lines)}")
        normal, offset = lines[0]
        self.normal, self.offset = np.array(normal), offset  # the line n . x = offset
        self.axis = int(np.abs(self.normal).argmin())
        self.mu = friction.mu[self.facets]
        self.cells, self.of_facet = np.unique(contact.cells[self.facets], return_inverse=True)
        self.dofs = self.cells * contact.d + self.axis  # owned, local
        self.comm = comm

    # -- the units' interface of the increments (``_increment``; pair units: pair_friction.py) -----
    def total(self, value, op=MPI.SUM):
        """``value`` reduced over the processes (the cells are distributed)."""
        return self.comm.allreduce(value, op=op)

    def start(self, dem, b: np.ndarray, u: PETSc.Vec, it: Iterate) -> tuple[np.ndarray, None]:
        """The tangential load's point (on the obstacle's line) and the bodies it loads (all)."""
        return self.offset * self.normal, None

    def hold(self, dem, stick: np.ndarray) -> Constraints:
        """The stick cells' tangential dofs held (with the prescribed bodies')."""
        held = np.union1d(dem.prescribed.dofs, self.dofs[stick])
        return Constraints([], held, self.comm.allreduce(bool(len(held)), op=MPI.LOR))

    def slips(self, u: PETSc.Vec, previous: PETSc.Vec) -> np.ndarray:
        """s_c = t . (u_c - u_{k-1,c})."""
        return u.array[self.dofs] - previous.array[self.dofs]

    def add_forces(self, out: PETSc.Vec, forces: np.ndarray) -> None:
        """out += the tangential forces T_c on the cells."""
        out.array[self.dofs] += forces

    def stick_forces(self, residual: PETSc.Vec, stick: np.ndarray) -> np.ndarray:
        """The force T_c each hold carries: minus the Lagrangian force on its dof."""
        return -residual.array[self.dofs]

    def friction_force(self, force: np.ndarray) -> float:
        """The tangential force the obstacles exert: the sum of the T_c (collective)."""
        return self.comm.allreduce(float(force.sum()), op=MPI.SUM)

    def result(self, u: PETSc.Vec, start: PETSc.Vec, states: _States, **common) -> FrictionResult:
        """The solution's figures per frictional facet (``FrictionResult``)."""
        per_cell = np.bincount(self.of_facet, states.normal, len(self.cells)).astype(float)[self.of_facet]
        share = np.divide(states.normal, per_cell, out=np.zeros_like(per_cell), where=per_cell > 0)
        return FrictionResult(u=u, **common, facets=self.facets, normal=states.normal,
                              tangential=states.force[self.of_facet] * share,
                              stick=states.stick[self.of_facet] & (states.normal > 0),
                              slip=(u.array - start.array)[self.dofs][self.of_facet], axis=self.axis, mu=self.mu)

    def bounds(self, u: PETSc.Vec, it: Iterate) -> tuple[np.ndarray, np.ndarray]:
        """(N_f of the frictional facets, mu N_c of the cells) at u with the iterate's active and
        pinned facets (collective)."""
        contact = self.contact
        active = np.zeros(contact.num_own, dtype=bool)
        active[it.active] = True
        normal = contact.reactions(u, active)
        normal[it.pinned] = contact.statics().own_values(-it.multipliers, it.pinned)[it.pinned]
        normal = np.maximum(normal[self.facets], 0.0)
        return normal, np.bincount(self.of_facet, self.mu * normal, len(self.cells)).astype(float)  # float if empty


def tangential_load(dem, b: np.ndarray, point: np.ndarray, loaded: np.ndarray | None = None) -> PETSc.Vec:
    """The cell forces of the tangential load (module docstring): vol_c (b + kappa_B (x_c - G_B)^perp)
    for each body B (each ``loaded`` one: a bool per body, default all), kappa_B J_B = -(G_B - x_O) x
    b V_B the couple that moves the resultant b V_B onto the line through x_O = ``point`` along b,
    J_B = sum vol_c |x_c - G_B|^2 (collective)."""
    geom, comm, n = dem.geometry, dem.comm, dem.n_owned
    vol, x, body = geom.cell_volumes[:n], geom.cell_centres[:n, :2], geom.cell_bodies[:n]
    sums = np.zeros((geom.num_bodies, 3))
    sums[:, 0] = np.bincount(body, vol, geom.num_bodies)
    for i in range(2):
        sums[:, 1 + i] = np.bincount(body, vol * x[:, i], geom.num_bodies)
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    centre = sums[:, 1:] / sums[:, :1]
    r = x - centre[body]
    inertia = comm.allreduce(np.bincount(body, vol * (r**2).sum(axis=1), geom.num_bodies), op=MPI.SUM)
    arm = centre - point  # G_B - x_O
    moment = arm[:, 0] * b[1] - arm[:, 1] * b[0]  # (G - x_O) x b, per unit volume
    kappa = -moment * sums[:, 0] / inertia
    out = dem.create_vector()
    perp = np.stack([-r[:, 1], r[:, 0]], axis=1)
    out.array.reshape(-1, 2)[:] = vol[:, None] * (b + kappa[body, None] * perp)
    if loaded is not None:
        out.array.reshape(-1, 2)[~loaded[body]] = 0.0
    return out


@dataclasses.dataclass
class _States:
    """The cells' states: ``stick``, ``sign`` sigma_c of the slip cells (0 otherwise), the bounds
    mu N_c (0: open), the facets' N_f and the cells' tangential forces T_c; ``piece`` the own
    candidate facets in contact at the last solution, pinned ones included (the next solve's
    start: a facet pinned on its switch has g = 0 to rounding, not g < 0)."""

    stick: np.ndarray
    sign: np.ndarray
    bound: np.ndarray
    normal: np.ndarray
    force: np.ndarray
    piece: np.ndarray

    def key(self) -> np.ndarray:
        return np.where(self.bound > 0, np.where(self.stick, 2, self.sign), 3).astype(np.int8)


def _increment(problem, model, units, previous: PETSc.Vec, u: PETSc.Vec, load: PETSc.Vec,
               states: _States, linear: LinearSolver, t: float, max_iterations: int, state_iterations: int,
               bound_rtol: float, norm0: float) -> tuple[int, Iterate, PETSc.Vec, Constraints]:
    """One increment from ``previous`` (module docstring); u and ``states`` updated in place.
    ``units``: the cells of the obstacles' candidates (``_Cells``) or the pairs between bodies
    (pair_friction.Pairs). ``norm0``: the gradient norm the Newton iteration's tolerance is
    relative to on pieces that are not quadratic (between bodies). Returns the state iterations,
    the last Newton iterate, the force of its Lagrangian with the loads (not projected: minus the
    holds' reactions) and its constraints."""
    dem = problem.dem
    history = [states.key()]
    total, residual = dem.create_vector(), dem.create_vector()
    for iteration in range(1, state_iterations + 1):
        if units.total(int(states.stick.sum())) == 0:
            raise StaticsError(f"no {units.name} in contact sticks: the tangential load exceeds the friction's "
                               "capacity (gross slip; the body has no static equilibrium)")
        constraints = units.hold(dem, states.stick)
        load.copy(total)
        units.add_forces(total, -(states.sign * states.bound))  # T = -sigma mu N on the slip units
        previous.copy(u)
        model.prepare(u)
        newton = ActiveSetNewton(problem, model, t, constraints, linear, 1e-10, True, total)
        it = newton.run(u, norm0, max_iterations, states.piece)[0]
        normal, bound = units.bounds(u, it)
        newton.lagrangian_force(u, it, residual, project_it=False)
        force = np.where(states.stick, units.stick_forces(residual, states.stick), -states.sign * states.bound)
        slip = units.slips(u, previous)
        rounding = SLIP_ROUNDING * units.total(float(np.abs(slip).max(initial=0.0)), op=MPI.MAX)
        to_slip = states.stick & (np.abs(force) > bound * (1 + BOUND_ROUNDING))
        entering = (bound > 0) & (states.bound == 0)  # free in this solve: stick if it did not move, else slip
        to_stick = (states.sign * slip < -rounding) | (entering & (np.abs(slip) <= rounding))
        to_slip |= entering & (np.abs(slip) > rounding)
        settled = units.total(float(np.abs(bound - states.bound).max(initial=0.0)), op=MPI.MAX) <= (
            bound_rtol * units.total(float(bound.max(initial=0.0)), op=MPI.MAX))
        states.sign[to_slip] = np.where(entering, np.sign(slip), -np.sign(force))[to_slip]
        states.stick[to_slip] = False
        states.stick[to_stick], states.sign[to_stick] = True, 0.0
        states.stick[bound == 0], states.sign[bound == 0] = False, 0.0
        states.bound, states.normal, states.force = bound, normal, np.where(bound > 0, force, 0.0)
        key = states.key()
        changed = not units.total(bool(np.array_equal(key, history[-1])), op=MPI.LAND)
        if not changed and settled:
            states.piece = np.union1d(it.active, it.pinned)
            return iteration, it, residual, constraints
        if changed and any(units.total(bool(np.array_equal(key, old)), op=MPI.LAND) for old in history[:-1]):
            raise StaticsError(f"the friction states cycle (state iteration {iteration}): no consistent set of "
                               "stick and slip cells was found; try more increments")
        history.append(key)
    raise StaticsError(f"the friction states did not converge in {state_iterations} iterations (bounds settled: "
                       f"{settled}); try more increments")


def check_load_path(problem: DEMProblem, body_force, increments: int):
    """An InputError unless ``problem`` and the load path (``load_tangentially``'s arguments) are
    one this module solves; (the frictional contact, the body force, its units of friction: the
    obstacles' cells, ``_Cells``, or the pairs between bodies, pair_friction.Pairs). Known at
    set-up: a scene run checks it before its output folder is written."""
    contacts = problem.contacts if isinstance(problem, DEMProblem) else []
    contact = contacts[0] if len(contacts) == 1 else None
    if not isinstance(contact, (RigidContact, PairContact)) or contact.friction is None:
        raise InputError("load_tangentially takes a DEMProblem whose only contact model is a RigidContact with "
                         "friction (an obstacle with friction > 0) or a PairContact with friction")
    if isinstance(contact, RigidContact) and contact.friction.spread is not None:  # the same on every process
        raise InputError("statics with friction on scheme B candidates (method dem-B or dem-AB) is not implemented: "
                         "their bound is the dynamics' spread normal impulse (contact/friction.py); use dem-A")
    d = problem.d
    if d != 2:
        raise InputError(f"statics with friction is implemented in 2D, this problem is {d}D")
    b = np.asarray(body_force, dtype=float)
    if b.shape != (d,) or not np.isfinite(b).all():
        raise InputError(f"the tangential body force must be {d} finite numbers, got {np.asarray(body_force).tolist()}")
    if not (isinstance(increments, (int, np.integer)) and not isinstance(increments, bool) and increments >= 1):
        raise InputError(f"the number of increments must be an integer >= 1, got {increments!r}")
    if isinstance(contact, PairContact):
        return contact, b, Pairs(contact)
    cells = _Cells(contact)
    if b @ cells.normal != 0.0:
        raise InputError(f"the tangential body force {b.tolist()} must be parallel to the obstacle (normal "
                         f"{cells.normal.tolist()}): the normal load is the problem's own")
    return contact, b, cells


def load_tangentially(problem: DEMProblem, body_force, increments: int, fixed_mean=(), fixed_rotation: bool = False,
                      rtol: float = 1e-12, max_iterations: int = 50, state_iterations: int = 50,
                      bound_rtol: float = 1e-10, t: float = 0.0) -> FrictionResult | PairFrictionResult:
    """The load path of the module docstring: the normal load (``minimise_energy`` on frictionless
    contact, with ``fixed_mean`` and ``fixed_rotation``), then the tangential load of the body
    force ``body_force`` (N/m^3: force per unit area in 2D) moved onto the obstacle's line (between
    bodies: through the centre of pressure, pair_friction.py), in ``increments`` equal increments,
    each the incremental Coulomb solution."""
    wall = time.perf_counter()
    contact, b, units = check_load_path(problem, body_force, increments)
    dem, d, comm = problem.dem, problem.d, problem.comm
    normal_step = minimise_energy(problem, fixed_mean, fixed_rotation, rtol, max_iterations, t=t,
                                  normal_step=True)
    u = normal_step.u
    start = u.copy()
    model = contact.statics()
    first = Iterate(normal_step.active, normal_step.pinned, -normal_step.kink_forces, np.zeros(0))
    unit = tangential_load(dem, b, *units.start(dem, b, u, first))
    normal, bound = units.bounds(u, first)
    states = _States(bound > 0, np.zeros(len(bound)), bound, normal, np.zeros(len(bound)),
                     np.union1d(normal_step.active, normal_step.pinned))
    load, previous = dem.create_vector(), dem.create_vector()
    linear = LinearSolver(dem, rtol)
    done, newton_iterations = [], normal_step.iterations
    try:
        for k in range(1, increments + 1):
            u.copy(previous)
            load.set(0.0)
            load.axpy(k / increments, unit)
            iterations, it, force, constraints = _increment(problem, model, units, previous, u, load, states, linear,
                                                            t, max_iterations, state_iterations, bound_rtol,
                                                            normal_step.gradient_norm_initial)
            newton_iterations += it.iterations
            done.append(FrictionIncrement(
                k / increments, iterations, units.total(int((states.stick & (states.bound > 0)).sum())),
                units.total(int((states.sign != 0).sum())), units.friction_force(states.force)))
    finally:
        linear.destroy()
    gradient = force.copy()
    project(gradient, constraints)
    in_contact = len(it.active) + len(it.pinned)
    static = StaticResult(
        u=u, iterations=newton_iterations, linear_iterations=normal_step.linear_iterations + linear.iterations,
        gradient_norm_initial=normal_step.gradient_norm_initial, gradient_norm=gradient.norm(),
        energy=problem.energies(u, t)["potential"] - load.dot(u),
        in_contact=comm.allreduce(in_contact, op=MPI.SUM) if model.local_pieces else in_contact,
        wall_time_s=time.perf_counter() - wall, active=it.active, pinned=it.pinned, kink_forces=-it.multipliers,
        force=force)
    resultant = comm.allreduce(unit.array.reshape(-1, d).sum(axis=0), op=MPI.SUM)
    return units.result(u, start, states, static=static, tangential_load=resultant, increments=done)
