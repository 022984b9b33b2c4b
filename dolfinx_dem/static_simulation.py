"""Run a static scene (a ``statics`` table): DEM energy minimisation, or the DOLFINx P2 FEM
reference for the Hertz disc (method ``fem-P2``). Same output contract as a dynamic run, with one
state at t = 0, plus ``contact_pressure.csv`` (facet or boundary positions and pressures) and the
summary keys ``contact_half_width``, ``contact_half_width_last``, ``top_vertical_displacement``,
``max_contact_pressure``, ``h`` and ``iterations``.

The contact half-width is the a of the Hertz profile fitted to the pressures (hertz.py), which
resolves the edge of the contact zone below the mesh size; ``contact_half_width_last`` is the
largest |x| of a facet in contact, for comparison.
"""

from __future__ import annotations

import pathlib
import time
from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from dolfinx_dem import hertz, io, plotting, scenes, simulation
from dolfinx_dem.statics import minimise_energy


def _top_point(dem) -> list[float]:
    """The highest vertex of the body (largest last coordinate, then smallest |x|): the point
    whose vertical displacement the summary reports."""
    x = np.unique(dem.geometry.cell_vertices.reshape(-1, dem.d), axis=0)
    top = x[:, -1] >= x[:, -1].max() - 1e-12 * np.ptp(x[:, -1])
    candidates = x[top]
    return candidates[np.argmin(np.abs(candidates[:, 0] - np.median(x[:, 0])))].tolist()


def _write_pressure(path: pathlib.Path, comm, x: np.ndarray, p: np.ndarray):
    if comm.rank == 0:
        order = np.argsort(x[:, 0])
        header = ",".join([f"x{i}" for i in range(x.shape[1])] + ["pressure"])
        np.savetxt(path, np.c_[x[order], p[order]], delimiter=",", header=header, comments="", fmt="%.17g")


def run_static(scene: Mapping, out, comm: MPI.Comm = MPI.COMM_WORLD) -> dict:
    """Solve a static scene and write its outputs into ``out``; returns the summary."""
    if scene["method"] == "fem-P2":
        from dolfinx_dem.fem.hertz_scene import run_fem_hertz

        return run_fem_hertz(scene, out, comm)
    wall = time.perf_counter()
    with io.OutputDirectory(out, comm) as directory:
        dem = simulation.build(scene, comm)
        options = scene["statics"]
        result = minimise_energy(dem, options.get("fixed_mean", ()), options.get("fixed_rotation", False),
                                 options.get("rtol", 1e-12))
        u = result.u
        top = simulation.Probes(dem, [{"name": "top", "point": _top_point(dem), "component": dem.d - 1}])
        probes = simulation.Probes(dem, scene.get("probes", []))
        energies = dem.energies(u, 0.0)
        columns = simulation.SERIES_COLUMNS + simulation.contact_columns(dem) + tuple(probes.names)
        with io.SeriesWriter(comm, directory / "series.csv", columns) as series:
            series.write([0.0, 0.0, energies["elastic"], energies["stabilisation"], energies["external"],
                          sum(energies.values()), *simulation.contact_values(dem, u), *probes.values(u, 0.0)])
        with io.SolutionWriter(comm, directory, dem.mesh) as solution:
            solution.write(0.0, {"displacement": dem.function(u, "displacement"),
                                 "von_mises": dem.scalar_function(dem.von_mises(u, 0.0), "von_mises")})
        summary = {
            "scene": scene["name"],
            "method": scene["method"],
            "analysis": "static",
            "n_cells": dem.geometry.num_cells,
            "h": scene["mesh"].get("h", float(dem.geometry.facet_diameters.max())),
            "iterations": result.iterations,
            "linear_iterations": result.linear_iterations,
            "gradient_norm_reduction": result.gradient_reduction,
            "top_vertical_displacement": float(top.values(u, 0.0)[0]),
            "processes": comm.size,
        }
        if dem.contact is not None:
            c = dem.contact
            up = c.patch_values(u)
            pressure = c.reaction_pressures(up)
            x = dem.geometry.facet_centres[c.facets]
            _write_pressure(directory / "contact_pressure.csv", comm, x, pressure)
            touching = pressure > 0
            centre = x[touching, 0].mean() if touching.any() else 0.0
            summary["max_contact_pressure"] = float(pressure.max())
            summary["contact_half_width_last"] = float(np.abs(x[touching, 0] - centre).max()) if touching.any() else 0.0
            summary["contact_facets"] = int(touching.sum())
            summary["contact_force"] = float((pressure * dem.geometry.facet_areas[c.facets]).sum())
            if dem.d == 2 and touching.sum() >= 3:
                a, p0 = hertz.fit_hertz_profile(x[:, 0] - centre, pressure)
                summary["contact_half_width"], summary["fitted_max_pressure"] = a, p0
        plotting.plot_cell_field(dem.mesh, u.array_r.reshape(-1, dem.d), dem.von_mises(u, 0.0),
                                 directory / "final.png", "von Mises stress (Pa)",
                                 scene.get("output", {}).get("picture_scale", 1.0))
        summary["wall_time_s"] = time.perf_counter() - wall
        io.write_summary(directory / "summary.json", comm, summary)
    return summary
