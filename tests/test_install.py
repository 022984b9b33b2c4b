"""The environment contract: Debian's DOLFINx 0.5 + numpy 1.24.2, package installed."""

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI


@pytest.mark.mpi
def test_environment_versions():
    import dolfinx

    import dolfinx_dem  # noqa: F401

    assert np.__version__ == "1.24.2", "pip must not replace Debian's numpy (see constraints.txt)"
    assert dolfinx.__version__.startswith("0.5."), dolfinx.__version__


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
