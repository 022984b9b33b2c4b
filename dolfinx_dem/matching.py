"""Matching of points given in two numberings: the facets or cells of one mesh distributed over
different numbers of processes carry different numbers, but the same positions."""

from __future__ import annotations

import numpy as np
import scipy.spatial


def match_points(stored: np.ndarray, current: np.ndarray, tolerance: float) -> np.ndarray:
    """``index`` with ``current[i] == stored[index[i]]`` to ``tolerance`` (distance), for two
    arrays of the same points (n, d) in different orders; a ``ValueError`` when they are not
    the same set of points (another mesh)."""
    stored, current = np.asarray(stored, dtype=float), np.asarray(current, dtype=float)
    if stored.shape != current.shape:
        raise ValueError(f"{len(stored)} stored points against {len(current)} now: another mesh")
    if len(stored) == 0:
        return np.zeros(0, dtype=np.int64)
    distance, index = scipy.spatial.cKDTree(stored).query(current)
    if distance.max() > tolerance or len(np.unique(index)) != len(index):
        k = int(np.argmax(distance))
        raise ValueError(f"no stored point within {tolerance:.3g} of {current[k].tolist()} (nearest at "
                         f"{distance[k]:.3g}): another mesh")
    return index.astype(np.int64)
