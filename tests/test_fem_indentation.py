"""The DOLFINx FEM reference of a rigid cylinder indenting an elastic block (Nitsche contact).

One coarse mesh (h = 1e-2 m in the contact zone, P2), two indentations, solved once per process.
Converged numbers (docs/validation/indentation_fem.json): delta = 0.01 m gives P = 51.6 N/m,
a = 3.49e-2 m, close to the half-space estimate sqrt(4 P R / (pi E*)) = 3.46e-2 m.
"""

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem.fem.indentation import indentation_reference, solve_indentation

H = 1e-2
DELTAS = (0.005, 0.01)


@pytest.fixture(scope="module")
def coarse():
    return solve_indentation(MPI.COMM_WORLD, H, DELTAS)


@pytest.mark.mpi
def test_contact_force_equals_clamp_reaction_and_grows(coarse):
    for r in coarse:
        assert 1 <= r.iterations <= 20
        assert r.P > 0.0
        assert r.reaction == pytest.approx(r.P, rel=1e-8)
    assert coarse[1].P > 1.5 * coarse[0].P
    assert coarse[1].a > coarse[0].a
    # converged P is 51.6 N/m at delta = 0.01 m; a within 2 % of the half-space estimate here
    assert coarse[1].P == pytest.approx(51.6, rel=0.01)
    assert coarse[1].a == pytest.approx(coarse[1].hertz_a, rel=0.03)


@pytest.mark.mpi
def test_pressure_only_under_the_cylinder(coarse):
    """A wrong gap sign or normal would put pressure away from x = 0 or none under it."""
    for r in coarse:
        x, lam, g = r.contact_x, r.contact_pressure, r.contact_gap
        assert np.all(lam >= 0.0)
        assert np.all(lam[x > r.a + H] == 0.0)
        assert np.all(lam[x < 0.5 * r.a] > 0.0)
        # the gap is positive away from the contact; Nitsche's penetration is ~ p h / (gamma0 E)
        assert np.all(g[x > r.a + H] > 0.0)
        assert r.min_gap > -r.p_max * H / (r.gamma0 * 1e4)
        assert r.p_max == pytest.approx(r.hertz_p0, rel=0.05)


def test_bad_input():
    with pytest.raises(ValueError, match="increasing"):
        solve_indentation(MPI.COMM_SELF, H, [0.01, 0.005])
    with pytest.raises(ValueError, match="delta"):
        indentation_reference(-0.01, H)
    with pytest.raises(ValueError, match="mesh size"):
        indentation_reference(0.01, 0.2)


def test_reference_dict_is_the_solver_result(coarse):
    ref = indentation_reference(DELTAS[0], H, MPI.COMM_WORLD)
    assert {"P", "a", "p_max"} <= set(ref)
    for key in ("P", "a", "p_max"):
        assert ref[key] == pytest.approx(getattr(coarse[0], key), rel=1e-9)
