"""crackbake.exchange.exrstats: the statistics crackbake records in its EXR headers, and
``crackbake inspect`` trusting them only for the file as written.

Every check compares the record's route (header only) with the pixels' route (the OpenEXR
bindings' planes, numpy's statistics) on the same file, and files changed behind the record's
back (a chunk re-deflated from other pixels, a re-save by OpenImageIO) with statistics taken
here from the pixels the file really holds.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import cli_forks
import numpy as np
import OpenImageIO as oiio
import pytest

from crackbake.exchange.exr import read_exr, write_exr
from crackbake.exchange.exrstats import (
    STATS_ATTRIBUTE,
    STATS_VERSION,
    parse_header,
    plane_stats,
    recorded_stats,
)
from crackbake.exchange.exrzip import write_scanline
from crackbake.exchange.inspect import format_table, inspect_exr
from crackbake.exchange.layers import (
    crack_attributes,
    crack_planes,
    stress_attributes,
    stress_planes,
)

REPO = Path(__file__).resolve().parents[1]
H, W = 70, 90  # 5 ZIP chunks, the last one short


def _masters(d):
    """A crack master (half and float planes, NaN-free) and a stress file, as a run writes
    them; with a NaN and an inf in one plane of a third file."""
    rng = np.random.default_rng(4)
    mask = np.zeros((H, W), np.float16)
    mask[30:34, 5:80] = rng.uniform(0.2, 1, (4, 75))
    width = np.where(mask > 0, rng.uniform(1e-3, 2e-3, (H, W)), 0).astype(np.float32)
    normal = rng.uniform(-1, 1, (H, W, 3)).astype(np.float32)
    ids = np.where(mask > 0, 3, -1).astype(np.float32)
    roles = {"mask": mask, "width": width, "id": ids, "depth": -width, "normal": normal}
    planes = crack_planes(roles)
    write_exr(d / "a_cracks.exr", planes, crack_attributes("t", 0.1, 1.0, channels=planes))
    full = lambda v: np.full((H, W), v, np.float32)  # noqa: E731
    field = {"xx": rng.standard_normal((H, W)).astype(np.float32), "yy": full(-1.0),
             "xy": full(0.0), "p1": full(2.0), "p2": full(-1.0),
             "dir": np.dstack([full(1.0), full(0.0)]), "sep": full(2.0)}  # fmt: skip
    write_exr(d / "a_stress.exr", stress_planes({"stress0": field, "stress": field}),
              stress_attributes("t", units="Pa"))  # fmt: skip
    odd = rng.standard_normal((H, W)).astype(np.float32)
    odd[3, :3] = [np.nan, np.inf, -0.0]
    write_exr(d / "odd.exr", {"data.v.V": odd, "data.h.V": odd.astype(np.float16)},
              compression="zips")  # fmt: skip
    return planes


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("masters")
    planes = _masters(d)
    return d, planes


def _slow(path):
    info, channels = inspect_exr(path, pixels=True)
    assert channels is not None
    return info


@pytest.mark.parametrize("name", ["a_cracks.exr", "a_stress.exr", "odd.exr"])
def test_the_record_gives_the_pixels_statistics_to_the_bit(files, name):
    """Header only (no pixels read) and from the pixels: the same table and JSON, byte for
    byte; each record the statistics of the planes read back."""
    d, _ = files
    path = d / name
    assert recorded_stats(path) is not None
    fast, channels = inspect_exr(path, pixels=False)
    assert channels is None  # the pixels were not read
    slow = _slow(path)
    assert fast.to_json() == slow.to_json()
    assert format_table(fast) == format_table(slow)
    planes, _ = read_exr(path)
    assert recorded_stats(path) == {n: plane_stats(p) for n, p in planes.items()}


def test_the_command_prints_the_same_with_and_without_pictures(files, tmp_path):
    """``--png`` reads the pixels (the pictures need them): its JSON is the record's."""
    d, _ = files
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    fast = cli_forks.run(["inspect", str(d / "a_cracks.exr"), "--json"], env=env, timeout=120)
    slow = cli_forks.run(["inspect", str(d / "a_cracks.exr"), "--json", "--png",
                          str(tmp_path / "pics")], env=env, timeout=120)  # fmt: skip
    assert fast.returncode == slow.returncode == 0, fast.stderr + slow.stderr
    assert fast.stdout == slow.stdout


def _split(blob: bytes) -> tuple[bytes, list[bytes]]:
    """A ZIP scanline file's header and its chunks (y, size, data each), in file order."""
    _, end = parse_header(blob)
    count = -(-H // 16)
    table = np.frombuffer(blob, "<u8", count, end).astype(np.int64)
    chunks = []
    for off in table:
        (size,) = struct.unpack_from("<i", blob, int(off) + 4)
        chunks.append(blob[int(off) : int(off) + 8 + size])
    return blob[:end], chunks


def _join(head: bytes, chunks: list[bytes]) -> bytes:
    sizes = np.cumsum([0] + [len(c) for c in chunks[:-1]])
    table = (len(head) + 8 * len(chunks) + sizes).astype("<u8").tobytes()
    return head + table + b"".join(chunks)


def test_a_chunk_of_other_pixels_behind_the_record_is_read(tmp_path):
    """One chunk replaced by a valid deflate of other pixels (the file still reads): the
    record no longer matches, and the table gives the statistics of the pixels the file
    holds, computed here with numpy, not the record's."""
    rng = np.random.default_rng(8)
    mask = np.zeros((H, W), np.float16)
    mask[2:6, :] = 0.5
    dist = rng.uniform(0, 0.05, (H, W)).astype(np.float32)
    write_exr(tmp_path / "a.exr", {"crack.mask.V": mask, "crack.distance.V": dist})
    edited_mask, edited_dist = mask.copy(), dist.copy()
    edited_mask[20:24, 10:20] = 1  # rows of the second chunk (16..31)
    edited_dist[17, 3] = 9.0
    write_exr(tmp_path / "b.exr", {"crack.mask.V": edited_mask, "crack.distance.V": edited_dist})
    head, chunks = _split((tmp_path / "a.exr").read_bytes())
    _, others = _split((tmp_path / "b.exr").read_bytes())
    assert [c == o for c, o in zip(chunks, others, strict=True)] == [True, False, True, True, True]
    path = tmp_path / "edited.exr"
    path.write_bytes(_join(head, [chunks[0], others[1], *chunks[2:]]))
    got, _ = read_exr(path)  # a valid file holding the edited pixels
    assert np.array_equal(got["crack.mask.V"], edited_mask)
    assert recorded_stats(path) is None
    info, _ = inspect_exr(path, pixels=False)
    rows = {c.name: c for c in info.channels}
    want = edited_mask.astype(np.float64)
    assert (rows["crack.mask.V"].max, rows["crack.mask.V"].mean) == (1.0, want.mean())
    assert rows["crack.distance.V"].max == 9.0
    record = json.loads(read_exr(path)[1][STATS_ATTRIBUTE])["channels"]
    assert record["crack.mask.V"]["max"] == 0.5  # what the stale record would have said
    assert info.to_json() == _slow(path).to_json()


def test_a_header_edit_behind_the_record_is_read(tmp_path):
    """The same chunks under another channel list (two names swapped): not trusted."""
    a = np.zeros((H, W), np.float32)
    b = np.ones((H, W), np.float32)
    write_exr(tmp_path / "x.exr", {"p.V": a, "q.V": b})
    blob = (tmp_path / "x.exr").read_bytes()
    path = tmp_path / "swapped.exr"
    path.write_bytes(blob.replace(b"p.V\0", b"r.V\0", 1))  # same length, another name
    assert recorded_stats(path) is None
    info, _ = inspect_exr(path, pixels=False)
    assert [c.name for c in info.channels] == ["q.V", "r.V"]
    assert info.to_json() == _slow(path).to_json()


def test_a_file_resaved_by_openimageio_is_read(files, tmp_path):
    """OpenImageIO re-saves the crack master, one texel changed, and carries the
    ``crackbake:stats`` attribute over: the record is ignored, the table is the new pixels'."""
    d, planes = files
    buf = oiio.ImageBuf(str(d / "a_cracks.exr"))
    names = list(buf.spec().channelnames)
    k = names.index("crack.mask.V")
    pixel = list(buf.getpixel(7, 3))
    pixel[k] = 0.25
    buf.setpixel(7, 3, pixel)
    assert buf.getpixel(7, 3)[k] == 0.25
    path = tmp_path / "resaved.exr"
    assert buf.write(str(path)), oiio.geterror()
    _, header = read_exr(path)
    assert STATS_ATTRIBUTE in header  # carried over, now stale
    assert recorded_stats(path) is None
    info, _ = inspect_exr(path, pixels=False)
    rows = {c.name: c for c in info.channels}
    want = planes["crack.mask.V"].astype(np.float64)
    want[3, 7] = 0.25
    assert rows["crack.mask.V"].mean == pytest.approx(want.mean(), rel=1e-12)
    assert rows["crack.mask.V"].nonzero == np.count_nonzero(want) / want.size
    assert info.to_json() == _slow(path).to_json()


def test_only_the_attribute_is_added(tmp_path):
    """With and without the record: the same header otherwise, the same chunks to the byte
    (the offsets move by the attribute's length)."""
    rng = np.random.default_rng(2)
    planes = {"a.V": rng.random((H, W)).astype(np.float16),
              "b.V": rng.integers(0, 9, (H, W)).astype(np.uint32)}  # fmt: skip
    for compression in ("zip", "zips"):
        with_, without = tmp_path / "with.exr", tmp_path / "without.exr"
        write_scanline(with_, planes, {"owner": "x"}, compression, threads=2)
        write_scanline(without, planes, {"owner": "x"}, compression, threads=2, stats=False)
        a, b = with_.read_bytes(), without.read_bytes()
        (ha, ea), (hb, eb) = parse_header(a), parse_header(b)
        assert set(ha) - set(hb) == {STATS_ATTRIBUTE}
        assert all(ha[k] == hb[k] for k in hb)
        grow = ea - eb
        assert grow == len(STATS_ATTRIBUTE) + 1 + len("string") + 1 + 4 + len(
            ha[STATS_ATTRIBUTE][1])  # fmt: skip
        n = (int(np.frombuffer(b, "<u8", 1, eb)[0]) - eb) // 8
        ta = np.frombuffer(a, "<u8", n, ea).astype(np.int64)
        tb = np.frombuffer(b, "<u8", n, eb).astype(np.int64)
        assert np.all(ta - tb == grow)
        assert a[ea + 8 * n :] == b[eb + 8 * n :]
        assert recorded_stats(without) is None


def test_threads_give_the_same_record(tmp_path):
    rng = np.random.default_rng(6)
    planes = {f"c{i}.V": rng.standard_normal((H, W)).astype(np.float32) for i in range(6)}
    blobs = []
    for n in (0, 1, 3):
        write_scanline(tmp_path / "t.exr", planes, {}, "zip", threads=n)
        blobs.append((tmp_path / "t.exr").read_bytes())
    assert blobs[0] == blobs[1] == blobs[2]


def test_a_record_of_another_version_is_ignored(tmp_path):
    write_exr(tmp_path / "v.exr", {"a.V": np.ones((H, W), np.float32)})
    blob = (tmp_path / "v.exr").read_bytes()
    mark = f'"version":{STATS_VERSION}'.encode()
    assert mark in blob
    (tmp_path / "v2.exr").write_bytes(blob.replace(mark, b'"version":9', 1))
    assert recorded_stats(tmp_path / "v.exr") is not None
    assert recorded_stats(tmp_path / "v2.exr") is None
    assert recorded_stats(tmp_path / "missing.exr") is None


def test_a_udim_set_from_the_records(tmp_path):
    """A UDIM set's rows (over every tile) from the tiles' records: the pixels' rows."""
    from crackbake.exchange.inspect import inspect_udim

    rng = np.random.default_rng(3)
    for n in (1001, 1002, 1011):
        write_exr(tmp_path / f"t.{n}.exr", {
            "crack.mask.V": rng.random((H, W)).astype(np.float16),
            "crack.id.V": rng.integers(-1, 9, (H, W)).astype(np.float32)})  # fmt: skip
    fast, tiles = inspect_udim(tmp_path / "t.<UDIM>.exr", pixels=False)
    slow, planes = inspect_udim(tmp_path / "t.<UDIM>.exr", pixels=True)
    assert set(tiles.values()) == {None} and all(isinstance(p, dict) for p in planes.values())
    assert fast.to_json() == slow.to_json()
