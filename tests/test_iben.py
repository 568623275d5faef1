"""The iben crack solver on generated plates: kernels, invariants, determinism, pattern quality."""

from __future__ import annotations

import logging
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import impact_stress as impact
from conftest import largest_eigen
from conftest import sim_plate as plate
from conftest import stress_of as field
from conftest import uniform_stress as uniform

from crackbake.errors import CrackbakeError
from crackbake.geometry import edges
from crackbake.simulate.solver import SolverParams
from crackbake.simulate.solver.fem import (
    face_frames,
    face_geometry,
    node_forces,
    outer_over_norm,
    separation_tensors,
    split_tension,
)
from crackbake.simulate.solver.iben import solve_iben
from crackbake.simulate.solver.iben.calibration import flaw
from crackbake.simulate.solver.iben.eigen import eig_max_into, eig_max_value
from crackbake.simulate.solver.iben.separation import ISO_FAILURE

PARAMS = SolverParams(toughness=0.7, relax_steps=10, relax_rate=0.6, max_cracks=5000)


def directional(sim, d=(1.0, 0.3, 0.0), s=1.0):
    d = np.asarray(d) / np.linalg.norm(d)
    return field(np.repeat((s * np.outer(d, d))[None], len(sim.faces), 0))


# ------------------------------------------------------------------ crack-network measurements


def crack_graph(result):
    adj: dict[tuple, list[tuple]] = {}
    edges = []
    for c in result.cracks:
        for i in range(len(c.points) - 1):
            a, b = tuple(np.round(c.points[i], 9)), tuple(np.round(c.points[i + 1], 9))
            edges.append((a, b))
            adj.setdefault(a, []).append(b)
            adj.setdefault(b, []).append(a)
    return adj, edges


def on_plate_boundary(p, eps=1e-9):
    return min(p[0], p[1], 1 - p[0], 1 - p[1]) < eps


def total_length(result):
    return sum(np.linalg.norm(np.diff(c.points, axis=0), axis=1).sum() for c in result.cracks)


@pytest.fixture(scope="module")
def sim60():
    return plate(60)


@pytest.fixture(scope="module")
def shrink_result(sim60):
    return solve_iben(sim60, uniform(sim60), PARAMS)


@pytest.fixture(scope="module")
def impact_result(sim60):
    return solve_iben(sim60, impact(sim60), PARAMS)


# ------------------------------------------------------------------ kernels


def test_jacobi_eigen_matches_numpy():
    rng = np.random.default_rng(3)
    for _ in range(200):
        a = rng.normal(size=(3, 3))
        a = a + a.T
        if rng.random() < 0.3:  # nearly isotropic in a plane, the hard case for closed forms
            a = np.diag([1.0, 1.0 + 1e-12, -0.5])
        m, v = a.copy(), np.empty((3, 3))
        val = eig_max_into(m, v)
        vec = v[:, 0]
        assert eig_max_value(a.copy()) == val  # the value-only variant, bit for bit
        w, v = np.linalg.eigh(a)
        assert val == pytest.approx(w[-1], abs=1e-10)
        assert np.allclose(a @ vec, val * vec, atol=1e-9)


def reference_separation(sim, stress: np.ndarray, iso_share: float | None = None,
                         n_angles: int = 180) -> np.ndarray:
    """Failure value v+ per node, vectorised numpy (the solver's variant of §A5).

    The largest eigenvalue of ``iso_share ς̄ + (1 − iso_share) ς`` (default: the solver's
    ``ISO_FAILURE``), ``ς`` the paper's tensor (fem.py) and ``ς̄`` the same with each corner's
    ``m(f)`` replaced by ``A|g| E[m(Sĝ)]``, the mean over in-plane directions ĝ, here by a
    dense quadrature over the circle (the solver uses a closed quarter-circle rule).
    """
    share = ISO_FAILURE if iso_share is None else iso_share
    X, F = sim.vertices, sim.faces
    area, normal, grad = face_geometry(X, F)
    frames = face_frames(normal, X, F)
    plus, minus, _, _ = split_tension(stress, frames)
    fp, fm = node_forces(area, grad, plus), node_forces(area, grad, minus)
    paper = separation_tensors(F, fp, fm, len(X))
    th = (np.arange(n_angles) + 0.5) * 2 * np.pi / n_angles
    u = np.cos(th)[:, None, None] * frames[None, :, :, 0] + np.sin(th)[:, None, None] * frames[
        None, :, :, 1]
    weight = area[:, None] * np.linalg.norm(grad, axis=2)  # A |g| per corner

    def corner_sum(t: np.ndarray) -> np.ndarray:
        mean = outer_over_norm(np.einsum("eab,keb->kea", t, u)).mean(0)  # (M, 3, 3)
        out = np.zeros((len(X), 3, 3))
        for k in range(3):
            np.add.at(out, F[:, k], weight[:, k, None, None] * mean)
        return out

    sum_fp, sum_fm = np.zeros((len(X), 3)), np.zeros((len(X), 3))
    for k in range(3):
        np.add.at(sum_fp, F[:, k], fp[:, k])
        np.add.at(sum_fm, F[:, k], fm[:, k])
    averaged = 0.5 * (-outer_over_norm(sum_fp) + corner_sum(plus) + outer_over_norm(sum_fm)
                      - corner_sum(minus))
    return largest_eigen(share * averaged + (1 - share) * paper)[0]


def localized(sim, fld):
    """``fld`` with no stress where x > 0.8: under 95 % of the interior nodes stay loaded, so
    the solver treats the field as localized and applies no footprint factor."""
    keep = sim.vertices[sim.faces].mean(1)[:, 0] <= 0.8
    return field(fld.stress * keep[:, None, None])


def solver_separation(sim, fld, seed: int = 5) -> np.ndarray:
    """The solver's initial v+ per node of a localized field (it reports v+ / tau_n,
    tau_n = tau h_n flaw(x), the footprint factor being 1 on localized fields)."""
    r = solve_iben(sim, fld, SolverParams(max_cracks=0, max_steps=0, seed=seed))
    assert r.steps == 0 and r.cracks == [] and r.stats["tau"] > 0
    e, _ = edges(sim.faces, len(sim.vertices))
    elen = np.linalg.norm(np.diff(sim.vertices[e], axis=1)[:, 0], axis=1)
    h_node = np.bincount(e.ravel(), np.repeat(elen, 2)) / np.bincount(e.ravel())
    return r.separation * r.stats["tau"] * h_node * flaw(seed, sim.vertices)


def test_initial_separation_matches_numpy_reference(sim60):
    """The compiled per-node separation equals an independent numpy one (before any crack)."""
    mixed = directional(sim60).stress - 0.5 * directional(sim60, d=(-0.3, 1.0, 0.0)).stress
    for fld in (impact(sim60), field(mixed), field(-mixed), uniform(sim60)):
        fld = localized(sim60, fld)
        value = reference_separation(sim60, fld.stress)
        assert np.allclose(solver_separation(sim60, fld), value, rtol=2e-3,
                           atol=2e-3 * value.max())


def test_averaged_separation_does_not_see_the_mesh_layout():
    """Isotropic tension on a mesh with every diagonal one way.

    The paper's tensor is strongly anisotropic at every interior node (half the fan's outer
    edges lie along the diagonals), which is what steered cracks along asset lines; the
    direction-averaged one (the solver's crack direction) is isotropic there, equal to
    ``½ Σ A|g| · ½`` at every interior node, so the mesh prefers no direction.
    """
    n = 20
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    f = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)
    sim = SimpleNamespace(vertices=v, faces=f, asset_face=np.arange(len(f)))
    st = uniform(sim).stress
    area, normal, grad = face_geometry(v, f)
    plus, minus, _, _ = split_tension(st, face_frames(normal, v, f))
    paper = separation_tensors(f, node_forces(area, grad, plus), node_forces(area, grad, minus),
                               len(v))
    inner = ((v[:, :2] > 0.01) & (v[:, :2] < 0.99)).all(1)
    w = np.linalg.eigvalsh(paper[inner])
    assert np.min((w[:, -1] - w[:, -2]) / w[:, -1]) > 0.2
    corner = area[:, None] * np.linalg.norm(grad, axis=2)
    expect = 0.25 * np.bincount(f.ravel(), corner.ravel(), minlength=len(v))[inner]
    assert np.ptp(expect) < 1e-9 * expect.max()
    assert np.allclose(reference_separation(sim, st, iso_share=1.0)[inner], expect, rtol=1e-6)
    # And the solver's failure value is the documented blend on this mesh too.
    assert np.allclose(solver_separation(sim, field(st)), reference_separation(sim, st),
                       rtol=2e-3)


# ------------------------------------------------------------------ invariants


def check_mesh(result, sim):
    v, f = result.vertices, result.faces
    area, _, _ = face_geometry(v, f)
    area0, _, _ = face_geometry(sim.vertices, sim.faces)
    assert area.sum() == pytest.approx(area0.sum(), rel=1e-9)
    assert area.min() > 1e-6 * area0.mean()
    # Oriented 2-manifold with boundary: each directed edge once, each undirected edge <= 2.
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)
    und = np.sort(directed, axis=1)
    _, counts = np.unique(und, axis=0, return_counts=True)
    assert counts.max() <= 2
    # No pinched vertices: the faces around each vertex are connected through shared edges.
    inc: dict[int, list[int]] = {}
    for i, tri in enumerate(f.tolist()):
        for x in tri:
            inc.setdefault(x, []).append(i)
    for x, fl in inc.items():
        seen, stack = {fl[0]}, [fl[0]]
        while stack:
            g = stack.pop()
            for h in fl:
                if h not in seen and len(set(f[g]) & set(f[h])) == 2:
                    seen.add(h)
                    stack.append(h)
        assert len(seen) == len(fl), f"vertex {x} is pinched"
    assert len(result.asset_face) == len(f)
    assert result.stress_final.shape == (len(f), 3, 3)


def check_cracks(result, sim):
    n_asset = int(sim.asset_face.max()) + 1
    for c in result.cracks:
        n = len(c.points)
        assert n >= 2
        for arr in (c.asset_faces, c.time, c.width, c.depth):
            assert arr.shape == (n,)
        assert ((c.asset_faces >= 0) & (c.asset_faces < n_asset)).all()
        assert ((c.time >= 0) & (c.time <= 1)).all()
        assert (c.width >= 0).all() and np.allclose(c.depth, 0.5 * c.width)
    # No crossings: segments intersect only at shared end points (checked on a 2D plate).
    segs = np.array([np.stack([c.points[i, :2], c.points[i + 1, :2]])
                     for c in result.cracks for i in range(len(c.points) - 1)])
    a, b = segs[:, 0], segs[:, 1]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    for i in range(len(segs)):
        cand = np.nonzero((lo[:, 0] <= hi[i, 0]) & (hi[:, 0] >= lo[i, 0])
                          & (lo[:, 1] <= hi[i, 1]) & (hi[:, 1] >= lo[i, 1]))[0]
        for j in cand[cand > i]:
            p, r = a[i], b[i] - a[i]
            q, s = a[j], b[j] - a[j]
            den = r[0] * s[1] - r[1] * s[0]
            if abs(den) < 1e-15:
                continue
            t = ((q - p)[0] * s[1] - (q - p)[1] * s[0]) / den
            u = ((q - p)[0] * r[1] - (q - p)[1] * r[0]) / den
            assert not (1e-9 < t < 1 - 1e-9 and 1e-9 < u < 1 - 1e-9), "cracks cross"


def test_invariants_shrinkage(sim60, shrink_result):
    assert len(shrink_result.cracks) > 20
    check_mesh(shrink_result, sim60)
    check_cracks(shrink_result, sim60)


def test_invariants_impact(sim60, impact_result):
    assert len(impact_result.cracks) > 10
    check_mesh(impact_result, sim60)
    check_cracks(impact_result, sim60)
    widths = np.concatenate([c.width for c in impact_result.cracks])
    diag = np.sqrt(2.0)
    assert widths.max() == pytest.approx(1e-3 * diag)


def test_invariants_every_step():
    """The mesh is valid after each of the first crack events, not only at the end."""
    sim = plate(20)
    fld = impact(sim)
    for k in range(1, 12):
        r = solve_iben(sim, fld, SolverParams(toughness=0.7, relax_steps=10, relax_rate=0.6,
                                              max_cracks=k))
        check_mesh(r, sim)


def test_determinism(sim60, impact_result):
    again = solve_iben(sim60, impact(sim60), PARAMS)
    assert len(again.cracks) == len(impact_result.cracks)
    for a, b in zip(again.cracks, impact_result.cracks, strict=True):
        assert np.array_equal(a.points, b.points) and np.array_equal(a.width, b.width)
        assert np.array_equal(a.asset_faces, b.asset_faces)
    assert np.array_equal(again.faces, impact_result.faces)


def test_determinism_does_not_depend_on_the_thread_count(tmp_path):
    """Growth steps recompute the field in parallel: one thread must give the same cracks."""
    import os
    import subprocess
    import sys

    script = tmp_path / "run.py"
    script.write_text(
        "import sys, numpy as np\n"
        f"sys.path.insert(0, {str(Path(__file__).parent)!r})\n"
        "from conftest import sim_plate, uniform_stress\n"
        "from crackbake.simulate.solver import SolverParams\n"
        "from crackbake.simulate.solver.iben import solve_iben\n"
        "sim = sim_plate(40)\n"
        "f = uniform_stress(sim); f.growth = 0.02 * f.stress; f.stress = 0.0 * f.stress\n"
        "r = solve_iben(sim, f, SolverParams(max_cracks=40, max_steps=3000))\n"
        "np.savez(sys.argv[1], points=np.concatenate([c.points for c in r.cracks]),\n"
        "         growth_steps=r.stats['growth_steps'])\n"
    )
    outs = []
    for threads in ("1", "2"):
        env = {**os.environ, "NUMBA_NUM_THREADS": threads}
        out = tmp_path / f"t{threads}.npz"
        subprocess.run([sys.executable, str(script), str(out)], env=env, capture_output=True,
                       text=True, check=True)
        got = np.load(out)
        assert int(got["growth_steps"]) > 1  # growth steps ran
        outs.append(got["points"])
    assert np.array_equal(outs[0], outs[1])


def test_no_stress_no_cracks(sim60):
    r = solve_iben(sim60, uniform(sim60, 0.0), PARAMS)
    assert r.cracks == [] and r.steps == 0


def test_user_errors(sim60):
    with pytest.raises(CrackbakeError):
        solve_iben(sim60, uniform(sim60), SolverParams(toughness=0))
    with pytest.raises(CrackbakeError):
        solve_iben(sim60, field(np.zeros((3, 3, 3))), PARAMS)


def test_budget_and_growth(sim60):
    # max_cracks bounds the distinct cracks started; those keep growing past it.
    r = solve_iben(sim60, uniform(sim60), SolverParams(max_cracks=7))
    assert r.stats["cracks"] == 7 and r.stats["events"] > 7
    # max_steps bounds the solver steps (crack events here).
    r = solve_iben(sim60, uniform(sim60), SolverParams(max_steps=9))
    assert r.stats["events"] == 9 and r.steps == 9
    st = uniform(sim60, 0.0).stress
    grow = uniform(sim60, 0.05).stress
    r = solve_iben(sim60, field(st, grow), SolverParams(max_steps=80, relax_steps=10,
                                                           relax_rate=0.6, toughness=0.7))
    assert r.stats["growth_steps"] > 0 and r.steps == 80
    assert r.stats["events"] + r.stats["growth_steps"] == 80
    assert r.stats["stopped"] == "max steps"


def test_drying_stops_when_saturated():
    """A growing field with an unreachable crack budget ends once nothing can crack any more
    (it used to dry on, one whole-mesh step at a time, until max_steps)."""
    sim = plate(30)
    st = uniform(sim, 0.0).stress
    grow = uniform(sim, 0.05).stress
    r = solve_iben(sim, field(st, grow), SolverParams(max_cracks=100_000, max_steps=100_000))
    assert r.stats["stopped"] == "saturated"
    assert 0 < r.stats["cracks"] < 100_000 and r.steps < 20_000
    # The budget, when it binds, is reported as such.
    r = solve_iben(sim, field(st, grow), SolverParams(max_cracks=3))
    assert r.stats["cracks"] == 3 and r.stats["stopped"] == "max cracks"


def test_capacity_grows(sim60, shrink_result, monkeypatch):
    """Runs longer than the initial room grow the state, with the same result."""
    from crackbake.simulate.solver.iben import constants

    monkeypatch.setattr(constants, "INITIAL_ROOM", 8)
    r = solve_iben(sim60, uniform(sim60), PARAMS)
    assert r.stats["events"] == shrink_result.stats["events"] > 100
    assert np.array_equal(r.faces, shrink_result.faces)


def test_progress_is_logged_and_throttled(caplog, monkeypatch):
    """A run longer than a few progress periods logs its progress (INFO,
    crackbake.simulate.solver.iben), at most once every PROGRESS_SECONDS.  The period is
    shortened so the run is certain to outlast several whatever the machine's speed."""
    from crackbake.simulate.solver.iben import constants

    period = 0.05
    monkeypatch.setattr(constants, "PROGRESS_SECONDS", period)
    sim = plate(150)
    with caplog.at_level(logging.INFO, logger="crackbake.simulate.solver.iben"):
        r = solve_iben(sim, uniform(sim), PARAMS)
    times = [rec.created for rec in caplog.records if rec.getMessage().startswith("iben: ")]
    assert r.stats["loop_seconds"] > 4 * period, r.stats["loop_seconds"]
    assert len(times) >= 2, f"{len(times)} records in a {r.stats['loop_seconds']:.2f} s loop"
    gaps = np.diff(times)
    assert (gaps >= 0.9 * period).all(), gaps


# ------------------------------------------------------------------ pattern quality


def test_impact_radial_near_concentric_further_out(impact_result, sim60):
    """Length shares over three seeds (one run's handful of concentric links moves a lot)."""
    import dataclasses

    radius = np.pi * 0.25 / 2
    rows = []
    results = [impact_result] + [solve_iben(sim, impact(sim), dataclasses.replace(PARAMS,
                                                                                  seed=seed))
                                 for seed, sim in ((1, plate(60, seed=2)), (2, plate(60, seed=3)))]
    for result in results:
        for c in result.cracks:
            p = c.points[:, :2]
            for i in range(len(p) - 1):
                m, d = 0.5 * (p[i] + p[i + 1]), p[i + 1] - p[i]
                rr = m - 0.5
                dist = np.linalg.norm(rr)
                rows.append((dist / radius,
                             abs(d @ rr) / (np.linalg.norm(d) * max(dist, 1e-12)),
                             np.linalg.norm(d)))
    rows = np.array(rows)
    near, far = rows[rows[:, 0] < 0.35], rows[rows[:, 0] > 0.5]
    radial_near = (near[:, 2] * (near[:, 1] > 0.7)).sum() / near[:, 2].sum()
    tangential_far = (far[:, 2] * (far[:, 1] < 0.5)).sum() / far[:, 2].sum()
    assert radial_near > 0.45  # measured 0.77
    assert tangential_far > 0.15  # measured 0.23: concentric links (60-cell plates)
    dens = [rows[(rows[:, 0] >= a) & (rows[:, 0] < b), 2].sum() / (b * b - a * a)
            for a, b in ((0, 0.33), (0.33, 0.66), (0.66, 1.2))]
    assert dens[0] > dens[1] > dens[2]


def test_shrinkage_network(shrink_result):
    adj, edges = crack_graph(shrink_result)
    # Connected: the largest component holds most of the crack length.
    comp: dict[tuple, int] = {}
    for s in adj:
        if s in comp:
            continue
        comp[s] = len(comp)
        stack, cid = [s], comp[s]
        while stack:
            u = stack.pop()
            for w in adj[u]:
                if w not in comp:
                    comp[w] = cid
                    stack.append(w)
    length: dict[int, float] = {}
    for a, b in edges:
        length[comp[a]] = length.get(comp[a], 0) + np.linalg.norm(np.subtract(a, b))
    assert max(length.values()) / sum(length.values()) > 0.8
    # Most crack ends finish on another crack or the boundary.
    ends = [p for p, nb in adj.items() if len(nb) != 2]
    free = sum(1 for p in ends if len(adj[p]) == 1 and not on_plate_boundary(p))
    incidences = sum(len(adj[p]) for p in ends)
    assert 1 - free / incidences > 0.7
    # Junction angles: the stem of a T meets the through crack near 90 degrees.
    angles = []
    for p, nb in adj.items():
        if len(nb) != 3:
            continue
        dirs = []
        for q in nb:
            prev, cur = p, q
            for _ in range(3):
                if len(adj[cur]) != 2:
                    break
                prev, cur = cur, next(x for x in adj[cur] if x != prev)
            d = np.subtract(cur, p)[:2]
            dirs.append(d / np.linalg.norm(d))
        ang = [[np.degrees(np.arccos(np.clip(dirs[i] @ dirs[j], -1, 1))) for j in range(3)]
               for i in range(3)]
        i, j = max(((0, 1), (0, 2), (1, 2)), key=lambda ij: ang[ij[0]][ij[1]])
        k = 3 - i - j
        angles.append(min(ang[k][i], ang[k][j]))
    angles = np.array(angles)
    assert len(angles) > 20
    assert np.mean(np.abs(angles - 90) < 45) > 0.55  # measured ~0.62


def test_straight_under_directional_stress():
    sim = plate(60)
    r = solve_iben(sim, directional(sim), PARAMS)
    turn, length = 0.0, 0.0
    for c in r.cracks:
        d = np.diff(c.points[:, :2], axis=0)
        seg = np.linalg.norm(d, axis=1)
        u = d / seg[:, None]
        length += seg.sum()
        turn += np.arccos(np.clip((u[1:] * u[:-1]).sum(1), -1, 1)).sum()
    # Radians of turning per edge length h; following zig-zag mesh edges gives ~0.5-1.
    assert turn / length * sim.edge_length < 0.2  # measured ~0.13
    # Cracks run across the tension direction.
    d = np.array([1.0, 0.3]) / np.linalg.norm([1.0, 0.3])
    along = [abs((c.points[-1, :2] - c.points[0, :2]) @ d)
             / np.linalg.norm(c.points[-1, :2] - c.points[0, :2]) for c in r.cracks
             if np.linalg.norm(c.points[-1, :2] - c.points[0, :2]) > 5 * sim.edge_length]
    assert np.median(along) < 0.4


def test_origins_record_every_crack_started(impact_result, shrink_result):
    for r in (impact_result, shrink_result):
        o = r.origins
        assert o.shape == (r.stats["cracks"], 6)
        # Started in order, on the plate, and their lengths add up to the network's.
        assert (np.diff(o[:, 3]) >= 0).all()
        assert ((o[:, :2] >= 0) & (o[:, :2] <= 1)).all() and np.allclose(o[:, 2], 0)
        assert (o[:, 5] > 0).all()
        assert o[:, 5].sum() == pytest.approx(total_length(r), rel=1e-9)
        assert int(o[:, 4].sum()) == r.stats["edge_starts"]


def _inserted(cracks) -> set:
    """Points a later tip put on an older crack's segment to end there (the solver splits that
    crack edge): each lies on the segment between two of its neighbours along the cracks and
    carries that segment's time, not the step it was made at."""
    nb: dict[tuple, list] = {}
    for c in cracks:
        for i, q in enumerate(c.points):
            for j in (i - 1, i + 1):
                if 0 <= j < len(c.points):
                    nb.setdefault(tuple(q.round(12)), []).append(c.points[j])
    out = set()
    for k, ends in nb.items():
        m = np.asarray(k)
        for x in range(len(ends)):
            for y in range(x + 1, len(ends)):
                a, ab = ends[x], ends[y] - ends[x]
                t = np.dot(m - a, ab) / max(np.dot(ab, ab), 1e-300)
                if 0 < t < 1 and np.linalg.norm(a + t * ab - m) < 1e-9:
                    out.add(k)
    return out


@pytest.mark.parametrize("make", [uniform, impact], ids=["shrink", "glass"])
def test_no_crack_starts_right_beside_another(make):
    """A new crack starts no closer than RELAX_RINGS reference edges to any crack point that
    existed then (the reference edge: that of a TIP_REF_FACES-face mesh of the surface).

    Points inserted later on an older segment (where a tip ended on it) are left out: they
    carry the older segment's time, and counting them found a start 0.98 of the distance from
    a junction made 36 steps after it (plate seeds 1 and 3); without them the closest start
    over seeds 1-6 is 1.001 of it."""
    from crackbake.simulate.solver import iben

    sim = plate(150)
    r = solve_iben(sim, make(sim), PARAMS)
    ref = np.sqrt(4.0 * 1.0 / (np.sqrt(3.0) * iben.TIP_REF_FACES))  # unit plate, area 1
    later = _inserted(r.cracks)
    keep = np.array([tuple(q.round(12)) not in later for c in r.cracks for q in c.points])
    assert 0 < (~keep).sum() < keep.sum()
    pts = np.concatenate([c.points for c in r.cracks])[keep]
    born = (np.concatenate([c.time for c in r.cracks]) * r.steps)[keep]
    assert len(r.origins) > 5
    for x, y, z, step, _edge, _length in r.origins[1:]:
        older = pts[born < step - 0.5]
        if len(older):
            d = np.linalg.norm(older - [x, y, z], axis=1).min()
            assert d >= iben.RELAX_RINGS * ref * (1 - 1e-9), (step, d)


def _stops_short(r, rad: float) -> int:
    """Free crack ends (touching no other crack, off the plate boundary) with another crack's
    point ahead of them within ``rad``, inside the solver's ligament cone around the direction
    the crack arrived from (its last 0.02 units)."""
    from crackbake.simulate.solver.iben import LIGAMENT_CONE_DEG

    cos = np.cos(np.radians(LIGAMENT_CONE_DEG))
    count = 0
    for i, c in enumerate(r.cracks):
        others = np.concatenate([d.points for j, d in enumerate(r.cracks) if j != i])
        p = c.points
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        for end, sign in ((0, 1.0), (len(p) - 1, -1.0)):
            e = p[end]
            dist = np.linalg.norm(others - e, axis=1)
            if dist.min() < 1e-7 or min(e[0], e[1], 1 - e[0], 1 - e[1]) < 1e-6:
                continue
            back = int(np.argmin(np.abs(s - (s[end] + sign * min(0.02, s[-1])))))
            u = e - p[back]
            if np.linalg.norm(u) == 0:
                continue
            u /= np.linalg.norm(u)
            ahead = (dist < rad) & ((others - e) @ u >= cos * dist)
            count += int(ahead.any())
    return count


def test_arrested_tips_break_through_to_a_crack_ahead():
    """A tip that stops a few edges short of a crack it runs into breaks the ligament between
    them: on 60-cell plates (3 seeds, glass and shrinkage) measured 1 such free end in all,
    15 with the ligament rule off (LIGAMENT_REL = 0)."""
    from crackbake.simulate.solver import iben

    assert iben.LIGAMENT_REL == 0.25
    total = broken = 0
    for seed in range(3):
        sim = plate(60, seed=seed + 1)
        for make in (impact, uniform):
            r = solve_iben(sim, make(sim), SolverParams(**{**PARAMS.__dict__, "seed": seed}))
            total += _stops_short(r, 0.25 * r.stats["shadow_radius"])
            broken += r.stats["ligaments_broken"]
    assert broken > 0
    assert total <= 2


def test_struct_fields_match_the_driver_state(sim60):
    """The kernels' struct types (fixed so the compiled kernels are reused from the cache)
    are exactly the numba types of the state and scratch the driver builds, in field order."""
    from numba import typeof

    from crackbake.simulate.solver.iben.solve import _setup
    from crackbake.simulate.solver.iben.state import State, Work, work
    from crackbake.simulate.solver.iben.structs import STATE_FIELDS, WORK_FIELDS

    s, _mesh = _setup(sim60, uniform(sim60), SolverParams(max_steps=10))
    w = work(s)
    assert [n for n, _ in STATE_FIELDS] == list(State._fields)
    assert [n for n, _ in WORK_FIELDS] == list(Work._fields)
    assert [typeof(a) for a in s] == [t for _, t in STATE_FIELDS]
    assert [typeof(a) for a in w] == [t for _, t in WORK_FIELDS]
