"""Impact speed -> radial arm count: the star-crack law on a plate, over speeds and seeds.

Runs the glass preset on the unit plate (simulation mesh, stress field, solver; no bake) with one
``--impact 0.5,0.5,0:speed=V`` per speed and seed, counts the radial arms crossing the circle at
0.3 of the reach (:func:`crackbake.metrics.star.radial_arms`, the measure of the "no star formed"
warning) and prints, per speed, the law's count, the arms per seed, their mean and spread, then
the fitted exponent of mean arms against speed (least squares in log-log; the law's is 1/2), the
fitted ``N = a sqrt(V)`` with the largest deviation of a mean from it, and N(16V)/N(V) where the
speeds span 16x.  Usage::

    python benchmarks/bench_speed_law.py [--speeds 10,25,63,160] [--seeds 0,1,2]
        [--thickness 3] [--material plexiglas] [--sim-faces N] [--json out.json]
        [--picture docs/glass_speeds.png] [--mesh examples/spot.obj --point X,Y,Z]

``--mesh`` runs on a mesh instead of the plate, the impact at ``--point`` (arms over geodesic
distances on the sim mesh).

``--picture`` draws the first seed's star at each speed side by side (the cracks in red, the
0.3-reach circle in blue, the reach in green; bench_glass.py's drawing).
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
sys.path.insert(0, str(ROOT / "benchmarks"))

from crackbake.io.mesh import load_mesh  # noqa: E402
from crackbake.metrics.star import impact_reach, star_metrics  # noqa: E402
from crackbake.params import Impact, RunParams  # noqa: E402
from crackbake.params.speed import radial_cracks  # noqa: E402
from crackbake.pipeline import solve  # noqa: E402
from crackbake.precompile import plate_obj  # noqa: E402

CENTRE = (0.5, 0.5, 0.0)


def solve_speed(path: Path, speed: float, seed: int, thickness: float | None = None,
                material: str | None = None, sim_faces: int | None = None,
                point: tuple[float, float, float] = CENTRE):
    """Solve the mesh at ``path`` (the plate) with one speed impact at ``point`` (its centre);
    return ``(network, sim mesh, seconds)``."""
    params = RunParams(mesh=path, preset="glass", impacts=(Impact(point, speed=speed),),
                       seed=seed, sim_faces=sim_faces, thickness=thickness,
                       material=material).validate()
    resolved, relative = params.resolved()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = load_mesh(path)
        t0 = time.perf_counter()
        network, _, solved = solve(mesh, resolved, relative, {})
        seconds = time.perf_counter() - t0
    return network, solved.sim, seconds


def arms_of(network, sim=None) -> int:
    """Radial arms at 0.3 reach of the network's first impact (straight distances on a plate,
    geodesic over ``sim`` when given)."""
    imp = network.impacts[0]
    v, f = (None, None) if sim is None else (sim.vertices, sim.faces)
    return int(star_metrics(network, imp["point"], impact_reach(imp["radius"]), v, f)["arms"])


def fit(speeds: np.ndarray, means: np.ndarray) -> dict:
    """The log-log exponent, the ``a`` of ``N = a sqrt(V)`` (least squares) and the largest
    deviation of a mean from that law, arms."""
    exponent = float(np.polyfit(np.log(speeds), np.log(means), 1)[0])
    root = np.sqrt(speeds)
    a = float((means * root).sum() / (root * root).sum())
    return {"exponent": exponent, "a": a, "max_dev": float(np.abs(means - a * root).max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speeds", default="10,25,63,160")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--thickness", type=float, default=3.0)
    ap.add_argument("--material", default="plexiglas")
    ap.add_argument("--sim-faces", type=int, default=None)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--picture", type=Path, default=None)
    ap.add_argument("--mesh", type=Path, default=None)
    ap.add_argument("--point", default=None)
    args = ap.parse_args()
    point = CENTRE if args.point is None else tuple(float(c) for c in args.point.split(","))
    speeds = [float(v) for v in args.speeds.split(",")]
    seeds = [int(s) for s in args.seeds.split(",")]
    rows, pictures = [], []
    with tempfile.TemporaryDirectory() as tmp:
        path = args.mesh or plate_obj(Path(tmp) / "plate.obj", 4, uv_margin=0.0)
        for v in speeds:
            law = radial_cracks(v, args.thickness, args.material)
            arms, secs = [], []
            for s in seeds:
                network, sim, seconds = solve_speed(path, v, s, args.thickness, args.material,
                                                    args.sim_faces, point)
                arms.append(arms_of(network, sim if args.mesh else None))
                secs.append(seconds)
                if args.picture is not None and s == seeds[0]:
                    from bench_glass import draw

                    imp = network.impacts[0]
                    pictures.append(draw(f"{v:g} m/s: {arms[-1]} arms (law {law:.1f})", network,
                                         np.asarray(imp["point"]),
                                         impact_reach(imp["radius"]), sim))
            row = {"speed": v, "law": law, "arms": arms, "mean": float(np.mean(arms)),
                   "std": float(np.std(arms)), "seconds": float(np.mean(secs)),
                   "sim_faces": len(sim.faces)}
            rows.append(row)
            print(f"V {v:7.1f} m/s  law {law:5.2f}  arms {arms}  mean {row['mean']:5.2f} "
                  f"+- {row['std']:4.2f}  {row['seconds']:5.1f} s/solve  "
                  f"({row['sim_faces']} sim faces)", flush=True)
    sp = np.array([r["speed"] for r in rows])
    means = np.array([r["mean"] for r in rows])
    f = fit(sp, means) if len(set(speeds)) > 1 else {}
    if f:
        print(f"{args.material} {args.thickness:g} mm, seeds {seeds}: fitted exponent "
              f"{f['exponent']:.3f} (law 0.5); N = {f['a']:.3f} sqrt(V), largest deviation of "
              f"a mean {f['max_dev']:.2f} arms")
    if sp.max() / sp.min() == 16.0:
        print(f"N(16V)/N(V) = {means[np.argmax(sp)] / means[np.argmin(sp)]:.2f} (law 4)")
    if pictures:
        from PIL import Image

        size = pictures[0].size[0]
        sheet = Image.new("RGB", (size * len(pictures), size), "white")
        for i, im in enumerate(pictures):
            sheet.paste(im, (i * size, 0))
        sheet.save(args.picture, optimize=True)
    if args.json is not None:
        args.json.write_text(json.dumps({"rows": rows, "fit": f}, indent=1))


if __name__ == "__main__":
    main()
