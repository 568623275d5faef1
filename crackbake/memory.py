"""Peak memory of a run, estimated before the heavy stages, and the memory the run may use.

The estimate is a linear model of the sizes that drive memory, fitted to measured runs
(``benchmarks/bench_memory.py``: peak RSS of fresh ``crackbake`` processes while one size at a
time varies)::

    peak = BASE + PER_FACE * faces + PER_SIM_FACE * sim_faces
           + PER_TEXEL * res**2 + PER_GL_TEXEL * min(res, tile)**2
           + PER_STRESS_TEXEL * stress_res**2 + PER_DECAL_TEXEL * decal_res**2
           + PER_FRAME_TEXEL * res**2 (with --frames)

and, where the run unwraps with xatlas, the larger of that and the unwrap's own peak::

    BASE + PER_FACE * faces + XATLAS_BASE + XATLAS_PER_FACE * faces

xatlas runs in a child process (:mod:`crackbake.bake.xatlas_worker`) while the run waits for
it, before the solver and the bake: the two processes' peaks add up (a cgroup or the physical
memory holds both), but only with what the run holds at that point (the interpreter, the GL
context, the mesh), not with the later stages, whose arrays do not exist yet.

The crack-map terms are split because the bake draws in bands of at most ``tile**2`` texels: the
GL targets (about 70 bytes a texel) stop growing at the tile while the maps in numpy keep
growing with ``res**2``.  The stress bake's bands are small whatever the tile (measured: the
same peak at tile 1024 and 4096), so it has one term.  Over the 15 measured runs the model is
within -10 %..+17 % of the peak RSS (docs/memory.md); adding the stages' shares errs on the
safe side where they do not overlap (the solver's arrays are freed before the bake peaks).

:func:`estimate_peak` is the model alone (the batch's Ray ``memory`` requests call it with the
job's sizes); :func:`check_memory` compares it with :func:`available_memory` (the cgroup limit,
``RLIMIT_AS`` or the physical memory) and refuses a run that cannot fit with one line naming the
estimate, the limit and the option to lower.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from crackbake.errors import CrackbakeError
from crackbake.memory_limit import ADDRESS_OVERHEAD, available_memory, cgroup_limit
from crackbake.params import DECAL_RES_DEFAULT, STRESS_RES_DEFAULT, TILE_DEFAULT

__all__ = ["MemoryEstimate", "available_memory", "cgroup_limit", "check_memory", "estimate_peak",
           "run_sizes"]

GIB = 2**30
# Bytes, least-squares fit of benchmarks/bench_memory.py's 15 runs (docs/memory.md), rounded up.
BASE = 0.35 * GIB
PER_FACE = 670.0
PER_SIM_FACE = 960.0
PER_TEXEL = 59.0
# The GL targets' fit (71 B) plus the 32-bit depth buffer the bake's surface pass has written
# since (it lets llvmpipe skip texels off the faces), added rather than re-fitted.
PER_GL_TEXEL = 75.0
PER_STRESS_TEXEL = 85.0
#: --decal: one projector bake at a time, after the asset's maps (which stay in memory): spot,
#: --res 1024, --decal-res 4096 peaked 1.84 GB above the same run without a decal (110 B/texel).
PER_DECAL_TEXEL = 115.0
#: --frames: the frames are thresholded from the maps already baked and written a few at a time
#: (whatever N): spot glass at --res 2048 with --frames 16 peaked 73 MB higher (17 B/texel).
PER_FRAME_TEXEL = 20.0
#: The unwrap's share (``benchmarks/bench_unwrap.py --memory``: scan-like meshes of 20k to 270k
#: faces, docs/memory.md): the xatlas child's peak RSS fits 149 MB + 428 B a face (its
#: interpreter, numpy and xatlas, then the atlas's per-face data), and the run's own pipe
#: buffers and results grow by 196 B a face while it waits; rounded up.  Under ``make test``
#: (another numba cache, more imports warm) a 40k-face child peaked at 216 MB, above the fit's
#: 166 MB: the base is 0.21 GiB so that the model stays an upper bound.
XATLAS_BASE = 0.21 * GIB
XATLAS_PER_FACE = 700.0
#: Share of a cgroup or physical limit a run may plan to use: the model's error, the page cache
#: and other processes.  An address-space cap is the process's own, and the overhead above is
#: already the largest measured, so the whole cap counts.
HEADROOM = 0.9


@dataclass(frozen=True)
class MemoryEstimate:
    """A run's estimated peak memory, bytes.

    Attributes
    ----------
    rss : int
        Peak resident memory (what a cgroup limit or the physical memory must hold): the run's
        stages, or the xatlas unwrap (the run so far plus its child) where that is larger.
    parts : dict of str to int
        The terms of the model: ``base``, ``mesh``, ``sim``, ``bake``, ``stress``, ``decal``,
        ``frames``, ``xatlas`` (the child's peak; not part of the stages' sum).
    """

    rss: int
    parts: dict[str, int] = field(default_factory=dict)

    @property
    def address_space(self) -> int:
        """Peak address space of one process (what ``RLIMIT_AS``, which each process has
        alone, must allow): the run's, or the xatlas child's where larger."""
        return int(max(self.stages, self.parts.get("xatlas", 0)) + ADDRESS_OVERHEAD)

    @property
    def stages(self) -> int:
        """Peak of the run's own process: the stages' sum."""
        return sum(v for k, v in self.parts.items() if k != "xatlas")

    @property
    def unwrap_peak(self) -> int:
        """Run and xatlas child together while the unwrap runs (0 without an unwrap)."""
        child = self.parts.get("xatlas", 0)
        return self.parts.get("base", 0) + self.parts.get("mesh", 0) + child if child else 0

    @property
    def largest(self) -> str:
        """The part that weighs most: which option to lower."""
        if self.unwrap_peak > self.stages:
            return "xatlas"
        return max((k for k in self.parts if k not in ("base", "xatlas")),
                   key=self.parts.__getitem__)  # fmt: skip


def estimate_peak(faces: int, sim_faces: int, res: int, stress_res: int | None = None,
                  tile: int = TILE_DEFAULT, decal_res: int | None = None,
                  frames: int = 0, unwrap_faces: int = 0) -> MemoryEstimate:
    """Estimated peak memory of a run from its sizes.

    Parameters
    ----------
    faces : int
        Faces of the asset mesh.
    sim_faces : int
        Faces of the simulation mesh (the ``--sim-faces`` target, or the asset's own faces
        where it is finer and no proxy stands in).
    res : int
        Texels per side of the crack maps (``--res``).
    stress_res : int or None
        Texels per side of the stress maps; None when they are not written.
    tile : int
        Largest framebuffer edge of a bake pass (``--tile``).
    decal_res : int or None
        Texels per side of the projected decals (``--decal``); None when none is baked.
    frames : int
        ``--frames N``: the growth frames (their cost does not grow with N).
    unwrap_faces : int
        Faces xatlas unwraps (0: the run keeps the mesh's UVs).

    Returns
    -------
    MemoryEstimate
    """
    gl = min(res, tile) ** 2
    parts = {
        "base": BASE,
        "mesh": PER_FACE * faces,
        "sim": PER_SIM_FACE * sim_faces,
        "bake": PER_TEXEL * res * res + PER_GL_TEXEL * gl,
        "stress": PER_STRESS_TEXEL * stress_res**2 if stress_res else 0.0,
        "decal": PER_DECAL_TEXEL * decal_res**2 if decal_res else 0.0,
        "frames": PER_FRAME_TEXEL * res * res if frames else 0.0,
    }
    if unwrap_faces:
        parts["xatlas"] = XATLAS_BASE + XATLAS_PER_FACE * unwrap_faces
    parts = {k: int(v) for k, v in parts.items()}
    est = MemoryEstimate(rss=0, parts=parts)
    return MemoryEstimate(rss=max(est.stages, est.unwrap_peak), parts=parts)


def run_sizes(params, mesh=None, faces: int | None = None) -> dict:
    """The keyword arguments of :func:`estimate_peak` for a run.

    Parameters
    ----------
    params : RunParams
        Resolved (:meth:`RunParams.resolved`) or not: an unset ``sim_faces`` counts as the
        default.
    mesh : Mesh, optional
        The loaded asset: its face count, and its area for ``--detail``.
    faces : int, optional
        The asset's face count when the mesh is not loaded (a batch planning its jobs).
    """
    from crackbake.params import SIM_FACES_DEFAULT

    faces = len(mesh.faces) if mesh is not None else int(faces or 0)
    if params.cracks is not None:
        sim = 0  # a re-bake solves nothing (nor imports the sim-mesh modules)
    else:
        from crackbake.simulate.simmesh.proxy import proxy_limit

        wanted = params.sim_faces or SIM_FACES_DEFAULT
        if params.detail is not None and mesh is not None:
            from crackbake.geometry import face_cross

            area = 0.5 * float(np.linalg.norm(face_cross(mesh.vertices, mesh.faces), axis=1).sum())
            wanted = area / (0.25 * np.sqrt(3.0) * params.detail**2)  # equilateral triangles
        limit = {"auto": proxy_limit(wanted), "always": 0}.get(params.sim_proxy, faces)
        # Refinement never coarsens: an asset finer than wanted is its own sim mesh, unless a
        # proxy of the wanted size stands in for it.
        sim = int(wanted if faces > limit else max(wanted, faces))
    stress = None
    if "stress" in params.formats and params.cracks is None:
        stress = params.stress_res or min(params.res, STRESS_RES_DEFAULT)
    decal = None
    if params.decal is not None:
        decal = params.decal_res or min(params.res, DECAL_RES_DEFAULT)
    # --uv auto unwraps a mesh without UVs (and one whose UVs are unusable, which only the UV
    # check finds: counted as kept).  A cached unwrap runs no child, but may be gone by then.
    no_uv = mesh is not None and getattr(mesh, "uv", None) is None
    unwrapping = params.uv == "unwrap" or (params.uv == "auto" and no_uv)
    return {"faces": faces, "sim_faces": sim, "res": params.res, "stress_res": stress,
            "tile": params.tile, "decal_res": decal, "frames": int(params.frames or 0),
            "unwrap_faces": faces if unwrapping else 0}


_LOWER = {
    "bake": "--res",
    "stress": "--stress-res (or drop stress from --formats)",
    "decal": "--decal-res",
    "frames": "--res (the frames are --res wide)",
    "sim": "--sim-faces (or a larger --detail)",
    "mesh": "the mesh's face count (decimate it)",
    "xatlas": "the mesh's face count (decimate it; xatlas unwraps in a second process), or keep "
              "your own UVs (--uv keep)",
}


def check_memory(estimate: MemoryEstimate, max_memory: float | None = None) -> None:
    """Refuse a run whose estimated peak does not fit the memory it may use.

    Parameters
    ----------
    estimate : MemoryEstimate
    max_memory : float, optional
        ``--max-memory``: GiB the run may use, in place of the detected limit (a larger value
        lets a run the estimate refuses go ahead).

    Raises
    ------
    CrackbakeError
        One line: the estimate, the limit and where it comes from, the option to lower.
    """
    if max_memory is not None:
        limit, source, address = int(max_memory * GIB), "--max-memory", False
        need = estimate.rss
        room = limit
    else:
        limit, source, address = available_memory()
        need = estimate.address_space if address else estimate.rss
        room = limit if address else HEADROOM * limit
    if need <= room:
        return
    shares = {**estimate.parts, **({"libraries": ADDRESS_OVERHEAD} if need > estimate.rss else {})}
    if estimate.largest == "xatlas":  # the unwrap's peak: the run so far and its child
        shares = {k: v for k, v in shares.items() if k in ("base", "mesh", "xatlas", "libraries")}
    else:
        shares.pop("xatlas", None)
    parts = ", ".join(f"{k} {v / GIB:.1f}" for k, v in shares.items() if v >= 0.05 * GIB)
    space = " of address space" if address else ""
    override = ("raise --max-memory" if max_memory is not None
                else "pass --max-memory GIB to run anyway")
    raise CrackbakeError(
        f"this run needs about {need / GIB:.1f} GiB{space} ({parts}) but {source} allows "
        f"{limit / GIB:.1f} GiB; lower {_LOWER[estimate.largest]}, or {override}"
    )
