"""What a batch leaves beside its job folders: ``batch.json`` (every job's record),
``batch.csv`` (the same, one row a job, for a spreadsheet) and ``batch_sheet.png`` (every job's
``preview.png`` in a labelled grid: people look before they read)."""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

import numpy as np

from crackbake import __version__

#: batch.csv's columns, in order.
CSV_COLUMNS = ("name", "status", "error", "node", "host", "wall_s", "run_s", "pipeline_total_s",
               "peak_rss_mb", "memory_estimate_mb", "files", "folder", "mesh", "hash")
THUMB = 256
LABEL = 40
#: The contact sheet's size bound, so the driver's memory does not grow with the batch (an
#: RGB sheet of this many pixels is 48 MiB): tiles shrink to fit, down to MIN_THUMB.
MAX_SHEET_PIXELS = 16 * 2**20
MIN_THUMB = 64
STATUS_COLOURS = {"ok": (40, 140, 60), "skipped": (60, 90, 160), "failed": (190, 40, 40),
                  "cancelled": (150, 110, 30)}


def _write_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def counts(records: list[dict]) -> dict[str, int]:
    """Jobs per status."""
    out: dict[str, int] = {}
    for r in records:
        out[r.get("status", "cancelled")] = out.get(r.get("status", "cancelled"), 0) + 1
    return out


def write_summary(out: Path, records: list[dict], batch_file: Path, info: dict) -> list[Path]:
    """Write ``batch.json``, ``batch.csv`` and ``batch_sheet.png`` into ``out``; their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"crackbake": __version__, "batch_file": str(batch_file), "counts": counts(records),
           "ray": info, "jobs": records}
    _write_atomic(out / "batch.json", (json.dumps(doc, indent=2) + "\n").encode())
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for r in records:
        row = dict(r, files=len(r.get("files", [])),
                   pipeline_total_s=r.get("pipeline_s", {}).get("total", ""))
        writer.writerow([row.get(c, "") for c in CSV_COLUMNS])
    _write_atomic(out / "batch.csv", text.getvalue().encode())
    _write_atomic(out / "batch_sheet.png", _png(contact_sheet(records)))
    return [out / n for n in ("batch.json", "batch.csv", "batch_sheet.png")]


def _png(image) -> bytes:
    buf = io.BytesIO()
    image.save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def sheet_layout(n: int, thumb: int = THUMB) -> tuple[int, int, int]:
    """``(columns, tile size in pixels, tiles shown)`` of a contact sheet of ``n`` jobs: rows of
    up to 6 tiles of ``thumb`` pixels while that fits :data:`MAX_SHEET_PIXELS`; beyond, a
    square grid of smaller tiles (at least :data:`MIN_THUMB`), and past that only as many tiles
    as fit."""
    n = max(1, n)
    cols = min(6, math.ceil(math.sqrt(n)))
    if n * thumb * (thumb + LABEL) <= MAX_SHEET_PIXELS:
        return cols, thumb, n
    # t * (t + LABEL) = MAX / n, solved for t
    size = int((-LABEL + math.sqrt(LABEL**2 + 4 * MAX_SHEET_PIXELS / n)) / 2)
    size = max(MIN_THUMB, min(thumb, size))
    shown = min(n, MAX_SHEET_PIXELS // (size * (size + LABEL)))
    return math.ceil(math.sqrt(shown)), size, shown


def contact_sheet(records: list[dict], thumb: int = THUMB):
    """A PIL image: each job's preview scaled to ``thumb`` pixels, its name and status beneath
    (a grey tile where the job wrote no preview), rows of up to 6; for a large batch smaller
    tiles (:func:`sheet_layout`), and where even those do not fit, the jobs that did not end
    ok first, then the others in order, as many as fit."""
    from PIL import Image, ImageDraw, ImageFont

    cols, thumb, shown = sheet_layout(len(records), thumb)
    if shown < len(records):
        records = ([r for r in records if r.get("status") not in ("ok", "skipped")]
                   + [r for r in records if r.get("status") in ("ok", "skipped")])[:shown]
    n = max(1, len(records))
    rows = math.ceil(n / cols)
    sheet = Image.new("RGB", (cols * thumb, rows * (thumb + LABEL)), (24, 24, 24))
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default(size=15)
    small = ImageFont.load_default(size=12)
    for k, r in enumerate(records):
        x, y = (k % cols) * thumb, (k // cols) * (thumb + LABEL)
        preview = Path(r["folder"]) / "preview.png"
        tile = None
        if r.get("status") in ("ok", "skipped") and preview.is_file():
            try:
                with Image.open(preview) as im:
                    tile = im.convert("RGB")
                    tile.thumbnail((thumb, thumb))
            except OSError:
                tile = None
        if tile is None:
            grey = np.full((thumb, thumb, 3), 70, np.uint8)
            sheet.paste(Image.fromarray(grey), (x, y))
            what = "no preview" if r.get("status") in ("ok", "skipped") else r.get("status", "")
            draw.text((x + thumb // 2, y + thumb // 2), what, fill=(230, 230, 230), font=font,
                      anchor="mm")
        else:
            sheet.paste(tile, (x + (thumb - tile.width) // 2, y + (thumb - tile.height) // 2))
        status = r.get("status", "")
        draw.rectangle((x, y + thumb, x + thumb - 1, y + thumb + LABEL - 1),
                       fill=STATUS_COLOURS.get(status, (90, 90, 90)))
        draw.text((x + 6, y + thumb + 4), _fit(draw, r["name"], font, thumb - 12),
                  fill=(255, 255, 255), font=font)
        detail = status
        if r.get("run_s") is not None and status == "ok":
            detail += f"  {r['run_s']:.1f} s"
        elif r.get("error"):
            detail = _fit(draw, r["error"].removeprefix("error: "), small, thumb - 12)
        draw.text((x + 6, y + thumb + 22), detail, fill=(235, 235, 235), font=small)
    return sheet


def _fit(draw, text: str, font, width: int) -> str:
    """``text`` cut with an ellipsis to ``width`` pixels."""
    if draw.textlength(text, font=font) <= width:
        return text
    while text and draw.textlength(text + "…", font=font) > width:
        text = text[:-1]
    return text + "…"
