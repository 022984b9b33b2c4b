"""The benchmark studies run (quick mode) and write their JSON and charts, so that they never rot."""

import json
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_bench_study_quick(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_study.py"), "--quick", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=600, cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
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


def _quick(script, *args, timeout=300):
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--quick", *args],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    return proc


def test_bench_signorini_quick(tmp_path):
    _quick("bench_signorini.py", "--out-dir", str(tmp_path))
    data = json.loads((tmp_path / "signorini.json").read_text())
    assert data["quick"]


def test_bench_wave2d_quick(tmp_path):
    _quick("bench_wave2d.py", "--out-dir", str(tmp_path))
    assert json.loads((tmp_path / "wave2d.json").read_text())


def test_bench_contact_scaling_quick(tmp_path):
    _quick("bench_contact_scaling.py", "--out", str(tmp_path / "scaling.json"))
    data = json.loads((tmp_path / "scaling.json").read_text())
    # the contact work per step does not grow like the contact facets (5 x more here)
    assert data["contact_facets_ratio"] == 5.0 and data["contact_work_ratio"] < 3.0


def test_bench_contact3d_quick(tmp_path):
    _quick("bench_contact3d.py", "--out", str(tmp_path / "contact3d.json"))
    data = json.loads((tmp_path / "contact3d.json").read_text())
    assert 0 < data["cradle"]["contact_fraction"] < 1
    assert [r["idle_balls"] for r in data["idle_balls"]] == [0, 2]


def test_bench_parallel_quick(tmp_path):
    _quick("bench_parallel.py", "--repeat", "1", "--out", str(tmp_path / "parallel.json"))
    data = json.loads((tmp_path / "parallel.json").read_text())
    runs = data["scaling"]
    assert [r["processes"] for r in runs] == [1, 2, 4] and len({r["cells"] for r in runs}) == 1
    # the halo stays a thin layer: no process holds much more than its owned cells
    assert all(r["held_over_owned_max"] < 1.5 for r in runs)
    # the pile is measured while its discs press on each other
    assert all(p["touching_pair_entries_at_start"] > 0 and p["touching_pair_entries"] > 0 for p in data["pile"])
    assert data["pile"][0]["cells"] == data["pile"][1]["cells"]


def test_bench_two_materials_small(tmp_path):
    """The two-material study on two coarse meshes: T converges, the energy is conserved, the
    reaction balances the load."""
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_two_materials.py"), "--meshes", "140",
                           "280", "--out", str(tmp_path / "two.json")], capture_output=True, text=True, timeout=300,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    data = json.loads((tmp_path / "two.json").read_text())
    for study in data["weights"].values():
        rows = study["dynamic_A"]["rows"]
        assert rows[1]["T_error"] < 0.5 * rows[0]["T_error"]
        assert all(r["pseudo_energy_drift_rel"] < 1e-14 for r in rows)
        assert all(s["reaction_error_rel"] < 1e-10 for s in study["static"])
