"""The Markdown pages of validation/friction_slide.py: scheme A's (``page``, docs/validation/friction.md)
and scheme B's or dem-AB's (``page_b``, friction_scheme_b.md, friction_scheme_ab.md), from the
study's results; ``v0`` the discs' launch speed."""

import json
import pathlib


def held_table(held: list, drift: str = "contact cells' drift after the first step (m)") -> list[str]:
    """The page's section on the block held by friction."""
    lines = ["", "## Held by friction (mu = 0.5), from the settled state", "",
             f"| tan t | cells | steps | {drift} | first step with a facet at the Coulomb limit | D at the end (J/m) "
             "| balance error |", "|---" * 7 + "|"]
    for r in held:
        lines.append(f"| {r['tan']:g} | {r['cells']} | {r['steps']} | {r['drift_after_first_step']:.2e} | "
                     f"{r['first_slip_step'] or 'none'} | {r['dissipation']:.2e} | {r['balance_error']:.1e} |")
    return lines


def rolling_table(rows: list, v0: float) -> list[str]:
    """The page's section on the disc; rows with ``speed_at_end`` (scheme B's) add the bound, the
    speed and the slip at 2 t* and the smallest D increment."""
    more = "speed_at_end" in rows[0]
    lines = ["", "## A disc launched sliding without spin (mu = 0.5, v0 = 0.05 m/s, E = 1e6 Pa)", "",
             "| h (m) | cells | " + ("bound | " if more else "") + "slip stops (ms) | t* (ms) | error | speed at t* "
             "(m/s) | 2/3 v0 | error | " + ("speed at 2 t* (m/s) | slip at 2 t* (m/s) | " if more else "")
             + "D (J/m) | rigid D | balance error |" + (" smallest D increment | wall (s) |" if more else ""),
             "|---" * (16 if more else 11) + "|"]
    for r in rows:
        stops = ("not within 2 t* | " + f"{1e3 * r['t_star']:.4f} | |" if r["slip_stops"] is None else
                 f"{1e3 * r['slip_stops']:.4f} | {1e3 * r['t_star']:.4f} | {100 * r['slip_stops_error']:+.2f} % |")
        lines.append(f"| {r['h']:g} | {r['cells']} | " + (f"{'per facet' if r['per_facet'] else 'spread'} | "
                                                           if more else "")
                     + f"{stops} {r['speed_at_t_star']:.5f} | {2 / 3 * v0:.5f} | {100 * r['speed_error']:+.2f} % | "
                     + (f"{r['speed_at_end']:.5f} | {r['slip_at_end']:.5f} | " if more else "")
                     + f"{r['dissipation']:.4e} | {r['rigid_dissipation']:.4e} | {r['balance_error']:.1e} |"
                     + (f" {r['min_dissipation_increment']:.1e} | {r['wall_time_s']:.1f} |" if more else ""))
    return lines


def page(results: dict, v0: float) -> str:
    lines = ["# Friction: a block sliding down a slope and a block held by it", "",
             f"Written by `validation/friction_slide.py` (one process). Command: `{results['command']}`.", "",
             "The block and the measures: the script's docstring. Scheme A, CFL 0.5 of the bound.", "",
             "## Sliding from rest, dropped at zero height (tan t = 0.577, t = 30 deg)", "",
             "| mu | cells | acceleration (m/s^2) | g (sin t - mu cos t) | error | bottom cells' velocity spread (m/s)"
             " | balance error | smallest D increment | wall (s) |", "|---" * 9 + "|"]
    for r in results["sliding"]:
        lines.append(f"| {r['mu']:g} | {r['cells']} | {r['acceleration']:.4f} | {r['exact']:.4f} | "
                     f"{100 * r['relative_error']:+.2f} % | {r['bottom_velocity_spread']:.3f} | {r['balance_error']:.1e} | "
                     f"{r['min_dissipation_increment']:.1e} | {r['wall_time_s']:.1f} |")
    lines += held_table(results["held"])
    lines += rolling_table(results["rolling"], v0)
    lines += ["", "## 3D: a block sliding down a slope, 30 degrees from x (6 x 6 x 3 cubes)", "",
              "| mu | cells | acceleration (m/s^2) | g (sin t - mu cos t) along the slope | error | balance error |",
              "|---" * 6 + "|"]
    for r in results["sliding3d"]:
        a = ", ".join(f"{x:.4f}" for x in r["acceleration"])
        e = ", ".join(f"{x:.4f}" for x in r["exact"])
        lines.append(f"| {r['mu']:g} | {r['cells']} | ({a}) | ({e}) | {100 * r['relative_error']:.2f} % | "
                     f"{r['balance_error']:.1e} |")
    lines += ["", "## The stable step with and without friction (sliding, 16 x 8 squares)", "",
              "| mu | largest stable dt / bound |", "|---|---|"]
    lines += [f"| {mu} | {f:g} |" for mu, f in results["stable_factor"].items()]
    lines += ["", "## 3D: a ball launched sliding without spin (mu = 0.5, v0 = 0.05 m/s, E = 1e6 Pa)", "",
              "t* = 2 v0 / (7 mu g); the speed is the centre of mass's, the slip that of the contact point of the "
              "rigid motion fitted to the cells' momenta (v + omega x (0, 0, -z_G), z_G the centroid's height).", "",
              "| h (m) | cells | steps | slip stops (ms) | t* (ms) | error | speed at t* (m/s) | 5/7 v0 | error | "
              "speed after t*: mean (min - max) | error of the mean | D (J) | rigid D | balance error | smallest D "
              "increment | slipping facets while sliding | steps with a slipping facet after | wall (s) |",
              "|---" * 18 + "|"]
    for r in results["rolling3d"]:
        lines.append(f"| {r['h']:g} | {r['cells']} | {r['steps']} | {1e3 * r['slip_stops']:.4f} | "
                     f"{1e3 * r['t_star']:.4f} | {100 * r['slip_stops_error']:+.2f} % | {r['speed_at_t_star']:.5f} | "
                     f"{5 / 7 * v0:.5f} | {100 * r['speed_error']:+.2f} % | {r['rolling_speed']:.5f} "
                     f"({r['rolling_speed_range'][0]:.5f} - {r['rolling_speed_range'][1]:.5f}) | "
                     f"{100 * r['rolling_speed_error']:+.2f} % | {r['dissipation']:.4e} | "
                     f"{r['rigid_dissipation']:.4e} | {r['balance_error']:.1e} | {r['min_dissipation_increment']:.1e} | "
                     f"{r['slipping_while_sliding']} | {r['steps_slipping_after_stop']} | {r['wall_time_s']:.0f} |")
    lines += ["", "Friction acts on the contact cell, whose centre lies above the floor: the ball turns about that "
              "centre, with the lever L = z_G - z_c. The rigid law with that lever and the mesh's inertia, "
              "t*_c = v0 / (mu g (1 + I / (m L^2))) and the speed v0 / (1 + I / (m L^2)), against the slip of the "
              "fitted motion at the cell's centre (v - omega L):", "",
              "| h (m) | contact cell's centre over the floor (mm) | t*_c (ms) | slip at the cell stops (ms) | error | "
              "rolling speed with L (m/s) | the mean after t*: error |", "|---" * 7 + "|"]
    for r in results["rolling3d"]:
        lines.append(f"| {r['h']:g} | {1e3 * (r['height'] - r['lever']):.2f} | {1e3 * r['t_star_cell']:.4f} | "
                     f"{1e3 * r['cell_slip_stops']:.4f} | {100 * r['cell_slip_stops_error']:+.2f} % | "
                     f"{r['rolling_speed_cell']:.5f} | {100 * (r['rolling_speed'] / r['rolling_speed_cell'] - 1):+.2f} % |")
    lines += ["", "The ball stands on the centre of one boundary facet, right below its centroid (``ball`` in the "
              "script). A first variant stood on three facet centres: it rolled over the leading one, off its "
              "centroid's foot, and climbed, its normal force and friction up to 1.4 m g at h = 0.02 m (measured with "
              "that variant, not by this script). The slip stops late against t* because the contact cell's centre, "
              "the point the law holds still, lies O(h) above the floor (the theory's \"where the slip is "
              "measured\"), by a height that depends on the cell under the ball more than on h; against the rigid "
              "law with the cell's lever it stops within 1 % (the 1 % slip threshold itself moves it up to 1 % "
              "early), and the ball rolls on at that law's speed within 0.7 %. Once stuck, the ball's tangential "
              "compliance at its contact makes its speed oscillate about the rolling speed (the min - max column; no "
              "damping), the friction force turning sign within the Coulomb limit: the mean over (t*, 2 t*) covers "
              "about two periods."]
    for stability in results["stability3d"]:
        factors = [r["f"] for r in max(stability["0"], stability["0.5"], key=len)]
        lines += ["", f"## 3D: the stable step with and without friction (the ball above, h = {stability['h']:g} m, "
                  "over 2 t*)", "", "dt = f times the bound; each entry the largest mechanical energy over the "
                  "initial one (friction only takes energy: above 1, an unstable mode grew, even if friction then "
                  "damped it), or the stability monitor's verdict. The elastic operator's own limit (SLEPc): "
                  f"{stability['eigenvalue_over_bound']:.4f} times the bound.", "",
                  "| mu | " + " | ".join(f"f = {f:.2f}" for f in factors) + " |", "|---" * (len(factors) + 1) + "|"]
        for mu in ("0", "0.5"):
            cells = [f"{r['largest_mechanical'] / r['initial_mechanical']:.3f}" if r["stable"] else "unstable"
                     for r in stability[mu]]
            lines.append(f"| {mu} | " + " | ".join(cells + [""] * (len(factors) - len(cells))) + " |")
    lines += ["", "Friction leaves the ball's stable step where it was: the same f completes with and without it, "
              "up to the elastic operator's own limit. In the variant standing on three facet centres (h = 0.03 m, "
              "measured with that variant, not by this script), friction let a mode grow above the bound: the largest "
              "mechanical energy rose 1.04, 1.06, 1.21 and 5.4 times the initial one at f = 1.01, 1.02, 1.03 and "
              "1.04 (friction damped it again; the monitor stopped f = 1.04), against 1.000 without friction up to "
              "f = 1.04; both blew up at 1.05. Friction can bring the stable step down towards the bound; it did not "
              "bring it below in any run.",
              "", "## Oblique impact on a rigid wall", "",
              "A disc and a ball hitting a rigid wall obliquely, in gross slip and across the normalised incidence",
              "of Maw, Barber and Fawcett, with the balance at every step: [oblique_impact.md](oblique_impact.md)",
              "(`validation/oblique_impact.py`). Friction between bodies: [friction_bodies.md](friction_bodies.md)."]
    return "\n".join(lines) + "\n"


def page_b(results: dict, v0: float) -> str:
    """The Markdown page of ``scheme_b``'s results, with scheme A's of friction.json beside them."""
    documented = json.loads((pathlib.Path(__file__).parents[1] / "docs" / "validation" / "friction.json").read_text())
    scheme_a = {(r["mu"], r["cells"]): r["relative_error"] for r in documented["sliding"]}
    lines = [f"# Friction on scheme B candidates (dem-{results['scheme']}): the spread bound", "",
             f"Written by `validation/friction_slide.py --scheme ...` (one process). Command: `{results['command']}`.", "",
             "The block and the measures: the script's docstring; CFL 0.5 of the bound. The law (docs/theory.md, "
             "Friction on rigid obstacles): each scheme B candidate's bound lags its normal impulse spread over its "
             "neighbours, N'_f = |f| sum_g N_g / A_g, before the positive part (``contact.friction.Spread``). "
             "\"per facet\": the bound of scheme A, mu times the lagged N_f^+ of the facet's own normal impulse. "
             "sum N+ / sum N: the facets' normal impulses' positive parts over their sum, over the facets and steps; "
             "T / (mu N): the friction impulse over mu sum N_f; after 0.1 s: the same over the fit's window, and the "
             "mean normal force there over the weight's normal part. Scheme A: docs/validation/friction.json.", "",
             "## Sliding from rest, dropped at zero height (tan t = 0.577, t = 30 deg)", "",
             "| mu | cells | bound | acceleration (m/s^2) | g (sin t - mu cos t) | error | scheme A's error | "
             "sum N+ / sum N | T / (mu N) | after 0.1 s: T / (mu N) | after 0.1 s: N / (m g cos t) | balance error | "
             "smallest D increment | wall (s) |", "|---" * 14 + "|"]
    for r in results["sliding"]:
        a = scheme_a.get((r["mu"], r["cells"]))
        lines.append(f"| {r['mu']:g} | {r['cells']} | {'per facet' if r['per_facet'] else 'spread'} | "
                     f"{r['acceleration']:.4f} | {r['exact']:.4f} | {100 * r['relative_error']:+.2f} % | "
                     + (f"{100 * a:+.2f} %" if a is not None else "") + f" | {r['normal_positive_ratio']:.4f} | "
                     f"{r['friction_over_mu_n']:.4f} | {r['friction_over_mu_n_late']:.4f} | "
                     f"{r['normal_over_weight_late']:.4f} | {r['balance_error']:.1e} | {r['min_dissipation_increment']:.1e} | "
                     f"{r['wall_time_s']:.1f} |")
    lines += held_table(results["held"], "contact cells' drift after the first step (m; the block is 1 m long)")
    lines += ["", "## 3D: a block sliding down a slope, 30 degrees from x (n x n x n/2 cubes of six tetrahedra)", "",
              "The acceleration's error along the slope and its whole error's size (its components across the slope and "
              "along the normal included), both over |g (sin t - mu cos t)|; scheme A run alongside.", "",
              "| mu | cells | method, bound | acceleration (m/s^2) | g (sin t - mu cos t) along the slope | error along "
              "the slope | size of the error | balance error | smallest D increment |", "|---" * 9 + "|"]
    for r in results.get("sliding3d", []):
        bound = "" if r["scheme"] == "A" else (", per facet" if r["per_facet"] else ", spread")
        lines.append(f"| {r['mu']:g} | {r['cells']} | dem-{r['scheme']}{bound} | "
                     f"({', '.join(f'{x:.4f}' for x in r['acceleration'])}) | "
                     f"({', '.join(f'{x:.4f}' for x in r['exact'])}) | {100 * r['along_error']:+.2f} % | "
                     f"{100 * r['relative_error']:.2f} % | {r['balance_error']:.1e} | "
                     f"{r['min_dissipation_increment']:.1e} |")
    if "stable_factor" in results:
        nx = int(results["command"].split("--meshes ")[1].split()[0])
        lines += ["", f"## The stable step with and without friction (sliding, {nx} x {nx // 2} squares)", "",
                  "The block above from rest for 0.5 s at dt = f times the bound, f = 1, 1.04, ..., 1.16: the largest f "
                  "the stability monitor let complete (scheme A: docs/validation/friction.json).", "",
                  "| mu | largest stable dt / bound | scheme A's |", "|---|---|---|"]
        lines += [f"| {mu} | {f:g} | {documented['stable_factor'].get(mu, '')} |" for mu, f in results["stable_factor"].items()]
    if "rolling" in results:
        lines += rolling_table(results["rolling"], v0)
        lines += ["", "The closed form: the slip (v + omega R, omega fitted to the cells' momenta) stops at t* = v0 / "
                  "(3 mu g), the disc then rolls at 2/3 v0; sliding on without turning it would decelerate at mu g, "
                  "through 2/3 v0 at t* as well, to v0 / 3 at 2 t*. Scheme A: docs/validation/friction.md."]
    return "\n".join(lines) + "\n"
