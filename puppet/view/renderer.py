"""Offscreen OpenGL renderer for the deforming face, built on moderngl.

The face's topology, albedo and materials never change while it is puppeteered; only vertex
positions (and therefore normals) do. So the renderer uploads colours, materials and triangle
indices once into static buffers and, each frame, writes positions and normals into one dynamic
vertex buffer of fixed size (``Buffer.write``, no reallocation) before drawing and reading the
image back. On a GPU the vertex shader sums the normals itself from the positions and the mesh's
vertex rings in storage buffers (``choose_normals``), so a frame uploads positions alone.

Shading aims to be realistic enough to judge facial motion, not photoreal: per-frame vertex
normals; a three-light studio rig (warm key, cool fill, rim) attached to the camera; wrapped
(half-Lambert-like) diffuse whose extra light near the terminator is tinted red, imitating light
scattered under skin; a normalised Blinn-Phong specular lobe with Schlick Fresnel whose strength
and sharpness follow a per-vertex ``specular`` material (low for skin, high for wet eyes and
teeth); and a sky/ground hemisphere ambient. Lighting is computed in linear space and encoded to
sRGB on output. A GPU lights every pixel; a software rasteriser lights every vertex and
interpolates the colour (``choose_shading``): the face's triangles are a few pixels wide, so
the image hardly changes and the draw costs a third less.

Eyeballs and teeth seen small are drawn from a quarter of their triangles (``PartDetail``,
chosen from the camera): at the live window's 640x480 they were 10,876 of the default face's
19,932 triangles, edges of 3-4 pixels mostly behind the lids and lips, and a sixth of a
software rasteriser's frame; the image changes by under 0.1 of a level on average.

Back faces are culled: they cost a software rasteriser a fifth of the frame (the back of the
skull and the teeth's inner sides behind the face), and on the default face they show only
where the skin folds over at the corners of a wide open mouth (at most 92 of 307,200 pixels of
any demo take frame, from any view, differ from drawing both sides). ``Renderer(cull=False)``
draws both sides, a back face lit with its normal flipped (a mesh seen from inside).

Optionally the albedo comes from a texture (a face built from a photo, ``puppet.photo.build``):
per-vertex texture coordinates and a per-vertex texture weight that mixes the texture's colour
over the vertex colour (0 keeps the vertex colour: where the photo does not see the surface).
Without a texture the weight is 0 everywhere and the colour path is the per-vertex one.

Coordinates follow the face: +x the face's own left, +y up, +z toward the viewer.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import itertools
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import moderngl
import numpy as np

from puppet.runtime.normals import VertexNormals, vertex_rings
from puppet.view import rasterthreads
from puppet.view.partdetail import PartDetail

SKIN_SRGB = (0.80, 0.62, 0.53)
"""Albedo (sRGB, 0-1) used where a mesh has no colours."""

SKIN_SPECULAR = 0.3
"""Default per-vertex specular strength: a soft sheen. Eyes and teeth want about 1."""

DEFAULT_FOV = 27.0
"""Vertical field of view in degrees of ``Renderer.aim``: a portrait lens, little distortion."""

VIEW_DIRECTIONS = {
    "front": (0.0, 0.0, 1.0),
    "three_quarter": (np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)),
    "profile": (1.0, 0.0, 0.0),
}
"""Unit directions from the framed object toward the camera, in the face frame. The angled
views look at the face's own left side (+x)."""

# Studio rig in camera space (x right, y up, z from the subject toward the camera): direction
# toward each light and its linear colour. Rotated into the world whenever the camera moves.
_LIGHT_DIRECTIONS_CAMERA = np.array(
    [
        [-0.65, 0.50, 0.57],  # key: upper left of the camera, warm
        [0.80, 0.05, 0.60],  # fill: right, cool and weak
        [0.35, 0.60, -0.72],  # rim: behind and above, outlines the silhouette
    ]
)
_LIGHT_COLORS = np.array(
    [
        [1.30, 1.18, 1.05],
        [0.20, 0.24, 0.31],
        [0.85, 0.85, 0.90],
    ]
)
_SKY_COLOR = (0.11, 0.12, 0.14)
_GROUND_COLOR = (0.05, 0.04, 0.035)

LIGHT_UNIFORMS = {"sky_color": np.array(_SKY_COLOR), "ground_color": np.array(_GROUND_COLOR),
                  "light_color": _LIGHT_COLORS}
"""The mesh shaders' uniforms that never change: the hemisphere ambient and the lights' colours."""

# The mesh shaders are one source compiled in variants. ``TEXTURED`` mixes a texture over the
# vertex albedo; without it no texture is sampled and the uv + weight varying is gone.
# ``PER_VERTEX`` lights each vertex in the vertex shader (``SHADING_MODES``): an untextured
# triangle then interpolates one sRGB colour, a textured one its light and sheen, which the
# fragment shader multiplies into the texture's albedo. Without it every pixel is lit from the
# interpolated position and normal (varyings packed into vec4s: albedo + specular strength share
# one). The lighting itself (``_LIGHTING``) is the same text in either stage. ``GPU_NORMALS``
# (GLSL 4.30: storage buffers) sums each vertex's normal from the positions in the draw itself
# (``choose_normals``) instead of taking the CPU's from a vertex attribute.
_LIGHTING = """
const int N_LIGHTS = 3;
const float WRAP = 0.5;                           // how far light wraps past the terminator
const vec3 SCATTER_TINT = vec3(1.0, 0.38, 0.26);  // colour of the wrapped (scattered) light
const float F0 = 0.04;                            // dielectric reflectance at normal incidence

uniform vec3 light_direction[N_LIGHTS];  // world space, unit, toward the light
uniform vec3 light_color[N_LIGHTS];      // linear
uniform vec3 eye;
uniform vec3 sky_color;
uniform vec3 ground_color;

// Lambert plus the extra light of wrapped diffuse, tinted: skin's reddish terminator.
vec3 skin_diffuse(float n_dot_l) {
    float lambert = max(n_dot_l, 0.0);
    float wrapped = max((n_dot_l + WRAP) / (1.0 + WRAP), 0.0);
    return vec3(lambert) + SCATTER_TINT * (wrapped - lambert);
}

// x^5 by multiplication: pow() is an exp2 of a log2, which a software rasteriser computes in full.
float pow5(float x) {
    float x2 = x * x;
    return x2 * x2 * x;
}

// Normalised Blinn-Phong with Schlick Fresnel; strength also sharpens the lobe.
float specular(vec3 n, vec3 l, vec3 v, float strength) {
    vec3 h = normalize(l + v);
    float shininess = mix(24.0, 512.0, strength * strength);
    float fresnel = F0 + (1.0 - F0) * pow5(1.0 - max(dot(h, v), 0.0));
    float lobe = (shininess + 8.0) / 8.0 * pow(max(dot(n, h), 0.0), shininess);
    return strength * fresnel * lobe * max(dot(n, l), 0.0);
}

// The light a unit albedo reflects diffusely at unit normal n: hemisphere ambient and the rig.
vec3 diffuse_light(vec3 n) {
    vec3 light = mix(ground_color, sky_color, 0.5 + 0.5 * n.y);
    for (int i = 0; i < N_LIGHTS; ++i) {
        light += light_color[i] * skin_diffuse(dot(n, light_direction[i]));
    }
    return light;
}

// The rig's specular light toward the eye, seen from direction v.
vec3 sheen(vec3 n, vec3 v, float strength) {
    vec3 light = vec3(0.0);
    for (int i = 0; i < N_LIGHTS; ++i) {
        light += light_color[i] * specular(n, light_direction[i], v, strength);
    }
    return light;
}

vec3 srgb_decode(vec3 c) {
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(0.04045, c));
}

vec3 srgb_encode(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}
"""

_MESH_VERTEX_SHADER = """
uniform mat4 view_projection;
in vec3 in_position;
in vec4 in_material;  // linear albedo, specular strength
#ifdef GPU_NORMALS
layout(std430, binding = 0) readonly buffer Positions { float positions[]; };  // in_position's buffer
layout(std430, binding = 1) readonly buffer RingStarts { uint ring_starts[]; };
layout(std430, binding = 2) readonly buffer Rings { uint rings[]; };  // corner pairs (normals.vertex_rings)

vec3 position(uint i) {
    return vec3(positions[3u * i], positions[3u * i + 1u], positions[3u * i + 2u]);
}

// The unit sum of this vertex's triangles' area-weighted normals, as VertexNormals on the CPU.
vec3 vertex_normal() {
    uint v = uint(gl_VertexID);
    vec3 sum = vec3(0.0);
    for (uint j = ring_starts[v]; j < ring_starts[v + 1u]; ++j) {
        sum += cross(position(rings[2u * j]) - in_position, position(rings[2u * j + 1u]) - in_position);
    }
    return normalize(sum);
}
#else
in vec3 in_normal;

vec3 vertex_normal() {
    return in_normal;
}
#endif
#ifdef TEXTURED
in vec3 in_surface;   // uv, texture weight
out vec3 v_surface;
#endif
#ifdef PER_VERTEX
#ifdef TEXTURED
out vec3 v_albedo;
out vec3 v_light;     // diffuse light, times the albedo per pixel
out vec3 v_sheen;     // specular light, added
#else
out vec3 v_color;     // sRGB
#endif
#else
out vec3 v_position;
out vec3 v_normal;
out vec4 v_material;
#endif

void main() {
#ifdef TEXTURED
    v_surface = in_surface;
#endif
#ifdef PER_VERTEX
    vec3 n = normalize(vertex_normal());
    vec3 light = diffuse_light(n);
    vec3 shine = sheen(n, normalize(eye - in_position), in_material.a);
#ifdef TEXTURED
    v_albedo = in_material.rgb;
    v_light = light;
    v_sheen = shine;
#else
    v_color = srgb_encode(in_material.rgb * light + shine);
#endif
#else
    v_position = in_position;
    v_normal = vertex_normal();
    v_material = in_material;
#endif
    gl_Position = view_projection * vec4(in_position, 1.0);
}
"""

_MESH_FRAGMENT_SHADER = """
#ifdef TEXTURED
uniform sampler2D albedo_map;  // sRGB
in vec3 v_surface;
#endif
#ifdef PER_VERTEX
#ifdef TEXTURED
in vec3 v_albedo;
in vec3 v_light;
in vec3 v_sheen;
#else
in vec3 v_color;
#endif
#else
in vec3 v_position;
in vec3 v_normal;
in vec4 v_material;
#endif
out vec4 f_color;

void main() {
#if defined(PER_VERTEX) && !defined(TEXTURED)
    f_color = vec4(v_color, 1.0);
#else
#ifdef PER_VERTEX
    vec3 albedo = v_albedo;
#else
    vec3 albedo = v_material.rgb;
#endif
#ifdef TEXTURED
    albedo = mix(albedo, srgb_decode(texture(albedo_map, v_surface.xy).rgb), v_surface.z);
#endif
#ifdef PER_VERTEX
    vec3 color = albedo * v_light + v_sheen;
#else
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) {
        n = -n;
    }
    vec3 color = albedo * diffuse_light(n) + sheen(n, normalize(eye - v_position), v_material.a);
#endif
    f_color = vec4(srgb_encode(color), 1.0);
#endif
}
"""

# FXAA-style post pass (after Lottes' FXAA 3 "console" variant): where the luma of the four
# diagonal neighbours shows an edge, blend along the edge's direction; elsewhere, where the local
# contrast is under a threshold, the pixel passes through unchanged, so flat shading is untouched.
_FXAA_FRAGMENT_SHADER = """
#version 330
const float REDUCE_MIN = 1.0 / 128.0;
const float REDUCE_MUL = 1.0 / 8.0;
const float SPAN_MAX = 8.0;
const float EDGE_THRESHOLD = 1.0 / 8.0;
const float EDGE_THRESHOLD_MIN = 1.0 / 32.0;
const vec3 LUMA = vec3(0.299, 0.587, 0.114);

uniform sampler2D scene;
out vec4 f_color;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 last = textureSize(scene, 0) - 1;  // neighbours past the border repeat it
    vec4 rgba_m = texelFetch(scene, p, 0);  // alpha: 0 where a transparent backdrop shows
    vec3 rgb_m = rgba_m.rgb;
    float nw = dot(texelFetch(scene, clamp(p + ivec2(-1, -1), ivec2(0), last), 0).rgb, LUMA);
    float ne = dot(texelFetch(scene, clamp(p + ivec2(1, -1), ivec2(0), last), 0).rgb, LUMA);
    float sw = dot(texelFetch(scene, clamp(p + ivec2(-1, 1), ivec2(0), last), 0).rgb, LUMA);
    float se = dot(texelFetch(scene, clamp(p + ivec2(1, 1), ivec2(0), last), 0).rgb, LUMA);
    float m = dot(rgb_m, LUMA);
    float luma_min = min(m, min(min(nw, ne), min(sw, se)));
    float luma_max = max(m, max(max(nw, ne), max(sw, se)));
    if (luma_max - luma_min < max(EDGE_THRESHOLD_MIN, luma_max * EDGE_THRESHOLD)) {
        f_color = rgba_m;
        return;
    }
    vec2 px = 1.0 / vec2(last + 1);
    vec2 uv = gl_FragCoord.xy * px;
    vec2 dir = vec2(-((nw + ne) - (sw + se)), (nw + sw) - (ne + se));
    float reduce = max((nw + ne + sw + se) * 0.25 * REDUCE_MUL, REDUCE_MIN);
    dir = clamp(dir / (min(abs(dir.x), abs(dir.y)) + reduce), -SPAN_MAX, SPAN_MAX) * px;
    vec4 rgba_a = 0.5 * (texture(scene, uv + dir * (1.0 / 3.0 - 0.5))
                       + texture(scene, uv + dir * (2.0 / 3.0 - 0.5)));
    vec4 rgba_b = 0.5 * rgba_a + 0.25 * (texture(scene, uv - 0.5 * dir) + texture(scene, uv + 0.5 * dir));
    float luma_b = dot(rgba_b.rgb, LUMA);
    f_color = (luma_b < luma_min || luma_b > luma_max) ? rgba_a : rgba_b;
}
"""

# Full-screen triangle from gl_VertexID: a vertical grey gradient with a soft vignette, sRGB.
_BACKGROUND_VERTEX_SHADER = """
#version 330
out vec2 v_uv;

void main() {
    vec2 corner = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    v_uv = corner;
    gl_Position = vec4(corner * 2.0 - 1.0, 1.0, 1.0);
}
"""

_BACKGROUND_FRAGMENT_SHADER = """
#version 330
in vec2 v_uv;
out vec4 f_color;

void main() {
    vec3 top = vec3(0.50, 0.51, 0.53);
    vec3 bottom = vec3(0.26, 0.265, 0.28);
    vec3 color = mix(bottom, top, v_uv.y);
    float vignette = 1.0 - 0.25 * dot(v_uv - 0.5, v_uv - 0.5);
    f_color = vec4(color * vignette, 1.0);
}
"""


SOFTWARE_RASTERISERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "lavapipe")
"""Substrings of ``GL_RENDERER`` (lower case) that name a CPU rasteriser: Mesa's llvmpipe,
softpipe and swrast, Google's SwiftShader, Mesa's Vulkan lavapipe under Zink."""

ANTIALIAS_MODES = ("fxaa", "none")
"""Screen-space antialiasing after drawing: an FXAA-style post pass, or nothing."""

SHADING_MODES = ("pixel", "vertex")
"""Where the studio lighting is computed: per pixel from the interpolated normal, or per vertex
with the colour interpolated (Gouraud)."""

_RING_BINDINGS = (0, 1, 2)
"""Storage buffer bindings of the GPU normals' positions, ring starts and rings (the shader's)."""


def software_rasteriser(ctx: moderngl.Context) -> bool:
    """Whether ``ctx`` draws on the CPU (``SOFTWARE_RASTERISERS``), where every sample costs."""
    renderer = str(ctx.info.get("GL_RENDERER", "")).lower()
    return any(name in renderer for name in SOFTWARE_RASTERISERS)


def choose_antialias(
    ctx: moderngl.Context, samples: int | None = None, antialias: str | None = None
) -> tuple[int, str]:
    """The (MSAA samples, post pass) a renderer on ``ctx`` uses: the one place defaults are set.

    On a GPU, 4x MSAA and no post pass: the hardware resolves samples almost for free. On a
    software rasteriser, neither: llvmpipe shades and resolves every sample on the CPU (4x cost
    35 ms of a 52 ms frame at 640x480, and 2x as much as 4x), and even the FXAA pass, one
    texture pass over the head's screen box, is 40% of a frame lit per vertex (2.2 of 5.5 ms
    at 640x480 on two cores), which a sample waits for on its way to the screen once in its own
    frame and about half of it in the frame before. ``antialias="fxaa"`` asks for the pass (a
    video render, where nobody waits: ``puppet render --antialias fxaa``). Either value may be
    given to override the default; giving only ``samples`` > 1 turns the post pass off (MSAA
    already smooths edges).
    """
    if antialias is not None and antialias not in ANTIALIAS_MODES:
        raise ValueError(f"antialias {antialias!r}: expected one of {ANTIALIAS_MODES}")
    software = software_rasteriser(ctx)
    if samples is None:
        samples = 0 if software or antialias == "fxaa" else 4
    if antialias is None:
        antialias = "none"
    samples = min(int(samples), ctx.max_samples) if samples > 1 else 0
    return samples, antialias


def choose_shading(ctx: moderngl.Context, shading: str | None = None, *, cull: bool = True) -> str:
    """The ``SHADING_MODES`` entry a renderer on ``ctx`` uses, beside ``choose_antialias``.

    On a software rasteriser, per vertex: the default face's triangles cover about ten pixels
    each at 640x480, so lighting its 10k vertices instead of every covered pixel takes about a
    third off the frame (10.5 -> 7.3 ms with the FXAA pass, on two busy cores) and changes the
    image by 0.15 of a level on average, most on the teeth and lips, whose sheen a vertex
    samples more coarsely (``tests/test_render_variants.py``). On a GPU, per pixel: there it costs nothing. Drawing
    back faces (``cull`` off) needs per pixel, which turns a back face's normal round.
    """
    if shading is not None and shading not in SHADING_MODES:
        raise ValueError(f"shading {shading!r}: expected one of {SHADING_MODES}")
    if not cull:
        return "pixel"
    return shading or ("vertex" if software_rasteriser(ctx) else "pixel")


def gpu_normals_supported(ctx: moderngl.Context) -> bool:
    """Whether a vertex shader on ``ctx`` can read storage buffers (GL 4.3 with vertex shader
    storage blocks): what summing normals in the draw needs. macOS stops at GL 4.1."""
    blocks = ctx.info.get("GL_MAX_VERTEX_SHADER_STORAGE_BLOCKS", 0)
    return ctx.version_code >= 430 and int(blocks or 0) > 0


def choose_normals(ctx: moderngl.Context, gpu_normals: bool | None = None) -> bool:
    """Whether a renderer on ``ctx`` sums vertex normals in its vertex shader, beside
    ``choose_antialias``: then a frame uploads positions only and the CPU computes no normals
    (a quarter to two thirds of the CPU's deform + normals: 0.25 ms of the default face's
    frame, 2.6 ms at 75k vertices). On a GPU, yes where it can (``gpu_normals_supported``): a
    vertex's ring of six triangles is a few hundred flops beside its lighting. On a software
    rasteriser, no: there the vertex shader runs on the CPU once per corner that misses
    llvmpipe's small vertex cache (1.5 times a vertex on the default face), so summing a ring
    per invocation costs more than numpy's sums once per vertex (``tools/bench/normals_draw.py``).
    ``gpu_normals`` True asks for it anyway and fails clearly where the GL cannot.
    """
    if gpu_normals and not gpu_normals_supported(ctx):
        raise ValueError(f"normals on the GPU need GL 4.3 with vertex shader storage blocks; "
                         f"this GL is {ctx.info.get('GL_VERSION', ctx.version_code)} "
                         f"({ctx.info.get('GL_RENDERER', 'unknown renderer')})")
    if gpu_normals is not None:
        return bool(gpu_normals)
    return gpu_normals_supported(ctx) and not software_rasteriser(ctx)


def wait_for_gl(ctx: moderngl.Context) -> None:
    """Wait until ``ctx`` (current) has executed everything issued so far, letting go of the GIL
    meanwhile: glFinish through ctypes, which releases it around a foreign call, where the GL
    library is found (moderngl's ``finish`` and ``read`` hold it, so while a software rasteriser
    draws for 10 ms no other Python thread runs: a device's reader could not stamp its samples);
    ``ctx.finish()`` elsewhere."""
    gl = _gl_library()
    if gl is None:
        ctx.finish()
    else:
        gl.glFinish()


def draw_triangles(vertex_array: moderngl.VertexArray) -> None:
    """Draw an indexed ``vertex_array`` as triangles, letting go of the GIL
    meanwhile as ``wait_for_gl`` does: on a software rasteriser the draw call itself transforms,
    lights (per vertex) and bins the mesh on this thread, about 2 ms of the default face, during
    which moderngl's ``render`` would keep every device's reader from stamping its samples.
    ``vertex_array.render`` where the GL library is not found."""
    gl = _gl_library()
    if gl is None:
        vertex_array.render(moderngl.TRIANGLES)
        return
    gl.glUseProgram(vertex_array.program.glo)
    gl.glBindVertexArray(vertex_array.glo)
    index_type = _GL_INDEX_TYPES[vertex_array.index_element_size]
    gl.glDrawElements(moderngl.TRIANGLES, vertex_array.vertices, index_type, None)


_GL_INDEX_TYPES = {1: 0x1401, 2: 0x1403, 4: 0x1405}  # bytes an index -> GL_UNSIGNED_BYTE, _SHORT, _INT


@functools.cache
def _gl_library() -> ctypes.CDLL | None:
    """The system's GL library (GLVND's libOpenGL, else libGL) with glFinish, glUseProgram,
    glBindVertexArray and glDrawElements; None where there is none."""
    for name in ("OpenGL", "GL"):
        path = ctypes.util.find_library(name)
        if not path:
            continue
        try:
            library = ctypes.CDLL(path)
            for function in ("glFinish", "glUseProgram", "glBindVertexArray", "glDrawElements"):
                getattr(library, function)
        except (OSError, AttributeError):
            continue
        library.glUseProgram.argtypes = [ctypes.c_uint]
        library.glBindVertexArray.argtypes = [ctypes.c_uint]
        library.glDrawElements.argtypes = [ctypes.c_uint, ctypes.c_int, ctypes.c_uint, ctypes.c_void_p]
        return library
    return None


class FaceLike(Protocol):
    """What ``render_face`` needs of a face: rest vertices, triangles and optional colours."""

    vertices: np.ndarray
    triangles: np.ndarray
    colors: np.ndarray | None


@dataclass(frozen=True)
class Camera:
    """A perspective pin-hole camera: position, aim, vertical field of view and clip planes."""

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov: float
    near: float
    far: float

    def basis(self) -> np.ndarray:
        """Rows: the camera's right, up and back (target-to-eye) unit axes in world space."""
        back = _unit(self.eye - self.target)
        right = _unit(np.cross(self.up, back))
        return np.stack([right, np.cross(back, right), back])

    def view_matrix(self) -> np.ndarray:
        """World-to-camera rigid transform (4x4)."""
        view = np.eye(4)
        view[:3, :3] = self.basis()
        view[:3, 3] = -view[:3, :3] @ self.eye
        return view

    def projection_matrix(self, aspect: float) -> np.ndarray:
        """OpenGL perspective projection (4x4) for a width/height ``aspect``."""
        f = 1.0 / np.tan(np.radians(self.fov) / 2.0)
        near, far = self.near, self.far
        return np.array(
            [
                [f / aspect, 0.0, 0.0, 0.0],
                [0.0, f, 0.0, 0.0],
                [0.0, 0.0, (far + near) / (near - far), 2.0 * far * near / (near - far)],
                [0.0, 0.0, -1.0, 0.0],
            ]
        )


class Renderer:
    """Draws one fixed-topology triangle mesh with changing vertex positions to RGB images.

    The renderer owns its GL objects (buffers, programs, framebuffers) and, unless given an
    existing ``ctx`` (a window's), a standalone headless context that it also releases. Use it
    as a context manager or call ``release()``.

    OpenGL calls go to whichever context is current on the thread, so a renderer that owns its
    context makes it current around its own GL work (several renderers may coexist); with a
    borrowed ``ctx`` the caller (the window) keeps its context current.
    """

    def __init__(
        self,
        triangles: np.ndarray,
        n_vertices: int,
        colors: np.ndarray | None = None,
        *,
        materials: np.ndarray | None = None,
        uv: np.ndarray | None = None,
        texture: np.ndarray | None = None,
        texture_weight: np.ndarray | None = None,
        width: int = 640,
        height: int = 640,
        backend: str = "egl",
        samples: int | None = None,
        antialias: str | None = None,
        shading: str | None = None,
        ctx: moderngl.Context | None = None,
        cull: bool = True,
        gpu_normals: bool | None = None,
        detail: PartDetail | None = None,
        transparent: bool = False,
        backdrop: tuple[float, float, float] | None = None,
    ) -> None:
        """Upload topology, albedo (sRGB 0-1, per vertex) and specular strengths (0-1).

        ``colors`` None paints the mesh in a skin tone; ``materials`` None gives every vertex
        ``SKIN_SPECULAR``. ``texture`` (H, W, 3) uint8 sRGB, top row first, with ``uv`` (N, 2)
        per vertex (v up, as in OBJ) and ``texture_weight`` (N,) in 0-1 (None: 1) paints the
        texture over the vertex colours. ``samples`` (MSAA, > 1 where supported) and
        ``antialias`` (``ANTIALIAS_MODES``) default to ``choose_antialias``'s choice for the GL,
        ``shading`` (``SHADING_MODES``) to ``choose_shading``'s, ``gpu_normals`` to
        ``choose_normals``'s (True: the draw sums the normals, ``draw`` ignores any given; chosen
        by default and not built by the driver: a warning, and the CPU computes them).
        ``cull`` False draws back faces too (a mesh seen from inside), always shaded per pixel.
        ``detail`` (``PartDetail``, of these triangles) draws inner parts seen small from fewer
        triangles, chosen whenever the camera changes; None draws every triangle.
        ``transparent`` draws the face alone on a transparent backdrop (alpha 0 where no surface
        is: a program feed keyed over other video); ``read`` returns RGBA then. ``backdrop`` (sRGB 0-1)
        paints every pixel the face does not cover that flat colour instead of the studio gradient
        (a key colour, for a window captured and chroma-keyed: ``puppet.show.program``).
        On a software rasteriser its threads get a core each (``rasterthreads.spread``;
        ``rasteriser_cores``: {thread id: core} of those pinned).
        """
        self.n_vertices = int(n_vertices)
        self.cull = cull
        self.transparent = transparent
        self.backdrop = None if backdrop is None else tuple(float(c) for c in backdrop)
        self.size = (int(width), int(height))
        self._owns_ctx = ctx is None
        self.ctx = ctx or moderngl.create_context(standalone=True, backend=backend)
        self.camera: Camera | None = None
        self._uniform_camera: Camera | None = None  # the camera whose uniforms the mesh program holds
        self.detail = detail
        self.levels: dict[str, str] = {}  # the level each of ``detail``'s parts is drawn at
        try:
            with self._current():
                samples, self.antialias = choose_antialias(self.ctx, samples, antialias)
                self.shading = choose_shading(self.ctx, shading, cull=cull)
                self.rasteriser_cores = rasterthreads.spread() if software_rasteriser(self.ctx) else {}
                self._create_texture(uv, texture, texture_weight)
                self._build(triangles, colors, materials, samples, gpu_normals)
        except BaseException:
            if self._owns_ctx:  # nothing else holds it
                self.ctx.release()
            raise

    @classmethod
    def for_face(cls, face: FaceLike, *, detail: bool = True, **options) -> Renderer:
        """A renderer for ``face``: its triangles, vertex colours and, when it has one, its
        texture (``texture_kwargs``); its inner parts (eyeballs, teeth) drawn coarser where they
        are seen small (``PartDetail``) unless ``detail`` is False; ``options`` as for the
        constructor (size, ctx, samples...)."""
        parts = getattr(face, "parts", None)
        part_detail = PartDetail(face.vertices, face.triangles, parts, face.colors) if detail and parts else None
        return cls(face.triangles, len(face.vertices), face.colors, **texture_kwargs(face), detail=part_detail,
                   **options)

    def _build(self, triangles: np.ndarray, colors: np.ndarray | None, materials: np.ndarray | None,
               samples: int, gpu_normals: bool | None) -> None:
        """``_create_gl_objects`` with the normals from ``choose_normals``; where that chose the
        draw and the driver cannot build its shader, with a warning, from the CPU."""
        self._set_normals(triangles, choose_normals(self.ctx, gpu_normals))
        try:
            self._create_gl_objects(triangles, colors, materials, samples)
        except moderngl.Error:
            if gpu_normals is not None or not self.gpu_normals:
                raise
            warnings.warn(f"{self.ctx.info.get('GL_RENDERER')}: the shader that sums normals in the draw "
                          "did not build; the CPU computes them", RuntimeWarning, stacklevel=3)
            self._set_normals(triangles, False)
            self._create_gl_objects(triangles, colors, materials, samples)

    def _set_normals(self, triangles: np.ndarray, gpu: bool) -> None:
        """Where this renderer's normals come from (``choose_normals``) and the buffers for it."""
        self.gpu_normals = gpu
        self._normals = None if gpu else VertexNormals(triangles, self.n_vertices)
        self._normal_out = None if gpu else np.empty((self.n_vertices, 3))
        self._staging = np.empty((self.n_vertices, 3 if gpu else 6), dtype="f4")

    def _create_texture(
        self, uv: np.ndarray | None, texture: np.ndarray | None, weight: np.ndarray | None
    ) -> None:
        """The albedo texture (mipmapped, clamped) and the per-vertex uv + weight buffer, when
        there is a texture; none of either otherwise (the untextured shader samples nothing)."""
        self._texture = self._surface = None
        if texture is None:
            return
        surface = np.empty((self.n_vertices, 3), dtype="f4")
        surface[:, :2] = uv
        surface[:, 2] = 1.0 if weight is None else np.clip(weight, 0.0, 1.0)
        image = np.ascontiguousarray(np.asarray(texture, dtype=np.uint8)[::-1, :, :3])
        self._texture = self.ctx.texture((image.shape[1], image.shape[0]), 3, image.tobytes(), alignment=1)
        self._texture.repeat_x = self._texture.repeat_y = False
        self._texture.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self._texture.build_mipmaps()
        self._surface = self.ctx.buffer(surface)

    def _create_gl_objects(
        self,
        triangles: np.ndarray,
        colors: np.ndarray | None,
        materials: np.ndarray | None,
        samples: int,
    ) -> None:
        """Programs, static and dynamic buffers, vertex arrays, constant uniforms, targets
        (after ``_create_texture``: the mesh's shader variant follows whether there is one)."""
        header = "#version 430\n#define GPU_NORMALS\n" if self.gpu_normals else "#version 330\n"
        header += "#define TEXTURED\n" if self._texture is not None else ""
        header += ("#define PER_VERTEX\n" if self.shading == "vertex" else "") + _LIGHTING
        self._mesh_program = self.ctx.program(
            vertex_shader=header + _MESH_VERTEX_SHADER, fragment_shader=header + _MESH_FRAGMENT_SHADER
        )
        self._background_program = self.ctx.program(
            vertex_shader=_BACKGROUND_VERTEX_SHADER, fragment_shader=_BACKGROUND_FRAGMENT_SHADER
        )
        self._fxaa_program = self.ctx.program(
            vertex_shader=_BACKGROUND_VERTEX_SHADER, fragment_shader=_FXAA_FRAGMENT_SHADER
        )
        self._dynamic = self.ctx.buffer(reserve=self._staging.nbytes, dynamic=True)
        self._static = self.ctx.buffer(material_data(self.n_vertices, colors, materials))
        self._indices = self.ctx.buffer(np.ascontiguousarray(triangles, dtype="u4"))
        self._rings: tuple[moderngl.Buffer, ...] = ()
        if self.gpu_normals:
            starts, others = vertex_rings(triangles, self.n_vertices)
            self._rings = (self._dynamic, self.ctx.buffer(starts), self.ctx.buffer(others))
            attributes = [(self._dynamic, "3f", "in_position")]
        else:
            attributes = [(self._dynamic, "3f 3f", "in_position", "in_normal")]
        attributes.append((self._static, "4f", "in_material"))
        if self._surface is not None:
            attributes.append((self._surface, "3f", "in_surface"))
        self._mesh = self.ctx.vertex_array(
            self._mesh_program, attributes, index_buffer=self._indices, index_element_size=4
        )
        self._background = self.ctx.vertex_array(self._background_program, [])
        self._fxaa = self.ctx.vertex_array(self._fxaa_program, [])
        for name, value in LIGHT_UNIFORMS.items():
            self._set_uniform(name, value)
        self._make_targets(samples)

    def __enter__(self) -> Renderer:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.release()

    @property
    def samples(self) -> int:
        """Multisample count actually in use (0: no multisampling)."""
        return self._multi.samples if self._multi is not None else 0

    def set_material_data(self, data: np.ndarray) -> None:
        """Replace the per-vertex linear albedo and specular strengths with ``data`` (N, 4), as
        ``material_data`` makes them: what the show's feed sends, taken as sent (a round trip
        through sRGB colours could move a value by one float32 step)."""
        data = np.ascontiguousarray(data, dtype="f4")
        if data.shape != (self.n_vertices, 4):
            raise ValueError(f"expected material data of shape ({self.n_vertices}, 4), got {data.shape}")
        with self._current():
            self._static.write(data)

    def look_at(
        self,
        eye: np.ndarray,
        target: np.ndarray,
        up: np.ndarray = (0.0, 1.0, 0.0),
        fov: float = DEFAULT_FOV,
        near: float | None = None,
        far: float | None = None,
    ) -> Camera:
        """Place the camera at ``eye`` aimed at ``target``; fov is vertical, in degrees.

        Clip planes default to 1/20 and 20 times the eye-target distance.
        """
        eye, target = np.asarray(eye, dtype=float), np.asarray(target, dtype=float)
        distance = float(np.linalg.norm(eye - target))
        self.camera = Camera(
            eye=eye,
            target=target,
            up=np.asarray(up, dtype=float),
            fov=float(fov),
            near=distance / 20.0 if near is None else float(near),
            far=distance * 20.0 if far is None else float(far),
        )
        return self.camera

    def aim(
        self,
        vertices: np.ndarray,
        view: str = "front",
        margin: float = 1.15,
        fov: float = DEFAULT_FOV,
    ) -> Camera:
        """Aim the camera at ``vertices`` (e.g. the head) from a named view (``aim_camera``)."""
        self.camera = aim_camera(vertices, self.size, view, margin, fov)
        return self.camera

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates (M, 2) as (column, row), row 0 at the top, of world ``points``."""
        clip = self._view_projection() @ np.c_[points, np.ones(len(points))].T
        ndc = clip[:2] / clip[3]
        width, height = self.size
        return np.stack([(ndc[0] + 1.0) / 2.0 * width, (1.0 - ndc[1]) / 2.0 * height], axis=1)

    def draw(
        self,
        vertices: np.ndarray,
        normals: np.ndarray | None = None,
        framebuffer: moderngl.Framebuffer | None = None,
    ) -> None:
        """Draw background and mesh into ``framebuffer`` (default: the offscreen one).

        A window passes ``ctx.screen`` (of the renderer's size, since the camera's aspect
        follows it) and skips the readback of ``render``; it gets the same antialiasing as an
        offscreen frame (a multisampled screen is drawn into directly). Without a camera yet,
        the first call frames ``vertices`` from the front.
        """
        self._prepare(vertices)
        with self._current():
            self._upload(vertices, normals)
            self._set_frame_uniforms()
            self._draw_antialiased(framebuffer or self._output, vertices)

    def render(self, vertices: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
        """Render one frame and return it as (height, width, 3) uint8 sRGB, top row first.

        ``normals`` None computes unit vertex normals from ``vertices``; a renderer whose draw
        sums them (``gpu_normals``) ignores any given.
        """
        self.draw(vertices, normals)
        return self.read()

    def read(self) -> np.ndarray:
        """The last frame drawn offscreen, as (height, width, 3) uint8 sRGB, top row first
        ((height, width, 4) with alpha when ``transparent``).

        It waits for the drawing first without holding the GIL (``wait_for_gl``), so other
        threads (the devices' readers) run meanwhile."""
        with self._current():
            wait_for_gl(self.ctx)
            components = 4 if self.transparent else 3
            data = self._output.read(components=components, alignment=1)
        width, height = self.size
        return np.frombuffer(data, dtype=np.uint8).reshape(height, width, components)[::-1].copy()

    def finish(self) -> None:
        """Wait until the GL has executed everything issued so far (``wait_for_gl``)."""
        with self._current():
            wait_for_gl(self.ctx)

    def release(self) -> None:
        """Free every GL object this renderer made, and its context if it created it."""
        with self._current():
            for obj in (
                self._mesh,
                self._texture,
                self._surface,
                self._background,
                self._fxaa,
                self._dynamic,
                self._static,
                self._indices,
                *self._rings[1:],
                self._mesh_program,
                self._background_program,
                self._fxaa_program,
                *self._targets,
            ):
                if obj is not None:
                    obj.release()
        if self._owns_ctx:
            self.ctx.release()

    def _current(self) -> contextlib.AbstractContextManager:
        """Make an owned context current for a ``with`` block; never nest these blocks, since
        glcontext keeps one saved context per context and a nested exit loses the outer one."""
        return self.ctx if self._owns_ctx else contextlib.nullcontext()

    def _make_targets(self, samples: int) -> None:
        """The offscreen output (plain RGBA8 + depth, what ``read`` reads); the background,
        drawn once (``_backdrop``); a multisampled
        target to draw into when ``samples`` > 1 (dropped if the driver refuses it); and for the
        FXAA pass, a scene target whose colour is a texture the pass samples."""
        color = self.ctx.renderbuffer(self.size, components=4)
        depth = self.ctx.depth_renderbuffer(self.size)
        self._output = self.ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
        backdrop = self.ctx.renderbuffer(self.size, components=4)
        self._backdrop = self.ctx.framebuffer(color_attachments=[backdrop])
        self._backdrop.use()
        self._paint_backdrop(self._backdrop)
        self._targets: list = [self._output, color, depth, self._backdrop, backdrop]
        self._multi = self._scene = None
        if samples > 1:
            try:
                color = self.ctx.renderbuffer(self.size, components=4, samples=samples)
                depth = self.ctx.depth_renderbuffer(self.size, samples=samples)
                self._multi = self.ctx.framebuffer(color_attachments=[color], depth_attachment=depth)
                self._targets += [self._multi, color, depth]
            except moderngl.Error:
                self._multi = None
        if self.antialias == "fxaa":
            self._scene_color = self.ctx.texture(self.size, 4)
            self._scene_color.repeat_x = self._scene_color.repeat_y = False
            depth = self.ctx.depth_renderbuffer(self.size)
            self._scene = self.ctx.framebuffer(color_attachments=[self._scene_color], depth_attachment=depth)
            self._targets += [self._scene, self._scene_color, depth]

    def _draw_antialiased(self, out: moderngl.Framebuffer, vertices: np.ndarray) -> None:
        """Draw into ``out``: through the multisampled target (resolved) and the FXAA pass where
        those are on, straight into ``out`` when neither is, or when ``out`` is a screen that
        multisamples by itself and there is no post pass. The FXAA pass runs only over the
        mesh's screen box (the background is a smooth gradient, nothing to smooth), the rest of
        the frame copied as drawn; it needs the scene finished, which it waits for with the GIL
        let go (``wait_for_gl``)."""
        own_samples = out is self._output or not out.samples
        first = self._scene or out
        if self._multi is not None and own_samples:
            self._draw_scene(self._multi)
            self.ctx.copy_framebuffer(first, self._multi)
        else:
            self._draw_scene(first)
        if self._scene is not None:
            wait_for_gl(self.ctx)  # the copy would wait for the scene holding the GIL
            self.ctx.copy_framebuffer(out, self._scene)
            out.use()
            out.scissor = self._screen_box(vertices)
            self.ctx.disable(moderngl.DEPTH_TEST)
            self._scene_color.use(location=0)
            self._fxaa.render(moderngl.TRIANGLES, vertices=3)
            out.scissor = None

    def _screen_box(self, vertices: np.ndarray, margin: int = 2) -> tuple[int, int, int, int]:
        """(x, y, width, height), y up as GL counts it, of a pixel box holding the projection
        of ``vertices``: that of their bounding box's corners (which contains it), widened by
        ``margin``; the whole image when a corner lies behind the camera."""
        low, high = _bounds(vertices)
        corners = np.array(list(itertools.product(*zip(low, high))))
        local = (corners - self.camera.eye) @ self.camera.basis().T
        width, height = self.size
        if np.any(local[:, 2] >= 0):
            return 0, 0, width, height
        pixels = self.project(corners)
        x0, y0 = np.floor(pixels.min(axis=0)).astype(int) - margin
        x1, y1 = np.ceil(pixels.max(axis=0)).astype(int) + margin
        x0, x1 = max(x0, 0), min(x1, width)
        y0, y1 = max(height - y1, 0), min(height - y0, height)
        return int(x0), int(y0), max(int(x1 - x0), 0), max(int(y1 - y0), 0)

    def _prepare(self, vertices: np.ndarray) -> None:
        """Check the vertex array's shape; frame it from the front if there is no camera yet."""
        shape = np.shape(vertices)
        if shape != (self.n_vertices, 3):
            raise ValueError(f"expected vertices of shape ({self.n_vertices}, 3), got {shape}")
        if self.camera is None:
            self.aim(vertices)

    def _set_frame_uniforms(self) -> None:
        """The camera's uniforms: view-projection, eye and the camera-attached lights, and the
        parts' levels of detail (``_choose_detail``); set only when the camera changed (a
        ``Camera`` is frozen: ``look_at`` makes a new one), as the uniforms cost a software
        rasteriser's frame 0.2 ms."""
        if self.camera is self._uniform_camera:
            return
        self._uniform_camera = self.camera
        for name, value in camera_uniforms(self.camera, self.size[0] / self.size[1]).items():
            self._set_uniform(name, value)
        self._choose_detail()

    def _choose_detail(self) -> None:
        """Draw each of ``detail``'s parts at the level this camera sees it at: the index
        buffer rewritten (never longer than every triangle) when a level changes."""
        if self.detail is None:
            return
        levels = self.detail.levels(self.camera.eye, self.camera.basis()[2], self.camera.fov, self.size[1])
        if levels == self.levels:
            return
        self.levels = levels
        indices = self.detail.triangles(levels)
        self._indices.write(indices)
        self._mesh.vertices = indices.size

    def _draw_scene(self, target: moderngl.Framebuffer) -> None:
        """Draw background then mesh into ``target``; the context is current. The background
        never changes, so a single-sampled target gets it copied from ``_backdrop`` (a shader
        pass over every pixel costs a software rasteriser more than the copy); back faces are
        culled unless ``cull`` is off (module docstring)."""
        if target.samples or tuple(target.size) != self.size:
            target.use()
            target.clear(depth=1.0)
            self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
            self._paint_backdrop(target)
        else:
            self.ctx.copy_framebuffer(target, self._backdrop)
            target.color_mask = (False, False, False, False)
            target.use()
            target.clear(depth=1.0)
            target.color_mask = (True, True, True, True)
            target.use()
        self.ctx.enable(moderngl.DEPTH_TEST | (moderngl.CULL_FACE if self.cull else 0))
        if self._texture is not None:
            self._texture.use(location=0)
        for buffer, binding in zip(self._rings, _RING_BINDINGS):  # bindings are the context's: rebind
            buffer.bind_to_storage_buffer(binding)
        draw_triangles(self._mesh)
        self.ctx.disable(moderngl.CULL_FACE)

    def _paint_backdrop(self, target: moderngl.Framebuffer) -> None:
        """The studio gradient; nothing at all (alpha 0) when ``transparent``; the flat
        ``backdrop`` colour when there is one."""
        if self.transparent:
            target.clear(0.0, 0.0, 0.0, 0.0)
        elif self.backdrop is not None:
            target.clear(*self.backdrop, 1.0)
        else:
            self._background.render(moderngl.TRIANGLES, vertices=3)

    def _upload(self, vertices: np.ndarray, normals: np.ndarray | None) -> None:
        """Write positions and normals (positions alone where the draw sums the normals) into
        the dynamic vertex buffer in place."""
        vertices = np.asarray(vertices)
        if self.gpu_normals:
            self._staging[:] = vertices
            self._dynamic.write(self._staging)
            return
        if normals is None:
            normals = self._normals(vertices, out=self._normal_out)
        self._staging[:, :3] = vertices
        self._staging[:, 3:] = normals
        self._dynamic.write(self._staging)

    def _view_projection(self) -> np.ndarray:
        if self.camera is None:
            raise RuntimeError("no camera: call frame() or look_at() first")
        aspect = self.size[0] / self.size[1]
        return self.camera.projection_matrix(aspect) @ self.camera.view_matrix()

    def _set_uniform(self, name: str, value: np.ndarray) -> None:
        """Write a float uniform; matrices must already be transposed to column-major."""
        self._mesh_program[name].write(np.ascontiguousarray(value, dtype="f4"))


def render_face(
    face: FaceLike,
    vertices: np.ndarray | None = None,
    *,
    view: str = "front",
    width: int = 640,
    height: int = 640,
) -> np.ndarray:
    """One-shot render of ``face`` (its rest pose unless ``vertices`` given), framed on the
    whole face from ``view``. Uses ``face.colors``, or a skin tone where it has none, and the
    face's texture when it has one (``texture_kwargs``)."""
    vertices = face.vertices if vertices is None else vertices
    with Renderer.for_face(face, width=width, height=height) as r:
        r.aim(vertices, view=view)
        return r.render(vertices)


def aim_camera(
    vertices: np.ndarray,
    size: tuple[int, int],
    view: str = "front",
    margin: float = 1.15,
    fov: float = DEFAULT_FOV,
) -> Camera:
    """A perspective camera for an image of ``size`` aimed at ``vertices`` (e.g. the head) from a named view.

    The camera looks at the centre of their bounding box along ``VIEW_DIRECTIONS[view]``
    and backs off just far enough that every vertex projects inside the image shrunk by
    ``margin`` (1.15: 15% breathing room).
    """
    points = np.asarray(vertices, dtype=float)
    direction = np.asarray(VIEW_DIRECTIONS[view])
    target = (points.min(axis=0) + points.max(axis=0)) / 2.0
    probe = Camera(target + direction, target, np.array([0.0, 1.0, 0.0]), fov, 1.0, 2.0)
    local = (points - target) @ probe.basis().T
    tan_y = np.tan(np.radians(fov) / 2.0)
    tan_x = tan_y * size[0] / size[1]
    reach = np.maximum(np.abs(local[:, 0]) / tan_x, np.abs(local[:, 1]) / tan_y)
    distance = float(np.max(local[:, 2] + margin * reach))
    depth = float(np.ptp(local[:, 2])) + 1e-9
    return Camera(target + distance * direction, target, np.array([0.0, 1.0, 0.0]), float(fov),
                  max(distance - local[:, 2].max() - depth, distance / 100.0), distance + 2.0 * depth)


def camera_uniforms(camera: Camera, aspect: float) -> dict[str, np.ndarray]:
    """The mesh shaders' uniforms that follow the camera, for an image of ``aspect`` (width /
    height): the view-projection (column-major, as GL takes it), the eye and the directions of
    the lights, which are attached to the camera."""
    view_projection = camera.projection_matrix(aspect) @ camera.view_matrix()
    return {"view_projection": view_projection.T, "eye": camera.eye,
            "light_direction": _LIGHT_DIRECTIONS_CAMERA @ camera.basis()}


def webgl_shaders(textured: bool = False, shading: str = "pixel") -> tuple[str, str]:
    """The mesh's vertex and fragment shaders in GLSL ES 3.00 (WebGL 2), lit per pixel or per
    vertex (``SHADING_MODES``) from the normals given: this renderer's own text under another
    header, so that a browser drawing the same vertices, materials and uniforms shows the face
    with the same look (``puppet.show``)."""
    header = "#version 300 es\nprecision highp float;\nprecision highp int;\n"
    header += ("#define TEXTURED\n" if textured else "") + ("#define PER_VERTEX\n" if shading == "vertex" else "")
    header += _LIGHTING
    return header + _MESH_VERTEX_SHADER, header + _MESH_FRAGMENT_SHADER


def texture_kwargs(face: FaceLike) -> dict:
    """``Renderer`` keyword arguments for a face's texture: ``uv``, ``texture`` and
    ``texture_weight`` when it has a ``texture`` (a face from ``puppet.face.folder``), else none."""
    texture = getattr(face, "texture", None)
    if texture is None:
        return {}
    return {"uv": face.uv, "texture": texture, "texture_weight": getattr(face, "texture_weight", None)}


def save_png(image: np.ndarray, path: str | Path) -> None:
    """Write an (H, W, 3) uint8 image as PNG."""
    from PIL import Image

    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(path, format="PNG")


VIDEO_PRESET = "veryfast"
"""libx264's preset for every video: at imageio's default quality (CRF 25) it encodes a face
take with 2.4x less CPU than x264's default ("medium": 2.9 -> 1.2 ms a 320x240 frame, 7.2 -> 3.6
at 640x480) into files no larger (the demo take: 21 -> 17 KiB at 320x240); the encoder runs
beside the renderer, so in a batch it takes cores the other takes could use."""


def write_video(frames: Iterable[np.ndarray], path: str | Path, fps: float = 30.0) -> int:
    """Encode (H, W, 3) uint8 frames to an H.264 MP4 (yuv420p, ``VIDEO_PRESET``) and return the
    frame count.

    yuv420p needs even dimensions, so an odd last row or column is duplicated. Every frame
    must have the first frame's size.
    """
    import imageio_ffmpeg

    iterator: Iterator[np.ndarray] = iter(frames)
    first = _even(next(iterator))
    height, width = first.shape[:2]
    writer = imageio_ffmpeg.write_frames(
        str(path),
        (width, height),
        fps=fps,
        codec="libx264",
        pix_fmt_out="yuv420p",
        macro_block_size=2,
        output_params=["-preset", VIDEO_PRESET],
    )
    writer.send(None)
    count = 0
    try:
        for frame in itertools.chain([first], iterator):
            frame = _even(frame)
            if frame.shape != first.shape:
                raise ValueError(f"frame {count} has shape {frame.shape}, expected {first.shape}")
            writer.send(np.ascontiguousarray(frame, dtype=np.uint8))
            count += 1
    finally:
        writer.close()
    return count


def _even(image: np.ndarray) -> np.ndarray:
    """Pad an odd height or width by repeating the last row or column."""
    height, width = image.shape[:2]
    return np.pad(image, ((0, height % 2), (0, width % 2), (0, 0)), mode="edge")


def material_data(
    n_vertices: int, colors: np.ndarray | None, materials: np.ndarray | None
) -> np.ndarray:
    """Static per-vertex attributes (N, 4) float32: linear albedo and specular strength."""
    data = np.empty((n_vertices, 4), dtype="f4")
    srgb = np.broadcast_to(SKIN_SRGB if colors is None else np.asarray(colors), (n_vertices, 3))
    data[:, :3] = _srgb_to_linear(np.clip(srgb, 0.0, 1.0))
    data[:, 3] = SKIN_SPECULAR if materials is None else np.asarray(materials)
    return data


def _bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (low, high) corners of the box around ``points`` (N, 3): one strided pass per
    coordinate, since numpy's ``min(axis=0)`` of an (N, 3) array steps three values at a time
    (0.26 ms for the default face's 10k vertices against 0.016)."""
    flat = np.ascontiguousarray(points).reshape(-1)
    columns = [flat[i::3] for i in range(3)]
    return np.array([c.min() for c in columns]), np.array([c.max() for c in columns])


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)
