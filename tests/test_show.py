"""``dolfinx-dem show``'s pictures (show.py): the energies with the pseudo-energy's drift, the other
columns with their units, the force against the displacement of prescribed bodies, the pressure
profile of a static run, and what a stopped run folder offers."""

import json

import numpy as np
import pytest

from dolfinx_dem import cli, show

pytestmark = pytest.mark.skip_in_parallel


def write_series(directory, header, rows, summary):
    directory.mkdir()
    np.savetxt(directory / "series.csv", rows, delimiter=",", header=",".join(header), comments="")
    (directory / "summary.json").write_text(json.dumps(summary))
    return summary


def test_units_of_the_series_columns():
    assert [show.unit(c) for c in ("kinetic", "balance", "contact_force_0_1_x", "reaction_disc_y",
                                   "contact_pressure", "momentum_z", "penetration", "tip_uy")] == \
        ["J", "J", "N", "N", "Pa", "kg m/s", "m", "m"]


def test_a_dynamic_run_with_a_prescribed_body_gets_energies_series_and_its_force_curve(tmp_path):
    """Before: five panels of raw columns, the pseudo-energy drawn raw (a flat line), nothing of the
    force-indentation curve."""
    t = np.linspace(0.0, 1.0, 21)
    header = ["t", "kinetic", "elastic", "stabilisation", "external", "pseudo_energy", "work", "balance",
              "reaction_disc_x", "reaction_disc_y", "prescribed_disc_displacement_x", "prescribed_disc_displacement_y"]
    rows = np.c_[t, 1 - t, t, 0 * t, 0 * t, 1 + 1e-15 * t, t, 1 + 2e-15 * t, 0 * t, -5 * t, 0 * t, -0.01 * t]
    summary = write_series(tmp_path / "run", header, rows, {"scene": "indentation", "status": "completed"})
    written = show.write_pictures(tmp_path / "run", summary)
    assert [p.rsplit("/", 1)[1] for p in written] == ["energies.png", "series.png", "force_displacement.png"]


def test_a_static_run_gets_its_pressure_profile_and_no_energy_panels(tmp_path):
    header = ["t", "kinetic", "elastic", "stabilisation", "external", "pseudo_energy", "contact_gap"]
    summary = write_series(tmp_path / "run", header, np.array([[0.0, 0.0, 1.0, 0.1, -2.0, -0.9, 0.0]]),
                           {"scene": "hertz", "analysis": "static", "contact_half_width_fit": 0.05,
                            "fitted_max_pressure": 3e6})
    x = np.linspace(-0.2, 0.2, 41)
    p = 3e6 * np.sqrt(np.clip(1 - (x / 0.05) ** 2, 0, 1))
    np.savetxt(tmp_path / "run" / "contact_pressure.csv", np.c_[x, 0 * x, p], delimiter=",", header="x0,x1,pressure",
               comments="")
    written = show.write_pictures(tmp_path / "run", summary)
    assert [p.rsplit("/", 1)[1] for p in written] == ["pressure.png"]


def test_a_killed_run_with_a_checkpoint_says_how_to_resume_it(tmp_path):
    run = tmp_path / "run"
    (run / "checkpoint").mkdir(parents=True)
    (run / "INCOMPLETE").write_text("")
    assert "resume" not in cli.run_state(run, None)
    (run / "checkpoint" / "checkpoint.json").write_text("{}")
    assert cli.run_state(run, None).endswith(f"continue it from its last checkpoint with: dolfinx-dem resume {run}")
