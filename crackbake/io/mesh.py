"""Loading asset meshes and deriving the welded copy used for topology.

The asset mesh keeps its UV seams (vertices are split where UVs differ); that is the mesh the
textures are baked for and the mesh written to the GLB.  Anything topological (adjacency,
geodesic distances, the simulation mesh) works on :func:`weld_by_position`'s copy, so UV seams
never cut cracks or stress.

OBJ files are read by :mod:`crackbake.io.obj_reader` (numpy, the arrays trimesh would give);
trimesh reads the other formats and the OBJ files that reader leaves to it.
"""

from __future__ import annotations

import io
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from crackbake.errors import CrackbakeError, CrackbakeWarning
from crackbake.geometry import face_cross_numpy, welded_vertex_normals
from crackbake.io import obj_checks, obj_reader
from crackbake.io.safe_open import check_regular, open_regular, read_bytes

__all__ = ["SUPPORTED_SUFFIXES", "VERTEX_COLOURS", "Mesh", "load_mesh"]

SUPPORTED_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
# Key of the vertex colours in :attr:`Mesh.attributes` (also how error messages list them).
VERTEX_COLOURS = "(vertex colours)"
# Largest vertex coordinate: the bake uploads positions as 32-bit floats (max 3.4e38), and
# squared lengths of bigger ones overflow even in float64 sums.
COORDINATE_MAX = 1e38
#: Meshes with this many faces or more get their face cross products and vertex normals from
#: numba kernels (the same arrays): at 1.5M faces numpy's passes cost more than numba's import.
JIT_FACES = 200_000
# PLY vertex properties that are geometry, not painted attributes.
_PLY_GEOMETRY = {"x", "y", "z", "nx", "ny", "nz"}


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh as loaded, with its own UVs when it has them.

    Attributes
    ----------
    vertices : (V, 3) float64
        Positions, mesh units.
    faces : (F, 3) int64
        Counter-clockwise triangles indexing ``vertices``.
    uv : (V, 2) float64 or None
        Per-vertex texture coordinates, ``v`` pointing up (OBJ/Blender convention); vertices are
        split at UV seams.  ``None`` when the file has none.
    normals : (V, 3) float64
        Unit vertex normals (the file's own where present, else area-weighted).
    source : str
        Path the mesh was read from.
    name : str
        Object name (file stem, or the picked/concatenated object names).
    attributes : dict of str to (V, ...) array
        Per-vertex attributes read with the mesh, in the file's dtype, rows aligned with
        ``vertices``: PLY vertex properties other than position and normal, glTF custom
        attributes (names as stored, e.g. ``_NAME``), and the vertex colours (RGBA) under
        :data:`VERTEX_COLOURS`.  Only attributes every concatenated object has are kept.
    objects : int
        How many objects of the file were concatenated into this mesh.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None
    normals: np.ndarray
    source: str = ""
    name: str = "mesh"
    attributes: dict[str, np.ndarray] = field(default_factory=dict)
    objects: int = 1

    @property
    def bbox_min(self) -> np.ndarray:
        return self.vertices.min(axis=0)

    @property
    def bbox_max(self) -> np.ndarray:
        return self.vertices.max(axis=0)

    @property
    def diagonal(self) -> float:
        """Bounding-box diagonal, mesh units."""
        return float(np.linalg.norm(self.bbox_max - self.bbox_min))

    def describe(self) -> dict:
        """Counts, bounding box and UV presence, for reports and the sidecar."""
        return {
            "source": self.source,
            "vertices": int(len(self.vertices)),
            "faces": int(len(self.faces)),
            "bbox_min": [float(x) for x in self.bbox_min],
            "bbox_max": [float(x) for x in self.bbox_max],
            "has_uv": self.uv is not None,
        }


@dataclass
class _Geometry:
    """One object of a mesh file, whichever reader read it: the arrays :func:`load_mesh`
    stacks."""

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None
    normals: np.ndarray | None
    attributes: dict[str, np.ndarray]
    #: (positions, index): the OBJ reader's ``v`` lines and each vertex's line, for welding.
    source: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def of_trimesh(cls, geom) -> _Geometry:
        return cls(np.asarray(geom.vertices, dtype=np.float64),
                   np.asarray(geom.faces, dtype=np.int64), _uv_of(geom), _file_normals(geom),
                   _vertex_attributes(geom))  # fmt: skip

    @classmethod
    def of_obj(cls, part: obj_reader.ObjPart) -> _Geometry:
        return cls(part.vertices, part.faces, part.uv, _unit_normals(part.normals), {},
                   (part.positions, part.source))  # fmt: skip


def _scene_items(scene) -> list[tuple[str, str, _Geometry]]:
    """(node name, geometry name, geometry) of a trimesh scene's meshes, transforms applied."""
    import trimesh

    # dump() applies the node transforms; geometry names survive in metadata.
    items = []
    for node in scene.graph.nodes_geometry:
        transform, geom_name = scene.graph[node]
        geom = scene.geometry[geom_name]
        if not isinstance(geom, trimesh.Trimesh):
            continue
        geom = _Geometry.of_trimesh(geom.copy().apply_transform(transform))
        items.append((str(node), str(geom_name), geom))
    return items


def _scene_geometries(items: list, object_name: str | None, path: Path) -> list[_Geometry]:
    """The geometries of a scene's ``items`` that ``object_name`` picks (all without it)."""
    if not items:
        return []
    if object_name is not None:
        picked = [g for node, gname, g in items if object_name in (node, gname)]
        if not picked:
            names = ", ".join(sorted({n for n, _, _ in items} | {g for _, g, _ in items}))
            raise CrackbakeError(
                f"{path}: no object named '{object_name}'; objects in the file: {names}"
            )
        return picked
    if len(items) > 1:
        warnings.warn(
            f"{path.name} holds {len(items)} meshes; concatenating them "
            "(use --object NAME to pick one)",
            CrackbakeWarning,
            stacklevel=3,
        )
    return [g for _, _, g in items]


def _resolver(path: Path, allow_outside: bool):
    """trimesh's resolver for the files a mesh names (MTL, textures, glTF buffers), reading
    only regular files, bounded by their size, inside the mesh's folder unless
    ``allow_outside`` (trimesh refuses escapes too, but would block on a FIFO or read a
    device forever)."""
    import trimesh

    class Resolver(trimesh.resolvers.FilePathResolver):
        def get(self, name: str) -> bytes:
            # trimesh's own candidates: the name, without a leading /, the bare file name
            for candidate in (name.strip(), name.strip().lstrip("/"), os.path.split(name)[-1]):
                try:
                    found = self.absolute(candidate)
                except ValueError:
                    continue
                if found.exists():
                    try:
                        return read_bytes(found, label=f"{path.name}: '{name}'")
                    except CrackbakeError as exc:  # an OSError: trimesh skips bad materials
                        raise _Refused(exc) from None
            try:
                self.absolute(name)
            except ValueError:
                raise _Refused(CrackbakeError(
                    f"{path}: names '{name}', which lies outside the mesh's folder; move it "
                    "beside the mesh or pass --allow-outside-textures"
                )) from None
            raise FileNotFoundError(name)

    return Resolver(str(path), allow_anywhere=allow_outside)


class _Refused(OSError):
    """A file the mesh names that the resolver will not read (trimesh skips a material it
    cannot read; a glTF buffer fails the load with ``error``'s message)."""

    def __init__(self, error: CrackbakeError) -> None:
        super().__init__(str(error))
        self.error = error


def _read_file(path: Path, allow_outside: bool = False):
    """The trimesh object of a mesh file (for most OBJ files, :func:`obj_reader.read_obj`'s
    parts), after the path and format checks."""
    if not path.exists():
        raise CrackbakeError(f"{path}: file not found; check the path")
    if path.is_dir():
        raise CrackbakeError(f"{path}: is a directory; pass a mesh file")
    check_regular(path)  # a FIFO would block the read forever, /dev/zero never ends
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise CrackbakeError(
            f"{path}: unsupported format '{suffix or '(none)'}'; "
            f"use one of {', '.join(s[1:].upper() for s in SUPPORTED_SUFFIXES)}"
        )
    if path.stat().st_size == 0:  # trimesh's readers fail on no bytes with AttributeErrors
        raise CrackbakeError(f"{path}: the file is empty, so it holds no triangles; crackbake "
                             "needs a triangle mesh (export it again)")
    data, short_faces = None, 0
    if suffix == ".obj":
        data = _read_bytes(path)
        checked, scan = obj_checks.prepare_obj_scan(data, path)
        short_faces = scan.short_faces
        parts = obj_reader.read_obj(checked, scan, path, allow_outside)
        if parts is not None:  # the common case, without importing trimesh
            return parts, checked, short_faces
        source = str(path) if checked is data else io.BytesIO(checked)
        data = checked
    else:
        with open_regular(path) as fh:
            head = fh.read(len(obj_checks.BOM))
        # A byte-order mark hides the first token of text formats from trimesh.
        source = io.BytesIO(_read_bytes(path)[len(head):]) if head == obj_checks.BOM else str(path)
    import trimesh  # after the checks: a wrong path or a bad OBJ line fails before the import

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # numpy on corrupt numbers
            # From bytes too, the resolver finds materials and buffers beside the file.
            loaded = trimesh.load(
                source, file_type=suffix[1:], process=False,
                resolver=_resolver(path, allow_outside),
            )  # fmt: skip
    except _Refused as exc:
        raise exc.error from None
    except Exception as exc:  # trimesh raises many types for corrupt input
        known = obj_checks.explain_bad_index(data, path) if data is not None else None
        if known is not None:
            raise known from exc
        raise CrackbakeError(
            f"{path}: could not read the {suffix[1:].upper()} file "
            f"({type(exc).__name__}: {_one_line(exc)}); check that it is a valid mesh"
        ) from exc
    return loaded, data, short_faces


def _read_bytes(path: Path) -> bytes:
    try:
        return read_bytes(path)
    except OSError as exc:
        raise CrackbakeError(f"{path}: cannot read the file ({exc.strerror}); check it") from exc


def _one_line(exc: Exception, limit: int = 160) -> str:
    """An exception's text on one line, shortened (trimesh messages can span lines)."""
    text = " ".join(str(exc).split()) or "no details"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _stack(geoms: list, uvs: list, keep_uv: bool, path: Path):
    """Vertices (V, 3) and faces (F, 3) of the objects concatenated and checked, with the
    per-object UV and file-normal parts."""
    vertices, faces, uv_parts, normal_parts = [], [], [], []
    offset = 0
    for g, u in zip(geoms, uvs, strict=True):
        vertices.append(g.vertices)
        faces.append(g.faces + offset if offset else g.faces)
        offset += len(g.vertices)
        if keep_uv:
            uv_parts.append(u)
        normal_parts.append(g.normals)
    if len(geoms) == 1 and geoms[0].source is not None:
        # the OBJ reader's own arrays, made for this mesh: no copies (100 MB at 1.5M faces)
        vertices, faces = vertices[0], faces[0]
    else:
        vertices = np.concatenate(vertices)
        faces = np.concatenate(faces)

    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices).all(axis=1)).sum())
        raise CrackbakeError(
            f"{path}: {bad} vert{'ices have' if bad != 1 else 'ex has'} NaN or infinite "
            "coordinates; repair the mesh first"
        )
    biggest = float(np.abs(vertices).max(initial=0.0))
    if biggest > COORDINATE_MAX:
        raise CrackbakeError(
            f"{path}: vertex coordinates reach {biggest:.3g}, beyond the {COORDINATE_MAX:g} the "
            "GPU bake's 32-bit floats hold; scale the mesh down (or re-export it in larger units)"
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise CrackbakeError(f"{path}: faces index missing vertices; repair the mesh first")
    return vertices, faces, uv_parts, normal_parts


def load_mesh(
    path: str | Path, object_name: str | None = None, allow_outside_textures: bool = False
) -> Mesh:
    """Load a triangle mesh from OBJ, PLY, STL, OFF, glTF or GLB.

    Quads and polygons are triangulated, a scene with several meshes is concatenated (with a
    warning) unless ``object_name`` picks one, and UVs are kept with their seams.

    Parameters
    ----------
    path : str or Path
        Mesh file.
    object_name : str, optional
        Node or geometry name to pick from a multi-object file.
    allow_outside_textures : bool
        Let the file's material libraries, textures and glTF buffers lie outside its folder
        (refused by default: an asset from elsewhere must not make crackbake read any file).

    Raises
    ------
    CrackbakeError
        Missing file, unsupported format, unreadable file, no triangles, non-finite vertices.
    """
    path = Path(path)
    # is_file() is true of regular files only: a FIFO or device goes on to _read_file's refusal.
    if path.suffix.lower() == ".ply" and path.is_file() and _declares_strips(path):
        loaded, obj_text, short_faces = _strip_mesh(path), None, 0
    else:
        loaded, obj_text, short_faces = _read_file(path, allow_outside_textures)
    fast = isinstance(loaded, list)
    if fast:  # obj_reader's parts: one mesh, or a scene's geometries
        parts = [_Geometry.of_obj(p) for p in loaded]
        single = len(parts) == 1
        if not single:
            items = [(p.name, p.name, g) for p, g in zip(loaded, parts, strict=True)]
            geoms = _scene_geometries(items, object_name, path)
    else:
        import trimesh  # loaded by the reader by now

        single = isinstance(loaded, trimesh.Trimesh)
        if isinstance(loaded, trimesh.Scene):
            geoms = _scene_geometries(_scene_items(loaded), object_name, path)
        elif single:
            parts = [_Geometry.of_trimesh(loaded)]
        else:
            geoms = []
    if single:
        if object_name is not None:
            warnings.warn(
                f"{path.name} holds a single mesh; --object '{object_name}' ignored",
                CrackbakeWarning,
                stacklevel=2,
            )
        geoms = parts
    geoms = [g for g in geoms if len(g.faces) > 0]
    if obj_text is not None:
        obj_checks.warn_dropped_faces(short_faces, sum(len(g.faces) for g in geoms), path)
    if not geoms:
        kind = type(loaded).__name__
        what = "a point cloud" if kind == "PointCloud" else "no triangles"
        held = _ply_elements(loaded) if path.suffix.lower() == ".ply" else ""
        if held:
            what = f"{what} ({held}; no faces or triangle strips)"
        raise CrackbakeError(f"{path}: the file holds {what}; crackbake needs a triangle mesh")

    uvs = [g.uv for g in geoms]
    keep_uv = all(u is not None for u in uvs)
    if not keep_uv and any(u is not None for u in uvs):
        warnings.warn(
            f"{path.name}: only some objects have UVs; ignoring them all (the mesh will be "
            "unwrapped). Use --object to pick one",
            CrackbakeWarning,
            stacklevel=2,
        )

    vertices, faces, uv_parts, normal_parts = _stack(geoms, uvs, keep_uv, path)

    if keep_uv and len(geoms) == 1 and geoms[0].source is not None:
        uv = uv_parts[0]  # the OBJ reader's own array, as the vertices
    else:
        uv = np.concatenate(uv_parts) if keep_uv else None
    if uv is not None and not np.isfinite(uv).all():
        bad = ~np.isfinite(uv)
        what = " and ".join(w for w, hit in (("NaN", np.isnan(uv).any()),
                                             ("infinite values", np.isinf(uv).any())) if hit)
        warnings.warn(
            f"{path.name}: {int(bad.any(axis=1).sum())} UVs hold {what}; ignoring them all "
            "(the mesh will be unwrapped)",
            CrackbakeWarning,
            stacklevel=2,
        )
        uv = None
    # the reader reads UVs whenever every corner names a vt it has (else trimesh reads it)
    if uv is None and obj_text is not None and keep_uv is False and not fast:
        bad_vt = obj_checks.explain_bad_uv_index(obj_text)
        if bad_vt is not None:
            warnings.warn(
                f"{path.name}: {bad_vt}; ignoring every UV (the mesh will be unwrapped; fix "
                "the file to keep its UVs)",
                CrackbakeWarning,
                stacklevel=2,
            )

    # numpy's cross below JIT_FACES: numba's import and first call cost more than it saves
    jit = len(faces) >= JIT_FACES
    if jit:
        from crackbake.geometry_kernels import face_cross_kernel
        from crackbake.jit import light_cache_loads

        light_cache_loads()  # numba's cache loads without its compiler's set-up
        cross = face_cross_kernel(vertices, faces)
    else:
        cross = face_cross_numpy(vertices, faces)
    if all(n is not None for n in normal_parts):
        normals = np.concatenate(normal_parts)
    else:
        source = None
        if all(g.source is not None for g in geoms):  # one file's v lines: weld those
            source = (geoms[0].source[0], np.concatenate([g.source[1] for g in geoms]))
        normals = welded_vertex_normals(vertices, faces, cross, source, jit)

    if jit:
        from crackbake.geometry_kernels import area_counts

        n_positive, n_degenerate = area_counts(cross)
    else:
        area2 = np.linalg.norm(cross, axis=1)
        n_positive, n_degenerate = int((area2 > 0).sum()), int((area2 <= 0).sum())
    if not n_positive:
        raise CrackbakeError(f"{path}: every face has zero area; crackbake needs a surface")
    if n_degenerate:
        warnings.warn(
            f"{path.name}: {n_degenerate} zero-area faces (they get no texels)",
            CrackbakeWarning,
            stacklevel=2,
        )

    name = object_name if object_name is not None else path.stem
    return Mesh(
        vertices=vertices,
        faces=faces,
        uv=uv,
        normals=normals,
        source=str(path),
        name=name,
        attributes=_concatenate_attributes([g.attributes for g in geoms]),
        objects=len(geoms),
    )


def _ply_elements(loaded) -> str:
    """What a PLY file holds, for the error message: each element trimesh read, with its count
    and properties."""
    raw = (getattr(loaded, "metadata", None) or {}).get("_ply_raw", {})
    if not isinstance(raw, dict) or not raw:
        return ""
    parts = []
    for name, element in raw.items():
        count = element.get("length", 0) if isinstance(element, dict) else 0
        props = list(element.get("properties", {})) if isinstance(element, dict) else []
        parts.append(f"{count} '{name}' ({', '.join(props) or 'no properties'})")
    return "the elements " + "; ".join(parts)


def _declares_strips(path: Path) -> bool:
    """Whether the PLY file declares triangle strips (the reader is imported for PLY files
    only: it is part of the imports before a run's first stage)."""
    from crackbake.io import ply_strips

    return ply_strips.declares_strips(path)


def _strip_mesh(path: Path):
    """A triangle-strip PLY as a trimesh, its raw vertex properties kept as trimesh keeps them."""
    import trimesh

    from crackbake.io import ply_strips

    vertices, props, faces = ply_strips.read_strip_ply(path)
    metadata = {"_ply_raw": {"vertex": {"data": props}}}
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False, metadata=metadata)


def _uv_of(geom) -> np.ndarray | None:
    uv = getattr(geom.visual, "uv", None)
    if uv is None or len(uv) != len(geom.vertices):
        return None
    return np.asarray(uv, dtype=np.float64)


def _file_normals(geom) -> np.ndarray | None:
    # trimesh keeps a file's vertex normals in its cache; computing them ourselves would weld
    # across seams anyway, so only trust explicit ones of the right shape.
    n = geom._cache.cache.get("vertex_normals") if hasattr(geom, "_cache") else None
    if n is None or len(n) != len(geom.vertices):
        return None
    return _unit_normals(n)


def _unit_normals(n: np.ndarray | None) -> np.ndarray | None:
    """A file's vertex normals scaled to unit length; None where any is not finite or zero."""
    if n is None:
        return None
    n = np.asarray(n, dtype=np.float64)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    if not np.isfinite(n).all() or (length < 1e-12).any():
        return None
    return n / length


def _vertex_attributes(geom) -> dict[str, np.ndarray]:
    """Per-vertex attributes of one trimesh geometry, one row per vertex, the file's dtype.

    trimesh's own ``vertex_attributes`` (glTF custom attributes) win over the raw PLY
    properties of the same name; vertex colours are stored under :data:`VERTEX_COLOURS`.
    """
    n = len(geom.vertices)
    out: dict[str, np.ndarray] = {}
    raw = (geom.metadata or {}).get("_ply_raw", {}).get("vertex", {}).get("data", {})
    if isinstance(raw, np.ndarray) and raw.dtype.names:  # a binary PLY's rows
        raw = {name: raw[name] for name in raw.dtype.names}
    if isinstance(raw, dict):
        for key in set(raw) - _PLY_GEOMETRY:
            out[key] = np.asarray(raw[key])
    for key, values in (getattr(geom, "vertex_attributes", {}) or {}).items():
        out[key] = np.asarray(values)
    if getattr(geom.visual, "kind", None) == "vertex":
        out[VERTEX_COLOURS] = np.asarray(geom.visual.vertex_colors)
    return {k: v for k, v in out.items() if v.ndim >= 1 and len(v) == n}


def _concatenate_attributes(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The attributes every object has, stacked in object order (those that do not stack are
    left out)."""
    if len(parts) == 1:
        return parts[0]
    out = {}
    for key in set.intersection(*(set(p) for p in parts)):
        try:
            out[key] = np.concatenate([p[key] for p in parts])
        except ValueError:  # different trailing shapes: not one attribute
            continue
    return out
