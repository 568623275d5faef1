"""Network measures (crackbake.metrics.cells) on analytic networks with known answers."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import plate_mesh

from crackbake.metrics.cells import cell_areas, junctions, network_stats, straightness


def line(p, q, n=41):
    """A straight polyline of n points from p to q (z = 0)."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.c_[(1 - t) * np.asarray(p, float) + t * np.asarray(q, float), np.zeros(n)]


def brick_grid(k: int):
    """A brick wall on the unit square: k - 1 full-width horizontal cracks; in each of the k
    rows, k - 1 vertical pieces from one horizontal line to the next at x = i / k, shifted by
    1 / (2 k) in odd rows so no two pieces meet at one point (true T-junctions, not crossings).

    Returns the polylines and the cell areas (k rows of height 1 / k cut at the pieces):
    (k - 1) (2 k - 2) T-junctions, every vertical piece end off the border."""
    s = np.arange(1, k) / k
    rows = [line((0, y), (1, y)) for y in s]
    cols, areas = [], []
    for j in range(k):
        xs = s + (0.5 / k if j % 2 else 0.0)
        cols += [line((x, j / k), (x, (j + 1) / k), 11) for x in xs]
        areas += list(np.diff(np.r_[0.0, xs, 1.0]) / k)
    return rows + cols, np.sort(areas)[::-1]


def test_grid_network_has_known_cells_angles_and_straightness():
    k = 4
    plate = plate_mesh(8)
    cracks, expected = brick_grid(k)
    widths = [np.full(len(p), 0.01) for p in cracks]
    st = network_stats(cracks, widths, plate.vertices, plate.faces)
    assert st.cracks == (k - 1) + (k - 1) * k
    assert st.length == pytest.approx(2 * (k - 1))
    assert st.mean_width == pytest.approx(0.01)
    assert st.straightness == pytest.approx(1.0, abs=1e-12)
    assert st.t_junctions == (k - 1) * (2 * k - 2)
    assert st.stem_angle == pytest.approx(90.0, abs=1e-6)
    assert st.cells == k * k
    assert st.mean_cell_area == pytest.approx(1 / k**2)
    areas = cell_areas(plate.vertices, plate.faces, cracks)
    assert areas.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(areas, expected, rtol=0.1)  # sampling noise of a few %


def test_split_polylines_t_and_known_stem_angle():
    """The solver's form: a through-crack split at the junction, the stem a third polyline
    ending there; a stem at 60 degrees to the through-crack reads 60."""
    a = np.radians(60)
    left, right = line((0.1, 0.5), (0.5, 0.5)), line((0.5, 0.5), (0.9, 0.5))
    stem = line((0.5, 0.5), (0.5 + 0.3 * np.cos(a), 0.5 + 0.3 * np.sin(a)))
    angles, cuts = junctions([left, stem, right])
    assert cuts == {}
    np.testing.assert_allclose(angles, [60.0], atol=1e-6)
    # Four ends at one point are a crossing, not a T.
    down = line((0.5, 0.5), (0.5, 0.1))
    assert len(junctions([left, stem, right, down])[0]) == 0


def test_straightness_of_a_half_circle_is_two_over_pi():
    t = np.linspace(0, np.pi, 2001)
    arc = np.c_[np.cos(t), np.sin(t), np.zeros_like(t)]
    pieces = straightness([arc])
    assert pieces[0, 0] == pytest.approx(2 / np.pi, rel=1e-5)
    # Cut at its middle: two quarter circles, chord / arc = 2 sqrt(2) / pi each.
    pieces = straightness([arc], {0: [np.pi / 2]})
    np.testing.assert_allclose(pieces[:, 0], 2 * np.sqrt(2) / np.pi, rtol=1e-5)


def test_open_cracks_leave_one_cell_and_no_network_is_nan():
    plate = plate_mesh(4)
    st = network_stats([line((0.2, 0.5), (0.8, 0.5))], None, plate.vertices, plate.faces)
    assert st.cells == 1 and st.mean_cell_area == pytest.approx(1.0)
    assert np.isnan(st.mean_width) and np.isnan(st.stem_angle) and st.t_junctions == 0
    empty = network_stats([])
    assert empty.cracks == 0 and np.isnan(empty.mean_cell_area)


def test_cells_on_a_closed_surface_a_sphere_cut_at_the_equator():
    """Works on closed meshes (no border, no UVs): the equator splits a sphere into two
    hemispheres of half the (faceted) area each; the open half-ring alone cuts nothing."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=4)
    t = np.linspace(0, 2 * np.pi, 401)
    ring = np.c_[np.cos(t), np.sin(t), np.zeros_like(t)]
    areas = cell_areas(sphere.vertices, sphere.faces, [ring])
    assert len(areas) == 2
    np.testing.assert_allclose(areas, sphere.area / 2, rtol=0.02)
    assert len(cell_areas(sphere.vertices, sphere.faces, [ring[:200]])) == 1


def test_geodesic_straightness_on_a_sphere():
    """With surface normals the chord is taken on the unrolled polyline: half a great circle is
    straight (1, its 3D chord / arc is 2 / pi); half the 60-degree latitude circle unrolls to a
    circular arc of radius tan 60 and angle pi cos 60 = pi / 2: chord / arc 2 sqrt(2) / pi."""
    t = np.linspace(0, np.pi, 4001)
    great = np.c_[np.cos(t), np.sin(t), np.zeros_like(t)]
    assert straightness([great])[0, 0] == pytest.approx(2 / np.pi, rel=1e-5)
    assert straightness([great], normals=[great])[0, 0] == pytest.approx(1.0, abs=1e-9)
    polar = np.radians(60)
    lat = np.c_[np.sin(polar) * np.cos(t), np.sin(polar) * np.sin(t), np.full_like(t, 0.5)]
    got = straightness([lat], normals=[lat])[0, 0]
    assert got == pytest.approx(2 * np.sqrt(2) / np.pi, rel=1e-4)
