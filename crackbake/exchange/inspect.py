"""``crackbake inspect``: what an EXR holds, as a table, as JSON, and as false-colour pictures.

Works on any EXR the OpenEXR library reads (its first part): every channel gets its pixel type
and statistics; files written by crackbake also get each channel's units and role from the
``crackbake:channels`` header table, and pictures made for what each map is (normals as colours,
ids as distinct colours, signed stress on a diverging map, the principal directions as short
strokes over p1, the crack mask overlaid).
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from crackbake.exchange.exr import read_exr
from crackbake.exchange.exrstats import plane_stats, recorded_stats
from crackbake.exchange.layers import layer_of


@dataclass
class ChannelStats:
    """One channel's row of the table.  Statistics skip NaN and +-inf (counted apart)."""

    name: str
    layer: str
    channel: str
    type: str
    min: float | None
    max: float | None
    mean: float | None
    nonzero: float
    nonfinite: int
    units: str | None
    role: str | None


@dataclass
class Inspection:
    path: str
    width: int
    height: int
    compression: str
    attributes: dict[str, str]
    channels: list[ChannelStats]
    #: UDIM numbers of the tiles described (a UDIM set), None for a single file.
    tiles: list[int] | None = None

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2)


def _row(name: str, stats: dict, meta: dict) -> ChannelStats:
    """A table row from :func:`~crackbake.exchange.exrstats.plane_stats`'s figures (taken
    now, or recorded by the writer) and the channel's ``crackbake:channels`` entry."""
    return ChannelStats(
        name, layer_of(name), name.rpartition(".")[2], stats["type"], stats["min"],
        stats["max"], stats["mean"], stats["nonzero"], stats["nonfinite"], meta.get("units"),
        meta.get("role"),
    )  # fmt: skip


def _stats(name: str, arr: np.ndarray, meta: dict) -> ChannelStats:
    return _row(name, plane_stats(arr), meta)


def _all_stats(channels: dict[str, np.ndarray], table: dict) -> list[ChannelStats]:
    """One row per channel, sorted by name; the planes on a few threads (the statistics'
    numba kernels release the GIL: each plane's statistics are its own, the rows the same as
    one by one).
    Plain threads: ``concurrent.futures`` would import ``logging`` too (about 15 ms of a
    command whose floor is 0.5 s)."""
    import threading

    names = sorted(channels)
    workers = min(len(names), 4, os.cpu_count() or 1)
    if workers < 2:
        return [_stats(n, channels[n], table.get(n, {})) for n in names]
    rows: list[ChannelStats | None] = [None] * len(names)
    todo = iter(range(len(names)))
    lock = threading.Lock()
    failed: list[BaseException] = []

    def work() -> None:
        while not failed:
            with lock:
                i = next(todo, None)
            if i is None:
                return
            try:
                rows[i] = _stats(names[i], channels[names[i]], table.get(names[i], {}))
            except BaseException as exc:  # noqa: BLE001 - raised again by the caller
                failed.append(exc)

    helpers = [threading.Thread(target=work, daemon=True) for _ in range(workers - 1)]
    for t in helpers:
        t.start()
    work()
    for t in helpers:
        t.join()
    if failed:
        raise failed[0]
    return rows  # type: ignore[return-value]


def _attribute_text(value) -> str:
    return value if isinstance(value, str) else repr(value)


def inspect_exr(
    path: str | os.PathLike, pixels: bool = True
) -> tuple[Inspection, dict[str, np.ndarray] | None]:
    """Read ``path`` and describe every channel.

    Parameters
    ----------
    path : str or os.PathLike
    pixels : bool
        Read and return the pixels (for :func:`write_pictures`).  When False and the file
        carries a ``crackbake:stats`` record that matches its bytes
        (:func:`~crackbake.exchange.exrstats.recorded_stats`: a file crackbake wrote, as it
        wrote it), the statistics are the record's and only the header is read: the same
        rows as from the pixels, to the bit.

    Returns
    -------
    inspection : Inspection
        Size, compression, the header's attributes as text, one :class:`ChannelStats` per
        channel (sorted by name, as files store them).
    channels : dict of str to (H, W) ndarray, or None
        The pixels, for :func:`write_pictures`; None when they were not read.

    Raises
    ------
    CrackbakeError
        When the file cannot be read as an EXR.
    """
    recorded = None if pixels else recorded_stats(path)
    if recorded is not None:
        from crackbake.exchange.exr import read_header

        header, channels = read_header(path), None
        (x0, y0), (x1, y1) = header["dataWindow"]
        h, w = int(y1) - int(y0) + 1, int(x1) - int(x0) + 1
    else:
        channels, header = read_exr(path)
        h, w = next(iter(channels.values())).shape if channels else (0, 0)
    table: dict = {}
    if isinstance(header.get("crackbake:channels"), str):
        try:
            table = json.loads(header["crackbake:channels"])
        except ValueError:  # a foreign or damaged table: the channels still get a row
            table = {}
    skip = {"channels", "compression"}
    attributes = {k: _attribute_text(v) for k, v in sorted(header.items()) if k not in skip}
    if recorded is not None:
        rows = [_row(n, recorded[n], table.get(n, {})) for n in sorted(recorded)]
    else:
        rows = _all_stats(channels, table)
    info = Inspection(
        os.fspath(path), int(w), int(h), str(header.get("compression", "")), attributes, rows
    )
    return info, channels


#: ``<name>.<UDIM>.exr``: the token a UDIM set is named with.
UDIM_TOKEN = "<UDIM>"
_TILE = re.compile(r"^(?P<pre>.*)\.(?P<n>1\d{3})\.exr$", re.IGNORECASE)


def udim_files(path: str | os.PathLike) -> dict[int, Path]:
    """The tiles of a UDIM set ``<name>.<UDIM>.exr``: UDIM number -> file, ascending.

    Raises
    ------
    CrackbakeError
        No tile of the set exists.
    """
    from crackbake.errors import CrackbakeError

    path = Path(path)
    pre, _, post = path.name.partition(UDIM_TOKEN)
    found = {}
    folder = path.parent
    if folder.is_dir():
        for f in folder.iterdir():
            m = _TILE.match(f.name)
            if m and f.name.startswith(pre) and f.name.endswith(post) and len(f.name) == len(
                pre) + 4 + len(post) and 1001 <= int(m["n"]) <= 1999:  # fmt: skip
                found[int(m["n"])] = f
    if not found:
        raise CrackbakeError(
            f"no tile of the UDIM set '{path}' found (files {pre}1001{post}, {pre}1002{post}, "
            "...); check the folder and the name"
        )
    return dict(sorted(found.items()))


def inspect_udim(
    path: str | os.PathLike, pixels: bool = True
) -> tuple[Inspection, dict[int, dict | None]]:
    """Inspect every tile of a UDIM set ``<name>.<UDIM>.exr``: one row per channel over all
    tiles (min, max and non-finite over every texel, mean and non-zero share averaged over the
    tiles, which are the same size); the channels of each tile by UDIM number (None for the
    tiles whose pixels were not read: ``pixels`` as in :func:`inspect_exr`).

    Raises
    ------
    CrackbakeError
        No tile found, a tile unreadable, or tiles of different sizes or channels.
    """
    from crackbake.errors import CrackbakeError

    tiles = udim_files(path)
    parts = {n: inspect_exr(f, pixels) for n, f in tiles.items()}
    first_n = next(iter(parts))
    first, _ = parts[first_n]
    for n, (info, _) in parts.items():
        if (info.width, info.height) != (first.width, first.height) or [
            c.name for c in info.channels] != [c.name for c in first.channels]:  # fmt: skip
            raise CrackbakeError(
                f"UDIM tile {tiles[n]} is {info.width}x{info.height} with "
                f"{len(info.channels)} channels but tile {tiles[first_n]} is "
                f"{first.width}x{first.height} with {len(first.channels)}; a set's tiles must "
                "match (rebake them together)"
            )
    rows = []
    for k, c in enumerate(first.channels):
        cs = [parts[n][0].channels[k] for n in parts]
        lo = [x.min for x in cs if x.min is not None]
        hi = [x.max for x in cs if x.max is not None]
        mean = [x.mean for x in cs if x.mean is not None]
        rows.append(ChannelStats(
            c.name, c.layer, c.channel, c.type, min(lo) if lo else None,
            max(hi) if hi else None, float(np.mean(mean)) if mean else None,
            float(np.mean([x.nonzero for x in cs])), sum(x.nonfinite for x in cs), c.units,
            c.role,
        ))  # fmt: skip
    info = Inspection(os.fspath(path), first.width, first.height, first.compression,
                      first.attributes, rows, tiles=list(parts))  # fmt: skip
    return info, {n: ch for n, (_, ch) in parts.items()}


def _num(v: float | None) -> str:
    return "-" if v is None else f"{v:.6g}"


def format_table(info: Inspection) -> str:
    """The channel table as fixed-width text (one line per channel)."""
    head = (
        f"{info.path}: {info.width}x{info.height}, {len(info.channels)} channels, "
        f"{info.compression or 'unknown'} compression"
    )
    if info.tiles:
        head = (
            f"{info.path}: UDIM set of {len(info.tiles)} tiles "
            f"({', '.join(str(n) for n in info.tiles)}), each {info.width}x{info.height}, "
            f"{len(info.channels)} channels, {info.compression or 'unknown'} compression"
        )
    cols = ("layer", "channel", "type", "min", "max", "mean", "non-zero", "units")
    rows = [
        (
            c.layer or "-", c.channel, c.type, _num(c.min), _num(c.max), _num(c.mean),
            f"{100 * c.nonzero:.1f}%" + (f" ({c.nonfinite} nan/inf)" if c.nonfinite else ""),
            c.units or "-",
        )
        for c in info.channels
    ]  # fmt: skip
    widths = [max(len(r[i]) for r in [cols, *rows]) for i in range(len(cols))]
    lines = [head, "  ".join(t.ljust(wd) for t, wd in zip(cols, widths, strict=True)).rstrip()]
    lines += [
        "  ".join(t.ljust(wd) for t, wd in zip(r, widths, strict=True)).rstrip() for r in rows
    ]
    notes = _notes(info)
    if notes:
        lines += ["", *notes]
    return "\n".join(lines)


#: Plain words for the units the table shows (crackbake's own EXRs), keyed by units text.
UNITS_TEXT = {
    "source strength (relative)": (
        "source strength: relative stress, not pascals: 1 is the stress a source of strength 1 "
        "(--impact, --direction, --shrink) adds; tension > 0, compression < 0"
    ),
    "x toughness": (
        "x toughness: how close the material is to cracking: the stress that pulls it apart "
        "divided by its toughness; 1 or more cracks"
    ),
    "unit vector": (
        "unit vector: the direction of p1 (the largest stress) along the texture's T (+u) and "
        "B (+v); 0, 0 where there is none (no stress, or the same every way, and the gutters)"
    ),
}


def _notes(info: Inspection) -> list[str]:
    """Lines under the table: what the stress fields are and what their units mean."""
    layers = {c.layer.split(".", 1)[0] for c in info.channels if c.layer}
    notes = []
    if {"stress0", "stress"} & layers:
        notes.append(
            "stress0 is the initial stress field (before any crack), stress the final one "
            "(after the last crack: what the cracks left)"
        )
    for units in dict.fromkeys(c.units for c in info.channels if c.units in UNITS_TEXT):
        notes.append(UNITS_TEXT[units])
    return notes


# ---------------------------------------------------------------------------------- pictures

# Colour maps as a few anchors, interpolated linearly (no plotting library needed).
_SEQUENTIAL = np.array(  # viridis at 0, 1/6, ..., 1
    [[68, 1, 84], [68, 58, 131], [49, 104, 142], [33, 145, 140],
     [53, 183, 121], [144, 215, 67], [253, 231, 37]], np.float32,
) / 255  # fmt: skip
_DIVERGING = np.array(  # blue (negative) - white (0) - red (positive)
    [[5, 48, 97], [67, 147, 195], [247, 247, 247], [214, 96, 77], [103, 0, 31]], np.float32
) / 255  # fmt: skip

#: Longest picture edge: bigger maps are subsampled (pictures only; the table uses every texel).
PICTURE_MAX = 2048
#: Smallest picture edge: small maps are enlarged so strokes and texels can be seen.
PICTURE_MIN = 512
STROKE_SPACING = 16  # picture pixels between direction strokes


def _colormap(t: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    t = np.clip(np.nan_to_num(t, nan=0.0), 0.0, 1.0) * (len(anchors) - 1)
    i = np.minimum(t.astype(np.int32), len(anchors) - 2)
    f = (t - i)[..., None]
    return anchors[i] * (1 - f) + anchors[i + 1] * f


#: Roles always drawn on the diverging map (0 white), even where a picture holds one sign only.
_SIGNED_ROLES = frozenset({"xx", "yy", "xy", "p1", "p2"})


def _false_colour(v: np.ndarray, signed: bool = False) -> np.ndarray:
    """Signed data on the diverging map (0 white, symmetric), else the sequential map."""
    v = v.astype(np.float32)
    good = v[np.isfinite(v)]
    if good.size == 0:
        return np.zeros((*v.shape, 3), np.float32)
    lo, hi = float(good.min()), float(good.max())
    if lo < 0 or signed:
        # The 99.5th percentile of |v| keeps one hot texel from washing the picture out.
        lim = float(np.percentile(np.abs(good), 99.5)) or max(-lo, hi) or 1.0
        return _colormap(0.5 + 0.5 * v / lim, _DIVERGING)
    return _colormap((v - lo) / (hi - lo) if hi > lo else v * 0, _SEQUENTIAL)


def _id_colours(v: np.ndarray) -> np.ndarray:
    ids = np.nan_to_num(v.astype(np.float64), nan=-1).astype(np.int64)
    h = (ids * 2654435761) & 0xFFFFFF  # Knuth's hash: neighbouring ids get unlike colours
    rgb = np.stack([(h >> 16) & 255, (h >> 8) & 255, h & 255], axis=-1) / 255.0
    rgb = 0.25 + 0.75 * rgb
    rgb[ids < 0] = 0.0
    return rgb.astype(np.float32)


def _resample(img: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Nearest-neighbour resize (pictures of data: never blend texels)."""
    rows = (np.arange(shape[0]) * img.shape[0] // shape[0]).astype(np.intp)
    cols = (np.arange(shape[1]) * img.shape[1] // shape[1]).astype(np.intp)
    return img[rows][:, cols]


def _picture_shape(h: int, w: int) -> tuple[int, int]:
    edge = max(h, w)
    scale = PICTURE_MAX / edge if edge > PICTURE_MAX else max(1, PICTURE_MIN // edge)
    return max(1, round(h * scale)), max(1, round(w * scale))


def _strokes(rgb: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Draw short strokes along (dx, dy) (T, B components; B is up) on a grid."""
    h, w = rgb.shape[:2]
    s = STROKE_SPACING
    cy, cx = np.mgrid[s // 2 : h : s, s // 2 : w : s]
    ux, uy = dx[cy, cx], dy[cy, cx]
    ok = np.isfinite(ux) & np.isfinite(uy) & ((ux != 0) | (uy != 0))
    cy, cx, ux, uy = cy[ok], cx[ok], ux[ok], uy[ok]
    norm = np.hypot(ux, uy)
    ux, uy = ux / norm, uy / norm
    t = np.linspace(-0.4 * s, 0.4 * s, 2 * s)[:, None]
    # Image rows grow downwards while B points up the image: flip the second component.
    px = np.rint(cx + t * ux).astype(np.intp).clip(0, w - 1)
    py = np.rint(cy - t * uy).astype(np.intp).clip(0, h - 1)
    # Black strokes on light colours, white on dark ones (deep red/blue of strong stress).
    lum = rgb[cy, cx] @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    ink = np.broadcast_to(np.where(lum < 0.35, 1.0, 0.0).astype(np.float32), py.shape)
    # Only over texels that have a direction: a stroke near an island's edge stops there
    # instead of running on over the gutter (crackbake writes (0, 0) there).
    on = (dx[py, px] != 0) | (dy[py, px] != 0)
    out = rgb.copy()
    out[py[on], px[on]] = ink[on][..., None]
    return out


def _overlay(rgb: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    if mask is None:
        return rgb
    m = np.clip(np.nan_to_num(mask.astype(np.float32)), 0, 1)[..., None]
    return rgb * (1 - m)  # cracks drawn black


def _sibling_mask(path: Path) -> np.ndarray | None:
    """The crack mask of ``<stem>_cracks.exr`` beside ``<stem>_stress.exr``, if there is one."""
    stem, tile = path.stem, ""
    m = re.match(r"^(.*)(\.1\d{3})$", stem)
    if m:  # a UDIM tile: <stem>_stress.1001.exr beside <stem>_cracks.1001.exr
        stem, tile = m[1], m[2]
    if not stem.endswith("_stress"):
        return None
    other = path.with_name(stem.removesuffix("_stress") + "_cracks" + tile + ".exr")
    if not other.is_file():
        return None
    try:
        chans, _ = read_exr(other)
    except Exception:  # a broken sibling only costs the overlay
        return None
    return chans.get("crack.mask.V")


def write_pictures(
    info: Inspection, channels: dict[str, np.ndarray], out_dir: str | os.PathLike,
    prefix: str = "",
) -> list[Path]:
    """False-colour PNGs of every layer into ``out_dir`` (created); the files written.

    One picture per layer ``<layer>.png`` (dots as ``_``): 3-channel vectors as colours
    (``n * 0.5 + 0.5``), ids as distinct colours, other channels one picture each on the
    diverging map when signed, the sequential map otherwise.  For every ``<field>.p1`` with a
    ``<field>.dir`` beside it, ``<field>_p1_dir.png`` adds the principal directions as strokes.
    The crack mask (``crack.mask.V`` of this file or of ``<stem>_cracks.exr`` beside a
    ``<stem>_stress.exr``) is drawn in black over the pictures of every layer outside
    ``crack.*`` (the crack maps themselves stay readable).  ``prefix`` starts every file name
    (a UDIM tile's number).
    """
    from crackbake.exchange.pngenc import png_bytes, write_bytes  # zlib-ng: pictures only
    from crackbake.exchange.targets import quantise  # numba: only for the pictures

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not channels:
        return []
    h, w = next(iter(channels.values())).shape
    shape = _picture_shape(h, w)
    small = {n: _resample(a, shape) for n, a in channels.items()}
    mask = small.get("crack.mask.V")
    if mask is None:
        sib = _sibling_mask(Path(info.path))
        mask = _resample(sib, shape) if sib is not None and sib.shape == (h, w) else None
    roles = {c.name: (c.role or "").rpartition(".")[2] for c in info.channels}
    layers: dict[str, list[str]] = {}
    for name in sorted(channels):
        layers.setdefault(layer_of(name) or name, []).append(name)

    written = []

    def save(stem: str, rgb: np.ndarray, overlay: bool = True) -> None:
        path = out / (prefix + stem.replace(".", "_") + ".png")
        rgb8 = quantise(_overlay(rgb, mask if overlay else None), 8)
        write_bytes(path, png_bytes(rgb8, srgb=True))
        written.append(path)

    for layer, names in layers.items():
        if len(names) == 3 and all(n.rpartition(".")[2][-1:].upper() in "XYZ" for n in names):
            rgb = np.stack([small[n].astype(np.float32) for n in names], axis=-1) * 0.5 + 0.5
            save(layer, rgb, overlay=not layer.startswith("crack."))
        elif len(names) == 2 and layer.endswith(".dir"):
            field = layer.rpartition(".")[0]
            p1 = small.get(f"{field}.p1.V")
            if p1 is not None:
                base = _overlay(_false_colour(p1, signed=True), mask)
                dx, dy = (small[n].astype(np.float32) for n in names)
                save(f"{field}_p1_dir", _strokes(base, dx, dy), overlay=False)
        else:
            for n in names:
                role = roles.get(n, "")
                rgb = (
                    _id_colours(small[n])
                    if role == "id"
                    else _false_colour(small[n], signed=role in _SIGNED_ROLES)
                )
                save(n if len(names) > 1 else layer, rgb, overlay=not n.startswith("crack."))
    return written
