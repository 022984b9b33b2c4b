# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: light
#       format_version: '1.5'
#       jupytext_version: 1.13.6
# ---

# # Cantilever beam: DEM, P2 finite elements and beam theory
#
# This demo is implemented in a single Python file, `demo_cantilever.py`. It runs the
# cell-centred Discrete Element Method (DEM) of `dolfinx_dem` next to a DOLFINx P2 finite
# element reference on the classic FEniCS cantilever, and compares both with Euler-Bernoulli
# beam theory.
#
# This demo illustrates how to:
#
# - run a built-in scene (DEM with boundary scheme A, explicit MEMM time stepping) with
#   `dolfinx_dem.simulation.run`;
# - compute the eigenfrequencies of the DEM operator, $K x = \omega^2 M x$, with SLEPc;
# - run the P2 finite element reference `FEMElastodynamics` (implicit Newmark) on the same mesh;
# - measure a static deflection and a period from an undamped tip history;
# - check the DEM against FEM and beam theory, and look at its convergence under mesh refinement.
#
# It runs in serial and in parallel, e.g. `mpirun -n 2 python3 demo_cantilever.py`. With the
# environment variable `DOLFINX_DEM_DEMO_QUICK=1` it runs a coarse, short version (the tests do).
#
# ## The problem
#
# A beam $\Omega = (0, L) \times (0, H)$, $L = 1$ m, $H = 0.1$ m, in plane strain, with
# $E = 1000$ Pa, $\nu = 0.3$, $\rho = 1$ kg/m$^3$, is clamped at $x = 0$ and free elsewhere. It
# starts at rest, and at $t = 0$ a uniform body force $f = (0, -0.1)$ N/m$^3$ is switched on:
#
# $$
# \rho \ddot{u} - \nabla \cdot \sigma(u) = f \quad \text{in } \Omega, \qquad
# \sigma(u) = \lambda\, \mathrm{tr}\, \varepsilon(u)\, I + 2 \mu\, \varepsilon(u),
# $$
#
# $$
# u = 0 \ \text{on } x = 0, \qquad \sigma n = 0 \ \text{on the other sides}, \qquad
# u(0) = \dot{u}(0) = 0 .
# $$
#
# Nothing damps the motion: the tip oscillates forever about the static deflection. Beam theory
# gives both numbers we compare. With the load per unit length $q = |f| H$, the plane-strain
# modulus $E' = E / (1 - \nu^2)$, $I = H^3/12$ and $A = H$ (per unit thickness),
#
# $$
# w_\mathrm{static} = \frac{q L^4}{8 E' I}, \qquad
# \omega_1 = 1.8751^2 \sqrt{\frac{E' I}{\rho A L^4}} .
# $$
#
# If the first mode dominates, the tip follows $w(t) \approx -w_\mathrm{static}(1 - \cos \omega_1 t)$:
# the mean of the oscillation is the static deflection, its amplitude is as large again.
# Euler-Bernoulli theory neglects shear; for $L/H = 10$ the 2D solution is expected to be about
# half a percent softer than the beam formulas.

# +
import json
import os
import pathlib
import time

import matplotlib
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

import dolfinx_dem.fem.elastodynamics as fem_elastodynamics  # noqa: E402
from dolfinx_dem import meshes, scenes, simulation, stability  # noqa: E402

comm = MPI.COMM_WORLD
# -

# ## Settings
#
# The built-in scene `cantilever` holds the problem above on a 40 x 4 "crossed" mesh (each
# rectangle cut into four triangles by its diagonals, 640 cells). The full run covers three
# periods; the quick run (`DOLFINX_DEM_DEMO_QUICK=1`) uses a 20 x 2 mesh and two periods, still
# enough for the analysis below. The DEM eigenfrequency is also computed on a sequence
# of refined meshes, which is cheap (no time stepping).

# +
QUICK = os.environ.get("DOLFINX_DEM_DEMO_QUICK") == "1"

n_cells = [20, 2] if QUICK else [40, 4]
t_end = 4.0 if QUICK else 6.0
refinements = [[20, 2], [40, 4]] if QUICK else [[20, 2], [40, 4], [80, 8], [160, 16]]

scene = scenes.load("cantilever", overrides={"mesh.n": n_cells, "time.end": t_end,
                                              "output.series_every": 10})
L, H = (np.array(scene["mesh"]["p1"]) - np.array(scene["mesh"]["p0"])).tolist()
E, nu, rho = (scene["material"][k] for k in ("E", "nu", "rho"))
body_force = np.array(scene["loads"]["body_force"])
tip_point = np.array(scene["probes"][0]["point"])  # (1, 0.05): middle of the free end

out_folder = pathlib.Path("results") / "demo_cantilever"
# -

# ## Euler-Bernoulli reference

# +
E_plane = E / (1.0 - nu**2)
I_beam, A_beam = H**3 / 12.0, H
q = abs(body_force[1]) * A_beam
static_deflection_eb = q * L**4 / (8.0 * E_plane * I_beam)
omega_eb = 1.8751**2 * np.sqrt(E_plane * I_beam / (rho * A_beam * L**4))
# -

# ## The DEM run
#
# `simulation.run` builds the DEM on the scene's mesh (cell-centred displacements $u_C$,
# reconstruction of the facet values $u_F = R u_C$, energy $\frac12 u_C^T K u_C - f^T u_C$ with
# $K = R^T A R$, lumped mass $M = \rho |c|$) and integrates with MEMM,
#
# $$
# u^{n+1} = u^n + \Delta t\, v^{n+1/2}, \qquad
# v^{n+3/2} = v^{n-1/2} + 2 M^{-1} \int_0^{\Delta t} F(u^n + \tau v^{n+1/2})\, d\tau ,
# $$
#
# with the midpoint rule (exact here: the force is affine in $\tau$) and half the stability
# limit $2 / \sqrt{\lambda_\max(M^{-1} K)}$ as time step. The probe `tip_uy` is the vertical
# displacement at $(1, 0.05)$, taken from the P1 reconstruction of the nearest cell; we record it
# every 10 steps. The run writes `series.csv`, `summary.json`, `solution.xdmf` (for ParaView)
# and `final.png` into its own folder.

# +
dem_folder = out_folder / "dem"
summary_dem = simulation.run(scene, dem_folder, comm, quiet=True, overwrite=True)
wall_dem = summary_dem["wall_time_s"]

series = None
if comm.rank == 0:
    series = np.genfromtxt(dem_folder / "series.csv", delimiter=",", names=True)
series = comm.bcast(series, root=0)
t_dem, tip_dem = series["t"], series["tip_uy"]
# -

# ## The DEM eigenfrequencies
#
# The undamped motion is a sum of the modes of $K x = \omega^2 M x$. The lumped mass is
# diagonal, so the symmetric matrix $M^{-1/2} K M^{-1/2}$ has the eigenvalues $\omega^2$.
# SLEPc finds the smallest ones by shift-and-invert around 0 (a direct LU solve, MUMPS in
# parallel), in `stability.eigenvalues`; `stable_time_step("eigenvalue")` uses its
# largest one (by default `stable_time_step()` uses a guaranteed upper bound on it instead).


# +
def dem_eigenfrequencies(dem, n=1):
    """The n lowest angular frequencies (rad/s) of M^-1 K for a DEMDiscretisation."""
    return np.sqrt(stability.eigenvalues(dem.K, dem.inverse_mass, n))


problem = simulation.build(scene, comm)  # the DEMProblem of the scene (no contact here)
dem = problem.dem
omega_dem = float(dem_eigenfrequencies(dem)[0])
# -

# As a check of the time history's mean, we also solve the static DEM problem $K u = f$ directly
# and read the tip probe the same way as during the run.

# +
F0 = dem.create_vector()
dem.force(dem.create_vector(), 0.0, F0)  # F(0) = f (the clamp is homogeneous)
u_static = dem.create_vector()
ksp = PETSc.KSP().create(comm)
ksp.setOperators(dem.K)
ksp.setType(PETSc.KSP.Type.PREONLY)
ksp.getPC().setType(PETSc.PC.Type.LU)
if PETSc.Sys.hasExternalPackage("mumps"):
    ksp.getPC().setFactorSolverType("mumps")
ksp.solve(F0, u_static)
ksp.destroy()
static_deflection_dem_solve = -float(simulation.Probes(problem, scene["probes"]).values(u_static, 0.0)[0])
# -

# ## The finite element reference
#
# The same rectangle with the same crossed mesh, P2 Lagrange displacements, consistent mass,
# and the implicit Newmark average-acceleration scheme ($\beta = 1/4$, $\gamma = 1/2$),
# unconditionally stable with a relative period error of about $(\omega \Delta t)^2 / 12$:
# with 100 steps per period that is 0.03 %. `first_eigenfrequency` solves the generalized
# eigenproblem of the P2 stiffness and mass matrices.

# +
mesh, _, facet_tags = meshes.create_rectangle(comm, scene["mesh"]["p0"], scene["mesh"]["p1"],
                                              n_cells, scene["mesh"]["diagonal"])
clamped = facet_tags.find(meshes.XMIN)
omega_fem = float(fem_elastodynamics.first_eigenfrequency(mesh, 2, E, nu, rho, clamped)[0])

dt_fem = 2.0 * np.pi / omega_fem / 100.0
tic = time.perf_counter()
fem = fem_elastodynamics.FEMElastodynamics(mesh, 2, E, nu, rho, dt_fem, clamped, body_force=body_force)
n_steps_fem = int(np.ceil(t_end / dt_fem))
t_fem, tip_fem = np.zeros(n_steps_fem + 1), np.zeros(n_steps_fem + 1)
tip_fem[0] = fem.point_values(tip_point[None, :])[0, 1]
for n in range(1, n_steps_fem + 1):
    fem.step()
    t_fem[n], tip_fem[n] = fem.t, fem.point_values(tip_point[None, :])[0, 1]
wall_fem = time.perf_counter() - tic
# -

# ## Static deflection and period from a tip history
#
# The tip history $w(t)$ of an undamped run oscillates about the static deflection. We take its
# mean over whole periods: starting from the middle of its range, find the times where $w$
# crosses its mean (linear interpolation), fit the crossing times $c_k \approx c_0 + k T/2$ to get
# the period $T$, average $w$ over the longest run of whole periods between crossings, and
# repeat with the new mean. At least three crossings (one period) are needed.


# +
def mean_and_period(t, w, iterations=3):
    """Mean over whole periods and period (s) of an oscillating history w(t)."""
    mean = 0.5 * (w.max() + w.min())
    for _ in range(iterations):
        s = w - mean
        k = np.flatnonzero(np.sign(s[:-1]) * np.sign(s[1:]) < 0)
        crossings = t[k] - s[k] * (t[k + 1] - t[k]) / (s[k + 1] - s[k])
        if len(crossings) < 3:
            raise ValueError(f"{len(crossings)} mean crossings: run at least one full period")
        period = 2.0 * np.polyfit(np.arange(len(crossings)), crossings, 1)[0]
        last = 2 * ((len(crossings) - 1) // 2)
        inside = (t >= crossings[0]) & (t <= crossings[last])
        tw = np.concatenate([[crossings[0]], t[inside], [crossings[last]]])
        ww = np.concatenate([[mean], w[inside], [mean]])
        mean = np.trapz(ww, tw) / (tw[-1] - tw[0])
    return mean, period


mean_dem, period_dem = mean_and_period(t_dem, tip_dem)
mean_fem, period_fem = mean_and_period(t_fem, tip_fem)
static_deflection_dem, static_deflection_fem = -mean_dem, -mean_fem
# -

# ## Mesh refinement
#
# The crossed 40 x 4 mesh has only four cells across the thickness. How fast does the DEM
# frequency approach the (converged) P2 value as the mesh is refined? For scale, P1 finite
# elements on the same meshes, the FEM with the same number of unknowns per vertex.

# +
omega_dem_refined, omega_p1_refined, omega_p2_refined = [], [], []
for n in refinements:
    refined = scenes.load("cantilever", overrides={"mesh.n": n})
    omega_dem_refined.append(float(dem_eigenfrequencies(simulation.build(refined, comm).dem)[0]))
    mesh_n, _, tags_n = meshes.create_rectangle(comm, scene["mesh"]["p0"], scene["mesh"]["p1"], n,
                                                scene["mesh"]["diagonal"])
    for degree, omegas in ((1, omega_p1_refined), (2, omega_p2_refined)):
        omegas.append(float(fem_elastodynamics.first_eigenfrequency(
            mesh_n, degree, E, nu, rho, tags_n.find(meshes.XMIN))[0]))
omega_dem_refined, omega_p1_refined, omega_p2_refined = (
    np.array(omega_dem_refined), np.array(omega_p1_refined), np.array(omega_p2_refined))
refinement_error = omega_dem_refined / omega_p2_refined[-1] - 1.0
refinement_error_p1 = omega_p1_refined / omega_p2_refined[-1] - 1.0
# -

# ## Comparison
#
# All relative differences are with respect to the P2 finite element values on the same mesh.

# +
numbers = {
    "quick": QUICK,
    "processes": comm.size,
    "mesh": n_cells,
    "n_cells_dem": summary_dem["n_cells"],
    "t_end": t_end,
    "dt_dem": summary_dem["dt"],
    "dt_fem": dt_fem,
    "omega_dem": omega_dem,
    "omega_fem": omega_fem,
    "omega_eb": omega_eb,
    "omega_dem_from_period": 2.0 * np.pi / period_dem,
    "omega_fem_from_period": 2.0 * np.pi / period_fem,
    "period_dem": period_dem,
    "period_fem": period_fem,
    "static_deflection_dem": static_deflection_dem,
    "static_deflection_dem_solve": static_deflection_dem_solve,
    "static_deflection_fem": static_deflection_fem,
    "static_deflection_eb": static_deflection_eb,
    "max_deflection_dem": -float(tip_dem.min()),
    "max_deflection_fem": -float(tip_fem.min()),
    "pseudo_energy_rel_drift": summary_dem["pseudo_energy_rel_drift"],
    "refinements": refinements,
    "omega_dem_refined": omega_dem_refined.tolist(),
    "omega_p1_refined": omega_p1_refined.tolist(),
    "omega_p2_refined": omega_p2_refined.tolist(),
    "wall_time_dem_s": wall_dem,
    "wall_time_fem_s": wall_fem,
}

rows = [
    ("omega_1 (rad/s), eigenvalue", omega_dem, omega_fem, omega_eb),
    ("omega_1 (rad/s), 2 pi / period", 2 * np.pi / period_dem, 2 * np.pi / period_fem, omega_eb),
    ("static deflection (m), mean", static_deflection_dem, static_deflection_fem, static_deflection_eb),
    ("static deflection (m), K u = f", static_deflection_dem_solve, static_deflection_fem,
     static_deflection_eb),
]
if comm.rank == 0:
    print(f"Cantilever, {n_cells[0]} x {n_cells[1]} crossed mesh, t_end = {t_end} s "
          f"({comm.size} process{'es' if comm.size > 1 else ''})")
    print(f"{'':32s}{'DEM':>11s}{'FEM P2':>11s}{'E-B':>11s}{'DEM/FEM-1':>11s}{'FEM/E-B-1':>11s}")
    for name, a, b, c in rows:
        print(f"{name:32s}{a:11.5g}{b:11.5g}{c:11.5g}{a / b - 1:+11.2%}{b / c - 1:+11.2%}")
    print("First eigenfrequency under refinement (relative to P2 on the finest mesh):")
    for n, w, e, w1, e1 in zip(refinements, omega_dem_refined, refinement_error, omega_p1_refined,
                               refinement_error_p1):
        print(f"  {n[0]:4d} x {n[1]:<3d} DEM {w:.5f} ({e:+.2%})   FEM P1 {w1:.5f} ({e1:+.2%})")
    print(f"Wall time: DEM {wall_dem:.1f} s ({summary_dem['n_steps']} steps), "
          f"FEM {wall_fem:.1f} s ({n_steps_fem} steps)")
# -

# The figure shows both tip histories with their means and the beam-theory deflection, and the
# convergence of the DEM and P1 frequencies. The DEM history also carries higher modes (the wiggles):
# neither scheme damps them.

# +
if comm.rank == 0:
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [2, 1]})
    ax0.plot(t_dem, tip_dem, label=f"DEM, MEMM ($\\Delta t$ = {summary_dem['dt']:.2g} s)")
    ax0.plot(t_fem, tip_fem, "--", label=f"FEM P2, Newmark ($\\Delta t$ = {dt_fem:.2g} s)")
    ax0.axhline(mean_dem, color="C0", lw=0.8, ls=":", label="DEM mean")
    ax0.axhline(mean_fem, color="C1", lw=0.8, ls=":", label="FEM mean")
    ax0.axhline(-static_deflection_eb, color="k", lw=0.8, label="Euler-Bernoulli static")
    ax0.set(xlabel="t (s)", ylabel="tip displacement $u_y(1, 0.05)$ (m)",
            title=f"Cantilever tip, {n_cells[0]} x {n_cells[1]} crossed mesh")
    ax0.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=3)
    cells_across = np.array([n[1] for n in refinements])
    ax1.loglog(cells_across, np.abs(refinement_error), "o-", label="DEM (below P2)")
    ax1.loglog(cells_across, np.abs(refinement_error_p1), "s-", label="FEM P1 (above P2)")
    ax1.loglog(cells_across, np.abs(refinement_error[0]) * (cells_across / cells_across[0]) ** -2.0,
               "k:", label="slope -2")
    ax1.set(xlabel="cells across the thickness", ylabel="|$\\omega/\\omega_{P2}$ - 1|, P2 on the finest mesh",
            title="First eigenfrequency")
    ax1.set_xticks(cells_across, [str(c) for c in cells_across])
    ax1.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax1.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_folder / "cantilever_tip.png", dpi=120)
    with open(out_folder / "cantilever.json", "w") as f:
        json.dump(numbers, f, indent=2)
    if not QUICK:
        validation = pathlib.Path(__file__).resolve().parent.parent / "docs" / "validation"
        validation.mkdir(parents=True, exist_ok=True)
        fig.savefig(validation / "cantilever.png", dpi=120)
        with open(validation / "cantilever.json", "w") as f:
            json.dump(numbers, f, indent=2)
    plt.close(fig)
# -

# ## What we see
#
# - The P2 reference is converged on this mesh (its frequency changes by 0.03 % from 40 x 4 to
#   160 x 16) and sits half a percent below Euler-Bernoulli, which neglects shear; its static
#   deflection is half a percent above.
# - The DEM is softer than P2: on the 40 x 4 crossed mesh its first frequency is about 2 % lower
#   and its static deflection about 4 % larger. The two numbers are one error: the lumped mass is
#   exact, so $\omega^2 w_\mathrm{static}$ agrees with P2's to a fraction of a percent. The error
#   falls with the square of the mesh size (-8 %, -2 %, -0.5 %, -0.14 %), mirror image of P1's
#   (+8 %, +2 %, ...), which is stiffer than P2 (bending locking).
# - The mean of the DEM oscillation is the DEM's static solution, and its period is
#   $2\pi/\omega_\mathrm{DEM}$ to within 0.1-0.2 %: the explicit MEMM run (tens of thousands of
#   steps, pseudo-energy conserved to round-off) adds no visible error of its own.
# - The DEM history carries higher modes (small wiggles near the turning points) that the
#   Newmark run with 100 steps per first period resolves less well; neither scheme damps them.
