"""The vertex surface of the contact between bodies (contact/surface.py): its weights, its rows
on any number of processes, its inputs, and the hole it closes."""

import numpy as np
import pytest
import scipy.spatial
from helpers import cell_vector
from mpi4py import MPI
from pair_scenes import two_discs
from test_pair_contact3d import two_boxes

from dolfinx_dem import scenes, simulation
from dolfinx_dem.contact import PairContact
from dolfinx_dem.contact.surface import vertex_weights
from dolfinx_dem.errors import InputError


def test_vertex_weights_are_the_area_means_around_the_vertices():
    """Three triangles of areas 1, 2, 3 around vertex 0 (the first two share the edge 0-1, the
    third also touches vertex 9): beta by hand, rows >= 0 and summing to 1."""
    star_ids = np.array([[0, 1, 2], [0, 1, 3], [0, 3, 9]])
    area = np.array([1.0, 2.0, 3.0])
    beta = vertex_weights(star_ids, area, star_ids).toarray()
    # vertex means: 0 -> (1, 2, 3)/6, 1 -> (1, 2)/3, 2 -> (1), 3 -> (2, 3)/5, 9 -> (3)
    expected = np.array([
        [1 / 6 + 1 / 3 + 1, 2 / 6 + 2 / 3, 3 / 6],
        [1 / 6 + 1 / 3, 2 / 6 + 2 / 3 + 2 / 5, 3 / 6 + 3 / 5],
        [1 / 6, 2 / 6 + 2 / 5, 3 / 6 + 3 / 5 + 1],
    ]) / 3
    assert np.allclose(beta, expected, rtol=0, atol=1e-15)
    assert (beta >= 0).all() and np.allclose(beta.sum(axis=1), 1.0, rtol=0, atol=1e-15)


@pytest.mark.parametrize("scheme", ["A", "B"])
def test_the_vertex_surface_reproduces_translations_and_averages_convexly(scheme):
    """The records' rows K of the vertex surface: under scheme B their entries are convex weights
    of the cells (>= 0, summing to 1 per component); under either scheme a rigid translation
    of every cell moves every candidate facet by it, to rounding; and they differ from the
    facets' own reconstructions (each reads more cells)."""
    facet, vertex = (two_boxes(MPI.COMM_SELF, scheme, s).find(PairContact) for s in ("facet", "vertex"))
    F, G = vertex.pair_list.local, facet.pair_list.local
    assert np.array_equal(F.key, G.key)
    read = (F.R_dofs >= 0).sum(axis=2)
    assert (read > (G.R_dofs >= 0).sum(axis=2)).all()
    if scheme == "B":
        assert (F.R_values >= 0).all() and np.abs(F.R_values.sum(axis=2) - 1.0).max() < 1e-15
    dem = vertex.dem
    shift = np.array([0.3, -0.2, 0.7])
    u = cell_vector(dem, lambda x: np.tile(shift, (len(x), 1)))
    for c in (vertex, facet):
        c.prepare(u)
        uc = c.free_displacements(c.patch_values(u))[: len(c.facets)]
        assert np.abs(uc - shift).max() < 1e-14


def _rows_by_place(c):
    """The own facets' centres and their rows as dicts {(row, cell centre, component): value}."""
    dem, d = c.dem, c.d
    cells = np.arange(dem.geometry.num_cells)
    place = {}
    for cell in cells:
        for x in range(d):
            place[int(dem.columns[cell * d + x])] = (tuple(np.round(dem.geometry.cell_centres[cell], 9)), x)
    F = c.pair_list.local
    rows = []
    for k in range(c.num_own):
        rows.append({(x, *place[int(g)]): float(v) for x in range(d)
                     for g, v in zip(F.R_dofs[k, x], F.R_values[k, x]) if g >= 0})
    return F.centre[: c.num_own], rows


@pytest.mark.mpi
@pytest.mark.parametrize("scheme, tolerance", [("B", 0.0), ("A", 1e-14)])
def test_the_vertex_rows_are_those_of_one_process(scheme, tolerance):
    """The rows K of the own facets on 1, 2, 3 processes (the stars of first-layer facets
    received from their owners) equal the serial ones, cell by cell: bit-identical under scheme
    B (the sums run in an order of barycentres and coordinates, not of DOLFINx's numbers, which
    depend on the partition), to rounding under scheme A, whose own rows R_f differ by rounding
    between partitions (an entry that cancels to rounding may be absent from one of them)."""
    centres, rows = _rows_by_place(two_boxes(MPI.COMM_WORLD, scheme, "vertex").find(PairContact))
    serial_centres, serial_rows = _rows_by_place(two_boxes(MPI.COMM_SELF, scheme, "vertex").find(PairContact))
    distance, found = scipy.spatial.cKDTree(serial_centres).query(centres)
    assert distance.max(initial=0.0) < 1e-12
    for k, j in enumerate(found):
        a, b = rows[k], serial_rows[j]
        assert max(abs(a.get(e, 0.0) - b.get(e, 0.0)) for e in a.keys() | b.keys()) <= tolerance
        assert sum(abs(x) for x in a.values()) > 0.999  # rows of weights summing to 1 per component


def test_bad_surfaces_are_rejected():
    dem, facets = two_discs(h=0.05, comm=MPI.COMM_SELF)
    with pytest.raises(InputError, match="contact.surface must be one of 'facet', 'vertex'"):
        PairContact(dem, facets, surface="vertices")
    with pytest.raises(InputError, match="contact.surface = 'vertex' with contact.friction > 0"):
        PairContact(dem, facets, friction=0.3, surface="vertex")
    with pytest.raises(scenes.SceneError, match="scene key 'contact.surface' must be a string"):
        scenes.load("two-disks", {"contact.surface": "edge"})


@pytest.mark.parametrize("overrides, error, message", [
    ({"contact.friction": 0.3}, InputError, "contact.surface = 'vertex' with contact.friction"),
    ({"method": "fem-P1"}, scenes.SceneError, "scene key 'contact.surface'.*method 'fem-P1'"),
])
def test_surface_scenes_are_rejected_before_the_run(overrides, error, message, tmp_path):
    with pytest.raises(error, match=message):
        scene = scenes.load("two-disks", {"mesh.h": 0.05, "contact.surface": "vertex", **overrides})
        simulation.run(scene, tmp_path / "out", quiet=True)
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_two_balls_with_the_papers_stabilisation_hold_on_the_vertex_surface(tmp_path):
    """Issue 32 §3's hole: two-balls on a uniform mesh h = 0.02 m with eta = E. With the facet
    surface the facets slide into each other's holes and the run stops at 0.223 s (the touching
    pairs sink deeper than the list radius); the vertex surface runs to 0.25 s, past the
    deepest approach, with exact energy."""
    scene = scenes.load("two-balls", {"mesh.h": 0.02, "mesh.refine_h": 0.02, "contact.skin": 0.05,
                                      "material.eta": 100.0, "contact.surface": "vertex", "time.end": 0.25,
                                      "output.every": 100000})
    summary = simulation.run(scene, tmp_path, MPI.COMM_SELF, quiet=True)
    assert summary["status"] == "completed"
    assert summary["pseudo_energy_rel_drift"] < 1e-13
