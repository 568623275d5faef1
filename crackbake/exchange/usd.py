"""USD (``<stem>.usda``): the output mesh with a bound UsdPreviewSurface and MaterialX material.

Written with Pixar's ``pxr`` (the ``usd-core`` wheel, the ``usd`` extra).  The stage holds:

* ``/<stem>`` (Xform, ``kind = component``, the ``defaultPrim``) with the mesh ``/<stem>/mesh``,
  whose arrays are referenced from the binary layer ``<stem>_mesh.usdc`` beside it (as text a
  big mesh is slow and large to write): the asset's welded points (one per input vertex the
  faces use), its triangles, and face-varying indexed primvars ``st`` (the baked UVs, ``v``
  up), ``normals`` and ``tangents`` (float4, MikkTSpace ``xyz`` + bitangent sign ``w``, as
  the GLB's TANGENT).  ``subdivisionScheme = "none"``: the triangles are the surface the maps
  were baked on.
* ``/<stem>/Looks/crack_material``, bound with ``MaterialBindingAPI``:

  - ``outputs:surface``: a ``UsdPreviewSurface`` with diffuseColor from the base-colour PNG
    (``sRGB``), normal from the OpenGL normal map (``raw``, scale (2, 2, 2, 1), bias
    (-1, -1, -1, 0)), occlusion and roughness from the ORM map (``raw``), metallic 0, every
    texture read through one ``UsdPrimvarReader_float2`` of ``st``;
  - ``outputs:mtlx:surface``: a MaterialX ``standard_surface`` network of the same textures
    for renderers that prefer MaterialX;
  - ``crack_mask``, ``crack_width``, ``crack_depth``, ``crack_time``: ``UsdUVTexture`` readers
    of the 16-bit data map (``raw``, width and depth scaled back to mesh units) that no surface
    uses, for look-dev networks to connect.

Texture paths are relative to the layer (``./<file>``): the folder moves as a whole.  Asset paths
are plain strings here, so a UDIM set can later be named ``./<stem>_basecolor.<UDIM>.png``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from crackbake.errors import CrackbakeError

PathLike = str | os.PathLike

#: The install command named when ``pxr`` is missing.
INSTALL_HINT = "pip install 'crackbake[usd]' (the usd-core package)"


def require_pxr(fmt: str = "usd") -> None:
    """Raise a one-line :class:`CrackbakeError` naming ``--formats fmt`` when ``pxr``
    (usd-core) cannot be imported."""
    try:
        import pxr.Usd  # noqa: F401
    except ImportError as exc:
        raise CrackbakeError(
            f"--formats {fmt} needs Pixar's USD Python module (pxr), which is not installed; "
            f"run {INSTALL_HINT} or drop {fmt} from --formats"
        ) from exc


@dataclass(frozen=True)
class UsdTextures:
    """The PNGs the material reads, as file names in the layer's folder.

    Attributes
    ----------
    base_color : str
        sRGB base colour (RGB).
    normal : str
        Tangent-space normal, OpenGL (+Y), 8 or 16 bit, ``n * 0.5 + 0.5``.
    occlusion, roughness : (str, str)
        File and channel (``"r"``, ``"g"``, ...) of each; linear.
    data : str
        16-bit RGBA data map: R mask, G width / ``width_scale``, B depth / ``depth_scale``,
        A crack time.
    width_scale, depth_scale : float
        Mesh units of a full-range G and B value of ``data``.
    """

    base_color: str
    normal: str
    occlusion: tuple[str, str]
    roughness: tuple[str, str]
    data: str
    width_scale: float = 1.0
    depth_scale: float = 1.0


def welded(uvmesh) -> tuple[np.ndarray, np.ndarray]:
    """The output mesh with its seam splits undone: one point per input vertex it uses.

    Parameters
    ----------
    uvmesh : UVMesh
        ``vertices`` (V', 3) are ``mesh.vertices[vertex_map]``; seams and tangent splits
        repeat an input vertex.

    Returns
    -------
    points : (P, 3) float64
        Mesh units, in input-vertex order.
    face_points : (F, 3) int64
        Point of each face corner (the corners of ``uvmesh.faces``).
    """
    _, first, inverse = np.unique(
        np.asarray(uvmesh.vertex_map), return_index=True, return_inverse=True
    )
    points = np.asarray(uvmesh.vertices, np.float64)[first]
    return points, inverse.reshape(-1)[np.asarray(uvmesh.faces)]


def up_transform(up: np.ndarray) -> tuple[str, np.ndarray | None]:
    """The stage's ``upAxis`` for the mesh's up vector and, for an up USD cannot name
    (x, -x, -y, -z), the (3, 3) rotation (row-vector convention, USD's) taking it to +Y."""
    up = np.asarray(up, np.float64)
    if np.allclose(up, (0.0, 1.0, 0.0)):
        return "Y", None
    if np.allclose(up, (0.0, 0.0, 1.0)):
        return "Z", None
    from crackbake.bake.preview import _frame

    # _frame(up) @ +Y = up; as a row-vector matrix it is the transpose of the rotation back.
    return "Y", _frame(up)


def write_usd(
    path: PathLike,
    name: str,
    uvmesh,
    textures: UsdTextures,
    up: np.ndarray = (0.0, 1.0, 0.0),
    meters_per_unit: float = 1.0,
    doc: str = "",
    lookdev: bool = True,
    split: bool = True,
) -> str | None:
    """Write ``uvmesh`` and its material as a USD text layer and a binary geometry layer.

    The text layer ``path`` holds the stage metadata, the prims, the material and its binding;
    the mesh's arrays go into ``<path stem>_mesh.usdc`` beside it, referenced by the mesh prim
    (as text a 1M-face mesh took 14 s and 166 MB; as crate 1.3 s and 42 MB,
    ``benchmarks/bench_usd.py``).  Opening ``path`` composes both.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.usda`` file.
    name : str
        Root prim name (made a valid identifier).
    uvmesh : UVMesh
        The output mesh: ``vertices`` (V', 3), ``faces`` (F, 3) counter-clockwise, ``uv``
        (V', 2) ``v`` up, ``normals`` (V', 3), ``vertex_map`` (V',) and optional
        ``tangents`` (V', 4).
    textures : UsdTextures
        File names of the maps, relative to ``path``'s folder.
    up : (3,) float
        The mesh's up axis: ``+Y`` or ``+Z`` become ``upAxis``; any other axis is rotated to
        +Y by the root prim's transform.
    meters_per_unit : float
        Stage ``metersPerUnit`` (of both layers).
    doc : str
        The layer's ``doc`` string.
    lookdev : bool
        Also the MaterialX network and the crack-map readers (False: the UsdPreviewSurface
        network alone, what AR Quick Look reads).
    split : bool
        The mesh's arrays in the geometry layer (False: in ``path`` itself).

    Returns
    -------
    str or None
        The geometry layer's file name (None when not ``split``).
    """
    require_pxr()
    from pxr import Kind, Sdf, Tf, Usd, UsdGeom, UsdShade

    path = os.fspath(path)
    root_name = Tf.MakeValidIdentifier(name) or "crackbake"
    geometry = os.path.splitext(os.path.basename(path))[0] + "_mesh.usdc"
    axis, rotation = up_transform(np.asarray(up, np.float64))

    def new_stage(ext: str):
        layer = Sdf.Layer.CreateAnonymous(ext)
        stage = Usd.Stage.Open(layer)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if axis == "Y" else UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
        return layer, stage

    if split:
        geo_layer, geo_stage = new_stage(".usdc")
        mesh = _define_mesh(geo_stage, Sdf.Path("/mesh"), uvmesh)
        geo_stage.SetDefaultPrim(mesh.GetPrim())
        _export(geo_layer, os.path.join(os.path.dirname(path), geometry))

    layer, stage = new_stage(os.path.splitext(path)[1] or ".usda")
    if doc:
        layer.documentation = doc
    root = UsdGeom.Xform.Define(stage, Sdf.Path(f"/{root_name}"))
    Usd.ModelAPI(root.GetPrim()).SetKind(Kind.Tokens.component)
    stage.SetDefaultPrim(root.GetPrim())
    if rotation is not None:
        from pxr import Gf

        m = np.eye(4)
        m[:3, :3] = rotation
        root.AddTransformOp().Set(Gf.Matrix4d(m.tolist()))
    # The prim is defined here (its type readable without the geometry layer); its arrays come
    # from the reference, added to the layer once no stage composes it: an anonymous layer
    # cannot resolve the relative path, and the stage would warn that it tried.
    mesh_path = root.GetPath().AppendChild("mesh")
    if split:
        mesh_prim = UsdGeom.Mesh.Define(stage, mesh_path).GetPrim()
    else:
        mesh_prim = _define_mesh(stage, mesh_path, uvmesh).GetPrim()
    material = _define_material(stage, root.GetPath().AppendPath(Sdf.Path("Looks/crack_material")),
                                textures, lookdev)  # fmt: skip
    UsdShade.MaterialBindingAPI.Apply(mesh_prim).Bind(material)
    del mesh_prim, material, root, stage
    if not split:
        _export(layer, path)
        return None
    layer.GetPrimAtPath(mesh_path).referenceList.Prepend(Sdf.Reference(f"./{geometry}"))
    _export(layer, path)
    return geometry


def _export(layer, path: str) -> None:
    from pxr import Tf

    try:
        ok = layer.Export(path)
    except Tf.ErrorException as exc:
        ok, why = False, str(exc).strip().splitlines()[-1]
    else:
        why = "the USD library refused it"
    if not ok:
        raise CrackbakeError(
            f"cannot write USD '{path}': {why}; check the folder exists, is writable and has space"
        )


def _define_mesh(stage, path, uvmesh):
    from pxr import Sdf, UsdGeom, Vt

    points, corners = welded(uvmesh)
    faces = np.asarray(uvmesh.faces)
    if len(faces) == 0 or not np.all(np.isfinite(points)):
        raise CrackbakeError("USD export got an empty mesh or non-finite points; check the mesh")
    mesh = UsdGeom.Mesh.Define(stage, path)
    p32 = np.ascontiguousarray(points, np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(p32))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(corners.astype(np.int32).ravel()))
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([p32.min(0), p32.max(0)])))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)

    # Face-varying, indexed by the split vertex of each corner: seams keep their two UVs while
    # the points stay welded (subdivision and deformation see one surface).
    corner_ids = Vt.IntArray.FromNumpy(faces.astype(np.int32).ravel())
    api = UsdGeom.PrimvarsAPI(mesh.GetPrim())

    def primvar(name, type_name, values):
        pv = api.CreatePrimvar(name, type_name, UsdGeom.Tokens.faceVarying)
        pv.Set(values)
        pv.SetIndices(corner_ids)
        return pv

    primvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
            Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(uvmesh.uv, np.float32)))  # fmt: skip
    normals = np.asarray(uvmesh.normals, np.float64)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-12), (0.0, 0.0, 1.0))
    primvar("normals", Sdf.ValueTypeNames.Normal3fArray,
            Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(normals, np.float32)))  # fmt: skip
    tangents = getattr(uvmesh, "tangents", None)
    if tangents is not None:
        primvar("tangents", Sdf.ValueTypeNames.Float4Array,
                Vt.Vec4fArray.FromNumpy(np.ascontiguousarray(tangents, np.float32)))  # fmt: skip
    return mesh


def _asset(name: str):
    from pxr import Sdf

    return Sdf.AssetPath(f"./{name}")


def _define_material(stage, path, tex: UsdTextures, lookdev: bool = True):
    from pxr import Sdf, UsdShade

    T = Sdf.ValueTypeNames
    material = UsdShade.Material.Define(stage, path)

    def shader(name: str, shader_id: str):
        s = UsdShade.Shader.Define(stage, path.AppendChild(name))
        s.CreateIdAttr(shader_id)
        return s

    # --- UsdPreviewSurface -------------------------------------------------------------
    st = shader("st_reader", "UsdPrimvarReader_float2")
    st.CreateInput("varname", T.String).Set("st")
    st_out = st.CreateOutput("result", T.Float2)

    def texture(name, file, colorspace, outputs, scale=None, bias=None):
        s = shader(name, "UsdUVTexture")
        s.CreateInput("file", T.Asset).Set(_asset(file))
        s.CreateInput("st", T.Float2).ConnectToSource(st_out)
        s.CreateInput("sourceColorSpace", T.Token).Set(colorspace)
        s.CreateInput("wrapS", T.Token).Set("repeat")  # the GLB's REPEAT sampler
        s.CreateInput("wrapT", T.Token).Set("repeat")
        if scale is not None:
            s.CreateInput("scale", T.Float4).Set(scale)
        if bias is not None:
            s.CreateInput("bias", T.Float4).Set(bias)
        return {o: s.CreateOutput(o, T.Float3 if o == "rgb" else T.Float) for o in outputs}

    surface = shader("preview_surface", "UsdPreviewSurface")
    base = texture("base_color_texture", tex.base_color, "sRGB", ("rgb",))
    normal = texture("normal_texture", tex.normal, "raw", ("rgb",),
                     scale=(2.0, 2.0, 2.0, 1.0), bias=(-1.0, -1.0, -1.0, 0.0))  # fmt: skip
    surface.CreateInput("diffuseColor", T.Color3f).ConnectToSource(base["rgb"])
    surface.CreateInput("normal", T.Normal3f).ConnectToSource(normal["rgb"])
    surface.CreateInput("metallic", T.Float).Set(0.0)
    by_file: dict[str, list[tuple[str, str]]] = {}
    for slot, (file, channel) in (("occlusion", tex.occlusion), ("roughness", tex.roughness)):
        by_file.setdefault(file, []).append((slot, channel))
    for file, slots in by_file.items():  # one reader per file: an ORM map feeds both
        name = "_".join(slot for slot, _ in slots) + "_texture"
        outs = texture(name, file, "raw", tuple(dict.fromkeys(c for _, c in slots)))
        for slot, channel in slots:
            surface.CreateInput(slot, T.Float).ConnectToSource(outs[channel])
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    if not lookdev:
        return material

    # --- crack maps for look-dev (no surface reads them) -----------------------------------
    for name, channel, scale in (
        ("crack_mask", "r", 1.0),
        ("crack_width", "g", tex.width_scale),
        ("crack_depth", "b", tex.depth_scale),
        ("crack_time", "a", 1.0),
    ):
        s = float(scale)
        texture(name, tex.data, "raw", (channel,), scale=(s, s, s, s) if s != 1.0 else None)

    _materialx(material, shader, tex)
    return material


def _materialx(material, shader, tex: UsdTextures) -> None:
    """The MaterialX ``standard_surface`` network on ``outputs:mtlx:surface``."""
    from pxr import Sdf

    T = Sdf.ValueTypeNames
    st = shader("mtlx_st", "ND_geompropvalue_vector2")
    st.CreateInput("geomprop", T.String).Set("st")
    st_out = st.CreateOutput("out", T.Float2)

    def image(name, file, kind, colorspace=None):
        s = shader(name, f"ND_image_{kind}")
        f = s.CreateInput("file", T.Asset)
        f.Set(_asset(file))
        if colorspace:
            f.GetAttr().SetColorSpace(colorspace)
        s.CreateInput("texcoord", T.Float2).ConnectToSource(st_out)
        s.CreateInput("uaddressmode", T.String).Set("periodic")
        s.CreateInput("vaddressmode", T.String).Set("periodic")
        return s.CreateOutput("out", T.Color3f if kind == "color3" else T.Float3)

    def channel(name, source, index):
        s = shader(name, "ND_extract_vector3")
        s.CreateInput("in", T.Float3).ConnectToSource(source)
        s.CreateInput("index", T.Int).Set(index)
        return s.CreateOutput("out", T.Float)

    surf = shader("mtlx_standard_surface", "ND_standard_surface_surfaceshader")
    surf.CreateInput("base", T.Float).Set(1.0)
    surf.CreateInput("metalness", T.Float).Set(0.0)
    surf.CreateInput("base_color", T.Color3f).ConnectToSource(
        image("mtlx_base_color", tex.base_color, "color3", "srgb_texture")
    )
    nmap = shader("mtlx_normalmap", "ND_normalmap_float")
    nmap.CreateInput("in", T.Float3).ConnectToSource(
        image("mtlx_normal_image", tex.normal, "vector3")
    )
    surf.CreateInput("normal", T.Float3).ConnectToSource(nmap.CreateOutput("out", T.Float3))
    rough_file, rough_channel = tex.roughness
    surf.CreateInput("specular_roughness", T.Float).ConnectToSource(
        channel("mtlx_roughness", image("mtlx_roughness_image", rough_file, "vector3"),
                "rgba".index(rough_channel))  # fmt: skip
    )
    out = surf.CreateOutput("out", T.Token)
    material.CreateSurfaceOutput("mtlx").ConnectToSource(out)


def write_usdz(
    path: PathLike,
    name: str,
    uvmesh,
    textures: UsdTextures,
    up: np.ndarray = (0.0, 1.0, 0.0),
    meters_per_unit: float = 1.0,
    doc: str = "",
) -> None:
    """Write a ``.usdz`` package for AR Quick Look: the stage flattened into one binary layer
    with its textures, by ``UsdUtils.CreateNewARKitUsdzPackage``.

    The material is the UsdPreviewSurface network alone (ARKit reads no other shader; the
    MaterialX network and the crack readers stay in the ``.usda``).  The textures must already
    be written in ``path``'s folder.  Parameters as :func:`write_usd`.
    """
    require_pxr()
    from pxr import Tf, UsdUtils

    path = os.fspath(path)
    # One binary layer, the mesh inline, beside the textures (their paths are relative): the
    # package's root layer, named after it; removed once packed.
    source = os.path.splitext(path)[0] + ".usdc"
    try:
        write_usd(source, name, uvmesh, textures, up, meters_per_unit, doc, lookdev=False,
                  split=False)  # fmt: skip
        try:
            ok = UsdUtils.CreateNewARKitUsdzPackage(source, path)
        except Tf.ErrorException as exc:
            ok = False
            why = str(exc).strip().splitlines()[-1]
        else:
            why = "the USD library refused it"
        if not ok:
            raise CrackbakeError(
                f"cannot write USDZ '{path}': {why}; check the folder is writable and has space"
            )
    finally:
        if os.path.exists(source):
            os.remove(source)
