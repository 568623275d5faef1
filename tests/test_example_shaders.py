"""The example crack-growth shaders (examples/shaders): the GLSL pair compiles and links in a
real GL context, the Godot shader shares the growth function verbatim, and that function
computes on the GPU what its comment says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

SHADERS = Path(__file__).resolve().parents[1] / "examples" / "shaders"
_BLOCK = re.compile(r"// --- crack_grow:.*?// --- end crack_grow ---", re.S)


def _grow_block(name: str) -> str:
    found = _BLOCK.findall((SHADERS / name).read_text())
    assert len(found) == 1, name
    return found[0]


def test_glsl_example_compiles_and_links(gl_ctx):
    prog = gl_ctx.program(
        vertex_shader=(SHADERS / "crack_grow.vert").read_text(),
        fragment_shader=(SHADERS / "crack_grow.frag").read_text(),
    )
    try:
        for name in ("u_progress", "u_feather", "u_data", "u_normal", "u_surface"):
            assert name in prog, name  # used, so not optimised away
    finally:
        prog.release()


def test_godot_shader_shares_the_growth_function():
    assert _grow_block("crack_grow.gdshader") == _grow_block("crack_grow.frag")
    text = (SHADERS / "crack_grow.gdshader").read_text()
    assert "shader_type spatial;" in text and "NORMAL_MAP" in text


@pytest.mark.parametrize("progress", [0.0, 0.3, 0.75, 1.0])
def test_growth_function_opens_cracks_behind_the_front(gl_ctx, progress):
    import moderngl

    rng = np.random.default_rng(4)
    data = rng.random((16, 16, 4)).astype(np.float32)
    feather = 0.05
    frag = (
        "#version 330 core\nuniform sampler2D u_data; uniform float u_p; uniform float u_f;\n"
        "out vec4 o;\n" + _grow_block("crack_grow.frag") + "\nvoid main() {\n"
        "  o = vec4(crack_grow(texelFetch(u_data, ivec2(gl_FragCoord.xy), 0), u_p, u_f));\n}\n"
    )
    vert = (
        "#version 330 core\nin vec2 p; void main() { gl_Position = vec4(p, 0.0, 1.0); }\n"
    )
    prog = gl_ctx.program(vertex_shader=vert, fragment_shader=frag)
    tex = gl_ctx.texture((16, 16), 4, data.tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    out = gl_ctx.texture((16, 16), 4, dtype="f4")
    fbo = gl_ctx.framebuffer([out])
    quad = gl_ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], np.float32).tobytes())
    vao = gl_ctx.vertex_array(prog, [(quad, "2f", "p")])
    try:
        tex.use(0)
        prog["u_data"].value = 0
        prog["u_p"].value = progress
        prog["u_f"].value = feather
        fbo.use()
        vao.render(moderngl.TRIANGLES)
        got = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(16, 16, 4)
    finally:
        gl_ctx.detect_framebuffer(0).use()  # as GLScope: never leave a deleted fbo bound
        for obj in (vao, quad, fbo, out, tex, prog):
            obj.release()
    want = data[..., 0] * np.clip((progress - data[..., 3]) / feather, 0, 1)
    np.testing.assert_allclose(got[..., 0], want, atol=1e-5)
    if progress == 0.0:
        assert (got[..., 0] == 0).all()
    if progress == 1.0:
        behind = data[..., 3] <= 1.0 - feather
        np.testing.assert_allclose(got[..., 0][behind], data[..., 0][behind], atol=1e-6)
