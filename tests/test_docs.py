"""The documentation against the code: every error message of docs/scenes.md is the one the
command prints, the lists of built-in scenes, top-level keys, summary keys and demos are
complete, docs/theory.md describes what is implemented, every link and script the documents name
exists, and the benchmark and validation pages quote the figures of their JSON."""

import contextlib
import io
import json
import pathlib
import re
import shlex
import shutil
import sys

import pytest
from helpers import run_command
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
    # the first line after the warnings a run may print before it stops (a 3D impact's crossing facets)
    first = [line for line in stderr.getvalue().strip().splitlines() if not line.startswith("dolfinx-dem: warning:")][0]
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


@pytest.mark.slow
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
    patterns = {
        re.sub(
            r"^reaction_\d+_",
            "reaction_<i>_",
            re.sub(r"_(\d+)_(\d+)_", "_<i>_<j>_", re.sub(r"obstacle\d+", "obstacle<k>", c)),
        )
        for c in columns
    }
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


def _documents():
    """The project's markdown documents: docs/ (recursively), the READMEs, the changelog."""
    return sorted(
        [*(ROOT / "docs").rglob("*.md"), ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "demos" / "README.md"]
    )


def _anchors(page: pathlib.Path) -> set[str]:
    """The anchors of a markdown page's headings, as GitHub makes them."""
    headings = re.findall(r"^#+ (.+)$", page.read_text(), flags=re.M)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in headings}


def test_every_link_of_the_documents_resolves():
    """Every relative link names an existing file, and every anchor into a markdown page one of
    its headings."""
    broken = []
    for page in _documents():
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
            path, _, anchor = target.partition("#")
            if re.match(r"[a-z]+:", path):
                continue
            file = page.parent / path if path else page
            if not file.exists() or (anchor and file.suffix == ".md" and anchor not in _anchors(file)):
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert broken == []


def test_every_script_the_documents_name_exists():
    """Scripts of benchmarks/, validation/ and demos/ named by a page, a JSON of docs/, the
    Makefile or a test (the changelog names the history's scripts too)."""
    sources = [p for p in _documents() if p.name != "CHANGELOG.md"]
    sources += [*(ROOT / "docs").rglob("*.json"), ROOT / "Makefile", *(ROOT / "tests").glob("*.py")]
    named = {m for p in sources for m in re.findall(r"\b(?:benchmarks|validation|demos)/\w+\.py", p.read_text())}
    assert named and {m for m in named if not (ROOT / m).exists()} == set()


def test_every_figure_and_json_of_the_result_pages_is_named_by_a_page():
    pages = "".join(p.read_text() for p in (ROOT / "docs").rglob("*.md"))
    files = [p for d in ("bench", "validation") for p in (ROOT / "docs" / d).iterdir() if p.suffix != ".md"]
    assert [p.name for p in files if p.name not in pages] == []


@pytest.mark.parametrize(
    "script, page", [("hertz3d.py", "hertz3d.md"), ("hertz3d_diagnostics.py", "hertz3d_diagnostics.md")]
)
@pytest.mark.slow
def test_the_hertz3d_pages_are_their_json_rendered(script, page, tmp_path):
    validation = ROOT / "docs" / "validation"
    for name in ("hertz3d.json", "hertz3d_diagnostics.json"):
        shutil.copy(validation / name, tmp_path / name)
    out = tmp_path / page.replace(".md", ".json")
    proc = run_command(
        [sys.executable, str(ROOT / "validation" / script), "--render", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    assert out.with_suffix(".md").read_text() == (validation / page).read_text()


def _row(text: str, section: str, first: str) -> list:
    """The cells after the first of the first table row after the heading ``section`` that starts
    with ``| first |``, bold removed."""
    lines = text[text.index(f"\n{section}\n") :].splitlines()
    line = next(line for line in lines if line.startswith(f"| {first} |"))
    return [c.strip() for c in line.replace("**", "").strip("|").split("|")][1:]


def _quotes(cell: str, value: float, scale: float = 1.0) -> bool:
    """Whether the first number of ``cell`` is ``value`` times ``scale`` to its printed digits."""
    number = re.match(r"[-+]?[\d,]*\.?\d+(?:e[-+]?\d+)?", cell).group().replace(",", "")
    mantissa, _, exponent = number.partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return abs(float(number) - value * scale) <= 0.5 * 10.0 ** (int(exponent or 0) - decimals) * 1.0001


def test_the_benchmark_pages_quote_their_json():
    bench = ROOT / "docs" / "bench"
    readme, parallel = (bench / "README.md").read_text(), (bench / "parallel.md").read_text()
    results = json.loads((bench / "results.json").read_text())
    for r in results["cost_growth"]:
        cells = _row(readme, "## The MEMM step, the set-up and the stable time step", f"{r['cells']:,}")
        step = r["seconds"]["step"] / r["seconds"]["matmult"]
        median = r["seconds_median"]["step"] / r["seconds_median"]["matmult"]
        assert _quotes(cells[0], step) and _quotes(cells[0].split("(")[1], median), cells
        assert _quotes(cells[1], r["force_vs_matmult_ratio"]), cells
        assert _quotes(cells[2], r["stable_time_step"]["bound_seconds"]), cells
        assert _quotes(cells[3], r["stable_time_step"]["fraction_of_setup"], 100), cells
    for scene, r in results["bound_tightness"].items():
        cells = _row(readme, "### The bound on the stable time step against SLEPc (`bound_tightness`)", f"`{scene}`")
        assert _quotes(cells[2], r["lambda_bound_over_lambda_max"]), cells
        assert _quotes(cells[3], r["dt_bound_over_dt_eigenvalue"]), cells
    for run, r in results["residual_refresh"].items():
        first = next(
            c
            for c in (
                "`cantilever`",
                "unit square, 1e4 cells, smooth u0",
                "`bar-impact`, 800 cells (free body, contact)",
            )
            if c.strip("`")[:9] in run
        )
        cells = _row(readme, "### Drift of the pseudo-energy with and without the refresh (`residual_refresh`)", first)
        for column, key in ((1, "pseudo_energy_drift"), (2, "energy_rows_distance")):
            quoted = cells[column].split(" / ")
            assert all(_quotes(q, r["refresh_every"][k][key]) for q, k in zip(quoted, ("0", "1000", "100"))), cells
    contact3d = json.loads((bench / "contact3d.json").read_text())
    assert f"`contact_fraction` **{contact3d['cradle']['contact_fraction']:.3f}**" in readme
    for r in contact3d["idle_balls"]:
        cells = _row(readme, "## Contact between bodies in 3D", str(r["idle_balls"]))
        assert _quotes(cells[4], r["contact_ms_per_step"]) and _quotes(cells[5], r["step_ms"]), cells
    data = json.loads((bench / "parallel.json").read_text())
    for r in data["scaling"]:
        cells = _row(parallel, "## Set-up, memory and step at 1e6 cells", str(r["processes"]))
        assert _quotes(cells[0], r["setup_seconds"]) and _quotes(cells[2], r["stable_step_seconds"]), cells
        assert _quotes(cells[3], r["peak_mb_max"]) and _quotes(cells[5], r["bytes_per_cell_summed"], 1e-3), cells
        assert _quotes(cells[7], r["step_seconds_median"], 1e3), cells
    one = [r for r in data["pile"] if r["processes"] == 1]
    two = [r for r in data["pile"] if r["processes"] == 2]
    for k, (a, b) in enumerate(zip(one, two)):
        cells = _row(parallel, "## Contact work of a pile of 64 discs", str(k + 1))
        assert _quotes(cells[0], a["contact_seconds_per_step_max"], 1e3), cells
        assert _quotes(cells[1], b["contact_seconds_per_step_max"], 1e3), cells
        assert _quotes(cells[3], b["contact_seconds_per_step_max"] / a["contact_seconds_per_step_max"]), cells
    assert f"Median ratio **{data['contact_2_over_1']:.3f}**" in parallel


#: Mesh types made by gmsh: another gmsh than Debian 12's (4.8) meshes them with other cell counts.
GMSH_MESHES = {"disc", "discs", "balls"}


def _scene_paragraphs() -> dict:
    """The text of "## Built-in scenes" that follows each **`name`** up to the next one."""
    section = SCENES_MD[SCENES_MD.index("## Built-in scenes") :]
    section = section[: section.index("\n## ", 1)]
    parts = re.split(r"\*\*`([a-z0-9-]+)`\*\*", section)
    return dict(zip(parts[1::2], parts[2::2]))


def test_the_scene_figures_the_docs_quote_are_those_of_the_scenes():
    """Every step count, time step and cell count quoted after a built-in scene's name in
    docs/scenes.md is the scene's (before: cantilever quoted 29,896 steps of dt = 1.338e-4, the
    old SLEPc step, for 32,868 of 1.217e-4; block and bar-wave too). Set-up only (0.1-0.5 s each)."""
    import gmsh

    from dolfinx_dem import dynamics, model

    paragraphs = _scene_paragraphs()
    assert set(scenes.builtin_names()) <= set(paragraphs)
    checked = 0
    for name, text in paragraphs.items():
        steps = re.findall(r"([\d,]+) steps(?: of dt = ([\d.e-]+))?", text)
        cells = re.findall(r"([\d,]+) (?:cells|triangles|tetrahedra)(?! with)", text)  # not "24 cells with ..."
        if not steps and not cells:
            continue
        scene = scenes.validate(scenes.load(name))
        if scene["mesh"]["type"] in GMSH_MESHES and gmsh.__version__ != "4.8.0":
            continue
        if "time" in scene:
            r = dynamics.DynamicRun(scene, MPI.COMM_SELF, quiet=True)
            dem, n_steps, dt = r.dem, r.n_steps, r.dt
        else:
            dem, n_steps, dt = model.build(scene, MPI.COMM_SELF).dem, None, None
        for n, step in steps:
            assert _quotes(n, n_steps), (name, n, n_steps)
            assert not step or _quotes(step, dt), (name, step, dt)
        for n in cells:
            assert _quotes(n, dem.n_owned), (name, n, dem.n_owned)
        checked += len(steps) + len(cells)
    assert checked >= (8 if gmsh.__version__ == "4.8.0" else 6)  # measured: 11 (Debian 12), 7 (another gmsh)
