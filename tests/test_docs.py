"""The documentation against the code: every error message of docs/scenes.md is the one the
command prints, the lists of built-in scenes, top-level keys, summary keys and demos are
complete, and docs/theory.md describes what is implemented."""

import contextlib
import io
import pathlib
import re
import shlex

import pytest
from mpi4py import MPI

from dolfinx_dem import cli, scenes, simulation

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENES_MD = (ROOT / "docs" / "scenes.md").read_text()

pytestmark = pytest.mark.skip_in_parallel


def _error_table():
    """(command, stage, message) rows of the table in "Errors for bad input"."""
    section = SCENES_MD[SCENES_MD.index("## Errors for bad input"):]
    rows = re.findall(r"^\| `(.+?)` \| (load|build|run) \| `(.+)` \|$", section, re.M)
    assert len(rows) >= 20
    return rows


def _materials_example() -> str:
    """The TOML example of the ``[[materials]]`` section (``materials.toml`` of the error table)."""
    section = SCENES_MD[SCENES_MD.index("### `[[materials]]`"):]
    return re.search(r"```toml\n(.*?)```", section, re.S).group(1)


def test_the_materials_example_runs(tmp_path):
    """The ``[[materials]]`` example runs, two materials and contact, with its energy conserved."""
    (tmp_path / "materials.toml").write_text(_materials_example())
    summary = simulation.run(scenes.load(str(tmp_path / "materials.toml")), tmp_path / "out", MPI.COMM_SELF, quiet=True)
    assert summary["pseudo_energy_rel_drift"] < 1e-13


@pytest.mark.parametrize("command, stage, message", _error_table(), ids=[r[0][:40] for r in _error_table()])
def test_the_error_table_shows_what_the_command_prints(command, stage, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "materials.toml").write_text(_materials_example())
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr):
        code = cli.main(["run", *shlex.split(command), "--quiet"])
    first = stderr.getvalue().strip().splitlines()[0]
    expected = message.replace("/work/", f"{tmp_path}/")
    pattern = ".*".join(re.escape(part) for part in expected.split("..."))
    assert re.fullmatch(pattern, first), f"\n documented: {expected}\n printed:    {first}"
    assert code == (1 if "MEMM is unstable" in message or "is not resolved" in message else 2)
    results = list((tmp_path / "results").glob("*")) if (tmp_path / "results").exists() else []
    if stage in ("load", "build"):  # the output folder is not touched
        assert results == []
    else:
        assert len(results) == 1 and (results[0] / "INCOMPLETE").exists() and (results[0] / "error.txt").exists()


def test_the_built_in_scenes_and_top_level_keys_are_all_documented():
    section = SCENES_MD[SCENES_MD.index("## Built-in scenes"):SCENES_MD.index("## The command line")]
    assert set(re.findall(r"\*\*`([a-z0-9-]+)`\*\*", section)) == set(scenes.builtin_names())
    top = SCENES_MD[SCENES_MD.index("### Top level"):SCENES_MD.index("### `[mesh]`")]
    assert {k for k in scenes.SCHEMA if f"`{k}`" not in top} == set()


def test_every_summary_key_and_series_column_is_documented(tmp_path):
    documented = set(re.findall(r"`([a-z_<>]+)`", SCENES_MD))
    keys, columns = set(), set()
    for name, overrides in (("bar-wave", {"time.end": 0.05}), ("bar-impact", {"time.end": 0.05}),
                            ("two-disks", {"mesh.h": 0.05, "time.end": 0.05})):
        keys |= set(simulation.run(scenes.load(name, overrides), tmp_path / name, MPI.COMM_SELF, quiet=True))
        columns |= set((tmp_path / name / "series.csv").read_text().splitlines()[0].split(","))
    assert "conservative" in keys
    assert keys - documented == set()
    assert {"contact_pressure", "contact_force_obstacle0_x", "contact_force_0_1_y", "reaction_0_x"} <= columns
    # per obstacle k, body pair i < j and Dirichlet condition i: documented as patterns
    patterns = {re.sub(r"^reaction_\d+_", "reaction_<i>_",
                       re.sub(r"_(\d+)_(\d+)_", "_<i>_<j>_", re.sub(r"obstacle\d+", "obstacle<k>", c))) for c in columns}
    suffixes = {re.sub(r"_[xyz]$", "_x", c) for c in patterns if "<" in c}  # `..._x`, `_y`, `_z`
    assert ({c for c in patterns if "<" not in c} | suffixes) - documented == set()


def test_every_demo_is_in_the_demos_readme():
    readme = (ROOT / "demos" / "README.md").read_text()
    demos = sorted(p.name for p in (ROOT / "demos").glob("demo_*.py"))
    assert "demo_contact_bodies.py" in demos
    assert [d for d in demos if f"[`{d}`]({d})" not in readme] == []


def test_theory_describes_what_is_implemented():
    theory = (ROOT / "docs" / "theory.md").read_text()
    assert "not implemented yet" not in theory.lower()  # contact between bodies is implemented
    assert "$-Ku$" not in theory  # the force is -Q^T(Qw + q) + f, in factored form
    for section in ("Contact between deformable bodies", "Rigid obstacles and contact between bodies together"):
        assert f"## {section}" in theory
