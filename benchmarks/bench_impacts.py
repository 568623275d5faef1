"""Several impacts: each star's measures alone and together with the others (issue 18 §2).

Runs the glass preset (simulation mesh, stress field, solver; no bake) once per impact alone and
once with all the case's impacts, and prints per impact the measures of
:mod:`crackbake.metrics.star` (arms crossing the 0.3-reach circle, median chord/arc of the arms,
tangential share in 0.35-0.65 reach, crack length beyond the reach) alone -> together, and the
ratio together / alone.  In the run with several impacts each star is measured on the cracks
nearer (in reaches) to its own impact than to any other (``star_metrics(..., others=...)``).

Impact points (vertices of examples/spot.obj, Y up, head towards -Z; found as extreme vertices,
see tests/test_impacts.py ``SPOT``):

* horn tip (0.1775, 0.9536, -0.2604): the highest vertex;
* ear tip (-0.4716, 0.7086, -0.1992): the vertex of least x (the ears stick out sideways);
* leg (0.3044, -0.5213, -0.1176): outer side of the front right leg;
* flank (0.351, 0.0109, 0.277) and the other flank (-0.351, 0.0109, 0.277).

Usage::

    python benchmarks/bench_impacts.py [--cases plate-2,spot-flank-horn,...] [--json out.json]
        [--picture out.png]

``--picture`` draws spot's flank and horn stars, alone and together (the picture of
docs/impacts_before_after.png is two such runs, before and after, side by side).  Timings on a
shared machine are noisy; the measures are deterministic.
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

SPOT = {
    "horn": (0.17745, 0.953646, -0.260405),
    "ear": (-0.471552, 0.708579, -0.199184),
    "leg": (0.3044, -0.5213, -0.1176),
    "flank": (0.351, 0.0109, 0.277),
    "flank2": (-0.351, 0.0109, 0.277),
}
#: Radius 0.12 (reach 0.19, shadow 4.7 sim edges at 100k faces: no refinement); the points
#: lie 0.40 apart or more (twice the reach: the stars do not meet) and 0.22 from the border.
PLATE5 = [(0.22, 0.22, 0.0), (0.78, 0.22, 0.0), (0.22, 0.78, 0.0), (0.78, 0.78, 0.0),
          (0.5, 0.5, 0.0)]
#: name -> (mesh, [(point, radius or None)], seed)
CASES: dict[str, tuple[str, list, int]] = {
    "plate-2": ("plate", [(PLATE5[0], 0.12), (PLATE5[3], 0.12)], 0),
    "plate-3": ("plate", [(p, 0.12) for p in PLATE5[:3]], 0),
    "plate-5": ("plate", [(p, 0.12) for p in PLATE5], 0),
    "spot-flank-horn": ("spot", [(SPOT["flank"], None), (SPOT["horn"], None)], 0),
    "spot-3": ("spot", [(SPOT[k], 0.2) for k in ("flank", "horn", "leg")], 0),
    "spot-5": ("spot", [(SPOT[k], 0.15) for k in ("flank", "horn", "leg", "ear", "flank2")], 0),
}
MEASURES = ("arms", "straight_median", "tangential", "beyond")


def mesh_path(name: str, tmp: Path) -> Path:
    if name == "plate":
        return plate_obj(tmp / "plate.obj", 4, uv_margin=0.0)
    return ROOT / "examples" / "spot.obj"


def run(path: Path, impacts: list, seed: int):
    """Solve with the glass preset; (network, solved, seconds)."""
    params = RunParams(mesh=path, preset="glass", seed=seed,
                       impacts=tuple(Impact(p, r) for p, r in impacts)).validate()
    resolved, relative = params.resolved()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = load_mesh(path)
        t0 = time.perf_counter()
        network, _, solved = solve(mesh, resolved, relative, {})
    return network, solved, time.perf_counter() - t0


def measure(network, solved, flat: bool, k: int) -> dict:
    """Star measures of impact ``k`` of the network, on the cracks nearer to it than to the
    other impacts."""
    imps = network.impacts
    reach = impact_reach(imps[k]["radius"])
    others = [(o["point"], impact_reach(o["radius"])) for i, o in enumerate(imps) if i != k]
    sim = solved.sim
    m = star_metrics(network, imps[k]["point"], reach, None if flat else sim.vertices,
                     None if flat else sim.faces, others=others)
    return {"arms": m["arms"], "straight_median": m["straight_median"],
            "tangential": m["tangential"], "beyond": m["beyond"] / reach,
            "sim_faces": int(len(sim.faces))}


def run_case(name: str, tmp: Path, pictures: list | None = None) -> list[dict]:
    mesh_name, impacts, seed = CASES[name]
    path = mesh_path(mesh_name, tmp)
    flat = mesh_name == "plate"
    together, solved, secs = run(path, impacts, seed)
    rows = []
    alone_nets = []
    for k in range(len(impacts)):
        net, sol, s1 = run(path, [impacts[k]], seed)
        alone_nets.append((net, sol))
        a = measure(net, sol, flat, 0)
        t = measure(together, solved, flat, k)
        rows.append({"case": name, "impact": k, "alone": a, "together": t,
                     "seconds_alone": s1, "seconds_together": secs})
    if pictures is not None and name == "spot-flank-horn":
        pictures.extend(draw_case(together, solved, alone_nets))
    return rows


def ratio(a: float, t: float) -> float:
    if not (np.isfinite(a) and np.isfinite(t)):
        return float("nan")
    if a == 0:
        return 1.0 if t == 0 else float("inf")
    return t / a


def table(rows: list[dict]) -> str:
    head = (f"{'case':<16} {'#':>1} {'arms a->t':>10} {'straight a->t':>14} "
            f"{'tangential a->t':>16} {'beyond/reach a->t':>18}  ratios t/a (arms str tang beyond)"
            f"  sim faces a/t")
    lines = [head]
    for r in rows:
        a, t = r["alone"], r["together"]
        rat = " ".join(f"{ratio(a[m], t[m]):5.2f}" for m in MEASURES)
        lines.append(
            f"{r['case']:<16} {r['impact']:>1} {a['arms']:>4} -> {t['arms']:<3} "
            f"{a['straight_median']:6.3f}->{t['straight_median']:6.3f} "
            f"{a['tangential']:7.3f}->{t['tangential']:6.3f} "
            f"{a['beyond']:8.3f}->{t['beyond']:7.3f}  {rat}  {a['sim_faces']}/{t['sim_faces']}")
    return "\n".join(lines)


def _view(sim, centre, reach, size):
    """Screen projection of the sim mesh round ``centre`` (see bench_glass.draw)."""
    from crackbake.geometry import face_normals

    v, f = sim.vertices, sim.faces
    fn = face_normals(v, f)
    cen = v[f].mean(axis=1)
    n = fn[np.linalg.norm(cen - centre, axis=1) < 0.3 * reach].mean(axis=0)
    n /= np.linalg.norm(n)
    u = np.cross([0.0, 1.0, 0.0] if abs(n[1]) < 0.9 else [1.0, 0.0, 0.0], n)
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    scale = size / (2.4 * reach)

    def xy(p):
        d = p - centre
        return np.stack([size / 2 + d @ u * scale, size / 2 - d @ w * scale], -1)

    return fn, cen, n, xy, scale


def draw(title: str, network, sim, centre, reach, size: int = 360):
    """One star: the sim mesh shaded, cracks red, 0.3-reach and reach circles."""
    from PIL import Image, ImageDraw

    from crackbake.metrics.star import polylines

    fn, cen, n, xy, scale = _view(sim, centre, reach, size)
    im = Image.new("RGB", (size, size), "white")
    dr = ImageDraw.Draw(im)
    order = np.argsort((cen - centre) @ n)
    order = order[(fn[order] @ n) > 0]
    tri = xy(sim.vertices[sim.faces[order]])
    shade = (120 + 120 * (fn[order] @ n)).astype(int)
    for t, g in zip(tri, shade, strict=True):
        dr.polygon([tuple(x) for x in t], fill=(g, g, g))
    for p in polylines(network):
        if np.min(np.linalg.norm(p - centre, axis=1)) < 1.3 * reach:
            dr.line([tuple(x) for x in xy(p)], fill=(200, 0, 0), width=2)
    for k, col in ((0.3, (0, 0, 255)), (1.0, (0, 150, 0))):
        r = k * reach * scale
        dr.ellipse([size / 2 - r, size / 2 - r, size / 2 + r, size / 2 + r], outline=col)
    dr.text((6, 6), title, fill="black")
    return im


def draw_case(together, solved, alone_nets):
    """Flank alone, flank with the horn, horn alone, horn with the flank."""
    out = []
    for k, label in ((0, "flank"), (1, "horn")):
        net, sol = alone_nets[k]
        imp = together.impacts[k]
        c, reach = np.asarray(imp["point"]), impact_reach(imp["radius"])
        out.append(draw(f"{label} alone", net, sol.result, c, reach))
        out.append(draw(f"{label} with the other", together, solved.result, c, reach))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--picture", type=Path, default=None)
    args = ap.parse_args()
    rows: list[dict] = []
    pictures: list | None = [] if args.picture is not None else None
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.cases.split(","):
            new = run_case(name, Path(tmp), pictures)
            rows += new
            print(table(new).split("\n", 1)[1], flush=True)
    print(table(rows))
    worst = max((abs(ratio(r["alone"][m], r["together"][m]) - 1.0) for r in rows
                 for m in MEASURES[:3]), default=0.0)
    print(f"largest change of arms / straightness / tangential share: {worst:.1%}")
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
