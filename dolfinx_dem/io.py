"""Output of dolfinx_dem runs: XDMF fields, a CSV time series, a JSON summary.

Completed-output contract
-------------------------
A run writes straight into its output directory, inside ``OutputDirectory``: on entry it writes
a marker file ``INCOMPLETE`` (and removes a stale ``error.txt``), on a clean exit it removes the
marker. A directory without ``INCOMPLETE`` therefore holds the complete output of a run that
finished; a directory with ``INCOMPLETE`` is from a run that is still going, crashed or was
killed, and if the run raised, ``error.txt`` holds the exception and its traceback.

Files (all in the output directory):

* ``solution.xdmf`` + ``solution.h5``: the mesh once, then DG0 fields (cell-centred) per time
  (``SolutionWriter``; collective).
* ``series.csv``: one header line of column names, then one row of floats per time, written
  with ``'%.17g'`` so that they read back bit-identical (``SeriesWriter``; rank 0 writes).
* ``summary.json`` (``write_summary``; rank 0 writes): strict JSON, a number that is not finite
  (NaN, inf) is written as ``null``.

MPI: every class and function here is collective over its ``comm``; values passed to the rank-0
writers must be the same on every rank (e.g. global reductions).
"""

from __future__ import annotations

import json
import math
import pathlib
import pickle
import traceback
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from mpi4py import MPI

import dolfinx.fem
import dolfinx.io

INCOMPLETE = "INCOMPLETE"
ERROR = "error.txt"


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
    """Context manager for a run's output directory under the ``INCOMPLETE`` marker contract.

    ``path``: the directory, created (with parents) if needed; existing files are overwritten by
    the run's writers, other files are left alone. The context value is the directory as a
    ``pathlib.Path``. On an exception each failing rank appends it with its traceback to
    ``error.txt`` and the marker stays; no collective call is made then, so a run failing on
    only some ranks cannot hang here.
    """

    def __init__(self, path: str | pathlib.Path, comm: MPI.Comm):
        self.path = pathlib.Path(path)
        self.comm = comm

    def __enter__(self) -> pathlib.Path:
        def start():
            if self.path.exists() and not self.path.is_dir():
                raise NotADirectoryError(f"output path {self.path} exists and is not a directory")
            self.path.mkdir(parents=True, exist_ok=True)
            (self.path / ERROR).unlink(missing_ok=True)
            (self.path / INCOMPLETE).write_text("dolfinx_dem run in progress or failed\n")

        call_on_root(self.comm, start)
        return self.path

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.comm.barrier()
            if self.comm.rank == 0:
                (self.path / INCOMPLETE).unlink()
            self.comm.barrier()
        else:
            message = "".join(traceback.format_exception(exc_type, exc, tb))
            with open(self.path / ERROR, "a") as f:
                f.write(f"[rank {self.comm.rank} of {self.comm.size}] {message}")
        return False


class SolutionWriter:
    """Context manager writing DG0 Functions over time to ``directory/solution.xdmf`` (+ ``.h5``).

    The mesh is written once on construction. Collective over ``comm`` (the mesh's communicator).
    """

    def __init__(self, comm: MPI.Comm, directory: str | pathlib.Path, mesh):
        directory = pathlib.Path(directory)
        if not directory.is_dir():
            raise FileNotFoundError(f"output directory {directory} does not exist")
        self.path = directory / "solution.xdmf"
        self._mesh = mesh
        self._xdmf = dolfinx.io.XDMFFile(comm, str(self.path), "w")
        self._xdmf.write_mesh(mesh)

    def write(self, t: float, fields: Mapping[str, dolfinx.fem.Function]) -> None:
        """Write ``fields`` (name -> DG0 Function on the writer's mesh) at time ``t`` (s).

        Each Function is renamed to its key, which becomes its name in the XDMF file.
        """
        if not math.isfinite(t):
            raise ValueError(f"time t must be finite, got {t!r}")
        if not fields:
            raise ValueError("fields must name at least one Function")
        for name, f in fields.items():
            if not isinstance(name, str) or not name:
                raise ValueError(f"field names must be non-empty strings, got {name!r}")
            if not isinstance(f, dolfinx.fem.Function):
                raise ValueError(f"field {name!r} must be a dolfinx.fem.Function, got {type(f)}")
            if f.function_space.mesh is not self._mesh:
                raise ValueError(f"field {name!r} is not defined on the writer's mesh")
        for name, f in fields.items():
            f.name = name
            self._xdmf.write_function(f, float(t))

    def close(self) -> None:
        self._xdmf.close()

    def __enter__(self) -> SolutionWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.close()
        return False


class SeriesWriter:
    """Context manager writing a CSV time series (rank 0 writes, all ranks call).

    ``columns``: column names (unique, no commas), e.g. ``("t", "kinetic_energy")``. Rows are
    flushed to disk every ``flush_every`` rows and on close.
    """

    def __init__(
        self,
        comm: MPI.Comm,
        path: str | pathlib.Path,
        columns: Sequence[str],
        flush_every: int = 10,
    ):
        columns = tuple(columns)
        if not columns:
            raise ValueError("columns must name at least one column")
        for name in columns:
            if not isinstance(name, str) or not name or any(c in name for c in ",\n\r\""):
                raise ValueError(
                    f"column names must be non-empty, without , \" or newlines, got {name!r}"
                )
        if len(set(columns)) != len(columns):
            raise ValueError(f"column names must be unique, got {columns}")
        if not (isinstance(flush_every, int) and flush_every >= 1):
            raise ValueError(f"flush_every must be an integer >= 1, got {flush_every!r}")
        self.path = pathlib.Path(path)
        self.columns = columns
        self._flush_every = flush_every
        self._rows = 0
        self._file = None

        def start():
            self._file = open(self.path, "w")
            self._file.write(",".join(columns) + "\n")

        call_on_root(comm, start)

    def write(self, row: Mapping[str, float] | Sequence[float]) -> None:
        """Append one row: a mapping with exactly the column names, or values in column order."""
        if isinstance(row, Mapping):
            if set(row) != set(self.columns):
                raise ValueError(
                    f"row keys {sorted(row)} do not match the columns {sorted(self.columns)}"
                )
            values = [row[name] for name in self.columns]
        else:
            values = list(row)
            if len(values) != len(self.columns):
                raise ValueError(f"row has {len(values)} values for {len(self.columns)} columns")
        values = [float(v) for v in values]
        if self._file is not None:
            self._file.write(",".join("%.17g" % v for v in values) + "\n")
            self._rows += 1
            if self._rows % self._flush_every == 0:
                self._file.flush()

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
    Python ones, and numbers that are not finite (NaN, inf) are written as ``null``."""
    path = pathlib.Path(path)

    def write():
        text = json.dumps(_strict(dict(data)), sort_keys=True, indent=2, allow_nan=False)
        path.write_text(text + "\n")

    call_on_root(comm, write)
