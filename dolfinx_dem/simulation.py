"""Run a scene: the one path from a scene to its outputs, scene -> model -> runner -> writers.

- ``model.py``: the mesh, the DEM discretisation and its contact models, the probes;
- the runners: ``dynamics.DynamicRun`` (MEMM), ``fem.scene_run.FEMP1Run`` (method ``fem-P1``, the
  explicit FEM peer), ``static_simulation.StaticRun`` (statics, or the FEM reference); each
  builds its model and checks the input when constructed;
- the writers (``io.py``, ``plotting.py``): only once everything is checked does a runner touch
  the output folder (``io.OutputDirectory``: a folder holding another run is refused unless
  ``overwrite``).

Outputs in the run folder: ``summary.json`` (with ``status``: ``completed``, ``interrupted``,
``unstable``), ``series.csv`` (t, kinetic, elastic, stabilisation, external, pseudo_energy,
then contact columns and probes), ``solution.xdmf`` (+ ``solution.h5`` and ``solution/``: DG0
displacement, velocity, von Mises stress), ``final.png``, with ``output.animation`` the GIF
``animation.gif``, and for a dynamic run its ``checkpoint`` folder (``checkpoint.py``), from
which ``resume`` continues.

``build``, ``Probes``, ``contact_columns`` and ``contact_values`` of ``model.py`` are available
here too, for scripts that drive the model themselves.
"""

from __future__ import annotations

import json
import pathlib
from collections.abc import Mapping

from mpi4py import MPI

from dolfinx_dem import io
from dolfinx_dem.dynamics import DynamicRun
from dolfinx_dem.errors import InputError
from dolfinx_dem.fem.scene_run import FEMP1Run
from dolfinx_dem.model import Probes, build, contact_columns, contact_values  # noqa: F401 (public API)
from dolfinx_dem.static_simulation import StaticRun


def run(scene: Mapping, out: str | pathlib.Path, comm: MPI.Comm = MPI.COMM_WORLD, quiet: bool = False,
        overwrite: bool = False, checkpoint_every: int | None = None) -> dict:
    """Run a validated scene into the folder ``out``; returns the summary.

    ``overwrite``: replace another run held in ``out`` (refused otherwise). ``quiet``: no
    progress lines. ``checkpoint_every``: steps between checkpoints of a dynamic run (besides
    the one at an interrupt and at the end). Input errors are raised before ``out`` is touched.
    """
    if "statics" in scene and checkpoint_every is not None:
        raise InputError("a static scene has no time steps to checkpoint (drop --checkpoint-every)")
    output = io.OutputDirectory(out, comm, overwrite=overwrite)
    output.check()
    if "statics" in scene:
        return StaticRun(scene, comm).run(output)
    if scene.get("method") == "fem-P1":
        if checkpoint_every is not None:
            raise InputError("method 'fem-P1' writes no checkpoints (drop --checkpoint-every)")
        return FEMP1Run(scene, comm, quiet=quiet).run(output)
    return DynamicRun(scene, comm, quiet=quiet, checkpoint_every=checkpoint_every).run(output)


def resume(folder: str | pathlib.Path, comm: MPI.Comm = MPI.COMM_WORLD,
           overrides: Mapping[str, object] | None = None, quiet: bool = False,
           checkpoint_every: int | None = None) -> dict:
    """Continue the dynamic run held in ``folder`` from its checkpoint, appending to its outputs;
    returns the summary. ``overrides`` may only change ``time.end``."""
    summary = pathlib.Path(folder) / "summary.json"
    if io.call_on_root(comm, lambda: summary.is_file() and json.loads(summary.read_text()).get("method") == "fem-P1"):
        raise InputError(f"{folder} holds a fem-P1 run, which writes no checkpoint and cannot be resumed")
    output = io.OutputDirectory(folder, comm, resume=True)
    output.check()
    return DynamicRun.resume(folder, comm, overrides, quiet, checkpoint_every).run(output)
