"""Helpers shared by the test modules (tests/ is on sys.path under pytest's default import mode)."""

import contextlib
import importlib.util
import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np

from dolfinx_dem import _compat


def gmsh_mesh(comm, build, gdim=2):
    """A DOLFINx mesh from ``build(gmsh)``, which makes and meshes a gmsh model on rank 0."""
    import gmsh

    if comm.rank == 0:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        build(gmsh)
    try:
        return _compat.mesh_from_gmsh_model(gmsh.model, comm, gdim)[0]
    finally:
        if comm.rank == 0:
            gmsh.finalize()


def owned_centres(dem):
    """Barycentres of the owned cells, shape (n_owned, d)."""
    return dem.geometry.cell_centres[: dem.n_owned]


def cell_vector(dem, field):
    """PETSc vector of u_c = field(x_c) on the owned cells; field maps (n, d) -> (n, d)."""
    u = dem.create_vector()
    u.array[:] = np.asarray(field(owned_centres(dem))).ravel()
    return u


# --- running the command line in subprocesses -------------------------------------------------

#: The dolfinx-dem script of this Python's environment.
CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")


#: Wall time (s) a command run by a test may take: below a test's own limit (conftest.TEST_LIMIT),
#: so that a command that hangs (an ``mpirun`` that does not return) fails its own test.
SUBPROCESS_LIMIT = 600


def _state(pid: int) -> str:
    """A process's name and state from /proc (R running, S sleeping, Z exited), "gone" if none."""
    try:
        stat = pathlib.Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return "gone"
    name, rest = stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2:]
    return f"{name} {rest[0]}"


def run_command(args, timeout=SUBPROCESS_LIMIT, check=False, capture_output=False, input=None,
                **kwargs) -> subprocess.CompletedProcess:
    """``subprocess.run`` with a time limit: past it, the command and every process below it
    (an mpirun's ranks) are killed and the test fails, naming them and their states (an mpirun
    whose ranks have all exited is Open MPI's hang, a rank running is ours)."""
    if capture_output:
        kwargs["stdout"] = kwargs["stderr"] = subprocess.PIPE
    if input is not None:
        kwargs["stdin"] = subprocess.PIPE
    with subprocess.Popen(args, **kwargs) as process:
        try:
            stdout, stderr = process.communicate(input, timeout=timeout)
        except subprocess.TimeoutExpired:
            left = [process.pid, *descendants(process.pid)]
            states = {pid: _state(pid) for pid in left}
            for pid in reversed(left):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            process.communicate()
            raise AssertionError(f"still running after {timeout:g} s, killed: {' '.join(map(str, args))}; "
                                 f"its processes then: {states}") from None
    result = subprocess.CompletedProcess(args, process.returncode, stdout, stderr)
    if check:
        result.check_returncode()
    return result


def mpi_env(**extra):
    """The environment for mpirun as root in a container, one thread per process."""
    return dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
                OMPI_MCA_btl_vader_single_copy_mechanism="none", OMP_NUM_THREADS="1", **extra)


def wait_for(predicate, timeout=240.0, what="the condition"):
    """Poll ``predicate()`` every 0.1 s until it is true; fail after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.1)


def series_rows(path) -> int:
    """Rows written to a series.csv so far (0 if it does not exist yet)."""
    try:
        with open(path) as f:
            return max(sum(1 for _ in f) - 1, 0)
    except FileNotFoundError:
        return 0


def read_solution(path, field="displacement"):
    """Read every output time of a solution.xdmf back (VTK's XDMF reader, its own HDF5):
    returns (times, [cell data of ``field`` at each time]); raises if the file cannot be read."""
    from dolfinx_dem import _compat

    pyvista = _compat.import_pyvista()
    reader = pyvista.get_reader(str(path))
    times, data = list(reader.time_values), []
    for t in times:
        reader.set_active_time_value(t)
        data.append(np.asarray(reader.read()[field].cell_data[field]))
    return times, data


def children(pid: int) -> list[int]:
    """Process ids of the children of ``pid`` (Linux /proc), e.g. the ranks mpirun started."""
    out = []
    for task in pathlib.Path(f"/proc/{pid}/task").iterdir():
        out += [int(c) for c in (task / "children").read_text().split()]
    return out


def descendants(pid: int) -> list[int]:
    """Process ids of every process below ``pid`` (children first); those that end meanwhile are
    left out."""
    try:
        direct = children(pid)
    except (FileNotFoundError, ProcessLookupError):
        return []
    return direct + [d for c in direct for d in descendants(c)]


def stop_after(monkeypatch, at: int, first: int = 0, crash: bool = False):
    """Make the next run stop after step ``at`` (it starts after step ``first``): interrupted
    as by SIGINT, or with an exception (a crash: no checkpoint then)."""
    from dolfinx_dem import runcontrol
    calls = [first]

    def requested(self, now=False):
        calls[0] += 1
        if calls[0] == at and crash:
            raise RuntimeError(f"crash after step {at}")
        self.signal = signal.SIGINT if calls[0] >= at else 0
        return calls[0] >= at

    monkeypatch.setattr(runcontrol.Interrupts, "requested", requested)


# --- the studies' scripts (benchmarks/, validation/) ------------------------------------------

#: The repository's root: the scripts' paths are relative to it, and they run in it.
ROOT = pathlib.Path(__file__).resolve().parent.parent


def run_quick(script, *args, timeout=300):
    """Run ``script`` (a path from the repository root) with ``--quick`` and ``args``."""
    proc = run_command([sys.executable, str(ROOT / script), "--quick", *args],
                       capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    return proc


def import_script(path, monkeypatch):
    """The script at ``path`` imported as a module (its folder on sys.path, as when it runs)."""
    monkeypatch.syspath_prepend(str(path.parent))
    name = f"_script_{path.parent.name}_{path.stem}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, name, module)
    spec.loader.exec_module(module)
    return module
