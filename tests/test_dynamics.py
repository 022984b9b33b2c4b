"""A dynamic run (dynamics.py): the time step from the stability bound or the eigenvalue, a run
that stops on instability with its outputs marked, and the energy balance of a moving boundary."""

import json
import pathlib
import sys

import numpy as np
import pytest
from helpers import run_command
from mpi4py import MPI

from dolfinx_dem import io, scenes, simulation
from dolfinx_dem.errors import InstabilityError

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")


def _series(path):
    return np.genfromtxt(path, delimiter=",", names=True)


def test_instability_stops_the_run_with_a_clear_error(tempdir):
    scene = scenes.load("bar-wave", {"time.cfl": 1.2, "time.end": 20.0})
    out = pathlib.Path(tempdir) / "unstable"
    with pytest.raises(InstabilityError, match=r"unstable at step \d+ .*dt = .*Reduce the time step"):
        simulation.run(scene, out, MPI.COMM_WORLD, quiet=True)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stable"] is False and summary["suggested_dt"] < summary["dt"]
    assert (out / io.INCOMPLETE).exists() and (out / io.ERROR).exists()
    assert np.all(np.isfinite(_series(out / "series.csv")["pseudo_energy"]))


@pytest.mark.slow
def test_stable_step_from_the_bound_or_the_eigenvalue(tmp_path):
    """time.cfl is a fraction of the bound's stable step by default, of SLEPc's with
    time.stable_step = "eigenvalue" (for stability studies); the key needs time.cfl."""
    dts = {}
    for method in ("bound", "eigenvalue"):
        scene = scenes.load("cantilever", {"time.end": 0.01, "time.stable_step": method})
        dts[method] = simulation.run(scene, tmp_path / method, MPI.COMM_SELF, quiet=True)["dt"]
    dem = simulation.build(scenes.load("cantilever"), MPI.COMM_SELF).dem
    for method, dt in dts.items():
        assert 0.45 * dem.stable_time_step(method) < dt <= 0.5 * dem.stable_time_step(method)
    assert dts["bound"] < dts["eigenvalue"]
    with pytest.raises(scenes.SceneError, match="'time.stable_step' goes with 'time.cfl'"):
        scenes.load("bar-impact", {"time.stable_step": "eigenvalue"})
    with pytest.raises(scenes.SceneError, match="one of bound, eigenvalue"):
        scenes.load("cantilever", {"time.stable_step": "lanczos"})


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_a_moving_boundary_is_reported_as_not_conservative(tmp_path):
    """Before: "pseudo-energy drift 1.00e+00", read as a failure. The data's work W^n is counted
    (series columns work, balance): the balance E^n - W^n holds to rounding."""
    r = run_command([CLI, "run", "bar-wave", "--set", "time.end=0.1", "--set",
                        'dirichlet=[{boundary="left", value=["0.01 * t"], time_dependent=true}]', "--out",
                        str(tmp_path / "out")], capture_output=True, text=True, check=True)
    assert "not conservative (time-dependent data): energy balance error (work counted)" in r.stdout
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["conservative"] is False and summary["pseudo_energy_rel_drift"] < 1e-13
    series = _series(tmp_path / "out" / "series.csv")
    assert np.abs(series["work"]).max() > 1e-3 * np.abs(series["elastic"]).max()
