"""Why the DEM's cradle drifts sideways (issue 33): one run of the built-in ``cradle`` scene per call,
one row of measurements appended to a JSON file; ``--page`` rewrites the table of
docs/validation/cradle_drift.md from the file.

The first ball starts at ``--speed`` times the scene's 0.3 m/s and the end time is the scene's 3 s
divided by it, so every run covers the same distance (the fifth ball travels about 0.9 m) and the
same impacts; the lateral drift then compares directly: a deflection angle a of the impulses gives
a drift of about a times the distance travelled, whatever the speed. Per run (long_runs.py's
measures): the lateral drift, the largest distance of a ball's centre of mass from the x axis at the
end (exact: 0); the largest axial displacement of a ball (the distance travelled); the energy error
max |E - E(0)| / E(0) of the ``pseudo_energy`` column; the summary's ``max_contact_crossing_angle``
(DEM only) and ``max_penetration``; the contact episodes; the wall time (one process).

    .venv/bin/python validation/cradle_drift.py --method dem-B --h 0.04 --speed 0.1 --out OUT.json
    .venv/bin/python validation/cradle_drift.py --method dem-B --h 0.04 --set contact.surface=vertex --out OUT.json
    .venv/bin/python validation/cradle_drift.py --page docs/validation/cradle_drift.md --out OUT.json
"""

import argparse
import json
import pathlib
import shutil
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import long_runs  # noqa: E402

SPEED, END, INTERVAL = 0.3, 3.0, 0.025  # the scene's, and long_runs.py's output interval for it


def value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def run(method: str, h: float, speed: float, extra: dict) -> dict:
    from dolfinx_dem import scenes, simulation

    spec = long_runs.SCENES["cradle"]
    end, interval = END / speed, INTERVAL / speed
    every = max(1, round(interval / (spec["dt_over_h"][method] * h * extra.get("time.cfl", 0.2) / 0.2)))
    overrides = {"method": method, "mesh.h": h, "time.end": end, "output.every": every,
                 "initial.velocity": [f"where(x < 0.205, {SPEED * speed:g}, 0.0)", "0", "0"], **extra}
    scene = scenes.load("cradle", overrides)
    with tempfile.TemporaryDirectory() as tmp:
        out = pathlib.Path(tmp) / "run"
        start = time.perf_counter()
        summary = simulation.run(scene, out, quiet=True, overwrite=True)
        wall = time.perf_counter() - start
        assert summary["status"] == "completed", summary["status"]
        series = np.genfromtxt(out / "series.csv", delimiter=",", names=True)
        times, positions, velocities = long_runs.centres_of_mass(out, np.array(spec["centres"]), spec["radius"])
        episodes = long_runs.contact_episodes(series, interval)
        early = long_runs.contact_episodes(series[series["t"] <= end / 3], interval)
        shutil.rmtree(out)
    energy = series["pseudo_energy"]
    u = positions[-1] - positions[0]  # the centres' displacements at the last frame
    third = int(np.argmin(np.abs(times - end / 3)))  # the lateral speeds at t = end / 3, over the first ball's
    kick = np.linalg.norm(velocities[third, :, 1:], axis=1) / (SPEED * speed)
    return {"method": method, "h": h, "speed": SPEED * speed, "end": end, "set": extra,
            "steps": summary["n_steps"], "dt": summary["dt"], "t_last_frame": float(times[-1]),
            "lateral_end": float(np.linalg.norm(u[:, 1:], axis=1).max()),
            "lateral_per_ball": np.linalg.norm(u[:, 1:], axis=1).tolist(),
            "axial_end": float(np.abs(u[:, 0]).max()), "axial_per_ball": u[:, 0].tolist(),
            "energy_error": float(np.max(np.abs(energy - energy[0])) / energy[0]),
            "crossing_angle": summary.get("max_contact_crossing_angle"),
            "max_penetration": summary.get("max_penetration"),
            "contact_episodes": episodes, "contact_episodes_to_third": early, "t_third": float(times[third]),
            "lateral_speed_third": float(kick.sum()), "lateral_speed_third_per_ball": kick.tolist(), "wall_s": wall}


def table(rows: list) -> str:
    lines = ["| method | h (m) | v0 (m/s) | T (s) | other settings | steps | crossing angle (deg) | energy error | "
             "contact episodes, to T/3 / to T | lateral speeds at T/3, sum / v0 | lateral drift at T, largest (m) | "
             "lateral drift at T, sum (m) | dem-B / fem-P1, largest drift | wall (s) |", "|---" * 14 + "|"]
    fem = {(r["h"], r["speed"]): r["lateral_end"] for r in rows if r["method"] == "fem-P1" and not r["set"]}
    for r in sorted(rows, key=lambda r: (-r["speed"], -r["h"], r["method"], sorted(r["set"].items()))):
        other = ", ".join(f"`{k}={v}`" for k, v in r["set"].items()) or "-"
        ratio = fem.get((r["h"], r["speed"])) if r["method"] == "dem-B" else None
        angle = "-" if r["crossing_angle"] is None else f"{r['crossing_angle']:.1f}"
        lines.append(f"| {r['method']} | {r['h']:g} | {r['speed']:g} | {r['end']:g} | {other} | {r['steps']} | {angle} | "
                     f"{r['energy_error']:.1e} | {r['contact_episodes_to_third']} / {r['contact_episodes']} | "
                     f"{r['lateral_speed_third']:.3f} | {r['lateral_end']:.3f} | {sum(r['lateral_per_ball']):.3f} | "
                     f"{'-' if ratio is None else format(r['lateral_end'] / ratio, '.2f')} | {r['wall_s']:.1f} |")
    return "\n".join(lines)


def with_table(page: str, text: str) -> str:
    """``page`` with its table (the lines from the one that starts as ``text`` to the last line of
    the block that starts with "|") replaced by ``text``."""
    lines = page.split("\n")
    start = next(i for i, line in enumerate(lines) if line.startswith(text[:30]))
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    return "\n".join(lines[:start] + [text] + lines[end:])


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--method", default="dem-B", choices=long_runs.METHODS)
    parser.add_argument("--h", type=float, default=0.04)
    parser.add_argument("--speed", type=float, default=1.0, help="the first ball's speed over the scene's 0.3 m/s")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="another scene override")
    parser.add_argument("--page", type=pathlib.Path, help="rewrite this page's table from --out's rows (no run)")
    parser.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args()
    rows = json.loads(args.out.read_text()) if args.out.exists() else []
    if args.page:
        args.page.write_text(with_table(args.page.read_text(), table(rows)))
        return
    extra = {k: value(v) for k, v in (s.split("=", 1) for s in args.set)}
    row = run(args.method, args.h, args.speed, extra)
    print(json.dumps(row), flush=True)
    args.out.write_text(json.dumps(rows + [row], indent=1) + "\n")


if __name__ == "__main__":
    main()
