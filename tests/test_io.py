import json
import math
import pathlib
import xml.etree.ElementTree as ElementTree

import dolfinx.fem
import dolfinx.io
import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import _compat, io, meshes
from dolfinx_dem.errors import OutputError, StateError


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
    assert (directory / "solution.h5").is_file() and (directory / "solution" / "000002.h5").is_file()
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


def test_write_summary_killed_while_writing_keeps_the_previous_one(tmp_path, monkeypatch):
    """A run killed while it writes summary.json (at its end, or when interrupted) leaves the
    previous summary whole: a resume reads it (the kill loop met a truncated one, an empty file
    that a resume could not parse)."""
    path = tmp_path / "summary.json"
    io.write_summary(path, MPI.COMM_SELF, {"status": "interrupted"})
    write_text = pathlib.Path.write_text

    def killed(self, text, *args, **kwargs):  # half the text is on disk when the process dies
        write_text(self, text[: len(text) // 2], *args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(pathlib.Path, "write_text", killed)
    with pytest.raises(KeyboardInterrupt):
        io.write_summary(path, MPI.COMM_SELF, {"status": "completed", "steps": 10})
    monkeypatch.undo()
    assert json.loads(path.read_text()) == {"status": "interrupted"}
    io.write_summary(path, MPI.COMM_SELF, {"status": "completed"})
    assert json.loads(path.read_text()) == {"status": "completed"}
    assert not path.with_suffix(".json.tmp").exists()


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
    # A later run in the same directory needs overwrite, then clears both.
    comm.barrier()
    with pytest.raises(io.OutputFolderError, match="holds another run \\(INCOMPLETE, error.txt\\): pass --overwrite"):
        io.OutputDirectory(path, comm).check()
    with io.OutputDirectory(path, comm, overwrite=True):
        pass
    assert list(path.iterdir()) == []


@pytest.mark.mpi
def test_output_directory_refuses_another_run_and_overwrite_removes_only_run_files(tmp_path):
    comm = MPI.COMM_WORLD
    path = shared_path(tmp_path) / "out"
    if comm.rank == 0:
        path.mkdir()
        (path / "notes.txt").write_text("mine")
    comm.barrier()
    with io.OutputDirectory(path, comm):  # a folder without a run is fine
        io.write_summary(path / "summary.json", comm, {"old": True})
        if comm.rank == 0:
            (path / "animation.gif").write_text("old")
            (path / "checkpoint").mkdir()
            (path / "checkpoint" / "checkpoint.json").write_text("{}")
    comm.barrier()
    before = sorted(p.name for p in path.iterdir())
    comm.barrier()  # every rank has listed before rank 0's check (a probe folder, the lock) touches the folder
    with pytest.raises(io.OutputFolderError, match="holds another run .*--overwrite.*dolfinx-dem resume"):
        io.OutputDirectory(path, comm).check()
    with pytest.raises(io.OutputFolderError):
        with io.OutputDirectory(path, comm):
            pass
    assert sorted(p.name for p in path.iterdir()) == before  # refused: nothing touched
    comm.barrier()  # every rank has looked before rank 0 removes
    with io.OutputDirectory(path, comm, overwrite=True):
        assert sorted(p.name for p in path.iterdir()) == [io.LOCK, io.INCOMPLETE, "notes.txt"]
    assert sorted(p.name for p in path.iterdir()) == ["notes.txt"]
    assert (path / "notes.txt").read_text() == "mine"


@pytest.mark.mpi
def test_output_directory_resume_and_keep_incomplete(tmp_path):
    comm = MPI.COMM_WORLD
    path = shared_path(tmp_path) / "out"
    output = io.OutputDirectory(path, comm)
    with output:
        io.write_summary(path / "summary.json", comm, {"status": "interrupted"})
        io.call_on_root(comm, lambda: [(path / f).write_text("x") for f in ("series.csv", "energies.png")])
        output.keep_incomplete("interrupted at step 3")
    assert (path / io.INCOMPLETE).read_text() == "interrupted at step 3\n"
    comm.barrier()  # every rank has looked before rank 0 removes
    with io.OutputDirectory(path, comm, resume=True):
        # the derived files go, the series stays to be appended to
        assert sorted(p.name for p in path.iterdir()) == [io.LOCK, io.INCOMPLETE, "series.csv"]
    assert sorted(p.name for p in path.iterdir()) == ["series.csv"]


def test_output_directory_not_a_directory(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(io.OutputFolderError, match="exists and is not a directory"):
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


@pytest.mark.mpi
def test_series_writer_appends_at_a_position(tmp_path):
    comm = MPI.COMM_WORLD
    path = shared_path(tmp_path) / "series.csv"
    with io.SeriesWriter(comm, path, ["t", "e"]) as series:
        series.write([0.0, 1.0])
        position = series.position()
        series.write([1.0, 2.0])  # written after the "checkpoint": dropped on resume
    with io.SeriesWriter(comm, path, ["t", "e"], append_at=position) as series:
        series.write([1.0, 3.0])
    comm.barrier()
    assert path.read_text() == "t,e\n0,1\n1,3\n"
    with pytest.raises(ValueError, match="has the columns 't,e', not 't,x'"):
        io.SeriesWriter(comm, path, ["t", "x"], append_at=position)
    with pytest.raises(ValueError, match="cannot continue at 1000"):
        io.SeriesWriter(comm, path, ["t", "e"], append_at=1000)


@pytest.mark.mpi
def test_solution_writer_resumes_after_a_later_write_and_flushes_every_write(tmp_path):
    """A resumed writer keeps the first output times, drops the later ones (their HDF5 datasets
    too, or DOLFINx could not write those times again), and writes the mesh again for the new
    times; the file reads back between writes (it is closed after each)."""
    comm = MPI.COMM_WORLD
    directory = shared_path(tmp_path)
    mesh, _, _ = meshes.create_rectangle(comm, [0, 0], [1, 1], [4, 4])
    u = dolfinx.fem.Function(_compat.create_vector_space(mesh, "DG", 0))
    with io.SolutionWriter(comm, directory, mesh) as writer:
        for t in (0.0, 0.5, 1.0):
            u.x.array[:] = t
            writer.write(t, {"displacement": u})
            if t == 0.5:
                kept = writer.writes
                with dolfinx.io.XDMFFile(comm, str(directory / "solution.xdmf"), "r") as xdmf:
                    assert xdmf.read_mesh(name="mesh").topology.index_map(2).size_global == 32
    with io.SolutionWriter(comm, directory, mesh, resume_writes=kept) as writer:
        for t in (1.0, 1.5):
            u.x.array[:] = 10 * t
            writer.write(t, {"displacement": u})
        assert writer.writes == 4
    assert xdmf_times(directory / "solution.xdmf") == {"displacement": [0.0, 0.5, 1.0, 1.5]}
    text = (directory / "solution.xdmf").read_text()
    assert text.count("Grid[@Name='mesh_1'][1]") == 2 and 'Grid Name="mesh_1"' in text
    if comm.rank == 0:
        pyvista = _compat.import_pyvista()
        reader = pyvista.get_reader(str(directory / "solution.xdmf"))
        assert reader.time_values == [0.0, 0.5, 1.0, 1.5]
        for t, value in ((0.5, 0.5), (1.0, 10.0), (1.5, 15.0)):
            reader.set_active_time_value(t)
            data = reader.read()["displacement"].cell_data["displacement"]
            assert data.shape[0] == 32 and np.all(data[:, :2] == value)


@pytest.mark.skip_in_parallel
def test_a_resumed_writer_drops_what_a_killed_writer_left_and_never_rewrites_a_listed_file(tmp_path):
    """A writer killed while writing its 4th time leaves hidden files, and one killed between
    renaming a time's file into place and listing it leaves that file unlisted: a writer resumed
    at 2 kept times first lists those 2 (solution.xdmf reads), removes every file it does not
    list, and writes the later times to new files; the listed files are the same files."""
    comm = MPI.COMM_SELF
    mesh, _, _ = meshes.create_rectangle(comm, [0, 0], [1, 1], [2, 2])
    u = dolfinx.fem.Function(_compat.create_vector_space(mesh, "DG", 0))
    with io.SolutionWriter(comm, tmp_path, mesh) as writer:
        for t in (0.0, 0.5, 1.0):
            writer.write(t, {"displacement": u})
    folder = tmp_path / "solution"
    for leftover in (".000003.h5", ".000003.xdmf", "000004.h5"):
        (folder / leftover).write_text("a killed writer's")
    listed = {name: (folder / name).stat().st_ino for name in ("000000.h5", "000001.h5")}
    with pytest.raises(OutputError, match="solution.xdmf lists 3 of the 4 output times of the checkpoint"):
        io.SolutionWriter(comm, tmp_path, mesh, resume_writes=4)
    with io.SolutionWriter(comm, tmp_path, mesh, resume_writes=2) as writer:
        assert sorted(p.name for p in folder.iterdir()) == ["000000.h5", "000001.h5"]
        assert xdmf_times(tmp_path / "solution.xdmf") == {"displacement": [0.0, 0.5]}
        with dolfinx.io.XDMFFile(comm, str(tmp_path / "solution.xdmf"), "r") as xdmf:
            assert xdmf.read_mesh(name="mesh").topology.index_map(2).size_global == 8
        u.x.array[:] = 2.0
        writer.write(1.0, {"displacement": u})
    assert {name: (folder / name).stat().st_ino for name in listed} == listed
    assert sorted(p.name for p in folder.iterdir()) == ["000000.h5", "000001.h5", "000002.h5", "mesh_1.h5"]
    assert xdmf_times(tmp_path / "solution.xdmf") == {"displacement": [0.0, 0.5, 1.0]}
    with pytest.raises(StateError, match="closed"):
        writer.write(1.5, {"displacement": u})


def test_an_overwrite_stopped_midway_leaves_the_folder_marked_incomplete(tmp_path, monkeypatch):
    """The marker is written before the old run's files go, and its checkpoint goes first: a run
    killed meanwhile leaves no folder that looks complete, nor a checkpoint to resume into
    half-removed outputs."""
    out = tmp_path / "out"
    out.mkdir()
    for name in ("summary.json", "series.csv", "solution.xdmf"):
        (out / name).write_text("an old run's")
    (out / "checkpoint").mkdir()
    (out / "checkpoint" / "checkpoint.json").write_text("{}")
    unlink = pathlib.Path.unlink

    def killed(self, *args, **kwargs):
        if self.name == "series.csv":
            raise RuntimeError("killed")
        unlink(self, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "unlink", killed)
    with pytest.raises(RuntimeError, match="killed"):
        with io.OutputDirectory(out, MPI.COMM_SELF, overwrite=True):
            pass
    assert sorted(p.name for p in out.iterdir()) == [io.INCOMPLETE, "series.csv", "solution.xdmf"]


@pytest.mark.skip_in_parallel
def test_a_1d_solution_reads_without_vtk_warnings(tmp_path, capfd):
    """The 1D displacement (one component) is typed Scalar in solution.xdmf: typed Vector, as
    DOLFINx 0.5 writes it, VTK printed "Can not set attribute Vectors. Incorrect number of
    components" at every read (about 80 times per 1D animation)."""
    from dolfinx_dem import scenes, simulation
    from dolfinx_dem.plotting import pyvista

    simulation.run(scenes.load("bar-impact", {"time.end": 0.05, "output.every": 5}), tmp_path / "run", quiet=True)
    capfd.readouterr()
    reader = pyvista.get_reader(str(tmp_path / "run" / "solution.xdmf"))
    for t in reader.time_values:
        reader.set_active_time_value(t)
        u = reader.read()["displacement"].cell_data["displacement"]
        assert len(u) == 100  # one value per cell (DOLFINx 0.9 pads it to three components, typed Vector)
    assert "Can not set attribute" not in capfd.readouterr().err


@pytest.mark.skip_in_parallel
def test_an_unwritable_output_folder_is_an_error_before_the_set_up(capsys):
    """Before: a Python traceback after the set-up, when the folder was made."""
    from dolfinx_dem import cli

    assert cli.main(["run", "bar-wave", "--out", "/proc/dolfinx-dem-test"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dolfinx-dem: error: output folder /proc/dolfinx-dem-test cannot be written (/proc: ")
    assert "Traceback" not in err


@pytest.mark.skip_in_parallel
def test_two_runs_never_write_into_one_folder_at_once(tmp_path):
    """The folder's lock (flock on .lock) is held while a run writes: another run, even with
    --overwrite, is refused before its set-up; once the first ends, the folder is free again. Before,
    two concurrent --overwrite runs wrote into the same files."""
    first = io.OutputDirectory(tmp_path / "out", MPI.COMM_SELF)
    with first:
        second = io.OutputDirectory(tmp_path / "out", MPI.COMM_SELF, overwrite=True)
        with pytest.raises(io.OutputFolderError, match="is in use by a run in progress"):
            second.check()
        with pytest.raises(io.OutputFolderError, match="is in use by a run in progress"):
            second.__enter__()
    with io.OutputDirectory(tmp_path / "out", MPI.COMM_SELF, overwrite=True) as directory:
        assert (directory / io.LOCK).exists()
    assert not (tmp_path / "out" / io.LOCK).exists()
