"""Each channel's statistics (what ``crackbake inspect`` shows), and their record in the header
of the EXRs crackbake writes, tied to the file's pixel data by a SHA-256 fingerprint.

``crackbake inspect`` of a 4096² crack master spent about 1.5 CPU-s reading 0.47 GB of planes
back and reducing them (issue 25: ≤ 0.5 s whole process).  The writer has those planes in hand:
:func:`crackbake.exchange.exrzip.write_scanline` takes each stored plane's statistics with
:func:`plane_stats`, the very function ``inspect`` runs on the planes it reads, and records them
in the ``crackbake:stats`` header attribute with the SHA-256 of what fixes the pixels: the
version field, the ``channels``, ``compression``, ``dataWindow`` and ``lineOrder`` attributes,
and every byte after the header (the offset table and the chunks).  :func:`recorded_stats`
reads the header, hashes those bytes again (about 7 MB: a few milliseconds) and gives the
record only when the hash matches: inflating is deterministic, so the same compressed bytes
under the same channel list are the same pixels, and the record is the statistics ``inspect``
would take of them.  Any other file (re-saved by another tool, edited, truncated, written by
an older crackbake, or with another :data:`STATS_VERSION`) gives None and is read in full.

Imports numpy alone (no numba, no OpenEXR): ``crackbake inspect`` loads it at start-up;
:func:`plane_stats` imports its numba kernels (:mod:`crackbake.exchange.stats_kernels`) when
first called, by the writer or by ``inspect`` reading the pixels of a file without a record.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import stat
import struct
from collections.abc import Iterable

import numpy as np

#: The header attribute holding the record.
STATS_ATTRIBUTE = "crackbake:stats"
#: Bumped whenever :func:`plane_stats` changes what it gives: older records are then ignored.
STATS_VERSION = 2
#: The attributes besides the chunks that decide the pixels a reader gets.
PIXEL_ATTRIBUTES = ("channels", "compression", "dataWindow", "lineOrder")
#: Bytes read to find the header (its attributes, then a null byte): crackbake's are a few KB.
HEADER_READ = 1 << 20

_MAGIC = b"\x76\x2f\x31\x01"
#: Version flags of layouts crackbake does not write: tiled, deep, multi-part.
_OTHER_LAYOUTS = 0x200 | 0x800 | 0x1000
_TYPES = {np.dtype(np.float16): "half", np.dtype(np.float32): "float", np.dtype(np.uint32): "uint"}


def plane_stats(arr: np.ndarray) -> dict:
    """The statistics of one (H, W) plane that ``crackbake inspect`` shows.

    One pass of a :mod:`crackbake.exchange.stats_kernels` kernel (numba, imported here: the
    record's check never needs it), the same for the writer's record and ``inspect``'s read
    of the pixels.  The mean is exact, then rounded once, for half and uint planes; for float
    planes a float64 sum in a fixed order (each column's from the top, then the columns from
    the left): the same bits on any machine and thread count.

    Returns
    -------
    dict
        ``type`` ("half", "float", "uint"), ``min``, ``max``, ``mean`` (floats, None when no
        texel is finite), ``nonzero`` (share of texels other than ±0, NaN and ±inf included,
        0..1) and ``nonfinite`` (count of NaN and ±inf, which the others skip).
    """
    from crackbake.exchange import stats_kernels as k

    kind = _TYPES.get(arr.dtype, str(arr.dtype))
    plane = np.asarray(arr)
    plane = plane if plane.ndim == 2 else plane.reshape(1, -1)
    plane = np.ascontiguousarray(plane, plane.dtype.newbyteorder("="))
    if plane.dtype not in _TYPES:  # no EXR holds these: widened, as float64
        plane = plane.astype(np.float64)
    lo = hi = mean = None
    if plane.dtype == np.float16:
        bits = plane.view(np.uint16).ravel()
        klo, khi, nonzero, nonfinite, high, low = k.half_stats(bits, True)
        if khi >= k.HALF_INF_KEY or klo <= ~k.HALF_INF_KEY:  # an inf or a NaN: skip them
            klo, khi, nonzero, nonfinite, high, low = k.half_stats(bits, False)
        finite = plane.size - nonfinite
        if finite:
            # a key is the magnitude's pattern, complemented for a negative value
            keys = np.array([klo, khi], np.int32)
            both = np.where(keys < 0, ~keys | 0x8000, keys).astype(np.uint16).view(np.float16)
            lo, hi = float(both[0]), float(both[1])
            mean = ((high << 32) + low) / (finite << 24)
    elif plane.dtype == np.float32:
        bits = plane.view(np.int32)
        klo, khi, nonzero, nonfinite, total = k.float_stats(plane, bits, True)
        if khi >= k.FLOAT_INF_KEY or klo <= ~k.FLOAT_INF_KEY:  # an inf or a NaN: skip them
            klo, khi, nonzero, nonfinite, total = k.float_stats(plane, bits, False)
        finite = plane.size - nonfinite
        if finite:
            # a key is the bits, the magnitude's flipped for a negative value
            keys = np.array([klo, khi], np.int32)
            both = np.where(keys < 0, keys ^ 0x7FFFFFFF, keys).view(np.float32)
            lo, hi, mean = float(both[0]), float(both[1]), float(total) / finite
    elif plane.dtype == np.uint32:
        klo, khi, nonzero, high, low = k.uint_stats(plane.ravel())
        nonfinite = 0
        if plane.size:
            lo, hi, mean = float(klo), float(khi), ((high << 32) + low) / plane.size
    else:
        flo, fhi, nonzero, nonfinite, total = k.wide_stats(plane)
        finite = plane.size - nonfinite
        if finite:
            lo, hi, mean = float(flo), float(fhi), float(total) / finite
    return {
        "type": kind, "min": lo, "max": hi, "mean": mean,
        "nonzero": float(nonzero) / plane.size if plane.size else 0.0,
        "nonfinite": int(nonfinite),
    }  # fmt: skip


def parse_header(data: bytes | memoryview) -> tuple[dict[str, tuple[bytes, bytes]], int] | None:
    """The attributes of a single-part scanline EXR's header and the offset just past it.

    Returns
    -------
    (attributes, end) or None
        name -> (type name, value bytes); None when ``data`` does not start with a whole
        header of a single-part scanline file (another layout, not an EXR, or cut short).
    """
    data = memoryview(data)
    if bytes(data[:4]) != _MAGIC or len(data) < 9:
        return None
    (version,) = struct.unpack_from("<I", data, 4)
    if version & _OTHER_LAYOUTS:
        return None
    raw = data.obj if isinstance(data.obj, bytes) else bytes(data)
    attrs: dict[str, tuple[bytes, bytes]] = {}
    p = 8
    try:
        while raw[p] != 0:
            name_end = raw.index(b"\0", p)
            type_end = raw.index(b"\0", name_end + 1)
            (size,) = struct.unpack_from("<i", raw, type_end + 1)
            start = type_end + 5
            if size < 0 or start + size > len(raw):
                return None
            attrs[raw[p:name_end].decode("utf-8", "replace")] = (
                raw[name_end + 1 : type_end], raw[start : start + size])  # fmt: skip
            p = start + size
    except (IndexError, ValueError, struct.error):
        return None
    return attrs, p + 1


def fingerprint(head: bytes, tail: Iterable) -> str:
    """SHA-256 (hex) of what fixes a file's pixels: ``head`` (a whole header: its version
    field and :data:`PIXEL_ATTRIBUTES` are hashed, the other attributes not) and ``tail``,
    the buffers after the header (the offset table, then the chunks), in file order.

    Raises
    ------
    ValueError
        ``head`` is not a header :func:`parse_header` reads.
    """
    parsed = parse_header(head)
    if parsed is None:
        raise ValueError("not a single-part scanline EXR header")
    attrs = parsed[0]
    h = hashlib.sha256(bytes(head[:8]))
    for name in PIXEL_ATTRIBUTES:
        kind, value = attrs.get(name, (b"", b""))
        h.update(name.encode() + b"\0" + kind + b"\0" + struct.pack("<i", len(value)) + value)
    for piece in tail:
        h.update(piece)
    return h.hexdigest()


def stats_text(stats: dict[str, dict], digest: str) -> str:
    """The ``crackbake:stats`` attribute's value: compact JSON of the fingerprint and each
    channel's :func:`plane_stats` by name (floats as ``repr``: they read back to the bit)."""
    record = {"version": STATS_VERSION, "sha256": digest, "channels": stats}
    return json.dumps(record, separators=(",", ":"), sort_keys=True)


def recorded_stats(path: str | os.PathLike) -> dict[str, dict] | None:
    """The statistics recorded in ``path``'s ``crackbake:stats`` header attribute, by channel
    name, when its fingerprint matches the file as it is now; None otherwise (no record, a
    record of another :data:`STATS_VERSION`, other bytes, not a file crackbake's parser
    reads: the caller reads the pixels).  Never raises for a bad file: the pixel read names
    the damage."""
    try:
        # O_NONBLOCK and a regular file only: a FIFO at the path must not block (the pixel
        # read refuses it in words).
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with open(fd, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                return None
            head = fh.read(HEADER_READ)
            parsed = parse_header(head)
            if parsed is None or STATS_ATTRIBUTE not in parsed[0]:
                return None
            attrs, end = parsed
            kind, value = attrs[STATS_ATTRIBUTE]
            if kind != b"string":
                return None
            record = json.loads(value.decode("utf-8"))
            if not isinstance(record, dict) or record.get("version") != STATS_VERSION:
                return None
            channels = record.get("channels")
            # What crackbake writes with a record (ZIP or ZIPS, every channel's row well
            # formed), checked before the pixel data is read: a big file of another kind is
            # not read twice.
            if attrs.get("compression", (b"", b""))[1] not in (b"\x02", b"\x03"):
                return None
            if not isinstance(channels, dict) or sorted(channels) != _channel_names(
                    attrs["channels"][1]):  # fmt: skip
                return None
            if not all(_well_formed(row) for row in channels.values()):
                return None
            rest = iter(lambda: fh.read(1 << 22), b"")  # hashed as read, 4 MB at a time
            digest = fingerprint(head[:end], itertools.chain([memoryview(head)[end:]], rest))
        if digest != record.get("sha256"):
            return None
    except (OSError, ValueError, KeyError, TypeError, UnicodeDecodeError):
        return None
    return channels


def _well_formed(row) -> bool:
    """A record's row has :func:`plane_stats`'s keys and value types (a file made to match
    its own hash could hold anything)."""
    number = (int, float)
    return (
        isinstance(row, dict) and set(row) == _KEYS and row["type"] in _TYPES.values()
        and all(row[k] is None or isinstance(row[k], number) for k in ("min", "max", "mean"))
        and isinstance(row["nonzero"], number) and isinstance(row["nonfinite"], int)
    )  # fmt: skip


_KEYS = frozenset({"type", "min", "max", "mean", "nonzero", "nonfinite"})


def _channel_names(chlist: bytes) -> list[str]:
    """The names of an EXR ``chlist`` value (name, null, 16 bytes of type and sampling)."""
    names, p = [], 0
    while p < len(chlist) and chlist[p] != 0:
        end = chlist.index(b"\0", p)
        names.append(chlist[p:end].decode("utf-8", "replace"))
        p = end + 1 + 16
    return sorted(names)
