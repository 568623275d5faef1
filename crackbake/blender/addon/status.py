"""The running bake in Blender's status bar: "Crackbake: <stage> 43 %" and a Cancel button,
drawn by a function appended to the status bar's header while a bake runs and removed when it
ends (finished, failed or cancelled), so the bar is the artist's again afterwards.

The status bar is not one of a screen's areas, so tagging areas does not redraw it; Blender
redraws it when the workspace's status text is set, which :func:`redraw` does (to no text)
only while no operator has put its own text there.
"""

from __future__ import annotations

import bpy

#: What the status bar shows now: None, or ``(text, fraction)``; set by :func:`show`/:func:`update`.
STATE: dict = {"line": None}


def line(message: str, fraction: float) -> tuple[str, float]:
    """The status bar's text for a bake at ``fraction`` (0..1) of its stage ``message``."""
    fraction = min(max(float(fraction), 0.0), 1.0)
    return f"Crackbake: {message or 'baking'} {int(100 * fraction)} %", fraction


def draw(self, context) -> None:
    """The status bar header's extra draw function (``self.layout`` is the header's row)."""
    shown = STATE["line"]
    if shown is None:
        return
    text, fraction = shown
    row = self.layout.row(align=True)
    if hasattr(row, "progress"):  # Blender 4.0+
        row.ui_units_x = 14
        row.progress(factor=fraction, type="BAR", text=text)
    else:
        row.label(text=text, icon="TIME")
    row.operator("crackbake.cancel", text="", icon="CANCEL")


def _header():
    return bpy.types.STATUSBAR_HT_header


def show(message: str = "starting", fraction: float = 0.0) -> None:
    """Put the bake's line in the status bar (once; later calls update it)."""
    if STATE["line"] is None:
        _header().append(draw)
    STATE["line"] = line(message, fraction)
    redraw()


def update(message: str, fraction: float) -> None:
    """A new stage or fraction: the line changes and the bar is redrawn when it did."""
    if STATE["line"] is None:
        return
    new = line(message, fraction)
    if new[0] != STATE["line"][0]:
        STATE["line"] = new
        redraw()


def hide() -> None:
    """Take the line out of the status bar (the bake ended)."""
    if STATE["line"] is None:
        return
    STATE["line"] = None
    try:
        _header().remove(draw)
    except ValueError:  # already gone (the header was re-registered by a UI reload)
        pass
    redraw()


def is_shown() -> bool:
    """Whether the header draws the bake's line now (in its list of draw functions)."""
    funcs = getattr(_header(), "_dyn_ui_initialize", lambda: [])()
    return STATE["line"] is not None and draw in funcs


_OPERATOR_TEXT = {"on": False}


def operator_text(active: bool) -> None:
    """An operator of the extension (Place Impacts) holds the workspace's status text: leave
    it alone while it does."""
    _OPERATOR_TEXT["on"] = active


def redraw() -> None:
    """Redraw the status bar of every window (clearing a status text nobody else holds)."""
    if bpy.app.background or _OPERATOR_TEXT["on"]:
        return
    for window in bpy.context.window_manager.windows:
        with bpy.context.temp_override(window=window):  # Blender 3.2+
            window.workspace.status_text_set_internal(None)
