"""Reference solutions of the 1D dynamic Signorini benchmarks (dolfinx_dem.exact).

Benchmark 1 (impact) has a closed form; benchmark 2 (bounce under gravity) is computed by the
method of characteristics, which is exact on its grid when the contact status changes at grid
times: it must reproduce benchmark 1 to round-off, conserve the total energy to round-off, give
the same values on every grid, and be periodic. The period found is 16/3 s (two contacts of
2/3 s per period, 8/3 s apart; 8/3 s itself is not a period).
"""

import time

import numpy as np
import pytest

from dolfinx_dem import exact

L, RHO, E, C = 10.0, 1.0, 900.0, 30.0
T1, T2 = 0.5, 0.5 + 2 * L / C  # benchmark 1: impact, release (7/6)
PERIOD = 16.0 / 3.0


@pytest.fixture(scope="module")
def bounce():
    """Benchmark 2 on [0, 20] with n = 60 cells (dt = 1/180 s)."""
    return exact.signorini_bar_characteristics(L, RHO, E, 0.0, 10.0, 5.0, 20.0, 60)


# -- benchmark 1: closed form ---------------------------------------------------------------------


def test_impact_closed_form():
    t = np.array([0.0, 0.25, 0.5, 0.8, 7 / 6 - 1e-9, 7 / 6, 1.5, 2.0])
    x = exact.impact_tip_position(t)
    assert x.shape == t.shape
    rebound = [10 * (1.5 - 7 / 6), 10 * (2.0 - 7 / 6)]
    assert np.allclose(x, [5.0, 2.5, 0.0, 0.0, 0.0, 0.0, *rebound], atol=1e-12)
    p = exact.impact_contact_pressure(t)
    assert np.array_equal(p, [0, 0, 300, 300, 300, 0, 0, 0])  # rho c |v0| on [t1, t2)
    assert np.array_equal(exact.impact_tip_velocity(t), [-10, -10, 0, 0, 0, 10, 10, 10])
    # contact duration 2 L / c, rebound velocity +|v0| (finite difference of the closed form)
    assert T2 - T1 == pytest.approx(2 / 3)
    rebound = (exact.impact_tip_position(1.9) - exact.impact_tip_position(1.4)) / 0.5
    assert rebound == pytest.approx(10.0, abs=1e-12)
    assert np.ndim(exact.impact_tip_position(0.3)) == 0
    # no contact when moving away
    assert exact.impact_tip_position(1.0, v0=2.0) == pytest.approx(7.0)
    assert exact.impact_contact_pressure(1.0, v0=2.0) == 0.0


@pytest.mark.parametrize("n", [2, 20, 60, 120])
def test_characteristics_reproduce_impact(n):
    sol = exact.signorini_bar_characteristics(L, RHO, E, -10.0, 0.0, 5.0, 2.0, n)
    assert sol.exact and [kind for _, kind, _ in sol.events] == ["contact", "release"]
    assert [ev[0] for ev in sol.events] == pytest.approx([T1, T2], abs=1e-12)
    # grid values (right limits at the jumps, as the closed form)
    assert np.abs(sol.x_tip - exact.impact_tip_position(sol.t)).max() < 1e-10
    assert np.abs(sol.p - exact.impact_contact_pressure(sol.t)).max() < 1e-10
    assert np.abs(sol.v_tip - exact.impact_tip_velocity(sol.t)).max() < 1e-10
    # between grid times
    t = np.random.default_rng(0).uniform(0.0, sol.t[-1], 500)
    assert np.abs(sol.tip_position(t) - exact.impact_tip_position(t)).max() < 1e-10
    p = exact.impact_contact_pressure(t)
    assert np.abs(sol.contact_pressure(t) - p).max() < 1e-10
    # rigid, unstressed rebound: w+ = w- = +|v0| everywhere
    assert np.abs(sol.w_plus - 10.0).max() < 1e-10 and np.abs(sol.w_minus - 10.0).max() < 1e-10
    assert np.ptp(sol.energy) < 1e-10 * sol.energy[0]
    assert sol.energy[0] == pytest.approx(0.5 * RHO * L * 100)


def test_off_grid_event_is_flagged():
    """n odd: t1 = 0.5 = 1.5 n dt is not a grid time; warned, flagged, error O(dt)."""
    with pytest.warns(RuntimeWarning, match="between grid times"):
        sol = exact.signorini_bar_characteristics(L, RHO, E, -10.0, 0.0, 5.0, 2.0, 21)
    assert not sol.exact
    assert sol.events[0][:2] == (pytest.approx(T1), "contact") and not sol.events[0][2]
    assert sol.x_tip.min() >= 0.0
    assert np.abs(sol.x_tip - exact.impact_tip_position(sol.t)).max() < 2 * 10 * sol.dt


# -- benchmark 2: bounce under gravity ------------------------------------------------------------


def test_bounce_contact_and_pressure(bounce):
    sol = bounce
    assert sol.exact
    assert sol.x_tip.min() >= -1e-12
    assert min(sol.p.min(), sol.p_minus.min()) >= 0.0
    assert np.all(sol.p[~np.append(sol.contact, True)] == 0.0)
    # free fall, first contact at sqrt(2 h0 / g) = 1 with velocity -g = -10
    assert sol.events[0][:2] == (pytest.approx(1.0, abs=1e-12), "contact")
    i1 = int(round(1.0 / sol.dt))
    before = sol.t < 1.0 - 1e-9
    assert np.abs(sol.x_tip[before] - (5.0 - 5.0 * sol.t[before] ** 2)).max() < 1e-10
    assert sol.v_tip_minus[i1] == pytest.approx(-10.0, abs=1e-10)
    # p = rho c g t on [1, 1 + 2 L / c) = [1, 5/3), then release (left limit 500)
    assert sol.events[1][:2] == (pytest.approx(5 / 3, abs=1e-12), "release")
    first = (sol.t > 1.0 - 1e-9) & (sol.t < 5 / 3 - 1e-9)
    assert np.abs(sol.p[first] - RHO * C * 10.0 * sol.t[first]).max() < 1e-10
    assert np.abs(sol.p[first] - (300.0 + 300.0 * (sol.t[first] - 1.0))).max() < 1e-10
    assert sol.p_minus[int(round(5 / 3 / sol.dt))] == pytest.approx(500.0, abs=1e-10)
    t = np.linspace(1.0, 5 / 3, 101)[:-1] + 1e-4
    assert np.abs(sol.contact_pressure(t) - 300.0 * t).max() < 1e-10
    # after the release the tip leaves with 10/3 and accelerates upwards:
    # v = g t - 40/3 on (5/3, 7/3) (by hand, following the characteristics)
    free = (sol.t > 5 / 3 + 1e-9) & (sol.t < 7 / 3 - 1e-9)
    assert np.abs(sol.v_tip[free] - (10.0 * sol.t[free] - 40 / 3)).max() < 1e-10
    # contacts every 8/3 s, each lasting 2/3 s
    times = np.array([ev[0] for ev in sol.events])
    assert np.allclose(times[0::2], 1.0 + 8 / 3 * np.arange(len(times[0::2])), atol=1e-10)
    assert np.allclose(times[1::2] - times[0::2][: len(times[1::2])], 2 / 3, atol=1e-10)


def test_bounce_energy_conservation(bounce):
    """kinetic + elastic + gravity potential from the grid fields: constant to round-off."""
    sol = bounce
    energy = sol.energy
    assert energy[0] == pytest.approx(RHO * 10.0 * L * (5.0 + L / 2))  # at rest, unstressed
    assert np.ptp(energy) / energy[0] < 1e-10
    # all three terms move: the check is not trivial
    assert sol.kinetic.max() > 400 and sol.elastic.max() > 600 and np.ptp(sol.gravity) > 600


def test_bounce_independent_of_grid(bounce):
    """Exact on every grid: n = 15 and n = 60 agree on the common grid times."""
    coarse = exact.signorini_bar_characteristics(L, RHO, E, 0.0, 10.0, 5.0, 20.0, 15)
    fine = bounce
    assert coarse.exact
    assert np.abs(fine.x_tip[::4] - coarse.x_tip).max() < 1e-10
    assert np.abs(fine.p[::4] - coarse.p).max() < 1e-10
    t = np.random.default_rng(1).uniform(0.0, 20.0, 1000)
    assert np.abs(fine.tip_position(t) - coarse.tip_position(t)).max() < 1e-10
    assert np.abs(fine.contact_pressure(t) - coarse.contact_pressure(t)).max() < 1e-10


def test_bounce_period(bounce):
    sol = bounce
    # first return to the initial state (tip at h0, at rest, unstressed)
    back = (sol.kinetic + sol.elastic < 1e-10) & (np.abs(sol.x_tip - 5.0) < 1e-10)
    period = sol.t[np.flatnonzero(back)[1]]
    assert abs(period - PERIOD) < 1e-9
    assert exact.BOUNCE_PERIOD == PERIOD
    # the whole state is back: the fields vanish at t = 16/3
    one = exact.signorini_bar_characteristics(L, RHO, E, 0.0, 10.0, 5.0, PERIOD, 60)
    assert one.t[-1] == pytest.approx(PERIOD, abs=1e-12)
    assert abs(one.x_tip[-1] - 5.0) < 1e-9
    assert max(np.abs(one.w_plus).max(), np.abs(one.w_minus).max()) < 1e-9
    # time series shifted by the period coincide; half the period (two bounces differ) does not
    for shift, periodic in ((PERIOD, True), (PERIOD / 2, False)):
        k = int(round(shift / sol.dt))
        dx = np.abs(sol.x_tip[k:] - sol.x_tip[:-k]).max()
        dp = np.abs(sol.p[k:] - sol.p[:-k]).max()
        assert (max(dx, dp / 300.0) < 1e-9) == periodic
    t = np.linspace(0.0, 20.0 - PERIOD, 777)
    assert np.abs(sol.tip_position(t + PERIOD) - sol.tip_position(t)).max() < 1e-9
    # time reversal about t = 0 and the period: x(P - t) = x(t)
    t = t[t < PERIOD]
    assert np.abs(sol.tip_position(PERIOD - t) - sol.tip_position(t)).max() < 1e-9


def test_bounce_api():
    start = time.perf_counter()
    t, x, p = exact.bounce_solution()
    assert t.shape == x.shape == p.shape and t[0] == 0.0 and t[-1] == pytest.approx(20.0)
    assert np.allclose(np.diff(t), 1.0 / 360.0)
    assert time.perf_counter() - start < 2.0
    assert np.abs(exact.bounce_tip_position(t) - x).max() < 1e-10
    assert np.abs(exact.bounce_contact_pressure(t) - p).max() < 1e-9
    assert np.ndim(exact.bounce_tip_position(0.5)) == 0
    assert exact.bounce_tip_position(0.5) == pytest.approx(5.0 - 5.0 * 0.25)
    pressure = exact.bounce_contact_pressure(np.array([[1.2, 0.5]]))
    assert pressure.shape == (1, 2) and np.allclose(pressure, [[360.0, 0.0]], rtol=0, atol=1e-10)
    # beyond 20 s the cache is extended
    x25 = exact.bounce_tip_position(25.0)
    assert x25 == pytest.approx(float(exact.bounce_tip_position(25.0 - 4 * PERIOD)), abs=1e-9)
    with pytest.raises(ValueError):
        exact.bounce_tip_position(-1.0)
    with pytest.raises(ValueError):
        exact.signorini_bar_characteristics(-1.0, RHO, E, 0.0, 10.0, 5.0, 1.0, 10)
