"""Helpers shared by the work-precision benchmarks (bench_signorini.py, bench_wave2d.py)."""

from __future__ import annotations

import math

import numpy as np


def time_to_error(errors, times, target):
    """Time at which the error reaches ``target``, log-log interpolated between consecutive
    meshes (None outside the measured range)."""
    e, w = np.log(np.asarray(errors)), np.log(np.asarray(times))
    for i in range(len(e) - 1):
        lo, hi = sorted((e[i], e[i + 1]))
        if lo <= math.log(target) <= hi and e[i] != e[i + 1]:
            s = (math.log(target) - e[i]) / (e[i + 1] - e[i])
            return float(math.exp(w[i] + s * (w[i + 1] - w[i])))
    return None
