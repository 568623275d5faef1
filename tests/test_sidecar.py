"""The cracks.json sidecar (crackbake.io.sidecar): exact round trips, layout, validation, demo."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import plate_mesh, tiny_network

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.mesh import Mesh, load_mesh
from crackbake.io.sidecar import from_dict, read_sidecar, to_dict, write_sidecar
from crackbake.network import Crack, CrackNetwork

REPO = Path(__file__).resolve().parents[1]


def unit_square() -> Mesh:
    """Two triangles covering [0, 1]^2 at z = 0: face 0 below the diagonal, face 1 above."""
    return plate_mesh(1, name="square")


def random_network(seed: int = 0) -> CrackNetwork:
    """Awkward floats (full mantissas, tiny, negative zero) to prove exact round trips."""
    rng = np.random.default_rng(seed)
    cracks = []
    for cid in (0, 3, 1):
        n = int(rng.integers(2, 9))
        pts = rng.uniform(0, 1, (n, 3))
        pts[:, 2] = 0.0
        pts[0, 2] = -0.0
        pts[-1, 0] = 1e-300
        width = rng.uniform(0, 0.01, n)
        cracks.append(
            Crack(
                id=cid,
                points=pts,
                faces=(pts[:, 1] > pts[:, 0]).astype(np.int64),
                time=np.sort(rng.uniform(0, 1, n)),
                width=width,
                depth=width / 3,
            )
        )
    net = tiny_network()
    net.cracks = cracks
    return net


# --- sidecar round trip ---------------------------------------------------------------------


def assert_same_network(x: CrackNetwork, y: CrackNetwork) -> None:
    assert [c.id for c in x.cracks] == [c.id for c in y.cracks]
    for cx, cy in zip(x.cracks, y.cracks, strict=True):
        for key in ("points", "faces", "time", "width", "depth"):
            vx, vy = getattr(cx, key), getattr(cy, key)
            assert vx.dtype == vy.dtype and vx.shape == vy.shape
            # Bitwise, so -0.0 and every last mantissa bit must survive.
            assert vx.tobytes() == vy.tobytes(), key
    assert x.mesh == y.mesh and x.params == y.params and x.impacts == y.impacts
    assert x.solver_steps == y.solver_steps


@pytest.mark.parametrize("make", [tiny_network, random_network])
def test_round_trip_exact_and_byte_identical(tmp_path, make):
    net = make()
    first, second = tmp_path / "a.json", tmp_path / "b.json"
    write_sidecar(net, first)
    back = read_sidecar(first)
    assert_same_network(net, back)
    write_sidecar(back, second)
    assert first.read_bytes() == second.read_bytes()


def test_layout_and_key_order(tmp_path):
    path = tmp_path / "cracks.json"
    write_sidecar(tiny_network(), path)
    data = json.loads(path.read_text())
    assert list(data) == [
        "format",
        "version",
        "units",
        "mesh",
        "params",
        "impacts",
        "cracks",
        "stats",
    ]
    assert data["format"] == "crackbake-cracks" and data["version"] == 1
    assert data["units"] == "mesh"
    assert list(data["mesh"]) == ["source", "vertices", "faces", "bbox_min", "bbox_max"]
    assert list(data["cracks"][0]) == ["id", "points", "faces", "time", "width", "depth"]
    assert data["stats"]["points"] == 5
    text = path.read_text()
    # Per-point arrays stay on one line each; no timings or dates anywhere.
    assert '"points": [[0.2, 0.1, 0.0], [0.5, 0.1, 0.0], [0.9, 0.4, 0.0]]' in text
    assert "time_s" not in text and "date" not in text and text.endswith("}\n")


def test_determinism_two_writes(tmp_path):
    write_sidecar(random_network(5), tmp_path / "a.json")
    write_sidecar(random_network(5), tmp_path / "b.json")
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
    write_sidecar(random_network(6), tmp_path / "c.json")
    assert (tmp_path / "a.json").read_bytes() != (tmp_path / "c.json").read_bytes()


def test_numpy_params_are_written_as_plain_json(tmp_path):
    net = tiny_network()
    net.params = {"seed": np.int64(4), "size": np.array([2.0, 3.0]), "on": np.bool_(True)}
    write_sidecar(net, tmp_path / "c.json")
    assert read_sidecar(tmp_path / "c.json").params == {"seed": 4, "size": [2.0, 3.0], "on": True}


def test_write_refuses_params_nested_past_the_stack(tmp_path):
    """Params nested 900 deep (a library user's, or a sidecar's read back) made the writer
    recurse past Python's limit; now a one-line error and no file."""
    net = tiny_network()
    deep: object = 1
    for _ in range(900):
        deep = [deep]
    net.params = {"x": deep}
    with pytest.raises(CrackbakeError, match="nest"):
        write_sidecar(net, tmp_path / "c.json")
    assert not (tmp_path / "c.json").exists()


def test_a_number_of_5000_digits_is_one_line(tmp_path):
    path = tmp_path / "digits.json"
    path.write_text(json.dumps(valid()).replace('"id": 7', '"id": ' + "9" * 5000))
    with pytest.raises(CrackbakeError, match="holds a number JSON cannot hold here"):
        read_sidecar(path)


def test_decoding_a_deeply_nested_file_is_one_line(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text('{"format": "crackbake-cracks", "version": 1, "cracks": '
                    + "[" * 200_000 + "]" * 200_000 + "}")
    with pytest.raises(CrackbakeError, match="nests lists or objects thousands deep"):
        read_sidecar(path)


def test_largest_allowed_id_and_width_reach_the_maps_exactly(tmp_path):
    """The limits are what the EXR channels hold: id 2**24 - 1 in float32 crack.id, a width
    past half's 65504 in float32 crack.width."""
    from crackbake.exchange.layers import CRACK_LAYERS

    assert not CRACK_LAYERS["id"].half and not CRACK_LAYERS["width"].half
    assert float(np.float32(2**24 - 1)) == 2**24 - 1 and float(np.float32(2**24 + 1)) != 2**24 + 1
    data = valid()
    data["cracks"][0]["id"] = 2**24 - 1
    data["cracks"][0]["width"] = [1e5, 1e5, 1e5]
    net = from_dict(data)
    assert net.cracks[0].id == 2**24 - 1 and float(np.float32(net.cracks[0].width[0])) == 1e5


def test_write_refuses_unreadable_network(tmp_path):
    net = tiny_network()
    net.cracks[0].width[1] = np.nan
    with pytest.raises(CrackbakeError, match="crack 7 has NaN or infinite width"):
        write_sidecar(net, tmp_path / "c.json")
    assert not (tmp_path / "c.json").exists()


# --- validation -----------------------------------------------------------------------------


def valid() -> dict:
    return copy.deepcopy(to_dict(tiny_network()))


def _set(path: list, value):
    def mutate(d: dict) -> None:
        target = d
        for key in path[:-1]:
            target = target[key]
        if value is DELETE:
            del target[path[-1]]
        else:
            target[path[-1]] = value

    return mutate


DELETE = object()

INVALID = [
    ("not object", lambda d: None, "top level is a JSON list, not an object"),
    ("format", _set(["format"], "something"), 'not "crackbake-cracks"'),
    ("version", _set(["version"], 2), 'unsupported "version" 2'),
    ("version bool", _set(["version"], True), 'unsupported "version" True'),
    ("no cracks", _set(["cracks"], DELETE), "missing 'cracks'"),
    ("no mesh", _set(["mesh"], DELETE), "missing 'mesh'"),
    ("mesh keys", _set(["mesh", "faces"], DELETE), "\"mesh\" is missing 'faces'"),
    ("crack keys", _set(["cracks", 1, "width"], DELETE), "cracks\\[1\\] is missing 'width'"),
    ("one point", _set(["cracks", 1, "points"], [[0.1, 0.5, 0.0]]), "crack 2 has 1 point; "),
    (
        "ragged faces",
        _set(["cracks", 0, "faces"], [0, 0]),
        "crack 7 has 3 points but 2 faces; every per-point array must have one entry per point",
    ),
    ("ragged time", _set(["cracks", 0, "time"], [0, 0.5, 0.7, 1]), "3 points but 4 time"),
    ("ragged width", _set(["cracks", 1, "width"], [0.1]), "crack 2 has 2 points but 1 width"),
    ("ragged depth", _set(["cracks", 1, "depth"], []), "crack 2 has 2 points but 0 depth"),
    (
        "points 2d",
        _set(["cracks", 1, "points"], [[0, 0], [1, 1]]),
        "points of shape \\(2, 2\\); points must be a list of \\[x, y, z\\]",
    ),
    (
        "points ragged",
        _set(["cracks", 1, "points"], [[0, 0, 0], [1, 1]]),
        "crack 2 'points' is not an array of numbers",
    ),
    (
        "points text",
        _set(["cracks", 1, "points"], [["a", 0, 0], [1, 1, 0]]),
        "'points' is not an array of numbers",
    ),
    ("nan point", _set(["cracks", 0, "points", 1, 2], float("nan")), "NaN or infinite points"),
    ("inf width", _set(["cracks", 0, "width", 0], float("inf")), "NaN or infinite width"),
    ("nan time", _set(["cracks", 0, "time", 0], float("nan")), "NaN or infinite time"),
    ("negative width", _set(["cracks", 0, "width", 2], -0.5), "crack 7 has negative width"),
    ("negative depth", _set(["cracks", 1, "depth", 0], -1e-9), "crack 2 has negative depth"),
    ("time > 1", _set(["cracks", 0, "time", 2], 1.5), "time outside \\[0, 1\\]"),
    ("time < 0", _set(["cracks", 1, "time", 0], -0.1), "time outside \\[0, 1\\]"),
    ("float face", _set(["cracks", 0, "faces", 0], 0.5), "'faces' is not an array of integers"),
    # JSON true/false are Python bools, an int subclass: never a face index or a coordinate.
    ("true face", _set(["cracks", 0, "faces", 0], True), "'faces' is not an array of integers"),
    ("false face", _set(["cracks", 1, "faces", 1], False), "'faces' is not an array of integers"),
    ("bool point", _set(["cracks", 0, "points", 1, 0], True), "'points' is not an array of"),
    ("bool width", _set(["cracks", 0, "width", 0], False), "'width' is not an array of numbers"),
    ("negative width plain", _set(["cracks", 0, "width", 2], -5.0), r"negative width \(-5\);"),
    ("time range plain", _set(["cracks", 0, "time", 2], 1.5), r"\(range 0\.\.1\.5\)"),
    ("dup id", _set(["cracks", 1, "id"], 7), "crack id 7 is used twice"),
    ("id text", _set(["cracks", 1, "id"], "two"), "has id 'two'; crack ids must be integers"),
    (
        "face range",
        _set(["cracks", 1, "faces", 1], 2),
        "crack 2 has face index 2 but the mesh has 2 faces",
    ),
    ("negative face", _set(["cracks", 0, "faces", 0], -1), "crack 7 has face index -1"),
    ("units", _set(["units"], "cm"), "\"units\" is 'cm'"),
    ("cracks type", _set(["cracks"], {"id": 0}), '"cracks" is not a list'),
    ("crack type", _set(["cracks", 0], [1, 2]), "cracks\\[0\\] is not an object"),
    # Issue 19: values JSON holds but the bake cannot (the CLI's ranges, crack.id's float32).
    ("id -1", _set(["cracks", 0, "id"], -1), r"has id -1; crack ids must lie in 0\.\.16777215"),
    ("id 2**24", _set(["cracks", 0, "id"], 2**24), "has id 16777216; crack ids must lie in"),
    ("id 2**70", _set(["cracks", 0, "id"], 2**70), "has id 1180591620717411303424; crack ids"),
    ("id 10**400", _set(["cracks", 0, "id"], 10**400), r"has id 2\*\*1328 or more; crack ids"),
    ("width 1e308", _set(["cracks", 0, "width", 0], 1e308), "width 1e\\+308; width must be at"),
    ("depth 1e16", _set(["cracks", 1, "depth", 0], 1e16), "depth 1e\\+16; depth must be at"),
    ("point 1e300", _set(["cracks", 0, "points", 0, 1], 1e300), "point coordinate of 1e\\+300"),
    ("params width", _set(["params"], {"crack_width": 0}),
     '"params"."crack_width" is 0; it must be a number above 0 up to 1e\\+15 mesh units'),
    ("params steps huge", _set(["params"], {"max_steps": 10**400}),
     r'"params"."max_steps" is 2\*\*1328 or more; it must be a number from 1'),
    ("params noise text", _set(["params"], {"noise": "loud"}), '"params"."noise" is \'loud\''),
    ("params seed", _set(["params"], {"seed": -3}),
     '"params"."seed" is -3; it must be a non-negative'),
    ("params impact", _set(["params"], {"impacts": [{"point": [0, 0, 1e300]}]}),
     '"params"."impacts"\\[0\\]."point" is \\[0, 0, 1e\\+300\\]'),
    ("impact radius", _set(["impacts"], [{"point": [0, 0, 0], "radius": -1, "strength": 1}]),
     '"impacts"\\[0\\]."radius" is -1'),
    ("impact point", _set(["impacts"], [{"point": [0, 0], "strength": 1}]),
     '"impacts"\\[0\\]."point" is \\[0, 0\\]; it must be \\[x, y, z\\]'),
    ("nested params", _set(["params"], {"x": json.loads("[" * 40 + "1" + "]" * 40)}),
     "nests lists or objects more than 32 deep"),
]


@pytest.mark.parametrize("name, mutate, message", INVALID, ids=[c[0] for c in INVALID])
def test_validation_errors(name, mutate, message):
    data = valid()
    if name == "not object":
        data = [data]
    else:
        mutate(data)
    with pytest.raises(CrackbakeError, match=message) as info:
        from_dict(data, source="cracks.json")
    text = str(info.value)
    assert text.startswith("cracks.json: ") and "\n" not in text and ";" in text
    assert "np." not in text  # numbers as the user wrote them, never numpy reprs


def test_not_json(tmp_path):
    path = tmp_path / "cracks.json"
    path.write_text('{"format": "crackbake-cracks", ')
    with pytest.raises(CrackbakeError, match="cracks.json: is not valid JSON"):
        read_sidecar(path)
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(CrackbakeError, match="not UTF-8 text"):
        read_sidecar(path)
    with pytest.raises(CrackbakeError, match="file not found"):
        read_sidecar(tmp_path / "missing.json")


def test_read_file_not_object(tmp_path):
    path = tmp_path / "cracks.json"
    path.write_text("[1, 2, 3]\n")
    with pytest.raises(CrackbakeError, match="not an object"):
        read_sidecar(path)


def test_face_range_checked_against_given_mesh(tmp_path):
    path = tmp_path / "cracks.json"
    write_sidecar(tiny_network(), path)
    data = json.loads(path.read_text())
    data["cracks"][0]["faces"][0] = 5
    with pytest.raises(CrackbakeError, match="crack 7 has face index 5"):
        from_dict(data, mesh=unit_square())


# --- mesh checks ----------------------------------------------------------------------------


def test_matching_mesh_reads_without_warning(tmp_path):
    path = tmp_path / "cracks.json"
    write_sidecar(tiny_network(), path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        net = read_sidecar(path, unit_square())
    assert len(net.cracks) == 2


def test_mesh_count_mismatch(tmp_path):
    path = tmp_path / "cracks.json"
    write_sidecar(tiny_network(), path)
    sq = unit_square()
    bigger = Mesh(
        vertices=np.vstack([sq.vertices, [[0.5, 0.5, 0.0]]]),
        faces=sq.faces,
        uv=None,
        normals=np.tile([0.0, 0.0, 1.0], (5, 1)),
        source="other.obj",
    )
    with pytest.raises(
        CrackbakeError,
        match="was made for a mesh with 4 vertices and 2 faces but other.obj has 5 vertices and "
        "2 faces; bake it on the mesh it was made for",
    ):
        read_sidecar(path, bigger)


def test_mesh_bbox_mismatch(tmp_path):
    path = tmp_path / "cracks.json"
    write_sidecar(tiny_network(), path)
    sq = unit_square()
    scaled = Mesh(
        vertices=sq.vertices * 1.01,
        faces=sq.faces,
        uv=None,
        normals=sq.normals,
        source="scaled.obj",
    )
    with pytest.raises(CrackbakeError, match="bounding box .* scaled.obj spans .*bake it on"):
        read_sidecar(path, scaled)
    # Far below the 1e-6 x diagonal tolerance: accepted.
    nudged = Mesh(
        vertices=sq.vertices * (1 + 1e-9),
        faces=sq.faces,
        uv=None,
        normals=sq.normals,
        source="nudged.obj",
    )
    assert len(read_sidecar(path, nudged).cracks) == 2


def test_points_off_face_plane_warn(tmp_path):
    net = tiny_network()
    net.cracks[1].points[1, 2] = 0.01  # 1e-2 off the plane; the tolerance is 1e-3 x sqrt(2)
    path = tmp_path / "cracks.json"
    write_sidecar(net, path)
    with pytest.warns(CrackbakeWarning, match="1 crack points \\(cracks 2\\) lie up to 0.01"):
        back = read_sidecar(path, unit_square())
    assert back.cracks[1].points[1, 2] == 0.01
    # Without a mesh there is nothing to compare against, so no warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_sidecar(path)


# --- demo script ----------------------------------------------------------------------------


def test_demo_script_on_spot(tmp_path):
    out = tmp_path / "demo.json"
    script = REPO / "examples" / "make_demo_cracks.py"
    for target in (out, tmp_path / "again.json"):
        subprocess.run(
            [sys.executable, str(script), "examples/spot.obj", "-o", str(target), "--seed", "1"],
            cwd=REPO,
            check=True,
            capture_output=True,
            timeout=120,
        )
    assert out.read_bytes() == (tmp_path / "again.json").read_bytes()
    mesh = load_mesh(REPO / "examples" / "spot.obj")
    with warnings.catch_warnings():
        warnings.simplefilter("error", CrackbakeWarning)
        net = read_sidecar(out, mesh)
    assert len(net.cracks) >= 5
    from trimesh.triangles import closest_point

    points = np.concatenate([c.points for c in net.cracks])
    faces = np.concatenate([c.faces for c in net.cracks])
    dist = np.linalg.norm(closest_point(mesh.vertices[mesh.faces[faces]], points) - points, axis=1)
    assert dist.max() < 1e-6 * mesh.diagonal
    for c in net.cracks:
        assert c.width.max() <= 0.004 + 1e-12 and np.isclose(c.width.min(), 0.0)
        np.testing.assert_array_equal(c.depth, 0.5 * c.width)
        assert (np.diff(c.time) >= 0).all()
