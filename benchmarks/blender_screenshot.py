"""docs/blender_panel.png: the Crackbake panel and a bake's result in a real Blender window.

Blender's ``bpy`` module opens no window, so this runs a Blender executable older than 4.2
(Debian's ``blender`` 3.4: ``apt install blender python3-numpy xvfb xdotool``) under Xvfb with
``tests/blender/addon_screenshot.py``: the extension zip installed as a legacy add-on, spot
imported, one impact added with ``crackbake.add_impact``, the crackle preset baked in the
background at 1024², the sidebar's Crackbake tab clicked (xdotool) and the window captured with
``screen.screenshot`` after EEVEE has compiled the material.  The 3D view and sidebar are
cropped out, scaled to 1100 px wide and stored with 256 colours (< 400 KB).  About 3 minutes.

Usage::

    python benchmarks/blender_screenshot.py [--blender blender] [--out docs/blender_panel.png]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tests" / "blender" / "addon_screenshot.py"
#: The sidebar's Crackbake tab in Blender 3.4's default layout on a 1600x1000 screen.
TAB = (1307, 256)
CROP = (0, 0, 1322, 906)  # the top bar, the 3D view and its sidebar


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--blender", default="blender")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "blender_panel.png")
    ap.add_argument("--res", type=int, default=1024)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from PIL import Image

    from crackbake.blender.build import build_extension

    with tempfile.TemporaryDirectory(prefix="cb-shot-") as tmp:
        tmp = Path(tmp)
        zip_path = build_extension(tmp / "zip")
        env = {**os.environ, "BLENDER_USER_CONFIG": str(tmp / "config"),
               "BLENDER_USER_SCRIPTS": str(tmp / "scripts"), "PYTHONPATH": str(ROOT),
               "XDO": f"mousemove {TAB[0]} {TAB[1]};click 1;mousemove 500 650"}
        # no splash screen over the window
        subprocess.run([args.blender, "-b", "--factory-startup", "--python-expr",
                        "import bpy; bpy.context.preferences.view.show_splash = False; "
                        "bpy.ops.wm.save_userpref()"], env=env, check=True,
                       capture_output=True, timeout=300)
        shots = tmp / "shots"
        shots.mkdir()
        subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", args.blender,
                        "--python", str(SCRIPT), "--", str(zip_path),
                        str(ROOT / "examples" / "spot.obj"), str(tmp / "out"), str(shots),
                        str(args.res)], env=env, check=True, timeout=900)
        log = json.loads((shots / "log.json").read_text())
        if log.get("error") or not (shots / "final.png").is_file():
            print(f"no screenshot: {log.get('error')}", file=sys.stderr)
            return 1
        im = Image.open(shots / "final.png").convert("RGB").crop(CROP)
        im = im.resize((1100, round(im.height * 1100 / im.width)), Image.LANCZOS)
        im = im.quantize(colors=256, method=Image.MEDIANCUT, dither=Image.FLOYDSTEINBERG)
        buf = io.BytesIO()
        im.save(buf, "PNG", optimize=True)
        args.out.write_bytes(buf.getvalue())
        print(f"{args.out}: {len(buf.getvalue()) // 1024} KB; Blender {log['blender']}, "
              f"status {log.get('status')!r}, status bar during the bake: "
              f"{[d['line'][0] for d in log.get('during', [])]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
