"""Shared test factories and the session's EGL context.

Factories build meshes in memory (the tests read nothing outside the repository):

* :func:`plate_mesh`: a square plate as a :class:`crackbake.io.mesh.Mesh`, an n x n grid of
  squares (2 n^2 triangles), optionally with moved inner vertices, UVs = (x, y) / size;
* :func:`sim_plate`: a jittered, Delaunay-triangulated unit plate duck-typed as a
  :class:`crackbake.simulate.simmesh.SimMesh`, what the solver tests run on.

``gl_ctx`` is one headless EGL context for the whole session; every test that uses it is
checked for a pending GL error afterwards, as moderngl's own test suite does.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial import Delaunay

from crackbake.geometry import vertex_normals, weld_by_position, welded_vertex_normals
from crackbake.io.mesh import Mesh

# ------------------------------------------------------------------ reference checks
# Tests marked ``reference`` check outputs with a real client (Blender's bpy, the Khronos glTF
# validator) and skip when it is missing.  ``make test`` installs both and sets
# CRACKBAKE_REFERENCE=require, so there a skipped reference check fails the run instead.


def _references_required() -> bool:
    return os.environ.get("CRACKBAKE_REFERENCE", "") == "require"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if report.skipped and item.get_closest_marker("reference") and _references_required():
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else report.longrepr
        report.outcome = "failed"
        report.longrepr = (f"reference check skipped under CRACKBAKE_REFERENCE=require "
                           f"(make test installs it: make references): {reason}")


def pytest_terminal_summary(terminalreporter):
    """One line: how many reference checks ran, so a CI log shows none was left out."""
    outcome = {}
    for reports in terminalreporter.stats.values():
        for rep in reports:
            # stats also holds deselected items and warnings: only test reports have "when"
            # (a collection report, which some plugins leave there, has no keywords)
            if getattr(rep, "when", None) and "reference" in getattr(rep, "keywords", ()):
                if rep.outcome != "passed":
                    outcome[rep.nodeid] = rep.outcome
                elif rep.when == "call":
                    outcome.setdefault(rep.nodeid, "passed")
    if outcome:
        counts = {k: list(outcome.values()).count(k) for k in sorted(set(outcome.values()))}
        terminalreporter.write_line(
            "reference checks (Blender, glTF validator): "
            + ", ".join(f"{n} {k}" for k, n in counts.items()))


def wait_for_staging(proc, folder: Path, timeout: float = 120.0) -> None:
    """Block until a crackbake child has opened its output stage in ``folder`` (a
    ``.<name>.crackbake-staging-*`` entry appears): from then on its SIGINT/SIGTERM handlers
    are in place.

    A fixed sleep is not enough on a loaded machine, where the child may still be importing
    when the signal arrives (it then dies by the signal, -15, instead of exiting 143).
    """
    end = time.monotonic() + timeout
    while not any(".crackbake-staging-" in p.name for p in folder.iterdir()):
        if proc.poll() is not None or time.monotonic() > end:
            raise AssertionError(f"the child never staged its output (exit {proc.poll()})")
        time.sleep(0.05)


def grid_faces(nx: int, ny: int) -> np.ndarray:
    """Faces of an (nx+1) x (ny+1) vertex grid indexed ``i * (ny + 1) + j``, counter-clockwise
    in the (i, j) plane: (2 nx ny, 3) int64."""
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).reshape(-1, 3)


def plate_mesh(cells: int, size: float = 1.0, wobble: float = 0.0, seed: int = 0,
               uv: bool = True, name: str = "plate") -> Mesh:
    """Flat square plate in z = 0 from (0, 0) to (size, size), 2 cells^2 triangles.

    ``wobble`` moves inner vertices by up to ±wobble/2 of a cell (seeded).
    """
    t = np.linspace(0.0, size, cells + 1)
    x, y = np.meshgrid(t, t, indexing="ij")
    xy = np.stack([x.ravel(), y.ravel()], 1)
    inner = ((xy > 0) & (xy < size)).all(axis=1)
    if wobble:
        rng = np.random.default_rng(seed)
        xy[inner] += wobble * (size / cells) * rng.uniform(-0.5, 0.5, (int(inner.sum()), 2))
    vertices = np.column_stack([xy, np.zeros(len(xy))])
    faces = grid_faces(cells, cells).astype(np.int64)
    wv, wf, inverse = weld_by_position(vertices, faces)
    return Mesh(vertices=vertices, faces=faces, uv=xy / size if uv else None,
                normals=vertex_normals(wv, wf)[inverse], source=f"{name}.obj", name=name)


def sim_plate(n: int, jitter: float = 0.35, seed: int = 1) -> SimpleNamespace:
    """Unit plate, n x n jittered grid points, Delaunay triangulated, normals +z.

    Duck-typed sim mesh: ``vertices``, ``faces``, ``asset_face`` (two sim faces per asset face
    where possible, so asset faces are not all distinct), ``edge_length``, ``boundary=None``
    (the solver finds it).
    """
    h = 1.0 / n
    x, y = np.meshgrid(np.arange(n + 1) * h, np.arange(n + 1) * h, indexing="ij")
    p = np.stack([x.ravel(), y.ravel()], 1)
    inner = (p > 1e-9).all(1) & (p < 1 - 1e-9).all(1)
    p[inner] += np.random.default_rng(seed).uniform(-jitter, jitter, (inner.sum(), 2)) * h
    tri = Delaunay(p).simplices.astype(np.int64)
    v = np.concatenate([p, np.zeros((len(p), 1))], 1)
    cr = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])[:, 2]
    tri[cr < 0] = tri[cr < 0][:, [0, 2, 1]]
    tri = tri[np.abs(cr) > 1e-12 * h * h]
    return SimpleNamespace(vertices=v, faces=tri, asset_face=np.arange(len(tri)) // 2,
                           edge_length=h, boundary=None)


def make_mesh(vertices, faces, uv=None, source: str = "test.obj") -> Mesh:
    """A :class:`Mesh` from arrays, with welded area-weighted vertex normals (as the loader)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    return Mesh(
        vertices=vertices,
        faces=faces,
        uv=None if uv is None else np.asarray(uv, dtype=np.float64),
        normals=welded_vertex_normals(vertices, faces),
        source=source,
    )


def torus_mesh(major: int = 48, minor: int = 24) -> Mesh:
    """A closed torus (radii 1 and 0.3) without UVs."""
    import trimesh

    t = trimesh.creation.torus(1.0, 0.3, major_sections=major, minor_sections=minor)
    return make_mesh(t.vertices, t.faces, source="torus.obj")


def uv_grid(nx: int, ny: int, width: float, height: float, jitter: float = 0.0, seed: int = 0):
    """A flat nx x ny quad grid over [0, width] x [0, height], two triangles per quad.

    Returns the 2-D points ((nx+1)(ny+1), 2) and faces (2 nx ny, 3); ``jitter`` moves inner
    points by up to ±jitter of a cell (seeded).
    """
    xs, ys = np.meshgrid(np.linspace(0, width, nx + 1), np.linspace(0, height, ny + 1))
    pts = np.stack([xs.ravel(), ys.ravel()], axis=1)
    if jitter:
        rng = np.random.default_rng(seed)
        interior = (
            (xs.ravel() > 0) & (xs.ravel() < width) & (ys.ravel() > 0) & (ys.ravel() < height)
        )
        step = min(width / nx, height / ny)
        pts[interior] += rng.uniform(-jitter, jitter, (interior.sum(), 2)) * step
    idx = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return pts, faces


def tiny_network():
    """Two cracks on the unit square (:func:`plate_mesh` with one cell), values chosen so
    segments, lengths and the sidecar can be derived by hand."""
    from crackbake.network import Crack, CrackNetwork, mesh_info

    a = Crack(
        id=7,
        points=np.array([[0.2, 0.1, 0.0], [0.5, 0.1, 0.0], [0.9, 0.4, 0.0]]),  # 0.3 + 0.5 long
        faces=np.array([0, 0, 0]),
        time=np.array([0.0, 0.5, 1.0]),
        width=np.array([0.004, 0.002, 0.0]),
        depth=np.array([0.002, 0.001, 0.0]),
    )
    b = Crack(
        id=2,
        points=np.array([[0.1, 0.5, 0.0], [0.1, 0.9, 0.0]]),  # 0.4 long
        faces=np.array([1, 1]),
        time=np.array([0.2, 0.6]),
        width=np.array([0.001, 0.003]),
        depth=np.array([0.0, 0.0015]),
    )
    return CrackNetwork(
        cracks=[a, b],
        mesh=mesh_info(plate_mesh(1, name="square")),
        params={"seed": 3, "method": "iben", "preset": "glass", "nested": {"k": [1, 2.5]}},
        impacts=[{"point": [0.5, 0.5, 0.0], "radius": 0.1, "strength": 2.0}],
        solver_steps=11,
    )


@pytest.fixture(scope="session")
def gl_session():
    from crackbake.bake.context import create_context

    ctx = create_context()
    yield ctx
    ctx.release()


@pytest.fixture
def gl_ctx(gl_session):
    """The session's EGL context; fails the test if it left a GL error behind."""
    assert gl_session.error == "GL_NO_ERROR"
    yield gl_session
    assert gl_session.error == "GL_NO_ERROR"


# ------------------------------------------------------------------ solver fields (test_iben,
# benchmarks/bench_resolution.py)


def stress_of(stress: np.ndarray, growth=None) -> SimpleNamespace:
    """Duck-typed stress field: per-face ``stress`` (M, 3, 3) and optional ``growth``."""
    return SimpleNamespace(stress=stress, growth=growth, weight=np.ones(len(stress)), impacts=[])


def uniform_stress(sim, s: float = 1.0) -> SimpleNamespace:
    """Isotropic in-plane tension ``s`` (xx = yy) on every face of a z = 0 plate."""
    st = np.zeros((len(sim.faces), 3, 3))
    st[:, 0, 0] = st[:, 1, 1] = s
    return stress_of(st)


def impact_stress(sim, centre=(0.5, 0.5, 0.0), radius: float = 0.25) -> SimpleNamespace:
    """Glass impact: ``w (r r^T + 1.25 t t^T)``, ``w = 2 cos(d / radius)`` within
    ``d <= pi radius / 2`` of ``centre`` (r radial, t hoop)."""
    c = sim.vertices[sim.faces].mean(1) - np.asarray(centre)
    d = np.linalg.norm(c, axis=1)
    w = np.where(d <= np.pi * radius / 2, 2 * np.cos(d / radius), 0.0)
    r = c / np.maximum(d, 1e-12)[:, None]
    t = np.cross([0.0, 0.0, 1.0], r)
    return stress_of(w[:, None, None] * (np.einsum("ea,eb->eab", r, r)
                                         + 1.25 * np.einsum("ea,eb->eab", t, t)))


def largest_eigen(tensors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Test oracle: largest eigenvalue (N,) and its unit eigenvector (N, 3) of symmetric 3x3
    tensors, by numpy."""
    w, v = np.linalg.eigh(tensors)
    return w[:, -1], v[:, :, -1]


# ------------------------------------------------------------------ scheduling
# ``make test`` hands whole files to its 2 workers (pytest-xdist --dist loadfile) in collection
# order, longest first, so that no long file starts when the other worker is nearly done and the
# run ends on short files (longest-processing-time-first).  The longest files, by the seconds of
# their tests in a whole ``make test`` (--durations, under load; re-rank them with
# benchmarks/bench_tests.py), then every other file holding slow tests, then the rest.  A file
# missing here costs only time, never a result.
_LONGEST = ("test_open_meshes.py", "test_transaction.py", "test_golden.py", "test_looks.py",
            "test_batch.py", "test_proxy.py", "test_bad_inputs.py", "test_blender_addon.py",
            "test_docs.py", "test_fuzz.py", "test_precompile.py", "test_bake.py",
            "test_sidecar.py", "test_units.py", "test_spacing.py", "test_decal.py",
            "test_progress.py", "test_impacts.py")


def pytest_configure(config):
    # xdist's loadfile would sort the files by their number of tests instead, which put the
    # long files with few tests (golden runs, the precompile check) last.
    if getattr(config.option, "loadscopereorder", None):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(config, items):
    slow = {item.path for item in items if item.get_closest_marker("slow")}
    rank = {name: i for i, name in enumerate(_LONGEST)}
    # stable: the order within a file is kept
    items.sort(key=lambda item: (rank.get(item.path.name, len(rank)), item.path not in slow))
