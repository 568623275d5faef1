"""Images read as data: grayscale weight maps (OpenImageIO when installed, else Pillow)."""

from __future__ import annotations

import contextlib
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.safe_open import check_regular

# Rec. 709 luminance weights, for colour weight maps and vertex colours.
LUMA = np.array([0.2126, 0.7152, 0.0722])
#: Largest weight-map edge kept in memory, texels.  The weights are sampled at the simulation
#: mesh's vertices (about 100k faces, a few hundred across), so 8192 is far more than the
#: solver resolves; larger maps are read in bands and block-averaged down to this.
WEIGHT_MAP_EDGE = 8192


def load_weight_map(path, max_edge: int = WEIGHT_MAP_EDGE) -> np.ndarray:
    """Read an image as a grayscale weight map.

    Colour images become Rec. 709 luminance of the stored values (no colour-space conversion, so
    mid-grey 128 is about 0.5); alpha is ignored (flatten the image onto a background first).

    An image with an edge over ``max_edge`` is read in bands of rows and averaged over square
    blocks down to at most ``max_edge`` (a warning says so): memory stays bounded by the reduced
    map, where a 50000² map read whole needed about 30 GB.  Without OpenImageIO such an image is
    refused with its size and the limit.

    Parameters
    ----------
    path : str or Path
    max_edge : int
        Largest edge of the returned map, texels.

    Returns
    -------
    (H, W) float64 in [0, 1], row 0 at the top of the image (``v = 1``).

    Raises
    ------
    CrackbakeError
        Missing or unreadable file.
    """
    path = Path(path)
    if path.is_dir():
        raise CrackbakeError(f"{path}: the weight map is a folder; pass an image file")
    if not path.exists():
        raise CrackbakeError(f"{path}: weight map not found; check the path")
    check_regular(path, f"--weight-map {path}")  # a FIFO blocks the reader, a device never ends
    try:
        gray = _read_oiio(path, max_edge)
    except ImportError:
        gray = _read_pillow(path, max_edge)
    if not np.isfinite(gray).all():
        raise CrackbakeError(f"{path}: weight map holds NaN or infinite pixels; fix the image")
    if gray.min() < 0 or gray.max() > 1:
        warnings.warn(
            f"{path.name}: weight map values outside [0, 1] clipped",
            CrackbakeWarning,
            stacklevel=2,
        )
        gray = np.clip(gray, 0.0, 1.0)
    return gray


def _gray(pixels: np.ndarray) -> np.ndarray:
    """(H, W, C) -> (H, W) float64: Rec. 709 luminance of colour, the first channel else."""
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim == 2:
        return pixels
    if pixels.shape[2] >= 3:
        return pixels[:, :, :3] @ LUMA
    return pixels[:, :, 0]  # gray or gray + alpha


@contextlib.contextmanager
def _quiet_stderr(captured: list[str]):
    """Hold the process's stderr (fd 2) while a C library decodes: libpng prints its errors
    there ("libpng error: ..."), which would be a second line beside crackbake's own."""
    with tempfile.TemporaryFile() as tmp:
        saved = os.dup(2)
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            captured.append(tmp.read(4096).decode("utf-8", "replace").strip())


def _read_oiio(path: Path, max_edge: int) -> np.ndarray:
    import OpenImageIO as oiio

    said: list[str] = []
    with _quiet_stderr(said):
        inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise CrackbakeError(
            f"{path}: could not read the weight map ({oiio.geterror() or 'unknown format'}); "
            "use a PNG, JPEG, TIFF or EXR image"
        )
    try:
        spec = inp.spec()
        w, h, nch = spec.width, spec.height, spec.nchannels
        factor = -(-max(w, h) // max_edge)  # ceil
        with _quiet_stderr(said):
            gray = _reduced(inp, w, h, nch, factor) if factor > 1 else _whole(inp, w, h, nch)
    finally:
        inp.close()
    if gray is None:
        detail = (said[-1].splitlines() or [""])[-1] if said and said[-1] else oiio.geterror()
        detail = f" ({detail.removeprefix('libpng error: ')})" if detail else ""
        raise CrackbakeError(f"{path}: could not decode the weight map{detail}; re-save the image")
    if factor > 1:
        warnings.warn(
            f"{path.name}: weight map is {w}x{h}; read reduced to {gray.shape[1]}x"
            f"{gray.shape[0]} ({factor}x{factor} blocks averaged, over {max_edge} texels a "
            "side the solver cannot resolve more)",
            CrackbakeWarning,
            stacklevel=3,
        )
    return gray


def _whole(inp, w: int, h: int, nch: int) -> np.ndarray | None:
    data = inp.read_image(0, 0, 0, nch, "float")
    return None if data is None else _gray(np.asarray(data).reshape(h, w, nch))


def _reduced(inp, w: int, h: int, nch: int, factor: int) -> np.ndarray | None:
    """Mean of each ``factor`` x ``factor`` block (partial blocks at the far edges averaged over
    the texels they hold), decoding ``factor`` rows at a time."""
    out_w, out_h = -(-w // factor), -(-h // factor)
    out = np.empty((out_h, out_w))
    cols = np.minimum(np.arange(out_w) * factor + factor, w) - np.arange(out_w) * factor
    for i in range(out_h):
        y0, y1 = i * factor, min(h, i * factor + factor)
        data = inp.read_scanlines(0, 0, y0, y1, 0, 0, nch, "float")
        if data is None:
            return None
        rows = _gray(np.asarray(data).reshape(y1 - y0, w, nch))
        sums = np.add.reduceat(rows.sum(axis=0), np.arange(0, w, factor))
        out[i] = sums / (cols * (y1 - y0))
    return out


def _read_pillow(path: Path, max_edge: int) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            if max(im.size) > max_edge:
                raise CrackbakeError(
                    f"{path}: weight map is {im.size[0]}x{im.size[1]}, over the {max_edge} "
                    "texels a side crackbake reads without OpenImageIO; shrink it or install "
                    "OpenImageIO (it reads big maps reduced)"
                )
            return np.asarray(im.convert("L"), dtype=np.float64) / 255.0
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError,
            UnidentifiedImageError) as exc:
        raise CrackbakeError(
            f"{path}: could not read the weight map ({exc}); use a PNG, JPEG or TIFF image"
        ) from exc
