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

Imports numpy alone (no numba, no OpenEXR): ``crackbake inspect`` loads it at start-up.
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
STATS_VERSION = 1
#: The attributes besides the chunks that decide the pixels a reader gets.
PIXEL_ATTRIBUTES = ("channels", "compression", "dataWindow", "lineOrder")
#: Bytes read to find the header (its attributes, then a null byte): crackbake's are a few KB.
HEADER_READ = 1 << 20

_MAGIC = b"\x76\x2f\x31\x01"
#: Version flags of layouts crackbake does not write: tiled, deep, multi-part.
_OTHER_LAYOUTS = 0x200 | 0x800 | 0x1000
_TYPES = {np.dtype(np.float16): "half", np.dtype(np.float32): "float", np.dtype(np.uint32): "uint"}
#: The bit patterns of +inf and -inf: a pattern at or above one of them (of its sign) is an
#: inf or a NaN.
_HALF_INF, _HALF_NEG_INF = 0x7C00, 0xFC00


def _half_range(arr: np.ndarray) -> tuple[float, float, bool] | None:
    """min and max of a float16 plane and whether it holds a negative (-0 included), or
    None when it holds a NaN or an inf.

    Works on the bit patterns, as integer reductions of two views of the plane, no copy:
    the non-negative halves are the non-negative int16 patterns, in float order; the negative
    ones the uint16 patterns from 0x8000 (-0) up, in order of magnitude.  So the max is the
    largest int16 pattern (the smallest uint16 one when every texel is negative), the min the
    largest uint16 pattern (the smallest int16 one when none is), -0 just below +0; the
    patterns from +inf and -inf up are the infinities and NaNs.  (numpy's half reductions
    run an element at a time, about 85 ms a 4096² plane; these four take a few.)
    """
    signed, unsigned = arr.view(np.int16), arr.view(np.uint16)
    top, utop = int(signed.max()), int(unsigned.max())
    if top >= _HALF_INF or utop >= _HALF_NEG_INF:
        return None
    negative = utop >= 0x8000
    hi = top if top >= 0 else int(unsigned.min())
    lo = utop if negative else int(signed.min())
    both = np.array([lo, hi], np.uint16).view(np.float16)
    return float(both[0]), float(both[1]), negative


def _half_nonzero(arr: np.ndarray, negative: bool) -> int:
    """Texels of a float16 plane other than +0 and -0 (-0 looked for only where the plane
    holds a negative)."""
    signed = arr.view(np.int16)
    count = np.count_nonzero(signed)
    return count - int(np.count_nonzero(signed == -0x8000)) if negative else count


def plane_stats(arr: np.ndarray) -> dict:
    """The statistics of one (H, W) plane that ``crackbake inspect`` shows.

    Returns
    -------
    dict
        ``type`` ("half", "float", "uint"), ``min``, ``max``, ``mean`` (floats, None when no
        texel is finite), ``nonzero`` (share of texels other than ±0, 0..1) and ``nonfinite``
        (count of NaN and ±inf, which the others skip).
    """
    # The common case, every texel finite, costs no copy of the plane: min and max (of the
    # half bits' two integer views, or of the floats, whose NaN would show as a NaN extreme
    # and inf as an infinite one), the mean summed in float64 as numpy casts it (the same
    # buffered sum whatever the source type, so a half plane gives the same bits as its
    # float32 copy would), the non-zero count of the bits without the sign (-0 is zero).  A
    # plane with a NaN or an inf is widened and masked.
    lo = hi = mean = None
    good = None
    if arr.size and arr.dtype == np.float16:
        extremes = _half_range(arr)
        if extremes is not None:
            good, (lo, hi, negative) = arr, extremes
            nonzero = _half_nonzero(arr, negative)
        else:
            nonzero = np.count_nonzero(arr.view(np.uint16) & np.uint16(0x7FFF))
    else:
        if arr.size and arr.dtype.kind == "f":
            lo, hi = float(arr.min()), float(arr.max())
            if np.isfinite(lo) and np.isfinite(hi):
                good = arr
        elif arr.size:
            good, lo, hi = arr, float(arr.min()), float(arr.max())
        nonzero = np.count_nonzero(arr)
    if good is None:  # NaN or inf present (or an empty plane): skip them
        wide = arr.astype(np.float32) if arr.dtype == np.float16 else arr
        good = wide[np.isfinite(wide)] if wide.dtype.kind == "f" else wide
        lo = hi = None
        if good.size:
            lo, hi = float(good.min()), float(good.max())
    if good.size:
        mean = float(good.mean(dtype=np.float64))
    return {
        "type": _TYPES.get(arr.dtype, str(arr.dtype)), "min": lo, "max": hi, "mean": mean,
        "nonzero": float(nonzero) / arr.size if arr.size else 0.0,
        "nonfinite": int(arr.size - good.size),
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
