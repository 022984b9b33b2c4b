"""Output of dolfinx_dem runs: the output folder, XDMF fields, a CSV time series, a JSON summary.

Output folder contract
----------------------
A run writes straight into its output folder, inside ``OutputDirectory``:

* Before: the folder may be missing, empty, or hold files that are not a run's; a folder holding
  another run (any of ``RUN_FILES``) is refused unless ``overwrite``, which removes that run's
  files first (and only those; its checkpoint first, and after writing the marker below), so no
  stale file survives. The caller builds and checks everything before entering, so an error in
  the input leaves the folder as it was.
* During: a marker file ``INCOMPLETE``. On a clean exit the marker is removed, unless the run
  keeps it with a note (``keep_incomplete``: an interrupted run, to be resumed); if the run
  raised, every failing rank appends the exception and its traceback to ``error.txt``. A folder
  without ``INCOMPLETE`` therefore holds the complete output of a run that finished.
* Resuming (``resume=True``): the folder must hold the run; the files derived from the whole
  run (summary, pictures) are removed, the series and solution are appended to.

Files (all in the output folder):

* ``solution.xdmf``, ``solution.h5`` and the folder ``solution``: the mesh (``solution.h5``), then
  DG0 fields (cell-centred) per output time, each time in its own HDF5 file ``solution/<k:06d>.h5``
  (``SolutionWriter``, ``_xdmf``; collective). A file is renamed into place once complete and
  only then listed in ``solution.xdmf`` (replaced atomically): a run killed at any moment leaves
  every listed time readable. Hidden files (``solution/.*``, ``solution.xdmf.tmp``) are those of
  a write in progress. A resumed run writes the mesh again (``mesh_1``, ``mesh_2``, ...: its
  processes may number the cells differently) and its times refer to it.
* ``series.csv``: one header line of column names, then one row of floats per time, written
  with ``'%.17g'`` so that they read back bit-identical (``SeriesWriter``; rank 0 writes).
* ``summary.json`` (``write_summary``; rank 0 writes): strict JSON, a number that is not finite
  (NaN, inf) is written as ``null``; replaced atomically (``summary.json.tmp`` is a write in
  progress).

MPI: every class and function here is collective over its ``comm``; values passed to the rank-0
writers must be the same on every rank (e.g. global reductions).
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import pathlib
import pickle
import shutil
import tempfile
import traceback
from collections.abc import Callable, Mapping, Sequence

import dolfinx.fem
import dolfinx.io
import numpy as np
from mpi4py import MPI

from dolfinx_dem import _xdmf
from dolfinx_dem.errors import InputError, MissingFileError, OutputFolderError, StateError

INCOMPLETE = "INCOMPLETE"
#: The lock file of a run in progress in its folder (``OutputDirectory``), removed at its end.
LOCK = ".lock"
ERROR = "error.txt"
#: Every file and folder that a run (or ``dolfinx-dem show``) writes into its output folder.
#: (``.solution.xdmf``, ``.solution.h5``: the working files of earlier versions.)
RUN_FILES = (INCOMPLETE, ERROR, "summary.json", "series.csv", "solution.xdmf", _xdmf.FOLDER, "solution.h5",
             "final.png", "animation.gif", "contact_pressure.csv", "energies.png", "series.png",
             "force_displacement.png", "pressure.png", "checkpoint", "solution.xdmf.tmp", ".solution.xdmf",
             ".solution.h5", "summary.json.tmp")
#: The files derived from a whole run, removed when it is resumed (the resumed run rewrites them).
DERIVED_FILES = ("summary.json", "final.png", "animation.gif", "energies.png", "series.png", "force_displacement.png",
                 "pressure.png")


def call_on_root(comm: MPI.Comm, fn: Callable, *args):
    """Call ``fn(*args)`` on rank 0 and broadcast its result; its exception is raised on all ranks.

    Keeps the ranks in step when rank-0-only work (gmsh, file system) fails before a collective.
    """
    result, error = None, None
    if comm.rank == 0:
        try:
            result = fn(*args)
        except Exception as exc:  # re-raised below, on every rank
            error = exc
    try:
        pickle.dumps(error)
        shared = error
    except Exception:  # an unpicklable exception: send its description instead
        shared = RuntimeError(f"rank 0 failed: {error!r}")
    shared = comm.bcast(shared, root=0)
    if shared is not None:
        if comm.rank == 0:
            raise error
        raise shared
    return comm.bcast(result, root=0)


class OutputDirectory:
    """Context manager for a run's output folder under the contract of the module docstring.

    ``path``: the folder, created (with parents) if needed. ``overwrite``: replace another run
    held there. ``resume``: continue the run held there. ``check`` refuses what entering would
    refuse without touching anything (call it before the set-up); entering checks again, clears
    the old run's files if ``overwrite`` (or the derived files if ``resume``), and writes the
    marker. The context value is the folder as a ``pathlib.Path``. On an exception each failing
    rank appends it with its traceback to ``error.txt`` and the marker stays; no collective call
    is made then, so a run failing on only some ranks cannot hang here.
    """

    def __init__(self, path: str | pathlib.Path, comm: MPI.Comm, overwrite: bool = False, resume: bool = False):
        self.path = pathlib.Path(path)
        self.comm = comm
        self.overwrite, self.resume = overwrite, resume
        self._note = None
        self._lock = None  # rank 0's open lock file while the run holds the folder

    def _take_lock(self) -> None:
        """An exclusive lock (flock) on ``LOCK`` in the folder, which the OS releases when the
        process ends, however it ends: two runs never write into one folder at once. The file is
        removed on release; a lock taken on a file removed meanwhile (its inode no longer the
        path's) counts as taken by another run."""
        path = self.path / LOCK
        self._lock = open(path, "a")  # noqa: SIM115 (held until _release_lock)
        try:
            fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if os.fstat(self._lock.fileno()).st_ino != os.stat(path).st_ino:
                raise BlockingIOError
        except (BlockingIOError, FileNotFoundError):
            self._lock.close()
            self._lock = None
            raise OutputFolderError(f"output folder {self.path} is in use by a run in progress (it holds "
                                    f"{path}): wait for it to end, or choose another --out") from None

    def _release_lock(self) -> None:
        (self.path / LOCK).unlink()
        self._lock.close()
        self._lock = None

    def _check(self) -> list[pathlib.Path]:
        """The run files present in the folder; raises if the run may not go there: not a folder,
        not writable (a folder made and removed in its nearest existing ancestor tells), held by
        another run, or locked by a run in progress (``_lock``)."""
        if self.path.exists() and not self.path.is_dir():
            raise OutputFolderError(f"output path {self.path} exists and is not a directory")
        ancestor = next(p for p in (self.path.absolute(), *self.path.absolute().parents) if p.exists())
        try:
            os.rmdir(tempfile.mkdtemp(dir=ancestor, prefix=".dolfinx-dem-"))
        except OSError as err:
            raise OutputFolderError(f"output folder {self.path} cannot be written ({ancestor}: "
                                    f"{err.strerror})") from None
        if self.path.is_dir() and self._lock is None:
            self._take_lock()
            self._release_lock()
        present = [self.path / name for name in RUN_FILES if os.path.lexists(self.path / name)]
        if self.resume or not present or self.overwrite:
            return present
        hint = (f"or `dolfinx-dem resume {self.path}` to continue it" if (self.path / "checkpoint").exists()
                else "or another --out")
        raise OutputFolderError(
            f"output folder {self.path} holds another run ({', '.join(p.name for p in present)}): pass "
            f"--overwrite to replace it (its files are removed first), {hint}")

    def check(self) -> None:
        """Raise (on every rank) if entering would refuse the folder; touches nothing."""
        call_on_root(self.comm, self._check)

    def keep_incomplete(self, note: str) -> None:
        """Write ``note`` into the ``INCOMPLETE`` marker now and leave it there on a clean exit
        (e.g. an interrupted run, which may be killed before it exits)."""
        self._note = note.rstrip("\n") + "\n"
        call_on_root(self.comm, (self.path / INCOMPLETE).write_text, self._note)

    def __enter__(self) -> pathlib.Path:
        def start():
            self._check()
            self.path.mkdir(parents=True, exist_ok=True)
            self._take_lock()
            try:
                present = self._check()
                # the marker first, then the old checkpoint: a run killed while the old files go
                # leaves a folder marked incomplete, and no checkpoint to resume into half-removed outputs
                (self.path / INCOMPLETE).write_text("dolfinx_dem run in progress or failed\n")
                remove = [p for p in present if p.name != INCOMPLETE and (
                    self.overwrite or p.name == ERROR or (self.resume and p.name in DERIVED_FILES))]
                for p in sorted(remove, key=lambda p: p.name != "checkpoint"):
                    shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
            except BaseException:
                self._release_lock()
                raise

        call_on_root(self.comm, start)
        return self.path

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.comm.barrier()
            if self.comm.rank == 0:
                if self._note is None:
                    (self.path / INCOMPLETE).unlink()
                self._release_lock()
            self.comm.barrier()  # every rank leaves after the marker and the lock are gone
        else:
            message = "".join(traceback.format_exception(exc_type, exc, tb))
            with open(self.path / ERROR, "a") as f:
                f.write(f"[rank {self.comm.rank} of {self.comm.size}] {message}")
            if self._lock is not None:
                self._release_lock()
        return False


class SolutionWriter:
    """Context manager writing DG0 Functions over time to ``directory/solution.xdmf`` and its
    folder ``directory/solution`` of HDF5 files (``_xdmf``: one file per output time).

    The mesh is written on construction. ``resume_writes``: continue the output of a run whose
    first ``resume_writes`` output times are kept (later ones, written after its last
    checkpoint, are dropped), with the mesh written again with the first new time (see the
    module docstring). ``writes`` counts the output times listed. Collective over ``comm`` (the
    mesh's communicator).

    Kill-safety: DOLFINx keeps HDF5 metadata in memory until it closes a file and rewrites its
    XML file in place at every write, so a kill during a write damaged a single growing file.
    Here every output time is a new file, written under a hidden name, renamed into place once
    closed, and only then listed in ``solution.xdmf`` (replaced atomically): a kill at any moment
    leaves every listed time readable.
    """

    def __init__(self, comm: MPI.Comm, directory: str | pathlib.Path, mesh, resume_writes: int | None = None):
        directory = pathlib.Path(directory)
        if not directory.is_dir():
            raise MissingFileError(f"output directory {directory} does not exist")
        self.path = directory / "solution.xdmf"
        self._folder = directory / _xdmf.FOLDER
        self._comm, self._mesh = comm, mesh
        self._index, self._closed = None, False  # rank 0's _xdmf.Index

        def start():
            fresh = resume_writes is None
            self._index = _xdmf.Index.fresh(self.path) if fresh else _xdmf.Index.resume(self.path, resume_writes)
            return self._index.next_mesh()

        self._mesh_name = call_on_root(comm, start)
        self._mesh_xpath = None  # until the mesh is written: now, or with a resumed writer's first time
        if resume_writes is None:
            self._write_mesh()
        self.writes = resume_writes or 0

    def _write_mesh(self) -> None:
        name = self._mesh_name
        with dolfinx.io.XDMFFile(self._comm, str(_xdmf.hidden(self._folder, name, ".xdmf")), "w") as xdmf:
            xdmf.write_mesh(self._mesh)
        call_on_root(self._comm, lambda: self._index.add_mesh(name))
        self._mesh_xpath = _xdmf.mesh_xpath(name)

    def write(self, t: float, fields: Mapping[str, dolfinx.fem.Function]) -> None:
        """Write ``fields`` (name -> DG0 Function on the writer's mesh) at time ``t`` (s).

        Each Function is renamed to its key, which becomes its name in the XDMF file.
        """
        if self._closed:
            raise StateError("the solution writer is closed")
        if not math.isfinite(t):
            raise InputError(f"time t must be finite, got {t!r}")
        if not fields:
            raise InputError("fields must name at least one Function")
        for name, f in fields.items():
            if not isinstance(name, str) or not name:
                raise InputError(f"field names must be non-empty strings, got {name!r}")
            if not isinstance(f, dolfinx.fem.Function):
                raise InputError(f"field {name!r} must be a dolfinx.fem.Function, got {type(f)}")
            if f.function_space.mesh is not self._mesh:
                raise InputError(f"field {name!r} is not defined on the writer's mesh")
        if self._mesh_xpath is None:
            self._write_mesh()
        k = self.writes
        call_on_root(self._comm, lambda: self._index.time_template(k))
        xdmf = dolfinx.io.XDMFFile(self._comm, str(_xdmf.hidden(self._folder, _xdmf.time_file(k), ".xdmf")), "a")
        try:
            for name, f in fields.items():
                f.name = name
                xdmf.write_function(f, float(t), self._mesh_xpath)
        finally:
            xdmf.close()
        call_on_root(self._comm, lambda: self._index.add_time(k))
        self.writes += 1

    def sync(self) -> None:
        """Put every listed output time on disk (fsync; before a checkpoint, so that a stopped
        machine keeps what the checkpoint counts)."""
        call_on_root(self._comm, lambda: self._index.sync())

    def close(self) -> None:
        """Every output time is published as it is written: closing only ends the writer."""
        self._index, self._closed = None, True

    def __enter__(self) -> SolutionWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.close()
        return False


class SeriesWriter:
    """Context manager writing a CSV time series (rank 0 writes, all ranks call).

    ``columns``: column names (unique, no commas), e.g. ``("t", "kinetic_energy")``. Rows are
    flushed to disk every ``flush_every`` rows and on close. ``append_at``: continue an
    existing file with these columns from that byte (a ``position``), dropping what follows.
    """

    def __init__(
        self,
        comm: MPI.Comm,
        path: str | pathlib.Path,
        columns: Sequence[str],
        flush_every: int = 10,
        append_at: int | None = None,
    ):
        columns = tuple(columns)
        if not columns:
            raise InputError("columns must name at least one column")
        for name in columns:
            if not isinstance(name, str) or not name or any(c in name for c in ",\n\r\""):
                raise InputError(
                    f"column names must be non-empty, without , \" or newlines, got {name!r}"
                )
        if len(set(columns)) != len(columns):
            raise InputError(f"column names must be unique, got {columns}")
        if not (isinstance(flush_every, int) and flush_every >= 1):
            raise InputError(f"flush_every must be an integer >= 1, got {flush_every!r}")
        self.path = pathlib.Path(path)
        self.columns = columns
        self._flush_every = flush_every
        self._rows = 0
        self._file = None

        self._comm = comm

        def start():
            if append_at is None:
                self._file = open(self.path, "w")
                self._file.write(",".join(columns) + "\n")
                return
            self._file = open(self.path, "r+")
            header = self._file.readline().rstrip("\n")
            if header != ",".join(columns):
                self._file.close()
                raise InputError(f"{self.path} has the columns {header!r}, not {','.join(columns)!r}")
            if not len(header) < append_at <= self.path.stat().st_size:
                self._file.close()
                raise InputError(f"{self.path} has {self.path.stat().st_size} bytes, cannot continue at {append_at}")
            self._file.truncate(append_at)
            self._file.seek(append_at)

        call_on_root(comm, start)

    def write(self, row: Mapping[str, float] | Sequence[float]) -> None:
        """Append one row: a mapping with exactly the column names, or values in column order."""
        if isinstance(row, Mapping):
            if set(row) != set(self.columns):
                raise InputError(
                    f"row keys {sorted(row)} do not match the columns {sorted(self.columns)}"
                )
            values = [row[name] for name in self.columns]
        else:
            values = list(row)
            if len(values) != len(self.columns):
                raise InputError(f"row has {len(values)} values for {len(self.columns)} columns")
        values = [float(v) for v in values]
        if self._file is not None:
            self._file.write(",".join("%.17g" % v for v in values) + "\n")  # noqa: UP031 (the series' format)
            self._rows += 1
            if self._rows % self._flush_every == 0:
                self._file.flush()

    def position(self) -> int:
        """Flush the file to disk (fsync) and return its size in bytes, where a resumed run
        continues (``append_at``); the same on every rank."""
        size = None
        if self._file is not None:
            self._file.flush()
            os.fsync(self._file.fileno())
            size = self._file.tell()
        return self._comm.bcast(size, root=0)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> SeriesWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.close()
        return False


def _strict(value):
    """``value`` with numpy scalars and arrays as Python values, paths as strings, and every
    float that is not finite (NaN, inf) as None: strict JSON has no NaN or Infinity."""
    if isinstance(value, Mapping):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if isinstance(value, np.ndarray):
        return _strict(value.tolist())
    if isinstance(value, np.generic):
        return _strict(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, pathlib.PurePath):
        return str(value)
    if value is None or isinstance(value, (bool, int, str)):
        return value
    raise TypeError(f"cannot write {type(value).__name__} {value!r} to JSON")


def write_summary(path: str | pathlib.Path, comm: MPI.Comm, data: Mapping) -> None:
    """Write ``data`` as strict JSON (sorted keys, indent 2) on rank 0: numpy values become
    Python ones, and numbers that are not finite (NaN, inf) are written as ``null``. The file is
    replaced atomically (a temporary file, then ``os.replace``): a run killed while writing it
    leaves the previous summary, never a truncated one (a resume reads it)."""
    path = pathlib.Path(path)

    def write():
        text = json.dumps(_strict(dict(data)), sort_keys=True, indent=2, allow_nan=False)
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(text + "\n")
        os.replace(tmp, path)

    call_on_root(comm, write)
