"""Run every demo in its quick setting, serially and under ``mpirun -n 2``, and check the
cantilever demo's numbers.

The demos read ``DOLFINX_DEM_DEMO_QUICK=1`` (coarse mesh, short end time). The run tests start
the demos as subprocesses (the MPI one launches ``mpirun`` itself), so they are serial tests
(``skip_in_parallel``). ``test_cantilever_numbers`` imports the cantilever demo in this process
and asserts on the module-level results it leaves; it runs serially and under MPI.

Tolerances were set from measured values (quick setting: 20 x 2 crossed mesh, t_end = 4 s,
refinement study on 20 x 2 and 40 x 4; the same on 1 and 2 processes):

===============================================  ========  =========
quantity                                         measured  tolerance
===============================================  ========  =========
omega_dem / omega_fem - 1 (20 x 2)               -8.1 %    (-12 %, 0)
omega_dem / omega_p2 - 1 (40 x 4)                -2.0 %    (-3 %, 0)
error ratio 20 x 2 / 40 x 4 (2nd order: 4)       3.98      > 3
2 pi / (measured DEM period) / omega_dem - 1     +0.19 %   1 %
DEM mean / DEM static solve K u = f - 1          +0.00 %   1 %
DEM mean / FEM mean - 1 (20 x 2)                 +18.6 %   (0, 25 %)
omega^2 x static deflection, DEM / FEM - 1       +0.07 %   2 %
omega_fem / omega_eb - 1                         -0.51 %   1.5 %
FEM mean / Euler-Bernoulli static - 1            +0.49 %   1.5 %
MEMM pseudo-energy relative drift                1e-12     1e-8
===============================================  ========  =========

A factor 2 in the DEM stiffness or mass moves omega by a factor sqrt(2) (and the static
deflection by 2, or the product omega^2 x deflection by 2), far outside these bounds: scaling
``DEMDiscretisation.K`` or ``mass`` by 2 after construction was checked to fail the first
frequency assertion (+30 % and -35 %).
"""

import importlib.util
import os
import pathlib
import shutil
import sys

import numpy as np
import pytest
from helpers import run_command
from mpi4py import MPI

DEMO_DIR = pathlib.Path(__file__).resolve().parent.parent / "demos"
DEMOS = sorted(DEMO_DIR.glob("demo_*.py"))
QUICK = {"DOLFINX_DEM_DEMO_QUICK": "1"}
MPI_ENV = {
    "OMPI_ALLOW_RUN_AS_ROOT": "1",
    "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
    "OMPI_MCA_btl_vader_single_copy_mechanism": "none",
}
TIMEOUT = 600  # s

# each test runs a demo (serially or under mpirun) or reads what a demo wrote
pytestmark = pytest.mark.slow


def _environment(extra):
    """This process's environment without the variables of its own MPI (singleton) start-up,
    so that a nested ``mpirun`` starts cleanly; plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "ORTE_"))}
    env.update(OMP_NUM_THREADS="1", PYVISTA_OFF_SCREEN="true", **extra)
    return env


def _check(result, command):
    assert result.returncode == 0, (
        f"{' '.join(map(str, command))} exited with {result.returncode}\n"
        f"--- stdout ---\n{result.stdout[-4000:]}\n--- stderr ---\n{result.stderr[-4000:]}")


def test_demos_exist():
    assert DEMOS, f"no demo_*.py in {DEMO_DIR}"


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("demo", DEMOS, ids=[d.stem for d in DEMOS])
def test_demo_serial(demo, tmp_path):
    command = [sys.executable, str(demo)]
    result = run_command(command, cwd=tmp_path, env=_environment(QUICK), capture_output=True,
                            text=True, timeout=TIMEOUT)
    _check(result, command)


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("demo", DEMOS, ids=[d.stem for d in DEMOS])
def test_demo_mpi(demo, tmp_path):
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        pytest.skip("mpirun not found (Debian package openmpi-bin)")
    command = [mpirun, "-n", "2", "--oversubscribe", sys.executable, str(demo)]
    result = run_command(command, cwd=tmp_path, env=_environment({**QUICK, **MPI_ENV}),
                            capture_output=True, text=True, timeout=TIMEOUT)
    _check(result, command)


def _import_quick(tmp_path_factory, name):
    """Run a demo module in quick mode in an MPI-shared temporary directory and return it."""
    comm = MPI.COMM_WORLD
    path = tmp_path_factory.mktemp(name) if comm.rank == 0 else None
    path = comm.bcast(path, root=0)
    spec = importlib.util.spec_from_file_location(name, DEMO_DIR / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DOLFINX_DEM_DEMO_QUICK", "1")
        mp.chdir(path)
        spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def cantilever(tmp_path_factory):
    return _import_quick(tmp_path_factory, "demo_cantilever")


def _rel(a, b):
    return a / b - 1.0


@pytest.mark.mpi
def test_cantilever_numbers(cantilever):
    d = cantilever
    assert d.QUICK
    # The same numbers on every process.
    values = np.array([d.omega_dem, d.omega_fem, d.static_deflection_dem, d.static_deflection_fem])
    assert np.allclose(MPI.COMM_WORLD.allgather(values), values, rtol=1e-12, atol=0)

    # Frequencies: the DEM is softer than P2 and converges to it at second order.
    assert -0.12 < _rel(d.omega_dem, d.omega_fem) < 0.0
    assert -0.03 < _rel(d.omega_dem_refined[1], d.omega_p2_refined[1]) < 0.0
    assert d.refinement_error[0] / d.refinement_error[1] > 3.0
    # The period of the MEMM history is the eigenvalue's.
    assert abs(_rel(2.0 * np.pi / d.period_dem, d.omega_dem)) < 0.01

    # Static deflection: the mean of the DEM oscillation is the DEM's static solution, larger
    # than P2's by the stiffness deficit that lowers its frequency (the lumped mass is exact).
    assert abs(_rel(d.static_deflection_dem, d.static_deflection_dem_solve)) < 0.01
    assert 0.0 < _rel(d.static_deflection_dem, d.static_deflection_fem) < 0.25
    assert abs(_rel(d.omega_dem**2 * d.static_deflection_dem,
                    d.omega_fem**2 * d.static_deflection_fem)) < 0.02
    assert np.isclose(d.tip_dem[0], 0.0) and d.tip_dem.min() < -1.5 * d.static_deflection_dem

    # The FEM reference against beam theory (2D is slightly softer: shear).
    assert abs(_rel(d.omega_fem, d.omega_eb)) < 0.015
    assert abs(_rel(d.static_deflection_fem, d.static_deflection_eb)) < 0.015
    assert d.numbers["pseudo_energy_rel_drift"] < 1e-8


@pytest.fixture(scope="module")
def signorini(tmp_path_factory):
    return _import_quick(tmp_path_factory, "demo_signorini_bar")


@pytest.mark.mpi
def test_signorini_demo_numbers(signorini):
    """The quick Signorini bar demo (benchmark 1 on 100 cells up to t = 1.25 s, benchmark 2 on 20
    and 40 cells up to 4 s, CFL 0.75; the same on 1 and 2 processes):

    ==================================================  ===============  ==============
    quantity                                            measured         tolerance
    ==================================================  ===============  ==============
    pseudo-energy variation, event splitting (all)      <= 6.1e-15       1e-12
    pseudo-energy variation, Gauss-Legendre 2           2.25e-6          > 1e-9, > 1e4 x split
    the same before the lift-off                        6.6e-15          1e-12
    extra force evaluations with splitting (impact)     2                <= 4
    max force evaluations per step with splitting       2                <= 3
    first contact (s)                                   0.5              one step (0.0025)
    lift-off / 7/6, relative to the duration 2/3        +1.25 %          2 %
    penetration (m)                                     0                1e-12
    mean pressure over [1/2, 7/6] / 300 - 1             -1.2 %           2 %
    pressure after the lift-off (Pa, A and B)           0                exactly 0
    tip L2 order, N = 50, 100 (A, B)                    0.77, 0.78       >= 0.5
    benchmark 2 tip L2 error, N = 40 / N = 20           0.58, 0.56       < 0.8
    benchmark 2 first peak / exact - 1, N = 40          -2.4 %, -2.3 %   5 %
    stability limit, CFL of 2 / sqrt(lambda_max)        1.0002           (0.99, 1.01)
    runs at CFL 1.05 and 1.2                            stopped after t = 0.5, no NaN
    ==================================================  ===============  ==============

    Without event splitting the variation is that of Gauss-Legendre 1 (about 1e-6, the lift-off
    inside a step); a wrong contact reconstruction moves the pressure or the lift-off by far more
    than these bounds (a wave speed off by a factor sqrt(2) changes the contact duration by 40 %).
    """
    d = signorini
    assert d.QUICK
    n = d.numbers
    values = np.array([n["impact"]["A"]["mean_pressure"], n["impact"]["B"]["tip_l2_error"],
                       n["bounce"]["A"]["tip_l2_error"], n["energy"]["gauss-legendre-2"]["max_rel_variation"]])
    assert np.allclose(MPI.COMM_WORLD.allgather(values), values, rtol=1e-8, atol=0)

    # Conservation: exact with event splitting, not with a Gauss-Legendre rule (jump at lift-off).
    assert max(d.paper_drifts.values()) <= 1e-12
    assert max(d.refined_drifts.values()) <= 1e-12
    split, gl2 = n["energy"]["midpoint-split"], n["energy"]["gauss-legendre-2"]
    assert gl2["max_rel_variation"] > max(1e-9, 1e4 * split["max_rel_variation"])
    assert gl2["max_rel_variation_before_release"] <= 1e-12
    # Cost: one force per step, plus one contact-patch evaluation per extra piece of a step.
    assert 0 <= split["extra_evaluations"] <= 4
    assert gl2["extra_evaluations"] == 0
    assert max(d.split_evaluations) <= 3

    # Benchmark 1: contact interval, penetration, pressure.
    for scheme in "AB":
        m = d.impact_numbers[scheme]
        assert abs(m["contact_start"] - 0.5) <= 0.0025 + 1e-12
        assert abs(m["contact_end_error_rel_duration"]) <= 0.02
        assert m["penetration"] <= 1e-12
        assert abs(m["mean_pressure_rel_error"]) <= 0.02
        assert d.order_tip[scheme] >= 0.5
        assert m["max_abs_pressure_after_release"] == 0.0  # the obstacle's force: none with the gap open

    # Benchmark 2: the error falls under refinement, the first bounce is within 5 %.
    assert np.isclose(d.exact_peaks[0], 40.0 / 9.0, rtol=1e-6)
    for scheme in "AB":
        l2 = d.bounce_tip_l2[scheme]
        assert l2[1] / l2[0] < 0.8
        assert abs(d.bounce_peaks[scheme][0] / d.exact_peaks[0] - 1.0) < 0.05

    # Stability: the limit is CFL 1; beyond it the monitor stops the run after the impact,
    # before any NaN.
    assert 0.99 < n["stability"]["cfl_limit"] < 1.01
    for r in n["stability"]["runs"]:
        assert r["stable"] == (r["cfl"] < n["stability"]["cfl_limit"])
        assert r["series_finite"]
        if not r["stable"]:
            assert r["failure_t"] > 0.5 and r["summary_stable_flag"] is False
