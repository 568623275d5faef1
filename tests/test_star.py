"""Glass impact stars (issue 12 §1): the measures of crackbake.metrics.star on networks built by
hand, the goals on a plate through cracks.json, and the ``--impact X,Y,Z:Rd`` radius."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import plate_mesh, sim_plate

from crackbake.errors import CrackbakeError
from crackbake.io.mesh import load_mesh
from crackbake.io.sidecar import read_sidecar, write_sidecar
from crackbake.metrics.star import (
    annulus_density,
    arm_straightness,
    impact_reach,
    length_beyond,
    radial_arms,
    star_checks,
    star_metrics,
    surface_distance,
    tangential_share,
    trimmed_mean,
    web_stars,
)
from crackbake.params import Impact, RunParams, parse_impact
from crackbake.pipeline import solve
from crackbake.precompile import plate_obj
from crackbake.simulate.setup import stress_sources

C = np.array([0.5, 0.5, 0.0])


def _ring(r: float, n: int = 400) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, n + 1)
    return C + r * np.stack([np.cos(t), np.sin(t), 0 * t], 1)


def _arm(phi: float, r0: float, r1: float, n: int = 30) -> np.ndarray:
    s = np.linspace(r0, r1, n)[:, None]
    return C + s * np.array([np.cos(phi), np.sin(phi), 0.0])


def _dists(polys):
    return [np.linalg.norm(p - C, axis=1) for p in polys]


def test_synthetic_star_measures():
    # N straight arms from 0.02 to 0.5 reach plus rings at 0.45 and 0.55 reach, reach 0.4.
    reach, n = 0.4, 12
    arms = [_arm(2 * np.pi * k / n + 0.1, 0.02 * reach, 0.5 * reach) for k in range(n)]
    rings = [_ring(0.45 * reach), _ring(0.55 * reach)]
    polys = arms + rings
    d = _dists(polys)
    assert len(radial_arms(polys, d, reach)) == n
    assert np.allclose(arm_straightness(polys, d, reach), 1.0)
    # Inside 0.35-0.65 reach: arm length (0.5 - 0.35) reach each, rings fully tangential.
    arm_len = n * 0.15 * reach
    ring_len = 2 * np.pi * (0.45 + 0.55) * reach
    assert tangential_share(polys, d, reach) == pytest.approx(ring_len / (ring_len + arm_len),
                                                             rel=1e-3)
    # Annuli of 0.2 reach: the arms add n * 0.2 reach per annulus (less in the first and
    # third), the rings theirs; densities are length over the plane annulus area.
    dens = annulus_density(polys, d, reach, bins=5)
    area0 = np.pi * (0.2 * reach) ** 2
    assert dens[0] == pytest.approx(n * 0.18 * reach / area0, rel=1e-6)
    area2 = np.pi * ((0.6 * reach) ** 2 - (0.4 * reach) ** 2)
    expect2 = (n * 0.1 * reach + ring_len) / area2
    assert dens[2] == pytest.approx(expect2, rel=2e-3)  # ring polygons are 400-gons
    assert dens[3] == dens[4] == 0.0
    assert length_beyond(polys, d, reach) == 0.0


def test_arms_that_wander_or_run_beyond():
    reach = 1.0
    # A zig-zag arm: each leg 40 degrees off its mean direction, chord/arc = cos 40 (the
    # part cut at 0.6 reach and the first leg off the centre make it approximate).
    s = np.arange(0, 14) * 0.05
    zig = np.stack([s, np.where(np.arange(14) % 2, 0.05 * np.tan(np.radians(40)), 0.0),
                    0 * s], 1)
    polys = [zig + np.array([0.002, 0.0, 0.0]) + C]
    d = _dists(polys)
    assert len(radial_arms(polys, d, reach)) == 1
    assert arm_straightness(polys, d, reach)[0] == pytest.approx(np.cos(np.radians(40)),
                                                                 abs=0.02)
    # A crack through the impact is two arms, each straight; 0.5 of its 2.4 length is beyond.
    line = [_arm(0.0, -1.2, 1.2, 241)]
    dl = _dists(line)
    assert len(radial_arms(line, dl, reach)) == 2
    assert np.allclose(arm_straightness(line, dl, reach), 1.0)
    assert length_beyond(line, dl, reach) == pytest.approx(0.4, abs=1e-9)
    # A tangential ring at 0.3 reach crosses no circle: no arm.
    ring = [_ring(0.5)]
    assert radial_arms(ring, _dists(ring), reach) == []


def _spiral(phi: float, slant: float, r0: float, r1: float, n: int = 200) -> np.ndarray:
    """A log spiral from radius r0 to r1 round C, running ``slant`` radians off radial."""
    b = 1.0 / np.tan(slant)  # r = r0 exp(b t): tan(angle to radial) = 1 / b
    t = np.linspace(0.0, np.log(r1 / r0) / b, n)
    r = r0 * np.exp(b * t)
    return C + np.stack([r * np.cos(phi + t), r * np.sin(phi + t), 0 * t], 1)


@pytest.mark.parametrize("slant", [15.0, 35.0])
def test_arms_that_wander_make_a_web(slant):
    # 12 arms running a constant angle off radial (log spirals) from 0.05 to 0.8 reach: each
    # gains cos(angle) of its length in distance from the impact, which is its geodesic
    # straightness.  15 degrees (0.966) is a star, 35 degrees (0.819) a web of cells (issue 18
    # §3: suzanne's low-poly brow, 0.81).
    reach, n = 0.4, 12
    arms = [_spiral(2 * np.pi * k / n, np.radians(slant), 0.05 * reach, 0.8 * reach)
            for k in range(n)]
    network = {"cracks": [{"points": p} for p in arms],
               "impacts": [{"point": list(C), "radius": reach / (0.5 * np.pi)}]}
    [(_, arms_n, radial)] = star_checks(network)
    assert arms_n == n
    assert radial == pytest.approx(np.cos(np.radians(slant)), abs=2e-3)
    assert len(web_stars(network)) == (slant > 30)


def test_nearest_centroid_within_the_patch_equals_the_whole_tree():
    """The star check's nearest sim face: searched in the impact's patch first, the same face
    a KD-tree of every centroid gives, for points inside the ball, near its rim and far out."""
    from scipy.spatial import cKDTree

    from crackbake.geometry import shared_centroids
    from crackbake.metrics.star import _nearest_centroid

    sim = sim_plate(45)
    centroid, corner_reach = shared_centroids(np.asarray(sim.vertices), np.asarray(sim.faces))
    rng = np.random.default_rng(2)
    snapped = centroid[len(centroid) // 2]
    pts = np.column_stack([rng.uniform(0, 1, 3000), rng.uniform(0, 1, 3000), np.zeros(3000)])
    whole = cKDTree(centroid).query(pts)[1]
    for reach in (0.05, 0.2, 0.45, 2.0, None):
        near = _nearest_centroid(centroid, corner_reach, snapped, reach, pts)
        assert np.array_equal(near, whole), reach


def test_trimmed_mean_drops_the_extremes():
    assert trimmed_mean(np.array([0.2, 0.9, 0.95, 0.97, 1.0])) == pytest.approx(0.94)
    assert trimmed_mean(np.array([0.5, 0.6])) == pytest.approx(0.55)
    assert np.isnan(trimmed_mean(np.zeros(0)))


def test_geodesic_distance_on_a_cylinder():
    # Around a cylinder of radius rho the surface distance at equal height is rho * angle, the
    # straight one the chord 2 rho sin(angle / 2).
    rho, n_a, n_h = 0.3, 240, 121  # near-square quads: first-order fast marching
    a = np.linspace(0, 2 * np.pi, n_a, endpoint=False)
    h = np.linspace(0.0, 1.0, n_h)
    aa, hh = np.meshgrid(a, h, indexing="ij")
    v = np.stack([rho * np.cos(aa), rho * np.sin(aa), hh], -1).reshape(-1, 3)
    idx = np.arange(n_a * n_h).reshape(n_a, n_h)
    q0, q1 = idx, np.roll(idx, -1, axis=0)
    f = np.concatenate([np.stack([q0[:, :-1], q1[:, :-1], q1[:, 1:]], -1).reshape(-1, 3),
                        np.stack([q0[:, :-1], q1[:, 1:], q0[:, 1:]], -1).reshape(-1, 3)])
    ang = np.array([0.5, 1.5, 2.5])
    pts = np.stack([rho * np.cos(ang), rho * np.sin(ang), 0.5 + 0 * ang], 1)
    d = surface_distance(pts, [rho, 0.0, 0.5], v, f)
    assert np.allclose(d, rho * ang, rtol=0.03)
    assert not np.allclose(d, 2 * rho * np.sin(ang / 2), rtol=0.03)
    assert np.allclose(surface_distance(pts, [rho, 0.0, 0.5]), 2 * rho * np.sin(ang / 2))


def test_parse_impact_radius_units():
    imp = parse_impact("0.1,0.2,0.3:0.2d:1.5")
    assert imp.radius is None and imp.radius_rel == 0.2 and imp.strength == 1.5
    assert parse_impact("0,0,0:0.25").radius == 0.25
    assert parse_impact("0,0,0:0.25D").radius_rel == 0.25
    for bad in ("0,0,0:d", "0,0,0:-0.1d", "0,0,0:0d", "0,0,0:11d", "0,0,0:0.2dd"):
        with pytest.raises(CrackbakeError, match="--impact"):
            parse_impact(bad)
    with pytest.raises(CrackbakeError, match="not both"):
        RunParams(mesh="x.obj", impacts=(Impact((0, 0, 0), 0.1, radius_rel=0.2),)).validate()


def test_resolved_radius_is_a_fraction_of_the_diagonal():
    mesh = plate_mesh(4, size=2.0)  # diagonal 2 sqrt 2
    diag = 2 * np.sqrt(2)
    for text, expect in (("1,1,0:0.2d", 0.2 * diag), ("1,1,0:0.3", 0.3), ("1,1,0", 0.15 * diag)):
        params = RunParams(mesh="plate.obj", preset="glass", impacts=(parse_impact(text),))
        resolved, relative = params.validate().resolved()
        src = stress_sources(resolved, mesh, relative)[0]  # then the preset's noise
        assert src.radius == pytest.approx(expect)
    # The radius the field used is the one written to the sidecar.
    from crackbake.simulate.stress import ImpactSource, stress_field

    field = stress_field(sim_plate(40), mesh, [ImpactSource((0.5, 0.5, 0.0), 0.2 * diag)])
    assert field.impacts[0]["radius"] == pytest.approx(0.2 * diag)
    assert field.shadow_radius == pytest.approx(0.12 * impact_reach(0.2 * diag))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_glass_star_goals_on_a_plate(seed, tmp_path):
    """Issue 12 §1 on a plate, default glass preset, measured from cracks.json."""
    path = plate_obj(tmp_path / "plate.obj", 4, uv_margin=0.0)
    params = RunParams(mesh=path, preset="glass", impacts=(Impact((0.5, 0.5, 0.0)),),
                       seed=seed).validate()
    resolved, relative = params.resolved()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = load_mesh(path)
        network, _, _ = solve(mesh, resolved, relative, {})
    write_sidecar(network, tmp_path / "cracks.json")
    back = read_sidecar(tmp_path / "cracks.json")
    imp = back.impacts[0]
    reach = impact_reach(imp["radius"])
    assert reach == pytest.approx(0.5 * np.pi * 0.15 * np.sqrt(2))
    m = star_metrics(back, imp["point"], reach)  # flat: straight distances are geodesic
    assert m["arms"] >= 10
    assert m["straight_median"] >= 0.97
    assert m["tangential"] >= 0.25
    # density falls with distance; between neighbouring annuli a realisation may rise by a few
    # per cent (seed 1 at the position grain: 43.4 then 45.5 per unit, then 36.2, 7.6, 0)
    density = m["density"]
    assert np.all(np.diff(density) <= 0.1 * density[:-1]), density
    assert density[-1] < 0.5 * density[0], density
    assert m["beyond"] == 0.0
