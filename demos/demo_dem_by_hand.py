# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: light
#       format_version: '1.5'
#       jupytext_version: 1.13.6
# ---

# # The DEM loop by hand, next to DOLFINx finite elements
#
# This demo is implemented in a single Python file, `demo_dem_by_hand.py`. It builds a DEM
# problem from a DOLFINx mesh with the library's public API only (no scene file), drives the
# explicit MEMM time loop itself, and runs a DOLFINx P2 finite element solution of the same
# problem (implicit Newmark) side by side.
#
# This demo illustrates how to:
#
# - build a `DEMDiscretisation` on a DOLFINx mesh, with a `DirichletBC` on facets found by
#   `locate_boundary_facets`;
# - compose it into a `DEMProblem` and integrate it with `MEMM`, step by step;
# - start from a DOLFINx `Function` of the DEM's DG0 space (any DOLFINx `Function` of the mesh is
#   interpolated into it);
# - read a point value from the DEM's cellwise P1 reconstruction (`problem.gradient`);
# - write the DEM displacement with `dolfinx.io.XDMFFile` for ParaView;
# - compare with the P2 finite element solution of the same problem, and check the DEM's
#   pseudo-energy balance.
#
# It runs in serial and in parallel, e.g. `mpirun -n 2 python3 demo_dem_by_hand.py`. With the
# environment variable `DOLFINX_DEM_DEMO_QUICK=1` it runs a coarse, short version (the tests do).
#
# ## The problem
#
# A plate $\Omega = (0, L) \times (0, H)$, $L = 1$ m, $H = 0.25$ m, in plane strain, $E = 1000$ Pa,
# $\nu = 0.3$, $\rho = 1$ kg/m$^3$, is clamped at $x = 0$ and free elsewhere. It starts
# undeformed with the transverse velocity $v_0(x) = (0, -V x / L)$, $V = 0.01$ m/s, and vibrates
# freely:
#
# $$
# \rho \ddot{u} - \nabla \cdot \sigma(u) = 0 \ \text{in } \Omega, \qquad u = 0 \ \text{on } x = 0,
# \qquad \sigma n = 0 \ \text{elsewhere}, \qquad u(0) = 0, \ \dot u(0) = v_0 .
# $$
#
# Nothing damps the motion and no force does work: the energy is conserved. The DEM's MEMM
# scheme conserves a pseudo-energy exactly (to rounding); the Newmark average-acceleration
# scheme of the finite element reference conserves its own discrete energy.

# +
import os
import pathlib

import matplotlib
from mpi4py import MPI

matplotlib.use("Agg")
import dolfinx.fem  # noqa: E402
import dolfinx.io  # noqa: E402
import dolfinx.mesh  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import dolfinx_dem  # noqa: E402
from dolfinx_dem.fem.elastodynamics import FEMElastodynamics  # noqa: E402

QUICK = os.environ.get("DOLFINX_DEM_DEMO_QUICK") == "1"
comm = MPI.COMM_WORLD
L, H, E, nu, rho, V = 1.0, 0.25, 1000.0, 0.3, 1.0, 0.01
n = (20, 5) if QUICK else (40, 10)
T = 0.8 if QUICK else 3.0  # the first period is about 0.75 s
out = pathlib.Path("results") / "demo_dem_by_hand"
if comm.rank == 0:
    out.mkdir(parents=True, exist_ok=True)
# -

# ## The DEM problem, from the mesh up
#
# The mesh is a DOLFINx mesh like any other. The DEM's unknowns are the cells' displacements
# (a DG0 vector space, `dem.V`); the clamp acts on the reconstructed facet displacements, so
# it is given on facets. Scheme A reconstructs the free boundary facets by a local solve of
# $\sigma n = 0$ (paper, eq. (20)); `DEMProblem` composes the discretisation with contact models
# (none here).

# +
mesh = dolfinx.mesh.create_rectangle(comm, [[0.0, 0.0], [L, H]], n, dolfinx.mesh.CellType.triangle,
                                     diagonal=dolfinx.mesh.DiagonalType.crossed)
clamped = dolfinx_dem.locate_boundary_facets(mesh, lambda x: np.isclose(x[0], 0.0))
material = dolfinx_dem.ElasticMaterial(E=E, nu=nu, rho=rho, plane="strain")
dem = dolfinx_dem.DEMDiscretisation(mesh, material, "A", [dolfinx_dem.DirichletBC(clamped, [0.0, 0.0])])
problem = dolfinx_dem.DEMProblem(dem)
# -

# MEMM is explicit: its step must stay below the stability limit $2/\sqrt{\lambda_{\max}(M^{-1}K)}$,
# which `stable_time_step` bounds from above by a cheap guaranteed bound. We take half of it,
# rounded so that it divides $T$. The initial velocity is a DOLFINx `Function` on the DEM's DG0
# space `dem.V` (its values at the cell barycentres); `initialise` takes any `Function` of the
# mesh and interpolates it into that space.

# +
dt = T / np.ceil(T / (0.5 * dem.stable_time_step()))
stepper = dolfinx_dem.MEMM(problem, dt)
v0 = dolfinx.fem.Function(dem.V)
v0.interpolate(lambda x: np.stack([np.zeros(x.shape[1]), -V * x[0] / L]))
first = stepper.initialise(dem.create_vector(), v0)
# -

# ## A point value of the DEM solution
#
# A DEM solution is one displacement per cell; its cellwise P1 reconstruction (paper, eq. (10))
# $u_c + G_c (x - x_c)$ gives values anywhere in a cell. The tip point $(L, H/2)$ lies in cells
# owned by one process: each process proposes its nearest owned cell, the nearest wins.

# +
tip = np.array([L, 0.5 * H])
centres = dem.geometry.cell_centres[: dem.n_owned]
nearest = int(np.argmin(np.linalg.norm(centres - tip, axis=1))) if dem.n_owned else -1
distance = np.linalg.norm(centres[nearest] - tip) if dem.n_owned else np.inf
owner = comm.allreduce((distance, comm.rank), op=MPI.MINLOC)[1]


def dem_tip(t: float) -> np.ndarray:
    """The displacement at the tip point (collective: the gradient is)."""
    G = problem.gradient(stepper.u, t)
    value = np.zeros(2)
    if comm.rank == owner:
        value = stepper.u.array_r.reshape(-1, 2)[nearest] + G[nearest] @ (tip - centres[nearest])
    return comm.allreduce(value, op=MPI.SUM)
# -

# ## The time loop
#
# Each `step` advances by eq. (35a)-(35b) and returns the energies at the new time: the kinetic
# energy of the mean velocity, the elastic and stabilisation energies of eq. (11) and (13), and
# the pseudo-energy that MEMM conserves exactly. Every few steps we record the tip and write the
# displacement field (`dem.function` is the DG0 displacement as a DOLFINx `Function`).

# +
record_every = max(1, int(round(0.01 / dt)))
times, tips, pseudo, kinetic, elastic = [0.0], [dem_tip(0.0)], [first.pseudo_energy], [first.kinetic], \
    [first.elastic + first.stabilisation]
with dolfinx.io.XDMFFile(comm, out / "dem.xdmf", "w") as xdmf:
    xdmf.write_mesh(mesh)
    xdmf.write_function(dem.function(stepper.u, "displacement"), 0.0)
    while stepper.n < round(T / dt):
        diagnostics = stepper.step()
        if stepper.n % record_every == 0:
            times.append(diagnostics.t)
            tips.append(dem_tip(diagnostics.t))
            pseudo.append(diagnostics.pseudo_energy)
            kinetic.append(diagnostics.kinetic)
            elastic.append(diagnostics.elastic + diagnostics.stabilisation)
            if stepper.n % (10 * record_every) == 0:
                xdmf.write_function(dem.function(stepper.u, "displacement"), diagnostics.t)
times, tips = np.array(times), np.array(tips)
drift = np.abs(np.array(pseudo) - first.pseudo_energy).max() / first.mechanical
# -

# ## The finite element solution of the same problem
#
# `FEMElastodynamics` is a DOLFINx P2 discretisation of the same equations on the same mesh,
# integrated by the implicit Newmark average-acceleration scheme (unconditionally stable: a
# step ten times MEMM's, still small against the period).

# +
fem = FEMElastodynamics(mesh, 2, E, nu, rho, 10 * dt, clamped,
                        initial_velocity=lambda x: np.stack([np.zeros(x.shape[1]), -V * x[0] / L]))
fem_times, fem_tips = [0.0], [fem.point_values([tip])[0]]
fem_energy0 = sum(fem.energies())
while fem.t < T - 1e-12:
    fem.step()
    fem_times.append(fem.t)
    fem_tips.append(fem.point_values([tip])[0])
fem_times, fem_tips = np.array(fem_times), np.array(fem_tips)
fem_drift = abs(sum(fem.energies()) - fem_energy0) / fem_energy0
# -

# ## Side by side
#
# The tip's vertical displacement of both methods, and the DEM's energies: kinetic and elastic
# energy exchange while their sum, the pseudo-energy, stays constant.

# +
dem_on_fem_times = np.interp(fem_times, times, tips[:, 1])
difference = np.abs(dem_on_fem_times - fem_tips[:, 1]).max() / np.abs(fem_tips[:, 1]).max()
if comm.rank == 0:
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4))
    ax0.plot(times, 1e3 * tips[:, 1], label="DEM (MEMM, scheme A)")
    ax0.plot(fem_times, 1e3 * fem_tips[:, 1], "--", label="P2 FEM (Newmark)")
    ax0.set_xlabel("t (s)")
    ax0.set_ylabel("tip displacement $u_y$ (mm)")
    ax0.legend()
    ax1.plot(times, kinetic, label="kinetic")
    ax1.plot(times, elastic, label="elastic + stabilisation")
    ax1.plot(times, pseudo, label="pseudo-energy")
    ax1.set_xlabel("t (s)")
    ax1.set_ylabel("energy (J/m)")
    ax1.legend()
    fig.tight_layout()
    fig.savefig(out / "tip_and_energies.png", dpi=120)
    print(f"DEM: {stepper.n} steps of {dt:.3g} s, pseudo-energy drift {drift:.2e} of the energy; "
          f"FEM: {len(fem_times) - 1} steps, energy drift {fem_drift:.2e}; largest tip difference "
          f"{100 * difference:.1f} % of the FEM amplitude")
# -

# The DEM conserves its pseudo-energy to rounding (measured: 4.9e-15 of the energy over four
# periods), as the theory says. The tip histories agree to about 10 % of the amplitude after
# four periods (9.6 % measured on the 40 x 10 mesh, 12.4 % on the quick 20 x 5 one): the DEM's
# cellwise-constant strains make it a little softer than P2 on the same mesh, and the phase
# difference grows with time.

assert drift < 1e-12
assert fem_drift < 1e-10
assert difference < 0.15
