"""The ``dolfinx-dem`` command: ``list``, ``run SCENE [--set key=value]... [--out DIR]``, ``show DIR``."""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

from mpi4py import MPI


def _list(args) -> int:
    from dolfinx_dem import scenes

    for name in scenes.builtin_names():
        scene = scenes.load(name)
        first = scene.get("description", "").strip().split("\n")[0]
        print(f"{name:16s} {first}")
    return 0


def _run(args) -> int:
    from dolfinx_dem import scenes, simulation
    from dolfinx_dem.memm import InstabilityError
    from dolfinx_dem.statics import StaticsError

    comm = MPI.COMM_WORLD
    try:
        overrides = dict(scenes.parse_override(s) for s in args.set)
        scene = scenes.load(args.scene, overrides)
    except (scenes.SceneError, FileNotFoundError) as err:
        if comm.rank == 0:
            print(f"dolfinx-dem: error: {err}", file=sys.stderr)
        return 2
    out = pathlib.Path(args.out or pathlib.Path("results") / scene["name"])
    try:
        summary = simulation.run(scene, out, comm, quiet=args.quiet)
    except InstabilityError as err:
        if comm.rank == 0:
            print(f"dolfinx-dem: error: {err}\nPartial results (marked INCOMPLETE) are in {out}", file=sys.stderr)
        return 1
    except (scenes.SceneError, ValueError, FileNotFoundError, StaticsError) as err:
        if comm.rank == 0:
            print(f"dolfinx-dem: error: {err}", file=sys.stderr)
        return 2
    if comm.rank == 0 and not args.quiet:
        if summary.get("analysis") == "static":
            print(f"{summary['scene']} ({summary['method']}, static): {summary['iterations']} iterations in "
                  f"{summary['wall_time_s']:.1f} s; top vertical displacement "
                  f"{summary['top_vertical_displacement']:.5g} m")
        else:
            print(f"{summary['scene']}: {summary['n_steps']} steps of dt = {summary['dt']:.4g} s on "
                  f"{summary['n_cells']} cells in {summary['wall_time_s']:.1f} s; pseudo-energy drift "
                  f"{summary['pseudo_energy_rel_drift']:.2e}")
            if summary.get("contact_pairs_scheme_b_rule"):
                print(f"note: {summary['contact_pairs_scheme_b_rule']} pairs of scheme A facets used the scheme B "
                      "contact rule, eq. (23)-(24) having no well-posed solution for them (docs/theory.md)")
        print(f"results in {out.resolve()}")
    return 0


def _show(args) -> int:
    from dolfinx_dem import plotting

    directory = pathlib.Path(args.directory)
    series = directory / "series.csv"
    if not series.is_file():
        print(f"dolfinx-dem: error: {series} does not exist (not a run directory?)", file=sys.stderr)
        return 2
    if MPI.COMM_WORLD.rank == 0:
        with open(series) as f:
            header = f.readline().strip().split(",")
        energies = plotting.plot_series(series, [c for c in header[1:6]], directory / "energies.png")
        print(f"wrote {energies}")
        probes = header[6:]
        if probes:
            print(f"wrote {plotting.plot_series(series, probes, directory / 'probes.png')}")
        summary = directory / "summary.json"
        if summary.is_file():
            print(json.dumps(json.loads(summary.read_text()), indent=2))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="dolfinx-dem", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the built-in scenes").set_defaults(func=_list)
    run = sub.add_parser("run", help="run a scene (built-in name or TOML file)")
    run.add_argument("scene")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                     help="override a scene key, e.g. --set mesh.n=[80,8] --set time.end=1.0")
    run.add_argument("--out", help="output directory (default results/<scene name>)")
    run.add_argument("--quiet", action="store_true", help="no progress or summary output")
    run.set_defaults(func=_run)
    show = sub.add_parser("show", help="plot the energies and probes of a run directory")
    show.add_argument("directory")
    show.set_defaults(func=_show)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
