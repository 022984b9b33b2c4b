"""Controls of a running time integration: stopping it cleanly on a signal, and its progress line.

Interrupts. SIGINT (Ctrl-C) and SIGTERM (``kill``, a batch system's time limit) only set a flag;
the run loop calls ``Interrupts.requested()`` after every step, all processes stop after the same
step, close their outputs and write a checkpoint. The handlers are installed when the run starts,
after every import (``import gmsh`` resets SIGINT to the default action, which kills the process
at once), and put back at every check if something replaced them. A second signal while the
first is being handled stops the process at once (KeyboardInterrupt).

Cost. Looking at the handlers (``signal.getsignal``) and agreeing under MPI (one reduction) cost a
sizeable part of a short step if done at every step. So the check runs every ``k`` steps, ``k``
adapted so that checks are about ``interval`` (0.02 s) of wall time apart; under MPI, rank 0's
``k`` and the flags travel in one non-blocking reduction (``MPI_Iallreduce``, completed at the
next check), so that every process checks at the same steps and stops at the same one, with
no synchronisation added. A step that wrote an output time (slow: files are created, renamed
and synced) is followed by a check that agrees at once (``requested(now=True)``, a blocking
reduction after a step that already synchronised): before, a check interval that held such
writes stretched the stop to 0.3 s. A run stops within about 0.05 s of the signal, or after
the step in progress if one step takes longer.

``mpirun`` does not pass SIGINT or SIGTERM on: on either it sends the processes SIGCONT, then
SIGTERM and SIGKILL. Open MPI 4 (Debian 12) waits ``odls_base_sigkill_timeout`` seconds (default
1) before each, which ``OMPI_MCA_odls_base_sigkill_timeout=30`` raises; Open MPI 5.0.7 (Debian 13)
sends SIGTERM 0.25 s after SIGCONT and SIGKILL 0.25 s later, and neither that variable nor
``PRTE_MCA_odls_base_sigkill_timeout`` changed it (measured). The run must reach its checkpoint
within that time; ``mpirun`` itself then exits with 1 whatever the processes return. A run
killed then keeps its last complete checkpoint and every listed output time (``checkpoint.py``,
``io.SolutionWriter``). A signal sent to the processes
themselves (``kill`` of their ids, a batch system such as SLURM) gives every process and
``mpirun`` the exit status 130.
"""

from __future__ import annotations

import signal
import sys
import time

import numpy as np
from mpi4py import MPI

#: The signals that stop a run cleanly.
SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupts:
    """Context manager: SIGINT and SIGTERM request a clean stop (see the module docstring).
    ``interval``: wall time (s) between checks of the flag."""

    def __init__(self, comm: MPI.Comm, interval: float = 0.02):
        self.comm, self.interval = comm, interval
        self.signal = 0  # the first signal received, 0 if none
        self._previous = {}
        self._send, self._result = np.zeros(2, dtype=np.int64), np.zeros(2, dtype=np.int64)
        self._request = None
        self._every, self._count, self._last = 1, 0, time.perf_counter()

    def _handle(self, signum, frame):
        if self.signal:
            self._restore()
            raise KeyboardInterrupt(f"second signal {signal.Signals(signum).name}: stopped at once")
        self.signal = signum

    def _install(self):
        for s in SIGNALS:
            if signal.getsignal(s) != self._handle:
                signal.signal(s, self._handle)

    def _restore(self):
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        self._previous = {}

    def __enter__(self) -> Interrupts:
        self._previous = {s: signal.getsignal(s) for s in SIGNALS}
        self._install()
        self._last = time.perf_counter()
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if self._request is not None:
            self._request.Wait()
            self._request = None
        self._restore()
        return False

    @property
    def name(self) -> str:
        """Name of the signal received (e.g. "SIGINT"), "" if none."""
        return signal.Signals(self.signal).name if self.signal else ""

    def requested(self, now: bool = False) -> bool:
        """Collective: whether to stop now (call it after every step). Every process gets the
        same answer at the same call: True at the first check after the signal in serial, at
        the second under MPI (the reduction started at one check completes at the next).
        ``now`` (the same on every process: after a step that wrote an output time, which is
        slow) checks at this call and agrees at once (a blocking reduction): a step that took
        much longer than the others does not stretch the time to the stop."""
        self._count += 1
        if self._count < self._every and not now:
            return False
        steps, self._count = self._count, 0
        self._install()
        t = time.perf_counter()
        # steps to the next check, for checks `interval` apart (at most doubling each time)
        every = int(min(2 * self._every, max(1, steps * self.interval / max(t - self._last, 1e-9))))
        self._last = t
        if self.comm.size == 1:
            self._every = every
            return bool(self.signal)
        stop = False
        if self._request is not None:
            self._request.Wait()
            self._request = None
            stop, self._every = bool(self._result[0]), int(self._result[1])
        if stop:
            return True
        self._send[:] = self.signal, every if self.comm.rank == 0 else 0
        if now:
            self.comm.Allreduce(self._send, self._result, op=MPI.MAX)
            stop, self._every = bool(self._result[0]), int(self._result[1])
        else:
            self._request = self.comm.Iallreduce(self._send, self._result, op=MPI.MAX)
        return stop


class Progress:
    """Rank 0 reports the step, t, the relative pseudo-energy drift and the time left on stderr.

    On a terminal, in serial, one line rewritten at most every 0.5 s; otherwise (a log file, a
    pipe, under ``mpirun``) a new line every ``interval`` seconds (10). ``quiet`` silences it.
    ``first``: the step the run (re)starts from, for the estimate of the time left.
    """

    def __init__(self, comm: MPI.Comm, n_steps: int, quiet: bool, first: int = 0, interval: float = 10.0,
                 stream=None):
        self.stream = sys.stderr if stream is None else stream
        self.enabled = comm.rank == 0 and not quiet
        self.terminal = comm.size == 1 and self.stream.isatty()
        self.interval = 0.5 if self.terminal else interval
        self.n_steps, self.first = n_steps, first
        self.start = self.last = time.perf_counter()
        self._open_line = False  # a terminal line without its newline yet

    def update(self, n: int, t: float, drift: float, conservative: bool = True):
        """Report step ``n`` at time ``t`` if it is time to; ``drift``: relative pseudo-energy
        drift (when the scene is not ``conservative``: the error of the balance E - W with the
        work W of the time-dependent data counted)."""
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self.last < self.interval and not (self.terminal and n == self.n_steps):
            return
        self.last = now
        left = (now - self.start) / max(n - self.first, 1) * (self.n_steps - n)
        energy = f"energy drift {drift:.2e}" if conservative else f"energy balance {drift:.2e} (work counted)"
        line = f"step {n}/{self.n_steps}  t = {t:.5g}  {energy}  {left:.0f} s left"
        if self.terminal:
            self._open_line = n != self.n_steps
            self.stream.write(f"\r{line} " + ("" if self._open_line else "\n"))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def finish(self):
        """End a rewritten terminal line that did not reach the last step."""
        if self._open_line:
            self.stream.write("\n")
            self.stream.flush()
            self._open_line = False
