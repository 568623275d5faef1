"""EXR channel layouts that Blender, Nuke and OpenImageIO all read as typed layers.

Every map is one *layer* named ``<part>.<pass>.<channel>``, at most four channels each:

* **Blender** (5.0 multilayer reader, ``imbuf/intern/openexr``) splits a name at its last two dots
  into render layer, pass and channel.  Two-part names (``mask.V``) land in a render layer with an
  empty name, which the compositor's Image node does not list at all, and a name without a pass
  (``crack.mask``) makes ``crack`` one pass of many channels that it cannot order.  So every
  channel has three parts.  A one-channel pass is a VALUE; a 3-channel pass whose channel ids
  contain ``Y`` (and no ``B``) is a VECTOR ordered X, Y, Z; a 2-channel pass is a VECTOR too
  (Z = 0).  Two-letter channel names take their id from the second letter, so ``NX/NY/NZ`` are
  X/Y/Z.
* **Nuke** (``ExrChannelNameToNuke``) joins all but the last part with ``_`` into its layer name
  (``crack.mask.V`` -> layer ``crack_mask``, channel ``V``) and handles at most four channels per
  layer; layer names avoid its reserved ``depth``, ``mask``, ``rgba``, ``forward``, ``backward``.
* **OpenImageIO** takes any channel whose last part is ``Z`` or ``depth`` (any case) as the
  file's camera-depth channel (``ImageSpec.z_channel``), and ``A``/``alpha`` as alpha; so single
  values are ``.V`` and the normal is ``NX/NY/NZ`` (the Autodesk/3ds Max convention), never ``.Z``.

Images are ``(H, W)`` (or ``(H, W, C)`` for vectors), row 0 the top (UV ``v = 1``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from crackbake.errors import CrackbakeError

#: Version of the layout below, stored in every file's ``crackbake:layout`` attribute.
LAYOUT_VERSION = 1


@dataclass(frozen=True)
class Layer:
    """One map in an EXR: its channel names, pixel type, units and range.

    Attributes
    ----------
    role : str
        The map's name in crackbake (``"mask"``, ``"normal"``, ``"p1"``, ...).
    layer : str
        Channel prefix ``<part>.<pass>``: Blender render layer and pass, Nuke layer
        ``<part>_<pass>``.
    channels : tuple of str
        Channel suffixes in component order (1 for a value, 2-3 for a vector).
    kind : {"value", "vector"}
        What Blender types the pass as.
    half : bool
        Stored as half unless the run asks for float32 everywhere; False = always float.
    units : str
    range : str
        Human-readable value range.
    description : str
    """

    role: str
    layer: str
    channels: tuple[str, ...]
    kind: str
    half: bool
    units: str
    range: str
    description: str

    @property
    def names(self) -> tuple[str, ...]:
        """Full EXR channel names, in component order."""
        return tuple(f"{self.layer}.{c}" for c in self.channels)


def _value(role, layer, half, units, rng, text) -> Layer:
    return Layer(role, layer, ("V",), "value", half, units, rng, text)


#: The crack master ``<stem>_cracks.exr``, by role, in file-description order.  Pixel types are
#: half where the range is bounded (0..1 or unit vectors), float for lengths in mesh units
#: (width, depth, distance: half stops at 65504) and for ids (half holds integers exactly only
#: up to 2048, float32 up to 2**24, the sidecar's id limit).
CRACK_LAYERS: dict[str, Layer] = {
    layer.role: layer
    for layer in (
        _value("mask", "crack.mask", True, "fraction", "0..1", "anti-aliased crack coverage"),
        _value(
            "width", "crack.width", False, "mesh units", ">= 0",
            "opening width of the nearest crack (0 where none within max distance)",
        ),
        _value(
            "time", "crack.time", True, "0..1 of the growth", "0..1",
            "when the nearest crack point formed (grow cracks with mask * (time < t))",
        ),
        _value(
            "depth", "crack.depth", False, "mesh units", ">= 0 (< 0 on curled rims)",
            "depth of the crack profile at the texel (negative: raised, a curled cell edge)",
        ),
        _value(
            "distance", "crack.distance", False, "mesh units", "0..max distance",
            "world distance to the nearest crack, clamped at max distance",
        ),
        _value(
            "id", "crack.id", False, "integer", "-1 or >= 0",
            "id of the nearest crack (cracks.json), -1 where none within max distance",
        ),
        Layer(
            "normal", "crack.normal", ("NX", "NY", "NZ"), "vector", True, "unit vector",
            "-1..1 (Z > 0)",
            "tangent-space normal of the crack relief, OpenGL: X along T (+u), Y along B "
            "(+v), Z along N; flat = (0, 0, 1)",
        ),
        _value(
            "occlusion", "crack.occlusion", True, "fraction", "0..1",
            "ambient occlusion of the crack relief (1 = open, crack interiors dark)",
        ),
    )
}  # fmt: skip

#: The two stress fields of ``<stem>_stress.exr``: before any crack and after the last.
STRESS_FIELDS: dict[str, str] = {
    "stress0": "initial stress (before any crack)",
    "stress": "final stress (after the last crack)",
}

#: Per-field components of the stress file (all FLOAT: stress overflows half).
STRESS_COMPONENTS: dict[str, tuple[tuple[str, ...], str, str, str]] = {
    # role: (channel suffixes, kind, range, description)
    "xx": (("V",), "value", "signed", "tensor component along T (+u), tension > 0"),
    "yy": (("V",), "value", "signed", "tensor component along B (+v)"),
    "xy": (("V",), "value", "signed", "shear component in the (T, B) frame"),
    "p1": (("V",), "value", "signed, >= p2", "largest principal stress"),
    "p2": (("V",), "value", "signed, <= p1", "smallest principal stress"),
    "dir": (
        ("X", "Y"), "vector", "-1..1",
        "unit direction of p1 in (T, B) components (a line: its sign is arbitrary); 0, 0 where "
        "the stress has no direction (none, or the same every way)",
    ),
    "sep": (("V",), "value", ">= 0", "separation that drives cracking / toughness (>= 1 fails)"),
}  # fmt: skip


def stress_layers(units: str = "stress") -> dict[str, Layer]:
    """The stress file's layers, keyed ``"<field>.<component>"`` (e.g. ``"stress0.p1"``).

    Parameters
    ----------
    units : str
        Units of the stress values, written into each layer's description and the header.
    """
    out = {}
    for field in STRESS_FIELDS:
        for comp, (chans, kind, rng, text) in STRESS_COMPONENTS.items():
            # sep is relative to the toughness, whatever the stress units are.
            unit = {"dir": "unit vector", "sep": "x toughness"}.get(comp, units)
            role = f"{field}.{comp}"
            out[role] = Layer(role, role, chans, kind, False, unit, rng, text)
    return out


def _components(arr: np.ndarray, layer: Layer) -> list[np.ndarray]:
    arr = np.asarray(arr)
    n = len(layer.channels)
    if n == 1 and arr.ndim == 2:
        return [arr]
    if n > 1 and arr.ndim == 3 and arr.shape[2] == n:
        return [arr[:, :, i] for i in range(n)]
    want = "(H, W)" if n == 1 else f"(H, W, {n})"
    raise CrackbakeError(
        f"EXR layer '{layer.layer}' ({layer.role}) got shape {arr.shape}; pass a {want} array"
    )


def _planes(roles: Mapping[str, np.ndarray], layers: dict[str, Layer], float32: bool) -> dict:
    unknown = sorted(set(roles) - set(layers))
    if unknown:
        raise CrackbakeError(
            f"unknown EXR map role(s) {', '.join(unknown)}; use {', '.join(layers)}"
        )
    out: dict[str, np.ndarray] = {}
    for role, layer in layers.items():  # layout order, whatever order the caller used
        if roles.get(role) is None:
            continue
        want = np.float16 if layer.half and not float32 else np.float32
        for name, plane in zip(layer.names, _components(roles[role], layer), strict=True):
            if want is np.float16 and plane.dtype == np.float32 and plane.size >= 1 << 16:
                # numpy's cast runs an element at a time (0.12 s per 4096² plane)
                from crackbake.exchange.exrzip import to_half

                out[name] = to_half(plane)
            else:
                # astype(copy=False) keeps planes that already have the right type (no copies).
                out[name] = plane.astype(want, copy=False)
    return out


def crack_planes(roles: Mapping[str, np.ndarray | None], float32: bool = False) -> dict:
    """The crack master's channel dict for :func:`~crackbake.exchange.exr.write_exr`.

    Parameters
    ----------
    roles : mapping of str to ndarray or None
        Role (a key of :data:`CRACK_LAYERS`) to image: (H, W) for values, (H, W, 3) for
        ``normal``.  None or missing roles are left out (e.g. no normal without tangents).
    float32 : bool
        Store every channel as FLOAT instead of the layout's half/float types.

    Returns
    -------
    dict of str to (H, W) ndarray
        Channel name to plane; float16 or float32 as the layout says.
    """
    return _planes(roles, CRACK_LAYERS, float32)


def stress_planes(fields: Mapping[str, object], units: str = "stress") -> dict:
    """The stress file's channel dict for :func:`~crackbake.exchange.exr.write_exr`, all FLOAT.

    Parameters
    ----------
    fields : mapping of str to mapping or object
        ``"stress0"`` and/or ``"stress"`` to that field's planes: a mapping or an object with
        attributes ``xx, yy, xy, p1, p2, sep`` (H, W) and ``dir`` (H, W, 2).
    units : str
        Stress units (only for error messages here; see :func:`stress_attributes`).
    """
    layers = stress_layers(units)
    roles: dict[str, np.ndarray] = {}
    for field, planes in fields.items():
        if field not in STRESS_FIELDS:
            raise CrackbakeError(f"unknown stress field '{field}'; use {', '.join(STRESS_FIELDS)}")
        for comp in STRESS_COMPONENTS:
            arr = planes.get(comp) if isinstance(planes, Mapping) else getattr(planes, comp, None)
            if arr is None:
                raise CrackbakeError(
                    f"stress field '{field}' has no '{comp}' plane; bake every component "
                    f"({', '.join(STRESS_COMPONENTS)})"
                )
            roles[f"{field}.{comp}"] = arr
    return _planes(roles, layers, float32=True)


def _layout_json(layers: Mapping[str, Layer], present: set[str] | None) -> str:
    table = {
        name: {"role": layer.role, "units": layer.units, "range": layer.range}
        for layer in layers.values()
        for name in layer.names
        if present is None or name in present
    }
    return json.dumps(table, separators=(",", ":"))


def crack_attributes(
    version: str,
    max_distance: float,
    profile_shape: float,
    channels: Mapping[str, np.ndarray] | None = None,
    normal_convention: str = "opengl",
) -> dict[str, str | float | int]:
    """Header attributes of the crack master: units, frames and what each channel holds.

    Parameters
    ----------
    version : str
        crackbake version.
    max_distance : float
        Clamp of the distance channel, mesh units.
    profile_shape : float
        Depth profile exponent.
    channels : mapping, optional
        The planes being written (:func:`crack_planes`): the ``crackbake:channels`` table then
        lists only those.
    normal_convention : {"opengl", "directx"}
        Y direction of the normal layer's second component.
    """
    if normal_convention not in ("opengl", "directx"):
        raise CrackbakeError(
            f"normal convention '{normal_convention}' is unknown; use opengl or directx"
        )
    y_axis = "+v (up in the image)" if normal_convention == "opengl" else "-v (DirectX)"
    return {
        "crackbake:version": version,
        "crackbake:layout": LAYOUT_VERSION,
        "crackbake:units": "mesh",
        "crackbake:uvConvention": "texel (0,0) is UV (0,1): v up, top row first",
        "crackbake:depthProfile": f"V exponent {profile_shape:g}",
        "crackbake:maxDistance": float(max_distance),
        "crackbake:normalSpace": (
            f"tangent (MikkTSpace), {normal_convention}: NX along T (+u), NY along B {y_axis}, "
            "NZ along N; decode n = normalize(NX*T + NY*B + NZ*N)"
        ),
        "crackbake:channels": _layout_json(CRACK_LAYERS, set(channels) if channels else None),
    }


def stress_attributes(version: str, units: str = "stress") -> dict[str, str | float | int]:
    """Header attributes of the stress file: units, frame and component order.

    Parameters
    ----------
    version : str
        crackbake version.
    units : str
        Units of the stress values (the solver's own scale unless the caller knows better).
    """
    return {
        "crackbake:version": version,
        "crackbake:layout": LAYOUT_VERSION,
        "crackbake:stressUnits": units,
        "crackbake:stressFrame": (
            "per texel tangent frame: x = T (+u), y = B (+v, up in the image); tension > 0"
        ),
        "crackbake:componentOrder": (
            "xx, yy, xy (symmetric 2D tensor in (T, B)); p1 >= p2 principal values; "
            "dir.X, dir.Y = unit direction of p1 in (T, B), sign arbitrary; sep"
        ),
        "crackbake:fields": "stress0 = initial (before any crack), stress = final",
        "crackbake:uvConvention": "texel (0,0) is UV (0,1): v up, top row first",
        "crackbake:channels": _layout_json(stress_layers(units), None),
    }


def layer_of(name: str) -> str:
    """The layer part of a channel name (all but the last dot-separated part; '' if none)."""
    return name.rpartition(".")[0]


def run_attributes(version: str, params: Mapping[str, object] | None) -> dict[str, str]:
    """The standard ``owner`` and ``comments`` attributes naming crackbake and the run.

    Compositing tools show these two (OpenImageIO reads them as ``Copyright`` and
    ``ImageDescription``): ``owner`` is ``crackbake <version>``; ``comments`` the run as a short
    command line (mesh file name, preset, method, seed, resolution, target, impacts) and the
    SHA-256 of the run's effective parameters, the ``params`` object of ``manifest.json`` less
    its ``out`` and ``solver`` (where, and timings), serialised as
    ``json.dumps(params, sort_keys=True, separators=(",", ":"))``, so a file can be
    matched to its manifest.  No ``chromaticities``: every channel is data, not colour.

    Parameters
    ----------
    version : str
        crackbake version.
    params : mapping or None
        The effective parameters (:func:`crackbake.exchange.manifest.effective_params`); None
        gives ``comments`` with the version only.
    """
    import hashlib
    from pathlib import PurePath

    out = {"owner": f"crackbake {version}"}
    if params is None:
        out["comments"] = f"crackbake {version}"
        return out
    words = ["crackbake", PurePath(str(params.get("mesh", "mesh"))).name]
    for key in ("cracks", "preset", "method", "seed", "res", "target"):
        value = params.get(key)
        if value is not None:
            words += [f"--{key}", PurePath(str(value)).name if key == "cracks" else str(value)]
    impacts = params.get("impacts")
    # a tile's "impacts" is a count of random impacts, not a list of points
    impacts = list(impacts) if isinstance(impacts, list | tuple) else []
    for imp in impacts[:3]:
        pos = imp.get("point") if isinstance(imp, Mapping) else imp
        if isinstance(pos, list | tuple) and len(pos) == 3:
            words += ["--impact", ",".join(f"{float(x):.4g}" for x in pos)]
    if len(impacts) > 3:
        words.append(f"(+{len(impacts) - 3} impacts)")
    # Without the output folder and the solver's figures (they hold its timings): the same run
    # again, or written elsewhere, gives byte-identical files.
    what = {k: v for k, v in params.items() if k not in ("out", "solver")}
    text = json.dumps(what, sort_keys=True, separators=(",", ":"), default=str)
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]
    out["comments"] = (
        f"{' '.join(words)} (crackbake {version}); parameters sha256 {digest}... "
        "(manifest.json params)"
    )
    return out
