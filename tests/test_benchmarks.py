"""The core benchmark runs (quick mode) and writes its JSON, so that it never rots."""

import json
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_bench_core_quick(tmp_path):
    out = tmp_path / "core.json"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_core.py"), "--quick", "--out", str(out)],
        capture_output=True, text=True, timeout=300, cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    for key in ("setup_seconds", "force_vs_matmult_ratio", "step_vs_matmult_ratio", "memory_bytes_per_cell"):
        assert set(data[key]) == {"1e4"}, key
    assert 9000 < data["sizes"]["1e4"] < 11000
    setup = data["setup_seconds"]["1e4"]
    parts = {"geometry", "reconstruction", "operators", "stiffness_product", "petsc_matrices"}
    assert set(setup) >= parts | {"constructor", "constructor_cold"}
    assert all(setup[key] > 0 for key in parts | {"constructor", "constructor_cold"})
    # a force evaluation is one K.mult plus vector updates; a MEMM step one force + diagnostics
    assert 0.5 < data["force_vs_matmult_ratio"]["1e4"] < 10
    assert data["step_vs_matmult_ratio"]["1e4"] > 1
    assert 0 < data["memory_bytes_per_cell"]["1e4"] < 1e6
    assert "10082" in proc.stdout  # the table
