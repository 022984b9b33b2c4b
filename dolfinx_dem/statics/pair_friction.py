"""Statics with Coulomb friction between bodies (2D): the pairs, units of friction.py's load path.

The load path, the stick and slip states and their iteration are those of friction.py (the
obstacles'); here the unit of friction is a pair p of candidate facets (facet i of cell c, facet
j of cell c', ``PairContact.pair_keys``), as in the dynamics (contact/pair_friction.py). Its
tangent t_p is the pair's (the common normal's plane), its slip the increment of its cells'
relative tangential displacement and its tangential force acts on both cells:

    s_p = w_p . (u - u_{k-1}),   w_p: t_p on the dofs of c, -t_p on those of c',
    force T_p w_p (T_p t_p on c, -T_p t_p on c': the total force is unchanged),

its bound mu N_p, N_p the pair's normal force in contact (``PairStatics.pinned_values``' reaction
on the piece, or a pinned pair's multiplier). A stick pair holds w_p . d = 0 for the steps d of
the increment: a linear constraint coupling two cells, which the Krylov solve of statics imposes
with the rigid modes' machinery (linear.py: the stick pairs' w_p orthonormalised are its
normals; a dependent set, a cycle of stick pairs, is a StaticsError). The forces the holds carry
are T = -G^-1 W^T r (W the stick pairs' w_p, G = W^T W, r the Lagrangian force with the loads:
at the solution it lies in their span).

The units are the pairs that face each other (listed with a positive overlap) at the end of the
normal step, by their keys, the same on every process like the pieces of contact between bodies
(pair_statics.py): the states iterate identically everywhere from reduced values. A pair that
comes into contact during the tangential load without facing another after the normal step is a
StaticsError.

The tangential load is the body force b on the bodies with candidate facets that neither a
Dirichlet condition nor a prescribed motion holds (those carry it through their conditions, as the
clamped block of Cattaneo and Mindlin's half-plane), each with the couple that moves its line of
action through the normal step's centre of pressure X = sum N_p x_p / sum N_p (x_p the midpoint
of the pair's facets' centres): a tangential force at the contact. b must be tangential there:
|b . n_X| <= ``TANGENTIAL`` |b|, n_X the direction of sum N_p n_p (the pairs' normals follow the
facets, so n_X is the interface's only to the mesh's symmetry).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx_dem.errors import InputError, StateError, StaticsError
from dolfinx_dem.statics.active_set import Iterate
from dolfinx_dem.statics.linear import Constraints, held_bodies

#: The largest |b . n_X| / |b| of a tangential load (module docstring).
TANGENTIAL = 1e-2
#: Stick pairs whose Gram matrix has an eigenvalue below this fraction of its largest are dependent.
DEPENDENT = 1e-10


@dataclasses.dataclass(frozen=True)
class PairFrictionResult:
    """The solution at the end of the path between bodies (as friction.FrictionResult for
    obstacles). Per pair of the units (the same on every process, by their ``keys``):
    ``positions`` x_p, ``normals`` n_p, ``tangents`` t_p, ``normal`` N_p and ``tangential`` T_p
    (N/m: the force on the cell of facet i along t_p), ``stick`` (bool, in contact), ``slip``
    (s_p over the path since the normal step, m), and ``side`` (+1 where facet i's body takes the
    load, -1 where facet j's does, 0 otherwise); ``centre`` the normal step's centre of pressure X
    and ``direction`` the load's; ``loaded`` whether each body takes the load."""

    u: PETSc.Vec
    static: object  # statics.StaticResult
    tangential_load: np.ndarray
    increments: list
    keys: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    normal: np.ndarray
    tangential: np.ndarray
    stick: np.ndarray
    slip: np.ndarray
    side: np.ndarray
    centre: np.ndarray
    direction: np.ndarray
    loaded: np.ndarray
    mu: float


def _dots(vectors: list[PETSc.Vec], x: PETSc.Vec, comm) -> np.ndarray:
    """[w . x for w in vectors] with one reduction."""
    out = np.array([w.array_r @ x.array_r for w in vectors])
    comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
    return out


class Pairs:
    """The frictional pairs of a PairContact with friction (module docstring); ``start`` makes
    them from the normal step's solution."""

    name = "pair"

    def __init__(self, contact):
        self.contact, self.comm = contact, contact.comm
        self.mu = contact.friction.mu

    def total(self, value, op=MPI.SUM):
        """``value`` itself: the pairs' states are the same on every process."""
        return value

    def start(self, dem, b: np.ndarray, u: PETSc.Vec, it: Iterate) -> tuple[np.ndarray, np.ndarray]:
        """The units at the normal step's solution u (the facing pairs, their w_p); the tangential
        load's point X and the bodies it loads (``friction.tangential_load``; collective)."""
        pc, comm = self.contact, self.comm
        model = pc.statics()
        model.prepare(u)
        up = pc.patch_values(u)
        self.keys = model.touching_pairs(up, np.inf)  # the facing pairs (w > 0), sorted, everywhere
        L, F = pc.listed, pc.facets_all
        at = np.searchsorted(self.keys, pc.pair_keys())
        mine = (L.i < pc.num_own) & (at < len(self.keys))
        mine[mine] = self.keys[at[mine]] == pc.pair_keys()[mine]
        k, p = at[mine], np.flatnonzero(mine)
        t = L.t[p, 0]
        self.vectors = [dem.create_vector() for _ in self.keys]
        ci, cj = F.cell_dof[L.i[p]], F.cell_dof[L.j[p]]
        #: this process's pairs' w_p as (their indices, global dofs (m, 4), values (m, 4))
        self.rows = (k, np.stack([ci, ci + 1, cj, cj + 1], axis=1).astype(PETSc.IntType),
                     np.concatenate([t, -t], axis=1))
        for kk, dofs, values in zip(*self.rows):
            self.vectors[kk].setValues(dofs, values, addv=PETSc.InsertMode.ADD_VALUES)
        for w in self.vectors:
            w.assemble()
        # per pair: its normal, its position, and whether facet i's body takes the load (+1) or j's (-1)
        loaded = ~held_bodies(dem)
        geo = np.zeros((len(self.keys), 7))
        geo[k, 0:2], geo[k, 2:4] = L.n[p], t
        geo[k, 4:6] = 0.5 * (F.centre[L.i[p]] + F.centre[L.j[p]])
        geo[k, 6] = loaded[F.body[L.i[p]]].astype(float) - loaded[F.body[L.j[p]]]
        comm.Allreduce(MPI.IN_PLACE, geo, op=MPI.SUM)
        self.normals, self.tangents, self.positions, self.side = geo[:, 0:2], geo[:, 2:4], geo[:, 4:6], geo[:, 6]
        bodies = np.zeros(len(loaded), dtype=np.int64)  # the bodies of the facing pairs
        bodies[F.body[L.i[p]]] = 1
        bodies[F.body[L.j[p]]] = 1
        comm.Allreduce(MPI.IN_PLACE, bodies, op=MPI.MAX)
        self.loaded = bodies = (bodies == 1) & loaded
        if not bodies.any():
            raise InputError("statics with friction between bodies: every body in contact is held by a Dirichlet "
                             "condition or a prescribed motion, so no body takes the tangential load")
        N = np.maximum(self.bounds(u, it)[0], 0.0)
        if N.sum() == 0.0:
            raise StaticsError("statics with friction between bodies: no pair is in contact after the normal load")
        n_x = N @ self.normals
        n_x /= np.linalg.norm(n_x)
        if abs(b @ n_x) > TANGENTIAL * np.linalg.norm(b):
            raise InputError(f"the tangential body force {b.tolist()} must be parallel to the contact interface: its "
                             f"normal at the centre of pressure is {n_x.tolist()} (|b . n| / |b| = "
                             f"{abs(b @ n_x) / np.linalg.norm(b):.3g} > {TANGENTIAL:g}); the normal load is the "
                             "problem's own")
        self.direction = b / np.linalg.norm(b) if b.any() else np.zeros(2)
        self.centre = N @ self.positions / N.sum()
        return self.centre, bodies

    def hold(self, dem, stick: np.ndarray) -> Constraints:
        """The stick pairs' constraints w_p . d = 0, orthonormalised (with the prescribed bodies'
        dofs held)."""
        W = [self.vectors[k] for k in np.flatnonzero(stick)]
        self._held = (stick.copy(), gram := self._gram(W))  # stick_forces' Gram matrix: the same stick set
        values, vectors = np.linalg.eigh(gram)
        if len(values) and values[0] <= DEPENDENT * values[-1]:
            raise StaticsError(f"the {len(W)} stick pairs' constraints are dependent (a cycle of stick pairs between "
                               "the same cells): their forces are not determined")
        normals = []
        for column, value in zip(vectors.T, values):
            q = dem.create_vector()
            q.maxpy(column / np.sqrt(value), W)
            normals.append(q)
        mine = stick[self.rows[0]]
        return Constraints(normals, dem.prescribed.dofs, bool(dem.prescribed),
                           rows=(self.rows[1][mine], self.rows[2][mine]))

    def _gram(self, W: list[PETSc.Vec]) -> np.ndarray:
        gram = np.array([[w.array_r @ v.array_r for v in W] for w in W]).reshape(len(W), len(W))
        self.comm.Allreduce(MPI.IN_PLACE, gram, op=MPI.SUM)
        return gram

    def slips(self, u: PETSc.Vec, previous: PETSc.Vec) -> np.ndarray:
        """s_p = w_p . (u - u_{k-1})."""
        change = u.copy()
        change.axpy(-1.0, previous)
        return _dots(self.vectors, change, self.comm)

    def add_forces(self, out: PETSc.Vec, forces: np.ndarray) -> None:
        """out += sum_p T_p w_p."""
        if len(forces):
            out.maxpy(forces, self.vectors)

    def stick_forces(self, residual: PETSc.Vec, stick: np.ndarray) -> np.ndarray:
        """T = -G^-1 W^T r on the stick pairs (module docstring), 0 on the others; ``stick`` is the
        set of the last ``hold``, whose G it reuses."""
        held, gram = self._held
        if not np.array_equal(held, stick):
            raise StateError("stick_forces takes the stick pairs of the last hold")
        out = np.zeros(len(self.keys))
        W = [self.vectors[k] for k in np.flatnonzero(stick)]
        if W:
            out[stick] = -np.linalg.solve(gram, _dots(W, residual, self.comm))
        return out

    def bounds(self, u: PETSc.Vec, it: Iterate) -> tuple[np.ndarray, np.ndarray]:
        """(N_p, mu N_p) of the pairs at u with the iterate's piece and pinned pairs (collective)."""
        zone = np.union1d(it.active, it.pinned)
        if not np.isin(zone, self.keys).all():
            raise StaticsError("a pair came into contact under the tangential load that did not face another after "
                               "the normal load: statics with friction between bodies keeps the pairs of the normal "
                               "step (try a smaller tangential load or more increments)")
        reaction = self.contact.statics().pinned_values(self.contact.patch_values(u), it.active, self.keys)[1]
        normal = np.where(np.isin(self.keys, it.active), reaction, 0.0)
        normal[np.searchsorted(self.keys, it.pinned)] = -np.asarray(it.multipliers)
        normal = np.maximum(normal, 0.0)
        return normal, self.mu * normal

    def friction_force(self, force: np.ndarray) -> float:
        """The tangential force on the loaded bodies along the load's direction."""
        return float((force * self.side) @ (self.tangents @ self.direction))

    def result(self, u: PETSc.Vec, start: PETSc.Vec, states, **common) -> PairFrictionResult:
        """The solution's figures per pair (``PairFrictionResult``)."""
        return PairFrictionResult(u=u, **common, keys=self.keys, positions=self.positions, normals=self.normals,
                                  tangents=self.tangents, normal=states.normal, tangential=states.force,
                                  stick=states.stick & (states.normal > 0), slip=self.slips(u, start), side=self.side,
                                  centre=self.centre, direction=self.direction, loaded=self.loaded, mu=self.mu)
