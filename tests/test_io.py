import json
import math
import pathlib
import xml.etree.ElementTree as ElementTree

import numpy as np
import pytest
from mpi4py import MPI

import dolfinx.fem
import dolfinx.io

from dolfinx_dem import _compat, io, meshes


def shared_path(tmp_path) -> pathlib.Path:
    """Rank 0's tmp_path, on every rank."""
    return MPI.COMM_WORLD.bcast(tmp_path, root=0)


def xdmf_times(path: pathlib.Path) -> dict[str, list[float]]:
    """Time values of each temporal collection (function) of an XDMF file."""
    root = ElementTree.parse(path).getroot()
    return {
        grid.get("Name"): [float(t.get("Value")) for t in grid.iter("Time")]
        for grid in root.iter("Grid")
        if grid.get("CollectionType") == "Temporal"
    }


@pytest.mark.mpi
def test_solution_writer(tmp_path):
    comm = MPI.COMM_WORLD
    directory = shared_path(tmp_path)
    mesh, _, _ = meshes.create_rectangle(comm, [0, 0], [1, 1], [4, 4])
    u = dolfinx.fem.Function(_compat.create_vector_space(mesh, "DG", 0))
    s = dolfinx.fem.Function(_compat.create_scalar_space(mesh, "DG", 0))
    times = [0.0, 0.5, 1.0]
    with io.SolutionWriter(comm, directory, mesh) as writer:
        for t in times:
            u.x.array[:] = t
            s.x.array[:] = 2 * t
            writer.write(t, {"displacement": u, "von_mises": s})
    assert u.name == "displacement" and s.name == "von_mises"
    assert (directory / "solution.h5").is_file()
    assert xdmf_times(directory / "solution.xdmf") == {"displacement": times, "von_mises": times}
    with dolfinx.io.XDMFFile(comm, str(directory / "solution.xdmf"), "r") as xdmf:
        mesh2 = xdmf.read_mesh(name="mesh")
    assert mesh2.topology.index_map(2).size_global == 32


def test_solution_writer_errors(tmp_path):
    comm = MPI.COMM_WORLD
    mesh, _, _ = meshes.create_interval(comm, 4, 0.0, 1.0)
    other, _, _ = meshes.create_interval(comm, 4, 0.0, 1.0)
    u = dolfinx.fem.Function(_compat.create_scalar_space(other, "DG", 0))
    with pytest.raises(FileNotFoundError, match="nowhere"):
        io.SolutionWriter(comm, tmp_path / "nowhere", mesh)
    with io.SolutionWriter(comm, tmp_path, mesh) as writer:
        with pytest.raises(ValueError, match="not defined on the writer's mesh"):
            writer.write(0.0, {"u": u})
        with pytest.raises(ValueError, match="at least one"):
            writer.write(0.0, {})
        with pytest.raises(ValueError, match="finite"):
            writer.write(math.nan, {"u": u})
        with pytest.raises(ValueError, match="'u' must be a dolfinx.fem.Function"):
            writer.write(0.0, {"u": u.x.array})


@pytest.mark.mpi
def test_series_writer_round_trip(tmp_path):
    comm = MPI.COMM_WORLD
    path = shared_path(tmp_path) / "series.csv"
    rows = [(0.0, 1 / 3, -1e-300), (0.1, math.pi, 2.5e300), (0.2, np.float64(1 / 7), 0)]
    with io.SeriesWriter(comm, path, ["t", "kinetic_energy", "gap"], flush_every=2) as series:
        series.write(rows[0])
        series.write({"gap": rows[1][2], "t": rows[1][0], "kinetic_energy": rows[1][1]})
        series.write(rows[2])
    comm.barrier()
    assert path.read_text().splitlines()[0] == "t,kinetic_energy,gap"
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    assert np.array_equal(data, np.array(rows, dtype=np.float64))  # bit-exact round trip


def test_series_writer_errors(tmp_path):
    comm = MPI.COMM_WORLD
    with pytest.raises(ValueError, match="unique"):
        io.SeriesWriter(comm, tmp_path / "a.csv", ["t", "t"])
    with pytest.raises(ValueError, match="'a,b'"):
        io.SeriesWriter(comm, tmp_path / "a.csv", ["t", "a,b"])
    with pytest.raises(ValueError, match="flush_every"):
        io.SeriesWriter(comm, tmp_path / "a.csv", ["t"], flush_every=0)
    with pytest.raises(FileNotFoundError):
        io.SeriesWriter(comm, tmp_path / "no" / "a.csv", ["t"])
    with io.SeriesWriter(comm, tmp_path / "a.csv", ["t", "e"]) as series:
        with pytest.raises(ValueError, match="2 columns"):
            series.write([1.0])
        with pytest.raises(ValueError, match="do not match"):
            series.write({"t": 1.0, "E": 2.0})


@pytest.mark.mpi
def test_write_summary(tmp_path):
    comm = MPI.COMM_WORLD
    path = shared_path(tmp_path) / "summary.json"
    data = {"steps": np.int64(12), "dt": np.float64(0.25), "energy": np.array([1.0, 2.0]), "a": "x"}
    io.write_summary(path, comm, data)
    text = path.read_text()
    assert json.loads(text) == {"steps": 12, "dt": 0.25, "energy": [1.0, 2.0], "a": "x"}
    assert text.index('"a"') < text.index('"dt"') < text.index('"energy"') < text.index('"steps"')
    assert text.startswith('{\n  "a"')
    with pytest.raises(TypeError, match="cannot write object"):
        io.write_summary(path, comm, {"bad": object()})


def test_write_summary_is_strict_json_without_nan(tmp_path):
    """NaN and inf have no strict-JSON form (Python's json writes bare NaN / Infinity, which
    strict parsers reject): they are written as null."""
    path = tmp_path / "summary.json"
    data = {"drift": float("nan"), "gap": np.float64(-np.inf), "values": np.array([1.0, np.nan]),
            "nested": {"t": [np.inf, 2]}, "ok": 1.5}
    io.write_summary(path, MPI.COMM_SELF, data)

    def reject(constant):
        raise ValueError(f"not strict JSON: {constant}")

    assert json.loads(path.read_text(), parse_constant=reject) == {
        "drift": None, "gap": None, "values": [1.0, None], "nested": {"t": [None, 2]}, "ok": 1.5}


@pytest.mark.mpi
def test_output_directory_success(tmp_path):
    comm = MPI.COMM_WORLD
    path = shared_path(tmp_path) / "run" / "out"
    with io.OutputDirectory(path, comm) as out:
        assert out == path
        assert (path / io.INCOMPLETE).is_file()
        io.write_summary(out / "summary.json", comm, {"ok": True})
    assert sorted(p.name for p in path.iterdir()) == ["summary.json"]


@pytest.mark.mpi
def test_output_directory_failure(tmp_path):
    comm = MPI.COMM_WORLD
    path = shared_path(tmp_path) / "out"
    with pytest.raises(RuntimeError, match="solver diverged"):
        with io.OutputDirectory(path, comm):
            raise RuntimeError("solver diverged")
    comm.barrier()
    assert (path / io.INCOMPLETE).is_file()
    error = (path / io.ERROR).read_text()
    assert error.count("RuntimeError: solver diverged") == comm.size
    # A later successful run in the same directory clears both.
    comm.barrier()
    with io.OutputDirectory(path, comm):
        pass
    assert list(path.iterdir()) == []


def test_output_directory_not_a_directory(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(NotADirectoryError, match="file"):
        with io.OutputDirectory(tmp_path / "file", MPI.COMM_WORLD):
            pass


@pytest.mark.mpi
def test_call_on_root_raises_everywhere():
    comm = MPI.COMM_WORLD

    def fail():
        raise KeyError("only rank 0 runs this")

    with pytest.raises(KeyError, match="only rank 0"):
        io.call_on_root(comm, fail)
    assert io.call_on_root(comm, lambda: comm.rank + 41) == 41
