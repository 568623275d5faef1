"""Glass impact stars: the issue-12 measures on a plate and on five mesh impacts.

Runs the default glass preset (simulation mesh, stress field, solver; no bake) and prints, per
case, the measures of :mod:`crackbake.metrics.star`: radial arms at 0.3 reach, median and least
chord/arc of the arms inside 0.6 reach and the median geodesic straightness (gain in surface
distance / arc), tangential share of the length in 0.35-0.65 reach,
crack length density in five annuli of the reach (1 / mesh unit, inner first), the length
beyond the reach and the solve time.  Distances are geodesic on the meshes (fast marching on
the sim mesh) and straight on the plate.

Impact points (vertices of the meshes, so they lie on the surface):

* spot (examples/spot.obj, Y up, head towards -Z): horn tip (0.1808, 0.9464, -0.2446), outer
  side of the front right leg (0.3044, -0.5213, -0.1176), flank (0.351, 0.0109, 0.277);
* stanford-bunny: near the tip of the ear (-0.0212, 0.1742, -0.0218);
* suzanne: nose tip (-2.494, 1.049, 4.932).

The mesh cases read /work/shared/meshes (or ``--meshes DIR``) and are skipped when a mesh is
missing.  Usage::

    python benchmarks/bench_glass.py [--cases plate-s0,spot-horn,...] [--sim-faces N]
        [--json out.json] [--picture out.png]

``--picture`` draws the cases side by side (docs/glass_plate.png, docs/glass_impacts.png): the
sim mesh's faces towards the viewer shaded, seen along the mean normal round the impact (across
the thinnest principal axis near it for ``SIDE_VIEW`` cases: the bunny's ear), the crack
polylines in red, the 0.3-reach and reach circles (straight radii: on a curved mesh the geodesic
circles differ) in blue and green.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from crackbake.io.mesh import load_mesh  # noqa: E402
from crackbake.metrics.star import impact_reach, star_metrics  # noqa: E402
from crackbake.params import Impact, RunParams  # noqa: E402
from crackbake.pipeline import solve  # noqa: E402
from crackbake.precompile import plate_obj  # noqa: E402

SHARED = Path("/work/shared/meshes")
#: name -> (mesh file or "plate", impact point, seed)
CASES: dict[str, tuple[str, tuple[float, float, float], int]] = {
    "plate-s0": ("plate", (0.5, 0.5, 0.0), 0),
    "plate-s1": ("plate", (0.5, 0.5, 0.0), 1),
    "plate-s2": ("plate", (0.5, 0.5, 0.0), 2),
    "spot-horn": ("spot.obj", (0.1808, 0.9464, -0.2446), 0),
    "spot-leg": ("spot.obj", (0.3044, -0.5213, -0.1176), 0),
    "spot-flank": ("spot.obj", (0.351, 0.0109, 0.277), 0),
    "bunny-ear": ("stanford-bunny.obj", (-0.0212, 0.1742, -0.0218), 0),
    "suzanne-nose": ("suzanne.obj", (-2.494, 1.049, 4.932), 0),
}

#: Cases drawn from the side (an ear's tip: the view along the mean normal looks down the ear).
SIDE_VIEW = {"bunny-ear"}


def mesh_path(name: str, meshes: Path, tmp: Path) -> Path | None:
    """The mesh file of a case, or None when it is missing."""
    if name == "plate":
        return plate_obj(tmp / "plate.obj", 4, uv_margin=0.0)
    if name == "spot.obj":
        return ROOT / "examples" / "spot.obj"
    path = meshes / name
    return path if path.exists() else None


def draw(name: str, network, centre: np.ndarray, reach: float, sim, size: int = 420):
    """A PIL picture of one case (see the module docstring)."""
    from PIL import Image, ImageDraw

    from crackbake.geometry import face_normals
    from crackbake.metrics.star import polylines

    v, f = sim.vertices, sim.faces
    fn = face_normals(v, f)
    cen = v[f].mean(axis=1)
    n = fn[np.linalg.norm(cen - centre, axis=1) < 0.3 * reach].mean(axis=0)
    n /= np.linalg.norm(n)
    if name in SIDE_VIEW:
        # Across the feature: its thinnest principal axis (the mean normal at a tip runs along it).
        near = v[np.linalg.norm(v - centre, axis=1) < reach]
        axis = np.linalg.eigh(np.cov((near - near.mean(axis=0)).T))[1][:, 0]
        n = axis if axis @ n >= 0 else -axis
    # Screen right u, up w (the world's +Y where it is not the view direction), n towards us.
    u = np.cross([0.0, 1.0, 0.0] if abs(n[1]) < 0.9 else [1.0, 0.0, 0.0], n)
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    scale = size / (2.4 * reach) * (1.6 if name in SIDE_VIEW else 1.0)

    def xy(p):
        d = p - centre
        return np.stack([size / 2 + d @ u * scale, size / 2 - d @ w * scale], -1)

    im = Image.new("RGB", (size, size), "white")
    dr = ImageDraw.Draw(im)
    order = np.argsort((cen - centre) @ n)
    order = order[(fn[order] @ n) > 0]
    tri = xy(v[f[order]])
    shade = (120 + 120 * (fn[order] @ n)).astype(int)
    for t, g in zip(tri, shade, strict=True):
        dr.polygon([tuple(x) for x in t], fill=(g, g, g))
    for p in polylines(network):
        dr.line([tuple(x) for x in xy(p)], fill=(200, 0, 0), width=2)
    for k, col in ((0.3, (0, 0, 255)), (1.0, (0, 150, 0))):
        r = k * reach * scale
        dr.ellipse([size / 2 - r, size / 2 - r, size / 2 + r, size / 2 + r], outline=col)
    dr.text((6, 6), name, fill="black")
    return im


def run_case(name: str, meshes: Path, tmp: Path, sim_faces: int | None,
             pictures: list | None = None) -> dict | None:
    """Solve one case with the glass preset and measure its star; None when skipped."""
    mesh_name, point, seed = CASES[name]
    path = mesh_path(mesh_name, meshes, tmp)
    if path is None:
        return None
    params = RunParams(mesh=path, preset="glass", impacts=(Impact(point),), seed=seed,
                       sim_faces=sim_faces).validate()
    resolved, relative = params.resolved()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = load_mesh(path)
        t0 = time.perf_counter()
        network, _, solved = solve(mesh, resolved, relative, {})
        seconds = time.perf_counter() - t0
    imp = network.impacts[0]
    reach = impact_reach(imp["radius"])
    sim = solved.sim
    flat = mesh_name == "plate"
    m = star_metrics(network, imp["point"], reach,
                     None if flat else sim.vertices, None if flat else sim.faces)
    if pictures is not None:
        pictures.append(draw(name, network, np.asarray(imp["point"]), reach, sim))
    return {
        "case": name, "reach": reach, "cracks": len(network.cracks), "arms": m["arms"],
        "straight_median": m["straight_median"], "straight_min": m["straight_min"],
        "radial_median": m["radial_median"],
        "tangential": m["tangential"], "density": [float(x) for x in m["density"]],
        "falling": m["falling"], "beyond": m["beyond"], "beyond_share": m["beyond"] / max(
            m["length"], 1e-300), "length": m["length"], "seconds": seconds,
    }


def table(rows: list[dict]) -> str:
    """The rows as a fixed-width text table."""
    head = (f"{'case':<13} {'arms':>4} {'str.med':>7} {'str.min':>7} {'geo.med':>7} {'tang':>5} "
            f"{'density per 0.2-reach annulus (inner first)':<44} {'fall':>4} "
            f"{'beyond':>6} {'time':>6}")
    lines = [head]
    for r in rows:
        dens = " ".join(f"{x:7.2f}" for x in r["density"])
        lines.append(
            f"{r['case']:<13} {r['arms']:>4} {r['straight_median']:7.3f} "
            f"{r['straight_min']:7.3f} {r['radial_median']:7.3f} {r['tangential']:5.2f} {dens:<44} "
            f"{'yes' if r['falling'] else 'no':>4} {r['beyond_share']:6.3f} "
            f"{r['seconds']:5.1f}s")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--sim-faces", type=int, default=None)
    ap.add_argument("--meshes", type=Path, default=SHARED)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--picture", type=Path, default=None)
    args = ap.parse_args()
    rows = []
    pictures: list | None = [] if args.picture is not None else None
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.cases.split(","):
            row = run_case(name, args.meshes, Path(tmp), args.sim_faces, pictures)
            if row is None:
                print(f"{name}: mesh missing, skipped", flush=True)
                continue
            rows.append(row)
            print(table([row]).splitlines()[1], flush=True)
    print(table(rows))
    if pictures:
        from PIL import Image

        size = pictures[0].size[0]
        sheet = Image.new("RGB", (size * len(pictures), size), "white")
        for i, im in enumerate(pictures):
            sheet.paste(im, (i * size, 0))
        sheet.save(args.picture, optimize=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1, default=float))


if __name__ == "__main__":
    main()
