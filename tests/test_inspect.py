"""``crackbake inspect``: run as a real process on real EXR files (ours, foreign, broken)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cli_forks
import numpy as np
import pytest
from PIL import Image

from crackbake.exchange.exr import write_exr
from crackbake.exchange.inspect import STROKE_SPACING, inspect_exr
from crackbake.exchange.layers import (
    crack_attributes,
    crack_planes,
    stress_attributes,
    stress_planes,
)

REPO = Path(__file__).resolve().parents[1]
H, W = 96, 160  # pictures of maps under 512 px are enlarged by an integer factor: 3 here


def cli(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return cli_forks.run(["inspect", *args], env=env, timeout=120)


def _uniform_field(p1: float, p2: float, angle: float) -> dict[str, np.ndarray]:
    """A constant tensor with principal values p1 >= p2 and p1 along ``angle`` (radians, T to B)."""
    c, s = np.cos(angle), np.sin(angle)
    xx, yy, xy = p1 * c * c + p2 * s * s, p1 * s * s + p2 * c * c, (p1 - p2) * c * s
    full = lambda v: np.full((H, W), v, np.float32)  # noqa: E731
    return {
        "xx": full(xx), "yy": full(yy), "xy": full(xy), "p1": full(p1), "p2": full(p2),
        "dir": np.dstack([full(c), full(s)]), "sep": full(max(p1, 0.0)),
    }  # fmt: skip


@pytest.fixture(scope="module")
def run_files(tmp_path_factory):
    """A crack master and a stress file beside it, as one run writes them."""
    d = tmp_path_factory.mktemp("run")
    mask = np.zeros((H, W), np.float16)
    mask[40:44, :] = 1  # a horizontal crack, rows 40..43
    rng = np.random.default_rng(2)
    width = np.where(mask > 0, rng.uniform(1e-3, 2e-3, (H, W)), 0).astype(np.float16)
    ids = np.where(mask > 0, 7, -1).astype(np.float32)
    roles = {"mask": mask, "width": width, "id": ids, "depth": width.astype(np.float32)}
    planes = crack_planes(roles)
    write_exr(d / "a_cracks.exr", planes, crack_attributes("t", 0.1, 1.0, channels=planes))
    fields = {
        "stress0": _uniform_field(3e5, -1e5, np.pi / 6),
        "stress": _uniform_field(-2e5, -4e5, 0),
    }
    write_exr(d / "a_stress.exr", stress_planes(fields), stress_attributes("t", units="Pa"))
    return d, roles, fields


def test_json_table_matches_the_pixels(run_files):
    d, roles, _ = run_files
    proc = cli(str(d / "a_cracks.exr"), "--json")
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout)
    assert (got["width"], got["height"], got["compression"]) == (W, H, "zip")
    rows = {c["name"]: c for c in got["channels"]}
    assert sorted(rows) == ["crack.depth.V", "crack.id.V", "crack.mask.V", "crack.width.V"]
    w = rows["crack.width.V"]
    ref = roles["width"].astype(np.float64)
    assert (w["layer"], w["channel"], w["type"], w["units"]) == (
        "crack.width",
        "V",
        "float",  # float32: mesh units are unbounded (half stops at 65504)
        "mesh units",
    )
    assert w["min"] == 0 and w["max"] == pytest.approx(ref.max(), rel=0, abs=0)
    assert w["mean"] == pytest.approx(ref.mean(), rel=1e-9)
    assert w["nonzero"] == pytest.approx(4 / H)
    ids = rows["crack.id.V"]
    assert (ids["min"], ids["max"], ids["type"], ids["role"]) == (-1, 7, "float", "id")
    assert rows["crack.mask.V"]["nonzero"] == pytest.approx(4 / H)
    assert got["attributes"]["crackbake:version"] == "t"


def test_text_table(run_files):
    d, _, _ = run_files
    proc = cli(str(d / "a_stress.exr"))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith(str(d / "a_stress.exr")) and "16 channels" in lines[0]
    assert lines[1].split() == [
        "layer",
        "channel",
        "type",
        "min",
        "max",
        "mean",
        "non-zero",
        "units",
    ]
    p1 = next(ln.split() for ln in lines if ln.startswith("stress0.p1 "))
    assert p1 == ["stress0.p1", "V", "float", "300000", "300000", "300000", "100.0%", "Pa"]


def _rgb(path: Path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB")).astype(np.int32)


def test_pictures_show_signs_directions_and_the_mask(run_files, tmp_path):
    d, _, _ = run_files
    out = tmp_path / "pics"
    proc = cli(str(d / "a_stress.exr"), "--png", str(out))
    assert proc.returncode == 0, proc.stderr
    names = sorted(p.name for p in out.iterdir() if p.name != "manifest.json")
    assert "stress0_p1_dir.png" in names and "stress_p2.png" in names and len(names) == 14
    scale = 3
    # Diverging map: tension red, compression blue (the final field is all compression).
    p1 = _rgb(out / "stress0_p1.png")
    assert p1.shape == (H * scale, W * scale, 3)
    r, g, b = p1[5, 5]
    assert r > b + 50
    r, g, b = _rgb(out / "stress_p1.png")[5, 5]
    assert b > r + 50
    # The crack mask from a_cracks.exr beside the file: rows 40..43 drawn black.
    assert np.all(p1[40 * scale : 44 * scale, :] == 0)
    assert not np.any(np.all(p1[: 40 * scale] == 0, axis=2)[:, ::7][::7])
    # Strokes along p1 at 30 degrees above the T axis: the stroke pixels around each grid
    # centre lie on that line (up in the image = +B = minus rows).
    strokes = _rgb(out / "stress0_p1_dir.png")
    assert np.all(strokes[strokes != p1] == 255)  # white ink on the deep red
    s = STROKE_SPACING
    cy, cx = s // 2, s // 2 + 2 * s
    box = np.s_[cy - s // 2 : cy + s // 2, cx - s // 2 : cx + s // 2]
    patch = np.any(strokes[box] != p1[box], axis=2)
    ys, xs = np.nonzero(patch)
    assert len(ys) >= s // 2
    dx, dy = xs - s // 2, -(ys - s // 2)
    # Distance of each stroke pixel from the line through the centre at 30 degrees.
    dist = np.abs(dx * np.sin(np.pi / 6) - dy * np.cos(np.pi / 6))
    assert dist.max() <= 1.0
    assert np.ptp(dx) >= 0.7 * 0.8 * s * np.cos(np.pi / 6)


def test_crack_pictures(run_files, tmp_path):
    d, _, _ = run_files
    out = tmp_path / "pics"
    assert cli(str(d / "a_cracks.exr"), "--png", str(out)).returncode == 0
    ids = _rgb(out / "crack_id.png")
    assert np.all(ids[5 * 3, 5 * 3] == 0)  # id -1: black
    assert ids[41 * 3, 5 * 3].min() >= 255 * 0.25 - 1  # id 7: a bright colour
    mask = _rgb(out / "crack_mask.png")
    assert mask[41 * 3, 10, 0] > mask[5, 10, 0]  # sequential: the crack is the bright end


def test_foreign_file_gets_the_table(tmp_path):
    path = tmp_path / "render.exr"
    ramp = np.linspace(-1, 1, H * W, dtype=np.float32).reshape(H, W)
    write_exr(
        path,
        {
            "R": ramp,
            "G": ramp * 0,
            "B": ramp.astype(np.float16),
            "objectId": np.arange(H * W, dtype=np.uint32).reshape(H, W),
        },
    )
    proc = cli(str(path), "--json", "--png", str(tmp_path / "pics"))
    assert proc.returncode == 0, proc.stderr
    rows = {c["name"]: c for c in json.loads(proc.stdout)["channels"]}
    assert rows["G"]["nonzero"] == 0 and rows["G"]["units"] is None
    assert (rows["R"]["min"], rows["R"]["max"], rows["B"]["type"]) == (-1, 1, "half")
    assert rows["objectId"]["type"] == "uint" and rows["objectId"]["max"] == H * W - 1
    assert len(list((tmp_path / "pics").glob("*.png"))) == 4


def test_nan_and_inf_are_counted_not_averaged(tmp_path):
    path = tmp_path / "nan.exr"
    v = np.ones((H, W), np.float32)
    v[0, :3] = [np.nan, np.inf, -np.inf]
    write_exr(path, {"data.v.V": v})
    info, _ = inspect_exr(path)
    (row,) = info.channels
    assert (row.min, row.max, row.mean, row.nonfinite) == (1, 1, 1, 3)


@pytest.mark.parametrize("case", ["finite", "nan", "inf", "-inf", "subnormal", "extremes"])
def test_half_planes_get_the_statistics_of_their_float32_values(tmp_path, case):
    """Half planes are described from their bit patterns (no float32 copy): min, max, mean,
    non-zero share and non-finite count must be those of the same values widened to float32
    and reduced by numpy, NaN and inf anywhere, -0 counted as zero, subnormals as numbers."""
    rng = np.random.default_rng(3)
    v = (rng.standard_normal((H, W)) * 100).astype(np.float16)
    v[rng.random((H, W)) < 0.5] = 0
    v[1, :4] = np.array([-0.0, -0.0, 0.0, -0.0], np.float16)
    bad = {"nan": np.nan, "inf": np.inf, "-inf": -np.inf}
    if case in bad:
        v[H // 2, W // 3] = bad[case]
        v[H - 1, W - 1] = bad[case]
    elif case == "subnormal":
        v = (rng.integers(-1023, 1024, (H, W)).astype(np.float16) * np.float16(6e-8))
    elif case == "extremes":
        v[2, :2] = [65504, -65504]
    path = tmp_path / "half.exr"
    write_exr(path, {"data.h.V": v})
    info, _ = inspect_exr(path)
    (row,) = info.channels
    wide = v.astype(np.float32)
    good = wide[np.isfinite(wide)]
    assert row.type == "half"
    assert (row.min, row.max) == (float(good.min()), float(good.max()))
    assert row.mean == float(good.mean(dtype=np.float64))
    assert row.nonfinite == wide.size - good.size
    assert row.nonzero == np.count_nonzero(wide) / wide.size


def test_half_extremes_from_the_bits_order_every_pattern():
    """min, max and non-zero count of half planes read from their bit patterns
    (:func:`~crackbake.exchange.exrstats.plane_stats`' kernel): against a sort of the widened
    finite values with -0 below +0, on planes drawn from the edge patterns (both zeros, the
    smallest subnormals, the largest finite, the infinities and NaNs) and from every finite
    pattern of each sign."""
    from crackbake.exchange.exrstats import plane_stats

    edges = np.array([0x0000, 0x8000, 0x0001, 0x8001, 0x03FF, 0x0400, 0x3C00, 0xBC00,
                      0x7BFF, 0xFBFF, 0x7C00, 0xFC00, 0x7C01, 0x7E00, 0xFE00, 0xFFFF],
                     np.uint16)  # fmt: skip
    every = np.arange(0x10000, dtype=np.uint32).astype(np.uint16)
    pools = [edges, every[:0x7C00], every[0x8000:0xFC00], every]
    rng = np.random.default_rng(11)
    checked = 0
    for trial in range(4000):
        plane = rng.choice(pools[trial % 4], (1, int(rng.integers(1, 7)))).view(np.float16)
        wide = plane.astype(np.float32).ravel()
        finite = wide[np.isfinite(wide)]
        got = plane_stats(plane)
        assert got["nonfinite"] == wide.size - finite.size
        assert got["nonzero"] == np.count_nonzero(wide) / wide.size
        if not finite.size:
            assert got["min"] is got["max"] is None, plane.view(np.uint16)
            continue
        order = sorted(finite.tolist(), key=lambda v: (v, not np.signbit(v)))
        lo, hi = got["min"], got["max"]
        assert (lo, np.signbit(lo)) == (order[0], np.signbit(order[0])), plane.view(np.uint16)
        assert (hi, np.signbit(hi)) == (order[-1], np.signbit(order[-1])), plane.view(np.uint16)
        checked += 1
    assert checked > 2500


@pytest.mark.parametrize("content", [b"", b"not an exr at all" * 10, b"v/1\x01" + b"\0" * 300])
def test_bad_files_give_one_line_and_exit_2(tmp_path, content):
    path = tmp_path / "broken.exr"
    path.write_bytes(content)
    proc = cli(str(path))
    assert proc.returncode == 2
    assert proc.stdout == ""
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: cannot read EXR"), proc.stderr


def _crack_master(path: Path) -> bytearray:
    """A crack master of ours (ZIP chunks of noisy half and float planes); its bytes."""
    rng = np.random.default_rng(5)
    planes = {f"crack.{k}.V": rng.random((256, 256)).astype(np.float16) for k in "abc"}
    planes["crack.id.V"] = rng.integers(0, 50, (256, 256)).astype(np.float32)
    write_exr(path, planes)
    return bytearray(path.read_bytes())


@pytest.mark.parametrize("damage", ["truncated", "chunk data"])
def test_damaged_crackbake_exr_gives_one_line_and_exit_2(tmp_path, damage):
    """A crack master cut short or with a damaged chunk: one error line naming the file,
    exit 2, nothing on stdout (no traceback, no table of half-read planes)."""
    path = tmp_path / "master.exr"
    data = _crack_master(path)
    if damage == "truncated":
        data = data[: len(data) // 2]
    else:
        middle = len(data) // 2
        data[middle : middle + 64] = bytes(64)
    path.write_bytes(bytes(data))
    proc = cli(str(path))
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: cannot read EXR '{path}'"), proc.stderr


def test_a_damaged_chunk_offset_is_rebuilt_not_trusted(tmp_path):
    """A chunk offset pointing past the end (the chunks themselves intact): OpenEXR finds
    the chunks by their own headers, so the table is the intact file's, to the byte."""
    path = tmp_path / "master.exr"
    data = _crack_master(path)
    intact = cli(str(path))
    assert intact.returncode == 0, intact.stderr
    last = _header_end(bytes(data)) + 8 * (256 // 16 - 1)  # the last of the 16 offsets
    data[last : last + 8] = (2**40).to_bytes(8, "little")
    path.write_bytes(bytes(data))
    proc = cli(str(path))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == intact.stdout


def _header_end(data: bytes) -> int:
    """The offset just past an EXR header's attributes (its terminating null byte)."""
    p = 8
    while data[p] != 0:
        name_end = data.index(b"\0", p)
        type_end = data.index(b"\0", name_end + 1)
        size = int.from_bytes(data[type_end + 1 : type_end + 5], "little")
        p = type_end + 5 + size
    return p + 1


def test_the_table_loads_no_numba_and_no_logging(run_files):
    """``crackbake inspect FILE`` (no pictures) imports neither numba (about 1 CPU-s of
    start-up before a cached kernel runs: ``benchmarks/bench_inspect.py``) nor
    ``concurrent.futures`` and the ``logging`` it pulls in: issue 25's 0.5 s floor."""
    d, _, _ = run_files
    code = (
        "import sys\n"
        "from crackbake.cli import main\n"
        "try:\n"
        "    main(['inspect', sys.argv[1]], prog_name='crackbake')\n"
        "except SystemExit as exc:\n"
        "    assert not exc.code, exc.code\n"
        "heavy = ('numba', 'concurrent.futures', 'logging')\n"
        "print(' '.join(h for h in heavy if h in sys.modules), file=sys.stderr)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-c", code, str(d / "a_cracks.exr")], env=env,
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "crack.mask" in r.stdout
    assert r.stderr.strip() == "", r.stderr


def test_missing_file_is_a_usage_error(tmp_path):
    proc = cli(str(tmp_path / "nope.exr"))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "does not exist" in proc.stderr


def test_text_table_says_what_the_fields_and_units_mean(run_files, tmp_path):
    from crackbake.bake.stress import STRESS_UNITS

    d, _, fields = run_files
    ours = tmp_path / "ours_stress.exr"
    write_exr(ours, stress_planes(fields), stress_attributes("t", units=STRESS_UNITS))
    proc = cli(str(ours))
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout
    assert "stress0 is the initial stress field (before any crack), stress the final one" in text
    # Each unit in the table is put in plain words once, under it.
    for units in (STRESS_UNITS, "x toughness", "unit vector"):
        assert any(ln.startswith(units.split(" (")[0] + ":") for ln in text.splitlines()), units
    assert "not pascals" in text and "1 or more cracks" in text
    # A crack master has none of those units: no notes.
    lines = cli(str(d / "a_cracks.exr")).stdout.splitlines()
    assert len(lines) == 2 + 4


def test_strokes_stay_off_the_gutters(run_files, tmp_path):
    _, _, fields = run_files
    # Texel columns from 78 on are gutter: crackbake writes no direction (0, 0) there.  The
    # stroke centred at picture column 232 (texel 77) would reach column 238 (texel 79).
    g = 78
    f = {k: v.copy() for k, v in fields["stress0"].items()}
    f["dir"][:, g:] = 0
    path = tmp_path / "g_stress.exr"
    write_exr(path, stress_planes({"stress0": f, "stress": fields["stress"]}),
              stress_attributes("t", units="Pa"))  # fmt: skip
    out = tmp_path / "pics"
    assert cli(str(path), "--png", str(out)).returncode == 0
    strokes, base = _rgb(out / "stress0_p1_dir.png"), _rgb(out / "stress0_p1.png")
    ink = np.any(strokes != base, axis=2)
    scale = 3
    assert ink[:, : g * scale].sum() > 100  # strokes on the island
    assert ink[:, 232 - 8 : g * scale].any()  # the last column of strokes, cut at the edge
    assert not ink[:, g * scale :].any()  # none on the gutter, not even stroke ends
