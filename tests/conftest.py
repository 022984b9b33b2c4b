"""Shared pytest configuration, in the style of DOLFINx's own test suite.

* ``tempdir``: a temporary directory that is the same on every MPI rank
  (created by rank 0, path broadcast over ``MPI.COMM_WORLD``).
* ``@pytest.mark.skip_in_parallel``: skip a test when run on more than one
  MPI process (e.g. under ``mpirun -n 2``).
* pyvista is forced off-screen (no X server in CI).
"""

import os
import re

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")

import pytest  # noqa: E402
from mpi4py import MPI  # noqa: E402


def pytest_runtest_setup(item):
    """Implement the ``skip_in_parallel`` marker."""
    if item.get_closest_marker("skip_in_parallel") is not None and MPI.COMM_WORLD.size > 1:
        pytest.skip("This test is only run in serial (MPI.COMM_WORLD.size > 1)")


@pytest.fixture
def tempdir(request, tmp_path_factory):
    """A temporary directory shared by all MPI ranks.

    Rank 0 creates it under pytest's ``tmp_path_factory`` and broadcasts the
    path; every rank must request the fixture (the broadcast is collective).
    """
    comm = MPI.COMM_WORLD
    path = None
    if comm.rank == 0:
        name = re.sub(r"[^A-Za-z0-9_.-]", "_", request.node.name)[:30]
        path = tmp_path_factory.mktemp(name, numbered=True)
    return comm.bcast(path, root=0)
