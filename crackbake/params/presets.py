"""The bundled material presets (``presets/*.toml``): their names and settings."""

from __future__ import annotations

import tomllib
from functools import cache
from pathlib import Path

from crackbake.errors import CrackbakeError

#: Folder of the bundled presets, ``crackbake/presets/``.
PRESET_DIR = Path(__file__).resolve().parent.parent / "presets"


@cache
def preset_names() -> tuple[str, ...]:
    """Names of the bundled material presets."""
    return tuple(sorted(p.stem for p in PRESET_DIR.glob("*.toml")))


@cache
def load_preset(name: str) -> dict:
    """The settings of a bundled preset (``presets/<name>.toml``)."""
    if name not in preset_names():
        raise CrackbakeError(
            f"--preset '{name}' is unknown; use one of {', '.join(preset_names())}"
        )
    with open(PRESET_DIR / f"{name}.toml", "rb") as fh:
        return tomllib.load(fh)
