"""The environment contract: Debian's DOLFINx 0.5 + numpy 1.24.2, package installed."""

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import run_command
from mpi4py import MPI


@pytest.mark.mpi
def test_environment_versions():
    import dolfinx

    import dolfinx_dem  # noqa: F401

    # Debian's numpy, the one DOLFINx was built against: pip must not replace it (the Makefile
    # constrains pip to the system's version)
    assert np.__file__.startswith("/usr/lib/python3/dist-packages/"), np.__file__
    assert dolfinx.__version__.startswith(("0.5.", "0.9.")), dolfinx.__version__


def test_entry_point_installed():
    if sys.prefix == sys.base_prefix:
        pytest.skip("not running in a virtual environment")
    script = Path(sys.executable).parent / "dolfinx-dem"
    assert script.is_file(), f"{script} missing: run `make setup`"
    assert os.access(script, os.X_OK)


@pytest.mark.mpi
def test_tempdir_is_shared(tempdir):
    comm = MPI.COMM_WORLD
    assert tempdir.is_dir()
    assert comm.allgather(str(tempdir)) == [str(tempdir)] * comm.size


@pytest.mark.skip_in_parallel
def test_make_test_runs_the_mpi_tests_on_2_and_3_processes():
    """An odd process count finds what 2 hides (DESIGN.md): ``make test`` runs the tests marked
    ``mpi`` under mpirun -n 2 and -n 3 (it used to run -n 2 only)."""
    import shutil

    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    root = Path(__file__).resolve().parents[1]
    # not the variables of a make that runs these tests (make test-fast passes MPI_NP=2 down)
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL", "MPI_NP")}
    dry = run_command(["make", "-n", "test"], cwd=root, capture_output=True, text=True, check=True, env=env).stdout
    assert "for np in 2 3; do" in dry
    assert "mpirun -n $np --oversubscribe" in dry and '-m pytest -q -m "mpi" ' in dry
    assert "ruff check ." in dry  # the linter first
    fast = run_command(["make", "-n", "test-fast"], cwd=root, capture_output=True, text=True, check=True,
                          env=env).stdout
    assert "for np in 2; do" in fast and '-m pytest -q -m "not slow"' in fast and '-m "mpi and (not slow)"' in fast
