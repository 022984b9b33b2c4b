"""Shared pytest configuration, in the style of DOLFINx's own test suite.

* ``tempdir``: a temporary directory that is the same on every MPI rank
  (created by rank 0, path broadcast over ``MPI.COMM_WORLD``).
* ``@pytest.mark.skip_in_parallel``: skip a test when run on more than one
  MPI process (e.g. under ``mpirun -n 2``).
* pyvista is forced off-screen (no X server in CI).
* A test that runs longer than ``DOLFINX_DEM_TEST_LIMIT`` seconds (900) prints every thread's
  traceback, kills the processes it started, names itself and ends its process (exit status 1);
  under ``mpirun`` the other processes are then ended too. A hang (a collective call made on some
  processes only, an ``mpirun`` that does not return) fails with where it hung, instead of
  running into CI's own time limit. (A command run by ``helpers.run_command`` has its own,
  shorter limit.)
* Under ``mpirun``, a test that fails on one process ends the run (``MPI_Abort``) after printing
  its report: the other processes would otherwise wait at the test's next collective call forever.
"""

import contextlib
import faulthandler
import os
import re
import signal
import sys
import threading

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")

import pytest  # noqa: E402
from helpers import descendants  # noqa: E402
from mpi4py import MPI  # noqa: E402

#: wall time (s) a test may take before its process is ended (see the module docstring)
TEST_LIMIT = float(os.environ.get("DOLFINX_DEM_TEST_LIMIT", "900"))
_stderr = None  # the terminal's stderr, which pytest's capture leaves alone


def pytest_configure(config):
    global _stderr
    _stderr = os.fdopen(os.dup(sys.__stderr__.fileno()), "w")


def pytest_unconfigure(config):
    _stderr.close()


def _over_time(nodeid: str):
    """The test ran past TEST_LIMIT: every thread's traceback, the processes it started killed,
    its name last (CI shows the end of its log), and this process ended."""
    faulthandler.dump_traceback(file=_stderr, all_threads=True)
    left = descendants(os.getpid())
    for pid in left:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    _stderr.write(f"\n{nodeid} ran longer than {TEST_LIMIT:g} s on process {MPI.COMM_WORLD.rank} of "
                  f"{MPI.COMM_WORLD.size} (traceback above); processes it had started, killed: {left}\n")
    _stderr.flush()
    os._exit(1)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Arm the time limit around each test (setup, call and teardown). The watchdog is a thread;
    faulthandler ends the process a minute later should the thread not run (a call that holds
    the interpreter's lock)."""
    watchdog = threading.Timer(TEST_LIMIT, _over_time, args=(item.nodeid,))
    watchdog.daemon = True
    watchdog.start()
    faulthandler.dump_traceback_later(TEST_LIMIT + 60, exit=True, file=_stderr)
    try:
        yield
    finally:
        watchdog.cancel()
        faulthandler.cancel_dump_traceback_later()


def pytest_runtest_logreport(report):
    """Under mpirun, a failure on one process ends every process (see the module docstring)."""
    comm = MPI.COMM_WORLD
    if report.failed and comm.size > 1:
        _stderr.write(f"\n{report.nodeid} failed on process {comm.rank} of {comm.size} ({report.when}):\n"
                      f"{report.longreprtext}\nMPI_Abort: the other processes would wait for this one.\n")
        _stderr.flush()
        comm.Abort(1)


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
