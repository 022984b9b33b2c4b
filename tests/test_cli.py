"""The command line (cli.py): its commands, their exit codes (2 for bad input, 1 for a run that
stops on instability or unresolved contact), the output folder left untouched on bad input, and
an error on one process aborting every process."""

import json
import os
import pathlib
import subprocess
import sys

import pytest
from helpers import run_command
from mpi4py import MPI

from dolfinx_dem import cli

CLI = str(pathlib.Path(sys.executable).parent / "dolfinx-dem")


def _snapshot(folder: pathlib.Path) -> dict:
    """Every file and folder below ``folder`` with its modification time and content."""
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, None if p.is_dir() else p.read_bytes())
            for p in folder.rglob("*")}


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_cli(tmp_path):
    listing = run_command([CLI, "list"], capture_output=True, text=True, check=True).stdout
    assert {"bar-wave", "cantilever", "block", "bar-impact", "bar-bounce"} <= {
        line.split()[0] for line in listing.splitlines()}

    missing = tmp_path / "scene.toml"
    missing.write_text('[mesh]\ntype = "file"\npath = "nope.msh"\n[material]\nE = 1.0\nnu = 0.3\n'
                       'rho = 1.0\n[time]\nend = 1.0\ndt = 0.1\n')
    r = run_command([CLI, "run", str(missing), "--out", str(tmp_path / "m")], capture_output=True, text=True)
    assert r.returncode == 2 and "nope.msh" in r.stderr

    r = run_command([CLI, "run", "no-such-scene"], capture_output=True, text=True)
    assert r.returncode == 2 and "unknown scene 'no-such-scene'" in r.stderr

    r = run_command([CLI, "run", "bar-wave", "--set", "mesh.n=20", "--set", "time.end=0.2",
                        "--out", str(tmp_path / "ok")], capture_output=True, text=True, check=True)
    assert "results in" in r.stdout
    assert json.loads((tmp_path / "ok" / "summary.json").read_text())["n_cells"] == 20
    r = run_command([CLI, "show", str(tmp_path / "ok")], capture_output=True, text=True, check=True)
    assert (tmp_path / "ok" / "energies.png").stat().st_size > 0
    assert (tmp_path / "ok" / "series.png").stat().st_size > 0


@pytest.mark.skip_in_parallel
@pytest.mark.parametrize("overwrite", [False, True])
@pytest.mark.parametrize("args, message", [
    (["cantilever", "--set", 'mesh={type="file", path="nope.msh"}'], "mesh file nope.msh does not exist"),
    (["cantilever", "--set", 'mesh={type="file", path="{quad}"}', "--set", 'dirichlet=[{boundary="all"}]'],
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


@pytest.mark.slow
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
            "solution, solution.h5, final.png, animation.gif, energies.png, series.png, checkpoint): pass "
            f"--overwrite to replace it (its files are removed first), or `dolfinx-dem resume {out}` to continue it") \
        in capsys.readouterr().err
    assert _snapshot(out) == before
    (out / "notes.txt").write_text("mine")
    assert cli.main([*run, "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["checkpoint", "final.png", "notes.txt", "series.csv",
                                                     "solution", "solution.h5", "solution.xdmf",
                                                     "summary.json"]


@pytest.mark.slow
@pytest.mark.skip_in_parallel
def test_show_survives_a_closed_pipe_and_says_what_a_folder_holds(tmp_path):
    """``dolfinx-dem show DIR | head -3`` crashed: PETSc caught SIGPIPE and aborted MPI."""
    out = tmp_path / "out"
    run_command([CLI, "run", "bar-wave", "--set", "time.end=0.05", "--out", str(out), "--quiet"], check=True)
    process = subprocess.Popen([CLI, "show", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    process.stdout.close()  # the reader has gone before the first line
    stderr = process.stderr.read()
    assert process.wait(timeout=120) == 0, stderr
    assert "PETSC ERROR" not in stderr and "Broken pipe" not in stderr and stderr == ""
    assert (out / "energies.png").stat().st_size > 0 and (out / "series.png").stat().st_size > 0
    (out / "INCOMPLETE").write_text("")
    (out / "error.txt").write_text("boom")
    shown = run_command([CLI, "show", str(out)], capture_output=True, text=True, check=True).stdout
    assert shown.startswith(f"INCOMPLETE: this run did not finish (it failed, see {out / 'error.txt'})")


@pytest.mark.slow
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
    r = run_command(
        ["mpirun", "-n", "2", "--oversubscribe", sys.executable, str(script)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert r.returncode != 0
    assert "dolfinx-dem: error on process 1 only: found on process 1 only" in r.stderr


@pytest.mark.skip_in_parallel
def test_exit_codes_in_process(tmp_path, capsys):
    """``main`` returns 0 for a listing, 2 for bad input (an unknown scene, a bad value: the
    package's InputError family) and 1 for a run that stops on instability, with the reason on
    stderr."""
    assert cli.main(["list"]) == 0
    assert "bar-wave" in capsys.readouterr().out
    assert cli.main(["run", "no-such-scene", "--quiet"]) == 2
    assert "unknown scene 'no-such-scene'" in capsys.readouterr().err
    assert cli.main(["run", "bar-wave", "--set", "material.E=-1", "--quiet", "--out", str(tmp_path / "bad")]) == 2
    assert "Young" in capsys.readouterr().err and not (tmp_path / "bad").exists()
    unstable = ["--set", "time.cfl=1.2", "--set", "time.end=20.0", "--quiet", "--out", str(tmp_path / "unstable")]
    assert cli.main(["run", "bar-wave", *unstable]) == 1
    assert "unstable at step" in capsys.readouterr().err
