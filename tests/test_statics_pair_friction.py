"""Statics with friction between bodies (statics/pair_friction.py): the hertz disc on an elastic
block of its material (Cattaneo and Mindlin's identical bodies), the normal load, then a
tangential load on the disc in increments. Run serial and under ``mpirun -n 2`` (``-m mpi``)."""

import copy

import numpy as np
import pytest
from mpi4py import MPI

from dolfinx_dem import model, scenes, simulation
from dolfinx_dem.errors import InputError, SceneError
from dolfinx_dem.statics.friction import load_tangentially

MU, LOAD = 0.3, 2e6

DISC_ON_BLOCK = {
    "name": "disc-on-block",
    "method": "dem-A",
    "mesh": {"type": "discs", "discs": [[0.0, 0.200001, 0.2]], "rectangles": [[-0.3, -0.2, 0.3, 0.0]], "h": 0.04},
    "material": {"E": 25e6, "nu": 0.25, "rho": 1.0, "plane": "strain"},
    "loads": {"body_force": [0.0, -LOAD]},
    "dirichlet": [{"boundary": "y <= -0.2", "name": "base"}],
    "contact": {"boundary": ["(y >= -0.1) & (y <= 0.05)"], "friction": MU},
    "statics": {"fixed_mean": [0], "fixed_rotation": True, "tangential_body_force": [0.5 * MU * LOAD, 0.0],
                "increments": 5},
}


def _scene(**statics):
    scene = copy.deepcopy(DISC_ON_BLOCK)
    scene["statics"].update(statics)
    return scenes.validate(scene)


def _stick_ratio(friction):
    """The stick zone's half-width over c = a sqrt(1 - Q / (mu P))."""
    Q, P = friction["tangential_load"][0], friction["contact_force"]
    return friction["stick_half_width"] / (friction["contact_half_width"] * np.sqrt(1 - Q / (MU * P)))


@pytest.mark.mpi
def test_friction_between_bodies_is_the_incremental_coulomb_solution(tmp_path):
    """Q = mu P / 2 in 5 increments at h = 0.04 m. Stick pairs have not slipped since the normal
    step (their cells' relative tangential displacement below 1e-15 of the disc's radius) and
    carry |T| <= mu N; slip pairs carry mu N (to 1e-8) against their slip; the disc's contact
    forces (friction and the frictionless pair forces) balance the tangential load to 1e-10; the
    stick zone's half-width is within 10 % of Cattaneo and Mindlin's c (measured 0.927 of it with
    Debian 12's mesh, 0.918 with 13's; docs/validation/cattaneo_mindlin_bodies.md for finer meshes),
    and 1, 2 and 3 processes agree to 1e-9 (measured 1e-14)."""
    comm = MPI.COMM_WORLD
    problem = model.build(_scene(), comm)
    r = load_tangentially(problem, [0.5 * MU * LOAD, 0.0], 5, (0,), True)
    touching = r.normal > 0
    stick, slip = r.stick, touching & ~r.stick
    assert stick.sum() >= 3 and slip.sum() >= 2
    assert (np.abs(r.slip[stick]) < 1e-15 * 0.2).all()
    assert (np.abs(r.tangential[stick]) <= MU * r.normal[stick] * (1 + 1e-9)).all()
    assert np.allclose(np.abs(r.tangential[slip]), MU * r.normal[slip], rtol=1e-8)
    assert (r.tangential[slip] * r.slip[slip] < 0).all()  # the force opposes the slip
    assert [k.factor for k in r.increments] == [0.2, 0.4, 0.6, 0.8, 1.0]
    assert r.loaded.sum() == 1  # the disc, not the clamped block

    folder = comm.bcast(str(tmp_path), root=0)
    summary = simulation.run(_scene(), folder + "/run", comm)
    friction = summary["friction"]
    Q = friction["tangential_load"][0]
    assert Q == pytest.approx(0.5 * MU * friction["contact_force"], rel=0.01)
    assert friction["contact_tangential_force"] == pytest.approx(-Q, rel=1e-10)
    low, high = friction["slip_traction_ratio"]
    assert 1 - 1e-8 < low <= high < 1 + 1e-8
    ratio = _stick_ratio(friction)
    assert abs(ratio - 1) < 0.1
    if comm.size > 1:
        alone = simulation.run(_scene(), folder + "/alone", MPI.COMM_SELF) if comm.rank == 0 else None
        assert ratio == pytest.approx(comm.bcast(alone and _stick_ratio(alone["friction"]), root=0), rel=1e-9)
    if comm.rank == 0:
        data = np.loadtxt(folder + "/run/contact_traction.csv", delimiter=",", skiprows=1)
        assert data.shape[1] == 4 and (data[:, 3] == 1).sum() == friction["stick_pairs"]


def test_the_load_path_between_bodies_needs_a_free_body_and_a_tangential_load():
    scene = _scene()
    scene["dirichlet"].append({"boundary": "y >= 0.39", "name": "top"})  # the disc held too
    with pytest.raises(InputError, match="no body takes the tangential load"):
        load_tangentially(model.build(scene, MPI.COMM_WORLD), [1e5, 0.0], 2, (0,), True)
    with pytest.raises(InputError, match="must be parallel to the contact interface"):
        load_tangentially(model.build(_scene(), MPI.COMM_WORLD), [1e5, 1e5], 2, (0,), True)


def test_a_static_scene_with_friction_between_bodies_needs_its_load_path():
    scene = copy.deepcopy(DISC_ON_BLOCK)
    del scene["statics"]["tangential_body_force"], scene["statics"]["increments"]
    with pytest.raises(SceneError, match="'contact.friction': friction is path dependent"):
        scenes.validate(scene)
