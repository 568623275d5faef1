"""Glass impacts on thin extremities (issue 18 §3): star or web, and the measures that tell.

Runs the glass preset through the command line (``--res 1024 --formats preview``) on real
extremities and two broad references, then measures each impact on a 100k-face sim mesh of the
asset (the default sim size; geodesic distances by fast marching on it):

* ``back``: area share of the surface inside the straight ball of 0.5 reach round the impact
  whose normal faces away from the normal at the impact (dot < 0): the star wraps round a
  feature smaller than itself (``crackbake.simulate.stress.fields.back_share``);
* ``reach_area``: surface area within geodesic reach over a flat star's ``pi reach^2``;
* ``chord_geo``: median straight / geodesic distance of the nodes 0.45-0.55 reach away (1 on a
  plane, less where the surface folds back);
* ``circle``: length of the geodesic 0.3-reach circle over a flat one's ``0.6 pi reach``;
* the star measures of :mod:`crackbake.metrics.star` (arms at 0.3 reach, geodesic
  straightness, tangential share, falling density) and the warnings the run printed.

Cases (points from the meshes: spot's tips are its extreme vertices; the others are the
points of issue 18 §3): bunny ear tip, teapot spout, suzanne ear, fandisk corner, spot's horn,
front-leg hoof, ear tip and flank, and a generated finger (a capsule of radius 0.1 and pole
distance 3 hit at its pole, default radius).  The mesh cases read /work/shared/meshes (or
``--meshes DIR``) and are skipped when a mesh is missing.  Usage::

    python benchmarks/bench_extremities.py --out /tmp/thin/after [--cases a,b] [--json f]
        [--sheet sheet.png] [--measure-only]

``--sheet`` tiles the preview.png files into one contact sheet, each labelled with its case,
arms and back share.  ``--measure-only`` skips the runs and measures the geometry alone (the
default radius, and the radius an adapted run would use).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from crackbake.io.mesh import load_mesh  # noqa: E402
from crackbake.metrics.star import impact_reach, star_metrics  # noqa: E402
from crackbake.simulate.simmesh import build_simmesh  # noqa: E402
from crackbake.simulate.stress.geodesic import impact_distance, iso_length  # noqa: E402

SHARED = Path("/work/shared/meshes")
SPOT = ROOT / "examples" / "spot.obj"
#: name -> (mesh file, impact point)
CASES: dict[str, tuple[str, tuple[float, float, float]]] = {
    "bunny-ear": ("stanford-bunny.obj", (-0.0175, 0.1873, -0.0198)),
    "teapot-spout": ("teapot.obj", (3.434, 2.4729, 0.0)),
    "suzanne-ear": ("suzanne.obj", (-3.8612, 1.5486, 3.6039)),
    "suzanne-brow": ("suzanne.obj", (-2.49, 1.2, 4.7)),  # a web on folds, not thin
    "fandisk-corner": ("fandisk.obj", (4.8279, 17.85, 0.0)),
    "spot-horn": ("spot.obj", (0.17745, 0.953646, -0.260405)),  # highest vertex
    "spot-leg": ("spot.obj", (0.229681, -0.733842, 0.0266899)),  # a front hoof's lowest
    "spot-ear": ("spot.obj", (0.393743, 0.706765, -0.3123)),  # the head's largest x
    "spot-flank": ("spot.obj", (0.334, 0.044, 0.287)),
    "finger": ("finger", (0.0, 0.0, 1.6)),  # default radius 0.48: capsule 0.13 reach
}


def finger_obj(path: Path) -> Path:
    """A capsule of radius 0.1 along z, pole centres 3 apart (poles at z = +-1.6)."""
    import trimesh

    t = trimesh.creation.capsule(height=3.0, radius=0.1, count=[48, 48])
    t.export(path)
    return path


def mesh_path(name: str, meshes: Path, tmp: Path) -> Path | None:
    if name == "finger":
        return finger_obj(tmp / "finger.obj")
    if name == "spot.obj":
        return SPOT
    path = meshes / name
    return path if path.exists() else None


def geometry_measures(sim, point, radius: float) -> dict:
    """The candidate measures of one impact on mesh ``sim`` (see the module docstring)."""
    from crackbake.simulate.stress.fields import back_share

    reach = impact_reach(radius)
    v, f = np.asarray(sim.vertices), np.asarray(sim.faces)
    dist, snapped, face = impact_distance(sim, point, max_distance=2.0 * reach)
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    d_face = dist[f].mean(axis=1)
    inside = np.isfinite(d_face) & (d_face <= reach)
    band = np.isfinite(dist) & (dist > 0.45 * reach) & (dist < 0.55 * reach)
    chord = np.linalg.norm(v[band] - snapped, axis=1) / dist[band]
    return {
        "back": back_share(v, f, dist, face, reach, normal_min=1.5 * sim.edge_length),
        "back_eucl": euclidean_back_share(v, f, snapped, reach),
        "reach_area": float(area[inside].sum() / (np.pi * reach * reach)),
        "chord_geo": float(np.median(chord)) if band.any() else float("nan"),
        "circle": iso_length(v, f, dist, 0.3 * reach) / (0.6 * np.pi * reach),
    }


def euclidean_back_share(v, f, point, reach: float) -> float:
    """Issue 18's first measure: the area share of the faces within a straight ball of 0.5
    reach whose normal has a negative dot with the mean normal within 0.1 reach."""
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    d = np.linalg.norm(tri.mean(axis=1) - point, axis=1)
    n0 = n[d <= max(0.1 * reach, float(d.min()))].sum(axis=0)
    inside = d <= 0.5 * reach
    area = np.linalg.norm(n[inside], axis=1)
    return float(area[n[inside] @ n0 < 0].sum() / area.sum())


def run_case(name: str, path: Path, point, out: Path, radius: float | None = None) -> dict:
    """The CLI run of one case (the default radius, or ``radius``); its wall time, warnings
    and cracks.json."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    given = "" if radius is None else f":{radius:.6g}"
    cmd = [sys.executable, "-m", "crackbake", str(path), "--preset", "glass", "--impact",
           ",".join(f"{x:g}" for x in point) + given, "--res", "1024", "--formats", "preview",
           "-o", str(out / name)]
    t = time.perf_counter()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(f"{name}: exit {r.returncode}: {r.stderr[-2000:]}")
    warns = [ln for ln in r.stderr.splitlines() if ln.startswith("warning:")]
    net = json.loads((out / name / "cracks.json").read_text())
    return {"wall": wall, "warnings": warns, "network": net}


def sheet(rows: list[dict], out: Path, path: Path, cell: int = 360) -> None:
    """Tile the cases' preview.png files, labelled, into one picture."""
    from PIL import Image, ImageDraw

    cols = 3
    nrows = (len(rows) + cols - 1) // cols
    img = Image.new("RGB", (cols * cell, nrows * (cell + 30)), "white")
    draw = ImageDraw.Draw(img)
    for k, row in enumerate(rows):
        x, y = (k % cols) * cell, (k // cols) * (cell + 30)
        pv = out / row["case"] / "preview.png"
        if pv.exists():
            im = Image.open(pv).convert("RGB")
            im.thumbnail((cell, cell))
            img.paste(im, (x, y + 30))
        label = (f"{row['case']}: {row.get('arms', '-')} arms, back {row['back']:.2f}, "
                 f"r {row['radius']:.3g}" + (" WARNED" if row.get("web_warned") else ""))
        draw.text((x + 4, y + 8), label, fill="black")
    img.save(path, optimize=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--meshes", type=Path, default=SHARED)
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_extremities"))
    ap.add_argument("--json", type=Path)
    ap.add_argument("--sheet", type=Path)
    ap.add_argument("--measure-only", action="store_true")
    ap.add_argument("--scale", type=float,
                    help="give every impact this times the default radius explicitly")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    sims: dict[str, object] = {}
    for name in args.cases.split(","):
        file, point = CASES[name]
        path = mesh_path(file, args.meshes, args.out)
        if path is None:
            print(f"{name}: mesh missing, skipped")
            continue
        mesh = load_mesh(path)
        if file not in sims:
            sims[file] = build_simmesh(mesh, seed=0)
        sim = sims[file]
        row: dict = {"case": name}
        default_r = 0.15 * mesh.diagonal
        if args.measure_only:
            row["radius"] = default_r
            row.update(geometry_measures(sim, point, default_r))
            from crackbake.simulate.stress.fields import fitted_radius

            dist, _, face = impact_distance(sim, point, max_distance=impact_reach(default_r))
            row["fitted"] = fitted_radius(np.asarray(sim.vertices), np.asarray(sim.faces),
                                          dist, face, default_r,
                                          normal_min=1.5 * sim.edge_length)
        else:
            given = None if args.scale is None else args.scale * default_r
            run = run_case(name, path, point, args.out, given)
            imp = run["network"]["impacts"][0]
            row["radius"] = imp["radius"]
            row["default_radius"] = default_r
            row["wall"] = run["wall"]
            row["warnings"] = run["warnings"]
            row["web_warned"] = any("web" in w or "wraps" in w for w in run["warnings"])
            row.update(geometry_measures(sim, imp["point"], imp["radius"]))
            m = star_metrics(run["network"], imp["point"], impact_reach(imp["radius"]),
                             sim.vertices, sim.faces)
            row.update({k: m[k] for k in ("arms", "radial_median", "straight_median",
                                          "tangential", "falling", "length", "beyond")})
            row["cracks"] = len(run["network"]["cracks"])
        rows.append(row)
        shown = {k: (round(x, 3) if isinstance(x, float) else x) for k, x in row.items()
                 if k != "warnings"}
        print(json.dumps(shown), flush=True)
        for w in row.get("warnings", []):
            print("   ", w[:300], flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float))
    if args.sheet and not args.measure_only:
        sheet(rows, args.out, args.sheet)


if __name__ == "__main__":
    main()
