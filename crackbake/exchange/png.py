"""8- and 16-bit PNGs: data maps untagged and linear, colour images tagged sRGB.

Images are ``(H, W)`` or ``(H, W, C)`` with row 0 the top of the image (UV ``v = 1``), written
as they are (never transformed).  8-bit PNGs are quantised in numpy and encoded by Pillow (faster
than OIIO), 16-bit PNGs by OpenImageIO (Pillow cannot write 16-bit RGB).

What the file *says* about its values is explicit (``color``): a data map (mask, depth, normal,
occlusion, packed data) carries no colour chunk at all (no sRGB, gAMA, cHRM or iCCP), so engines
and viewers read the numbers as they are; a colour image (base colour, preview) carries sRGB +
gAMA + cHRM.  OpenImageIO tags every 16-bit PNG sRGB unless its colour space is ``Raw``
(measured with OIIO 3.2), and Pillow never tags unless asked.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning

PathLike = str | os.PathLike

_OUT_OF_RANGE_TOLERANCE = 1e-3

#: What ``write_png(..., color=...)`` accepts: ``"data"`` untagged/linear, ``"srgb"`` tagged.
PNG_COLORS = ("data", "srgb")

# The chunks an sRGB PNG carries (PNG spec 11.3.3.5: sRGB writers should add the gAMA and cHRM
# that match it for decoders without sRGB support).  Rendering intent 0 = perceptual.
_SRGB_CHUNKS = (
    (b"sRGB", bytes([0])),
    (b"gAMA", (45455).to_bytes(4, "big")),
    (
        b"cHRM",
        b"".join(
            v.to_bytes(4, "big")
            for v in (31270, 32900, 64000, 33000, 30000, 60000, 15000, 6000)
        ),
    ),
)


def _checked_float(image: np.ndarray, bits: int, path: PathLike) -> np.ndarray:
    """Float32 ``image``; NaN and values clearly outside [0, 1] replaced/clipped with a warning."""
    if image.dtype.kind != "f":
        raise CrackbakeError(
            f"PNG '{path}': got {image.dtype} for a {bits}-bit PNG; pass floats in [0, 1] "
            f"or {'uint8' if bits == 8 else 'uint16'} values"
        )
    if image.dtype != np.float32:
        image = image.astype(np.float32)
    lo, hi = float(image.min()), float(image.max())
    # NaN makes min/max NaN, so this comparison also catches it.
    if not (lo >= -_OUT_OF_RANGE_TOLERANCE and hi <= 1.0 + _OUT_OF_RANGE_TOLERANCE):
        bad = int(np.count_nonzero(~((image >= 0.0) & (image <= 1.0))))
        warnings.warn(
            f"{Path(path).name}: {bad} values outside [0, 1] (min {lo:.4g}, max {hi:.4g}) were "
            "clipped; remap the data (e.g. n*0.5+0.5 for normals) before writing",
            CrackbakeWarning,
            stacklevel=4,
        )
        image = np.nan_to_num(image, nan=0.0)
    # Values still outside are clamped by the quantisation (ours for 8 bit, OIIO's for 16 bit),
    # which saves a full-image copy on the common in-range path.
    return image


def _to_uint8(image: np.ndarray, path: PathLike) -> np.ndarray:
    if image.dtype == np.uint8:
        return image
    q = _checked_float(image, 8, path) * np.float32(255.0)
    q += np.float32(0.5)  # round half up, as OIIO does for 16 bit
    np.clip(q, 0.0, 255.0, out=q)
    return q.astype(np.uint8)


def write_png(
    path: PathLike,
    image: np.ndarray,
    bits: int = 8,
    compression_level: int | None = None,
    color: str = "data",
) -> None:
    """Write an 8- or 16-bit PNG, values as given (no transform), tagged as ``color`` says.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; its folder must exist.
    image : (H, W) or (H, W, C) ndarray, C in 1..4
        Floats in [0, 1], row 0 = top of the image.  Values outside are clipped, with a
        :class:`~crackbake.io.mesh.CrackbakeWarning` when any was outside by more than 1e-3 (NaN
        is written as 0, also with the warning).  Already-quantised ``uint8`` (``bits=8``) or
        ``uint16`` (``bits=16``) arrays are written unchanged.  (H, W) and (H, W, 1) give a
        one-channel grey PNG.
    bits : {8, 16}
        8 bit is quantised in numpy and encoded by Pillow (measured faster than OIIO); 16 bit is
        written by OpenImageIO (Pillow cannot write 16-bit RGB).
    compression_level : int, optional
        zlib level 0..9; 6 when ``None``.  Level 1 is ~1.3x faster for a larger file.
    color : {"data", "srgb"}
        ``"data"`` (default: masks, depth, normals, occlusion, packed maps) writes no colour
        chunk, so readers take the values as linear data; ``"srgb"`` (base colour, previews,
        values already sRGB-encoded) writes sRGB + gAMA + cHRM.
    """
    if color not in PNG_COLORS:
        raise CrackbakeError(f"PNG colour '{color}' is unknown; use 'data' or 'srgb'")
    if bits not in (8, 16):
        raise CrackbakeError(f"PNG bit depth {bits} is not supported; use 8 or 16")
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if not (image.ndim == 2 or (image.ndim == 3 and 1 <= image.shape[2] <= 4)) or 0 in image.shape:
        raise CrackbakeError(
            f"PNG '{path}': image shape {image.shape} is not (H, W) or (H, W, C) with C in 1..4"
        )
    if compression_level is not None and not 0 <= int(compression_level) <= 9:
        raise CrackbakeError(f"PNG compression level {compression_level} is invalid; use 0..9")
    target = os.fspath(path)
    if bits == 8:
        _write_png8_pillow(target, _to_uint8(image, path), compression_level, color)
    else:
        if image.dtype != np.uint16:
            image = _checked_float(image, 16, path)
        _write_png16_oiio(target, image, compression_level, color)


def _write_png8_pillow(target: str, pixels: np.ndarray, level: int | None, color: str) -> None:
    from PIL import Image, PngImagePlugin

    nchan = 1 if pixels.ndim == 2 else pixels.shape[2]
    mode = {1: "L", 2: "LA", 3: "RGB", 4: "RGBA"}[nchan]
    info = PngImagePlugin.PngInfo()
    if color == "srgb":
        for cid, data in _SRGB_CHUNKS:
            info.add(cid, data)
    try:
        Image.fromarray(np.ascontiguousarray(pixels), mode).save(
            target,
            format="PNG",
            compress_level=6 if level is None else int(level),
            pnginfo=info,
        )
    except OSError as exc:
        raise CrackbakeError(
            f"cannot write PNG '{target}': {exc.strerror or exc}; "
            "check that the folder exists and is writable"
        ) from exc


def _write_png16_oiio(target: str, pixels: np.ndarray, level: int | None, color: str) -> None:
    import OpenImageIO as oiio

    if pixels.ndim == 2:
        # OIIO's Python write_image misreads 2-D arrays (measured): give it (H, W, 1).
        pixels = pixels[:, :, None]
    pixels = np.ascontiguousarray(pixels)
    h, w, nchan = pixels.shape
    spec = oiio.ImageSpec(w, h, nchan, "uint16")
    # OIIO writes sRGB + gAMA + cHRM for an unset colour space, none at all for "Raw".
    spec.attribute("oiio:ColorSpace", "sRGB" if color == "srgb" else "Raw")
    if level is not None:
        spec.attribute("png:compressionLevel", int(level))
    out = oiio.ImageOutput.create(target)
    ok = out is not None and out.open(target, spec) and out.write_image(pixels)
    error = "" if ok else (out.geterror() if out is not None else oiio.geterror())
    if out is not None:
        ok = out.close() and ok
    if not ok:
        raise CrackbakeError(
            f"cannot write PNG '{target}': {error.strip().splitlines()[0] if error else 'failed'}; "
            "check that the folder exists and is writable"
        )

