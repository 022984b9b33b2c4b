"""Scenes, the runner and the command line: the output contract, bad input, MPI agreement."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import cli, io, model, scenes, simulation
from dolfinx_dem.errors import InstabilityError

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")
SHORT = {"bar-wave": 0.5, "cantilever": 0.05, "block": 0.05, "bar-impact": 0.2, "bar-bounce": 0.25,
         "two-disks": 0.1, "billiard": 0.5, "two-balls": 0.05, "cradle": 0.05, "ball-drop": 0.05}
#: Coarser meshes for the tests of the multi-body scenes.
COARSE = {"two-disks": {"mesh.h": 0.03}, "billiard": {"mesh.h": 0.25}, "two-balls": {"mesh.h": 0.06},
          "cradle": {"mesh.h": 0.08}, "ball-drop": {"mesh.h": 0.07}}
SUMMARY_KEYS = {"scene", "method", "n_cells", "n_steps", "dt", "wall_time_s", "pseudo_energy_rel_drift", "stable"}


def _series(path):
    return np.genfromtxt(path, delimiter=",", names=True)


@pytest.mark.mpi
@pytest.mark.parametrize("name", sorted(SHORT))
def test_builtin_scene_output_contract(name, tempdir):
    scene = scenes.load(name, {"time.end": SHORT[name], **COARSE.get(name, {})})
    out = pathlib.Path(tempdir) / name
    summary = simulation.run(scene, out, MPI.COMM_WORLD, quiet=True)
    assert SUMMARY_KEYS <= set(summary)
    assert summary["stable"] and summary["pseudo_energy_rel_drift"] < 1e-12
    assert summary["n_steps"] * summary["dt"] == pytest.approx(SHORT[name], rel=1e-12)
    if MPI.COMM_WORLD.rank == 0:
        assert not (out / io.INCOMPLETE).exists()
        assert {p.name for p in out.iterdir()} <= set(io.RUN_FILES)  # what --overwrite removes
        assert summary["status"] == "completed" and (out / "checkpoint" / "checkpoint.json").is_file()
        for f in ("summary.json", "series.csv", "solution.xdmf", "solution.h5", "final.png"):
            assert (out / f).stat().st_size > 0, f
        data = _series(out / "series.csv")
        assert data.dtype.names[:6] == model.SERIES_COLUMNS
        assert len(data) == summary["n_steps"] + 1
        assert json.loads((out / "summary.json").read_text())["n_cells"] == summary["n_cells"]
        xdmf = (out / "solution.xdmf").read_text()
        for field in ("displacement", "velocity", "von_mises"):
            assert f'Name="{field}"' in xdmf
        assert ('Name="body"' in xdmf) == (name in COARSE)  # body numbers with several bodies


def test_bar_wave_matches_the_exact_standing_wave(tempdir):
    """bar-wave is the first mode of a clamped-free bar: tip u = 0.01 cos(pi t / 2)."""
    scene = scenes.load("bar-wave", {"time.end": 4.0})
    summary = simulation.run(scene, pathlib.Path(tempdir) / "bar", MPI.COMM_WORLD, quiet=True)
    data = _series(pathlib.Path(tempdir) / "bar" / "series.csv")
    exact = 0.01 * np.cos(np.pi * data["t"] / 2)
    error = np.abs(data["tip_u"] - exact).max() / 0.01
    assert error < 2e-3, error  # N = 100; a wrong mass or stiffness scale shifts the period by O(1)
    assert summary["pseudo_energy_rel_drift"] < 1e-12


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("name", ["cantilever", "block", "bar-impact", "two-disks"])
def test_two_processes_give_the_same_series(name, tmp_path):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_vader_single_copy_mechanism="none")
    sets = [f"time.end={SHORT[name] * 4}"] + [f"{k}={v}" for k, v in COARSE.get(name, {}).items()]
    options = [x for s in sets for x in ("--set", s)]
    subprocess.run([CLI, "run", name, *options, "--out", str(tmp_path / "1"), "--quiet"], check=True, env=env)
    subprocess.run(["mpirun", "-n", "2", "--oversubscribe", CLI, "run", name, *options, "--out",
                    str(tmp_path / "2"), "--quiet"], check=True, env=env)
    a, b = _series(tmp_path / "1" / "series.csv"), _series(tmp_path / "2" / "series.csv")
    assert a.shape == b.shape
    energy = max(np.abs(a[c]).max() for c in ("kinetic", "elastic", "stabilisation"))
    for column in a.dtype.names:
        # Energies relative to the mechanical energy scale (the pseudo-energy of a body released
        # from rest is ~0, the stabilisation energy of a smooth field tiny), probes to their own.
        # Momenta of colliding bodies are ~0 (rounding): compare them to 1 kg m/s, the order
        # of the momentum of each disc of two-disks.
        scale = energy if column in model.SERIES_COLUMNS[1:] else np.abs(a[column]).max()
        if column.startswith("reaction_"):  # to the largest reaction component (one can be pure rounding)
            scale = max(np.abs(a[c]).max() for c in a.dtype.names if c.startswith("reaction_"))
        if column.startswith("momentum_"):
            scale = max(scale, 1.0)
        assert np.abs(a[column] - b[column]).max() <= 1e-12 * scale, column
    assert json.loads((tmp_path / "2" / "summary.json").read_text())["processes"] == 2


def test_instability_stops_the_run_with_a_clear_error(tempdir):
    scene = scenes.load("bar-wave", {"time.cfl": 1.2, "time.end": 20.0})
    out = pathlib.Path(tempdir) / "unstable"
    with pytest.raises(InstabilityError, match=r"unstable at step \d+ .*dt = .*Reduce the time step"):
        simulation.run(scene, out, MPI.COMM_WORLD, quiet=True)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stable"] is False and summary["suggested_dt"] < summary["dt"]
    assert (out / io.INCOMPLETE).exists() and (out / io.ERROR).exists()
    assert np.all(np.isfinite(_series(out / "series.csv")["pseudo_energy"]))


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"mesh.foo": 1}, "'mesh.foo' is unknown"),
        ({"material.nu": 0.5}, "Poisson ratio nu"),
        ({"material.E": -1.0}, "Young.s modulus E must be > 0"),
        ({"initial.velocity": ["foo * x"]}, "unknown names \\[.foo.\\]"),
        ({"probes": [{"name": "p"}]}, "probes\\[0\\].point. is missing"),
        ({"time": {"end": 1.0, "dt": 0.03}}, "must be a multiple"),
        ({"material.rho": 0.0}, "density rho must be > 0"),
        ({"time.dt": -0.1}, "'time.dt' must be > 0"),
        ({"method": "dem-C"}, "'method' must be a string"),
        ({"mesh.n": "many"}, "'mesh.n' must be a list"),
        ({"initial.velocity": ["sin(x"]}, "not a valid expression"),
    ],
)
def test_bad_scene_values_are_rejected(overrides, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        scene = scenes.load("bar-wave", overrides)
        simulation.run(scene, tmp_path / "bad", MPI.COMM_SELF, quiet=True)


@pytest.mark.parametrize("names, message", [
    (["tip", "tip"], "probe names must be unique"),
    (["kinetic"], "probe names \\['kinetic'\\] are series columns"),
    (["contact_pressure"], "probe names \\['contact_pressure'\\] are series columns"),
    (["contact_force_obstacle0_x"], "probe names \\['contact_force_obstacle0_x'\\] are series columns"),
])
def test_probe_names_that_clash_with_a_series_column_are_rejected(names, message, tmp_path):
    """Probe names are series columns: a clash with any other column (energies, contact) is an
    error before the output folder is made."""
    probes = [{"name": name, "point": [10.0], "component": 0} for name in names]
    scene = scenes.load("bar-impact", {"probes": probes})
    with pytest.raises(scenes.SceneError, match=message):
        simulation.run(scene, tmp_path / "bad", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "bad").exists()


def test_both_dt_and_cfl_or_an_unknown_boundary_are_rejected(tmp_path):
    with pytest.raises(scenes.SceneError, match="exactly one of 'time.dt' and 'time.cfl'"):
        scenes.load("bar-wave", {"time.dt": 0.01})
    scene = scenes.load("cantilever", {"dirichlet": [{"boundary": "nowhere"}]})
    with pytest.raises(scenes.SceneError, match="unknown boundary 'nowhere'"):
        simulation.run(scene, tmp_path / "b", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "b").exists()  # checked before the output folder is made


def test_stable_step_from_the_bound_or_the_eigenvalue(tmp_path):
    """time.cfl is a fraction of the bound's stable step by default, of SLEPc's with
    time.stable_step = "eigenvalue" (for stability studies); the key needs time.cfl."""
    dts = {}
    for method in ("bound", "eigenvalue"):
        scene = scenes.load("cantilever", {"time.end": 0.01, "time.stable_step": method})
        dts[method] = simulation.run(scene, tmp_path / method, MPI.COMM_SELF, quiet=True)["dt"]
    dem = simulation.build(scenes.load("cantilever"), MPI.COMM_SELF).dem
    for method, dt in dts.items():
        assert 0.45 * dem.stable_time_step(method) < dt <= 0.5 * dem.stable_time_step(method)
    assert dts["bound"] < dts["eigenvalue"]
    with pytest.raises(scenes.SceneError, match="'time.stable_step' goes with 'time.cfl'"):
        scenes.load("bar-impact", {"time.stable_step": "eigenvalue"})
    with pytest.raises(scenes.SceneError, match="one of bound, eigenvalue"):
        scenes.load("cantilever", {"time.stable_step": "lanczos"})


@pytest.mark.skip_in_parallel
def test_cli(tmp_path):
    listing = subprocess.run([CLI, "list"], capture_output=True, text=True, check=True).stdout
    assert {"bar-wave", "cantilever", "block", "bar-impact", "bar-bounce"} <= {
        line.split()[0] for line in listing.splitlines()}

    missing = tmp_path / "scene.toml"
    missing.write_text('[mesh]\ntype = "file"\npath = "nope.msh"\n[material]\nE = 1.0\nnu = 0.3\n'
                       'rho = 1.0\n[time]\nend = 1.0\ndt = 0.1\n')
    r = subprocess.run([CLI, "run", str(missing), "--out", str(tmp_path / "m")], capture_output=True, text=True)
    assert r.returncode == 2 and "nope.msh" in r.stderr

    r = subprocess.run([CLI, "run", "no-such-scene"], capture_output=True, text=True)
    assert r.returncode == 2 and "unknown scene 'no-such-scene'" in r.stderr

    r = subprocess.run([CLI, "run", "bar-wave", "--set", "mesh.n=20", "--set", "time.end=0.2",
                        "--out", str(tmp_path / "ok")], capture_output=True, text=True, check=True)
    assert "results in" in r.stdout
    assert json.loads((tmp_path / "ok" / "summary.json").read_text())["n_cells"] == 20
    r = subprocess.run([CLI, "show", str(tmp_path / "ok")], capture_output=True, text=True, check=True)
    assert (tmp_path / "ok" / "energies.png").stat().st_size > 0
    assert (tmp_path / "ok" / "probes.png").stat().st_size > 0


@pytest.mark.parametrize(
    "obstacle, message",
    [
        ({"point": [6.0], "normal": [1.0], "boundary": "left"}, "intersects the body at t = 0"),
        ({"point": [0.0], "normal": [1.0], "boundary": "left", "tolerance": -1.0}, "must be >= 0"),
        ({"point": [0.0], "normal": [1.0]}, "'obstacles\\[0\\].boundary' is missing"),
        ({"point": [0.0], "normal": [1.0], "boundary": "nowhere"}, "unknown boundary 'nowhere'"),
    ],
)
def test_bad_obstacles_are_rejected_before_the_run(obstacle, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        scene = scenes.load("bar-impact", {"obstacles": [obstacle]})
        simulation.run(scene, tmp_path / "bad", MPI.COMM_SELF, quiet=True)
    assert not (tmp_path / "bad" / "series.csv").exists()


# -- the output folder, and the command line around a run ----------------------------------------

def _snapshot(folder: pathlib.Path) -> dict:
    """Every file and folder below ``folder`` with its modification time and content."""
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, None if p.is_dir() else p.read_bytes())
            for p in folder.rglob("*")}


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("overwrite", [False, True])
@pytest.mark.parametrize("args, message", [
    (["cantilever", "--set", "mesh.type=file", "--set", "mesh.path=nope.msh"], "mesh file nope.msh does not exist"),
    (["cantilever", "--set", "mesh.type=file", "--set", "mesh.path={quad}", "--set", 'dirichlet=[{boundary="all"}]'],
     "dolfinx_dem needs a simplex mesh (every cell with 3 vertices)"),
    (["bar-impact", "--set", 'obstacles=[{point=[6.0], normal=[1.0], boundary="left"}]'],
     "obstacle 0 intersects the body at t = 0"),
    (["bar-wave", "--set", "dirichlet=[{boundary=9}]"], "boundary 9 (tag 9) has no facet"),
    (["bar-wave", "--set", 'contact={boundary=["right"]}'],
     "contact between deformable bodies is implemented in 2D and 3D, not 1D"),
    (["cantilever", "--set", 'probes=[{name="p", point=[5.0, 0.0], component=1}]'],
     "probe 'p' at [5.0, 0.0] is outside"),
    (["bar-wave", "--set", 'initial.velocity=["0 * x / 0"]'], "is not finite at t = 0"),
    (["two-disks", "--set", "mesh.h=0.05", "--set", 'contact.boundary=["y > 100"]'], "selects no facet"),
])
def test_input_errors_leave_the_output_folder_untouched(args, message, overwrite, tmp_path, monkeypatch, capsys):
    """Before: a missing mesh file, a quadrilateral mesh, an overlapping obstacle, an empty tag
    or contact between 1D bodies were found after the folder was made, and left INCOMPLETE and
    error.txt (next to the old run's files). Now everything is checked first, even with
    --overwrite, which only removes the old run once the new one is ready to start; without it
    a folder of other files gets no INCOMPLETE either."""
    import dolfinx.io
    import dolfinx.mesh

    monkeypatch.chdir(tmp_path)
    quad = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 2, 2, dolfinx.mesh.CellType.quadrilateral)
    with dolfinx.io.XDMFFile(MPI.COMM_SELF, str(tmp_path / "quad.xdmf"), "w") as f:
        f.write_mesh(quad)
    out = tmp_path / "out"
    out.mkdir()
    # with --overwrite, a folder holding another run; without, a folder holding no run
    for name in ("summary.json", "series.csv", "animation.gif", "notes.txt") if overwrite else ("notes.txt",):
        (out / name).write_text(f"an earlier {name}")
    before = _snapshot(out)
    args = [a.replace("{quad}", str(tmp_path / "quad.xdmf")) for a in args]
    code = cli.main(["run", *args, "--out", str(out), "--quiet"] + (["--overwrite"] if overwrite else []))
    assert code == 2
    assert message in capsys.readouterr().err
    assert _snapshot(out) == before


@pytest.mark.skip_in_parallel
def test_a_folder_holding_a_run_needs_overwrite_and_keeps_no_stale_file(tmp_path, capsys):
    out = tmp_path / "out"
    run = ["run", "bar-wave", "--set", "time.end=0.1", "--out", str(out), "--quiet"]
    assert cli.main([*run, "--set", "output.animation=true", "--set", "output.every=5"]) == 0
    assert (out / "animation.gif").stat().st_size > 0
    assert cli.main(["show", str(out)]) == 0 and (out / "energies.png").exists()
    capsys.readouterr()
    before = _snapshot(out)
    assert cli.main(run) == 2
    assert (f"dolfinx-dem: error: output folder {out} holds another run (summary.json, series.csv, solution.xdmf, "
            "solution.h5, final.png, animation.gif, energies.png, probes.png, checkpoint): pass --overwrite to "
            f"replace it (its files are removed first), or `dolfinx-dem resume {out}` to continue it") \
        in capsys.readouterr().err
    assert _snapshot(out) == before
    (out / "notes.txt").write_text("mine")
    assert cli.main([*run, "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["checkpoint", "final.png", "notes.txt", "series.csv",
                                                     "solution.h5", "solution.xdmf", "summary.json"]


@pytest.mark.skip_in_parallel
def test_show_survives_a_closed_pipe_and_says_what_a_folder_holds(tmp_path):
    """``dolfinx-dem show DIR | head -3`` crashed: PETSc caught SIGPIPE and aborted MPI."""
    out = tmp_path / "out"
    subprocess.run([CLI, "run", "bar-wave", "--set", "time.end=0.05", "--out", str(out), "--quiet"], check=True)
    process = subprocess.Popen([CLI, "show", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    process.stdout.close()  # the reader has gone before the first line
    stderr = process.stderr.read()
    assert process.wait(timeout=120) == 0, stderr
    assert "PETSC ERROR" not in stderr and "Broken pipe" not in stderr and stderr == ""
    assert (out / "energies.png").stat().st_size > 0 and (out / "probes.png").stat().st_size > 0
    (out / "INCOMPLETE").write_text("")
    (out / "error.txt").write_text("boom")
    shown = subprocess.run([CLI, "show", str(out)], capture_output=True, text=True, check=True).stdout
    assert shown.startswith(f"INCOMPLETE: this run did not finish (it failed, see {out / 'error.txt'})")


@pytest.mark.skip_in_parallel
def test_the_first_form_compilation_prints_no_compiler_output(tmp_path):
    """A fresh JIT cache (HOME) makes DOLFINx compile its forms, which printed pages of
    ``INFO:root:running build_ext`` and gcc command lines."""
    env = dict(os.environ, HOME=str(tmp_path / "home"))
    r = subprocess.run([CLI, "run", "bar-wave", "--set", "time.end=0.05", "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, env=env, check=True)
    assert list((tmp_path / "home" / ".cache" / "fenics").iterdir())  # it did compile
    assert r.stderr == "", r.stderr[:500]
    assert r.stdout.startswith("bar-wave: 11 steps")  # time.cfl = 0.5 of the bound's stable step


@pytest.mark.skip_in_parallel
def test_a_moving_boundary_is_reported_as_not_conservative(tmp_path):
    """Before: "pseudo-energy drift 1.00e+00", read as a failure. The data's work W^n is counted
    (series columns work, balance): the balance E^n - W^n holds to rounding."""
    r = subprocess.run([CLI, "run", "bar-wave", "--set", "time.end=0.1", "--set",
                        'dirichlet=[{boundary="left", value=["0.01 * t"], time_dependent=true}]', "--out",
                        str(tmp_path / "out")], capture_output=True, text=True, check=True)
    assert "not conservative (time-dependent data): energy balance error (work counted)" in r.stdout
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["conservative"] is False and summary["pseudo_energy_rel_drift"] < 1e-13
    series = _series(tmp_path / "out" / "series.csv")
    assert np.abs(series["work"]).max() > 1e-3 * np.abs(series["elastic"]).max()


@pytest.mark.skip_in_parallel
def test_an_error_on_one_process_only_aborts_instead_of_hanging(tmp_path):
    script = tmp_path / "one.py"
    script.write_text(
        "import sys\nfrom mpi4py import MPI\nfrom dolfinx_dem import cli, simulation\n"
        "from dolfinx_dem.errors import InputError\n\n"
        "def run(*args, **kwargs):\n"
        "    if MPI.COMM_WORLD.rank == 1:\n"
        "        raise InputError('found on process 1 only')\n"
        "    MPI.COMM_WORLD.barrier()  # the others wait in a collective\n\n"
        "simulation.run = run\n"
        f"sys.exit(cli.main(['run', 'bar-wave', '--out', '{tmp_path / 'out'}', '--quiet']))\n"
    )
    env = dict(
        os.environ,
        OMPI_ALLOW_RUN_AS_ROOT="1",
        OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
        OMPI_MCA_btl_vader_single_copy_mechanism="none",
    )
    r = subprocess.run(
        ["mpirun", "-n", "2", "--oversubscribe", sys.executable, str(script)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert r.returncode != 0
    assert "dolfinx-dem: error on process 1 only: found on process 1 only" in r.stderr
