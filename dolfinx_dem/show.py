"""The pictures of ``dolfinx-dem show DIR``: what a run folder's ``series.csv`` (and, for a static
run with contact, ``contact_pressure.csv``) says, in panels with units.

- ``energies.png`` (dynamic runs): kinetic, elastic, stabilisation and external energies, and the
  pseudo-energy as its drift |P^n - P^0| over the run's largest mechanical energy (what the method
  conserves: the raw P^n is a flat line), or the energy balance's for a run whose data do work;
- ``series.png``: every other column (contact forces, gaps, penetration, reactions, momenta,
  probes, ...) against t, each with its unit;
- ``force_displacement.png``: for each prescribed body, its reaction against its displacement
  along the direction it moves most (the force-indentation curve of ``indentation``);
- ``pressure.png`` (static runs with obstacles): the facets' contact pressure against position,
  with the semi-ellipse of the fitted Hertz half-width and peak when the run has them.

Matplotlib on its Agg canvas; serial (rank 0 of the command).
"""

from __future__ import annotations

import pathlib

import matplotlib.figure
import numpy as np

from dolfinx_dem.errors import InputError, MissingFileError

ENERGIES = ("kinetic", "elastic", "stabilisation", "external")
#: Energies per unit thickness in 2D, per unit cross-section in 1D.
ENERGY_UNIT = "J"


def unit(column: str) -> str:
    """The unit of a series column (forces per unit thickness in 2D)."""
    if column in ENERGIES or column in ("pseudo_energy", "work", "balance"):
        return ENERGY_UNIT
    if column.startswith(("contact_force", "reaction_")):
        return "N"
    if column == "contact_pressure":
        return "Pa"
    if column.startswith("momentum_"):
        return "kg m/s"
    return "m"  # gaps, penetration, positions, displacements and the probes (displacement components)


def read_series(path: pathlib.Path) -> tuple[list[str], np.ndarray]:
    """The header and rows of a ``series.csv``."""
    if not path.is_file():
        raise MissingFileError(f"series file {path} does not exist")
    with open(path) as f:
        header = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if data.shape[0] == 0 or header[0] != "t":
        raise InputError(f"{path} holds no rows, or its first column is not t")
    return header, data


def plot_panels(panels: list[tuple[str, str, np.ndarray, np.ndarray]], filename: pathlib.Path,
                title: str = "") -> str:
    """One axes per (x label, y label, x, y) of ``panels``, stacked; returns ``str(filename)``."""
    if not panels:
        raise InputError("nothing to plot")
    figure = matplotlib.figure.Figure(figsize=(7.0, 0.8 + 2.2 * len(panels)))
    axes = figure.subplots(len(panels), 1, squeeze=False)[:, 0]
    for ax, (xlabel, ylabel, x, y) in zip(axes, panels):
        ax.plot(x, y, marker="." if len(x) < 30 else None)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    if title:
        figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(str(filename), dpi=120)
    return str(filename)


def _label(column: str) -> str:
    return f"{column.replace('_', ' ')} ({unit(column)})"


def write_pictures(directory: pathlib.Path, summary: dict | None) -> list[str]:
    """The pictures of the module docstring that the run folder ``directory`` has data for."""
    header, data = read_series(directory / "series.csv")
    column = {name: data[:, k] for k, name in enumerate(header)}
    t, static = column["t"], (summary or {}).get("analysis") == "static"
    scene = (summary or {}).get("scene", directory.name)
    written = []
    if not static and all(e in column for e in ENERGIES):
        mechanical = column["kinetic"] + column["elastic"] + column["stabilisation"]
        scale = max(np.abs(mechanical).max(), 1e-300)
        kept = "balance" if "balance" in column else "pseudo_energy"
        drift = np.abs(column[kept] - column[kept][0]) / scale
        panels = [("t (s)", _label(e), t, column[e]) for e in ENERGIES]
        panels.append(("t (s)", f"{kept.replace('_', ' ')} drift / max mechanical energy", t, drift))
        written.append(plot_panels(panels, directory / "energies.png",
                                   f"{scene}: energies (per unit thickness in 2D)"))
    others = [c for c in header[1:] if c not in (*ENERGIES, "pseudo_energy", "work", "balance")]
    if others and not static:
        written.append(plot_panels([("t (s)", _label(c), t, column[c]) for c in others], directory / "series.png",
                                   f"{scene}: series (forces per unit thickness in 2D)"))
    bodies = [c[len("prescribed_"):-len("_displacement_x")] for c in header if c.endswith("_displacement_x")
              and c.startswith("prescribed_")]
    panels = []
    for name in bodies:
        axes = [a for a in "xyz" if f"prescribed_{name}_displacement_{a}" in column]
        along = max(axes, key=lambda a: np.ptp(column[f"prescribed_{name}_displacement_{a}"]))
        x, f = column[f"prescribed_{name}_displacement_{along}"], column[f"reaction_{name}_{along}"]
        panels.append((f"{name} displacement {along} (m)", f"reaction {name} {along} (N)", x, f))
    if panels and (not static or len(t) > 1):
        written.append(plot_panels(panels, directory / "force_displacement.png",
                                   f"{scene}: force against displacement of the prescribed bodies"))
    pressure = directory / "contact_pressure.csv"
    if static and pressure.is_file():
        p = np.loadtxt(pressure, delimiter=",", skiprows=1, ndmin=2)
        x = p[:, 0] if p.shape[1] == 3 else np.hypot(p[:, 0], p[:, 1])  # 2D: x; 3D: the distance from the axis
        order = np.argsort(x)
        panels = [("x (m)" if p.shape[1] == 3 else "r (m)", "contact pressure (Pa)", x[order], p[order, -1])]
        written.append(_pressure_picture(panels, summary, directory / "pressure.png", scene))
    return written


def _pressure_picture(panels, summary: dict, filename: pathlib.Path, scene: str) -> str:
    """The pressure panel with the fitted Hertz semi-ellipse p0 sqrt(1 - x^2 / a^2), if fitted."""
    (xlabel, ylabel, x, p), = panels
    figure = matplotlib.figure.Figure(figsize=(7.0, 3.5))
    ax = figure.subplots()
    ax.plot(x, p, ".", label="DEM facets")
    a, p0 = summary.get("contact_half_width_fit"), summary.get("fitted_max_pressure")
    if a and p0:
        s = np.linspace(-a, a, 201) if x.min() < 0 else np.linspace(0.0, a, 101)
        ellipse = p0 * np.sqrt(np.clip(1 - (s / a) ** 2, 0.0, None))
        ax.plot(s, ellipse, label=f"Hertz fit: a = {a:.4g} m, p0 = {p0:.4g} Pa")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend()
    figure.suptitle(f"{scene}: contact pressure")
    figure.tight_layout()
    figure.savefig(str(filename), dpi=120)
    return str(filename)
