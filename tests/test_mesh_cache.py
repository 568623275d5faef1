"""The bake's mesh cache: gutter plans, tangent frames and UV checks stored by content."""

from __future__ import annotations

import hashlib
import os
import time

import numpy as np
import pytest
from conftest import plate_mesh

from crackbake.bake import mesh_cache as mc
from crackbake.bake.dilation import PlanAhead, fill_plan


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    # Never touch the user's ~/.cache from tests.
    folder = tmp_path / "cache"
    monkeypatch.setenv("CRACKBAKE_CACHE_DIR", str(folder))
    return folder


def _islands(seed: int = 11) -> np.ndarray:
    rng = np.random.default_rng(seed)
    inside = rng.random((97, 300)) < 0.02
    inside[30:50, 100:180] = True
    return inside


def _same_plan(a, b) -> bool:
    return all(np.array_equal(getattr(a, n), getattr(b, n)) for n in ("targets", "sources", "far"))


def _planned(inside, limit, cache=True):
    ahead = PlanAhead(inside, limit, cache=cache)
    plan = ahead.plan_for(inside, limit)
    ahead.close()  # the cache's write done
    return ahead, plan


@pytest.mark.parametrize("limit", [None, 3])
def test_plan_is_stored_then_read_and_equals_the_plan_in_place(cache, limit):
    inside = _islands()
    first, plan = _planned(inside, limit)
    assert not first.cached and _same_plan(plan, fill_plan(inside, limit))
    files = list(cache.glob("gutter-*.npys"))
    assert len(files) == 1 and not list(cache.glob(".tmp-*"))
    assert files[0].stat().st_mode & 0o044  # readable like any cache file
    second, again = _planned(inside.copy(), limit)
    assert second.cached and _same_plan(again, plan)
    assert len(list(cache.glob("gutter-*.npys"))) == 1


def test_changed_islands_or_limit_get_a_fresh_plan(cache):
    inside = _islands()
    _planned(inside, None)
    moved = inside.copy()
    moved[60, 10] = True  # one texel more island: another plan
    ahead, plan = _planned(moved, None)
    assert not ahead.cached and _same_plan(plan, fill_plan(moved, None))
    ahead, plan = _planned(inside, 2)
    assert not ahead.cached and _same_plan(plan, fill_plan(inside, 2))
    assert len(list(cache.glob("gutter-*.npys"))) == 3


def test_no_cache_touches_no_files(cache):
    ahead, plan = _planned(_islands(), None, cache=False)
    assert not ahead.cached and plan is not None
    assert not cache.exists()


def test_a_corrupt_or_foreign_plan_is_planned_again(cache):
    inside = _islands()
    _, plan = _planned(inside, None)
    (path,) = cache.glob("gutter-*.npys")
    path.write_bytes(path.read_bytes()[:1000])  # truncated
    ahead, again = _planned(inside, None)
    assert not ahead.cached and _same_plan(again, plan)
    # A file under the right key whose indices point outside the image: refused (the fill
    # kernels index without checks), not used.
    key = mc.plan_key(inside, None)
    bad = fill_plan(inside, None)
    bad.sources[0] = inside.size + 5
    mc.write_plan(key, inside, bad)
    assert mc.read_plan(key, inside, None) is None
    # Another islands' file under this key (the stored islands differ): refused.
    other = _islands(seed=3)
    mc.write_plan(key, other, fill_plan(other, None))
    assert mc.read_plan(key, inside, None) is None


def test_key_hashes_the_planning_code(monkeypatch):
    inside = _islands()
    key = mc.plan_key(inside, None)
    mc._sources.cache_clear()
    real = mc._sources.__wrapped__
    monkeypatch.setattr(mc, "_sources", lambda *m: hashlib.sha256(real(*m) + b"edit").digest())
    assert mc.plan_key(inside, None) != key


def test_trim_keeps_the_most_recently_used_under_the_bound(cache):
    cache.mkdir()
    now = time.time()
    paths = []
    for k, kind in enumerate(["gutter", "tangents", "uvcheck", "gutter", "gutter"]):
        p = cache / f"{kind}-{k:064x}.npys"
        p.write_bytes(b"x" * 100)
        os.utime(p, (now - 100 + k, now - 100 + k))  # k = 0 is the oldest
        paths.append(p)
    other = cache / "0123.npz"  # an unwrap: not the mesh cache's to remove
    other.write_bytes(b"y" * 1000)
    os.utime(other, (now - 1000, now - 1000))
    killed, writing = cache / ".tmp-killed.npys", cache / ".tmp-writing.npys"
    for p in (killed, writing):
        p.write_bytes(b"z")
    os.utime(killed, (now - 2 * mc.STALE_TMP_S, now - 2 * mc.STALE_TMP_S))
    mc.trim(cache, keep=paths[0], max_bytes=250)
    left = {p.name for p in cache.iterdir()}
    assert left == {paths[0].name, paths[4].name, other.name, writing.name}


def test_tangent_frames_cached_equal_the_computed_and_follow_the_uvs(cache):
    from crackbake.bake.tangents import with_tangents
    from crackbake.bake.uv.uvmesh import UVMesh

    mesh = plate_mesh(6, wobble=0.2, seed=1)
    uv = mesh.uv.copy()
    uv[: len(uv) // 2, 0] = 1 - uv[: len(uv) // 2, 0]  # mirrored half: split vertices
    base = UVMesh(vertices=mesh.vertices, faces=mesh.faces, uv=uv, normals=mesh.normals,
                  vertex_map=np.arange(len(mesh.vertices)), method="kept", overlap_fraction=0.0,
                  padding_px=0)  # fmt: skip
    computed = with_tangents(base)
    assert not cache.exists()
    first = with_tangents(base, cache=True)
    assert len(list(cache.glob("tangents-*.npys"))) == 1
    second = with_tangents(base, cache=True)
    for got in (first, second):
        for name in ("vertices", "faces", "uv", "normals", "vertex_map", "tangents"):
            np.testing.assert_array_equal(getattr(got, name), getattr(computed, name), name)
    moved = UVMesh(vertices=base.vertices, faces=base.faces, uv=mesh.uv, normals=base.normals,
                   vertex_map=base.vertex_map, method="kept", overlap_fraction=0.0,
                   padding_px=0)  # fmt: skip
    fresh = with_tangents(moved, cache=True)
    assert len(list(cache.glob("tangents-*.npys"))) == 2
    np.testing.assert_array_equal(fresh.tangents, with_tangents(moved).tangents)
    assert not np.array_equal(fresh.tangents, first.tangents)  # not the other UVs' frames


def test_uv_check_cached_equals_the_measured_and_follows_the_uvs(cache, gl_ctx):
    from crackbake.bake.uv.check import check_uvs
    from crackbake.bake.uv.prepare import _checked_uvs

    mesh = plate_mesh(8, wobble=0.2, seed=2)
    mesh.uv[:] = 0.1 + 0.8 * mesh.uv
    mesh.uv[0] -= 0.15  # a corner strays past the page: wrapped copies where the page is free
    measured = check_uvs(mesh, ctx=gl_ctx)
    assert measured.usable and len(measured.wraps)
    first = _checked_uvs(mesh, gl_ctx, True)
    assert len(list(cache.glob("uvcheck-*.npys"))) == 1
    second = _checked_uvs(mesh, gl_ctx, True)
    for got in (first, second):
        for name in ("usable", "reason", "udim", "overlap_fraction", "outside_fraction",
                     "lost_fraction", "lost_faces", "tiles"):  # fmt: skip
            assert getattr(got, name) == getattr(measured, name), name
        np.testing.assert_array_equal(got.wraps, measured.wraps)
    mesh.uv[:] = 0.5 * mesh.uv + 0.25  # folded into the page's middle: no strays
    fresh = _checked_uvs(mesh, gl_ctx, True)
    assert len(list(cache.glob("uvcheck-*.npys"))) == 2
    assert fresh.outside_fraction == 0 and not len(fresh.wraps)
    assert fresh.overlap_fraction == check_uvs(mesh, ctx=gl_ctx).overlap_fraction


def test_up_axis_cached_equals_the_guess_and_follows_the_positions(cache):
    """The preview's guessed up axis: stored on the first call, read on the next (no hull, so
    no scipy.spatial import for a re-bake), another key once the positions move; a file that
    holds no axis is guessed again."""
    from crackbake.bake.preview import up_axis, up_vector
    from crackbake.io.mesh import Mesh

    # a square pyramid on its base in the z = 0 plane: it stands on -Z, no facet faces -Y
    corners = np.array([[0, 0, 0], [3, 0, 0], [3, 3, 0], [0, 3, 0], [1.5, 1.5, 1]], float)
    faces = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])

    def mesh(vertices, source):
        return Mesh(vertices=vertices, faces=faces, uv=None, normals=np.zeros_like(vertices),
                    source=source)  # fmt: skip

    box = mesh(corners, "box.obj")
    guess = up_axis(box)
    assert tuple(guess) == (0, 0, 1)
    assert tuple(up_vector(None, box)) == (0, 0, 1) and not cache.exists()  # cache off
    assert tuple(up_vector(None, box, cache=True)) == (0, 0, 1)
    (path,) = cache.glob("up-*.npys")
    assert tuple(up_vector(None, box, cache=True)) == (0, 0, 1)
    assert list(cache.glob("up-*.npys")) == [path]
    assert tuple(up_vector("y", box, cache=True)) == (0, 1, 0)  # --up is never guessed
    tall = mesh(corners[:, [0, 2, 1]], "box.obj")  # the same pyramid on the y = 0 plane
    assert tuple(up_vector(None, tall, cache=True)) == tuple(up_axis(tall)) == (0, 1, 0)
    assert len(list(cache.glob("up-*.npys"))) == 2
    gltf = mesh(corners, "box.glb")  # glTF is +Y by definition
    assert tuple(up_vector(None, gltf, cache=True)) == (0, 1, 0)
    # a file whose array is not an axis is not believed
    with open(path, "wb") as fh:
        np.save(fh, np.array(path.stem.removeprefix("up-")))
        np.save(fh, np.array([0.0, -1.0, 0.0]))
    assert tuple(up_vector(None, box, cache=True)) == (0, 0, 1)


def _obj(path, u0: float) -> None:
    """A 2x1 plate whose UV island starts at u = ``u0``."""
    path.write_text("v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\n"
                    f"vt {u0} 0.2\nvt {u0 + 0.8} 0.2\nvt {u0 + 0.8} 0.8\nvt {u0} 0.8\n"
                    "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")  # fmt: skip


def _files(folder) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.name != "manifest.json"}


def test_rebakes_from_the_cache_write_the_same_files(cache, tmp_path):
    """A re-bake (``--cracks``) through the pipeline: the second reads the plan, the frames and
    the UV check from the cache and writes the same bytes as one without the cache; moved UVs
    bake with fresh ones, again as without the cache."""
    from crackbake.io.mesh import load_mesh
    from crackbake.io.sidecar import write_sidecar
    from crackbake.network import Crack, CrackNetwork, mesh_info
    from crackbake.params import RunParams
    from crackbake.pipeline import run

    obj = tmp_path / "plate.obj"
    _obj(obj, 0.1)
    crack = Crack(id=0, points=np.array([[1.2, 0.75, 0.0], [1.8, 0.7, 0.0]]),
                  faces=np.array([1, 1]), time=np.array([0.0, 1.0]),
                  width=np.array([0.02, 0.02]), depth=np.array([0.01, 0.01]))  # fmt: skip
    side = tmp_path / "cracks.json"
    write_sidecar(CrackNetwork(cracks=[crack], mesh=mesh_info(load_mesh(obj))), side)

    def bake(name, folder=cache):
        os.environ["CRACKBAKE_CACHE_DIR"] = str(folder)  # the fixture restores it
        run(RunParams(mesh=obj, cracks=side, res=128, out=tmp_path / name))
        return _files(tmp_path / name)

    # The cache is a run parameter the files record: the references use one of their own.
    plain = bake("plain", tmp_path / "empty1")
    assert bake("first") == plain
    kinds = ("gutter", "tangents", "uvcheck", "up")
    def stored():  # a hit reads the file, a miss replaces it (another inode)
        return {k: {p.name: p.stat().st_ino for p in cache.glob(f"{k}-*.npys")} for k in kinds}

    first = stored()
    assert all(len(v) == 1 for v in first.values()), first
    assert bake("second") == plain
    assert stored() == first
    _obj(obj, 0.15)  # the island moved: every cached result is another one's
    moved = bake("moved_plain", tmp_path / "empty2")
    assert moved != plain
    assert bake("moved") == moved
    # the positions did not move: the up axis is the one guessed before
    assert all(len(list(cache.glob(f"{k}-*.npys"))) == 2 for k in kinds[:3])
    assert len(list(cache.glob("up-*.npys"))) == 1


def _sim_arrays(sim) -> dict:
    names = ("vertices", "faces", "asset_face", "node_face", "node_bary", "boundary")
    return {n: getattr(sim, n) for n in names}


def _same_sim(a, b) -> bool:
    return a.edge_length == b.edge_length and a.proxy is None and b.proxy is None and all(
        x.dtype == y.dtype and np.array_equal(x, y)
        for x, y in zip(_sim_arrays(a).values(), _sim_arrays(b).values(), strict=True))


def test_sim_mesh_cached_equals_the_built_and_says_its_warnings_again(cache):
    """The sim mesh refined in the asset's faces: stored by the first build, read by the next
    (the same arrays and edge length), with the build's warnings given again; another seed,
    edge length or refined ball is another mesh; the cache off touches no file."""
    import warnings

    from crackbake.simulate.simmesh import Local, build_simmesh

    mesh = plate_mesh(6, wobble=0.4, seed=2)
    # a duplicated face: the build warns (and leaves it out of the simulation)
    mesh = type(mesh)(vertices=mesh.vertices, faces=np.vstack([mesh.faces, mesh.faces[:1]]),
                      uv=mesh.uv, normals=mesh.normals, source=mesh.source)  # fmt: skip

    def build(**kw):
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            sim = build_simmesh(mesh, target_faces=400, **kw)
        return sim, [str(w.message) for w in said]

    plain, said = build()
    assert said and "duplicated face" in said[0]
    assert not cache.exists()
    first, said_first = build(cache=True)
    (path,) = cache.glob("simmesh-*.npys")
    second, said_second = build(cache=True)
    assert _same_sim(plain, first) and _same_sim(plain, second)
    assert said_first == said_second == said
    assert list(cache.glob("simmesh-*.npys")) == [path]
    other, _ = build(cache=True, seed=5)
    assert not _same_sim(plain, other) and _same_sim(other, build(seed=5)[0])
    ball = Local(centres=np.array([[0.5, 0.5, 0.0]]), radii=np.array([0.2]),
                 edges=np.array([0.02]))  # fmt: skip
    fine, _ = build(cache=True, local=ball)
    assert _same_sim(fine, build(local=ball)[0]) and len(fine.faces) > len(plain.faces)
    assert len(list(cache.glob("simmesh-*.npys"))) == 3
    # a file whose arrays do not fit the asset is built again, and replaced
    with open(path, "wb") as fh:
        np.save(fh, np.array(path.stem.removeprefix("simmesh-")))
        for a in _sim_arrays(plain).values():
            np.save(fh, a + 1000 if a.dtype == np.int64 else a)
        np.save(fh, np.array('{"edge_length": 1.0, "warnings": []}'))
    again, said_again = build(cache=True)
    assert _same_sim(plain, again) and said_again == said


def test_a_cached_sim_mesh_brings_its_edges_shells_and_centroids(cache):
    """Read from the cache, the sim mesh's edges, shells and centroids are in the memo as the
    stress field, the star check and the solver ask for them (computed once, at its build),
    equal to computing them afresh; a file with wrong ones is built again."""
    from crackbake import geometry
    from crackbake.geometry import (
        DERIVED_ARRAYS,
        forget,
        recall,
        shared_centroids,
        shared_edges,
        shared_shells,
    )
    from crackbake.simulate.simmesh import build_simmesh

    mesh = plate_mesh(6, wobble=0.4, seed=3)
    build_simmesh(mesh, target_faces=400, cache=True)
    forget()
    sim = build_simmesh(mesh, target_faces=400, cache=True)  # read
    v, f, n = np.asarray(sim.vertices), np.asarray(sim.faces), len(sim.vertices)
    fk, vk = geometry.content_key(f), geometry.content_key(v)
    held = {name: recall(key) for name, key in (("edges", ("edges", fk, n)),
                                                  ("shells", ("shells", fk, n)),
                                                  ("centroids", ("centroids", vk, fk)))}
    assert all(value is not None for value in held.values())
    forget()
    edges, uses = shared_edges(f, n)
    centroids, reach = shared_centroids(v, f)
    assert np.array_equal(held["edges"][0], edges) and np.array_equal(held["edges"][1], uses)
    assert np.array_equal(held["shells"][0], shared_shells(f, n))
    assert np.array_equal(held["centroids"][0], centroids) and held["centroids"][1] == reach
    # wrong derived arrays (an edge past the last node): the file is not used
    (path,) = cache.glob("simmesh-*.npys")
    with open(path, "rb") as fh:
        parts = [np.load(fh) for _ in range(6 + 5 + len(DERIVED_ARRAYS) + 2)]
    parts[1 + 6 + 5] = parts[1 + 6 + 5] + n
    with open(path, "wb") as fh:
        for a in parts:
            np.save(fh, a)
    forget()
    again = build_simmesh(mesh, target_faces=400, cache=True)
    assert _same_sim(sim, again)
    assert np.array_equal(recall(("edges", fk, n))[0], edges)  # built, and computed again


def test_a_proxy_sim_mesh_is_cached_with_its_proxy_and_a_lazy_surface(cache):
    """A sim mesh refined in a decimated proxy: read back with the proxy's arrays and the
    asset surface, whose AABB tree is built when a solve starts, in a child process
    (crackbake.closest_worker), and answers as the built one."""
    from crackbake.simulate.simmesh import build_simmesh

    mesh = plate_mesh(12, wobble=0.3, seed=4)
    built = build_simmesh(mesh, target_faces=100, proxy_above=100)
    assert built.proxy is not None
    first = build_simmesh(mesh, target_faces=100, proxy_above=100, cache=True)
    read = build_simmesh(mesh, target_faces=100, proxy_above=100, cache=True)
    assert len(list(cache.glob("simmesh-*.npys"))) == 1
    for sim in (first, read):
        assert all(np.array_equal(a, b) for a, b in zip(_sim_arrays(built).values(),
                                                        _sim_arrays(sim).values(), strict=True))
        for name in ("vertices", "faces", "rows"):
            assert np.array_equal(getattr(sim.proxy, name), getattr(built.proxy, name))
        for name in ("vertices", "faces"):
            assert np.array_equal(getattr(sim.proxy.surface, name),
                                  getattr(built.proxy.surface, name))
    assert read.proxy.surface._tree is None  # not built until the solve starts
    read.proxy.surface.start_worker()  # as a solving run does (crackbake.pipeline)
    points = np.random.default_rng(0).uniform(-0.1, 1.1, (200, 3)) * [1, 1, 0.1]
    for a, b in zip(read.proxy.onto_asset(points), built.proxy.onto_asset(points), strict=True):
        np.testing.assert_array_equal(a, b)
    other = build_simmesh(mesh, target_faces=100, proxy_above=10_000, cache=True)
    assert other.proxy is None and len(list(cache.glob("simmesh-*.npys"))) == 2


def test_solving_runs_from_the_cached_sim_mesh_write_the_same_files(cache, tmp_path):
    """Two solving bakes through the pipeline: the second reads the sim mesh and writes the
    bytes a run without the cache writes."""
    from crackbake.params import RunParams
    from crackbake.params.impacts import Impact
    from crackbake.pipeline import run

    obj = tmp_path / "plate.obj"
    _obj(obj, 0.1)

    def bake(name, folder=cache, **more):
        os.environ["CRACKBAKE_CACHE_DIR"] = str(folder)  # the fixture restores it
        run(RunParams(mesh=obj, impacts=(Impact((1.0, 0.5, 0.0)),), res=128, sim_faces=2000,
                      out=tmp_path / name, **more))  # fmt: skip
        return _files(tmp_path / name)

    plain = bake("plain", tmp_path / "empty")
    assert bake("first") == plain
    (path,) = cache.glob("simmesh-*.npys")
    inode = path.stat().st_ino
    assert bake("second") == plain
    assert path.stat().st_ino == inode  # read, not written again
    # the same through a decimated proxy (its asset tree built when the cracks move onto it)
    proxied = bake("proxied_plain", tmp_path / "empty2", sim_proxy="always")
    assert proxied != plain
    assert bake("proxied_first", sim_proxy="always") == proxied
    assert bake("proxied_second", sim_proxy="always") == proxied
    assert len(list(cache.glob("simmesh-*.npys"))) == 2
