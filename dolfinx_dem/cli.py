"""The ``dolfinx-dem`` command: ``list``, ``run SCENE``, ``resume DIR``, ``show DIR``.

Exit status: 0 on success, 2 for invalid input (nothing written), 1 when the stability monitor
stops a run, 130 when SIGINT or SIGTERM stopped it (checkpoint written; ``resume`` continues).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import pathlib
import signal
import sys
import time
import warnings

from mpi4py import MPI

from dolfinx_dem.errors import (
    AccuracyWarning,
    DEMError,
    InputError,
    InstabilityError,
    SceneError,
    UnresolvedContactError,
)

#: Python's own display of warnings (``_show_accuracy_warning`` passes the others to it)
_SHOW_WARNING = warnings.showwarning

#: Exit status of a run stopped by SIGINT or SIGTERM (128 + SIGINT, as shells report Ctrl-C).
INTERRUPTED = 130


def _quiet_compiler_logging():
    """Show warnings and errors of Python logging, not the INFO records of form compilation.

    FFCx calls ``logging.basicConfig()`` when imported, and cffi sets the root logger to INFO
    for every compilation, so that DOLFINx's first form compilation printed pages of
    ``INFO:root:running build_ext`` and gcc command lines. A root handler of the command's own
    that passes WARNING and above comes first (basicConfig then adds none), and handlers
    already there are raised to WARNING. The library itself leaves logging alone."""
    root = logging.getLogger()
    for handler in root.handlers:
        handler.setLevel(logging.WARNING)
    handler = logging.StreamHandler()
    handler.setLevel(logging.WARNING)
    handler.setFormatter(logging.Formatter("%(levelname)s:%(name)s:%(message)s"))
    root.addHandler(handler)


def _print(*args, **kwargs):
    """print() that survives a closed pipe (``dolfinx-dem show DIR | head -3``): PETSc catches
    SIGPIPE and aborts MPI, so SIGPIPE is ignored and later output goes to /dev/null."""
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    try:
        print(*args, **kwargs)
        sys.stdout.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


#: Seconds the processes of an MPI run wait for each other to report the same error.
AGREEMENT_SECONDS = 10.0
_GUARD = None  # a duplicate of COMM_WORLD (main), see _error


def _error(comm, message: str) -> None:
    """Print an error on rank 0. Under MPI, input errors are found on every process (the
    checks are collective); one found on some processes only is a bug that would leave the
    others waiting in a collective and these in MPI_Finalize, for ever: if the processes have
    not all reported an error within ``AGREEMENT_SECONDS`` (a barrier on a communicator of its
    own), this one prints its message and aborts the run."""
    if comm.size > 1:
        request, deadline = _GUARD.Ibarrier(), time.monotonic() + AGREEMENT_SECONDS
        while not request.Test():
            if time.monotonic() > deadline:
                print(f"dolfinx-dem: error on process {comm.rank} only: {message}", file=sys.stderr, flush=True)
                comm.Abort(2)
            time.sleep(0.01)
    if comm.rank == 0:
        print(f"dolfinx-dem: error: {message}", file=sys.stderr)


def _list(args) -> int:
    from dolfinx_dem import scenes

    for name in scenes.builtin_names():
        scene = scenes.load(name)
        first = scene.get("description", "").strip().split("\n")[0]
        _print(f"{name:16s} {first}")
    return 0


def _overrides(args) -> dict:
    from dolfinx_dem import scenes

    return dict(scenes.parse_override(s) for s in args.set)


def _run(args) -> int:
    from dolfinx_dem import scenes

    comm = MPI.COMM_WORLD
    try:
        scene = scenes.load(args.scene, _overrides(args))
    except InputError as err:
        _error(comm, err)
        return 2
    out = pathlib.Path(args.out or pathlib.Path("results") / scene["name"])
    return _execute(comm, args, out, lambda simulation: simulation.run(
        scene, out, comm, quiet=args.quiet, overwrite=args.overwrite, checkpoint_every=args.checkpoint_every))


def _resume(args) -> int:

    comm = MPI.COMM_WORLD
    try:
        overrides = _overrides(args)
    except SceneError as err:
        _error(comm, err)
        return 2
    out = pathlib.Path(args.directory)
    return _execute(comm, args, out, lambda simulation: simulation.resume(
        out, comm, overrides, quiet=args.quiet, checkpoint_every=args.checkpoint_every))


def _execute(comm, args, out: pathlib.Path, start) -> int:
    """Run ``start(simulation)`` and report as the command does; returns the exit status."""
    from dolfinx_dem import simulation

    try:
        summary = start(simulation)
    except (InstabilityError, UnresolvedContactError) as err:
        _error(comm, f"{err}\nPartial results (marked INCOMPLETE) are in {out}")
        return 1
    except DEMError as err:  # bad input, or a static problem without solution: nothing written
        _error(comm, err)
        return 2
    if comm.rank == 0 and not args.quiet:
        _print(summary_line(summary))
        if summary.get("obstacle_facets_scheme_b_rule"):
            _print(f"note: {summary['obstacle_facets_scheme_b_rule']} scheme A candidate facets use the scheme B "
                   "contact rule, being more than 45 degrees from their obstacle's plane (docs/theory.md)")
        if summary.get("contact_pairs_scheme_b_rule"):
            _print(f"note: {summary['contact_pairs_scheme_b_rule']} pairs of scheme A facets used the scheme B "
                   "contact rule, eq. (23)-(24) having no well-posed solution for them (docs/theory.md)")
        _print(f"results in {out.resolve()}")
    return INTERRUPTED if summary["status"] == "interrupted" else 0


def summary_line(summary: dict) -> str:
    """The one-line account of a run: steps, time, and the energy balance as it applies."""
    if summary.get("analysis") == "static":
        return (f"{summary['scene']} ({summary['method']}, static): {summary['iterations']} iterations in "
                f"{summary['wall_time_s']:.1f} s; top vertical displacement "
                f"{summary['top_vertical_displacement']:.5g} m")
    status = "" if summary["status"] == "completed" else f" ({summary['status']})"
    energy = (f"pseudo-energy drift {summary['pseudo_energy_rel_drift']:.2e}" if summary["conservative"] else
              f"not conservative (time-dependent data): energy balance error (work counted) "
              f"{summary['pseudo_energy_rel_drift']:.2e}")
    return (f"{summary['scene']}{status}: {summary['n_steps']} steps of dt = {summary['dt']:.4g} s on "
            f"{summary['n_cells']} cells in {summary['wall_time_s']:.1f} s; {energy}")


def _show(args) -> int:
    from dolfinx_dem import show

    directory = pathlib.Path(args.directory)
    series = directory / "series.csv"
    if not series.is_file():
        print(f"dolfinx-dem: error: {series} does not exist (not a run directory?)", file=sys.stderr)
        return 2
    if MPI.COMM_WORLD.rank == 0:
        summary = directory / "summary.json"
        summary = json.loads(summary.read_text()) if summary.is_file() else None
        state = run_state(directory, summary)
        if state:
            _print(state)
        for picture in show.write_pictures(directory, summary):
            _print(f"wrote {picture}")
        if summary is not None:
            _print(json.dumps(summary, indent=2))
    return 0


def run_state(directory: pathlib.Path, summary: dict | None) -> str:
    """A plain sentence on a run folder that does not hold a completed run, else ""."""
    from dolfinx_dem import checkpoint, io

    marker = directory / io.INCOMPLETE
    if summary is not None and summary.get("status") == "interrupted":
        return (f"INTERRUPTED: the run stopped at step {summary['n_steps']} (t = {summary['t_end']:.6g}) of its "
                f"scene; continue it with: dolfinx-dem resume {directory}")
    if summary is not None and summary.get("status") == "unstable":
        return f"UNSTABLE: the stability monitor stopped the run: {summary.get('error', '')}"
    if summary is not None and summary.get("status") == "unresolved":
        return f"UNRESOLVED CONTACT: the run stopped: {summary.get('error', '')}"
    if marker.exists():
        error = directory / io.ERROR
        why = f"it failed, see {error}" if error.exists() else "it is still running, or was killed"
        again = (f"; continue it from its last checkpoint with: dolfinx-dem resume {directory}"
                 if (directory / checkpoint.DIRECTORY / "checkpoint.json").is_file() and not error.exists() else "")
        return f"INCOMPLETE: this run did not finish ({why}); the files below hold what it wrote{again}"
    return ""


def _show_accuracy_warning(message, category, filename, lineno, file=None, line=None):
    """AccuracyWarnings as the command's own lines, ``dolfinx-dem: warning: ...``; others as Python shows them."""
    if issubclass(category, AccuracyWarning):
        print(f"dolfinx-dem: warning: {message}", file=sys.stderr, flush=True)
    else:
        _SHOW_WARNING(message, category, filename, lineno, file, line)


def main(argv: list[str] | None = None) -> int:
    global _GUARD
    _quiet_compiler_logging()
    warnings.showwarning = _show_accuracy_warning
    if _GUARD is None and MPI.COMM_WORLD.size > 1:
        _GUARD = MPI.COMM_WORLD.Dup()  # for _error's agreement only
    parser = argparse.ArgumentParser(prog="dolfinx-dem", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="list the built-in scenes").set_defaults(func=_list)
    run = sub.add_parser("run", help="run a scene (built-in name or TOML file)")
    run.add_argument("scene")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                     help="override a scene key, e.g. --set mesh.n=[80,8] --set time.end=1.0")
    run.add_argument("--out", help="output directory (default results/<scene name>)")
    run.add_argument("--overwrite", action="store_true",
                     help="replace a run already in the output directory (its files are removed first)")
    run.set_defaults(func=_run)
    resume = sub.add_parser("resume", help="continue a run from its checkpoint, appending to its outputs")
    resume.add_argument("directory")
    resume.add_argument("--set", action="append", default=[], metavar="time.end=VALUE",
                        help="a later end time (the only scene key a resumed run may change)")
    resume.set_defaults(func=_resume)
    for command in (run, resume):
        command.add_argument("--checkpoint-every", type=int, metavar="N",
                             help="also write a checkpoint every N steps (always: when interrupted and at the end)")
        command.add_argument("--quiet", action="store_true", help="no progress or summary output")
    show = sub.add_parser("show", help="plot the energies and probes of a run directory")
    show.add_argument("directory")
    show.set_defaults(func=_show)
    args = parser.parse_args(argv)
    if getattr(args, "checkpoint_every", None) is not None and args.checkpoint_every < 1:
        parser.error(f"--checkpoint-every must be >= 1, got {args.checkpoint_every}")
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
