"""Where the contact time of a `cradle` step goes: processor time per step of the `PairContact`
methods, of the compiled kernels they call (each call timed by a wrapper), of the MEMM step and
of the per-step contact outputs (the series' contact columns, ``model.contact_values``), over the
first 0.3 s (202 steps through the first impacts) or ``--t-end``; and the same for the steps
without any touching pair (``force_integral`` skipped them) and those in contact apart.

    .venv/bin/python benchmarks/contact3d_breakdown.py [--t-end 0.3]

Serial. The methods are timed by wrappers (a few microseconds per call); nested ones (``_build``
inside ``prepare``) are parts of their callers, and the kernels parts of the methods.
"""

from __future__ import annotations

import argparse
import collections
import functools
import time

from mpi4py import MPI

from dolfinx_dem import model, pair_contact, scenes
from dolfinx_dem.dynamics import DynamicRun
from dolfinx_dem.pair_contact import PairContact

METHODS = ("prepare", "_build", "force_integral", "energy_correction", "penetration", "pair_forces", "contact_force")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=0.3)
    args = parser.parse_args()
    seconds = collections.Counter()

    def timed(name, f):
        @functools.wraps(f)
        def wrapper(*a, **k):
            start = time.process_time()
            try:
                return f(*a, **k)
            finally:
                seconds[name] += time.process_time() - start
        return wrapper

    for name in METHODS:
        setattr(PairContact, name, timed(name, getattr(PairContact, name)))
    kernels = pair_contact.lib

    class Timed:  # the kernels, each call timed
        def __getattr__(self, name):
            return timed("kernel " + name, getattr(kernels, name))

    pair_contact.lib = Timed()
    run = DynamicRun(scenes.load("cradle", {"time.end": args.t_end}), MPI.COMM_SELF, quiet=True)
    stepper, contact = run.stepper, run.dem.pair_contact
    contact.seconds, step, outputs = 0.0, 0.0, 0.0
    kinds = {True: [0, 0.0, 0.0, 0.0], False: [0, 0.0, 0.0, 0.0]}  # quiet: steps, step, contact, outputs
    for _ in range(run.n_steps):
        start, before = time.process_time(), contact.seconds
        stepper.step()
        step_time = time.process_time() - start
        start = time.process_time()
        model.contact_values(run.dem, stepper.u, stepper.contact_patch_values())
        output_time = time.process_time() - start
        step, outputs = step + step_time, outputs + output_time
        kind = kinds[contact._flight[5]]
        kind[0] += 1
        kind[1:] = [kind[1] + step_time, kind[2] + contact.seconds - before, kind[3] + output_time]
    pair_contact.lib = kernels
    n = run.n_steps
    print(f"load average {open('/proc/loadavg').read().split()[:3]}; {n} steps, {contact.num_pairs} pairs listed, "
          f"{contact.rebuilds} list builds")
    print(f"MEMM step {1e3 * step / n:.2f} ms, of which contact (PairContact.seconds) {1e3 * contact.seconds / n:.2f} ms; "
          f"contact outputs {1e3 * outputs / n:.2f} ms per step")
    print(f"contact share: {contact.seconds / step:.3f} of the step, {(contact.seconds + outputs) / (step + outputs):.3f} "
          "with the outputs")
    for name in METHODS:
        print(f"  {name:20s} {1e3 * seconds[name] / n:.3f} ms/step")
    print(f"compiled kernels {1e3 * sum(v for k, v in seconds.items() if k.startswith('kernel')) / n:.3f} ms/step:")
    for name, value in sorted(((k, v) for k, v in seconds.items() if k.startswith("kernel")), key=lambda kv: -kv[1]):
        print(f"  {name[7:]:28s} {1e3 * value / n:.4f} ms/step")
    for quiet, (steps, step_time, contact_time, output_time) in kinds.items():
        if steps:
            print(f"{'steps without a touching pair' if quiet else 'steps in contact'}: {steps}, per step: MEMM step "
                  f"{1e3 * step_time / steps:.3f} ms, contact {1e3 * contact_time / steps:.3f} ms, outputs "
                  f"{1e3 * output_time / steps:.3f} ms")


if __name__ == "__main__":
    main()
