"""Images read as data: grayscale weight maps (OpenImageIO when installed, else Pillow)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.io.safe_open import check_regular

# Rec. 709 luminance weights, for colour weight maps and vertex colours.
LUMA = np.array([0.2126, 0.7152, 0.0722])


def load_weight_map(path) -> np.ndarray:
    """Read an image as a grayscale weight map.

    Colour images become Rec. 709 luminance of the stored values (no colour-space conversion, so
    mid-grey 128 is about 0.5); alpha is ignored (flatten the image onto a background first).

    Parameters
    ----------
    path : str or Path

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
        pixels = _read_oiio(path)
    except ImportError:
        pixels = _read_pillow(path)
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    channels = pixels.shape[2]
    if channels >= 3:
        gray = pixels[:, :, :3] @ LUMA
    else:
        gray = pixels[:, :, 0]  # gray or gray + alpha
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


def _read_oiio(path: Path) -> np.ndarray:
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise CrackbakeError(
            f"{path}: could not read the weight map ({oiio.geterror() or 'unknown format'}); "
            "use a PNG, JPEG, TIFF or EXR image"
        )
    try:
        spec = inp.spec()
        data = inp.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        inp.close()
    if data is None:
        raise CrackbakeError(f"{path}: could not decode the weight map; re-save the image")
    return np.asarray(data).reshape(spec.height, spec.width, spec.nchannels)


def _read_pillow(path: Path) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("L"), dtype=np.float64) / 255.0
    except (OSError, UnidentifiedImageError) as exc:
        raise CrackbakeError(
            f"{path}: could not read the weight map ({exc}); use a PNG, JPEG or TIFF image"
        ) from exc
