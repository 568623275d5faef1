"""Growth over time: the connected share of the network ``crack.time`` reveals
(:mod:`crackbake.metrics.growth`) and the re-timing that grows it out of the impact
(:mod:`crackbake.simulate.timing`), on networks whose answers are derived by hand."""

from __future__ import annotations

import numpy as np
import pytest

from crackbake.metrics.growth import growth_curve, network_graph
from crackbake.network import Crack, CrackNetwork
from crackbake.simulate.timing import grow_from_impacts

IMPACT = [{"point": [0.0, 0.0, 0.0], "radius": 0.05, "strength": 1.0}]


def _crack(i: int, points, time) -> Crack:
    p = np.column_stack([np.asarray(points, float), np.zeros(len(points))])
    n = len(p)
    return Crack(id=i, points=p, faces=np.zeros(n), time=np.asarray(time, float),
                 width=np.full(n, 1e-3), depth=np.full(n, 5e-4))


def _network(cracks, impacts=IMPACT) -> CrackNetwork:
    return CrackNetwork(cracks=cracks, mesh={}, impacts=list(impacts))


def test_star_revealed_outward_is_always_connected():
    # Eight arms from the impact, time rising from 0 at the centre to 1 at each tip.
    arms = []
    for k in range(8):
        d = np.array([np.cos(k * np.pi / 4), np.sin(k * np.pi / 4)])
        arms.append(_crack(k, np.outer(np.linspace(0, 1, 5), d), np.linspace(0, 1, 5)))
    curve = growth_curve(_network(arms))
    assert curve.mode == "impact"
    np.testing.assert_allclose(curve.revealed, 8 * curve.t, atol=1e-12)  # linear in time
    assert np.all(curve.share[1:] == 1.0)
    assert curve.weighted_mean == 1.0 and curve.min_after(0.1) == 1.0


def test_isolated_segment_revealed_early_share_by_hand():
    # A: (0,0)-(1,0), time 0 -> 1 (revealed length t).  B: an isolated segment of length 0.5
    # revealed between t = 0.1 and 0.3, so B(t) = 2.5 (t - 0.1) there and 0.5 after.
    a = _crack(0, [[0, 0], [0.5, 0], [1, 0]], [0, 0.5, 1])
    b = _crack(1, [[0, 2], [0.5, 2]], [0.1, 0.3])
    curve = growth_curve(_network([a, b]))
    t = curve.t
    b_len = np.clip(2.5 * (t - 0.1), 0.0, 0.5)
    np.testing.assert_allclose(curve.revealed, t + b_len, atol=1e-12)
    np.testing.assert_allclose(curve.connected, t, atol=1e-12)
    k = int(np.argmin(np.abs(t - 0.2)))
    assert curve.share[k] == pytest.approx(0.2 / 0.45)
    assert curve.share[-1] == pytest.approx(1 / 1.5)
    # t / (t + 2.5 (t - 0.1)) falls on [0.1, 0.3] and t / (t + 0.5) rises after: min at 0.3.
    assert curve.min_after(0.1) == pytest.approx(0.375)
    assert curve.weighted_mean == pytest.approx(t.sum() / (t + b_len).sum())


def test_without_impact_the_reference_is_the_largest_piece():
    a = _crack(0, [[0, 0], [1, 0]], [0, 1])  # 1 long at t = 1
    b = _crack(1, [[0, 2], [0.4, 2]], [0, 0])  # 0.4 long from t = 0
    curve = growth_curve(_network([a, b], impacts=[]))
    assert curve.mode == "largest"
    share = curve.share
    t = curve.t
    np.testing.assert_allclose(share[1:], (np.maximum(t, 0.4) / (t + 0.4))[1:])


def _t_network():
    # B meets A at A's middle point (a thesis-style T: the junction is inside A's polyline)
    # and grew *towards* it: it cracked at its far end first (t 0.6) and joined at 0.8.
    a = _crack(0, [[0, 0], [0.5, 0], [1, 0]], [0, 0.5, 1])
    b = _crack(1, [[0.5, 0], [0.5, 0.5], [0.5, 1]], [0.8, 0.7, 0.6])
    return _network([a, b])


def test_junction_inside_a_polyline_joins_the_graph():
    g = network_graph(_t_network())
    assert len(g.positions) == 5  # 6 points, the junction shared
    curve = growth_curve(_t_network())
    k = int(np.argmin(np.abs(curve.t - 0.65)))
    # B's far segment (0.5 long, times 0.7 -> 0.6) is half revealed, hanging from its far end.
    assert curve.share[k] == pytest.approx(0.65 / 0.9)


def test_retiming_grows_the_piece_from_the_junction():
    net = _t_network()
    out = grow_from_impacts(net)
    # Tip speeds len / dt: A's segments 0.5 / 0.5, B's 0.5 / 0.1: median of [1, 1, 5, 5] = 3.
    # A keeps its order.  B's junction point takes the junction's time 0.5; (0.5, 0.5) cracked
    # at 0.7, after the junction was reached: kept; (0.5, 1) cracked at 0.6, before its
    # neighbour was reached: 0.7 + 0.5 / 3.
    np.testing.assert_allclose(out.cracks[0].time, [0, 0.5, 1])
    np.testing.assert_allclose(out.cracks[1].time, [0.5, 0.7, 0.7 + 0.5 / 3])
    for c_in, c_out in zip(net.cracks, out.cracks, strict=True):
        assert c_out.points is c_in.points and c_out.width is c_in.width
    curve = growth_curve(out)
    assert curve.min_after(0.0) == 1.0


def test_retiming_keeps_an_outward_star_and_stays_in_unit_range():
    arms = [_crack(k, [[0, 0], [np.cos(k), np.sin(k)], [2 * np.cos(k), 2 * np.sin(k)]],
                   [0.0, 0.3 + 0.1 * k, 0.9]) for k in range(4)]
    out = grow_from_impacts(_network(arms))
    for a, b in zip(arms, out.cracks, strict=True):
        np.testing.assert_array_equal(a.time, b.time)
    # A piece that cracked before the front came: T beyond 1 is scaled back into [0, 1].
    late = _network([_crack(0, [[0, 0], [1, 0]], [0, 1]), _crack(1, [[1, 0], [3, 0]], [1, 0])])
    out = grow_from_impacts(late)
    times = np.concatenate([c.time for c in out.cracks])
    assert times.min() >= 0 and times.max() == 1.0
    assert growth_curve(out).min_after(0.0) == 1.0


def test_networks_without_impact_keep_their_times():
    net = _network([_crack(0, [[0, 0], [1, 0]], [0.4, 0.1])], impacts=[])
    assert grow_from_impacts(net) is net


def test_plate_impact_grows_connected_and_points_unchanged(tmp_path):
    from crackbake.io.mesh import load_mesh
    from crackbake.network import from_solver
    from crackbake.params import RunParams, parse_impact
    from crackbake.pipeline import solve
    from crackbake.precompile import plate_obj

    path = plate_obj(tmp_path / "plate.obj", 8, uv_margin=0.0)
    run = RunParams(mesh=path, preset="glass", impacts=(parse_impact("0.5,0.5,0"),), seed=1,
                    sim_faces=20000).validate()
    run, relative = run.resolved()
    mesh = load_mesh(path)
    network, _stats, solved = solve(mesh, run, relative, {})
    raw = from_solver(solved.result.cracks, mesh, impacts=solved.field.impacts)
    before, after = growth_curve(raw), growth_curve(network)
    # The solver's own order leaves pieces mid-air (measured 0.77); the re-timed one none.
    assert before.min_after(0.1) < 0.9 <= after.min_after(0.1)
    assert after.weighted_mean >= before.weighted_mean
    for c_raw, c in zip(raw.cracks, network.cracks, strict=True):
        np.testing.assert_array_equal(c_raw.points, c.points)
        assert c.time.min() >= 0.0 and c.time.max() <= 1.0
