"""EXR layouts (crackbake.exchange.layers) read back by OpenImageIO and by Blender itself.

Every layout is written with write_exr and re-read by two independent readers: OpenImageIO
(channel names, per-channel pixel types, no camera-depth or alpha channel picked, values
bit-exact) and, when ``bpy`` is available, Blender 5.0's multilayer reader (each layer a pass of
the right type; each pass written back out of the compositor with the values bit-exact).
"""

from __future__ import annotations

import json

import numpy as np
import OpenImageIO as oiio
import pytest

from crackbake.errors import CrackbakeError
from crackbake.exchange.exr import read_exr, write_exr
from crackbake.exchange.layers import (
    CRACK_LAYERS,
    STRESS_COMPONENTS,
    STRESS_FIELDS,
    crack_attributes,
    crack_planes,
    stress_attributes,
    stress_layers,
    stress_planes,
)
from tests.blender_runner import run_blender

H, W = 6, 10  # not square, so a transposed plane cannot pass


def crack_roles(seed: int = 3) -> dict[str, np.ndarray]:
    """One plane per crack role, every texel distinct, in the types the bake produces."""
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(H, W, 3)).astype(np.float32)
    n[..., 2] = np.abs(n[..., 2]) + 0.1
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    return {
        "mask": rng.uniform(0, 1, (H, W)).astype(np.float16),
        "width": rng.uniform(0, 0.01, (H, W)).astype(np.float16),
        "time": rng.uniform(0, 1, (H, W)).astype(np.float16),
        "depth": rng.uniform(0, 0.003, (H, W)).astype(np.float32),
        "distance": rng.uniform(0, 0.05, (H, W)).astype(np.float32),
        # Large ids: a half channel would round 70001 to 69984.
        "id": rng.integers(-1, 70_000, (H, W)).astype(np.float32),
        "normal": n,
        "occlusion": rng.uniform(0.2, 1, (H, W)).astype(np.float16),
    }


def stress_fields(seed: int = 4) -> dict[str, dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    out = {}
    for field in STRESS_FIELDS:
        # Beyond half's 65504: stress in Pa must survive.
        xx, yy, xy = (rng.normal(0, 1e6, (H, W)).astype(np.float32) for _ in range(3))
        mean, rad = (xx + yy) / 2, np.hypot((xx - yy) / 2, xy)
        theta = 0.5 * np.arctan2(2 * xy, xx - yy)
        out[field] = {
            "xx": xx, "yy": yy, "xy": xy, "p1": mean + rad, "p2": mean - rad,
            "dir": np.stack([np.cos(theta), np.sin(theta)], axis=2).astype(np.float32),
            "sep": np.abs(rng.normal(0, 2, (H, W))).astype(np.float32),
        }  # fmt: skip
    return out


def _oiio_read(path):
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    formats = [str(spec.channelformat(i)) for i in range(spec.nchannels)]
    return spec, pixels, formats


def _expected(layers, roles, float32=False):
    """Channel -> (pixel type, plane) derived from the layer table, independently of the code."""
    out = {}
    for role, layer in layers.items():
        arr = np.asarray(roles[role])
        planes = [arr] if arr.ndim == 2 else [arr[..., i] for i in range(arr.shape[2])]
        kind = "half" if layer.half and not float32 else "float"
        for name, plane in zip(layer.names, planes, strict=True):
            out[name] = (kind, plane.astype(np.float16 if kind == "half" else np.float32))
    return out


def test_layouts_follow_the_reader_rules():
    """Names Blender/Nuke/OIIO type: 3 parts, <= 4 channels, no Z/depth/alpha, unique."""
    layouts = list(CRACK_LAYERS.values()) + list(stress_layers().values())
    names = [n for layer in layouts for n in layer.names]
    assert len(names) == len(set(names))
    for layer in layouts:
        assert 1 <= len(layer.channels) <= 4
        part, pass_ = layer.layer.split(".")
        # Nuke's layer is part_pass; its reserved layers must not be hit.
        assert f"{part}_{pass_}" not in {"rgba", "depth", "mask", "forward", "backward"}
        for name in layer.names:
            last = name.rsplit(".", 1)[1].lower()
            assert name.count(".") == 2
            assert last not in {"z", "depth", "a", "alpha"}
            if layer.kind == "vector":
                # Blender: a two-letter name takes its id from the second letter.
                assert last[-1].upper() in "XYZ"
    assert CRACK_LAYERS["normal"].names == ("crack.normal.NX", "crack.normal.NY", "crack.normal.NZ")


@pytest.mark.parametrize("float32", [False, True])
def test_crack_layout_through_openimageio(tmp_path, float32):
    roles = crack_roles()
    planes = crack_planes(roles, float32=float32)
    attrs = crack_attributes("0.0-test", 0.05, 1.0, channels=planes)
    path = tmp_path / "a_cracks.exr"
    write_exr(path, planes, attributes=attrs)

    spec, pixels, formats = _oiio_read(path)
    want = _expected(CRACK_LAYERS, roles, float32)
    names = list(spec.channelnames)
    assert sorted(names) == sorted(want)
    assert spec.z_channel == -1 and spec.alpha_channel == -1
    for i, name in enumerate(names):
        kind, plane = want[name]
        assert formats[i] == kind, name
        np.testing.assert_array_equal(pixels[..., i], plane.astype(np.float32), err_msg=name)
    table = json.loads(spec.getattribute("crackbake:channels"))
    assert table["crack.width.V"]["units"] == "mesh units"
    assert table["crack.normal.NY"]["role"] == "normal"
    assert spec.getattribute("crackbake:layout") == 1


def test_crack_planes_keep_types_and_skip_missing_roles():
    roles = crack_roles()
    roles["normal"] = None
    del roles["occlusion"]
    planes = crack_planes(roles)
    assert "crack.normal.NX" not in planes and "crack.occlusion.V" not in planes
    assert planes["crack.mask.V"] is roles["mask"]  # already half: no copy
    assert planes["crack.id.V"].dtype == np.float32
    with pytest.raises(CrackbakeError, match="unknown EXR map role"):
        crack_planes({"colour": roles["mask"]})
    with pytest.raises(CrackbakeError, match=r"\(H, W, 3\)"):
        crack_planes({"normal": roles["mask"]})


def test_stress_layout_through_openimageio(tmp_path):
    fields = stress_fields()
    planes = stress_planes(fields)
    path = tmp_path / "a_stress.exr"
    write_exr(path, planes, attributes=stress_attributes("0.0-test", units="Pa"))
    spec, pixels, formats = _oiio_read(path)
    roles = {f"{f}.{c}": fields[f][c] for f in STRESS_FIELDS for c in STRESS_COMPONENTS}
    want = _expected(stress_layers(), roles)
    assert sorted(spec.channelnames) == sorted(want)
    assert len(want) == 2 * 8
    assert spec.z_channel == -1 and spec.alpha_channel == -1
    assert set(formats) == {"float"}
    for i, name in enumerate(spec.channelnames):
        np.testing.assert_array_equal(pixels[..., i], want[name][1], err_msg=name)
    assert np.abs(pixels).max() > 65504  # really beyond half
    assert spec.getattribute("crackbake:stressUnits") == "Pa"
    assert "xx, yy, xy" in spec.getattribute("crackbake:componentOrder")


def test_stress_planes_refuse_missing_components():
    fields = stress_fields()
    del fields["stress"]["sep"]
    with pytest.raises(CrackbakeError, match="no 'sep' plane"):
        stress_planes(fields)
    with pytest.raises(CrackbakeError, match="unknown stress field"):
        stress_planes({"stress1": fields["stress0"]})


def _blender_passes(src, out_dir) -> dict:
    out_dir.mkdir()
    return run_blender("exr_passes.py", str(src), str(out_dir))


def _check_blender_pass(info, layer, want):
    """A pass Blender wrote back: its channels, in component order, equal the planes written."""
    chans, _ = read_exr(info["file"])
    got = [chans[k] for k in sorted(chans)]  # Blender writes V, or X, Y, Z
    assert info["type"] == ("VALUE" if layer.kind == "value" else "VECTOR"), layer.role
    planes = [want[n][1].astype(np.float32) for n in layer.names]
    if layer.kind == "vector":
        assert len(got) == 3  # Blender's vector passes are 3-D; a 2-D one gets Z = 0
        np.testing.assert_array_equal(got[len(planes) :], 0)
    for g, p in zip(got, planes, strict=False):
        assert g.shape == p.shape
        np.testing.assert_array_equal(g, p, err_msg=layer.role)


@pytest.mark.reference
def test_crack_layout_through_blender(tmp_path):
    roles = crack_roles()
    path = tmp_path / "a_cracks.exr"
    write_exr(path, crack_planes(roles))
    got = _blender_passes(path, tmp_path / "blender")
    assert got["image_type"] == "MULTILAYER"
    assert got["layers"] == ["crack"]
    passes = {p["pass"]: p for p in got["passes"]}
    assert sorted(passes) == sorted(CRACK_LAYERS)
    want = _expected(CRACK_LAYERS, roles)
    for role, layer in CRACK_LAYERS.items():
        _check_blender_pass(passes[role], layer, want)


@pytest.mark.reference
def test_stress_layout_through_blender(tmp_path):
    fields = stress_fields()
    path = tmp_path / "a_stress.exr"
    write_exr(path, stress_planes(fields))
    got = _blender_passes(path, tmp_path / "blender")
    assert sorted(got["layers"]) == sorted(STRESS_FIELDS)
    roles = {f"{f}.{c}": fields[f][c] for f in STRESS_FIELDS for c in STRESS_COMPONENTS}
    want = _expected(stress_layers(), roles)
    layers = stress_layers()
    assert len(got["passes"]) == len(layers)
    for info in got["passes"]:
        _check_blender_pass(info, layers[f"{info['layer']}.{info['pass']}"], want)


@pytest.mark.reference
def test_old_layout_is_invisible_to_blender(tmp_path):
    """Why the layout changed: two-part names give Blender's compositor no layer at all."""
    path = tmp_path / "old.exr"
    plane = np.ones((H, W), np.float32)
    write_exr(path, {f"crack.{k}": plane for k in ("mask", "width", "depth")})
    got = _blender_passes(path, tmp_path / "blender")
    assert got["layers"] == [] and got["passes"] == []


@pytest.fixture(scope="module")
def run_exrs(tmp_path_factory):
    """Both EXRs of a real run (solve, bake with tangents, stress bake) on a small plate,
    PIZ-compressed (the values must still come back bit-exact)."""
    from crackbake.params import Impact, RunParams
    from crackbake.pipeline import run
    from crackbake.precompile import plate_obj

    folder = tmp_path_factory.mktemp("run")
    mesh = folder / "plate.obj"
    plate_obj(mesh)
    out = folder / "out"
    run(RunParams(mesh=mesh, preset="glass", impacts=(Impact((0.5, 0.5, 0.0), 0.3),),
                  res=96, stress_res=64, sim_faces=3000, formats=("exr", "stress"), out=out,
                  exr_compression="piz"))
    return {"crack": out / "plate_cracks.exr", "stress": out / "plate_stress.exr",
            "manifest": out / "manifest.json"}


def _layout_of(kind):
    return CRACK_LAYERS if kind == "crack" else stress_layers()


@pytest.mark.parametrize("kind", ["crack", "stress"])
def test_every_exr_a_run_writes_through_openimageio(run_exrs, kind):
    spec, pixels, formats = _oiio_read(run_exrs[kind])
    chans, _ = read_exr(run_exrs[kind])
    layers = _layout_of(kind)
    want = {n: ("half" if layer.half else "float") for layer in layers.values()
            for n in layer.names}
    names = list(spec.channelnames)
    assert sorted(names) == sorted(want)  # every layer of the layout, normal included
    assert spec.z_channel == -1 and spec.alpha_channel == -1
    for i, name in enumerate(names):
        assert formats[i] == want[name], name
        np.testing.assert_array_equal(pixels[..., i], chans[name].astype(np.float32), name)
    assert np.isfinite(pixels).all()


@pytest.mark.reference
@pytest.mark.parametrize("kind", ["crack", "stress"])
def test_every_exr_a_run_writes_through_blender(run_exrs, kind, tmp_path):
    chans, _ = read_exr(run_exrs[kind])
    want = {name: (None, plane) for name, plane in chans.items()}
    got = _blender_passes(run_exrs[kind], tmp_path / "blender")
    assert got["image_type"] == "MULTILAYER"
    layers = _layout_of(kind)
    assert len(got["passes"]) == len(layers)
    for info in got["passes"]:
        key = info["pass"] if kind == "crack" else f"{info['layer']}.{info['pass']}"
        _check_blender_pass(info, layers[key], want)


@pytest.mark.parametrize("kind", ["crack", "stress"])
def test_run_exrs_name_crackbake_and_the_run(run_exrs, kind):
    """--exr-compression reaches both files; the standard owner and comments attributes (what
    OpenImageIO calls Copyright and ImageDescription) name crackbake, the run's options and the
    hash of the manifest's parameters; data-only files carry no chromaticities."""
    import hashlib

    from crackbake import __version__

    spec = oiio.ImageInput.open(str(run_exrs[kind])).spec()
    assert spec.getattribute("compression") == "piz"
    assert spec.getattribute("Copyright") == f"crackbake {__version__}"
    comments = spec.getattribute("ImageDescription")
    params = json.loads(run_exrs["manifest"].read_text())["params"]
    params.pop("out")
    params.pop("solver", None)
    digest = hashlib.sha256(json.dumps(params, sort_keys=True, separators=(",", ":")).encode())
    assert comments.startswith("crackbake plate.obj --preset glass --method iben --seed 0 --res 96")
    assert "--impact 0.5,0.5,0" in comments and f"sha256 {digest.hexdigest()[:16]}" in comments
    names = {a.name.lower() for a in spec.extra_attribs}
    assert not {n for n in names if "chromaticities" in n}
    _, header = read_exr(run_exrs[kind])
    assert "chromaticities" not in header and header["owner"] == f"crackbake {__version__}"


def test_exr_compression_is_lossless_only():
    from crackbake.params import RunParams

    assert RunParams(mesh="x.obj").exr_compression == "zip"  # the default before the option
    with pytest.raises(CrackbakeError, match=r"--exr-compression 'dwaa' is unknown or lossy"):
        RunParams(mesh="x.obj", exr_compression="dwaa").validate()
