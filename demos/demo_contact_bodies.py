# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: light
#       format_version: '1.5'
#       jupytext_version: 1.13.6
# ---

# # Deformable bodies in contact: two disks and a billiard table
#
# This demo is implemented in a single Python file, `demo_contact_bodies.py`. It reproduces the
# multi-body examples of the DEM paper (§5.3-5.4, Figures 12 to 15): two elastic disks meeting
# head-on, and seven elastic balls rolling on a deformable billiard table.
#
# This demo illustrates how to:
#
# - run the built-in scenes `two-disks` and `billiard`, which declare a `[contact]` table: the
#   boundary facets that may touch facets of another body;
# - read the contact columns of `series.csv` (summed normal contact force, interpenetration of
#   the contact reconstructions, total momentum) and the contact figures of `summary.json`
#   (first contact time, time spent in contact work);
# - check that the MEMM scheme with contact-event splitting conserves the pseudo-energy to
#   round-off through many simultaneous contacts (Figures 13 and 15);
# - compare the scheme A contact of eq. (23)-(24) with scheme B on the two disks;
# - write an animation of the von Mises stress on the deformed bodies (`animation.gif`) next
#   to the XDMF file, which holds a `body` field for ParaView.
#
# It runs in serial and in parallel (`mpirun -n 2 python3 demo_contact_bodies.py`). With
# `DOLFINX_DEM_DEMO_QUICK=1` it runs coarse, short versions (the tests do); the full run takes a
# few minutes and writes `docs/validation/contact_bodies*`.
#
# ## The contact model (scheme B, paper §3.4.3)
#
# A boundary facet $f$ of cell $c$ follows its cell, $u_f = u_c$, until it meets a facet
# $f'$ (cell $c'$) of another body. For such a pair the common normal $n$ (the normalised
# $|f| n_f - |f'| n_{f'}$), the normal penetration $g = (u_{c'} + x_{f'} - u_c - x_f)\cdot n$
# (eq. (30)) and the overlap $w = |f \cap f'|$ of the two facets projected along $n$ define the
# contact reconstruction (eq. (31))
#
# $$
# u_f = u_c + \frac12 \sum_{f'} \frac{w}{|f|}\, \min(g, 0)\, n .
# $$
#
# It equals $u_c$ when $g = 0$ or $w = 0$, so the energy is continuous. The force is the exact
# gradient of the energy, including the sliding force $F^G$ of eq. (34) from the derivative
# of $w$. Along a time step the cells move on straight lines: $g$ and the projected facet ends
# are affine in time, the force is a cubic between the events where a gap changes sign or a facet
# end passes the end of the other facet, and a two-point Gauss rule on each piece integrates it
# exactly (§4): the pseudo-energy is conserved to round-off.

# +
import json
import os
import pathlib

import matplotlib.figure
import numpy as np
from mpi4py import MPI

from dolfinx_dem import scenes, simulation

QUICK = os.environ.get("DOLFINX_DEM_DEMO_QUICK") == "1"
comm = MPI.COMM_WORLD
out_folder = pathlib.Path("results") / "demo_contact_bodies"
docs = pathlib.Path(__file__).resolve().parent.parent / "docs" / "validation"


def run(name, overrides):
    """Run scene ``name`` with ``overrides``; returns (summary, series as a structured array)."""
    scene = scenes.load(name, overrides)
    folder = out_folder / "_".join([name] + [f"{k}={v}" for k, v in overrides.items() if k in ("mesh.h", "method")])
    summary = simulation.run(scene, folder, comm, quiet=True, overwrite=True)
    series = np.genfromtxt(folder / "series.csv", delimiter=",", names=True) if comm.rank == 0 else None
    return summary, series, folder


def energy_error(series):
    """|E^n - E^0| / max mechanical energy over the run (Figures 13 and 15)."""
    mechanical = series["kinetic"] + series["elastic"] + series["stabilisation"]
    return np.abs(series["pseudo_energy"] - series["pseudo_energy"][0]) / mechanical.max()


def plot_energy_and_force(runs, title, filename):
    """Energy error (log) and contact force against time for ``runs`` {label: series}."""
    figure = matplotlib.figure.Figure(figsize=(10, 3.6))
    ax1, ax2 = figure.subplots(1, 2)
    for label, series in runs.items():
        ax1.semilogy(series["t"], np.maximum(energy_error(series), 1e-18), label=label)
        ax2.plot(series["t"], series["contact_force"], label=label)
    ax1.set(xlabel="t (s)", ylabel="|E^n - E^0| / max E_mech", title=f"{title}: energy error")
    ax2.set(xlabel="t (s)", ylabel="summed normal contact force (N/m)", title=f"{title}: contact force")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        if len(runs) > 1:
            ax.legend()
    figure.tight_layout()
    figure.savefig(out_folder / filename, dpi=110)
# -

# ## Two disks (§5.3)
#
# Disks of radius 0.1 m, E = 100 Pa, nu = 0.2, rho = 100 kg/m^3, approaching each other at
# 0.3 m/s each; CFL 0.2. The facing halves of their boundaries are the contact boundary. The
# gap between the circles is 0.02 m, so they touch at $t = 0.02/0.6 = 0.0333$ s; the polygonal
# boundary of a mesh of size h lies inside the circle by about $h^2/(4R)$ at the facet
# centres, which delays the first contact by about $h^2/(2R \cdot 0.6)$.

# +
h_disks = [0.03] if QUICK else [0.02, 0.01, 0.005]
h_animated = h_disks[0] if QUICK else 0.01  # the animation of the finest mesh would be ~6 MB
T_disks = 0.6 if QUICK else 1.0
disks = {}
for h in h_disks:
    summary, series, folder = run("two-disks", {"mesh.h": h, "time.end": T_disks,
                                                 "output.animation": h == h_animated,
                                                 "output.every": 60 if QUICK else 40})
    disks[h] = (summary, series)
    if h == h_animated:
        folder_animated = folder
    if comm.rank == 0:
        print(f"two-disks h = {h}: {summary['n_cells']} cells, {summary['n_steps']} steps, "
              f"first contact t = {summary['first_contact_time']:.5f} s "
              f"(circles: {0.02 / 0.6:.5f}), energy error {energy_error(series).max():.2e}, "
              f"momentum change {summary['momentum_rel_change']:.1e}, "
              f"max penetration {summary['max_penetration']:.2e} m, contact "
              f"{100 * summary['contact_fraction']:.0f} % of the step, wall {summary['wall_time_s']:.1f} s")
        assert summary["pseudo_energy_rel_drift"] < 1e-12 and summary["momentum_rel_change"] < 1e-12
# -

# The contact force history shows one impact: the disks touch, are pressed together, and
# separate (the force returns to zero before the end of the run).

# +
h = h_disks[-1]
summary, series = disks[h]
if comm.rank == 0:
    t = series["t"]
    in_contact = t[series["contact_force"] > 0]
    print(f"contact from t = {in_contact.min():.4f} to {in_contact.max():.4f} s; the run ends at {t[-1]:.2f} s")
    assert in_contact.max() < t[-1]
    plot_energy_and_force({f"h = {hh}": ser for hh, (_, ser) in disks.items()}, "two disks (Fig. 13)",
                          "two_disks.png")
# -

# ## Scheme A against scheme B on the two disks
#
# With `method = "dem-A"` the free boundary facets are scheme A facets (traction-free, eq. (19)-
# (21)), and a pair of scheme A facets in contact gets the corrections of eq. (23)-(24): equal
# normal tractions and no tangential traction on both sides, the gap closed for a fully
# overlapping pair. As for scheme B, each pair's correction is weighted by its overlap
# fraction, so the energy stays continuous when facets slide (see `contact.pair.PairContact._directions`).

# +
h_ab = 0.03 if QUICK else 0.01
schemes = {}
for method in ("dem-A", "dem-B"):
    summary, series, _ = run("two-disks", {"mesh.h": h_ab, "time.end": T_disks, "method": method})
    schemes[method] = (summary, series)
if comm.rank == 0:
    for method, (s, ser) in schemes.items():
        touching = ser["t"][ser["contact_force"] > 0]
        print(f"two-disks {method}, h = {h_ab}: contact {touching.min():.4f} - {touching.max():.4f} s, "
              f"peak contact force {ser['contact_force'].max():.3f} N/m, energy error "
              f"{energy_error(ser).max():.2e}, max penetration {s['max_penetration']:.2e} m, "
              f"wall {s['wall_time_s']:.1f} s")
        assert s["pseudo_energy_rel_drift"] < 1e-12
    plot_energy_and_force({method: ser for method, (_, ser) in schemes.items()}, f"two disks, h = {h_ab}",
                          "two_disks_schemes.png")
# -

# ## Billiard (§5.4)
#
# Seven balls of radius 0.5 m on the table [2, 10] x [2, 10] m inside a deformable frame 1 m
# wide, clamped on its outer boundary; each ball moves at 0.1 m/s, along y if its centre has
# x > y, along x otherwise. Balls 1 (4, 5) and 2 (5, 4) head for the same point: they touch when
# the distance of the centres, $\sqrt2\,(1 - 0.1 t)$, is 1 m, at $t = 10 (1 - 1/\sqrt 2) = 2.93$ s.
# The paper reports the first contact at 11 s, which does not follow from the positions and
# velocities it gives; we keep the data of the paper.

# +
billiard_overrides = {"mesh.h": 0.25, "time.end": 4.0} if QUICK else {}
billiard, billiard_series, billiard_folder = run("billiard", {**billiard_overrides, "output.animation": True,
                                                              "output.every": 40 if QUICK else 100})
if comm.rank == 0:
    b = billiard
    print(f"billiard: {b['n_cells']} cells, {b['n_steps']} steps of {b['dt']:.4g} s in {b['wall_time_s']:.1f} s; "
          f"first contact t = {b['first_contact_time']:.4f} s (expected {10 * (1 - 2**-0.5):.4f}), "
          f"energy error {energy_error(billiard_series).max():.2e}, max penetration {b['max_penetration']:.2e} m, "
          f"contact work {100 * b['contact_fraction']:.1f} % of the step, list rebuilds {b['contact_list_rebuilds']}")
    assert b["pseudo_energy_rel_drift"] < 1e-12
    plot_energy_and_force({"billiard": billiard_series}, "billiard (Fig. 15)", "billiard.png")
# -

# ## Results for the documentation
#
# The full run writes the numbers and figures into `docs/validation/`.

# +
results = {
    "two_disks": {str(h): {k: s[k] for k in ("n_cells", "n_steps", "dt", "first_contact_time",
                                              "pseudo_energy_rel_drift", "momentum_rel_change",
                                              "max_penetration", "contact_fraction", "wall_time_s")}
                  for h, (s, _) in disks.items()},
    "two_disks_schemes": {m: {"max_penetration": s["max_penetration"],
                              "pseudo_energy_rel_drift": s["pseudo_energy_rel_drift"],
                              "peak_contact_force": float(ser["contact_force"].max()) if comm.rank == 0 else None,
                              "contact_interval": [float(ser["t"][ser["contact_force"] > 0].min()),
                                                   float(ser["t"][ser["contact_force"] > 0].max())]
                              if comm.rank == 0 else None,
                              "wall_time_s": s["wall_time_s"]} for m, (s, ser) in schemes.items()},
    "billiard": {k: billiard[k] for k in ("n_cells", "n_steps", "dt", "first_contact_time",
                                          "pseudo_energy_rel_drift", "max_penetration", "contact_fraction",
                                          "contact_list_rebuilds", "contact_pairs_listed", "wall_time_s",
                                          "setup_time_s")},
    "processes": comm.size,
    "quick": QUICK,
}
if comm.rank == 0 and not QUICK:
    import shutil

    (docs / "contact_bodies.json").write_text(json.dumps(results, indent=1))
    for name in ("two_disks.png", "two_disks_schemes.png", "billiard.png"):
        shutil.copy(out_folder / name, docs / f"contact_bodies_{name}")
    shutil.copy(folder_animated / "animation.gif", docs / "contact_bodies_two_disks.gif")
    shutil.copy(billiard_folder / "animation.gif", docs / "contact_bodies_billiard.gif")
    print(f"wrote {docs / 'contact_bodies.json'} and the figures")
# -
