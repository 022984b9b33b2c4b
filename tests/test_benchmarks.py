"""The benchmark studies (benchmarks/) run in their quick modes and write their JSON and charts,
so that they never rot. Every script of benchmarks/ and validation/ imports, and the branch that no
quick mode reaches (the DEM in bench_signorini's stability sweep) runs on its smallest case. The
validation studies' quick runs: test_validation_studies.py."""

import json

import pytest
from helpers import ROOT, import_script, run_quick

SCRIPTS = sorted((ROOT / "benchmarks").glob("*.py")) + sorted((ROOT / "validation").glob("*.py"))
#: the modules among them that scripts import, without a main of their own
LIBRARIES = ("work_precision", "friction_slide_pages", "signorini_report", "signorini_tte_report")

# each test runs a study (quick mode) in a process of its own
pytestmark = pytest.mark.slow


@pytest.mark.parametrize("path", SCRIPTS, ids=[f"{p.parent.name}/{p.name}" for p in SCRIPTS])
def test_script_imports(path, monkeypatch):
    """Every script's module-level imports resolve against the package (its main is not run)."""
    assert len(SCRIPTS) >= 14
    module = import_script(path, monkeypatch)
    assert path.stem in LIBRARIES or callable(module.main)


def test_bench_signorini_dem_stability_sweep(tmp_path, monkeypatch):
    """The DEM part of the stability sweep (left out of --quick): its SLEPc limit and bound in
    CFL units, and a stable run at CFL 0.5 with the energy conserved."""
    signorini = import_script(ROOT / "benchmarks" / "bench_signorini.py", monkeypatch)
    sweep = signorini.stability_sweep([0.5], tmp_path, lambda message: None, n=50, t_end=0.2, dem=True)
    assert 1.0 < sweep["cfl_limit"]["dem-A"] < 1.01 and 0.99 < sweep["cfl_bound_dem-A"] <= 1.0
    (run,) = sweep["runs"]["dem-A"]
    assert run["stable"] and run["energy_rel_error_max"] < 1e-12


def test_bench_femp1_quick(tmp_path):
    run_quick("benchmarks/bench_femp1.py", "--out", str(tmp_path / "femp1.json"))
    data = json.loads((tmp_path / "femp1.json").read_text())
    for method in ("dem-A", "fem-P1"):
        assert data["results"][method]["steps"] == 800  # 2 rounds of 400 steps
        assert 0 < data["results"][method]["median_contact_step_us"] < 1e4
    assert data["ratio_dem_over_fem"] > 0


def test_bench_study_quick(tmp_path):
    run_quick("benchmarks/bench_study.py", "--out", str(tmp_path), timeout=600)
    data = json.loads((tmp_path / "results.json").read_text())
    for key in ("force_vs_matmult_ratio", "contact_fraction_billiard", "mpi_speedup_2",
                "setup_seconds_per_million_cells"):
        assert data[key] > 0, key
    # the force is two MatMults with Q = [S; J]; Q has fewer nonzeros than K
    assert data["nnz_Q_over_nnz_K"] < 1
    assert 0.5 < data["force_vs_matmult_ratio"] < 5
    assert 0 < data["contact_fraction_billiard"] < 1
    assert [r["processes"] for r in data["mpi"]["runs"]] == [1, 2]
    assert [r["cells"] for r in data["cost_growth"]] == [968, 4050]
    bar = data["bar_impact_dem_step"]
    assert bar["contact_in_contact"] and not bar["free_flight_in_contact"]
    assert 0 < bar["clamped_no_contact_step_seconds"] < bar["contact_step_seconds"]
    # the stable time step: a bound above SLEPc's lambda_max, in a fraction of the set-up
    assert data["stable_time_step_fraction_of_setup"] > 0
    assert all(1.0 < r["lambda_bound_over_lambda_max"] < 1.5 for r in data["bound_tightness"].values())
    for case in data["residual_refresh"].values():
        assert all(r["pseudo_energy_drift"] < 1e-12 for r in case["refresh_every"].values())
    pairs = data["bar_impact_work_precision"]["methods"]
    assert {"dem-A", "dem-B", "projection", "modified-mass", "newmark-penalty"} <= set(pairs)
    assert all(p["wall_time_s"] > 0 and p["tip_l2"] > 0 for rows in pairs.values() for p in rows)
    for name in data["charts"]:
        assert (tmp_path / name).stat().st_size > 1000


def test_bench_signorini_quick(tmp_path):
    run_quick("benchmarks/bench_signorini.py", "--out-dir", str(tmp_path))
    data = json.loads((tmp_path / "signorini.json").read_text())
    assert data["quick"]


def test_bench_signorini_tte_dispersion_and_decomposition(monkeypatch):
    """bench_signorini_tte.py's analysis (measured 2026-12-06): the DEM's 1D operator disperses
    like P1 on a mesh of spacing 2h (beta = 1/6 against P1 lumped's 1/24, whatever eta; scheme B
    exactly), eta sets the CFL limit (sqrt(E / eta) for eta >= E/3, 1.0002 at eta = E with the
    boundary cells), and on the documented run the time-to-error ratio is the product of its
    factors, the mesh factor (4.71 at 0.05) being the largest."""
    tte = import_script(ROOT / "benchmarks" / "bench_signorini_tte.py", monkeypatch)
    d = tte.dispersion_study(100, (1.0 / 3.0, 1.0, 2.0), (0.75,))
    assert abs(d["p1_lumped"]["beta"] - 1.0 / 24.0) < 2e-4 and abs(d["p1_lumped"]["cfl_limit"] - 1.0) < 1e-9
    rows = {(r["method"], round(r["eta_over_E"], 3)): r for r in d["dem"]}
    for eta in (0.333, 1.0, 2.0):
        assert abs(rows["dem-B", eta]["beta"] - 1.0 / 6.0) < 2e-4, rows["dem-B", eta]
        assert abs(rows["dem-A", eta]["beta"] - 1.0 / 6.0) < 0.01, rows["dem-A", eta]  # 0.1695-0.1728
    assert abs(rows["dem-B", 0.333]["cfl_limit"] - 3**0.5) < 1e-3
    assert 1.0 < rows["dem-A", 1.0]["cfl_limit"] < 1.001
    assert abs(rows["dem-A", 2.0]["cfl_limit"] - 0.5**0.5) < 1e-3
    conv = json.loads((ROOT / "docs" / "bench" / "signorini.json").read_text())["convergence"]["methods"]
    dec = tte.decomposition(conv, (0.05, 0.025))
    for r in dec.values():
        assert r["steps_per_cell_ratio"] == pytest.approx(1.0, abs=1e-9)
        assert r["product"] == pytest.approx(r["ratio"], rel=1e-9)
    # deterministic (errors only): the DEM needs 4.7 (at 0.05) and 3.6 (at 0.025) times the cells of (b)
    assert dec["0.05/dem-A"]["n_ratio"] == pytest.approx(4.71, abs=0.02)
    assert dec["0.025/dem-A"]["n_ratio"] == pytest.approx(3.59, abs=0.02)


def test_bench_signorini_tte_quick(tmp_path):
    """The quick study: (A, eta = E, CFL 0.75) reproduces the benchmark's errors on N = 50, 100,
    200; eta = E/6 at CFL 1.85 is stable with a smaller error (0.0574 against 0.0995 at N = 100);
    the page is signorini_tte.md."""
    run_quick("benchmarks/bench_signorini_tte.py", "--out-dir", str(tmp_path))
    data = json.loads((tmp_path / "signorini_tte.json").read_text())
    base, _, small_eta = data["variants"]["variants"]
    assert [r["tip_l2"] for r in base["rows"]] == pytest.approx([0.1618, 0.0995, 0.0621], abs=2e-4)
    assert small_eta["rows"][1]["tip_l2"] == pytest.approx(0.0574, abs=2e-4)
    assert (tmp_path / "signorini_tte.md").read_text().startswith("# Signorini bar: why the DEM takes")


def test_bench_wave2d_quick(tmp_path):
    run_quick("benchmarks/bench_wave2d.py", "--out-dir", str(tmp_path))
    assert json.loads((tmp_path / "wave2d.json").read_text())


def test_bench_contact_scaling_quick(tmp_path):
    run_quick("benchmarks/bench_contact_scaling.py", "--out", str(tmp_path / "scaling.json"))
    data = json.loads((tmp_path / "scaling.json").read_text())
    # the contact work per step does not grow like the contact facets (5 x more here)
    assert data["contact_facets_ratio"] == 5.0 and data["contact_work_ratio"] < 3.0


def test_bench_contact3d_quick(tmp_path):
    run_quick("benchmarks/bench_contact3d.py", "--out", str(tmp_path / "contact3d.json"))
    data = json.loads((tmp_path / "contact3d.json").read_text())
    assert 0 < data["cradle"]["contact_fraction"] < 1
    assert [r["idle_balls"] for r in data["idle_balls"]] == [0, 2]


def test_bench_parallel_quick(tmp_path):
    run_quick("benchmarks/bench_parallel.py", "--repeat", "1", "--out", str(tmp_path / "parallel.json"))
    data = json.loads((tmp_path / "parallel.json").read_text())
    runs = data["scaling"]
    assert [r["processes"] for r in runs] == [1, 2, 4] and len({r["cells"] for r in runs}) == 1
    # the halo stays a thin layer: no process holds much more than its owned cells
    assert all(r["held_over_owned_max"] < 1.5 for r in runs)
    # the pile is measured while its discs press on each other
    assert all(p["touching_pair_entries_at_start"] > 0 and p["touching_pair_entries"] > 0 for p in data["pile"])
    assert data["pile"][0]["cells"] == data["pile"][1]["cells"]
