"""USD export (crackbake.exchange.usd): the layer read back with Pixar's pxr, its validators,
the bound material's inputs and colour spaces, the up axis, and the texture files it names."""

from __future__ import annotations

import re
import sys

import numpy as np
import pytest
from conftest import tiny_network
from maps_factory import plate_uvmesh, synthetic_maps

from crackbake.bake.uv import UVMesh
from crackbake.errors import CrackbakeError
from crackbake.exchange.bundle import write_outputs
from crackbake.exchange.targets import data_scales
from crackbake.params import RunParams
from crackbake.transaction.stage import OutputStage

pxr = pytest.importorskip("pxr", reason="usd-core (the usd extra) is not installed")
from pxr import Sdf, Usd, UsdGeom, UsdShade  # noqa: E402


def _seamed():
    """The plate with its right half split off: those faces use copies of their vertices with
    other UVs (a UV seam down the middle), as an unwrap leaves a mesh."""
    mesh, uvm = plate_uvmesh()
    n = len(uvm.vertices)
    faces = uvm.faces.copy()
    right = uvm.vertices[faces].mean(axis=1)[:, 0] > 0.5
    faces[right] += n
    uv = np.concatenate([uvm.uv, 0.25 + 0.5 * uvm.uv])
    return mesh, UVMesh(
        vertices=np.concatenate([uvm.vertices, uvm.vertices]),
        faces=faces,
        uv=uv,
        normals=np.concatenate([uvm.normals, uvm.normals]),
        vertex_map=np.concatenate([np.arange(n), np.arange(n)]),
        method="unwrapped",
        overlap_fraction=0.0,
        padding_px=0,
        tangents=np.tile([1.0, 0.0, 0.0, 1.0], (2 * n, 1)),
    )


def _write(tmp_path, uvm=None, mesh=None, name="out", **kw):
    if uvm is None:
        mesh, uvm = _seamed()
    maps = synthetic_maps()
    kw.setdefault("formats", ("usd",))
    params = RunParams(mesh=mesh.source, **kw)
    out = tmp_path / name
    with OutputStage(out) as stage:
        write_outputs(stage, "rock", params, mesh, uvm, tiny_network(), maps)
        stage.commit()
    return out, uvm, maps


def _open(path) -> Usd.Stage:
    # Reloaded: the layer registry keeps a path's first read for the whole process.
    layer = Sdf.Layer.FindOrOpen(str(path))
    layer.Reload(force=True)
    return Usd.Stage.Open(layer)


def test_mesh_reads_back_welded_with_face_varying_uvs(tmp_path):
    out, uvm, _ = _write(tmp_path)
    stage = _open(out / "rock.usda")
    root = stage.GetDefaultPrim()
    assert root.GetName() == "rock" and Usd.ModelAPI(root).GetKind() == "component"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.HasAuthoredMetadata("metersPerUnit") and stage.HasAuthoredMetadata("upAxis")
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/rock/mesh"))
    # the arrays live in the binary geometry layer the text layer references
    assert [s.layer.identifier.rsplit("/", 1)[-1] for s in mesh.GetPrim().GetPrimStack()] == [
        "rock.usda", "rock_mesh.usdc"]
    points = np.asarray(mesh.GetPointsAttr().Get())
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    fvi = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    assert (counts == 3).all() and len(fvi) == len(uvm.faces)
    # welded: one point per input vertex, the seam's copies merged
    assert len(points) == len(np.unique(uvm.vertex_map)) < len(uvm.vertices)
    np.testing.assert_allclose(points[fvi], uvm.vertices[uvm.faces], atol=1e-6)
    # UVs per corner, both sides of the seam kept
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying
    assert st.GetTypeName() == Sdf.ValueTypeNames.TexCoord2fArray
    flat = np.asarray(st.ComputeFlattened()).reshape(-1, 3, 2)
    np.testing.assert_allclose(flat, uvm.uv[uvm.faces], atol=1e-6)
    for name, want in (("normals", uvm.normals), ("tangents", uvm.tangents)):
        pv = UsdGeom.PrimvarsAPI(mesh).GetPrimvar(name)
        assert pv.GetInterpolation() == UsdGeom.Tokens.faceVarying
        np.testing.assert_allclose(np.asarray(pv.ComputeFlattened()).reshape(-1, 3, want.shape[1]),
                                   want[uvm.faces], atol=1e-6)  # fmt: skip
    lo, hi = np.asarray(mesh.GetExtentAttr().Get())
    np.testing.assert_allclose(lo, uvm.vertices.min(0), atol=1e-6)
    np.testing.assert_allclose(hi, uvm.vertices.max(0), atol=1e-6)
    assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none


@pytest.mark.parametrize("up, axis", [("y", "Y"), ("z", "Z"), ("-x", "Y")])
def test_up_axis(tmp_path, up, axis):
    out, _, _ = _write(tmp_path, up=up, name=up)
    stage = _open(out / "rock.usda")
    assert UsdGeom.GetStageUpAxis(stage) == axis
    world = UsdGeom.Xformable(stage.GetPrimAtPath("/rock/mesh")).ComputeLocalToWorldTransform(0)
    m = np.array(world)[:3, :3]  # row vectors: p' = p @ m
    up_vec = {"y": (0, 1, 0), "z": (0, 0, 1), "-x": (-1, 0, 0)}[up]
    want = {"Y": (0, 1, 0), "Z": (0, 0, 1)}[axis]
    np.testing.assert_allclose(np.asarray(up_vec, float) @ m, want, atol=1e-12)
    assert abs(np.linalg.det(m) - 1) < 1e-12  # a rotation: nothing mirrored


def _pyramid(z_up: bool):
    """A square pyramid (base 2 x 2, height 1.5) standing on its base: on z = 0 (Z-up, as a scan
    or CAD export) or on y = 0 (Y-up); UVs from the base plane."""
    from conftest import make_mesh

    base = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    v = np.c_[base, np.zeros(4)]
    v = np.vstack([v, [0.0, 0.0, 1.5]])
    faces = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    uv = (v[:, :2] + 1) / 2
    if not z_up:  # (x, y, z) -> (x, z, -y): a right-handed quarter turn, the base on y = 0
        v = v[:, [0, 2, 1]] * [1, 1, -1]
    mesh = make_mesh(v, faces, uv, source="pyramid.obj")
    n = len(v)
    return mesh, UVMesh(vertices=mesh.vertices, faces=mesh.faces, uv=mesh.uv,
                        normals=mesh.normals, vertex_map=np.arange(n), method="kept",
                        overlap_fraction=0.0, padding_px=0,
                        tangents=np.tile([1.0, 0.0, 0.0, 1.0], (n, 1)))  # fmt: skip


@pytest.mark.parametrize("z_up", [False, True])
def test_a_z_up_and_a_y_up_mesh_keep_their_points_and_say_their_up_axis(tmp_path, z_up):
    """No --up: the stage's upAxis is the mesh's own (the preview's guess), the points are
    written as they are (no turn), so a DCC reading upAxis stands both the same way up."""
    mesh, uvm = _pyramid(z_up)
    out, _, _ = _write(tmp_path, uvm=uvm, mesh=mesh, name=f"z{z_up}")
    stage = _open(out / "rock.usda")
    assert UsdGeom.GetStageUpAxis(stage) == ("Z" if z_up else "Y")
    prim = stage.GetPrimAtPath("/rock/mesh")
    world = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(0))
    np.testing.assert_allclose(world, np.eye(4), atol=1e-12)
    points = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get())
    np.testing.assert_allclose(points, uvm.vertices, atol=1e-6)
    apex = points[np.argmax(points[:, 2 if z_up else 1])]
    np.testing.assert_allclose(apex, [0, 0, 1.5] if z_up else [0, 1.5, 0], atol=1e-6)


def test_validators_find_nothing(tmp_path):
    """Every UsdValidation validator (the successor of usdchecker's ComplianceChecker) but the
    usdz package rules: no errors.  usd-core's registry has no MaterialX node definitions (no
    usdMtlx plugin), so there the MaterialX shader ids are reported as unknown; that finding is
    allowed only for ``ND_`` ids that registry really lacks."""
    from pxr import Sdr
    from pxr import UsdValidation as V

    out, _, _ = _write(tmp_path)
    reg = V.ValidationRegistry()
    names = [m.name for m in reg.GetAllValidatorMetadata() if "UsdzValidators" not in
             list(m.GetKeywords())]  # fmt: skip
    stage = _open(out / "rock.usda")
    errors = V.ValidationContext(reg.GetOrLoadValidatorsByName(names)).Validate(stage)
    known = set(Sdr.Registry().GetShaderNodeIdentifiers())
    left = []
    for e in errors:
        # its sites name no prim: the id is in the message
        sid = re.search(r"shaderId '(ND_\w+)'", e.GetMessage())
        if e.GetName() == "MissingShaderIdInRegistry" and sid:
            assert sid.group(1) not in known
            continue
        left.append(f"{e.GetName()}: {e.GetMessage()}")
    assert left == []
    assert "UsdPreviewSurface" in known and "UsdUVTexture" in known


def _source(inp: UsdShade.Input):
    (src,) = inp.GetConnectedSources()[0]
    return UsdShade.Shader(src.source.GetPrim()), src.sourceName


def test_bound_material_inputs_and_colour_spaces(tmp_path):
    out, uvm, maps = _write(tmp_path)
    stage = _open(out / "rock.usda")
    mesh_prim = stage.GetPrimAtPath("/rock/mesh")
    assert mesh_prim.HasAPI(UsdShade.MaterialBindingAPI)
    material, _ = UsdShade.MaterialBindingAPI(mesh_prim).ComputeBoundMaterial()
    surface = material.ComputeSurfaceSource()[0]
    assert surface.GetShaderId() == "UsdPreviewSurface"

    def texture(slot):
        tex, channel = _source(surface.GetInput(slot))
        assert tex.GetShaderId() == "UsdUVTexture"
        reader, _ = _source(tex.GetInput("st"))
        assert reader.GetShaderId() == "UsdPrimvarReader_float2"
        varname = reader.GetInput("varname")
        assert varname.GetTypeName() == Sdf.ValueTypeNames.String and varname.Get() == "st"
        path = tex.GetInput("file").Get().path
        assert path.startswith("./") and (out / path[2:]).is_file()
        assert tex.GetInput("wrapS").Get() == "repeat"
        return tex, channel, path[2:]

    tex, channel, name = texture("diffuseColor")
    assert (channel, name, tex.GetInput("sourceColorSpace").Get()) == ("rgb", "rock_basecolor.png",
                                                                        "sRGB")  # fmt: skip
    tex, channel, name = texture("normal")
    assert (channel, name, tex.GetInput("sourceColorSpace").Get()) == ("rgb", "rock_normal.png",
                                                                        "raw")  # fmt: skip
    assert tuple(tex.GetInput("scale").Get()) == (2, 2, 2, 1)
    assert tuple(tex.GetInput("bias").Get()) == (-1, -1, -1, 0)
    for slot, want in (("occlusion", "r"), ("roughness", "g")):
        tex, channel, name = texture(slot)
        assert (channel, name, tex.GetInput("sourceColorSpace").Get()) == (want, "rock_orm.png",
                                                                            "raw")  # fmt: skip
    assert surface.GetInput("metallic").Get() == 0

    # MaterialX on the same material
    mtlx = material.ComputeSurfaceSource("mtlx")[0]
    assert mtlx.GetShaderId() == "ND_standard_surface_surfaceshader"
    image, _ = _source(mtlx.GetInput("base_color"))
    assert image.GetInput("file").GetAttr().GetColorSpace() == "srgb_texture"
    nmap, _ = _source(mtlx.GetInput("normal"))
    assert nmap.GetShaderId() == "ND_normalmap_float"

    # the crack maps: readers of the data map no surface uses, width and depth in mesh units
    scales = data_scales(maps)
    used = {_source(surface.GetInput(s))[0].GetPath() for s in
            ("diffuseColor", "normal", "occlusion", "roughness")}  # fmt: skip
    for name, channel, scale in (("mask", "r", 1), ("width", "g", scales["width"]),
                                 ("depth", "b", scales["depth"]), ("time", "a", 1)):  # fmt: skip
        reader = UsdShade.Shader(material.GetPrim().GetChild(f"crack_{name}"))
        assert reader.GetShaderId() == "UsdUVTexture" and reader.GetPath() not in used
        assert reader.GetInput("file").Get().path == "./rock_data.png"
        assert reader.GetInput("sourceColorSpace").Get() == "raw"
        assert [o.GetBaseName() for o in reader.GetOutputs()] == [channel]
        got = reader.GetInput("scale").Get() if scale != 1 else None
        assert got is None or np.allclose(tuple(got), [scale] * 4, rtol=1e-6)
    written = {p.name for p in out.iterdir()}
    assert {"rock_basecolor.png", "rock_normal.png", "rock_orm.png", "rock_data.png"} <= written


def test_reuses_the_targets_files_and_adds_an_opengl_normal(tmp_path):
    out, _, _ = _write(tmp_path, formats=("png", "usd"), target="unreal", name="ue")
    stage = _open(out / "rock.usda")  # kept: its prims die with it
    material = UsdShade.Material(stage.GetPrimAtPath("/rock/Looks/crack_material"))
    surface = material.ComputeSurfaceSource()[0]
    files = {s: _source(surface.GetInput(s))[0].GetInput("file").Get().path for s in
             ("diffuseColor", "normal", "roughness")}  # fmt: skip
    # Unreal's own base colour and ORM; its normal map is DirectX, so USD gets an OpenGL one
    assert files == {"diffuseColor": "./T_rock_BC.png", "normal": "./rock_normal.png",
                     "roughness": "./T_rock_ORM.png"}  # fmt: skip
    from PIL import Image

    gl = np.asarray(Image.open(out / "rock_normal.png"), np.int32)
    dx = np.asarray(Image.open(out / "T_rock_N.png"), np.int32)
    assert np.abs(gl[..., 1] + dx[..., 1] - 255).max() <= 1  # Y flipped, the rest equal
    assert (gl[..., [0, 2]] == dx[..., [0, 2]]).all()


def test_blender_target_binds_its_roughness_and_ao_maps(tmp_path):
    out, _, _ = _write(tmp_path, formats=("png", "usd"), target="blender", name="bl")
    stage = _open(out / "rock.usda")  # kept: its prims die with it
    material = UsdShade.Material(stage.GetPrimAtPath("/rock/Looks/crack_material"))
    surface = material.ComputeSurfaceSource()[0]
    got = {s: _source(surface.GetInput(s)) for s in ("roughness", "occlusion", "normal")}
    assert got["roughness"][0].GetInput("file").Get().path == "./rock_roughness.png"
    assert got["occlusion"][0].GetInput("file").Get().path == "./rock_ao.png"
    assert got["normal"][0].GetInput("file").Get().path == "./rock_normal.png"  # 16-bit, gl
    assert not (out / "rock_orm.png").exists()


def test_missing_pxr_is_one_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pxr", None)
    monkeypatch.setitem(sys.modules, "pxr.Usd", None)
    with pytest.raises(CrackbakeError, match=r"usd-core.*or drop usd from --formats"):
        RunParams(mesh="x.obj", formats=("png", "usd")).validate()
    RunParams(mesh="x.obj").validate()  # not a default format: runs without USD are untouched


@pytest.mark.reference
@pytest.mark.parametrize("up", ["y", "z"])
def test_blender_imports_the_material_and_the_up_axis(tmp_path, up):
    """Blender's USD importer binds each texture to the right Principled BSDF input in the
    right colour space, reads the st UVs, and stands a Y-up and a Z-up layer the same way up
    (Blender is Z-up: the plate lies in the mesh's z = 0 plane)."""
    from tests.blender_runner import run_blender

    out, uvm, _ = _write(tmp_path, up=up, name=up)
    got = run_blender("import_usd.py", out / "rock.usda")
    bound = {k: (v["image"].rsplit("/", 1)[-1], v["colorspace"], v["via"])
             for k, v in got["bound"].items()}  # fmt: skip
    assert bound["Base Color"] == ("rock_basecolor.png", "sRGB", [])
    assert bound["Normal"] == ("rock_normal.png", "Non-Color", ["NORMAL_MAP.Normal"])
    assert bound["Roughness"] == ("rock_orm.png", "Non-Color", ["SEPARATE_COLOR.Green"])
    assert got["uv_maps"] == ["st"] and got["faces"] == len(uvm.faces)
    assert all(got["images_found"].values())
    lo, hi = (np.asarray(c) for c in got["bbox"])
    flat = {"y": 1, "z": 2}[up]  # Blender axis the plate's normal (mesh +z) ends on
    extent = hi - lo
    assert extent[flat] < 1e-6 and (np.delete(extent, flat) > 0.99).all()


def test_usdz_packs_the_preview_surface_and_its_textures(tmp_path):
    """The package passes the usdz validators (what usdchecker --arkit runs); it holds one
    binary root layer and the three textures the UsdPreviewSurface reads, no MaterialX (ARKit
    reads no other shader) and no leftover source layers beside it."""
    import zipfile

    from pxr import UsdValidation as V

    out, uvm, _ = _write(tmp_path, formats=("usd", "usdz"))
    package = out / "rock.usdz"
    names = zipfile.ZipFile(package).namelist()
    assert names[0] == "rock.usdc" and sorted(names[1:]) == [
        "rock_basecolor.png", "rock_normal.png", "rock_orm.png"]  # fmt: skip
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]
    stage = Usd.Stage.Open(str(package))
    reg = V.ValidationRegistry()
    names = [m.name for m in reg.GetAllValidatorMetadata()]
    errors = V.ValidationContext(reg.GetOrLoadValidatorsByName(names)).Validate(stage)
    assert [f"{e.GetName()}: {e.GetMessage()}" for e in errors] == []
    shaders = {UsdShade.Shader(p).GetShaderId() for p in stage.Traverse() if p.IsA(UsdShade.Shader)}
    assert shaders == {"UsdPreviewSurface", "UsdUVTexture", "UsdPrimvarReader_float2"}
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/rock/mesh"))
    assert len(mesh.GetFaceVertexCountsAttr().Get()) == len(uvm.faces)
    material, _ = UsdShade.MaterialBindingAPI(mesh.GetPrim()).ComputeBoundMaterial()
    assert material.ComputeSurfaceSource()[0].GetShaderId() == "UsdPreviewSurface"


def test_materialx_network_matches_the_standard_library(tmp_path):
    """Every ``ND_`` shader of the MaterialX network is a node definition of MaterialX's own
    standard library, with each authored input and output named and typed as it declares (the
    check usd-core's registry cannot make: it ships without MaterialX)."""
    mx = pytest.importorskip("MaterialX", reason="the MaterialX package is not installed")
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    usd_type = {"float": "float", "integer": "int", "string": "string", "filename": "asset",
                "vector2": "float2", "vector3": "float3", "color3": "color3f",
                "surfaceshader": "token"}  # fmt: skip

    out, _, _ = _write(tmp_path)
    stage = _open(out / "rock.usda")
    shaders = [UsdShade.Shader(p) for p in stage.Traverse() if p.IsA(UsdShade.Shader)]
    mtlx = [s for s in shaders if s.GetShaderId().startswith("ND_")]
    assert len(mtlx) == 7
    for shader in mtlx:
        nodedef = lib.getNodeDef(shader.GetShaderId())
        assert nodedef is not None, shader.GetShaderId()
        for port, declared in ((p, nodedef.getActiveInput(p.GetBaseName()))
                               for p in shader.GetInputs()):  # fmt: skip
            assert declared is not None, f"{shader.GetPath()} {port.GetBaseName()}"
            assert str(port.GetTypeName()) == usd_type[declared.getType()], port.GetBaseName()
        for port in shader.GetOutputs():
            declared = nodedef.getActiveOutput(port.GetBaseName())
            assert declared is not None and str(port.GetTypeName()) == usd_type[declared.getType()]
