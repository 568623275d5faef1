"""EXR masters: named channels in their own pixel types, custom header attributes.

Images are ``(H, W)`` planes with row 0 the top of the image, which is UV ``v = 1`` (OBJ/Blender
convention); they are written as they are, never flipped.  Data maps are linear, never sRGB.

ZIP and ZIPS files (the default) are encoded by :mod:`crackbake.exchange.exrzip` (numba and
zlib-ng: a quarter of the bindings' CPU for the same pixels and header); the other lossless
compressions are written with the OpenEXR Python bindings, which take one 2-D array per channel
in its own pixel type.  OpenImageIO needs one interleaved buffer (an extra 700 MB and ~0.5 s at
4096² x 11 channels) and was 2-2.5x slower on the mixed half/float bake with its default two
threads (see ``benchmarks/bench_exr.py``); it is kept as the independent reader in the tests.
"""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.io.safe_open import check_regular

PathLike = str | os.PathLike

LOSSLESS_COMPRESSIONS = ("none", "zip", "zips", "piz", "rle", "zstd")
LOSSY_COMPRESSIONS = ("dwaa", "dwab", "b44", "b44a", "pxr24")

# Header attributes the EXR format itself owns; a custom attribute with one of these names would
# silently replace (or corrupt) the file's own.
_RESERVED_ATTRIBUTES = frozenset(
    {
        "channels", "compression", "dataWindow", "displayWindow", "lineOrder",
        "pixelAspectRatio", "screenWindowCenter", "screenWindowWidth", "type", "tiles",
        "name", "version", "chunkCount", "maxSamplesPerPixel",
    }
)  # fmt: skip

_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1

#: OpenEXR's worker threads while a file is read (the library default is none: the calling
#: thread decompresses every block alone).  ``crackbake inspect`` of a 4096² crack master
#: decompresses 0.47 GB of planes; the blocks are independent.
READ_THREADS = max(2, min(8, os.cpu_count() or 1))


@contextmanager
def exr_threads(n: int | None) -> Iterator[None]:
    """OpenEXR's global worker count set to ``n`` (None: unchanged), then restored."""
    import OpenEXR

    before = OpenEXR.global_thread_count()
    if n is not None:
        OpenEXR.set_global_thread_count(n)
    try:
        yield
    finally:
        if n is not None:
            OpenEXR.set_global_thread_count(before)


def _openexr_compression(name: str):
    import OpenEXR

    key = str(name).lower()
    if key in LOSSY_COMPRESSIONS:
        raise CrackbakeError(
            f"EXR compression '{name}' is lossy and would change data values; "
            f"use one of {', '.join(LOSSLESS_COMPRESSIONS)} (zip is the default)"
        )
    table = {
        "none": OpenEXR.NO_COMPRESSION,
        "zip": OpenEXR.ZIP_COMPRESSION,
        "zips": OpenEXR.ZIPS_COMPRESSION,
        "piz": OpenEXR.PIZ_COMPRESSION,
        "rle": OpenEXR.RLE_COMPRESSION,
        "zstd": OpenEXR.ZSTD_COMPRESSION,
    }
    if key not in table:
        raise CrackbakeError(
            f"unknown EXR compression '{name}'; use one of {', '.join(LOSSLESS_COMPRESSIONS)}"
        )
    return table[key]


def _compression_name(value) -> str:
    # The bindings spell it ZIP_COMPRESSION; give back the name write_exr accepts.
    text = getattr(value, "name", str(value)).removesuffix("_COMPRESSION").lower()
    return "none" if text == "no" else text


def _header_value(name: str, value):
    if isinstance(value, bool) or not isinstance(
        value, str | int | float | np.integer | np.floating
    ):
        raise CrackbakeError(
            f"EXR attribute '{name}' has type {type(value).__name__}; "
            "pass a str, int or float (write other values as a JSON string)"
        )
    if isinstance(value, int | np.integer):
        if not _INT32_MIN <= int(value) <= _INT32_MAX:
            # The bindings silently store 0 for ints beyond 32 bits.
            raise CrackbakeError(
                f"EXR attribute '{name}' = {value} does not fit a 32-bit int; pass it as a string"
            )
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    return value


def write_exr(
    path: PathLike,
    channels: dict[str, np.ndarray],
    attributes: dict[str, str | int | float] | None = None,
    compression: str = "zip",
) -> None:
    """Write a single-part scanline EXR with named channels and custom header attributes.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; its folder must exist.
    channels : dict of str to (H, W) ndarray
        Channel name (e.g. ``"crack.mask"``, ``"normal.X"``) to pixels, row 0 = top of the image
        (UV ``v = 1``).  The dtype picks the EXR pixel type: float16 -> HALF, float32 -> FLOAT,
        uint32 -> UINT.  Arrays are not converted (converting big planes costs seconds); other
        dtypes are refused.
    attributes : dict of str to str, int or float, optional
        Extra header attributes, e.g. ``{"crackbake:version": "0.1.0"}``.  Ints are stored as
        32-bit ints and floats as 32-bit floats (the bindings have no double attribute); pass a
        string where more precision matters.
    compression : str
        One of ``none``, ``zip`` (default), ``zips``, ``piz``, ``rle``, ``zstd``.  The lossy
        methods (``dwaa``, ``dwab``, ``b44``, ``b44a``, ``pxr24``) are refused: they alter data.

    Raises
    ------
    CrackbakeError
        For empty or mismatched channels, unsupported dtypes, bad attributes, lossy or unknown
        compression, or when the file cannot be written.
    """
    import OpenEXR

    if not channels:
        raise CrackbakeError("write_exr got no channels; pass at least one (H, W) array")
    planes: dict[str, np.ndarray] = {}
    shape = None
    for name, arr in channels.items():
        arr = np.asarray(arr)
        if not isinstance(name, str) or not name:
            raise CrackbakeError(f"EXR channel name {name!r} is invalid; use a non-empty string")
        if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] == 0:
            raise CrackbakeError(
                f"EXR channel '{name}' has shape {arr.shape}; pass one (H, W) array per channel"
            )
        if arr.dtype not in (np.float16, np.float32, np.uint32):
            raise CrackbakeError(
                f"EXR channel '{name}' has dtype {arr.dtype}; "
                "cast it to float16 (half), float32 (float) or uint32 (uint)"
            )
        if shape is None:
            shape = arr.shape
        elif arr.shape != shape:
            raise CrackbakeError(
                f"EXR channel '{name}' is {arr.shape[1]}x{arr.shape[0]} but the others are "
                f"{shape[1]}x{shape[0]}; bake every channel at the same resolution"
            )
        # The bindings size the data window from the array and read its buffer as C-ordered.
        planes[name] = np.ascontiguousarray(arr)

    header = {"compression": _openexr_compression(compression), "type": OpenEXR.scanlineimage}
    for key, value in (attributes or {}).items():
        if not isinstance(key, str) or not key or key in _RESERVED_ATTRIBUTES:
            raise CrackbakeError(
                f"EXR attribute name {key!r} is reserved or invalid; "
                "use a prefixed name such as 'crackbake:version'"
            )
        header[key] = _header_value(key, value)

    try:
        if str(compression).lower() in ("zip", "zips"):
            # Imported here: reading (crackbake inspect) needs no numba.
            from crackbake.exchange.exrzip import write_scanline

            extra = {k: v for k, v in header.items() if k not in ("compression", "type")}
            # OpenEXR's worker count (exr_threads) sets the encoder's threads too.
            write_scanline(path, planes, extra, str(compression).lower(),
                           threads=OpenEXR.global_thread_count())  # fmt: skip
        else:
            # File() replaces the dict's values with Channel objects; `planes` is our own copy.
            OpenEXR.File(header, planes).write(os.fspath(path))
    except (RuntimeError, ValueError, OSError) as exc:
        raise CrackbakeError(
            f"cannot write EXR '{path}': {str(exc).splitlines()[0] if str(exc) else exc}; "
            "check that the folder exists, is writable and has space"
        ) from exc


def _check_size(path: PathLike, header: dict) -> None:
    """Refuse a data window whose pixels would not fit in memory (a damaged or hostile header
    can declare any size), before the bindings allocate them."""
    window = header.get("dataWindow")
    if window is None:
        return
    (x0, y0), (x1, y1) = (np.asarray(c, np.int64) for c in window)
    w, h = int(x1 - x0 + 1), int(y1 - y0 + 1)
    nbytes = max(w, 0) * max(h, 0) * 4 * max(len(header.get("channels", [])), 1)
    limit = _memory_bytes() // 2
    if w <= 0 or h <= 0 or nbytes > limit:
        raise CrackbakeError(
            f"cannot read EXR '{path}': its data window is {w}x{h} pixels (about "
            f"{nbytes / 2**30:.3g} GiB decoded), beyond the {limit / 2**30:.3g} GiB this machine "
            "can hold (half its memory); check the file is complete and undamaged"
        )


@contextmanager
def _stderr_captured() -> Iterator[Callable[[], list[str]]]:
    """The library's messages on a damaged file (written straight to file descriptors 2 and
    1) kept out of the terminal, so it gives crackbake's one error line; yields a function
    returning what went to stderr, as lines."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile() as sink, open(os.devnull, "wb") as null:
        os.dup2(null.fileno(), 1)
        os.dup2(sink.fileno(), 2)
        try:
            yield lambda: _lines(sink)
        finally:
            for fd, old in zip((1, 2), saved, strict=True):
                os.dup2(old, fd)
                os.close(old)


def _lines(sink) -> list[str]:
    sink.seek(0)
    text = sink.read(4096).decode("utf-8", "replace")
    return [" ".join(line.split()) for line in text.splitlines() if line.strip()]


def _memory_bytes() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError):
        return 8 << 30


def read_header(path: PathLike) -> dict:
    """The header of ``path``'s first part as :func:`read_exr` gives it, pixels unread.

    Raises
    ------
    CrackbakeError
        When the file cannot be read as an EXR.
    """
    import OpenEXR

    try:
        check_regular(path)  # OpenEXR would block on a FIFO forever
        with _stderr_captured(), OpenEXR.File(os.fspath(path), header_only=True) as f:
            header = dict(f.parts[0].header)
    except (RuntimeError, ValueError, OSError, IndexError, KeyError, TypeError) as exc:
        raise CrackbakeError(
            f"cannot read EXR '{path}': {str(exc).splitlines()[0] if str(exc) else exc}; "
            "check the path and that the file is a complete OpenEXR image"
        ) from exc
    if "compression" in header:
        header["compression"] = _compression_name(header["compression"])
    return header


def read_exr(path: PathLike) -> tuple[dict[str, np.ndarray], dict]:
    """Read every channel of a (single-part or first-part) EXR with the OpenEXR bindings.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    channels : dict of str to (H, W) ndarray
        By name (files list channels sorted, not in write order); dtype float16, float32 or
        uint32 as stored.  Row 0 is the top of the image.
    header : dict
        The header as the bindings give it, except ``"compression"``, which is the lower-case
        name :func:`write_exr` accepts (``"zip"``, ``"none"``, ...).
    """
    import OpenEXR

    damaged = (
        f"cannot read EXR '{path}': {{}}; check the path and that the file is a complete "
        "OpenEXR image"
    )
    try:
        check_regular(path)  # OpenEXR would block on a FIFO forever
        with OpenEXR.File(os.fspath(path), header_only=True) as f:
            _check_size(path, f.parts[0].header if f.parts else {})
        with (
            exr_threads(READ_THREADS),
            _stderr_captured() as said,
            OpenEXR.File(os.fspath(path), separate_channels=True) as f,
        ):
            if not f.parts:  # what the bindings give for a truncated file
                why = (said() or ["it holds no readable image"])[0]
                why = why.removeprefix(f"{os.fspath(path)}: ")
                raise CrackbakeError(damaged.format(f"{why} (truncated?)"))
            part = f.parts[0]
            channels = {name: np.asarray(ch.pixels) for name, ch in part.channels.items()}
            header = dict(part.header)
    except (RuntimeError, ValueError, OSError, IndexError, KeyError, TypeError) as exc:
        raise CrackbakeError(
            damaged.format(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
        ) from exc
    except MemoryError as exc:
        raise CrackbakeError(damaged.format("out of memory decoding it")) from exc
    if "compression" in header:
        header["compression"] = _compression_name(header["compression"])
    return channels, header

