"""Checkpoints of a dynamic run: its complete state on disk, to resume on any number of processes.

Layout, in the run's output folder (docs/scenes.md, "Checkpoints and resume")::

    checkpoint/checkpoint.json          header (JSON), replaced atomically once the data are written
    checkpoint/step-<n>-<id>/cells-<r>.npz
                                        process r of the writing run: its owned cells' ``key``
                                        (index in the input mesh), ``centre`` (barycentre), the
                                        state vectors ``u``, ``v_prev``, ``v_next`` (n_owned, d)
                                        and the contact models' cell states (``contact<k>_<name>``,
                                        (n_owned, ...): friction's lagged normal forces; their
                                        shapes are in the header, ``cell_arrays``)
    checkpoint/step-<n>-<id>/local-<r>.npz
                                        process r's arrays that only its partition can read: the
                                        energy-row recurrence of MEMM (``y``, ``z``, ``means``)
                                        and the contact models' states (``contact<k>_<name>``)

The header holds the format number ``FORMAT``, the package version, the ``scene_hash``, the
validated scene itself, the number of processes, the step n, t and dt, and whatever the runner
adds (stepper scalars, statistics, output positions). A checkpoint is complete as soon as its
header names it: every process writes and fsyncs its files into a new folder, then rank 0
fsyncs that folder, writes the header to a temporary file, fsyncs it and renames it over the
old header (``os.replace``), and only then removes the previous checkpoint's folder. A run
killed (or a machine stopped) at any moment of a checkpoint keeps the previous one in force.

Cells are keyed by their index in the input mesh (DOLFINx's original cell index), which does not
depend on the number of processes; a resumed run sends each stored cell to the process that owns
its key range, each process asks there for its own cells (``_redistribute``: two all-to-all
exchanges, no process holds more than its share), and the barycentres are compared, so that a
checkpoint of another mesh is an error, not a wrong state. The ``local`` arrays are used when
the resumed run has the same partition (the same number of processes and the same owned cells
on each): the continuation is then bit-identical; otherwise the resumed run recomputes them. No
process writes or reads more than its share: there is no file of global size.
"""

from __future__ import annotations

import copy
import hashlib
import importlib.metadata
import json
import os
import pathlib
import shutil
import time
from collections.abc import Mapping

import numpy as np
from mpi4py import MPI

from dolfinx_dem._xdmf import fsync
from dolfinx_dem.errors import CheckpointError
from dolfinx_dem.io import call_on_root

FORMAT = 11  # 2: per-process local files (the recurrence, contact states); no shared file; 3: MEMM work;
# 4: the pair contact's exchange counter; 5: the solution as one HDF5 file per output time (io.SolutionWriter);
# 6: the largest penetration over the local facet diameter (run_statistics.PairContactStatistics); 7: MEMM's
# frictional dissipation; 8: the contact models' cell states (friction's lagged normal forces); 9: the counters
# of friction between bodies (run_statistics.PairContactStatistics); 10: the lagged normal forces of friction
# between bodies (contact/pair_lag.py) and the cell arrays' shapes in the header; 11: the touching pairs'
# largest crossing angle (run_statistics.PairContactStatistics)
DIRECTORY = "checkpoint"
HEADER = "checkpoint.json"
VECTORS = ("u", "v_prev", "v_next")


def package_version() -> str:
    return importlib.metadata.version("dolfinx-dem")


def scene_hash(scene: Mapping) -> str:
    """sha256 of the validated scene without ``time.end`` (a resumed run may go further), as
    canonical JSON, followed by the bytes of a mesh file (``mesh.type = "file"``)."""
    scene = copy.deepcopy(dict(scene))
    scene.get("time", {}).pop("end", None)
    digest = hashlib.sha256(json.dumps(scene, sort_keys=True, separators=(",", ":")).encode())
    if scene["mesh"]["type"] == "file":
        path = pathlib.Path(scene["mesh"]["path"])
        digest.update(path.read_bytes() if path.is_file() else b"missing")
    return digest.hexdigest()


def scene_differences(a: Mapping, b: Mapping, prefix: str = "") -> list[str]:
    """Dotted keys whose values differ between two scenes (tables compared key by key)."""
    out = []
    for key in sorted(set(a) | set(b)):
        name = f"{prefix}{key}"
        x, y = a.get(key), b.get(key)
        if isinstance(x, Mapping) and isinstance(y, Mapping):
            out += scene_differences(x, y, name + ".")
        elif x != y:
            out.append(name)
    return out


def write(folder: pathlib.Path, comm: MPI.Comm, header: Mapping, keys: np.ndarray, centres: np.ndarray,
          vectors: Mapping[str, np.ndarray], local: Mapping[str, np.ndarray]) -> None:
    """Write a checkpoint into ``folder/checkpoint`` (collective). ``header``: JSON-able values
    (``step`` among them); ``keys`` (n_owned,), ``centres`` (n_owned, d) and ``vectors``
    (n_owned, d) of this process's cells; ``local``: this process's arrays for a resume on the
    same partition."""
    root = pathlib.Path(folder) / DIRECTORY
    name = comm.bcast(f"step-{int(header['step']):09d}-{time.time_ns()}" if comm.rank == 0 else None, root=0)
    data = root / name
    call_on_root(comm, lambda: data.mkdir(parents=True))
    _save(data / f"cells-{comm.rank}.npz", dict(key=keys, centre=centres, **vectors))
    _save(data / f"local-{comm.rank}.npz", local)
    comm.barrier()  # every process's data are on disk before the header names them

    def commit():
        fsync(data)
        fsync(root)
        text = json.dumps(dict(header, data=name, processes=comm.size), indent=1, sort_keys=True)
        with open(root / (HEADER + ".tmp"), "w") as f:
            f.write(text + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(root / (HEADER + ".tmp"), root / HEADER)
        fsync(root)
        for old in root.glob("step-*"):
            if old.name != name:
                shutil.rmtree(old)

    call_on_root(comm, commit)


def _save(path: pathlib.Path, arrays: Mapping[str, np.ndarray]) -> None:
    """``np.savez`` to ``path``, on disk when it returns (fsync)."""
    with open(path, "wb") as f:
        np.savez(f, **arrays)
        f.flush()
        os.fsync(f.fileno())


def read_header(folder: pathlib.Path, comm: MPI.Comm) -> dict:
    """The header of the checkpoint in ``folder`` (read on rank 0, the same on every process)."""
    def read():
        path = pathlib.Path(folder) / DIRECTORY / HEADER
        if not path.is_file():
            raise CheckpointError(f"{folder} has no checkpoint ({path} does not exist): a run writes one at its "
                                  "end, when interrupted, and every --checkpoint-every steps")
        header = json.loads(path.read_text())
        if header.get("format") != FORMAT:
            raise CheckpointError(f"{path} has checkpoint format {header.get('format')}; this dolfinx-dem "
                                  f"{package_version()} reads format {FORMAT}")
        return header

    return call_on_root(comm, read)


def read_state(folder: pathlib.Path, comm: MPI.Comm, header: Mapping, keys: np.ndarray, centres: np.ndarray,
               tolerance: float, cell_arrays: Mapping[str, tuple] | None = None) -> dict[str, np.ndarray]:
    """The vectors of the checkpoint and its arrays ``cell_arrays`` (name: shape of a cell's row)
    for this process's cells ``keys`` (in their order), whatever the number of processes that
    wrote it; the stored barycentres must lie within ``tolerance`` of ``centres``."""
    data = pathlib.Path(folder) / DIRECTORY / header["data"]
    cell_arrays = dict(cell_arrays or {})
    stored = {name: [] for name in ("key", "centre", *VECTORS, *cell_arrays)}
    for r in range(comm.rank, header["processes"], comm.size):
        with np.load(data / f"cells-{r}.npz") as f:
            for name in stored:
                stored[name].append(f[name])
    # a process may read no file (more processes now than then): empty rows of the right shapes
    empty = ({name: np.zeros((0,) + centres.shape[1:]) for name in stored} | {"key": np.zeros(0, dtype=np.int64)}
             | {name: np.zeros((0, *shape)) for name, shape in cell_arrays.items()})
    stored = {name: np.concatenate(a) if a else empty[name] for name, a in stored.items()}
    stored["key"] = stored["key"].astype(np.int64)
    n_global = comm.allreduce(len(keys), op=MPI.SUM)
    values = _redistribute(comm, stored, np.asarray(keys, dtype=np.int64), n_global)
    far = np.linalg.norm(values["centre"] - centres, axis=1).max(initial=0.0) if len(keys) else 0.0
    if comm.allreduce(far, op=MPI.MAX) > tolerance:
        raise CheckpointError(f"the cells of the checkpoint in {folder} are not those of this mesh (a barycentre "
                              f"moved by {far:.3g}): it belongs to another mesh")
    return {name: values[name] for name in (*VECTORS, *cell_arrays)}


def read_local(folder: pathlib.Path, comm: MPI.Comm, header: Mapping, keys: np.ndarray) -> dict | None:
    """This process's ``local`` arrays of the checkpoint if the partition is the one that wrote
    it (same number of processes, the same owned cells ``keys`` on every process), else None
    (the same answer on every process)."""
    data = pathlib.Path(folder) / DIRECTORY / header["data"]
    same = header["processes"] == comm.size
    if same:
        with np.load(data / f"cells-{comm.rank}.npz") as f:
            same = np.array_equal(f["key"], keys)
    if not comm.allreduce(same, op=MPI.LAND):
        return None
    with np.load(data / f"local-{comm.rank}.npz") as f:
        return dict(f)


def _redistribute(comm: MPI.Comm, stored: Mapping[str, np.ndarray], wanted: np.ndarray,
                  n_global: int) -> dict[str, np.ndarray]:
    """The rows of ``stored`` (arrays whose first axis follows ``stored["key"]``, this
    process's share of all cells) at the keys ``wanted``: every key has a home process
    (key * P // n_global), the stored rows go home, the wanted keys ask there."""
    P = comm.size
    names = [n for n in stored if n != "key"]

    def by_home(keys):
        home = np.asarray(keys, dtype=np.int64) * P // max(n_global, 1)
        order = np.argsort(home, kind="stable")
        return order, np.searchsorted(home[order], np.arange(P + 1))

    order, bounds = by_home(stored["key"])
    parts = comm.alltoall([{n: stored[n][order[bounds[p]:bounds[p + 1]]] for n in stored} for p in range(P)])
    home = {n: np.concatenate([part[n] for part in parts]) for n in stored}
    sort = np.argsort(home["key"])
    home = {n: a[sort] for n, a in home.items()}

    order, bounds = by_home(wanted)
    asked = comm.alltoall([wanted[order[bounds[p]:bounds[p + 1]]] for p in range(P)])
    answers = []
    for keys in asked:
        at = np.searchsorted(home["key"], keys)
        found = (at < len(home["key"])) & (home["key"][np.minimum(at, len(home["key"]) - 1)] == keys) \
            if len(home["key"]) else np.zeros(len(keys), dtype=bool)
        if not found.all():
            raise CheckpointError(f"the checkpoint holds no cell of input index {keys[~found][0]}: it belongs to "
                                  "another mesh")
        answers.append({n: home[n][at] for n in names})
    answers = comm.alltoall(answers)
    out = {}
    for n in names:
        values = np.concatenate([a[n] for a in answers]) if answers else np.zeros(0)
        out[n] = np.empty_like(values)
        out[n][order] = values
    return out
