"""``--frames N``: the crack mask revealed over time, as an N-frame PNG sequence.

Frame ``k`` (0-based) is the 8-bit mask where the baked ``crack.time`` is ``<= k / (N - 1)`` and
0 elsewhere: what a shader thresholding ``crack.time`` at that moment shows.  Frame 0 holds what
cracked at t = 0, the last frame equals ``<stem>_mask.png``, and a texel once revealed stays
revealed (the threshold only rises).  The files are data maps (linear, no colour chunk), named
``<stem>_growth_0000.png`` ... in the output folder.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from crackbake.bake.raster import CrackMaps
from crackbake.exchange.pngenc import png_bytes, write_bytes
from crackbake.exchange.targets import quantise

__all__ = ["frame_name", "frame_pixels", "submit_frames"]


def frame_name(stem: str, k: int) -> str:
    """File name of frame ``k``: ``<stem>_growth_0000.png`` (four digits, more when needed)."""
    return f"{stem}_growth_{k:04d}.png"


def frame_pixels(mask: np.ndarray, time: np.ndarray, t: float) -> np.ndarray:
    """The (H, W) uint8 mask revealed at time ``t``: the mask where ``time <= t``, else 0."""
    m = quantise(mask, 8)
    return np.where(np.asarray(time, np.float32) <= np.float32(t), m, np.uint8(0))


def _write_frame(path: Path, maps: CrackMaps, t: float) -> None:
    write_bytes(path, png_bytes(frame_pixels(maps.mask, maps.time, t)))


def submit_frames(pool: ThreadPoolExecutor, path: Callable[[str], Path], stem: str,
                  maps: CrackMaps, frames: int | None) -> list[Future]:
    """Encode the ``frames`` growth frames on ``pool`` (none when ``frames`` is None).

    Parameters
    ----------
    pool : ThreadPoolExecutor
        The output stage's encoder pool.
    path : callable
        File name -> path in the staging folder (:meth:`OutputStage.path`).
    stem : str
        Mesh stem, the files' prefix.
    maps : CrackMaps
        The bake (``mask`` and ``time``).
    frames : int or None
        Frame count N >= 2 (validated by :class:`crackbake.params.RunParams`).
    """
    if not frames:
        return []
    times = np.linspace(0.0, 1.0, int(frames))
    times[-1] = np.inf  # the last frame is the whole mask, whatever the time map holds
    return [pool.submit(_write_frame, path(frame_name(stem, k)), maps, float(t))
            for k, t in enumerate(times)]
